"""A run's time series (pure: no I/O, no clock): what each robot was doing at each sample
of the run, and the swarm's curves, from the messages every observer of a run is fed.

A sample is a world state (``world/state``, every ``--state-every`` ticks). Its row for a
robot holds the robot's pose in that state and what its latest status of that tick or
before said: its phase, trips, decided site, leading site, the probability it gives the
best site, the entropy of its opinion and its last pool size. Its swarm row holds the
robots decided, each site's share of the swarm's opinion (the mean of the robots'
probabilities for it), the mean entropy and the poolings since the sample before.

The rows are the same however the messages came in: a status travels on its robot's key
and may reach an observer after the world state of its tick (a robot sends its status
after its answer, and the world may open the next tick first), so a sample is finished
only once two later world states came (or at ``finish``), from the statuses of its tick
or before. A recording of a run and the in-process engine that ran it give equal rows.

Memory does not grow with the run: the collector keeps each robot's latest status, the
statuses and the world states of the last few samples, and the finished rows until they
are taken (``take``); what keeps them (a file, ``Table``) decides the rest.
"""

from __future__ import annotations

import math
from array import array
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, get_args

import msgspec

from bestofn_swarm.wire import protocol
from world_server.core.layout import make_layout

# A robot's phase in the rows, by its index here (-1: no status yet), in the order of a trip.
PHASES: tuple[str, ...] = get_args(protocol.Phase)
PHASE_CODE = {phase: index for index, phase in enumerate(PHASES)}

# Samples a world state waits for before it is finished: statuses of its tick may arrive
# after the next state, never after two (the statuses of a tick precede the answers
# that let the world open the tick after the next).
SETTLE_SAMPLES = 2

# One row per robot per sample. Kinds: "i" an integer (-1: none), "f" a float (NaN: none),
# "p" a phase code.
ROBOT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("tick", "i"),
    ("t", "f"),
    ("robot", "i"),
    ("x", "f"),
    ("y", "f"),
    ("theta", "f"),
    ("phase", "p"),
    ("trips", "i"),
    ("decided_site", "i"),
    ("leading_site", "i"),
    ("p_leading", "f"),
    ("p_best", "f"),
    ("entropy", "f"),
    ("pool_size", "i"),
    ("poolings", "i"),
)
NONE = -1
NAN = math.nan


def swarm_columns(sites: int) -> tuple[tuple[str, str], ...]:
    """One row per sample: the swarm's curves, ``share_<site>`` for each site."""
    return (
        ("tick", "i"),
        ("t", "f"),
        ("robots", "i"),  # robots heard from so far
        ("decided", "i"),
        ("entropy_mean", "f"),
        ("p_best_mean", "f"),
        ("poolings", "i"),  # poolings since the sample before
        ("pool_size_mean", "f"),  # their mean pool size (NaN: none)
        *((f"share_{site}", "f") for site in range(sites)),
    )


