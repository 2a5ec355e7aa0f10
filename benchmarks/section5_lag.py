"""Why the last robot lags: the paper's diagnosis measured on our swarm.

Reads the observed runs of ``benchmarks/section5_study.py`` (one JSON line per run:
every pooling with its members and the sites each still held possible, and at every
decision a snapshot of all robots) and measures, per n:

* pool sizes per trip, and how often a robot pools alone, for the run's last robot (the
  one that sets the swarm's steps) against the others;
* where the last robot was when each of the others decided (at the nest, so it could
  have pooled with them, or out on a trip) and how many trips it made after every other
  robot had decided (alone at the nest, it can then only eliminate one site a trip);
* how much evidence leaves with the decided robots: after each decision, how many
  non-best sites the undecided robots, all together, still hold possible. Each decided
  robot has eliminated every non-best site; a site the undecided robots cannot rule out
  between them is evidence that left with the decided ones and must be found again.

Prints the tables; with ``--write`` also writes docs/section5-lag.png, docs/section5-lag.json
(the numbers behind both) and the tables into docs/section5.md, between markers naming
this command:

    .venv/bin/python benchmarks/section5_study.py --settings default --seeds 100
    .venv/bin/python benchmarks/section5_lag.py --setting default --write
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.section5_study import DEFAULT_OUT, load, result_path  # noqa: E402

AT_NEST = ("at_nest", "waiting")


def popcount(mask: int) -> int:
    return bin(mask).count("1")


def last_robot(record: dict[str, Any]) -> int:
    """The robot that set the swarm's steps: most steps, then the latest decision."""
    robots = record["per_robot"]
    best = max(robots, key=lambda robot: (robot["steps"], robot["decision_time_s"]))
    return int(best["id"])


def analyse_run(record: dict[str, Any]) -> dict[str, Any]:
    """The lag measures of one run that ended in consensus."""
    n = record["n"]
    last = last_robot(record)
    swarm_steps = max(robot["steps"] for robot in record["per_robot"])
    poolings = record["poolings"]
    last_pools = [pooling for pooling in poolings if pooling[0] == last]
    other_pools = [pooling for pooling in poolings if pooling[0] != last]
    # Where the last robot was as each other robot decided.
    phases: Counter[str] = Counter()
    distances = []
    undecided_missing: list[tuple[int, int]] = []  # (robots decided so far, sites missing)
    own_missing: list[tuple[int, float]] = []
    for order, (robot, _t, _trips, snapshot) in enumerate(record["decisions"], start=1):
        undecided = [entry for entry in snapshot if popcount(entry[3]) > 1]
        if robot != last:
            entry = next(entry for entry in snapshot if entry[0] == last)
            phases[_phase_group(entry[1])] += 1
            distances.append(entry[2])
        if undecided:
            together = undecided[0][3]
            for entry in undecided[1:]:
                together &= entry[3]
            undecided_missing.append((order, popcount(together) - 1))
            own_missing.append(
                (order, statistics.fmean(popcount(entry[3]) - 1 for entry in undecided))
            )
    # Trips the last robot made after every other robot had decided.
    others_done = max(
        (robot["decision_time_s"] for robot in record["per_robot"] if robot["id"] != last),
        default=0.0,
    )
    trips_after = sum(1 for pooling in last_pools if pooling[1] > others_done + 1e-6)
    return {
        "n": n,
        "seed": record["seed"],
        "swarm_steps": swarm_steps,
        "late": swarm_steps > n / 2,
        "last": last,
        "last_pools": [pooling[3] for pooling in last_pools],
        "other_pools": [pooling[3] for pooling in other_pools],
        "last_pools_by_trip": [(pooling[2], pooling[3]) for pooling in last_pools],
        "other_pools_by_trip": [(pooling[2], pooling[3]) for pooling in other_pools],
        "last_phases": dict(phases),
        "last_distances": distances,
        "undecided_missing": undecided_missing,
        "own_missing": own_missing,
        "trips_after_others": trips_after,
        "last_robot_steps": swarm_steps,
        "median_steps": statistics.median(robot["steps"] for robot in record["per_robot"]),
    }


def _phase_group(phase: str) -> str:
    if phase in AT_NEST:
        return "at the nest"
    if phase == "to_nest":
        return "on its way back"
    return "at or going to a site"


def summarise(runs: Sequence[dict[str, Any]], n: int) -> dict[str, Any]:
    mine = [run for run in runs if run["n"] == n]
    last_pools = [size for run in mine for size in run["last_pools"]]
    other_pools = [size for run in mine for size in run["other_pools"]]
    phases: Counter[str] = Counter()
    for run in mine:
        phases.update(run["last_phases"])
    total_phases = sum(phases.values()) or 1
    by_decided: dict[int, list[int]] = {}
    own_by_decided: dict[int, list[float]] = {}
    for run in mine:
        for order, missing in run["undecided_missing"]:
            by_decided.setdefault(order, []).append(missing)
        for order, missing in run["own_missing"]:
            own_by_decided.setdefault(order, []).append(missing)
    late = [run for run in mine if run["late"]]
    return {
        "last_pool_by_trip": _by_trip(mine, "last_pools_by_trip"),
        "other_pool_by_trip": _by_trip(mine, "other_pools_by_trip"),
        "n": n,
        "runs": len(mine),
        "late_runs": len(late),
        "last_pool_mean": _mean(last_pools),
        "other_pool_mean": _mean(other_pools),
        "last_alone": _share(last_pools, 1),
        "other_alone": _share(other_pools, 1),
        "last_phases": {name: phases[name] / total_phases for name in sorted(phases)},
        "trips_after_others_mean": _mean([run["trips_after_others"] for run in mine]),
        "trips_after_others_late": _mean([run["trips_after_others"] for run in late]),
        "runs_with_lone_finish": sum(1 for run in mine if run["trips_after_others"] > 0),
        "gap_steps_mean": _mean([run["last_robot_steps"] - run["median_steps"] for run in mine]),
        "undecided_missing": {order: _mean(values) for order, values in sorted(by_decided.items())},
        "undecided_missing_share": {
            order: sum(1 for value in values if value > 0) / len(values)
            for order, values in sorted(by_decided.items())
        },
        "own_missing": {order: _mean(values) for order, values in sorted(own_by_decided.items())},
    }


