"""What the study ``strategies`` runs and what its runs give, read by its tables, figure and
text (``strategies.py``, ``strategies_prose.py``): the strategies, options and sizes of its
grid, and the rows of its two tables (the well-stirred cells, the swarm's points)."""

from __future__ import annotations

from typing import Any

from deploy.study import tables
from deploy.study.declare import Records

STRATEGIES = ("paper", "dmvd", "dmmd", "dc")
WELLSTIRRED_OPTIONS = (5, 10, 20, 50, 100)
SITES = (5, 8, 10, 20)
DROPS = (0.0, 0.2)
SEEDS = {10: range(20), 50: range(10)}
TIMEOUT = 2400.0  # sim seconds


def wellstirred_rows(records: Records) -> list[dict[str, Any]]:
    rows = []
    for strategy in STRATEGIES:
        for n in WELLSTIRRED_OPTIONS:
            for record in records.where(part="wellstirred", strategy=strategy, options=n):
                result = tables.result(record)
                times, success = result["times"], result["success"]
                good = sorted(t for t, ok in zip(times, success, strict=True) if ok)
                rows.append(
                    {
                        "strategy": strategy,
                        "n": n,
                        "runs": len(times),
                        "correct": sum(success),
                        "times": good,
                        "median": tables.median(good),
                        "q1": _quartile(good, 0),
                        "q3": _quartile(good, 2),
                    }
                )
    return rows


def _quartile(values: list[int], which: int) -> float | None:
    import statistics

    return float(statistics.quantiles(values, n=4)[which]) if len(values) > 1 else None


def swarm_rows(records: Records) -> list[dict[str, Any]]:
    runs = [record for record in records.runs if record["params"]["part"] == "swarm"]
    grouped = tables.groups(runs, "robots", "sites", "drop", "strategy")
    rows = []
    for (robots, sites, drop, strategy), group in sorted(
        grouped.items(), key=lambda item: (*item[0][:3], STRATEGIES.index(item[0][3]))
    ):
        right = [tables.result(run) for run in group if tables.result(run)["verdict"] == "correct"]
        rows.append(
            {
                "robots": robots,
                "n": sites,
                "drop": drop,
                "strategy": strategy,
                "runs": len(group),
                **{verdict: tables.count(group, verdict) for verdict in tables.VERDICTS},
                "times": [result["sim_time_s"] for result in right],
                "by_seed": {
                    run["seed"]: tables.result(run)["sim_time_s"]
                    for run in group
                    if tables.result(run)["verdict"] == "correct"
                },
                "median": tables.median(result["sim_time_s"] for result in right),
                "steps": tables.median(
                    result["slowest_steps"]
                    for result in right
                    if result["slowest_steps"] is not None
                ),
            }
        )
    return rows
