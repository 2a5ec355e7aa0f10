"""Checking a study's published runs against today's code: a few of its runs made again
and compared, field by field, with what its results file says they gave.

The sample is chosen from the file alone, so it is the same on every machine: the runs
that took least wall time first (a check must stay cheap), one run per point before a
second of any point, ties broken by a hash of the key.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from typing import Any

from deploy.study import grid

# Runs that took at most this many wall seconds are preferred for a check.
CHEAP_WALL_S = 30.0


def sample(
    done: Sequence[grid.Run], records: Mapping[str, Mapping[str, Any]], k: int
) -> list[grid.Run]:
    """``k`` of the runs made: cheap ones first, spread over the points, deterministic."""

    def rank(run: grid.Run) -> tuple[bool, float, str]:
        wall = records[run.key].get("wall_s")
        seconds = float(wall) if isinstance(wall, int | float) else float("inf")
        return (seconds > CHEAP_WALL_S, seconds if seconds > CHEAP_WALL_S else 0.0, _hash(run.key))

    chosen: list[grid.Run] = []
    points: set[str] = set()
    ranked = sorted(done, key=rank)
    for run in ranked:  # one per point first
        if len(chosen) < k and run.point not in points:
            chosen.append(run)
            points.add(run.point)
    for run in ranked:
        if len(chosen) < k and run not in chosen:
            chosen.append(run)
    return chosen


def _hash(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def differences(published: Any, fresh: Any, path: str = "") -> list[str]:
    """Every field that differs, as ``field: published -> now`` (nested fields dotted)."""
    if isinstance(published, dict) and isinstance(fresh, dict):
        found = []
        for name in sorted(published.keys() | fresh.keys()):
            where = f"{path}.{name}" if path else str(name)
            if name not in fresh:
                found.append(f"{where}: {_short(published[name])} -> (none)")
            elif name not in published:
                found.append(f"{where}: (none) -> {_short(fresh[name])}")
            else:
                found += differences(published[name], fresh[name], where)
        return found
    if published != fresh:
        return [f"{path or 'result'}: {_short(published)} -> {_short(fresh)}"]
    return []


def _short(value: Any, limit: int = 80) -> str:
    shown = repr(value)
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."
