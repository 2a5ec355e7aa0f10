"""A study's grid: its points, each run of a point (a point and a seed) and its key.

A point is a set of parameters (what a reader sees in a table, and what keys the run) and
how to make a run of it: the options of ``swarm run`` (or, for the runs that are no swarm,
the parameters alone), a timeout in sim seconds, the seeds, an estimate of a run's wall
time. Its runs are what the runner makes and the results file holds, one each: a run's key
is its parameters, sorted by name, and its seed (``robots=10 sites=5 seed=3``), so it does
not change when a declaration is reordered.

Nothing here runs anything: expanding a grid, keying its runs, selecting part of it
(``--only``) and ordering the work are pure functions, and tested as such.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

Scalar = str | int | float | bool

# How a run is made (deploy/study/make.py): a swarm in this process, the same observed,
# the Section 4 model, the camera alone, or a swarm of real processes over Zenoh.
KINDS = ("inprocess", "comparisons", "lag", "wellstirred", "sensing", "zenoh")
SWARM_KINDS = ("inprocess", "comparisons", "lag", "zenoh")


def text(value: Scalar) -> str:
    """A parameter's value as keys, tables and ``--only`` write it: 0.2, 10, dmvd, true."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return format(value, ".12g")
    return str(value)


def key_of(params: Mapping[str, Scalar], seed: int) -> str:
    """The key of a run: its parameters by name, then its seed."""
    named = " ".join(f"{name}={text(params[name])}" for name in sorted(params))
    return f"{named} seed={seed}".strip()


@dataclass(frozen=True)
class Run:
    """One run of a study: what a worker needs to make it, and nothing that is not
    picklable. ``options``: the ``swarm run`` options of a swarm run (its seed and timeout
    among them); ``configs``: settings ``swarm run`` has no option for, as
    ``config.field`` (``spec.max_wheel_speed``); ``cost``: the wall seconds it is expected
    to take; ``wall_limit``: wall seconds after which it is given up (not recorded);
    ``record``: where a run over Zenoh writes its recording (set by the runner)."""

    study: str
    params: tuple[tuple[str, Scalar], ...]
    seed: int
    kind: str = "inprocess"
    options: tuple[str, ...] = ()
    configs: tuple[tuple[str, Scalar], ...] = ()
    cost: float = 1.0
    wall_limit: float | None = None
    record: bool = False
    record_to: str | None = None

    @property
    def key(self) -> str:
        return key_of(dict(self.params), self.seed)

    @property
    def point(self) -> str:
        """The key of the run's point: its parameters without the seed."""
        return key_of(dict(self.params), 0).rsplit(" seed=", 1)[0]

    def param(self, name: str) -> Scalar:
        return dict(self.params)[name]

    def command(self) -> str | None:
        """The ``swarm run`` command that makes the same run (None for runs that are not
        swarms, or whose settings ``swarm run`` has no option for)."""
        if self.kind not in SWARM_KINDS or self.configs:
            return None
        return " ".join(["swarm run", *self.options])


@dataclass(frozen=True)
class Point:
    """A point of a grid and its seeds. ``options``: its ``swarm run`` options but the
    seed and timeout, which the runs add; ``per_seed``: options that depend on the seed
    (which robots are Byzantine, say)."""

    params: Mapping[str, Scalar]
    seeds: Sequence[int]
    kind: str = "inprocess"
    options: Sequence[str] = ()
    timeout: float | None = None
    configs: Mapping[str, Scalar] = field(default_factory=dict)
    cost: float = 1.0
    wall_limit: float | None = None
    record: bool = False
    per_seed: Callable[[int], Sequence[str]] | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind {self.kind!r} is not one of {', '.join(KINDS)}")
        for name, value in self.params.items():
            shown = text(value)
            if not name.isidentifier() or " " in shown or not shown:
                raise ValueError(f"parameter {name}={shown!r}: a name and a value without spaces")
        if self.kind in SWARM_KINDS and self.timeout is None:
            raise ValueError(f"{key_of(self.params, 0)}: a swarm run needs a timeout")

    def runs(self, study: str) -> list[Run]:
        made = []
        for seed in self.seeds:
            options: list[str] = []
            if self.kind in SWARM_KINDS:
                options = [
                    *self.options,
                    "--seed",
                    str(seed),
                    "--timeout",
                    text(float(self.timeout or 0)),
                ]
                if self.per_seed is not None:
                    options += list(self.per_seed(seed))
            made.append(
                Run(
                    study=study,
                    params=tuple(self.params.items()),
                    seed=seed,
                    kind=self.kind,
                    options=tuple(options),
                    configs=tuple(sorted(self.configs.items())),
                    cost=self.cost,
                    wall_limit=self.wall_limit,
                    record=self.record,
                )
            )
        return made


