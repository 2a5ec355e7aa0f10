"""The study ``scale``: do large swarms reach consensus? Sim time to consensus against
swarm size (docs/scale.md, and README's per-size table).

10 sites, default settings, lockstep, the arena and the nest growing with the swarm:

* in one process (``engine=inprocess``): 10, 50, 100 and 200 robots, seeds 0-9, given up
  at 6000 sim s; 500 robots seeds 0-9 and 1000 robots seeds 0-2, given up at 12000 sim s;
* over Zenoh with real processes (``engine=zenoh``: ``swarm run``, robots hosted 50 to a
  process above 50 robots, a 300 s stall timeout so that a starved process does not break
  lockstep): seed 0 of 10, 50, 100 and 200 robots, and seed 0 of 1000 robots, recorded
  (``swarm run --record``).

The page also shows runs of the code before the large-swarm fixes, kept in
``docs/scale-before.json`` (they cannot be made again: that code is gone).
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import Any

from deploy.study import tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point

SITES = 10
IN_PROCESS = {
    10: range(10),
    50: range(10),
    100: range(10),
    200: range(10),
    500: range(10),
    1000: range(3),
}
OVER_ZENOH = {10: range(1), 50: range(1), 100: range(1), 200: range(1)}
RECORDED = {1000: range(1)}  # over Zenoh, with a recording
TIMEOUT = {10: 6000.0, 50: 6000.0, 100: 6000.0, 200: 6000.0, 500: 12000.0, 1000: 12000.0}
# Wall seconds a run takes, about, on a shared 2-core machine with the compiled cores: in one
# process, over Zenoh (the means of the published runs, docs/studies/scale.jsonl).
COST = {10: 0.4, 50: 2.9, 100: 12.2, 200: 52.3, 500: 532.0, 1000: 2401.0}
ZENOH_COST = {10: 9.6, 50: 25.9, 100: 40.6, 200: 97.1, 1000: 2466.0}
ZENOH_WALL_LIMIT = 12 * 3600.0
BEFORE_FILE = "docs/scale-before.json"


def options(robots: int) -> list[str]:
    return ["--robots", str(robots), "--sites", str(SITES)]


def points() -> list[Point]:
    found = [
        Point(
            {"engine": "inprocess", "robots": robots},
            seeds,
            options=options(robots),
            timeout=TIMEOUT[robots],
            cost=COST[robots],
        )
        for robots, seeds in IN_PROCESS.items()
    ]
    found += [
        Point(
            {"engine": "zenoh", "robots": robots},
            seeds,
            "zenoh",
            options=options(robots),
            timeout=TIMEOUT[robots],
            cost=ZENOH_COST[robots],
            record=robots in RECORDED,
            # An unattended run of hours over Zenoh is given up after 12 wall hours.
            wall_limit=ZENOH_WALL_LIMIT if robots in RECORDED else None,
        )
        for robots, seeds in {**OVER_ZENOH, **RECORDED}.items()
    ]
    return found


# --- the page ------------------------------------------------------------------------------


def _run(record: dict[str, Any]) -> dict[str, Any]:
    """A record as the tables read it: its result, its size, seed and wall time."""
    return {
        **tables.result(record),
        "robots": record["params"]["robots"],
        "seed": record["seed"],
        "wall_s": record.get("wall_s") or 0.0,
    }


def engine_runs(records: Records, engine: str) -> list[dict[str, Any]]:
    runs = [_run(record) for record in records.runs if record["params"]["engine"] == engine]
    return sorted(runs, key=lambda run: (run["robots"], run["seed"]))


HEADER = (
    "| robots | seed | consensus | correct | sim time (s) | wall time (s) | slowest robot's "
    "steps | undecided |\n|---:|---:|:---:|:---:|---:|---:|---:|---:|"
)


def yes(value: bool) -> str:
    return "yes" if value else "**no**"


def row(run: dict[str, Any]) -> str:
    sim = f"{run['sim_time_s']:.1f}" + (
        f" ({run.get('ended') or 'gave up'})" if not run["consensus"] else ""
    )
    steps = "-" if run["slowest_steps"] is None else str(run["slowest_steps"])
    return (
        f"| {run['robots']} | {run['seed']} | {yes(run['consensus'])} | {yes(run['correct'])} "
        f"| {sim} | {run['wall_s']:.0f} | {steps} | {run['undecided']} |"
    )


def per_size(runs: list[dict[str, Any]]) -> str:
    """One line per swarm size: runs in consensus (with its 95% interval), sim time to
    consensus, wall time."""
    from deploy.analysis.wilson import share

    lines = [
        "| robots | runs | consensus (95% interval) | correct | sim time to consensus, median "
        "(max) s | wall time, median (max) s |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run["robots"] for run in runs}):
        group = [run for run in runs if run["robots"] == robots]
        times = [run["sim_time_s"] for run in group if run["consensus"]]
        walls = [run["wall_s"] for run in group]
        sim = f"{statistics.median(times):.0f} ({max(times):.0f})" if times else "-"
        lines.append(
            f"| {robots} | {len(group)} | {share(sum(r['consensus'] for r in group), len(group))} "
            f"| {sum(r['correct'] for r in group)} | {sim} "
            f"| {statistics.median(walls):.0f} ({max(walls):.0f}) |"
        )
    return "\n".join(lines)


def unfinished(runs: list[dict[str, Any]]) -> str:
    """A pointer to why, when a run did not end in consensus."""
    missed = [run for run in runs if not run["consensus"]]
    if not missed:
        return "Every run here ended in consensus."
    which = ", ".join(
        f"{run['robots']} robots seed {run['seed']} ({run.get('ended') or 'gave up'}, "
        f"{run['undecided']} undecided)"
        for run in missed
    )
    return (
        f"**Not every run ended in consensus**: {which}. What held the last robots of "
        "earlier runs, and how it was found, is in "
        "[history.md](history.md#large-swarms-that-did-not-finish); a run listed here "
        "that history.md does not explain is not explained yet, and "
        "`benchmarks/stall_diagnosis.py --robots N --seed S --until T --plot FILE` shows "
        "where its undecided robots are and what holds them."
    )


def zenoh_against_in_process(zenoh: list[dict[str, Any]], in_process: list[dict[str, Any]]) -> str:
    """Each Zenoh run beside the in-process run of the same size and seed."""
    lines = [
        "| robots | seed | sim time in one process (s) | over Zenoh (s) | slowest steps, "
        "in one process / over Zenoh | same result | lockstep stalls | departures |",
        "|---:|---:|---:|---:|---:|:---:|---:|---:|",
    ]
    twins = {(run["robots"], run["seed"]): run for run in in_process}
    for run in zenoh:
        twin = twins.get((run["robots"], run["seed"]))
        if twin is None:
            continue
        fields = ("sim_time_s", "slowest_steps", "consensus", "correct")
        same = all(twin[name] == run[name] for name in fields)
        lines.append(
            f"| {run['robots']} | {run['seed']} | {twin['sim_time_s']:.1f} | "
            f"{run['sim_time_s']:.1f} "
            f"| {twin['slowest_steps']} / {run['slowest_steps']} | {yes(same)} | {run['stalls']} "
            f"| {run['departures']} |"
        )
    return "\n".join(lines)


def zenoh_block(records: Records) -> str:
    zenoh = engine_runs(records, "zenoh")
    if not zenoh:
        return "No run over Zenoh is made yet."
    parts = [HEADER + "\n" + "\n".join(row(run) for run in zenoh)]
    parts.append(zenoh_against_in_process(zenoh, engine_runs(records, "inprocess")))
    recorded = [
        f"{record['params']['robots']} robots seed {record['seed']}: "
        f"`{record['recording']['path']}` "
        f"({record['recording']['bytes'] / 2**20:.0f} MiB)"
        for record in records.runs
        if record.get("recording")
    ]
    if recorded:
        parts.append("Recorded (`swarm run --record`): " + "; ".join(recorded) + ".")
    return "\n\n".join(parts)


def load_before(root: Path) -> list[dict[str, Any]]:
    """The runs of the code before the large-swarm fixes, as the tables read them."""
    path = root / BEFORE_FILE
    if not path.exists():
        return []
    return [
        {**run, "wall_s": run["wall_time_s"], "stalls": run.get("stalls", 0)}
        for run in json.loads(path.read_text())
    ]


def slowest(group: list[dict[str, Any]]) -> str:
    worst = max(group, key=lambda run: run["sim_time_s"])
    return f"{worst['sim_time_s']:.0f}" + (" (gave up)" if not worst["consensus"] else "")


def before_block(records: Records, root: Path) -> str:
    """The same sizes and seeds before and after: consensus, slowest sim time, wall time."""
    before = load_before(root)
    after = engine_runs(records, "inprocess")
    lines = [
        "| robots | seeds | consensus before | consensus after | slowest sim time before (s) | "
        "slowest sim time after (s) | wall time before, total (s) | wall time after, total (s) |",
        "|---:|:---|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run["robots"] for run in after}):
        seeds = sorted({run["seed"] for run in after if run["robots"] == robots})
        old = [run for run in before if run["robots"] == robots and run["seed"] in seeds]
        new = [run for run in after if run["robots"] == robots]
        if len(old) != len(new):
            continue
        lines.append(
            f"| {robots} | {seeds[0]}-{seeds[-1]} | "
            f"{sum(r['consensus'] for r in old)}/{len(old)} | "
            f"{sum(r['consensus'] for r in new)}/{len(new)} | {slowest(old)} | {slowest(new)} | "
            f"{sum(r['wall_s'] for r in old):.0f} | {sum(r['wall_s'] for r in new):.0f} |"
        )
    return "\n".join(lines) + "\n\n" + HEADER + "\n" + "\n".join(row(run) for run in before)


def page_blocks(records: Records) -> dict[str, str]:
    in_process = engine_runs(records, "inprocess")
    return {
        "per-size": per_size(in_process),
        "unfinished": unfinished(in_process),
        "runs": HEADER + "\n" + "\n".join(row(run) for run in in_process),
        "zenoh": zenoh_block(records),
        "before": before_block(records, records.root),
    }


def plot(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    runs = engine_runs(records, "inprocess")
    sizes = sorted({run["robots"] for run in runs}) or sorted(IN_PROCESS)
    figure, axis = plt.subplots(figsize=(7, 4.2))
    data = [
        [r["sim_time_s"] for r in runs if r["robots"] == size and r["consensus"]] for size in sizes
    ]
    filled = [index for index, times in enumerate(data, start=1) if times]
    if filled:
        axis.boxplot([data[index - 1] for index in filled], positions=filled, whis=(0, 100))
    else:
        tables.no_runs_yet(axis)
    axis.set_xticks(range(1, len(sizes) + 1), [str(size) for size in sizes])
    for index, (size, times) in enumerate(zip(sizes, data, strict=True), start=1):
        axis.plot([index] * len(times), times, "o", color="tab:blue", alpha=0.5, ms=4)
        failed = [run for run in runs if run["robots"] == size and not run["consensus"]]
        if failed:
            axis.annotate(
                f"{len(failed)} without\nconsensus", (index, 0), ha="center", va="bottom",
                color="red", fontsize=8,
            )  # fmt: skip
    axis.set_xlabel("robots (10 sites; arena and nest grow with the swarm)")
    axis.set_ylabel("sim time to consensus (s)")
    axis.set_title("When the last robot decided, per seed (box: quartiles, whiskers: range)")
    axis.set_ylim(bottom=0)
    axis.grid(axis="y", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


STUDY = Study(
    name="scale",
    title="large swarms",
    about="sim time to consensus from 10 to 1000 robots, in one process and over Zenoh",
    points=points,
    source="deploy/study/scale.py",
    pages=(
        Page("docs/scale.md", page_blocks),
        Page(
            "README.md",
            lambda records: {"per-size": per_size(engine_runs(records, "inprocess"))},
            made=False,
        ),
    ),
    outputs=(Output("docs/scale.png", plot),),
)
