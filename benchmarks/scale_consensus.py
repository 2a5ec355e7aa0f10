"""Do large swarms reach consensus? Sim time to consensus against swarm size.

Runs whole lockstep swarms (10 sites, default settings) to consensus or ``--timeout`` sim
seconds, one run per (size, seed), and prints per run: consensus, correct, the sim time
at which the last robot decided, the wall time, the slowest robot's steps (the most
pooling rounds any robot needed before it decided) and how many robots were left
undecided. By default each run is in one process (``deploy.inprocess.engine.run_in_process``: the
same world, controllers and beacon as ``swarm run``, and the same per-robot results);
``--parallel K`` runs K of them at once. ``--zenoh`` runs the given sizes and seeds
through real processes instead: ``swarm run --json --no-record --quiet`` (hosting
``--robots-per-process`` robots per process above 50 robots).

``--save FILE`` keeps the results (JSON), ``--load FILE...`` adds earlier ones (a later
run of the same size and seed replaces an earlier one), and ``--doc`` writes docs/scale.md
with the tables and a box plot of sim time to consensus against swarm size
(docs/scale.png), and README's per-size table; ``--before FILE`` adds a before/after table
from the results of another checkout (the code before the large-swarm fixes, parking lanes
and long legs, run with this script). The commands that made docs/scale.md are listed there
(``COMMANDS``).

    .venv/bin/python benchmarks/scale_consensus.py --parallel 2          # the whole plan
    .venv/bin/python benchmarks/scale_consensus.py --sizes 200 --seeds 8 --zenoh

Sim times are exact (lockstep is deterministic); wall times depend on the machine and on
what else runs on it.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import shlex
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.reports import pages  # noqa: E402

SITES = 10
# The whole plan: ten seeds of every size up to 500 robots, three of 1000.
DEFAULT_PLAN = {
    10: range(10),
    50: range(10),
    100: range(10),
    200: range(10),
    500: range(10),
    1000: range(3),
}
# What docs/scale.md publishes at least: ten seeds up to 200 robots and three of 500; the
# whole plan's further 500- and 1000-robot seeds join them as their runs finish.
PUBLISHED_PLAN = {10: range(10), 50: range(10), 100: range(10), 200: range(10), 500: range(3)}
DEFAULT_TIMEOUT = 6000.0  # sim seconds: well beyond the slowest run of the plan
ROBOTS_PER_PROCESS = 50  # --zenoh: hosted robots per process above this swarm size
ZENOH_STALL_TIMEOUT = 300.0  # --zenoh: wall seconds the world waits for a silent robot


@dataclass(frozen=True)
class Run:
    """One run's result (a row of the table)."""

    robots: int
    seed: int
    mode: str  # "in-process" or "zenoh"
    consensus: bool
    correct: bool
    sim_time_s: float  # when the last robot decided, or when the run was given up
    wall_time_s: float
    slowest_steps: int | None  # most pooling rounds any robot needed to decide
    undecided: int
    timed_out: bool
    stalls: int = 0  # lockstep ticks closed without a silent controller (Zenoh only)
    ended: str = ""  # the summary's ending: consensus, split, stalled, timeout, ...
    departures: int = 0  # robots whose liveliness went mid-run (Zenoh only; breaks lockstep)


def from_summary(robots: int, seed: int, mode: str, summary: dict[str, Any], wall: float) -> Run:
    steps = [robot["steps"] for robot in summary["per_robot"] if robot["steps"] is not None]
    return Run(
        robots=robots,
        seed=seed,
        mode=mode,
        consensus=bool(summary["consensus"]),
        correct=bool(summary["correct"]),
        sim_time_s=float(summary["sim_time_s"]),
        wall_time_s=round(wall, 1),
        slowest_steps=max(steps) if steps else None,
        undecided=sum(robot["decided_site"] is None for robot in summary["per_robot"]),
        timed_out=bool(summary["timed_out"]),
        stalls=int(summary["world"]["stalls"]),
        ended=str(summary.get("ended", "")),
        departures=int(summary["world"].get("departures", 0)),
    )


