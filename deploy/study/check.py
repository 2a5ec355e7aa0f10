"""Checking a study's published runs against today's code: a few of its runs made again
and compared, field by field, with what its results file says they gave.

The sample reaches every kind of run the study declares (``Study.kinds``: a well-stirred
cell, a 10- and a 50-robot swarm, a run over Zenoh, the camera alone...): ``per_kind``
runs of each, drawn at random among the kind's runs whose recorded wall time fits the
budget, by the project's generator from a seed (``swarm study --check --sample-seed S``;
by default the day's date, so that each day's check makes other runs, and the seed is
printed, so that a failure can be made again). The draw reads the results file alone, so
a seed gives the same sample on every machine. When the runs drawn would take more than
the budget (their recorded wall seconds, in all), the costliest is replaced by the
cheapest of its kind until they fit; a kind with no run within the budget is named, not
made.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from bestofn_swarm.wire.rng import Stream, seed_of
from deploy.study import grid

BUDGET = 60.0  # recorded wall seconds a study's sample may take, in all (one core)


def default_kind(run: grid.Run) -> str:
    """A run's kind when its study declares none: how it is made, and its swarm's size."""
    robots = dict(run.params).get("robots")
    return run.kind + (f", {robots} robots" if robots is not None else "")


def todays_seed() -> int:
    """The day's date as a number, 20250314: the default seed of a check's sample."""
    return int(datetime.datetime.now(datetime.UTC).strftime("%Y%m%d"))


@dataclass
class Sample:
    """The runs to make again, by kind; how many runs of each kind took more than the
    budget (never drawn); the kinds no run of which fits it, with the wall seconds of
    their cheapest run."""

    runs: list[grid.Run] = field(default_factory=list)
    kinds: dict[str, list[grid.Run]] = field(default_factory=dict)
    beyond: dict[str, int] = field(default_factory=dict)
    out_of_reach: dict[str, float] = field(default_factory=dict)


def wall(records: Mapping[str, Mapping[str, Any]], run: grid.Run) -> float:
    """The run's recorded wall seconds (inf when the file does not say)."""
    found = records[run.key].get("wall_s")
    return float(found) if isinstance(found, int | float) else math.inf


def sample(
    done: Sequence[grid.Run],
    records: Mapping[str, Mapping[str, Any]],
    *,
    seed: int,
    kind_of: Callable[[grid.Run], str] = default_kind,
    per_kind: int = 1,
    budget: float = BUDGET,
) -> Sample:
    """``per_kind`` of the runs made of each kind, drawn from ``seed``, within ``budget``."""
    by_kind: dict[str, list[grid.Run]] = {}
    for run in sorted(done, key=lambda run: run.key):
        by_kind.setdefault(kind_of(run), []).append(run)
    found = Sample()
    for kind, runs in by_kind.items():
        affordable = [run for run in runs if wall(records, run) <= budget]
        if len(affordable) < len(runs):
            found.beyond[kind] = len(runs) - len(affordable)
        if not affordable:
            found.out_of_reach[kind] = min(wall(records, run) for run in runs)
            continue
        stream = Stream(seed_of(seed, "check", runs[0].study, kind))
        found.kinds[kind] = stream.sample(affordable, min(per_kind, len(affordable)))

    def total() -> float:
        return sum(wall(records, run) for chosen in found.kinds.values() for run in chosen)

    while total() > budget:  # the costliest run drawn gives way to a cheaper one of its kind
        movable = []
        for kind, chosen in found.kinds.items():
            for run in chosen:
                cost = wall(records, run)
                spare = [
                    other
                    for other in by_kind[kind]
                    if other not in chosen and wall(records, other) < cost
                ]
                if spare or len(chosen) > 1:  # one of each kind stays
                    movable.append((cost, run.key, kind, run, spare))
        if not movable:
            break  # each kind's cheapest run: a kind is never left out for the budget
        _, _, kind, run, spare = max(movable, key=lambda item: (item[0], item[1]))
        found.kinds[kind].remove(run)
        if spare:
            found.kinds[kind].append(
                min(spare, key=lambda other: (wall(records, other), other.key))
            )
    found.runs = [run for chosen in found.kinds.values() for run in chosen]
    return found


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
