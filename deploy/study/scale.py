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
import math
import statistics
from pathlib import Path
from typing import Any

import numpy as np

from deploy.analysis import effects
from deploy.analysis.prose import Claim
from deploy.analysis.wilson import share
from deploy.study import results, tables
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
    """One line per swarm size: runs in consensus and right (each with its 95% interval),
    sim time to consensus (its median's 95% interval), wall time."""
    lines = [
        "| robots | runs | consensus (95% interval) | correct (95% interval) | sim time to "
        "consensus, median (95% interval); max, s | wall time, median (max) s |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run["robots"] for run in runs}):
        group = [run for run in runs if run["robots"] == robots]
        times = [run["sim_time_s"] for run in group if run["consensus"]]
        walls = [run["wall_s"] for run in group]
        lines.append(
            f"| {robots} | {len(group)} | {share(sum(r['consensus'] for r in group), len(group))} "
            f"| {share(sum(r['correct'] for r in group), len(group))} | {_median_time(times)} "
            f"| {statistics.median(walls):.0f} ({max(walls):.0f}) |"
        )
    return "\n".join(lines)


def _median_time(times: list[float]) -> str:
    if not times:
        return "-"
    found = effects.median_interval(times)
    middle = (
        f"{statistics.median(times):.0f} ({tables.counting(len(times), 'run', 'runs')}: "
        "too few for an interval)"
        if found is None
        else f"{found.value:.0f} ({found.low:.0f}-{found.high:.0f})"
    )
    return f"{middle}; {max(times):.0f}"


def fit(runs: list[dict[str, Any]]) -> effects.PowerLaw | None:
    """Sim time to consensus against swarm size, every run in consensus a point."""
    finished = [run for run in runs if run["consensus"]]
    return effects.power_law(
        [float(run["robots"]) for run in finished], [run["sim_time_s"] for run in finished]
    )


def fit_sentence(runs: list[dict[str, Any]]) -> str:
    """How consensus time grows with the swarm: the power law fitted to the runs."""
    found = fit(runs)
    if found is None:
        return "No fit of time against size yet: it needs runs of two sizes in consensus."
    sizes = sorted({run["robots"] for run in runs if run["consensus"]})
    left_out = sum(not run["consensus"] for run in runs)
    exponent, doubling = found.exponent, found.doubling
    return (
        f"Sim time to consensus grows as a power of the swarm's size: fitted by least squares "
        f"on log time against log size over the {found.runs} runs in consensus "
        f"({sizes[0]} to {sizes[-1]} robots"
        + (f"; {left_out} without consensus left out" if left_out else "")
        + f"), time ≈ {found.scale.value:.1f} s × N^{exponent.value:.2f}, the exponent "
        f"{exponent.value:.2f} (95% interval {effects.outwards(exponent.low, exponent.high, 2)}"
        f", runs of each size resampled; R² = {found.r2:.2f} on log-log axes): doubling the "
        f"swarm multiplies the time by {doubling.value:.2f} "
        f"({effects.outwards(doubling.low, doubling.high, 2)})."
    )


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


def _time_or_gave_up(run: dict[str, Any]) -> float:
    """A run's sim time, ``inf`` for a run given up (slower than any finished run)."""
    return float(run["sim_time_s"]) if run["consensus"] else math.inf


def _median_cell(group: list[dict[str, Any]]) -> str:
    times = sorted(_time_or_gave_up(run) for run in group)
    middle = statistics.median(times)
    if math.isinf(middle):
        return "gave up"
    return f"{middle:.0f}"


def before_block(records: Records, root: Path) -> str:
    """The same sizes and seeds before and after: consensus, sim time, wall time, and how
    likely a run after is faster than one before (the Vargha-Delaney A; a run given up is
    slower than any that finished)."""
    before = load_before(root)
    after = engine_runs(records, "inprocess")
    lines = [
        "| robots | seeds | consensus before (95% interval) | consensus after | sim time "
        "before, median (s) | after | a run after faster than one before: A (95% interval) | "
        "wall time before, total (s) | after | wall time after over before: ratio of medians "
        "(95% interval) |",
        "|---:|:---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run["robots"] for run in after}):
        seeds = sorted({run["seed"] for run in after if run["robots"] == robots})
        old = [run for run in before if run["robots"] == robots and run["seed"] in seeds]
        new = [run for run in after if run["robots"] == robots]
        if len(old) != len(new):
            continue
        faster = effects.a_faster(
            [_time_or_gave_up(run) for run in new], [_time_or_gave_up(run) for run in old]
        )
        walls = tables.compare_times(  # unpaired: a seed's run differs before and after
            [run["wall_s"] for run in new], [run["wall_s"] for run in old], ("run", "runs")
        )
        lines.append(
            f"| {robots} | {seeds[0]}-{seeds[-1]} | "
            f"{share(sum(r['consensus'] for r in old), len(old))} | "
            f"{share(sum(r['consensus'] for r in new), len(new))} | {_median_cell(old)} "
            f"| {_median_cell(new)} | {effects.estimate_text(faster)} "
            f"| {sum(r['wall_s'] for r in old):.0f} | {sum(r['wall_s'] for r in new):.0f} "
            f"| {walls} |"
        )
    return "\n".join(lines) + "\n\n" + HEADER + "\n" + "\n".join(row(run) for run in before)


def page_blocks(records: Records) -> dict[str, str]:
    in_process = engine_runs(records, "inprocess")
    return {
        "per-size": per_size(in_process),
        "fit": fit_sentence(in_process),
        "unfinished": unfinished(in_process),
        "runs": HEADER + "\n" + "\n".join(row(run) for run in in_process),
        "zenoh": zenoh_block(records),
        "before": before_block(records, records.root),
    }


def claims(records: Records) -> list[Claim]:
    """The numbers of the page's text that the runs give."""
    by_key = {record["key"]: record for record in records.runs}
    recorded = by_key.get("engine=zenoh robots=1000 seed=0")
    twin = by_key.get("engine=inprocess robots=1000 seed=0")
    found = []
    if recorded is not None and twin is not None:
        digest = tables.result(recorded)["digest"]
        same = digest == tables.result(twin)["digest"]
        found.append(
            Claim(
                (
                    "is the in-process run of the same seed, bit for bit (the same digest, "
                    f"`{digest}`)"
                    if same
                    else "is not the in-process run of the same seed"
                )
                + ": 20 robot processes of 50 robots, the world, the beacon and the recorder, "
                "{} times faster than real time on the 2-core machine. Its recording ({} GB)",
                (
                    f"{tables.result(recorded)['sim_time_s'] / recorded['wall_s']:.1f}",
                    f"{recorded['recording']['bytes'] / 1e9:.1f}",
                ),
            )
        )
    commits = results.made_with(list(records.runs))
    if len(commits) == 2:
        (most, _), (fewest, count) = commits.items()
        odd = [record for record in records.runs if record.get("commit") == fewest]
        sizes = sorted({record["params"]["robots"] for record in odd})
        seeds = [record["seed"] for record in odd]
        words = {1: "One run", 2: "Two runs", 3: "Three runs"}
        found.append(
            Claim(
                f"{words.get(count, f'{count} runs')} ({', '.join(map(str, sizes))} robots, "
                f"{tables.seeds(seeds)}) were made at commit {fewest}, with the lock of that "
                f"time; every other run at {most}.",
                (),
            )
        )
    first = by_key.get("engine=inprocess robots=500 seed=0")
    if first is not None:
        found.append(
            Claim(
                f"gives the same run (digest `{tables.result(first)['digest']}`, {{}} s).",
                (f"{tables.result(first)['sim_time_s']:.1f}",),
            )
        )
    return found


def plot(records: Records, path: Path) -> None:
    """Every run's sim time to consensus against the swarm's size (log-log), each size's
    median with its 95% interval, and the power law fitted to the runs with its band."""
    plt = tables.pyplot()
    runs = engine_runs(records, "inprocess")
    figure, axis = plt.subplots(figsize=(7, 4.6))
    sizes = sorted({run["robots"] for run in runs})
    for size in sizes:
        times = [r["sim_time_s"] for r in runs if r["robots"] == size and r["consensus"]]
        axis.plot([size] * len(times), times, "o", color="tab:blue", alpha=0.4, ms=4)
        found = effects.median_interval(times)
        if found is not None:
            axis.errorbar(
                [size * 1.12], [found.value], yerr=[[found.value - found.low],
                [found.high - found.value]], fmt="s", color="black", capsize=3, ms=4,
            )  # fmt: skip
        failed = [run for run in runs if run["robots"] == size and not run["consensus"]]
        if failed:
            axis.annotate(
                f"{len(failed)} without\nconsensus", (size, axis.get_ylim()[0]), ha="center",
                va="bottom", color="red", fontsize=8,
            )  # fmt: skip
    found_fit = fit(runs)
    if found_fit is not None:
        line = np.geomspace(min(sizes), max(sizes), 60)
        central, low, high = found_fit.curve(line.tolist())
        exponent = found_fit.exponent
        axis.plot(
            line, central, "-", color="tab:red",
            label=f"fit: time ∝ N^{exponent.value:.2f} "
            f"({effects.outwards(exponent.low, exponent.high, 2)})",
        )  # fmt: skip
        axis.fill_between(line, low, high, color="tab:red", alpha=0.2, label="fit's 95% band")
    if not runs:
        tables.no_runs_yet(axis)
    axis.plot([], [], "o", color="tab:blue", alpha=0.4, ms=4, label="a run (seed)")
    axis.errorbar([], [], yerr=[], fmt="s", color="black", capsize=3, ms=4,
                  label=f"median, 95% interval (none under {effects.MIN_RUNS} runs)")  # fmt: skip
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xticks(
        sizes or sorted(IN_PROCESS), [str(size) for size in sizes or sorted(IN_PROCESS)]
    )
    axis.minorticks_off()
    shown = [r["sim_time_s"] for r in runs if r["consensus"]]
    if shown:
        steps = [100, 200, 500, 1000, 2000, 5000, 10000]
        marks = [mark for mark in steps if min(shown) / 1.5 <= mark <= max(shown) * 1.5]
        axis.set_yticks(marks, [str(mark) for mark in marks])
    axis.set_xlabel("robots (10 sites; arena and nest grow with the swarm)")
    axis.set_ylabel("sim time to consensus (s)")
    axis.set_title("When the last robot decided, per seed, and how it grows with the swarm")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=8, loc="upper left")
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
        Page("docs/scale.md", page_blocks, claims=claims),
        Page(
            "README.md",
            lambda records: {"per-size": per_size(engine_runs(records, "inprocess"))},
            made=False,
        ),
    ),
    outputs=(Output("docs/scale.png", plot),),
    kinds=lambda run: "in one process" if run.kind == "inprocess" else "over Zenoh",
)