def run_in_process(task: tuple[int, int, float]) -> Run:
    """One lockstep run in this process (a worker of the pool)."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.core.controller import ControllerConfig
    from world_server.core.world import WorldConfig

    robots, seed, timeout = task
    started = time.perf_counter()
    summary = run_in_process(
        WorldConfig(num_robots=robots, num_sites=SITES, seed=seed),
        ControllerConfig(),
        timeout=timeout,
    )
    return from_summary(robots, seed, "in-process", summary, time.perf_counter() - started)


def zenoh_command(robots: int, seed: int, timeout: float) -> list[str]:
    command = [
        str(REPO / ".venv" / "bin" / "swarm"),
        "run",
        "--robots",
        str(robots),
        "--sites",
        str(SITES),
        "--seed",
        str(seed),
        "--timeout",
        str(timeout),
        "--json",
        "--no-record",
        "--quiet",
        # A shared machine can starve a robot process for seconds; waiting for it keeps the
        # run in lockstep, so its results equal the in-process ones.
        "--stall-timeout",
        str(ZENOH_STALL_TIMEOUT),
    ]
    if robots > ROBOTS_PER_PROCESS:
        command += ["--robots-per-process", str(ROBOTS_PER_PROCESS)]
    return command


def run_over_zenoh(robots: int, seed: int, timeout: float) -> Run:
    """One run with real processes (``swarm run``), one at a time."""
    command = zenoh_command(robots, seed, timeout)
    print("  $", shlex.join(["swarm", *command[1:]]), file=sys.stderr, flush=True)
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=REPO)
    wall = time.perf_counter() - started
    if not done.stdout.strip():
        raise RuntimeError(f"swarm run printed no summary (exit {done.returncode}):\n{done.stderr}")
    return from_summary(robots, seed, "zenoh", json.loads(done.stdout), wall)


def run_plan(plan: dict[int, Sequence[int]], timeout: float, parallel: int) -> list[Run]:
    # Largest first, so the longest runs do not end up alone at the end of the pool.
    tasks = [
        (robots, seed, timeout) for robots in sorted(plan, reverse=True) for seed in plan[robots]
    ]
    runs: list[Run] = []
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, parallel)) as pool:
        futures = [pool.submit(run_in_process, task) for task in tasks]
        for future in concurrent.futures.as_completed(futures):
            run = future.result()
            runs.append(run)
            print(row(run), file=sys.stderr, flush=True)
    return sorted(runs, key=lambda run: (run.robots, run.seed))


# --- tables and figure ---------------------------------------------------------------

HEADER = (
    "| robots | seed | consensus | correct | sim time (s) | wall time (s) | slowest robot's "
    "steps | undecided |\n|---:|---:|:---:|:---:|---:|---:|---:|---:|"
)


def yes(value: bool) -> str:
    return "yes" if value else "**no**"


def row(run: Run) -> str:
    sim = f"{run.sim_time_s:.1f}" + (f" ({run.ended or 'gave up'})" if not run.consensus else "")
    steps = "-" if run.slowest_steps is None else str(run.slowest_steps)
    return (
        f"| {run.robots} | {run.seed} | {yes(run.consensus)} | {yes(run.correct)} | {sim} | "
        f"{run.wall_time_s:.0f} | {steps} | {run.undecided} |"
    )


def per_size(runs: Sequence[Run]) -> str:
    """One line per swarm size: runs in consensus, sim time to consensus, wall time."""
    lines = [
        "| robots | runs | consensus | correct | sim time to consensus, median (max) s | "
        "wall time, median (max) s |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run.robots for run in runs}):
        group = [run for run in runs if run.robots == robots]
        times = [run.sim_time_s for run in group if run.consensus]
        walls = [run.wall_time_s for run in group]
        sim = f"{statistics.median(times):.0f} ({max(times):.0f})" if times else "-"
        lines.append(
            f"| {robots} | {len(group)} | {sum(r.consensus for r in group)} | "
            f"{sum(r.correct for r in group)} | {sim} | "
            f"{statistics.median(walls):.0f} ({max(walls):.0f}) |"
        )
    return "\n".join(lines)


def before_after(before: Sequence[Run], after: Sequence[Run]) -> str:
    """The same sizes and seeds, before and after: consensus, slowest sim time, wall time."""
    lines = [
        "| robots | seeds | consensus before | consensus after | slowest sim time before (s) | "
        "slowest sim time after (s) | wall time before, total (s) | wall time after, total (s) |",
        "|---:|:---|---:|---:|---:|---:|---:|---:|",
    ]
    for robots in sorted({run.robots for run in after}):
        seeds = sorted({run.seed for run in after if run.robots == robots})
        old = [run for run in before if run.robots == robots and run.seed in seeds]
        new = [run for run in after if run.robots == robots]
        if len(old) != len(new):
            continue

        lines.append(
            f"| {robots} | {seeds[0]}-{seeds[-1]} | {sum(r.consensus for r in old)}/{len(old)} | "
            f"{sum(r.consensus for r in new)}/{len(new)} | {slowest(old)} | {slowest(new)} | "
            f"{sum(r.wall_time_s for r in old):.0f} | {sum(r.wall_time_s for r in new):.0f} |"
        )
    return "\n".join(lines)


def zenoh_against_in_process(zenoh: Sequence[Run], in_process: Sequence[Run]) -> str:
    """Each Zenoh run beside the in-process run of the same size and seed."""
    lines = [
        "| robots | seed | sim time in one process (s) | over Zenoh (s) | slowest steps, "
        "in one process / over Zenoh | same result | lockstep stalls | departures |",
        "|---:|---:|---:|---:|---:|:---:|---:|---:|",
    ]
    twins = {(run.robots, run.seed): run for run in in_process}
    for run in zenoh:
        twin = twins.get((run.robots, run.seed))
        if twin is None:
            continue
        same = (twin.sim_time_s, twin.slowest_steps, twin.consensus, twin.correct) == (
            run.sim_time_s,
            run.slowest_steps,
            run.consensus,
            run.correct,
        )
        lines.append(
            f"| {run.robots} | {run.seed} | {twin.sim_time_s:.1f} | {run.sim_time_s:.1f} | "
            f"{twin.slowest_steps} / {run.slowest_steps} | {yes(same)} | {run.stalls} | "
            f"{run.departures} |"
        )
    return "\n".join(lines)


def slowest(group: Sequence[Run]) -> str:
    """The sim time of the slowest run of ``group``, marked if it never reached consensus."""
    worst = max(group, key=lambda run: run.sim_time_s)
    return f"{worst.sim_time_s:.0f}" + (" (gave up)" if not worst.consensus else "")


def plot(runs: Sequence[Run], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({run.robots for run in runs})
    fig, ax = plt.subplots(figsize=(7, 4.2))
    data = [
        [run.sim_time_s for run in runs if run.robots == size and run.consensus] for size in sizes
    ]
    filled = [index for index, times in enumerate(data, start=1) if times]
    ax.boxplot([data[index - 1] for index in filled], positions=filled, whis=(0, 100))
    ax.set_xticks(range(1, len(sizes) + 1), [str(size) for size in sizes])
    for index, (size, times) in enumerate(zip(sizes, data, strict=True), start=1):
        ax.plot([index] * len(times), times, "o", color="tab:blue", alpha=0.5, ms=4)
        failed = [run for run in runs if run.robots == size and not run.consensus]
        if failed:
            ax.annotate(
                f"{len(failed)} without\nconsensus",
                (index, 0),
                ha="center",
                va="bottom",
                color="red",
                fontsize=8,
            )
    ax.set_xlabel("robots (10 sites; arena and nest grow with the swarm)")
    ax.set_ylabel("sim time to consensus (s)")
    ax.set_title("When the last robot decided, per seed (box: quartiles, whiskers: range)")
    ax.set_ylim(bottom=0)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


RUNS_FILE = "docs/scale-runs.json"
BEFORE_FILE = "docs/scale-before.json"
COMMANDS = f"""\
# sizes 10 to 200, seeds 0-9, in one process, one at a time
.venv/bin/python benchmarks/scale_consensus.py --sizes 10 50 100 200 \\
    --seeds 0 1 2 3 4 5 6 7 8 9 --save small.json
