"""Robustness of the swarm's decision to radio loss and camera noise.

Sweeps whole lockstep runs in one process each (``deploy.inprocess.engine.run_in_process``: the
same world, controllers and beacon as ``swarm run``, and the same per-robot results), 10
robots and 10 sites by default, several seeds per point. Every point is described by the
command-line options of ``swarm run`` and built through the same parsers, so any point
can be replayed with real processes: ``swarm run --seed S <options> --json``.

* drop sweep: iid radio loss 0, 0.1, ..., 0.8 with the paper's controller (alpha = 0,
  MProdOp). Also answers the 30 % loss claim: drop 0.3 against drop 0, same seeds.
* noise sweep: Gaussian pixel noise (``--camera-noise SIGMA``; ``--lighting`` adds a
  fixed per-site lighting variation to every point) for three controllers: the paper's
  (alpha = 0, MProdOp), distrust (alpha = 0.1, threshold 0.99, MProdOp), and distrust
  with the diluting pool (alpha = 0.1, threshold 0.99, ``--pooling loglinear``).

Accuracy is the fraction of runs in which every robot decided on the best site. Consensus
time is the sim time at which the last robot decided, over the runs that reached a
consensus (right or wrong); a run that does not decide within ``--timeout`` counts as a
failure. Each run also counts its comparisons from ``Controller.comparison`` (what
``Status.comparison`` carries) and how many were wrong against the true qualities.

Prints the tables and writes docs/robustness_drop.png and docs/robustness_noise.png.

    .venv/bin/python benchmarks/robustness.py                 # both sweeps (~5 min on 2 cores)
    .venv/bin/python benchmarks/robustness.py --quick         # fewer levels and seeds
    .venv/bin/python benchmarks/robustness.py --only drop     # or noise
    .venv/bin/python benchmarks/robustness.py --only none --processes   # 30 % claim, real runs

``--processes`` also runs the 30 % loss claim (drop 0 and 0.3, the same seeds) with real
processes, ``swarm run --robots 10 --sites 10 --seed S --drop D --json --no-record
--quiet``, one run at a time, and compares them run by run with the in-memory results.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import itertools
import json
import math
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from robot_agent.core import ports  # noqa: E402
from robot_agent.core.controller import Controller  # noqa: E402
from wire.endings import RESULT_CODES  # noqa: E402
from wire.rng import Stream, seed_of  # noqa: E402

DROP_LEVELS = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]
QUICK_DROP_LEVELS = [0.0, 0.3, 0.6, 0.8]
# Pixel noise: below about 110 the panel's pixel average hides it (runs are nearly always
# identical to noise-free ones); from about 120 the estimator's panel mask breaks up,
# frames are missed and neighbouring qualities swap. See docs/robustness.md.
SIGMA_LEVELS = [0.0, 120.0, 140.0, 150.0, 160.0, 170.0, 180.0]
QUICK_SIGMA_LEVELS = [0.0, 160.0, 180.0]
CLAIM_DROP = 0.3


@dataclass(frozen=True)
class Setup:
    """A controller set-up of the noise sweep, as ``swarm run`` options."""

    key: str
    label: str
    options: tuple[str, ...]


SETUPS = [
    Setup("alpha0", "alpha = 0, MProdOp (paper)", ()),
    Setup("alpha01", "alpha = 0.1, MProdOp", ("--alpha", "0.1", "--threshold", "0.99")),
    Setup(
        "loglinear",
        "alpha = 0.1, log-linear pool",
        ("--alpha", "0.1", "--threshold", "0.99", "--pooling", "loglinear"),
    ),
]


@dataclass(frozen=True)
class Task:
    """One run: a sweep point (its ``swarm run`` options) and a seed."""

    sweep: str
    level: float
    controller: str
    seed: int
    robots: int
    sites: int
    timeout: float
    world_options: tuple[str, ...]
    controller_options: tuple[str, ...]


@dataclass(frozen=True)
class Outcome:
    """What one run decided, and how well its robots compared sites."""

    task: Task
    correct: bool
    consensus: bool
    timed_out: bool
    sim_time_s: float
    comparisons: int
    wrong_comparisons: int
    best_eliminated: int  # wrong comparisons that eliminated the best site
    wall_time_s: float


# --- one run -------------------------------------------------------------------------


def observing_controller(log: list[tuple[int, Any]]) -> type[Controller]:
    """A Controller that records every new ``comparison`` (through the public property,
    after each ``step``; a new comparison is a new object) into ``log``."""

    class ObservedController(Controller):
        _last_seen: object = None

        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            command = super().step(reading, received)
            comparison = self.comparison
            if comparison is not None and comparison is not self._last_seen:
                self._last_seen = comparison
                log.append((self.robot_id, comparison))
            return command

    return ObservedController


def run_task(task: Task) -> Outcome:
    """Run one task in memory (in a worker process) and judge its comparisons."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.node import cli as node
    from robot_agent.node import options
    from world_server.server import cli as server

    common = ["--seed", str(task.seed), "--robots", str(task.robots), "--sites", str(task.sites)]
    world_args = server.build_parser().parse_args(
        [*common, "--run-id", "robustness", *task.world_options]
    )
    controller_args = node.build_parser().parse_args(["--id", "0", *task.controller_options])
    world_config = server.config_from_args(world_args)
    controller_config = options.controller_config(controller_args)
    qualities: dict[int, float] = {}

    def learn_qualities(world: Any) -> None:
        if not qualities:
            qualities.update({site.id: site.quality for site in world.layout.sites})

    log: list[tuple[int, Any]] = []
    started = time.perf_counter()
    summary = run_in_process(
        world_config,
        controller_config,
        timeout=task.timeout,
        on_tick=learn_qualities,
        controller_factory=observing_controller(log),
    )
    wall = time.perf_counter() - started
    best = summary["best_site"]
    wrong = 0
    best_eliminated = 0
    for _, comparison in log:
        eliminated = comparison.eliminated
        kept = comparison.site_b if eliminated == comparison.site_a else comparison.site_a
        if qualities[eliminated] > qualities[kept]:
            wrong += 1
            best_eliminated += eliminated == best
    return Outcome(
        task=task,
        correct=bool(summary["correct"]),
        consensus=bool(summary["consensus"]),
        timed_out=bool(summary["timed_out"]),
        sim_time_s=float(summary["sim_time_s"]),
        comparisons=len(log),
        wrong_comparisons=wrong,
        best_eliminated=best_eliminated,
        wall_time_s=wall,
    )