def expand(study: str, points: Iterable[Point]) -> list[Run]:
    """Every run of the points; ValueError if two runs have one key."""
    runs = [run for point in points for run in point.runs(study)]
    seen: dict[str, Run] = {}
    for run in runs:
        if run.key in seen:
            raise ValueError(f"study {study}: two runs have the key {run.key!r}")
        seen[run.key] = run
    return runs


def product(**axes: Sequence[Scalar]) -> list[dict[str, Scalar]]:
    """Every combination of the axes' values, the first axis slowest."""
    combos: list[dict[str, Scalar]] = [{}]
    for name, values in axes.items():
        combos = [{**combo, name: value} for combo in combos for value in values]
    return combos


# --- part of a grid: --only KEY=VALUE ------------------------------------------------------


def parse_only(items: Sequence[str]) -> dict[str, set[str]]:
    """``["robots=500", "sites=5,8"]`` -> ``{"robots": {"500"}, "sites": {"5", "8"}}``;
    ValueError for an item that is not NAME=VALUE[,VALUE...]."""
    wanted: dict[str, set[str]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or not name or not values:
            raise ValueError(f"--only {item}: give NAME=VALUE (several values: NAME=A,B)")
        wanted.setdefault(name, set()).update(value for value in values.split(",") if value)
    return wanted


def select(runs: Sequence[Run], only: Mapping[str, set[str]]) -> list[Run]:
    """The runs whose every parameter named in ``only`` (``seed`` included) has one of its
    values; ValueError naming a parameter no run has, or a value no run has."""
    if not only:
        return list(runs)
    values: dict[str, set[str]] = {"seed": set()}
    for run in runs:
        values["seed"].add(str(run.seed))
        for name, value in run.params:
            values.setdefault(name, set()).add(text(value))
    for name, wanted in only.items():
        if name not in values:
            raise ValueError(
                f"--only {name}=...: no such parameter (it has {', '.join(sorted(values))})"
            )
        if unknown := sorted(wanted - values[name]):
            known = ", ".join(sorted(values[name], key=_natural))
            raise ValueError(f"--only {name}={','.join(unknown)}: no run has it ({name}: {known})")

    def chosen(run: Run) -> bool:
        have = {name: text(value) for name, value in run.params} | {"seed": str(run.seed)}
        return all(have.get(name) in wanted for name, wanted in only.items())

    return [run for run in runs if chosen(run)]


def _natural(value: str) -> tuple[int, float, str]:
    try:
        return (0, float(value), value)
    except ValueError:
        return (1, 0.0, value)


# --- the work's order ----------------------------------------------------------------------


def estimate(run: Run, walls: Mapping[str, Sequence[float]]) -> float:
    """A run's expected wall seconds: the median of the runs of its point already made
    (``walls`` by point), else what its point declares."""
    made = sorted(walls.get(run.point, ()))
    return made[len(made) // 2] if made else run.cost


def order(runs: Sequence[Run], walls: Mapping[str, Sequence[float]] | None = None) -> list[Run]:
    """Longest first (so that on J workers the long runs do not end alone), then seed by
    seed (a sweep cut short has every point at a few seeds, not a few points done)."""
    walls = walls or {}
    return sorted(runs, key=lambda run: (-estimate(run, walls), run.seed, run.key))


def summarise_params(runs: Sequence[Run]) -> dict[str, list[str]]:
    """Each parameter and the values it takes, for ``--list`` and ``--status``."""
    values: dict[str, set[str]] = {}
    for run in runs:
        for name, value in run.params:
            values.setdefault(name, set()).add(text(value))
    return {name: sorted(found, key=_natural) for name, found in values.items()}
