"""The paper's strategy against its rivals: consensus time and accuracy against n.

Two parts, each resumable (every result is appended to ``docs/strategies-runs.jsonl`` as
it comes, and a task already there is not run again):

* ``wellstirred``: the Section 4 model for the paper's strategy (``wellstirred.model``:
  N = 100 agents shuffled into pools of k = 3) and for DMVD, DMMD and DC
  (``wellstirred.voting``: the same 100 agents, dmmd's group of 3: itself and 2
  neighbours), n = 5, 10, 20, 50 and 100, 100 runs per point, 2000 steps at most;
* ``swarm``: whole lockstep runs in one process each (``deploy.inprocess.engine.run_in_process``:
  the same world, controllers and beacon as ``swarm run``), every ``--strategy``, n = 5, 8,
  10 and 20 sites, 10 robots (``--seeds``, default 100 per point) and 50 robots
  (``--seeds-50``, default 20), without and with 20% message loss (``--drop 0.2``).

The runs go to an executor (``deploy/reports/sweep.py``: ``--parallel J`` local processes, or
``--dask [ADDRESS]``). ``--write`` renders docs/strategies.md's tables and
docs/strategies.png from the results file (it runs nothing that is missing: it says what
is). Any swarm run can be replayed with real processes: ``swarm run --robots R --sites n
--seed S --strategy X [--drop 0.2] --timeout T --json``.

    .venv/bin/python benchmarks/strategies.py --part wellstirred
    .venv/bin/python benchmarks/strategies.py --part swarm --seeds 100 --seeds-50 20
    .venv/bin/python benchmarks/strategies.py --write
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.reports import sweep  # noqa: E402
from robot_agent.core.voting import STRATEGIES, StrategyName  # noqa: E402

RESULTS = REPO / "docs" / "strategies-runs.jsonl"
PAGE = REPO / "docs" / "strategies.md"
FIGURE = REPO / "docs" / "strategies.png"
COMMAND = "benchmarks/strategies.py --write"
EDIT = "benchmarks/strategies.py"

WELLSTIRRED_OPTIONS = (5, 10, 20, 50, 100)
WELLSTIRRED_AGENTS = 100
WELLSTIRRED_GROUP = 3  # the paper's pool k, dmmd's group (itself and 2 neighbours)
WELLSTIRRED_RUNS = 100
WELLSTIRRED_STEPS = 2000
SWARM_SITES = (5, 8, 10, 20)
SWARM_DROPS = (0.0, 0.2)
DEFAULT_TIMEOUT = 2400.0  # sim seconds


# --- tasks ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class CellTask:
    """One point of the well-stirred part."""

    strategy: StrategyName
    options: int
    seed: int = 0

    @property
    def key(self) -> str:
        return f"wellstirred/{self.strategy}/n{self.options}/s{self.seed}"


@dataclass(frozen=True)
class RunTask:
    """One swarm run."""

    strategy: StrategyName
    robots: int
    sites: int
    drop: float
    seed: int
    timeout: float = DEFAULT_TIMEOUT

    @property
    def key(self) -> str:
        return f"swarm/{self.strategy}/N{self.robots}/n{self.sites}/d{self.drop:g}/s{self.seed}"


def run_cell(task: CellTask) -> dict[str, Any]:
    """One well-stirred point: every run's time and success."""
    from wellstirred.model import Model, cell_rng, simulate
    from wellstirred.voting import VoteModel, simulate_votes, vote_cell_rng

    started = time.perf_counter()
    if task.strategy == "paper":
        model = Model(task.options, WELLSTIRRED_GROUP, WELLSTIRRED_AGENTS, steps=WELLSTIRRED_STEPS)
        outcome = simulate(model, WELLSTIRRED_RUNS, cell_rng(task.seed, model))
    else:
        vote = VoteModel(
            task.strategy,
            task.options,
            WELLSTIRRED_GROUP,
            WELLSTIRRED_AGENTS,
            steps=WELLSTIRRED_STEPS,
        )
        outcome = simulate_votes(vote, WELLSTIRRED_RUNS, vote_cell_rng(task.seed, vote))
    return {
        "key": task.key,
        "kind": "wellstirred",
        **asdict(task),
        "agents": WELLSTIRRED_AGENTS,
        "group": WELLSTIRRED_GROUP,
        "steps_limit": WELLSTIRRED_STEPS,
        "times": [int(t) for t in outcome.times],
        "success": [bool(s) for s in outcome.success],
        "wall_s": round(time.perf_counter() - started, 2),
    }


