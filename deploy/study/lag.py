"""Why the last robot lags: the paper's diagnosis measured on observed runs.

A run observed by ``observe.pooling_controller`` yields every pooling (its members and the
sites each still held possible) and, at every decision, a snapshot of all robots.
``analyse`` turns one run into its lag measures (kept in the results file, one run a
line); ``summarise`` gathers them per n:

* pool sizes per trip, and how often a robot pools alone, for the run's last robot (the
  one that sets the swarm's steps) against the others;
* where the last robot was when each of the others decided (at the nest, so it could have
  pooled with them, or out on a trip) and how many trips it made after every other robot
  had decided (alone at the nest, it can then only eliminate one site a trip);
* how much evidence leaves with the decided robots: after each decision, how many
  non-best sites the undecided robots, all together, still hold possible.
"""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Sequence
from typing import Any

AT_NEST = ("at_nest", "waiting")
GROUPS = ("at the nest", "on its way back", "at or going to a site")


def popcount(mask: int) -> int:
    return bin(mask).count("1")


def analyse(
    n: int,
    per_robot: Sequence[dict[str, Any]],
    poolings: Sequence[list[Any]],
    decisions: Sequence[list[Any]],
) -> dict[str, Any]:
    """The lag measures of one run that ended in consensus (``per_robot``: each robot's
    ``id``, ``steps`` and ``decision_time_s``)."""
    last_entry = max(per_robot, key=lambda robot: (robot["steps"], robot["decision_time_s"]))
    last = int(last_entry["id"])
    swarm_steps = max(robot["steps"] for robot in per_robot)
    last_pools = [pooling for pooling in poolings if pooling[0] == last]
    other_pools = [pooling for pooling in poolings if pooling[0] != last]
    phases: Counter[str] = Counter()
    undecided_missing: list[tuple[int, int]] = []  # (robots decided so far, sites missing)
    own_missing: list[tuple[int, float]] = []
    for order, (robot, _t, _trips, snapshot) in enumerate(decisions, start=1):
        undecided = [entry for entry in snapshot if popcount(entry[3]) > 1]
        if robot != last:
            entry = next(entry for entry in snapshot if entry[0] == last)
            phases[_phase_group(entry[1])] += 1
        if undecided:
            together = undecided[0][3]
            for entry in undecided[1:]:
                together &= entry[3]
            undecided_missing.append((order, popcount(together) - 1))
            own_missing.append(
                (order, round(statistics.fmean(popcount(entry[3]) - 1 for entry in undecided), 6))
            )
    others_done = max(
        (robot["decision_time_s"] for robot in per_robot if robot["id"] != last), default=0.0
    )
    return {
        "swarm_steps": swarm_steps,
        "late": swarm_steps > n / 2,
        "last": last,
        "last_pools_by_trip": [[pooling[2], pooling[3]] for pooling in last_pools],
        "other_pools_by_trip": [[pooling[2], pooling[3]] for pooling in other_pools],
        "last_phases": dict(sorted(phases.items())),
        "undecided_missing": [list(item) for item in undecided_missing],
        "own_missing": [list(item) for item in own_missing],
        "trips_after_others": sum(1 for pooling in last_pools if pooling[1] > others_done + 1e-6),
        "median_steps": statistics.median(robot["steps"] for robot in per_robot),
    }


def _phase_group(phase: str) -> str:
    if phase in AT_NEST:
        return GROUPS[0]
    if phase == "to_nest":
        return GROUPS[1]
    return GROUPS[2]


def summarise(runs: Sequence[dict[str, Any]], n: int) -> dict[str, Any]:
    """The lag measures of the runs of one n (each an ``analyse`` result), gathered."""
    last_pools = [size for run in runs for _, size in run["last_pools_by_trip"]]
    other_pools = [size for run in runs for _, size in run["other_pools_by_trip"]]
    phases: Counter[str] = Counter()
    for run in runs:
        phases.update(run["last_phases"])
    total_phases = sum(phases.values()) or 1
    by_decided: dict[int, list[int]] = {}
    own_by_decided: dict[int, list[float]] = {}
    for run in runs:
        for order, missing in run["undecided_missing"]:
            by_decided.setdefault(order, []).append(missing)
        for order, missing in run["own_missing"]:
            own_by_decided.setdefault(order, []).append(missing)
    late = [run for run in runs if run["late"]]
    return {
        "last_pool_by_trip": _by_trip(runs, "last_pools_by_trip"),
        "other_pool_by_trip": _by_trip(runs, "other_pools_by_trip"),
        "n": n,
        "runs": len(runs),
        "late_runs": len(late),
        "last_pool_mean": _mean(last_pools),
        "other_pool_mean": _mean(other_pools),
        "last_alone": _share(last_pools, 1),
        "other_alone": _share(other_pools, 1),
        "last_phases": {name: phases[name] / total_phases for name in sorted(phases)},
        "trips_after_others_mean": _mean([run["trips_after_others"] for run in runs]),
        "trips_after_others_late": _mean([run["trips_after_others"] for run in late]),
        "runs_with_lone_finish": sum(1 for run in runs if run["trips_after_others"] > 0),
        "gap_steps_mean": _mean([run["swarm_steps"] - run["median_steps"] for run in runs]),
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
