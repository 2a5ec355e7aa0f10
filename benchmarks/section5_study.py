"""Section 5 study: how the settings the paper leaves open move time to consensus.

Runs whole lockstep runs in one process each (``deploy.inprocess.engine.run_in_process``: the same
world, controllers and beacon as ``swarm run``, the same per-robot results), ten robots,
n = 5, 8 and 10, seeds 0..S-1, for each *setting*: a comma-separated list of
``field=value`` overrides of the defaults, e.g. ``dwell=5,broadcast_period=1``. A field
is looked up in ControllerConfig, then BeaconConfig (as ``beacon_<field>``), then
WorldConfig, then EpuckSpec; ``default`` is no override.

Every run is observed by a Controller subclass that records each pooling (who, when,
which trip, the pool's members, the sites each member still held possible) and, at each
decision, where every robot was and what it still held possible. One JSON line per run
goes to ``OUT/<setting>.jsonl``; runs already there are not run again, so a sweep can be
stopped and resumed, and the analyses (``--report``, ``benchmarks/section5_lag.py``)
read the files without rerunning anything.

    .venv/bin/python benchmarks/section5_study.py --settings default dwell=5 --seeds 100
    .venv/bin/python benchmarks/section5_study.py --report --settings default dwell=5
    .venv/bin/python benchmarks/section5_study.py --write --settings default dwell=5

``--write`` puts the table into docs/section5.md between markers naming this script.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import math
import statistics
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from nest_beacon.core.beacon import BeaconConfig  # noqa: E402
from robot_agent.core import ports  # noqa: E402
from robot_agent.core.beliefs import Beliefs  # noqa: E402
from robot_agent.core.controller import Controller, ControllerConfig  # noqa: E402
from world_server.core.body import EpuckSpec  # noqa: E402
from world_server.core.world import WorldConfig  # noqa: E402

DEFAULT_OUT = Path("/tmp/section5-study")
SITES = (5, 8, 10)


# --- settings --------------------------------------------------------------------------


def _fields(cls: type) -> dict[str, object]:
    return {field.name: field.type for field in dataclasses.fields(cls)}


def _value(text: str) -> Any:
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def parse_setting(setting: str) -> dict[str, dict[str, Any]]:
    """``field=value,...`` -> overrides by config: controller, beacon, world, spec."""
    overrides: dict[str, dict[str, Any]] = {"controller": {}, "beacon": {}, "world": {}, "spec": {}}
    if setting == "default":
        return overrides
    for item in setting.split(","):
        name, sep, text = item.partition("=")
        if not sep:
            raise ValueError(f"{item!r} is not field=value")
        value = _value(text)
        if name in _fields(ControllerConfig):
            overrides["controller"][name] = value
        elif name.startswith("beacon_") and name[7:] in _fields(BeaconConfig):
            overrides["beacon"][name[7:]] = value
        elif name in _fields(WorldConfig):
            overrides["world"][name] = value
        elif name in _fields(EpuckSpec):
            overrides["spec"][name] = value
        else:
            raise ValueError(f"no setting named {name!r}")
    return overrides


def configs(
    setting: str, sites: int, seed: int, robots: int
) -> tuple[WorldConfig, ControllerConfig, BeaconConfig]:
    overrides = parse_setting(setting)
    spec = dataclasses.replace(EpuckSpec(), **overrides["spec"])
    world = WorldConfig(
        run="section5-study",
        seed=seed,
        num_sites=sites,
        num_robots=robots,
        spec=spec,
        **overrides["world"],
    )
    controller = ControllerConfig(**overrides["controller"])
    beacon = BeaconConfig(**overrides["beacon"])
    return world, controller, beacon


# --- one observed run ------------------------------------------------------------------


def support_mask(opinion: Sequence[float]) -> int:
    """The sites still held possible (probability > 0), as a bit mask."""
    return sum(1 << index for index, value in enumerate(opinion) if value > 0.0)


class Observed(Controller):
    """A Controller that logs its poolings and, when it decides, a snapshot of all robots.

    ``registry`` (set per run) holds every robot's controller and the run's event lists.
    """

    registry: dict[str, Any] = {}  # noqa: RUF012 - one run per worker process at a time

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        self.last_xy = (reading.x, reading.y)
        return super().step(reading, received)

    def _pool_and_decide(self, reading: ports.BodyReading) -> None:
        since = self._nest_arrival - 1e-9
        assert isinstance(self._beliefs, Beliefs)  # the study runs the paper's strategy
        heard = self._beliefs.heard
        partners = sorted(robot for robot, (when, _) in heard.items() if when >= since)
        partner_masks = [support_mask(heard[robot][1]) for robot in partners]
        before = support_mask(self.opinion)
        super()._pool_and_decide(reading)
        self.registry["poolings"].append(
            [
                self.robot_id,
                round(self._t, 2),
                self.trips,
                len(partners) + 1,
                partners,
                before,
                partner_masks,
                support_mask(self.opinion),
                round(self._nest_arrival, 2),
            ]
        )
        if self.decided_site is not None:
            snapshot = [
                [
                    other.robot_id,
                    other.phase,
                    round(math.hypot(*getattr(other, "last_xy", (0.0, 0.0))), 3),
                    support_mask(other.opinion),
                    other.trips,
                ]
                for other in self.registry["controllers"]
            ]
            self.registry["decisions"].append(
                [self.robot_id, round(self._t, 2), self.trips, snapshot]
            )


def observed_factory(registry: dict[str, Any]) -> type[Controller]:
    class Registered(Observed):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            registry["controllers"].append(self)

    Registered.registry = registry
    return Registered


def run_one(task: tuple[str, int, int, int]) -> dict[str, Any]:
    """One run of (setting, n, seed, robots), observed; the JSON line of the study."""
    from deploy.inprocess.engine import run_in_process

    setting, sites, seed, robots = task
    world, controller, beacon = configs(setting, sites, seed, robots)
    registry: dict[str, Any] = {"controllers": [], "poolings": [], "decisions": []}
    started = time.perf_counter()
    summary = run_in_process(
        world, controller, beacon, controller_factory=observed_factory(registry)
    )
    wall = time.perf_counter() - started
    return {
        "setting": setting,
        "n": sites,
        "seed": seed,
        "robots": robots,
        "ended": summary["ended"],
        "correct": summary["correct"],
        "best": summary["best_site"],
        "sim_time_s": summary["sim_time_s"],
        "wall_s": round(wall, 2),
        "per_robot": [
            {
                "id": robot["id"],
                "steps": robot["steps"],
                "decision_time_s": robot["decision_time_s"],
                "pools": robot["pool_sizes"],
            }
            for robot in summary["per_robot"]
        ],
        "poolings": registry["poolings"],
        "decisions": registry["decisions"],
    }


# --- many runs -------------------------------------------------------------------------


def result_path(out: Path, setting: str, robots: int) -> Path:
    name = setting.replace("=", "-").replace(",", "+").replace("/", "_")
    suffix = "" if robots == 10 else f"-N{robots}"
    return out / f"{name}{suffix}.jsonl"


def load(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        if line.strip():
            records.append(json.loads(line))
    return records


def run_setting(
    setting: str, seeds: Sequence[int], sites: Sequence[int], *, robots: int, out: Path, jobs: int
) -> None:
    path = result_path(out, setting, robots)
    done = {(record["n"], record["seed"]) for record in load(path)}
    tasks = [(setting, n, seed, robots) for seed in seeds for n in sites if (n, seed) not in done]
    if not tasks:
        print(f"{setting}: all {len(done)} runs already in {path}", file=sys.stderr)
        return
    started = time.perf_counter()
    with path.open("a") as sink:
        for index, record in enumerate(_results(tasks, jobs), start=1):
            sink.write(json.dumps(record, separators=(",", ":")) + "\n")
            sink.flush()
            if index % 25 == 0 or index == len(tasks):
                elapsed = time.perf_counter() - started
                print(
                    f"{setting}: {index}/{len(tasks)} runs, {elapsed:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )


def _results(tasks: Sequence[tuple[str, int, int, int]], jobs: int) -> Iterator[dict[str, Any]]:
    if jobs <= 1:
        yield from map(run_one, tasks)
        return
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs) as pool:
        yield from pool.map(run_one, tasks, chunksize=1)


# --- report ----------------------------------------------------------------------------


def swarm_steps(record: dict[str, Any]) -> int | None:
    steps = [robot["steps"] for robot in record["per_robot"]]
    if record["ended"] != "consensus" or any(step is None for step in steps):
        return None
    return max(steps)


def quartiles(values: Sequence[float]) -> tuple[float, float, float]:
    q1, median, q3 = statistics.quantiles(values, n=4, method="inclusive")
    return q1, median, q3


def row(records: Sequence[dict[str, Any]], n: int) -> dict[str, Any]:
    runs = [record for record in records if record["n"] == n]
    swarm = [swarm_steps(record) for record in runs]
    finished = [value for value in swarm if value is not None]
    pools = [size for record in runs for robot in record["per_robot"] for size in robot["pools"]]
    run_pool_means = [
        statistics.fmean(sizes)
        for record in runs
        if (sizes := [size for robot in record["per_robot"] for size in robot["pools"]])
    ]
    paper = [swarm_steps(record) for record in runs if record["seed"] < 10]
    robot_steps = [
        robot["steps"] for record in runs for robot in record["per_robot"] if robot["steps"]
    ]
    times = [record["sim_time_s"] for record in runs if swarm_steps(record) is not None]
    q1, median, q3 = quartiles(finished) if len(finished) >= 2 else (math.nan,) * 3
    return {
        "n": n,
        "runs": len(runs),
        "consensus": len(finished),
        "correct": sum(record["correct"] for record in runs),
        "within": sum(value <= n / 2 for value in finished) / max(len(runs), 1),
        "below": sum(value < n / 2 for value in finished) / max(len(runs), 1),
        "median": median,
        "q1": q1,
        "q3": q3,
        "mean_swarm": statistics.fmean(finished) if finished else math.nan,
        "robot_mean": statistics.fmean(robot_steps) if robot_steps else math.nan,
        "pool_mean": statistics.fmean(pools) if pools else math.nan,
        "run_pool_max": max(run_pool_means) if run_pool_means else math.nan,
        "run_pool_over3": sum(mean > 3 for mean in run_pool_means),
        "alone": sum(size == 1 for size in pools) / max(len(pools), 1),
        "paper_within": sum(value is not None and value <= n / 2 for value in paper),
        "paper_below": sum(value is not None and value < n / 2 for value in paper),
        "paper_runs": len(paper),
        "time": statistics.fmean(times) if times else math.nan,
    }


def report(settings: Sequence[str], robots: int, out: Path) -> None:
    header = (
        f"{'setting':34} {'n':>3} {'runs':>4} {'ok':>4} {'within':>6} {'below':>6} "
        f"{'med':>4} {'IQR':>7} {'mean':>5} {'robot':>5} {'pool':>5} {'maxrun':>6} "
        f"{'>3':>3} {'alone':>5} {'paper':>7} {'time':>6}"
    )
    print(header)
    for setting in settings:
        records = load(result_path(out, setting, robots))
        for n in sorted({record["n"] for record in records}):
            r = row(records, n)
            print(
                f"{setting[:34]:34} {n:>3} {r['runs']:>4} {r['correct']:>4} "
                f"{r['within']:>6.2f} {r['below']:>6.2f} {r['median']:>4g} "
                f"{r['q1']:>3g}-{r['q3']:<3g} {r['mean_swarm']:>5.2f} {r['robot_mean']:>5.2f} "
                f"{r['pool_mean']:>5.2f} {r['run_pool_max']:>6.2f} {r['run_pool_over3']:>3} "
                f"{r['alone']:>5.2f} {r['paper_within']:>3}/{r['paper_below']:<3} "
                f"{r['time']:>6.1f}"
            )


STUDY_BLOCK = "study"
STUDY_DOC = REPO / "docs" / "section5.md"


def describe(setting: str) -> str:
    """A setting as the table shows it: the override, or ``defaults``."""
    return "defaults" if setting == "default" else f"`{setting}`"


def markdown(settings: Sequence[str], robots: int, out: Path) -> str:
    """The study table: one line per setting and n, from the runs in ``out``."""
    lines = [
        "| setting | n | runs | right | swarm steps median (IQR) | mean | within n/2 "
        "| strictly below | mean pool | runs with mean pool > 3 | pooled alone "
        "| sim s to consensus |",
        "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for setting in settings:
        records = load(result_path(out, setting, robots))
        for n in sorted({record["n"] for record in records}):
            r = row(records, n)
            missing = r["runs"] - r["consensus"]
            right = f"{r['correct']}" + (f" ({missing} without consensus)" if missing else "")
            lines.append(
                f"| {describe(setting)} | {n} | {r['runs']} | {right} "
                f"| {r['median']:g} ({r['q1']:g}-{r['q3']:g}) | {r['mean_swarm']:.2f} "
                f"| {r['within']:.0%} | {r['below']:.0%} | {r['pool_mean']:.2f} "
                f"| {r['run_pool_over3']} | {r['alone']:.0%} | {r['time']:.0f} |"
            )
    return "\n".join(lines)


def write_markdown(settings: Sequence[str], robots: int, out: Path, doc: Path) -> None:
    """Put the study table into ``doc`` between the markers naming this script."""
    from deploy.reports.section5 import replace_block

    command = "benchmarks/section5_study.py --write"
    table = markdown(settings, robots, out)
    words = " ".join(settings)
    table += (
        f"\n\nMade by `.venv/bin/python benchmarks/section5_study.py --write --settings "
        f"{words}` from the runs that the same command without `--write` made "
        f"(in-process lockstep runs, {robots} robots, seeds from 0)."
    )
    edit = "benchmarks/section5_study.py"
    doc.write_text(replace_block(doc.read_text(), STUDY_BLOCK, table, command, edit))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--settings", nargs="+", default=["default"], metavar="SETTING")
    parser.add_argument("--seeds", type=int, default=100, help="seeds 0..S-1 (default: 100)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--sites", type=int, nargs="+", default=list(SITES))
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default: 2)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--report", action="store_true", help="only print the table")
    parser.add_argument(
        "--write",
        action="store_true",
        help="no runs: put the table of the given settings into docs/section5.md",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for setting in args.settings:
        parse_setting(setting)  # fail on a typo before any run
    args.out.mkdir(parents=True, exist_ok=True)
    if args.write:
        write_markdown(args.settings, args.robots, args.out, STUDY_DOC)
        print(f"wrote the {STUDY_BLOCK!r} block of {STUDY_DOC}", file=sys.stderr)
        return 0
    if not args.report:
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        for setting in args.settings:
            run_setting(
                setting, seeds, args.sites, robots=args.robots, out=args.out, jobs=args.jobs
            )
    report(args.settings, args.robots, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
