"""Checking a study's published runs against today's code: a few of its runs made again
and compared, field by field, with what its results file says they gave.

The sample is chosen from the file alone, so it is the same on every machine: the runs
that took least wall time first (by powers of two of their recorded wall seconds: a
check must stay cheap), one run per point before a second of any point, ties broken by a
hash of the key.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from typing import Any

from deploy.study import grid


def sample(
    done: Sequence[grid.Run], records: Mapping[str, Mapping[str, Any]], k: int
) -> list[grid.Run]:
    """``k`` of the runs made: cheap ones first, spread over the points, deterministic."""

    def rank(run: grid.Run) -> tuple[float, str]:
        wall = records[run.key].get("wall_s")
        seconds = float(wall) if isinstance(wall, int | float) else math.inf
        return (math.ceil(math.log2(max(seconds, 1.0))), _hash(run.key))

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
    """Every field of the published result that differs in the fresh one, as ``field:
    published -> now`` (nested fields dotted). A field only the fresh result has is not
    compared: a run converted from an older results file kept fewer fields."""
    if isinstance(published, dict) and isinstance(fresh, dict):
        found = []
        for name in sorted(published):
            where = f"{path}.{name}" if path else str(name)
            if name not in fresh:
                found.append(f"{where}: {_short(published[name])} -> (none)")
            else:
                found += differences(published[name], fresh[name], where)
        return found
    if published != fresh:
        return [f"{path or 'result'}: {_short(published)} -> {_short(fresh)}"]
    return []


def _short(value: Any, limit: int = 80) -> str:
    shown = repr(value)
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."
