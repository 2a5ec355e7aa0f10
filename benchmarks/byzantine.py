"""Byzantine robots against the swarm's defences: correct runs vs their number.

Whole lockstep runs in one process each (``deploy.inprocess.engine.run_in_process``: the same
world, controllers and beacon as ``swarm run``, and the same per-robot results), 10
robots, for 0 to 3 Byzantine robots of each mode (``liar``: broadcasts certainty of one
site, the same non-best site for every liar of a run; ``inverted``: eliminates the better
site of each pair; ``silent``: never broadcasts), under four defences:

* the paper's controller: alpha = 0, MProdOp;
* distrust: alpha = 0.05 and alpha = 0.1, threshold 0.99, MProdOp;
* distrust with the diluting pool: alpha = 0.1, threshold 0.99, ``--pooling loglinear``.

Which robots misbehave is a seeded draw per run (``byzantine_ids``), nested: the 2
Byzantine robots of a seed include its 1, and its 3 include those 2. Any run can be
replayed with real processes: ``swarm run --robots 10 --sites N --seed S <defence options>
--byzantine ID:MODE ... --timeout T --json``.

A run's outcome is judged on its honest robots (as ``swarm run`` does): correct (all
decided the best site), wrong consensus (all decided one other site), split (all decided,
not on one site), undecided (some had not decided at the timeout).

Writes the results section of docs/byzantine.md (between its markers; the rest of the
page is prose) and docs/byzantine.png.

    .venv/bin/python benchmarks/byzantine.py --seeds 40                  # the page's runs
    .venv/bin/python benchmarks/byzantine.py --seeds 3 --out /tmp/byz    # a quick look
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import math
import os
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.reports import pages, sweep  # noqa: E402
from robot_agent.core import byzantine  # noqa: E402
from wire.rng import Stream  # noqa: E402

MODES = ("liar", "inverted", "silent")
MAX_BYZANTINE = 3
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"


@dataclass(frozen=True)
class Defence:
    """A controller set-up, as ``swarm run`` options."""

    key: str
    label: str
    options: tuple[str, ...]


DEFENCES = [
    Defence("paper", "alpha = 0, MProdOp (paper)", ()),
    Defence("a005", "alpha = 0.05, MProdOp", ("--alpha", "0.05", "--threshold", "0.99")),
    Defence("a01", "alpha = 0.1, MProdOp", ("--alpha", "0.1", "--threshold", "0.99")),
    Defence(
        "loglinear",
        "alpha = 0.1, log-linear pool",
        ("--alpha", "0.1", "--threshold", "0.99", "--pooling", "loglinear"),
    ),
]


@dataclass(frozen=True)
class Task:
    mode: str  # "none" for the runs without Byzantine robots
    count: int
    defence: str
    seed: int
    robots: int
    sites: int
    timeout: float


@dataclass(frozen=True)
class Outcome:
    task: Task
    byzantine: tuple[str, ...]  # the --byzantine switches of the run
    verdict: str  # correct | wrong | split | undecided
    liar_won: bool  # a wrong consensus on the liars' site
    sim_time_s: float  # the honest robots' consensus (the last one decided), or the end
    wall_time_s: float


def byzantine_ids(seed: int, robots: int, count: int) -> list[int]:
    """The ``count`` Byzantine robots of run ``seed``: a seeded draw, nested in ``count``."""
    drawn = Stream.named(seed, "benchmark", "byzantine").sample(range(robots), MAX_BYZANTINE)
    return sorted(drawn[:count])


def run_task(task: Task) -> Outcome:
    """One run in memory (in a worker process)."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.node import cli as node
    from robot_agent.node import options
    from world_server.server import cli as server

    common = ["--seed", str(task.seed), "--robots", str(task.robots), "--sites", str(task.sites)]
    world_config = server.config_from_args(
        server.build_parser().parse_args([*common, "--run-id", "byzantine"])
    )
    defence = next(d for d in DEFENCES if d.key == task.defence)
    controller_config = options.controller_config(
        node.build_parser().parse_args(["--id", "0", *defence.options])
    )
    chosen = {
        robot: byzantine.Behaviour.parse(task.mode)
        for robot in byzantine_ids(task.seed, task.robots, task.count)
    }
    started = time.perf_counter()
    summary = run_in_process(
        world_config, controller_config, timeout=task.timeout, byzantine_robots=chosen
    )
    wall = time.perf_counter() - started
    robots = summary["per_robot"]
    switches = tuple(f"{r['id']}:{r['byzantine']}" for r in robots if r["byzantine"])
    honest = [robot["decided_site"] for robot in summary["per_robot"] if not robot["byzantine"]]
    if summary["correct"]:
        verdict = "correct"
    elif summary["consensus"]:
        verdict = "wrong"
    elif all(site is not None for site in honest):
        verdict = "split"
    else:
        verdict = "undecided"
    liar_site = byzantine.default_liar_site(task.sites, summary["best_site"], task.seed)
    return Outcome(
        task=task,
        byzantine=switches,
        verdict=verdict,
        liar_won=task.mode == "liar" and verdict == "wrong" and summary["chosen_site"] == liar_site,
        sim_time_s=float(summary["sim_time_s"]),
        wall_time_s=wall,
    )