def run_swarm(task: RunTask) -> dict[str, Any]:
    """One swarm run in process: how it ended, for the honest robots."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.core.controller_config import ControllerConfig
    from world_server.core.radio import RadioConfig
    from world_server.core.world import WorldConfig

    world = WorldConfig(
        run="strategies",
        seed=task.seed,
        num_sites=task.sites,
        num_robots=task.robots,
        radio=RadioConfig(drop=task.drop),
    )
    controller = ControllerConfig(strategy=task.strategy)
    started = time.perf_counter()
    summary = run_in_process(world, controller, timeout=task.timeout)
    robots = summary["per_robot"]
    steps = [robot["steps"] for robot in robots if robot["steps"] is not None]
    return {
        "key": task.key,
        "kind": "swarm",
        **asdict(task),
        "ended": summary["ended"],
        "verdict": verdict(summary),
        "sim_time_s": summary["sim_time_s"],
        "steps": max(steps) if steps else None,
        "wall_s": round(time.perf_counter() - started, 2),
    }


def verdict(summary: dict[str, Any]) -> str:
    """correct | wrong (all on one other site) | split (all decided, not on one site) |
    undecided (some had not decided when the run ended)."""
    if summary["correct"]:
        return "correct"
    if summary["consensus"]:
        return "wrong"
    decided = [robot["decided_site"] for robot in summary["per_robot"]]
    return "split" if all(site is not None for site in decided) else "undecided"


def wellstirred_tasks() -> list[CellTask]:
    return [CellTask(strategy, n) for strategy in STRATEGIES for n in WELLSTIRRED_OPTIONS]


def swarm_tasks(args: argparse.Namespace) -> list[RunTask]:
    tasks = []
    for robots in args.robots:
        seeds = args.seeds if robots <= 10 else args.seeds_50
        for sites in args.sites:
            for drop in args.drops:
                for strategy in args.strategies:
                    for seed in range(seeds):
                        tasks.append(RunTask(strategy, robots, sites, drop, seed, args.timeout))
    # Seed-major: a sweep cut short has every point at a few seeds, not a few points done.
    return sorted(tasks, key=lambda task: (task.seed, task.robots, task.sites, task.drop))


# --- the results file ----------------------------------------------------------------------


def load_results(path: Path = RESULTS) -> dict[str, dict[str, Any]]:
    """Every result in the file, by key (the last of a key wins)."""
    found: dict[str, dict[str, Any]] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                record = json.loads(line)
                found[record["key"]] = record
    return found


def run_missing(
    tasks: Sequence[CellTask] | Sequence[RunTask],
    executor: sweep.ExecutorSpec,
    path: Path,
    label: str,
) -> int:
    """Run the tasks not yet in ``path``, appending each result as it comes; failures."""
    from benchmarks import strategies as this  # importable by the workers, unlike __main__

    done = load_results(path)
    todo: list[Any] = [task for task in tasks if task.key not in done]
    print(f"{label}: {len(todo)} to run ({len(tasks) - len(todo)} already in {path})")
    if not todo:
        return 0
    function = this.run_cell if isinstance(todo[0], CellTask) else this.run_swarm
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as results:

        def keep(index: int, result: dict[str, Any]) -> None:
            results.write(json.dumps(result, separators=(",", ":")) + "\n")
            results.flush()  # a sweep stopped half way keeps what it ran

        outcome = sweep.run_sweep(
            function, todo, executor, sweep.print_progress(label), on_result=keep
        )
    return len(outcome.failures)


# --- the page ------------------------------------------------------------------------------


def _median(values: Iterable[float]) -> float:
    values = list(values)
    return statistics.median(values) if values else math.nan


def wellstirred_rows(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for strategy in STRATEGIES:
        for n in WELLSTIRRED_OPTIONS:
            record = results.get(CellTask(strategy, n).key)
            if record is None:
                continue
            times, success = record["times"], record["success"]
            good = [t for t, ok in zip(times, success, strict=True) if ok]
            rows.append(
                {
                    "strategy": strategy,
                    "n": n,
                    "runs": len(times),
                    "correct": sum(success),
                    "median": _median(good),
                    "q1": float(statistics.quantiles(good, n=4)[0]) if len(good) > 1 else math.nan,
                    "q3": float(statistics.quantiles(good, n=4)[2]) if len(good) > 1 else math.nan,
                }
            )
    return rows


def swarm_rows(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    groups: dict[tuple[int, int, float, str], list[dict[str, Any]]] = {}
    for record in results.values():
        if record["kind"] == "swarm":
            key = (record["robots"], record["sites"], record["drop"], record["strategy"])
            groups.setdefault(key, []).append(record)
    rows = []
    for (robots, sites, drop, strategy), runs in sorted(
        groups.items(), key=lambda item: (*item[0][:3], STRATEGIES.index(item[0][3]))
    ):
        verdicts = [run["verdict"] for run in runs]
        good = [run["sim_time_s"] for run in runs if run["verdict"] == "correct"]
        rows.append(
            {
                "robots": robots,
                "n": sites,
                "drop": drop,
                "strategy": strategy,
                "runs": len(runs),
                "correct": verdicts.count("correct"),
                "wrong": verdicts.count("wrong"),
                "split": verdicts.count("split"),
                "undecided": verdicts.count("undecided"),
                "median": _median(good),
                "steps": _median(
                    run["steps"]
                    for run in runs
                    if run["verdict"] == "correct" and run["steps"] is not None
                ),
            }
        )
    return rows


def _number(value: float, digits: int = 0) -> str:
    return "-" if math.isnan(value) else f"{value:.{digits}f}"


def wellstirred_table(rows: Sequence[dict[str, Any]]) -> str:
    lines = [
        "| strategy | n | right consensus | steps to consensus, median (IQR), right runs |",
        "|---|---:|---:|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['strategy']} | {row['n']} | {row['correct']}/{row['runs']} "
            f"| {_number(row['median'], 1)} ({_number(row['q1'], 1)}-{_number(row['q3'], 1)}) |"
        )
    return "\n".join(lines)


def swarm_table(rows: Sequence[dict[str, Any]]) -> str:
    lines = [
        "| robots | n | message loss | strategy | runs | right | wrong | split | undecided "
        "| sim s to consensus, median (right runs) | trips of the last robot, median |",
        "|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['robots']} | {row['n']} | {row['drop']:.0%} | {row['strategy']} "
            f"| {row['runs']} | {row['correct']} | {row['wrong']} | {row['split']} "
            f"| {row['undecided']} | {_number(row['median'])} | {_number(row['steps'], 1)} |"
        )
    return "\n".join(lines)


def render(results: dict[str, dict[str, Any]]) -> dict[str, str]:
    """The page's generated blocks."""
    return {
        "wellstirred": wellstirred_table(wellstirred_rows(results)),
        "swarm": swarm_table(swarm_rows(results)),
    }


