"""The conditions of a report's runs: which settings differ between them, each run's
values of those, and the groups they make.

A run's settings are its summary's ``config`` (every option of ``swarm run`` in force,
recorded with the run). A report groups its runs by the swarm's size and sites and by
every setting whose value is not the same in all of them, so that a ``--drop 0.3`` run is
never counted with the default ones; the groups and their figures are labelled by those
settings (``N = 10, n = 5, drop = 0.3``), and summary.csv gets a column for each.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

# What names a run rather than its conditions (its id, seed, where it was recorded and
# how it was reached), and what follows from the rest (the stall and world-stop windows
# default to values made of the swarm's size): never a condition of its own.
NOT_CONDITIONS = frozenset(
    {
        "run_id",
        "seed",
        "record",
        "no_record",
        "connect",
        "link_keys",
        "stall_window",
        "world_stop_window",
        "robots",
        "sites",
    }
)
SIZE = ("robots", "sites")  # every report groups by these, as the paper's panels do


def value_text(value: Any) -> str:
    """A setting's value as a label and a CSV cell show it: lists joined, None as "-"."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return " ".join(value_text(item) for item in value) or "-"
    if isinstance(value, dict):
        return json.dumps(value, sort_keys=True)
    return str(value)


def config_of(summary: Mapping[str, Any]) -> dict[str, Any]:
    config = summary.get("config")
    return dict(config) if isinstance(config, Mapping) else {}


def differing(summaries: Sequence[Mapping[str, Any]]) -> list[str]:
    """The settings whose values are not the same in every run (a setting a run does not
    record counts as its own value), in the order the first run that has them lists them."""
    configs = [config_of(summary) for summary in summaries]
    names: list[str] = []
    for config in configs:
        names += [name for name in config if name not in names and name not in NOT_CONDITIONS]
    return [name for name in names if len({value_text(config.get(name)) for config in configs}) > 1]


def conditions_of(summary: Mapping[str, Any], settings: Sequence[str]) -> dict[str, Any]:
    """A run's values of ``settings``."""
    config = config_of(summary)
    return {name: config.get(name) for name in settings}


def group_key(summary: Mapping[str, Any], settings: Sequence[str]) -> tuple[Any, ...]:
    """What puts runs in one group: their size and their values of ``settings``."""
    return (
        summary["num_robots"],
        summary["num_sites"],
        *(value_text(value) for value in conditions_of(summary, settings).values()),
    )


def label(robots: int, sites: int, conditions: Mapping[str, Any]) -> str:
    """A group's label: ``N = 10, n = 5, drop = 0.3``."""
    parts = [f"N = {robots}", f"n = {sites}"]
    parts += [f"{name} = {value_text(value)}" for name, value in conditions.items()]
    return ", ".join(parts)