def run_all(tasks: Sequence[Task], jobs: int) -> list[Outcome]:
    """Every task, ``jobs`` at a time, in the order given; progress on stderr."""
    outcomes: list[Outcome] = []
    started = time.perf_counter()
    if jobs <= 1:
        results: Iterator[Outcome] = map(run_task, tasks)
        for done, outcome in enumerate(results, 1):
            outcomes.append(outcome)
            _progress(done, len(tasks), started)
        return outcomes
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs) as pool:
        for done, outcome in enumerate(pool.map(run_task, tasks), 1):
            outcomes.append(outcome)
            _progress(done, len(tasks), started)
    return outcomes


def _progress(done: int, total: int, started: float) -> None:
    elapsed = time.perf_counter() - started
    print(f"\r  {done}/{total} runs, {elapsed:.0f} s", end="", file=sys.stderr, flush=True)
    if done == total:
        print(file=sys.stderr)


# --- sweeps ----------------------------------------------------------------------------


def drop_tasks(
    levels: Sequence[float], seeds: Sequence[int], args: argparse.Namespace
) -> list[Task]:
    return [
        Task(
            "drop",
            level,
            "alpha0",
            seed,
            args.robots,
            args.sites,
            args.timeout,
            ("--drop", str(level)),
            (),
        )
        for level in levels
        for seed in seeds
    ]


def noise_tasks(
    levels: Sequence[float], seeds: Sequence[int], args: argparse.Namespace
) -> list[Task]:
    lighting = ("--lighting", str(args.lighting)) if args.lighting else ()
    return [
        Task(
            "noise",
            level,
            setup.key,
            seed,
            args.robots,
            args.sites,
            args.timeout,
            ("--camera-noise", str(level), *lighting),
            setup.options,
        )
        for level in levels
        for setup in SETUPS
        for seed in seeds
    ]


@dataclass(frozen=True)
class PointSummary:
    level: float
    controller: str
    runs: int
    correct: int
    wrong_consensus: int  # all decided on one site, not the best
    split_or_timeout: int
    time_mean: float  # over runs with a consensus; nan if none
    time_median: float
    time_max: float
    comparisons: float  # per run
    wrong_share: float  # of all comparisons
    best_eliminated: float  # per run