def plot(results: dict[str, dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"paper": "tab:red", "dmvd": "tab:blue", "dmmd": "tab:orange", "dc": "tab:green"}
    well = wellstirred_rows(results)
    swarm = swarm_rows(results)
    robots = sorted({row["robots"] for row in swarm}) or [10]
    figure, axes = plt.subplots(2, 1 + len(robots), figsize=(5 * (1 + len(robots)), 7.5))
    for strategy in STRATEGIES:
        mine = [row for row in well if row["strategy"] == strategy]
        n = [row["n"] for row in mine]
        axes[0][0].plot(n, [r["correct"] / r["runs"] for r in mine], "o-", color=colours[strategy])
        axes[1][0].plot(
            n, [r["median"] for r in mine], "o-", color=colours[strategy], label=strategy
        )
    axes[0][0].set_title(f"well-stirred, N = {WELLSTIRRED_AGENTS}, group 3")
    axes[1][0].set_ylabel("steps to consensus, median of right runs")
    axes[0][0].set_ylabel("share of runs: consensus on the best")
    axes[1][0].set_yscale("log")
    axes[1][0].legend(fontsize="small")
    for column, count in enumerate(robots, start=1):
        for strategy in STRATEGIES:
            for drop, style in ((0.0, "o-"), (0.2, "s--")):
                mine = [
                    r
                    for r in swarm
                    if r["robots"] == count and r["strategy"] == strategy and r["drop"] == drop
                ]
                if not mine:
                    continue
                n = [row["n"] for row in mine]
                label = f"{strategy}, {drop:.0%} loss"
                axes[0][column].plot(
                    n, [r["correct"] / r["runs"] for r in mine], style, color=colours[strategy]
                )
                axes[1][column].plot(
                    n, [r["median"] for r in mine], style, color=colours[strategy], label=label
                )
        axes[0][column].set_title(f"swarm, {count} robots")
        axes[1][column].set_ylabel("sim s to consensus, median of right runs")
        axes[1][column].legend(fontsize="x-small", ncols=2)
    for axis in axes[0]:
        axis.set_ylim(-0.05, 1.05)
    for axis in [*axes[0], *axes[1]]:
        axis.set_xlabel("n (options / sites)")
        axis.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def write_page(results: dict[str, dict[str, Any]], page: Path, figure: Path) -> None:
    from deploy.reports.section5 import replace_block

    text = page.read_text()
    for name, content in render(results).items():
        text = replace_block(text, name, content, COMMAND, EDIT)
    page.write_text(text)
    plot(results, figure)


# --- the command ---------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--part", choices=["wellstirred", "swarm", "all"], default=None)
    parser.add_argument("--write", action="store_true", help="render the page and figure")
    parser.add_argument("--seeds", type=int, default=100, help="seeds per point, 10 robots")
    parser.add_argument("--seeds-50", type=int, default=20, help="seeds per point, 50 robots")
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 50])
    parser.add_argument("--sites", type=int, nargs="+", default=list(SWARM_SITES))
    parser.add_argument("--drops", type=float, nargs="+", default=list(SWARM_DROPS))
    parser.add_argument("--strategies", nargs="+", choices=STRATEGIES, default=list(STRATEGIES))
    parser.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, help="sim s per run")
    parser.add_argument("--results", type=Path, default=RESULTS)
    sweep.add_executor_options(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    executor = sweep.executor_from_args(args)
    failures = 0
    if args.part in ("wellstirred", "all"):
        failures += run_missing(wellstirred_tasks(), executor, args.results, "well-stirred")
    if args.part in ("swarm", "all"):
        failures += run_missing(swarm_tasks(args), executor, args.results, "swarm runs")
    if args.write:
        write_page(load_results(args.results), PAGE, FIGURE)
        print(f"wrote {PAGE} and {FIGURE}")
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