class SwarmSample(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """A swarm row as a recording and Foxglove carry it (``<run>/foxglove/swarm``): plottable
    fields, ``shares[i]`` being site i's share of the swarm's opinion."""

    tick: int
    t: float
    robots: int
    decided: int
    entropy_mean: float | None
    p_best_mean: float | None
    poolings: int
    pool_size_mean: float | None
    shares: list[float]


def entropy(opinion: Sequence[float]) -> float:
    """The Shannon entropy of an opinion, in bits (0: certain; log2 n: uniform)."""
    return -math.fsum(p * math.log2(p) for p in opinion if p > 0.0) + 0.0


def _leading(opinion: Sequence[float]) -> int:
    return max(range(len(opinion)), key=opinion.__getitem__)


@dataclass
class _Robot:
    """What the collector keeps of one robot: its status as of the last finished sample,
    and those that came since."""

    current: protocol.Status | None = None
    pending: deque[protocol.Status] = field(default_factory=deque)
    # Of ``current``: its leading site, that site's probability, the best site's, entropy.
    derived: tuple[int, float, float, float] = (NONE, NAN, NAN, NAN)


class FrameCollector:
    """Fed a run's statuses and world states, in the order an observer hears them (the
    run's observer forwards them: ``RunObserver(series=...)``); keeps the finished rows in
    two ``Table``s (``robots``, ``swarm``; ``dataframe``), or, with ``keep=False``, hands
    them out (``take``) to whoever streams them on.

    ``sites``: the number of sites; ``best_site``: the best one (for ``p_best``; None:
    not known, NaN). ``every``: keep every n-th world state. ``robot_rows``: whether
    per-robot rows are made (the live page needs only the swarm's)."""

    @classmethod
    def of_run(cls, sites: int, robots: int, seed: int, **options: Any) -> FrameCollector:
        """The collector of a run of this shape (its best site from the seed's layout)."""
        return cls(sites, make_layout(sites, robots, seed).best_site, **options)

    def __init__(
        self,
        sites: int,
        best_site: int | None,
        *,
        every: int = 1,
        robot_rows: bool = True,
        keep: bool = True,
    ) -> None:
        if every < 1:
            raise ValueError(f"every must be at least 1, got {every}")
        self.sites = sites
        self.best_site = best_site
        self.every = every
        self.robot_rows = robot_rows
        self.robot_columns = ROBOT_COLUMNS
        self.swarm_columns = swarm_columns(sites)
        self._robots: dict[int, _Robot] = {}
        self._states: deque[protocol.WorldState] = deque()
        self._seen_states = 0
        self._last_tick = -1
        self._finished = -1  # the tick of the last sample finished
        self._robot_rows: list[tuple[Any, ...]] = []
        self._swarm_rows: list[tuple[Any, ...]] = []
        self.late = 0  # statuses that came after their sample was finished (not in a row)
        self.keep = keep
        self.robots = Table(self.robot_columns)
        self.swarm = Table(self.swarm_columns)

    # --- fed -------------------------------------------------------------------------

    def status(self, status: protocol.Status) -> None:
        robot = self._robots.get(status.id)
        if robot is None:
            robot = self._robots[status.id] = _Robot()
        if status.tick <= self._finished:
            self.late += 1
        robot.pending.append(status)

    def state(self, state: protocol.WorldState) -> None:
        if state.tick <= self._last_tick:
            if self._states and state.tick == self._states[-1].tick:
                self._states[-1] = state  # the world's last state, again at its stop
            return
        self._last_tick = state.tick
        self._seen_states += 1
        if (self._seen_states - 1) % self.every:
            return
        self._states.append(state)
        while len(self._states) > SETTLE_SAMPLES:
            self._finish(self._states.popleft())

    def finish(self) -> None:
        """The run is over: finish every sample still waiting."""
        while self._states:
            self._finish(self._states.popleft())

    def take(self) -> tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]:
        """The rows finished since the last call and not kept: the robots', the swarm's."""
        robots, swarm = self._robot_rows, self._swarm_rows
        self._robot_rows, self._swarm_rows = [], []
        return robots, swarm

    def dataframe(self, *, swarm: bool = False, run_id: str | None = None) -> Any:
        """The kept rows as a pandas DataFrame: one row per robot per sample, or with
        ``swarm`` one per sample (``finish`` first, for the last samples)."""
        return (self.swarm if swarm else self.robots).dataframe(run_id)

    # --- a sample --------------------------------------------------------------------

    def _finish(self, state: protocol.WorldState) -> None:
        tick, t = state.tick, state.t
        self._finished = tick
        pooled: list[int] = []  # the pool sizes of the poolings since the sample before
        for robot in self._robots.values():
            pending = robot.pending
            if not pending or pending[0].tick > tick:
                continue
            while pending and pending[0].tick <= tick:
                status = pending.popleft()
                before = robot.current.poolings if robot.current is not None else 0
                if status.poolings != before and status.poolings > 0:
                    pooled.append(status.pool_size)
                robot.current = status
            robot.derived = self._derive(robot.current)
        known = {
            robot_id: robot for robot_id, robot in self._robots.items() if robot.current is not None
        }
        if self.robot_rows:
            poses = {pose.id: pose for pose in state.robots}
            for robot_id in sorted(poses.keys() | known.keys()):
                self._robot_rows.append(
                    self._robot_row(tick, t, robot_id, poses.get(robot_id), known.get(robot_id))
                )
        self._swarm_rows.append(self._swarm_row(tick, t, list(known.values()), pooled))
        if self.keep:
            self.robots.extend(self._robot_rows)
            self.swarm.extend(self._swarm_rows)
            self._robot_rows, self._swarm_rows = [], []

    def _derive(self, status: protocol.Status | None) -> tuple[int, float, float, float]:
        if status is None:
            return (NONE, NAN, NAN, NAN)
        opinion, best = status.opinion, self.best_site
        lead = _leading(opinion)
        p_best = opinion[best] if best is not None and best < len(opinion) else NAN
        return (lead, opinion[lead], p_best, entropy(opinion))

    @staticmethod
    def _robot_row(
        tick: int, t: float, robot_id: int, pose: protocol.Pose | None, robot: _Robot | None
    ) -> tuple[Any, ...]:
        x, y, theta = (pose.x, pose.y, pose.theta) if pose is not None else (NAN, NAN, NAN)
        status = robot.current if robot is not None else None
        if robot is None or status is None:
            return (tick, t, robot_id, x, y, theta, NONE, 0, NONE, NONE, NAN, NAN, NAN, NONE, 0)
        lead, p_lead, p_best, bits = robot.derived
        return (
            tick,
            t,
            robot_id,
            x,
            y,
            theta,
            PHASE_CODE.get(status.phase, NONE),
            status.trips,
            NONE if status.decided_site is None else status.decided_site,
            lead,
            p_lead,
            p_best,
            bits,
            status.pool_size if status.poolings else NONE,
            status.poolings,
        )

    def _swarm_row(
        self, tick: int, t: float, robots: list[_Robot], pooled: list[int]
    ) -> tuple[Any, ...]:
        count = len(robots)
        statuses = [robot.current for robot in robots if robot.current is not None]
        shares = [NAN] * self.sites
        if count:
            for site in range(self.sites):
                shares[site] = (
                    math.fsum(s.opinion[site] for s in statuses if site < len(s.opinion)) / count
                )
        return (
            tick,
            t,
            count,
            sum(1 for s in statuses if s.decided_site is not None),
            math.fsum(robot.derived[3] for robot in robots) / count if count else NAN,
            math.fsum(robot.derived[2] for robot in robots) / count
            if count and self.best_site is not None
            else NAN,
            len(pooled),
            math.fsum(pooled) / len(pooled) if pooled else NAN,
            *shares,
        )