def tasks_for(args: argparse.Namespace) -> list[Task]:
    tasks = []
    for sites in args.sites:
        for defence in DEFENCES:
            for seed in range(args.seeds):
                tasks.append(Task("none", 0, defence.key, seed, args.robots, sites, args.timeout))
                for mode in args.modes:
                    for count in range(1, MAX_BYZANTINE + 1):
                        tasks.append(
                            Task(mode, count, defence.key, seed, args.robots, sites, args.timeout)
                        )
    return tasks


def run_all(tasks: Sequence[Task], parallel: int) -> list[Outcome]:
    outcomes: list[Outcome] = []
    started = time.perf_counter()
    with concurrent.futures.ProcessPoolExecutor(max_workers=parallel) as pool:
        for done, outcome in enumerate(pool.map(run_task, tasks, chunksize=2), 1):
            outcomes.append(outcome)
            elapsed = time.perf_counter() - started
            print(f"\r  {done}/{len(tasks)} runs, {elapsed:.0f} s", end="", file=sys.stderr)
    print(file=sys.stderr)
    return outcomes


# --- summary --------------------------------------------------------------------------


@dataclass(frozen=True)
class Cell:
    sites: int
    mode: str
    count: int
    defence: str
    runs: int
    correct: int
    wrong: int
    liar_won: int
    split: int
    undecided: int  # hit the timeout with an honest robot undecided
    median_time: float  # over runs whose honest robots reached a consensus


def cells(outcomes: Sequence[Outcome], modes: Sequence[str]) -> list[Cell]:
    """Per (n, mode, count, defence); the runs without Byzantine robots count for every
    mode at count 0."""
    groups: dict[tuple[int, str, int, str], list[Outcome]] = {}
    for outcome in outcomes:
        task = outcome.task
        for mode in modes if task.mode == "none" else [task.mode]:
            groups.setdefault((task.sites, mode, task.count, task.defence), []).append(outcome)
    result = []
    for (sites, mode, count, defence), runs in sorted(
        groups.items(), key=lambda item: (item[0][0], modes.index(item[0][1]), item[0][2])
    ):
        times = [run.sim_time_s for run in runs if run.verdict in ("correct", "wrong")]
        result.append(
            Cell(
                sites=sites,
                mode=mode,
                count=count,
                defence=defence,
                runs=len(runs),
                correct=sum(run.verdict == "correct" for run in runs),
                wrong=sum(run.verdict == "wrong" for run in runs),
                liar_won=sum(run.liar_won for run in runs),
                split=sum(run.verdict == "split" for run in runs),
                undecided=sum(run.verdict == "undecided" for run in runs),
                median_time=statistics.median(times) if times else math.nan,
            )
        )
    defence_order = [d.key for d in DEFENCES]
    return sorted(
        result,
        key=lambda c: (c.sites, modes.index(c.mode), c.count, defence_order.index(c.defence)),
    )


