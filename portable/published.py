"""Which runs ``make check-portable`` runs, and what the published files say about each.

A *job* is one thing a probe computes (portable/probe.py): a published run, made again by
the very function that made it for its file, or a result that no file publishes but that
must not depend on the CPU (a run with camera noise and radio loss, the numeric kernel on
a grid of inputs). Its *record* is what the job gives in the form its published file
holds it, wall times left out (they are the machine's, not the code's).

The runs checked are ``FIXED`` (every part of what shapes a run: both Section 5 variants,
a 50-robot swarm, a rival strategy with loss, camera noise with loss, the Section 4
model's ``--exact`` table, the kernel) and a sample of the other published runs, drawn by
``sample`` from a seed: the same seed, the same runs.
"""

from __future__ import annotations

import json
import random
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent

SECTION5_FILE = REPO / "docs" / "section5-runs.json"
STUDIES = REPO / "docs" / "studies"  # the studies' results files (swarm study, docs/studies.md)
WELLSTIRRED_PAGE = REPO / "docs" / "wellstirred.md"
# The kinds of a study's runs a probe makes in its own process (a run over Zenoh starts
# processes, which qemu-user would not emulate: it is checked by make check-published).
IN_PROCESS_KINDS = frozenset({"inprocess", "comparisons", "lag", "sensing", "wellstirred"})

# What a record holds that is the machine's, not the code's.
WALL_FIELDS = frozenset({"wall_s", "wall_time_s"})
# The published runs a sample may draw: those whose published wall time (one process on
# the machine that made them) is at most this; emulation is about 15 times slower.
MAX_SAMPLE_SECONDS = 8.0
# A run whose file gives no wall time (Section 5: 10 robots, one to two seconds).
DEFAULT_SECONDS = 2.0

# The run with camera noise and radio loss: its `swarm run` options (in process; no file
# publishes it: compared with this machine's run of it).
NOISE_AND_LOSS_KEY = "run/camera-noise-10/drop-0.3/s0"
NOISE_AND_LOSS = ["--seed", "0", "--camera-noise", "10", "--drop", "0.3"]

FIXED = (
    "section5/default/n8/s44",
    "section5/linger/n10/s51",
    "scale/engine=inprocess robots=50 seed=8",
    "strategies/drop=0.2 part=swarm robots=10 sites=8 strategy=dmmd seed=1",
    NOISE_AND_LOSS_KEY,
    "wellstirred/exact",
    "kernel",
)


@dataclass(frozen=True)
class Job:
    """One thing to compute on every machine, and what is published about it."""

    source: str  # section5, scale, strategies, byzantine, wellstirred, run or kernel
    key: str
    args: dict[str, Any]
    published: Any  # the published record (no wall times), or None if none is published
    seconds: float  # about how long it takes natively

    def spec(self) -> dict[str, Any]:
        """What a probe needs to compute it."""
        return {"source": self.source, "key": self.key, "args": self.args}


def without_wall(record: dict[str, Any]) -> dict[str, Any]:
    return {name: value for name, value in record.items() if name not in WALL_FIELDS}