def summarise(outcomes: Sequence[Outcome]) -> list[PointSummary]:
    groups: dict[tuple[float, str], list[Outcome]] = {}
    for outcome in outcomes:
        groups.setdefault((outcome.task.level, outcome.task.controller), []).append(outcome)
    rows = []
    for (level, controller), runs in groups.items():
        times = [run.sim_time_s for run in runs if run.consensus]
        comparisons = sum(run.comparisons for run in runs)
        rows.append(
            PointSummary(
                level=level,
                controller=controller,
                runs=len(runs),
                correct=sum(run.correct for run in runs),
                wrong_consensus=sum(run.consensus and not run.correct for run in runs),
                split_or_timeout=sum(not run.consensus for run in runs),
                time_mean=statistics.fmean(times) if times else math.nan,
                time_median=statistics.median(times) if times else math.nan,
                time_max=max(times) if times else math.nan,
                comparisons=comparisons / len(runs),
                wrong_share=sum(run.wrong_comparisons for run in runs) / max(comparisons, 1),
                best_eliminated=sum(run.best_eliminated for run in runs) / len(runs),
            )
        )
    return rows


def print_table(title: str, level_name: str, rows: Sequence[PointSummary]) -> None:
    labels = {setup.key: setup.label for setup in SETUPS}
    print(f"\n{title}\n")
    print(
        f"| {level_name} | controller | correct | wrong consensus | split/timeout "
        "| consensus time s: mean / median / max | comparisons/run | wrong comparisons "
        "| best eliminated/run |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row.level:g} | {labels[row.controller]} | {row.correct}/{row.runs} "
            f"| {row.wrong_consensus} | {row.split_or_timeout} "
            f"| {row.time_mean:.0f} / {row.time_median:.0f} / {row.time_max:.0f} "
            f"| {row.comparisons:.1f} | {100 * row.wrong_share:.1f} % | {row.best_eliminated:.2f} |"
        )


def claim_report(outcomes: Sequence[Outcome]) -> dict[str, Any]:
    """The 30 % loss claim from the drop sweep: drop 0.3 against drop 0, seed by seed."""
    by_level: dict[float, dict[int, Outcome]] = {}
    for outcome in outcomes:
        by_level.setdefault(outcome.task.level, {})[outcome.task.seed] = outcome
    clean, lossy = by_level.get(0.0, {}), by_level.get(CLAIM_DROP, {})
    seeds = sorted(set(clean) & set(lossy))
    if not seeds:
        return {}
    clean_times = [clean[seed].sim_time_s for seed in seeds]
    lossy_times = [lossy[seed].sim_time_s for seed in seeds]
    report: dict[str, Any] = {
        "seeds": seeds,
        "all_correct_drop_0": all(clean[seed].correct for seed in seeds),
        "all_correct_drop_0.3": all(lossy[seed].correct for seed in seeds),
        "sim_time_drop_0": clean_times,
        "sim_time_drop_0.3": lossy_times,
        "mean_drop_0": statistics.fmean(clean_times),
        "mean_drop_0.3": statistics.fmean(lossy_times),
    }
    report["slowdown"] = report["mean_drop_0.3"] / report["mean_drop_0"]
    report["per_seed_ratio"] = [b / a for a, b in zip(clean_times, lossy_times, strict=True)]
    print(f"\n30 % iid loss, {len(seeds)} seeds ({seeds[0]}..{seeds[-1]}):")
    print(f"  every run right at drop 0:   {report['all_correct_drop_0']}")
    print(f"  every run right at drop 0.3: {report['all_correct_drop_0.3']}")
    ratios = report["per_seed_ratio"]
    print(
        f"  mean consensus sim time: {report['mean_drop_0']:.1f} s -> "
        f"{report['mean_drop_0.3']:.1f} s, slowdown x{report['slowdown']:.2f} "
        f"(per seed x{min(ratios):.2f} to x{max(ratios):.2f})"
    )
    return report


# --- what the noise does to one comparison ---------------------------------------------