def swarm_sample(row: Sequence[Any]) -> SwarmSample:
    """A swarm row as the message a recording and Foxglove carry (NaN as null)."""

    def number(value: float) -> float | None:
        return None if math.isnan(value) else value

    tick, t, robots, decided, entropy_mean, p_best_mean, poolings, pool_mean, *shares = row
    return SwarmSample(
        tick=tick,
        t=t,
        robots=robots,
        decided=decided,
        entropy_mean=number(entropy_mean),
        p_best_mean=number(p_best_mean),
        poolings=poolings,
        pool_size_mean=number(pool_mean),
        shares=[0.0 if math.isnan(share) else share for share in shares],
    )


# --- rows kept as columns ----------------------------------------------------------------


class Table:
    """Rows kept as typed columns (8 bytes a value, 1 for a phase), for a DataFrame."""

    def __init__(self, columns: Sequence[tuple[str, str]]) -> None:
        self.columns = tuple(columns)
        self.values: list[array[Any]] = [
            array("b") if kind == "p" else array("q") if kind == "i" else array("d")
            for _, kind in self.columns
        ]

    def extend(self, rows: Iterable[Sequence[Any]]) -> None:
        appenders = [column.append for column in self.values]
        for row in rows:
            for append, value in zip(appenders, row, strict=True):
                append(value)

    def __len__(self) -> int:
        return len(self.values[0]) if self.values else 0

    @property
    def nbytes(self) -> int:
        return sum(column.itemsize * len(column) for column in self.values)

    def dataframe(self, run_id: str | None = None) -> Any:
        """A pandas DataFrame (pandas is the ``analysis`` extra): integer columns with
        missing values as pandas' nullable integers, phases as a categorical."""
        try:
            import numpy
            import pandas
        except ImportError:
            raise ImportError(
                "a run's frame as a DataFrame needs pandas: pip install 'bestofn-swarm[analysis]'"
            ) from None
        data: dict[str, Any] = {}
        for (name, kind), column in zip(self.columns, self.values, strict=True):
            # The columns' own memory, not a copy (a Table is handed over to its frame).
            values = numpy.frombuffer(column, dtype=DTYPES[column.typecode])
            if kind == "p":
                data[name] = pandas.Categorical.from_codes(values, categories=list(PHASES))
            elif kind == "i" and name in NULLABLE:
                data[name] = pandas.arrays.IntegerArray(values, values == NONE)
            else:
                data[name] = values
        frame = pandas.DataFrame(data)
        if run_id is not None:
            frame.insert(0, "run_id", run_id)
        return frame


DTYPES = {"b": "int8", "q": "int64", "d": "float64"}
# Integer columns where -1 means "none" (the rest are counts and ids, never missing).
NULLABLE = frozenset({"decided_site", "leading_site", "pool_size"})


def text_cell(kind: str, value: Any) -> str:
    """A value as a CSV cell: empty for none; floats exactly (``repr``)."""
    if kind == "p":
        return "" if value == NONE else PHASES[value]
    if kind == "i":
        return "" if value == NONE else str(value)
    return "" if math.isnan(value) else repr(value)


__all__ = [
    "PHASES",
    "ROBOT_COLUMNS",
    "FrameCollector",
    "SwarmSample",
    "Table",
    "entropy",
    "swarm_columns",
    "swarm_sample",
    "text_cell",
]
