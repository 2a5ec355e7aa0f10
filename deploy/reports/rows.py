"""A run's summary as a report takes it (the launcher's, recorded, or rebuilt from the
recording), its line in the summary table (``summary.csv``) and the aggregates per group:
runs of one size and the same values of every setting that differs between the report's
runs (``conditions.py``)."""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bestofn_swarm.wire.endings import ENDINGS
from deploy.reports import conditions
from deploy.reports.audit import missing_messages
from deploy.reports.collect import Recording, rebuild_summary
from world_server.observer.summary import (
    run_digest,
)

CSV_COLUMNS = (
    "run_id",
    "robots",
    "sites",
    "seed",
    "consensus",
    "chosen_site",
    "best_site",
    "correct",
    "timed_out",
    "ended",
    "timeout_kind",
    "stuck",
    "complete",
    "missing_messages",
    "source",
    "sim_time_s",
    "wall_time_s",
    "decided",
    "swarm_steps",
    "steps_mean",
    "steps_median",
    "steps_min",
    "steps_max",
    "robots_within_half_n",
    "within_half_n",
    "pool_mean",
    "pool_median",
    "pool_min",
    "pool_max",
    "poolings",
    "recording",
)


# --- summaries ---------------------------------------------------------------------------


ABORTED = "aborted"  # the label of a run whose recording does not say how it ended

# The fields of a recorded summary this report reads, and the types it needs them in.
SUMMARY_FIELDS: dict[str, tuple[type, ...]] = {
    "run_id": (str,),
    "num_robots": (int,),
    "num_sites": (int,),
    "seed": (int,),
    "best_site": (int,),
    "consensus": (bool,),
    "chosen_site": (int, type(None)),
    "correct": (bool,),
    "timed_out": (bool,),
    "sim_time_s": (int, float),
    "wall_time_s": (int, float),
    "per_robot": (list,),
}
ROBOT_FIELDS: dict[str, tuple[type, ...]] = {
    "steps": (int, type(None)),
    "pool_sizes": (list,),
    "decided_site": (int, type(None)),
}


def run_summary(
    recording: Recording, warn: Any = None, launcher: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The run's summary: the launcher's if recorded; else ``launcher``, the summary the
    launcher printed, when its caller has it (a recorder that fell behind leaves its file
    unfinished, without one); else rebuilt from status messages.

    A recorded summary missing a field the report needs (or holding it in the wrong
    type) gets that field from the rebuilt summary, and ``warn`` is told which.
    """
    recorded = recording.summary
    source = "metadata"
    if recorded is None and launcher is not None:
        recorded, source = launcher, "launcher"
    if recorded is None:
        return {
            **rebuild_summary(recording),
            "source": "status messages",
            "complete": recording.complete,
            "missing_messages": missing_messages(recording),
        }
    unusable = unusable_fields(recorded)
    summary = dict(recorded)
    if unusable:
        rebuilt = rebuild_summary(recording)
        summary.update({name: rebuilt[name] for name in unusable})
        if warn is not None:
            warn(
                f"{recording.path}: the recorded summary lacks a usable "
                f"{', '.join(unusable)}; taken from the status messages instead"
            )
    summary["ended"] = recorded_ending(summary)
    return {
        **summary,
        "source": source,
        "complete": recording.complete,
        "missing_messages": missing_messages(recording),
    }


def unusable_fields(summary: dict[str, Any]) -> list[str]:
    """The fields of SUMMARY_FIELDS that ``summary`` lacks or holds in another type."""
    unusable = [
        name
        for name, types in SUMMARY_FIELDS.items()
        if not isinstance(summary.get(name, _MISSING), types)
    ]
    robots = summary.get("per_robot")
    if isinstance(robots, list) and not all(
        isinstance(robot, dict)
        and all(
            isinstance(robot.get(name, _MISSING), types) for name, types in ROBOT_FIELDS.items()
        )
        for robot in robots
    ):
        unusable.append("per_robot")
    return unusable


_MISSING = object()


def recorded_ending(summary: dict[str, Any]) -> str | None:
    """How a recorded run ended; None if its summary does not say (an aborted run).

    Summaries written before runs stated their ending still tell a consensus (every
    robot decided alike) and a timeout apart from the rest.
    """
    if "ended" in summary:
        ended = summary["ended"]
        return ended if ended in ENDINGS else None
    if summary.get("consensus") is True:
        return "consensus"
    if summary.get("timed_out") is True:
        return "timeout"
    return None


def _stats(values: Sequence[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "median": None, "min": None, "max": None}
    return {
        "mean": round(statistics.fmean(values), 3),
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
    }


def steps_of(summary: dict[str, Any]) -> list[int]:
    """Per-robot steps (trips) to decision of the robots that decided."""
    return [robot["steps"] for robot in summary["per_robot"] if robot["steps"] is not None]


def pools_of(summary: dict[str, Any]) -> list[int]:
    return [size for robot in summary["per_robot"] for size in robot["pool_sizes"]]


def csv_columns(settings: Sequence[str]) -> tuple[str, ...]:
    """The summary table's columns: one per setting that differs after the run's size."""
    at = CSV_COLUMNS.index("sites") + 1
    return (*CSV_COLUMNS[:at], *settings, *CSV_COLUMNS[at:])


def report_row(
    summary: dict[str, Any], recording: Path | str, settings: Sequence[str] = ()
) -> dict[str, Any]:
    """One run's line of the summary table; ``settings``: those that differ between the
    report's runs, each a column (its value as the run's configuration has it)."""
    steps, pools = steps_of(summary), pools_of(summary)
    half = summary["num_sites"] / 2
    step_stats, pool_stats = _stats(steps), _stats(pools)
    swarm_steps = max(steps) if steps and len(steps) == summary["num_robots"] else None
    return {
        "run_id": summary["run_id"],
        "robots": summary["num_robots"],
        "sites": summary["num_sites"],
        **{
            name: conditions.value_text(value) if isinstance(value, list | dict) else value
            for name, value in conditions.conditions_of(summary, settings).items()
        },
        "seed": summary["seed"],
        "consensus": summary["consensus"],
        "chosen_site": summary["chosen_site"],
        "best_site": summary["best_site"],
        "correct": summary["correct"],
        "timed_out": summary["timed_out"],
        "ended": summary.get("ended") or ABORTED,
        "timeout_kind": summary.get("timeout_kind"),
        "stuck": len(summary.get("stuck") or []),
        "complete": summary["complete"],
        "missing_messages": summary["missing_messages"],
        "source": summary["source"],
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "decided": len(steps),
        "swarm_steps": swarm_steps,
        "steps_mean": step_stats["mean"],
        "steps_median": step_stats["median"],
        "steps_min": step_stats["min"],
        "steps_max": step_stats["max"],
        "robots_within_half_n": sum(1 for value in steps if value <= half),
        "within_half_n": swarm_steps is not None and swarm_steps <= half,
        "pool_mean": pool_stats["mean"],
        "pool_median": pool_stats["median"],
        "pool_min": pool_stats["min"],
        "pool_max": pool_stats["max"],
        "poolings": len(pools),
        "digest": run_digest(summary["per_robot"]),
        "links": summary.get("links") or {},  # robots outside the emulator
        "recording": str(recording),
    }


def groups_of(summaries: Sequence[dict[str, Any]], settings: Sequence[str]) -> list[list[int]]:
    """The runs of each group (indices into ``summaries``), groups in order of size and
    settings, each group's runs in the order given."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for index, summary in enumerate(summaries):
        groups.setdefault(conditions.group_key(summary, settings), []).append(index)
    return [members for _, members in sorted(groups.items(), key=lambda item: _sortable(item[0]))]