def _jsonl(path: Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines file; a later record of a key replaces an earlier."""
    by_key: dict[str, dict[str, Any]] = {}
    for line in path.read_text().splitlines():
        if line.strip():
            record = json.loads(line)
            by_key[record["key"]] = record
    return list(by_key.values())


def section5_jobs() -> list[Job]:
    runs = json.loads(SECTION5_FILE.read_text())["runs"]
    return [
        Job(
            "section5",
            f"section5/{run['variant']}/n{run['n']}/s{run['seed']}",
            {"variant": run["variant"], "n": run["n"], "seed": run["seed"]},
            run,
            DEFAULT_SECONDS,
        )
        for run in runs
    ]


def study_jobs(study: str) -> list[Job]:
    """Every run of ``study``'s results file that a probe can make in its own process,
    with the result the file publishes for it."""
    path = STUDIES / f"{study}.jsonl"
    if not path.exists():
        return []
    return [
        Job(
            study,
            f"{study}/{record['key']}",
            {"study": study, "key": record["key"]},
            record["result"],
            float(record.get("wall_s") or DEFAULT_SECONDS),
        )
        for record in _jsonl(path)
        if record.get("kind") in IN_PROCESS_KINDS and "result" in record
    ]


def fixed_study_job(key: str) -> Job:
    """A fixed run of a study that its results file does not hold yet: compared with this
    machine's run of it only."""
    study, _, run_key = key.partition("/")
    return Job(study, key, {"study": study, "key": run_key}, None, 60.0)


def wellstirred_job() -> Job:
    return Job("wellstirred", "wellstirred/exact", {}, figure1_table(), 1.0)


def other_jobs() -> list[Job]:
    """What no file publishes: compared with this machine's own result only."""
    return [
        Job("run", NOISE_AND_LOSS_KEY, {"options": NOISE_AND_LOSS}, None, 2.0),
        Job("kernel", "kernel", {}, None, 3.0),
    ]


# The published files a sample draws from, in turn: Section 5's runs, then each study's.
SOURCES = ("section5", "scale", "strategies", "defence", "byzantine", "robustness",
           "section5-settings")  # fmt: skip


def every_job() -> dict[str, Job]:
    """Every job there is, by key: every published run, and the fixed others."""
    jobs = section5_jobs()
    jobs += [job for study in SOURCES[1:] for job in study_jobs(study)]
    jobs += [wellstirred_job(), *other_jobs()]
    found = {job.key: job for job in jobs}
    for key in FIXED:
        if key not in found and "=" in key:  # a study's run not made yet
            found[key] = fixed_study_job(key)
    return found


def sample(jobs: dict[str, Job], count: int, seed: int, exclude: Iterable[str]) -> list[Job]:
    """``count`` published runs not in ``exclude``, at most ``MAX_SAMPLE_SECONDS`` each,
    from each published file in turn (Section 5, the large swarms, the strategies, the
    defence against liars), each drawn at random, from ``seed``, among that file's."""
    left_out = set(exclude)
    pools = {
        source: sorted(
            key
            for key, job in jobs.items()
            if job.source == source and key not in left_out and job.seconds <= MAX_SAMPLE_SECONDS
        )
        for source in SOURCES
    }
    draw = random.Random(seed)
    chosen: list[Job] = []
    order = [source for source in SOURCES if pools[source]]
    for index in range(count):
        if not order:
            break
        source = order[index % len(order)]
        key = draw.choice(pools[source])
        pools[source].remove(key)
        chosen.append(jobs[key])
        if not pools[source]:
            order.remove(source)
    return chosen


def choose(count: int, seed: int, only: Sequence[str] = (), fixed: bool = True) -> list[Job]:
    """The jobs of a check: the fixed ones (unless not ``fixed``) and a sample of
    ``count``, or exactly the keys of ``only``; KeyError for a key that is no job."""
    jobs = every_job()
    if only:
        return [jobs[key] for key in only]
    return [jobs[key] for key in FIXED if fixed] + sample(jobs, count, seed, FIXED)


# --- the Section 4 model's Figure 1 table (docs/wellstirred.md) ---------------------------

TABLE_HEADER = "| n (n/2) |"


def figure1_table(page: Path = WELLSTIRRED_PAGE) -> list[str]:
    """The lines of the Figure 1 table of docs/wellstirred.md (ValueError if none)."""
    lines = page.read_text().splitlines()
    starts = [index for index, line in enumerate(lines) if line.startswith(TABLE_HEADER)]
    if len(starts) != 1:
        raise ValueError(f"{page}: {len(starts)} tables start with {TABLE_HEADER!r}, not 1")
    table = []
    for line in lines[starts[0] :]:
        if not line.startswith("|"):
            break
        table.append(line)
    return table


def render_figure1(cells: Sequence[dict[str, Any]]) -> list[str]:
    """The Figure 1 table from ``swarm wellstirred --exact --json``'s cells: per n, the
    simulated means (k* in bold) and k*, then the exact means; two decimals."""
    options = sorted({int(cell["options"]) for cell in cells})
    pools = sorted({int(cell["pool"]) for cell in cells})
    by_cell = {(int(cell["options"]), int(cell["pool"])): cell for cell in cells}
    lines = [
        TABLE_HEADER + "".join(f" k={k} |" for k in pools) + " k* |",
        "|---|" + "---:|" * (len(pools) + 1),
    ]
    for n in options:
        half = n / 2
        below = [k for k in pools if by_cell[(n, k)]["mean"] <= half]
        best = min(below) if below else None
        means = [f"{by_cell[(n, k)]['mean']:.2f}" for k in pools]
        shown = [f"**{mean}**" if k == best else mean for k, mean in zip(pools, means, strict=True)]
        lines.append(f"| {n} ({half:g}) | " + " | ".join(shown) + f" | {best or '-'} |")
        exact = [by_cell[(n, k)]["exact_mean"] for k in pools]
        lines.append(
            "| exact | "
            + " | ".join("-" if value is None else f"{value:.2f}" for value in exact)
            + " | |"
        )
    return lines


def published_form(job: Job, record: Any) -> Any:
    """A job's record in the form its published file holds it."""
    if job.source == "wellstirred":
        return render_figure1(record)
    if isinstance(record, dict):
        return without_wall(record)
    return record


def differences(published: Any, now: Any) -> list[str]:
    """What differs between two records, field by field (or line by line). Every field
    the published record has is compared (nested ones too); a field only the fresh record
    has is not, as ``swarm study --check`` does: a run converted from an older results
    file kept fewer fields."""
    if isinstance(published, dict) and isinstance(now, dict):
        from deploy.study import check

        return check.differences(published, now)
    if isinstance(published, list) and isinstance(now, list) and len(published) == len(now):
        return [f"{old} -> {new}" for old, new in zip(published, now, strict=True) if old != new]
    return [] if published == now else [f"{published!r} -> {now!r}"]
