"""What the study ``section5-settings`` runs and what its runs give, read by its tables,
figure and text (``section5_settings.py``, ``section5_prose.py``): the settings and sizes of
its grid, a point's row of the settings table, and the lag measures of the observed
default runs, per n (``lag.py``)."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from typing import Any

from deploy.analysis import effects
from deploy.study import lag, tables
from deploy.study.declare import Records

ROBOTS = 10
SITES = (5, 8, 10)
SEEDS = range(100)
TIMEOUT = 1800.0  # sim seconds: swarm run's default
SETTINGS = (
    "default",
    "dwell=1.5",
    "dwell=4",
    "dwell=4.5",
    "dwell=6",
    "dwell=10",
    "broadcast_period=0.1",
    "broadcast_period=1",
    "beacon_period=5",
    "beacon_range=0.3",
    "max_wheel_speed=0.065",
)


def swarm_steps(result: dict[str, Any]) -> int | None:
    steps = result["robots"]["steps"]
    if result["ended"] != "consensus" or any(step is None for step in steps):
        return None
    return int(max(steps))


def row(runs: Sequence[dict[str, Any]], n: int) -> dict[str, Any]:
    results = [tables.result(run) for run in runs]
    finished = [value for result in results if (value := swarm_steps(result)) is not None]
    pools = [size for result in results for robot in result["robots"]["pools"] for size in robot]
    run_pool_means = [
        statistics.fmean(sizes)
        for result in results
        if (sizes := [size for robot in result["robots"]["pools"] for size in robot])
    ]
    times = [result["sim_time_s"] for result in results if swarm_steps(result) is not None]
    per_run = [
        [size for robot in result["robots"]["pools"] for size in robot] for result in results
    ]
    if len(finished) >= 2:
        q1, median, q3 = statistics.quantiles(finished, n=4, method="inclusive")
    else:  # one run: its value; none: nothing
        q1 = median = q3 = float(finished[0]) if finished else math.nan
    return {
        "runs": len(results),
        "consensus": len(finished),
        "correct": sum(result["correct"] for result in results),
        "within": sum(value <= n / 2 for value in finished),
        "below": sum(value < n / 2 for value in finished),
        "median": median,
        "q1": q1,
        "q3": q3,
        "mean_swarm": tables.mean(finished),
        "pool_mean": tables.mean(pools),
        "run_pool_over3": sum(mean > 3 for mean in run_pool_means),
        "alone": sum(size == 1 for size in pools) / max(len(pools), 1),
        "alone_interval": effects.clustered_share(
            [sum(size == 1 for size in sizes) for sizes in per_run], [len(s) for s in per_run]
        ),
        "time": tables.mean(times),
        "times": {
            run["seed"]: result["sim_time_s"]
            for run, result in zip(runs, results, strict=True)
            if swarm_steps(result) is not None
        },
    }


def lag_summaries(records: Records) -> list[dict[str, Any]]:
    summaries = []
    for n in SITES:
        analysed = lag_analyses(records, n)
        if analysed:
            summaries.append(lag.summarise(analysed, n))
    return summaries


def lag_analyses(records: Records, n: int) -> list[dict[str, Any]]:
    """The lag measures of each observed default run of ``n`` (``lag.analyse``)."""
    return [
        found
        for run in records.where(setting="default", sites=n)
        if (found := tables.result(run).get("lag")) is not None
    ]
