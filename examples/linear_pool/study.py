"""The study ``linear-pool``: the linear opinion pool (this package's ``linear``) against the
paper's product operator (``mprodop``), in the paper's Section 5 swarm: 10 robots, 5 sites,
the paper's strategy (negative updating, alpha = 0) with either pooling operator, seeds
0-19, given up at 1800 sim s. Each run is ``swarm run --robots 10 --sites 5 --pooling P
--seed S --timeout 1800`` in one process.

    swarm study linear-pool --declared examples/linear_pool/study.py \
        --root examples/linear_pool [--render]

The results file is ``results/linear-pool.jsonl`` under the root (each run's row says
which plug-in made it: name, version, source hash); the page is ``linear-pool.md``.
"""

from __future__ import annotations

from typing import Any

from deploy.analysis.wilson import share
from deploy.study import tables
from deploy.study.declare import Page, Records, Study
from deploy.study.grid import Point

POOLINGS = ("mprodop", "linear")  # the paper's operator first: the baseline
ROBOTS, SITES, SEEDS, TIMEOUT = 10, 5, range(20), 1800.0


def points() -> list[Point]:
    return [
        Point(
            {"pooling": pooling},
            SEEDS,
            options=["--robots", str(ROBOTS), "--sites", str(SITES), "--pooling", pooling],
            timeout=TIMEOUT,
            cost=5.0,
        )
        for pooling in POOLINGS
    ]


def rows(records: Records) -> list[dict[str, Any]]:
    """One row per pooling operator: its runs' verdicts and times to consensus."""
    found = []
    for pooling in POOLINGS:
        group = records.where(pooling=pooling)
        right = {
            run["seed"]: tables.result(run)
            for run in group
            if tables.result(run)["verdict"] == "correct"
        }
        found.append(
            {
                "pooling": pooling,
                "runs": len(group),
                **{verdict: tables.count(group, verdict) for verdict in tables.VERDICTS},
                "by_seed": {seed: result["sim_time_s"] for seed, result in right.items()},
                "median": tables.median(result["sim_time_s"] for result in right.values()),
                "steps": tables.median(
                    result["slowest_steps"]
                    for result in right.values()
                    if result["slowest_steps"] is not None
                ),
                "plugin": _plugin(group, pooling),
            }
        )
    return found


def _plugin(group: list[dict[str, Any]], pooling: str) -> str:
    """The pooling operator as the runs' rows record it: its distribution, version, source."""
    made = {
        (plugin.get("distribution"), plugin.get("version"), plugin.get("source"))
        for run in group
        if (plugin := (run.get("plugins") or {}).get("pooling"))
    }
    return (
        "; ".join(
            f"{name or 'not installed'} {version or ''} (source {source})".replace("  ", " ")
            for name, version, source in sorted(made, key=str)
        )
        or pooling
    )


def table(records: Records) -> str:
    lines = [
        "| pooling | runs | right (95% interval) | wrong | split | undecided | sim s to "
        "consensus, median (right runs) | against the product: ratio of medians (95% "
        "interval) | trips of the last robot, median |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    found = rows(records)
    baseline = found[0]
    for row in found:
        runs = row["runs"]
        against = (
            "1 (the baseline)"
            if row is baseline
            else tables.compare_times(row["by_seed"], baseline["by_seed"])
        )
        lines.append(
            f"| {row['pooling']} | {runs} | {share(row['correct'], runs)} "
            f"| {tables.counted(row['wrong'], runs)} | {tables.counted(row['split'], runs)} "
            f"| {tables.counted(row['undecided'], runs)} | {tables.number(row['median'])} "
            f"| {against} | {tables.number(row['steps'], 1)} |"
        )
    return "\n".join(lines)


def made_with(records: Records) -> str:
    return "\n".join(f"* `{row['pooling']}`: {row['plugin']}" for row in rows(records))


STUDY = Study(
    name="linear-pool",
    title="a linear opinion pool against the product",
    about="the paper's swarm (10 robots, 5 sites) pooling by the linear pool or by MProdOp",
    points=points,
    source="examples/linear_pool/study.py",
    pages=(
        Page(
            "linear-pool.md",
            lambda records: {"table": table(records), "plugins": made_with(records)},
        ),
    ),
    results_file="results/linear-pool.jsonl",
)