def _by_trip(runs: Sequence[dict[str, Any]], key: str) -> dict[int, float | None]:
    """Mean pool size by trip (pool sizes over time), trips with at least 20 poolings."""
    sizes: dict[int, list[int]] = {}
    for run in runs:
        for trip, size in run[key]:
            sizes.setdefault(trip, []).append(size)
    return {trip: _mean(values) for trip, values in sorted(sizes.items()) if len(values) >= 20}


def _mean(values: Sequence[float]) -> float | None:
    return round(statistics.fmean(values), 3) if values else None


def _share(values: Sequence[int], target: int) -> float | None:
    return round(sum(1 for value in values if value == target) / len(values), 3) if values else None


def plot(summaries: Sequence[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for index, summary in enumerate(summaries):
        orders = sorted(summary["undecided_missing"])
        colour = f"C{index}"  # one colour per n: solid together, dashed alone
        left.plot(
            orders,
            [summary["undecided_missing"][order] for order in orders],
            color=colour,
            marker="o",
            label=f"n = {summary['n']}: all undecided together",
        )
        left.plot(
            orders,
            [summary["own_missing"][order] for order in orders],
            color=colour,
            linestyle="--",
            marker=".",
            label=f"n = {summary['n']}: an undecided robot alone",
        )
    left.set_xlabel("robots decided (and gone)")
    left.set_ylabel("non-best sites still held possible")
    left.set_title("(a) evidence left among the undecided robots")
    left.legend(fontsize=7)
    left.set_ylim(bottom=0)
    groups = ["at the nest", "on its way back", "at or going to a site"]
    width = 0.25
    for index, summary in enumerate(summaries):
        shares = [summary["last_phases"].get(group, 0.0) for group in groups]
        right.bar(
            [position + (index - 1) * width for position in range(len(groups))],
            shares,
            width,
            color=f"C{index}",
            label=f"n = {summary['n']}",
        )
    right.set_xticks(range(len(groups)), groups)
    right.set_ylabel("share of the other robots' decisions")
    right.set_title("(b) where the last robot was when another decided")
    right.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def tables(summaries: Sequence[dict[str, Any]]) -> str:
    """The Markdown that docs/section5.md shows, from the summaries."""
    lines = [
        "| n | runs | runs over n/2 | last robot: mean pool, pooled alone "
        "| the others: mean pool, pooled alone | last robot at the nest when another decided "
        "| runs the last robot finished alone | its trips after all others decided (mean) |",
        "|---|---:|---:|---|---|---:|---:|---:|",
    ]
    for s in summaries:
        lines.append(
            f"| {s['n']} | {s['runs']} | {s['late_runs']} | {s['last_pool_mean']:.2f}, "
            f"{s['last_alone']:.0%} | {s['other_pool_mean']:.2f}, {s['other_alone']:.0%} | "
            f"{s['last_phases'].get('at the nest', 0.0):.0%} | {s['runs_with_lone_finish']} | "
            f"{s['trips_after_others_mean']:.2f} |"
        )
    lines += ["", "Mean pool size by trip (pool sizes over time), the last robot (the others):", ""]
    for s in summaries:
        cells = ", ".join(
            f"{trip}: {size:.2f} ({_format(s['other_pool_by_trip'].get(trip))})"
            for trip, size in s["last_pool_by_trip"].items()
        )
        lines.append(f"* n = {s['n']}, trip {cells}")
    lines += [
        "",
        "Non-best sites that no undecided robot has ruled out (the undecided robots all "
        "together; in brackets, one undecided robot on its own), after the k-th decision:",
        "",
    ]
    for s in summaries:
        cells = ", ".join(
            f"{order}: {s['undecided_missing'][order]:.2f} ({s['own_missing'][order]:.2f})"
            for order in sorted(s["undecided_missing"])
        )
        lines.append(f"* n = {s['n']}, k = {cells}")
    return "\n".join(lines)


def _format(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--setting", default="default")
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--results", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--figure", type=Path, default=REPO / "docs" / "section5-lag.png")
    parser.add_argument("--json", type=Path, default=REPO / "docs" / "section5-lag.json")
    parser.add_argument(
        "--write",
        action="store_true",
        help="write the figure, the JSON and the tables' block in docs/section5.md "
        "(otherwise only print the tables)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    records = load(result_path(args.results, args.setting, args.robots))
    runs = [analyse_run(record) for record in records if record["ended"] == "consensus"]
    if not runs:
        print(f"no finished runs for {args.setting} in {args.results}", file=sys.stderr)
        return 1
    summaries = [summarise(runs, n) for n in sorted({run["n"] for run in runs})]
    text = tables(summaries)
    print(text)
    if args.write:
        from deploy.reports.section5 import replace_block

        plot(summaries, args.figure)
        args.json.write_text(json.dumps(summaries, indent=1) + "\n")
        command = f"benchmarks/section5_lag.py --setting {args.setting} --write"
        doc = REPO / "docs" / "section5.md"
        edit = "benchmarks/section5_lag.py"
        doc.write_text(replace_block(doc.read_text(), "lag", text, command, edit))
        print(f"wrote {args.figure}, {args.json} and the 'lag' block of {doc}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