def table(rows: Sequence[Cell]) -> str:
    labels = {d.key: d.label for d in DEFENCES}
    lines = [
        "| n | mode | Byzantine | defence | correct | wrong consensus | split "
        "| undecided at timeout | median consensus time (sim s) |",
        "|---:|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        wrong = f"{row.wrong}"
        if row.mode == "liar" and row.count > 0:
            wrong += f" ({row.liar_won} the liars' site)"
        lines.append(
            f"| {row.sites} | {row.mode} | {row.count} | {labels[row.defence]} "
            f"| {row.correct}/{row.runs} | {wrong} | {row.split} | {row.undecided} "
            f"| {row.median_time:.0f} |"
        )
    return "\n".join(lines)


def plot(rows: Sequence[Cell], modes: Sequence[str], path: Path, seeds: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    all_sites = sorted({row.sites for row in rows})
    colours = {
        "paper": "tab:red",
        "a005": "tab:orange",
        "a01": "tab:blue",
        "loglinear": "tab:green",
    }
    markers = {"paper": "o", "a005": "v", "a01": "s", "loglinear": "^"}
    fig, axes = plt.subplots(
        len(all_sites),
        len(modes),
        figsize=(4.2 * len(modes), 3.6 * len(all_sites)),
        squeeze=False,
        sharey=True,
    )
    for row_index, sites in enumerate(all_sites):
        for column, mode in enumerate(modes):
            ax = axes[row_index][column]
            for number, defence in enumerate(DEFENCES):
                # Each defence a little to the side, so that equal shares stay visible.
                nudge = (number - (len(DEFENCES) - 1) / 2) * 0.04
                mine = [
                    r
                    for r in rows
                    if r.sites == sites and r.mode == mode and r.defence == defence.key
                ]
                ax.plot(
                    [r.count + nudge for r in mine],
                    [r.correct / r.runs for r in mine],
                    "-",
                    color=colours[defence.key],
                    marker=markers[defence.key],
                    label=defence.label,
                )
            ax.set_title(f"{mode}, n = {sites}")
            ax.set_xticks(range(MAX_BYZANTINE + 1))
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
            ax.set_xlabel("Byzantine robots (of 10)")
            if column == 0:
                ax.set_ylabel("share of runs: honest robots all chose the best")
    axes[0][0].legend(loc="lower left", fontsize="small")
    fig.suptitle(f"Byzantine robots: {seeds} seeds per point, 10 robots")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def results_section(
    rows: Sequence[Cell], outcomes: Sequence[Outcome], args: argparse.Namespace, wall: float
) -> str:
    command = " ".join(["benchmarks/byzantine.py", *args.argv])
    hit = sum(outcome.verdict == "undecided" for outcome in outcomes)
    return "\n".join(
        [
            "",
            f"Made by `.venv/bin/python {command}` at {pages.made_at(REPO)}: "
            f"{len(outcomes)} runs, {args.robots} robots, seeds 0..{args.seeds - 1}, "
            f"timeout {args.timeout:g} sim s ({hit} run{'' if hit == 1 else 's'} hit it), "
            f"{wall / 60:.0f} min wall with {args.parallel} processes on {os.cpu_count()} "
            "cores. The rows with 0 Byzantine robots are the same runs in every mode.",
            "",
            table(rows),
            "",
        ]
    )


def write_page(path: Path, section: str) -> None:
    """Replace the results between the markers; a new page gets only the results."""
    if not path.exists():
        path.write_text(f"# Byzantine robots\n\n{BEGIN}\n{END}\n")
    pages.write_between(path, BEGIN, END, section)


# --- the defence study: --defence trimmed against liars ------------------------------

DEFENCE_RESULTS = REPO / "docs" / "byzantine-defence-runs.jsonl"
DEFENCE_FIGURE = "byzantine-defence.png"
DEFENCE_BEGIN, DEFENCE_END = "<!-- defence:begin -->", "<!-- defence:end -->"
# Liars per swarm size: 0-3 of 10; 10% and 20% of 50.
DEFENCE_LIARS = {10: (0, 1, 2, 3), 50: (0, 5, 10)}
# The defences per swarm size: the paper's pooling, and trimmed pooling with F the liars
# it is set to tolerate (one of 10; 10% of 50, and 20% of 50).
DEFENCE_SETTINGS = {10: ("none", "trimmed:1"), 50: ("none", "trimmed:5", "trimmed:10")}


@dataclass(frozen=True)
class DefenceTask:
    defence: str  # none, or trimmed:F
    robots: int
    liars: int
    seed: int
    sites: int = 10
    timeout: float = 2400.0

    @property
    def key(self) -> str:
        return f"{self.defence}/N{self.robots}/L{self.liars}/n{self.sites}/s{self.seed}"

    def options(self) -> list[str]:
        """The defence as ``swarm run`` options."""
        if self.defence == "none":
            return []
        name, _, trim = self.defence.partition(":")
        return ["--defence", name, "--trim", trim]


def liar_ids(seed: int, robots: int, count: int) -> list[int]:
    """The liars of run ``seed``: ``byzantine_ids`` for 10 robots (the same robots as the
    study above), else a seeded draw of 20% of the robots, nested in ``count``."""
    if robots == 10 and count <= MAX_BYZANTINE:
        return byzantine_ids(seed, robots, count)
    most = max(count, robots // 5)
    drawn = Stream.named(seed, "benchmark", "liars").sample(range(robots), most)
    return sorted(drawn[:count])


def run_defence(task: DefenceTask) -> dict[str, object]:
    """One run in memory with ``task.liars`` liars (each claiming the run's liar site)."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.node import cli as node
    from robot_agent.node import options
    from world_server.server import cli as server

    common = ["--seed", str(task.seed), "--robots", str(task.robots), "--sites", str(task.sites)]
    world_config = server.config_from_args(
        server.build_parser().parse_args([*common, "--run-id", "byzantine"])
    )
    controller_config = options.controller_config(
        node.build_parser().parse_args(["--id", "0", *task.options()])
    )
    liars = {
        robot: byzantine.Behaviour("liar") for robot in liar_ids(task.seed, task.robots, task.liars)
    }
    started = time.perf_counter()
    summary = run_in_process(
        world_config, controller_config, timeout=task.timeout, byzantine_robots=liars
    )
    honest = [robot["decided_site"] for robot in summary["per_robot"] if not robot["byzantine"]]
    if summary["correct"]:
        verdict = "correct"
    elif summary["consensus"]:
        verdict = "wrong"
    elif all(site is not None for site in honest):
        verdict = "split"
    else:
        verdict = "undecided"
    liar_site = byzantine.default_liar_site(task.sites, summary["best_site"], task.seed)
    return {
        "key": task.key,
        **dataclasses.asdict(task),
        "liar_ids": sorted(liars),
        "verdict": verdict,
        "liar_won": verdict == "wrong" and summary["chosen_site"] == liar_site,
        "liar_site_decided": sum(site == liar_site for site in honest),
        "honest": len(honest),
        "sim_time_s": summary["sim_time_s"],
        "wall_s": round(time.perf_counter() - started, 2),
    }


def defence_tasks(seeds: int, seeds_50: int, sizes: Sequence[int]) -> list[DefenceTask]:
    tasks = [
        DefenceTask(defence, robots, liars, seed)
        for robots in sizes
        for seed in range(seeds if robots <= 10 else seeds_50)
        for liars in DEFENCE_LIARS[robots]
        for defence in DEFENCE_SETTINGS[robots]
    ]
    return sorted(tasks, key=lambda task: (task.robots, task.seed))


def load_defence(path: Path) -> dict[str, dict[str, Any]]:
    found: dict[str, dict[str, Any]] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                record = json.loads(line)
                found[record["key"]] = record
    return found


def run_defence_study(args: argparse.Namespace) -> int:
    from benchmarks import byzantine as this  # importable by the workers, unlike __main__
    from deploy.reports import sweep

    done = load_defence(args.defence_results)
    tasks = [
        task
        for task in defence_tasks(args.seeds, args.seeds_50, args.sizes)
        if task.key not in done
    ]
    print(f"defence study: {len(tasks)} runs to make", file=sys.stderr)
    args.defence_results.parent.mkdir(parents=True, exist_ok=True)
    with args.defence_results.open("a") as results:

        def keep(index: int, result: dict[str, object]) -> None:
            results.write(json.dumps(result, separators=(",", ":")) + "\n")
            results.flush()

        outcome = sweep.run_sweep(
            this.run_defence,
            tasks,
            sweep.executor_from_args(args),
            sweep.print_progress("defence study"),
            on_result=keep,
        )
    return 1 if outcome.failures else 0


def defence_rows(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    groups: dict[tuple[int, int, str], list[dict[str, Any]]] = {}
    for record in results.values():
        groups.setdefault((record["robots"], record["liars"], record["defence"]), []).append(record)
    rows = []
    for (robots, liars, defence), runs in sorted(groups.items()):
        verdicts = [run["verdict"] for run in runs]
        times = [run["sim_time_s"] for run in runs if run["verdict"] == "correct"]
        rows.append(
            {
                "robots": robots,
                "liars": liars,
                "defence": defence,
                "runs": len(runs),
                "correct": verdicts.count("correct"),
                "wrong": verdicts.count("wrong"),
                "liar_won": sum(run["liar_won"] for run in runs),
                "split": verdicts.count("split"),
                "undecided": verdicts.count("undecided"),
                "median": statistics.median(times) if times else math.nan,
                "mean": statistics.fmean(times) if times else math.nan,
            }
        )
    order = {
        key: index for index, key in enumerate(("none", "trimmed:1", "trimmed:5", "trimmed:10"))
    }
    return sorted(rows, key=lambda r: (r["robots"], r["liars"], order.get(r["defence"], 99)))


def defence_label(defence: str) -> str:
    if defence == "none":
        return "none (the paper's pooling)"
    return f"trimmed, F = {defence.partition(':')[2]}"


def defence_table(rows: Sequence[dict[str, Any]]) -> str:
    lines = [
        "| robots | liars | defence | runs | correct | wrong consensus (the liars' site) "
        "| split | undecided | sim s to consensus, median (mean), correct runs |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        share = row["correct"] / row["runs"]
        time_text = "-" if math.isnan(row["median"]) else f"{row['median']:.0f} ({row['mean']:.0f})"
        lines.append(
            f"| {row['robots']} | {row['liars']} | {defence_label(row['defence'])} | {row['runs']} "
            f"| {row['correct']} ({share:.0%}) | {row['wrong']} ({row['liar_won']}) "
            f"| {row['split']} | {row['undecided']} | {time_text} |"
        )
    return "\n".join(lines)


def plot_defence(rows: Sequence[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = sorted({row["robots"] for row in rows})
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 3.8), squeeze=False)
    for axis, robots in zip(axes[0], sizes, strict=True):
        for defence in sorted({r["defence"] for r in rows if r["robots"] == robots}):
            mine = [r for r in rows if r["robots"] == robots and r["defence"] == defence]
            axis.plot(
                [100 * r["liars"] / robots for r in mine],
                [r["correct"] / r["runs"] for r in mine],
                "o-",
                label=defence_label(defence),
            )
        axis.axhline(0.9, linestyle=":", color="grey")
        axis.set_title(f"{robots} robots, n = 10")
        axis.set_xlabel("liars (% of the robots)")
        axis.set_ylabel("share of runs: honest robots all chose the best")
        axis.set_ylim(-0.05, 1.05)
        axis.grid(alpha=0.3)
        axis.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_defence(args: argparse.Namespace) -> None:
    rows = defence_rows(load_defence(args.defence_results))
    section = "\n".join(
        [
            "",
            f"Made by `.venv/bin/python benchmarks/byzantine.py --study defence --write` at "
            f"{pages.made_at(REPO)} from `docs/{args.defence_results.name}` (one run per line).",
            "",
            defence_table(rows),
            "",
        ]
    )
    pages.write_between(args.out / "byzantine.md", DEFENCE_BEGIN, DEFENCE_END, section)
    plot_defence(rows, args.out / DEFENCE_FIGURE)
    print(defence_table(rows))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds 0..S-1 (default: 20)")
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--sites", type=int, nargs="+", default=[10], help="n (default: 10)")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument(
        "--timeout", type=float, default=1200.0, help="sim seconds per run (default: 1200)"
    )
    parser.add_argument(
        "--out", type=Path, default=REPO / "docs", help="where byzantine.md/.png go (docs/)"
    )
    parser.add_argument(
        "--study",
        choices=["modes", "defence"],
        default="modes",
        help="modes: the Byzantine modes against distrust (the first table); defence: "
        "--defence trimmed against 0-3 liars of 10 and 10%%, 20%% of 50",
    )
    parser.add_argument("--seeds-50", type=int, default=30, help="defence study, 50 robots")
    parser.add_argument("--sizes", type=int, nargs="+", choices=[10, 50], default=[10, 50])
    parser.add_argument("--defence-results", type=Path, default=DEFENCE_RESULTS)
    parser.add_argument("--write", action="store_true", help="defence study: write the page")
    parser.add_argument("--no-run", action="store_true", help="defence study: only --write")
    sweep.add_executor_options(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    if args.study == "defence":
        failed = 0 if args.no_run else run_defence_study(args)
        if args.write:
            write_defence(args)
        return failed
    tasks = tasks_for(args)
    print(f"{len(tasks)} runs, {args.parallel} at a time", file=sys.stderr)
    started = time.perf_counter()
    outcomes = run_all(tasks, args.parallel)
    wall = time.perf_counter() - started
    rows = cells(outcomes, args.modes)
    print(table(rows))
    args.out.mkdir(parents=True, exist_ok=True)
    write_page(args.out / "byzantine.md", results_section(rows, outcomes, args, wall))
    plot(rows, args.modes, args.out / "byzantine.png", args.seeds)
    print(f"wrote {args.out / 'byzantine.md'} and {args.out / 'byzantine.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