def _sortable(key: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple((0, value, "") if isinstance(value, int) else (1, 0, str(value)) for value in key)


def group_rows(
    runs: Sequence[dict[str, Any]],
    summaries: Sequence[dict[str, Any]],
    settings: Sequence[str] = (),
) -> list[dict[str, Any]]:
    """Aggregates per group (robots, sites, and the values of ``settings``): what the
    paper's Section 5 text reports, per condition.

    Every run is counted by its ending; steps and pool sizes are aggregated over the runs
    that ended in consensus only (``aggregated_runs``), so that a stalled, timed-out or
    aborted run neither shortens nor lengthens the times to consensus.
    """
    result = []
    for all_members in groups_of(summaries, settings):
        every_row = [runs[i] for i in all_members]
        robots, sites = every_row[0]["robots"], every_row[0]["sites"]
        settled = conditions.conditions_of(summaries[all_members[0]], settings)
        members = [i for i in all_members if runs[i]["ended"] == "consensus"]
        rows = [runs[i] for i in members]
        swarm = [row["swarm_steps"] for row in rows if row["swarm_steps"] is not None]
        steps = [value for i in members for value in steps_of(summaries[i])]
        pools = [value for i in members for value in pools_of(summaries[i])]
        run_pool_means = [row["pool_mean"] for row in rows if row["pool_mean"] is not None]
        endings = Counter(row["ended"] for row in every_row)
        result.append(
            {
                "robots": robots,
                "sites": sites,
                "settings": settled,
                "label": conditions.label(robots, sites, settled),
                "run_ids": [row["run_id"] for row in every_row],
                "half_n": sites / 2,
                "runs": len(every_row),
                "endings": {name: endings[name] for name in (*ENDINGS, ABORTED) if endings[name]},
                "aggregated_runs": len(rows),
                "complete_runs": sum(1 for row in every_row if row["complete"]),
                "consensus_runs": sum(1 for row in every_row if row["consensus"]),
                "correct_runs": sum(1 for row in every_row if row["correct"]),
                "runs_within_half_n": sum(1 for value in swarm if value <= sites / 2),
                "runs_below_half_n": sum(1 for value in swarm if value < sites / 2),
                "swarm_steps": _stats(swarm),
                "robot_steps": _stats(steps),
                "pool_size": _stats(pools),
                "run_mean_pool_size": _stats(run_pool_means),
            }
        )
    return result
