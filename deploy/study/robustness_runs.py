"""What the study ``robustness`` runs and what its runs give, read by its tables, figures
and text (``robustness.py``, ``robustness_prose.py``): the grid's levels and controllers,
a point's summary (accuracy, failures, consensus times, judged comparisons) and the 30%
loss claim seed by seed."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Any

from deploy.analysis import effects
from deploy.study import tables
from deploy.study.declare import Records

ROBOTS, SITES = 10, 10
TIMEOUT = 1800.0  # sim seconds
DROPS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)
CLAIM_DROP = 0.3
SIGMAS = (0.0, 100.0, 120.0, 140.0, 150.0, 160.0, 170.0, 180.0)
FAILING = (150.0, 160.0, 170.0, 180.0)  # the levels run with 40 seeds
SENSING_SIGMAS = (0.0, 60.0, 100.0, 120.0, 140.0, 150.0, 160.0, 170.0, 180.0)
LIGHTING = 0.3
LIGHTING_SIGMAS = (0.0, 100.0)
SEEDS = range(10)
MORE_SEEDS = range(40)


@dataclass(frozen=True)
class Setup:
    """A controller set-up of the noise sweep, as ``swarm run`` options."""

    key: str
    label: str
    options: tuple[str, ...]


SETUPS = (
    Setup("alpha0", "α = 0, MProdOp (paper)", ()),
    Setup("alpha01", "α = 0.1, MProdOp", ("--alpha", "0.1", "--threshold", "0.99")),
    Setup(
        "loglinear",
        "α = 0.1, log-linear pool",
        ("--alpha", "0.1", "--threshold", "0.99", "--pooling", "loglinear"),
    ),
)
LABELS = {setup.key: setup.label for setup in SETUPS}


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """A point's runs: accuracy, failures, consensus times and comparisons."""
    results = [tables.result(run) for run in runs]
    times = [result["sim_time_s"] for result in results if result["consensus"]]
    by_seed = {
        run["seed"]: result["sim_time_s"]
        for run, result in zip(runs, results, strict=True)
        if result["consensus"]
    }
    comparisons = sum(result["comparisons"] for result in results)
    return {
        "runs": len(results),
        "correct": sum(result["correct"] for result in results),
        "wrong": sum(result["consensus"] and not result["correct"] for result in results),
        "split": sum(not result["consensus"] for result in results),
        "times": times,
        "by_seed": by_seed,
        "time_mean": tables.mean(times),
        "time_median": tables.median(times),
        "time_max": max(times) if times else None,
        "comparisons": comparisons / len(results),
        "wrong_share": sum(result["wrong_comparisons"] for result in results) / max(comparisons, 1),
        "wrong_interval": effects.clustered_share(
            [result["wrong_comparisons"] for result in results],
            [result["comparisons"] for result in results],
        ),
        "best_eliminated": sum(result["best_eliminated"] for result in results) / len(results),
    }


def claim_numbers(records: Records) -> dict[str, Any] | None:
    """The 30% claim, drop 0.3 against drop 0 seed by seed: what the claim block and the
    page's findings say (None before those runs are made)."""
    clean = {run["seed"]: tables.result(run) for run in records.where(sweep="drop", drop=0.0)}
    lossy = {
        run["seed"]: tables.result(run) for run in records.where(sweep="drop", drop=CLAIM_DROP)
    }
    seeds = sorted(set(clean) & set(lossy))
    if not seeds:
        return None
    before = [clean[seed]["sim_time_s"] for seed in seeds]
    after = [lossy[seed]["sim_time_s"] for seed in seeds]
    ratios = [b / a for a, b in zip(before, after, strict=True)]
    return {
        "seeds": seeds,
        "right_clean": sum(clean[s]["correct"] for s in seeds),
        "right_lossy": sum(lossy[s]["correct"] for s in seeds),
        "median_clean": statistics.median(before),
        "median_lossy": statistics.median(after),
        "ratio": effects.paired_median_ratio(
            {seed: lossy[seed]["sim_time_s"] for seed in seeds},
            {seed: clean[seed]["sim_time_s"] for seed in seeds},
        ),
        "per_seed": (min(ratios), max(ratios)),
    }