def sensing_table(sigmas: Sequence[float], args: argparse.Namespace, frames: int = 300) -> None:
    """The best and second-best site seen from their viewpoints: estimates, misses, swaps.

    Frames are rendered and read as in a run (world camera, robot vision) from the nominal
    viewpoint, facing the panel, no robot in the way; seed 0's layout.
    """

    from robot_agent.core import vision
    from robot_agent.core.controller import ControllerConfig
    from world_server.core.camera import CameraNoise, CameraRenderer
    from world_server.core.layout import make_layout
    from world_server.core.world import DEFAULT_CAMERA

    layout = make_layout(args.sites, args.robots, seed=0)
    best, second = sorted(layout.sites, key=lambda site: site.rank)[:2]
    radius = layout.arena_radius - ControllerConfig().view_distance
    light = f", lighting {args.lighting:g}" if args.lighting else ""
    print(
        f"\nOne comparison of the best (rho {best.quality:.3f}) and second-best site "
        f"(rho {second.quality:.3f}), {frames} frames each{light}\n"
    )
    print(
        "| sigma | best: mean (sd) | second: mean (sd) | frames with no site found "
        "| P(best reads below second) |"
    )
    print("|---|---|---|---|---|")
    for sigma in sigmas:
        renderer = CameraRenderer(
            layout,
            DEFAULT_CAMERA,
            noise=CameraNoise(sigma, args.lighting),
            seed=seed_of(0, "camera"),
        )
        rng = Stream.named(0, "frames")
        readings: list[list[float]] = []
        missed = 0
        for site in (best, second):
            x, y = radius * math.cos(site.angle), radius * math.sin(site.angle)
            values = []
            for _ in range(frames):
                quality = vision.estimate_quality(renderer.render(x, y, site.angle, rng=rng))
                if quality is None:
                    missed += 1
                else:
                    values.append(quality)
            readings.append(values)
        pairs = list(zip(*readings, strict=False))
        swapped = sum(a < b for a, b in pairs) / len(pairs) if pairs else math.nan
        cells = [
            f"{statistics.fmean(values):.3f} ({statistics.pstdev(values):.3f})" if values else "-"
            for values in readings
        ]
        print(
            f"| {sigma:g} | {cells[0]} | {cells[1]} | {100 * missed / (2 * frames):.0f} % "
            f"| {100 * swapped:.1f} % |"
        )


# --- real processes --------------------------------------------------------------------


def process_runs(
    seeds: Sequence[int],
    drops: Sequence[float],
    args: argparse.Namespace,
    in_memory: Sequence[Outcome],
) -> list[dict[str, Any]]:
    """The claim with real processes (``swarm run``), compared with the in-memory runs."""
    memory = {(o.task.level, o.task.seed): o for o in in_memory if o.task.sweep == "drop"}
    swarm = REPO / ".venv" / "bin" / "swarm"
    rows = []
    print(
        "\nreal processes: swarm run --robots R --sites N --seed S --drop D "
        "--json --no-record --quiet"
    )
    print("| drop | seed | correct | sim time s (processes) | in memory | same | wall s |")
    print("|---|---|---|---|---|---|---|")
    for drop in drops:
        for seed in seeds:
            command = [
                str(swarm),
                "run",
                "--robots",
                str(args.robots),
                "--sites",
                str(args.sites),
                "--seed",
                str(seed),
                "--drop",
                str(drop),
                "--timeout",
                str(args.timeout),
                "--json",
                "--no-record",
                "--quiet",
            ]
            started = time.perf_counter()
            result = subprocess.run(command, capture_output=True, text=True, cwd=REPO, check=False)
            wall = time.perf_counter() - started
            if result.returncode not in RESULT_CODES:  # split, stalled, timeout: results
                print(
                    f"| {drop:g} | {seed} | failed (exit {result.returncode}): "
                    f"{result.stderr.strip()[-200:]} | | | | |"
                )
                rows.append({"drop": drop, "seed": seed, "exit": result.returncode})
                continue
            summary = json.loads(result.stdout)
            twin = memory.get((drop, seed))
            same = twin is not None and (twin.correct, twin.sim_time_s) == (
                summary["correct"],
                summary["sim_time_s"],
            )
            print(
                f"| {drop:g} | {seed} | {summary['correct']} | {summary['sim_time_s']:.1f} "
                f"| {twin.sim_time_s if twin else float('nan'):.1f} | {same} | {wall:.1f} |"
            )
            rows.append(
                {
                    "drop": drop,
                    "seed": seed,
                    "correct": summary["correct"],
                    "sim_time_s": summary["sim_time_s"],
                    "same_as_in_memory": same,
                    "wall_time_s": round(wall, 2),
                }
            )
    for drop in drops:
        done = [row for row in rows if row["drop"] == drop and "sim_time_s" in row]
        times = [row["sim_time_s"] for row in done]
        right = [row["correct"] for row in done]
        if times:
            print(
                f"  drop {drop:g}: {sum(right)}/{len(seeds)} right, "
                f"mean consensus sim time {statistics.fmean(times):.1f} s"
            )
    return rows