# 500 robots seeds 0-9 and 1000 robots seeds 0-2, one run per command (niced, on a
# core of its own), each given up at 12000 s of sim time
.venv/bin/python benchmarks/scale_consensus.py --sizes 500 --seeds 0 --timeout 12000 \\
    --save r500-s0.json                   # and so on, for seeds 1 to 9
.venv/bin/python benchmarks/scale_consensus.py --sizes 1000 --seeds 0 --timeout 12000 \\
    --save r1000-s0.json                  # and so on, for seeds 1 and 2
# over Zenoh (swarm run): seed 0 of each size, one run at a time
.venv/bin/python benchmarks/scale_consensus.py --zenoh --sizes 10 50 100 200 --seeds 0 \\
    --save zenoh.json
# all together: the results file, this page, its figure and README's table
.venv/bin/python benchmarks/scale_consensus.py --no-run \\
    --load small.json r500-s*.json r1000-s*.json zenoh*.json \\
    --save {RUNS_FILE} --before {BEFORE_FILE} --doc"""


def render_doc(runs: Sequence[Run], before: Sequence[Run], figure: str) -> str:
    """docs/scale.md for these results (the figure is written separately)."""
    in_process = [run for run in runs if run.mode == "in-process"]
    zenoh = [run for run in runs if run.mode == "zenoh"]
    parts = [
        "# Large swarms\n",
        "How long a swarm takes to agree, against its size: 10 sites, default settings "
        "(alpha = 0, MProdOp, threshold 1), lockstep; the arena and the nest grow with the "
        "swarm (`world_server/core/layout.py`). Made by `benchmarks/scale_consensus.py`:\n",
        f"```\n{COMMANDS}\n```\n",
        "Sim times are exact: a lockstep run is deterministic, in one process or over "
        "Zenoh, on every CPU `make check-portable` checks (the portable kernel, "
        "[kernel.md](kernel.md)). Wall times are "
        "indicative only: the machine (2 cores) ran other work beside these runs. "
        "`tests/test_scale_doc.py` checks that this page is what the results file gives; "
        "`make check-published` (`pytest --published`, which CI runs) runs 10 robots seeds "
        "0 and 7, 50 robots seed 3 and 100 robots seed 3 again and fails if they differ "
        "from the file.\n",
        f"![sim time to consensus against swarm size]({figure})\n",
        "## Per swarm size (in one process)\n",
        per_size(in_process) + "\n",
        "Sim time to consensus is when the last robot decided; steps are pooling rounds "
        "(trips home) a robot needed before it decided.\n",
        *unfinished_note(in_process),
        "## Every run (in one process)\n",
        HEADER + "\n" + "\n".join(row(run) for run in in_process) + "\n",
    ]
    if zenoh:
        parts += [
            "## Over Zenoh\n",
            "The same runs with real processes, one at a time: `swarm run --json --no-record "
            f"--stall-timeout {ZENOH_STALL_TIMEOUT:g}`, with `--robots-per-process "
            f"{ROBOTS_PER_PROCESS}` above {ROBOTS_PER_PROCESS} robots. The long stall timeout "
            "keeps the world waiting for a robot process the busy machine starved, so the "
            "run stays in lockstep (lockstep stalls: ticks closed without a robot). A lockstep "
            "run should give the same sim time and steps as in one process; the last table "
            "says where it did. Departures are robots whose liveliness token went while the "
            "world ran (the summary's `world.departures`): the world takes such a robot out "
            "of the tick at once, so a run with any is no longer the seed's lockstep run.\n",
            HEADER + "\n" + "\n".join(row(run) for run in zenoh) + "\n",
            zenoh_against_in_process(zenoh, in_process) + "\n",
        ]
    if before:
        parts += [
            "## Before and after the large-swarm fixes\n",
            "Before: the code before the fixes (parking rings a body length apart, and a "
            "fixed 120 s for any leg), the same script and seeds, runs given up at 3000 s of "
            "sim time. The causes and the fixes (parking lanes, long legs) are in "
            "[history.md](history.md#large-swarms-that-did-not-finish). The before runs were "
            "made with the numeric kernel of their time, before the portable one, so a seed's "
            "run differs in detail from today's; compare the sizes, not the seeds.\n",
            before_after(before, in_process) + "\n",
            HEADER + "\n" + "\n".join(row(run) for run in before) + "\n",
        ]
    return "\n".join(parts)


def unfinished_note(runs: Sequence[Run]) -> list[str]:
    """A pointer to why, when a run of the plan did not end in consensus."""
    unfinished = [run for run in runs if not run.consensus]
    if not unfinished:
        return []
    which = ", ".join(
        f"{run.robots} robots seed {run.seed} ({run.ended or 'gave up'}, {run.undecided} undecided)"
        for run in unfinished
    )
    return [
        f"**Not every run ended in consensus**: {which}. What held the last robots of "
        "earlier runs, and how it was found, is in "
        "[history.md](history.md#large-swarms-that-did-not-finish); a run listed here "
        "that history.md does not explain is not explained yet, and "
        "`benchmarks/stall_diagnosis.py --robots N --seed S --until T --plot FILE` shows "
        "where its undecided robots are and what holds them.\n"
    ]


def write_doc(runs: Sequence[Run], before: Sequence[Run], path: Path) -> None:
    figure = path.with_suffix(".png")
    plot([run for run in runs if run.mode == "in-process"], figure)
    path.write_text(render_doc(runs, before, figure.name))
    print(f"wrote {path} and {figure}", file=sys.stderr)


def load_runs(path: Path) -> list[Run]:
    return [Run(**item) for item in json.loads(path.read_text())]


def merged(runs: Sequence[Run]) -> list[Run]:
    """One run per (mode, size, seed): a later one (of a later --load file, or run now)
    replaces an earlier one, so a results file can be loaded and saved over with more."""
    latest = {(run.mode, run.robots, run.seed): run for run in runs}
    return sorted(latest.values(), key=lambda run: (run.mode, run.robots, run.seed))


README = "README.md"
README_BEGIN = "<!-- scale_consensus:per-size -->"
README_END = "<!-- /scale_consensus:per-size -->"


def readme_block(runs: Sequence[Run]) -> str:
    """README's table: the per-size table of docs/scale.md, in one process."""
    return per_size([run for run in runs if run.mode == "in-process"])