# --- figures ---------------------------------------------------------------------------


def plot_drop(outcomes: Sequence[Outcome], rows: Sequence[PointSummary], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    levels = [row.level for row in rows]
    fig, (accuracy, timing) = plt.subplots(1, 2, figsize=(10, 4))
    accuracy.plot(levels, [row.correct / row.runs for row in rows], "o-", color="tab:blue")
    accuracy.set_xlabel("iid radio loss (drop probability)")
    accuracy.set_ylabel("accuracy (share of runs: all robots chose the best)")
    accuracy.set_ylim(-0.05, 1.05)
    accuracy.grid(alpha=0.3)
    for outcome in outcomes:
        if outcome.consensus:
            timing.plot(outcome.task.level, outcome.sim_time_s, ".", color="tab:grey", alpha=0.5)
    timing.plot(levels, [row.time_mean for row in rows], "o-", color="tab:blue", label="mean")
    timing.plot(
        levels, [row.time_median for row in rows], "s--", color="tab:orange", label="median"
    )
    timing.set_xlabel("iid radio loss (drop probability)")
    timing.set_ylabel("consensus time (sim s, last robot decided)")
    timing.grid(alpha=0.3)
    timing.legend()
    runs = rows[0].runs if rows else 0
    fig.suptitle(f"Radio loss: alpha = 0, MProdOp; {runs} seeds per point, dots are runs")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_noise(
    outcomes: Sequence[Outcome], rows: Sequence[PointSummary], path: Path, lighting: float
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"alpha0": "tab:red", "alpha01": "tab:blue", "loglinear": "tab:green"}
    markers = {"alpha0": "o", "alpha01": "s", "loglinear": "^"}
    fig, (accuracy, timing, errors) = plt.subplots(1, 3, figsize=(15, 4.3))
    levels_all = sorted({row.level for row in rows})
    spacing = min((b - a for a, b in itertools.pairwise(levels_all)), default=1.0)
    for number, setup in enumerate(SETUPS):
        # Each set-up's dots a little to the side, so that runs at one level stay apart.
        nudge = (number - (len(SETUPS) - 1) / 2) * 0.12 * spacing
        mine = [row for row in rows if row.controller == setup.key]
        levels = [row.level for row in mine]
        style = {"color": colours[setup.key], "marker": markers[setup.key]}
        accuracy.plot(
            levels, [row.correct / row.runs for row in mine], "-", label=setup.label, **style
        )
        timing.plot(levels, [row.time_mean for row in mine], "-", label=setup.label, **style)
        errors.plot(
            levels, [100 * row.wrong_share for row in mine], "-", label=setup.label, **style
        )
        for outcome in outcomes:
            if outcome.task.controller == setup.key and outcome.consensus:
                timing.plot(
                    outcome.task.level + nudge,
                    outcome.sim_time_s,
                    ".",
                    color=colours[setup.key],
                    alpha=0.35,
                )
    accuracy.set_ylabel("accuracy (share of runs: all robots chose the best)")
    accuracy.set_ylim(-0.05, 1.05)
    timing.set_ylabel("consensus time (sim s; mean line, dots are runs)")
    errors.set_ylabel("wrong comparisons (% of all comparisons)")
    for axes in (accuracy, timing, errors):
        axes.set_xlabel("camera pixel noise sigma (0..255 scale)")
        axes.grid(alpha=0.3)
    accuracy.legend(loc="lower left")
    runs = rows[0].runs if rows else 0
    light = f", lighting {lighting:g}" if lighting else ""
    fig.suptitle(f"Camera noise{light}: {runs} seeds per point, 10 robots, 10 sites")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# --- main ------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick", action="store_true", help="fewer levels and 3 seeds per point (a few minutes)"
    )
    parser.add_argument(
        "--only",
        choices=["drop", "noise", "none"],
        default=None,
        help="run one sweep only (none: just --processes)",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        default=None,
        help="seeds 0..N-1 per point (default: 10, or 3 with --quick)",
    )
    parser.add_argument(
        "--drops",
        type=float,
        nargs="+",
        default=None,
        help="drop levels (default: 0 to 0.8 in steps of 0.1)",
    )
    parser.add_argument(
        "--sigmas",
        type=float,
        nargs="+",
        default=None,
        help=f"pixel noise levels (default: {' '.join(map(str, SIGMA_LEVELS))})",
    )
    parser.add_argument(
        "--lighting",
        type=float,
        default=0.0,
        help="per-site lighting variation added to every noise point",
    )
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument(
        "--timeout",
        type=float,
        default=1800.0,
        help="sim seconds before a run counts as undecided (default: 1800)",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help="runs at a time, one process each (default: 2)",
    )
    parser.add_argument(
        "--processes",
        action="store_true",
        help="also run the 30 %% loss claim with real processes (swarm run)",
    )
    parser.add_argument(
        "--out", type=Path, default=REPO / "docs", help="directory for the figures (default: docs/)"
    )
    parser.add_argument(
        "--results",
        type=Path,
        default=None,
        help="also write every run's outcome to this JSON file",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    seeds = list(range(args.seeds if args.seeds is not None else (3 if args.quick else 10)))
    drops = args.drops or (QUICK_DROP_LEVELS if args.quick else DROP_LEVELS)
    sigmas = args.sigmas or (QUICK_SIGMA_LEVELS if args.quick else SIGMA_LEVELS)
    started = time.perf_counter()
    results: dict[str, Any] = {"seeds": seeds}
    if args.only in (None, "noise"):
        sensing_table(sigmas, args)
    drop_outcomes: list[Outcome] = []
    if args.only in (None, "drop") or args.processes:
        # --processes compares with in-memory runs of the claim: run those at least.
        claim_only = args.only not in (None, "drop")
        levels = [0.0, CLAIM_DROP] if claim_only else drops
        print(f"drop sweep: {len(levels)} levels x {len(seeds)} seeds", file=sys.stderr)
        drop_outcomes = run_all(drop_tasks(levels, seeds, args), args.jobs)
        rows = summarise(drop_outcomes)
        print_table("Radio loss (alpha = 0, MProdOp)", "drop", rows)
        results["claim"] = claim_report(drop_outcomes)
        results["drop"] = [asdict(row) for row in rows]
        if not claim_only:
            args.out.mkdir(parents=True, exist_ok=True)
            plot_drop(drop_outcomes, rows, args.out / "robustness_drop.png")
            print(f"wrote {args.out / 'robustness_drop.png'}")
    if args.only in (None, "noise"):
        print(
            f"noise sweep: {len(sigmas)} levels x {len(SETUPS)} controllers x {len(seeds)} seeds",
            file=sys.stderr,
        )
        noise_outcomes = run_all(noise_tasks(sigmas, seeds, args), args.jobs)
        rows = summarise(noise_outcomes)
        light = f", lighting {args.lighting:g}" if args.lighting else ""
        print_table(f"Camera pixel noise{light}", "sigma", rows)
        results["noise"] = [asdict(row) for row in rows]
        args.out.mkdir(parents=True, exist_ok=True)
        plot_noise(noise_outcomes, rows, args.out / "robustness_noise.png", args.lighting)
        print(f"wrote {args.out / 'robustness_noise.png'}")
        results["noise_runs"] = [_run_record(o) for o in noise_outcomes]
    results["drop_runs"] = [_run_record(o) for o in drop_outcomes]
    print(f"\nsweeps took {time.perf_counter() - started:.0f} s wall with {args.jobs} jobs")
    if args.processes:
        claim_seeds = seeds
        results["processes"] = process_runs(claim_seeds, [0.0, CLAIM_DROP], args, drop_outcomes)
    if args.results:
        args.results.write_text(json.dumps(results, indent=1, default=str))
        print(f"wrote {args.results}")
    return 0


def _run_record(outcome: Outcome) -> dict[str, Any]:
    record = asdict(outcome)
    task = record.pop("task")
    return {key: task[key] for key in ("sweep", "level", "controller", "seed")} | record


if __name__ == "__main__":
    raise SystemExit(main())