def write_readme(runs: Sequence[Run], path: Path) -> None:
    """Replace the table between README's markers with the one these runs give."""
    pages.write_between(path, README_BEGIN, README_END, readme_block(runs))
    print(f"wrote the table of {path}", file=sys.stderr)


# --- command line --------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", help="swarm sizes (default: the plan)")
    parser.add_argument("--seeds", type=int, nargs="+", help="seeds for every size given")
    parser.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, help="sim seconds")
    parser.add_argument("--parallel", type=int, default=1, help="runs at once (in-process)")
    parser.add_argument("--zenoh", action="store_true", help="real processes (swarm run)")
    parser.add_argument("--save", type=Path, help="write the results here (JSON)")
    parser.add_argument("--load", type=Path, nargs="+", default=[], help="results to add")
    parser.add_argument("--before", type=Path, help="results of the code before the fix")
    parser.add_argument(
        "--doc", action="store_true", help="write docs/scale.md and .png, and README's table"
    )
    parser.add_argument("--no-run", action="store_true", help="only --load, no new runs")
    args = parser.parse_args(argv)

    if args.sizes:
        plan = {size: args.seeds if args.seeds is not None else range(3) for size in args.sizes}
    else:
        plan = DEFAULT_PLAN
    runs = [run for file in args.load for run in load_runs(file)]
    if not args.no_run:
        if args.zenoh:
            for robots in sorted(plan):
                for seed in plan[robots]:
                    run = run_over_zenoh(robots, seed, args.timeout)
                    print(row(run), file=sys.stderr, flush=True)
                    runs.append(run)
        else:
            runs += run_plan(plan, args.timeout, args.parallel)
    runs = merged(runs)
    print(HEADER)
    for run in runs:
        print(row(run) + ("" if run.mode == "in-process" else " (zenoh)"))
    print()
    print(per_size([run for run in runs if run.mode == "in-process"]))
    if args.save:
        args.save.write_text(json.dumps([asdict(run) for run in runs], indent=1))
    before = load_runs(args.before) if args.before else []
    if before:
        print()
        print(before_after(before, [run for run in runs if run.mode == "in-process"]))
    if args.doc:
        write_doc(runs, before, REPO / "docs" / "scale.md")
        write_readme(runs, REPO / README)
    if any(not math.isfinite(run.sim_time_s) for run in runs):
        raise SystemExit("a run reported a non-finite sim time")


if __name__ == "__main__":
    main()
