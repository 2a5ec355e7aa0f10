"""``swarm report``: the paper's Section 5 figures and a summary table, from recordings alone.

Reads MCAP recordings made by the recorder (``world_server/recording/writer.py``) one message
at a time with ``world_server/recording/reader.py``, so a file cut short by a crash is read
up to its last complete record.
The run summary comes from the recording's ``bestofn.run`` metadata record when there is
one, else it is rebuilt from the robots' status messages (the same code that
``swarm run`` uses); a recorded summary that lacks a field the report needs gets it from
the rebuilt one, with a warning. Each run is labelled with how it ended (``ended``: see
``world_server/observer/summary.py``); one whose recording says nothing of its end, and whose robots
did not all decide, is labelled ``aborted``. Aggregates over runs (steps, pool sizes)
take only the runs that ended in consensus; the others are counted by ending.
Writes, into ``--out``:

* ``fig4.png``: per run, a box plot of the robots' steps (trips) to decision, one panel
  per (robots, sites), with the n/2 line (the paper's Figure 4);
* ``fig5.png``: per run, a box plot of pool sizes (the paper's Figure 5);
* ``fig2.png``: one robot's opinion of every site over sim time (cf. the paper's Fig. 2);
* ``trajectories.png``: the robots' paths in the arena of one run;
* ``summary.csv`` and ``summary.json``: one row per run, and aggregates per (robots, sites).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import re
import statistics
import sys
from array import array
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from bestofn_swarm.plumbing.private_files import make_private_folder, open_private, write_private
from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.endings import ENDINGS
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.summary import (
    RobotRecord,
    RunOutcome,
    build_summary,
    byzantine_in_config,
    run_digest,
)
from world_server.observer.watchdog import Watchdog
from world_server.recording.reader import RecordedMessage, RecordingReader, run_description
from world_server.recording.records import RUN_METADATA

FIGURES = ("fig4.png", "fig5.png", "fig2.png", "trajectories.png")
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


# --- reading a recording ---------------------------------------------------------------


@dataclass
class TickSpan:
    """Ticks seen on one channel: enough to tell whether any went missing."""

    first: int | None = None
    last: int | None = None
    count: int = 0

    def add(self, tick: int) -> None:
        self.first = tick if self.first is None else min(self.first, tick)
        self.last = tick if self.last is None else max(self.last, tick)
        self.count += 1

    @property
    def expected(self) -> int:
        """One per tick from the first to the last (a contiguous run of ticks)."""
        return 0 if self.first is None or self.last is None else self.last - self.first + 1


@dataclass
class AckTicks(TickSpan):
    """The ticks a beacon answered, each with the next it said it would answer
    (``Ack.next_tick``; None: the next tick): enough to tell whether any went missing."""

    next_of: dict[int, int | None] = field(default_factory=dict)

    def answered(self, tick: int, next_tick: int | None) -> None:
        self.add(tick)
        self.next_of[tick] = next_tick

    @property
    def expected(self) -> int:
        """The acks due from the first to the last: each names the next. Where the next
        recorded one is later than named, those missing in between are counted as many as
        fit at the step of the last named (a beacon answers at its period)."""
        ticks = sorted(self.next_of)
        expected = len(ticks)
        for tick, following in itertools.pairwise(ticks):
            due = self.next_of[tick]
            due = tick + 1 if due is None else due
            if following > due:
                expected += math.ceil((following - due) / max(1, due - tick))
        return expected


@dataclass
class Declared:
    """What publishers said they sent, read from the recorded messages themselves."""

    rx: int = 0  # sum of Sense.rx: radio deliveries the world announced
    camera: int = 0  # Senses with camera = true: frames the world announced
    tx: int = 0  # sum of Act.radio_tx and Ack.radio_tx: radio messages controllers sent
    status_gaps: int = 0  # status updates a robot's trip or pooling counter skipped


# Points of a robot's trail kept for the trajectories figure, at most: the trail is thinned
# to every other point each time it fills, so a report's memory does not grow with the
# length of the run (about 0.25 s of sim time between points in a 1000 s run).
TRAIL_POINTS = 4096


class Trail:
    """A robot's path, thinned to at most ``TRAIL_POINTS`` evenly spaced points (every
    ``stride``-th pose), plus its last pose."""

    def __init__(self, limit: int = TRAIL_POINTS) -> None:
        self.limit = max(2, limit)
        self.xs: array[float] = array("d")
        self.ys: array[float] = array("d")
        self.stride = 1
        self.seen = 0
        self.last: tuple[float, float] | None = None

    def add(self, x: float, y: float) -> None:
        if self.seen % self.stride == 0:
            if len(self.xs) >= self.limit:
                del self.xs[1::2], self.ys[1::2]
                self.stride *= 2
            if self.seen % self.stride == 0:
                self.xs.append(x)
                self.ys.append(y)
        self.seen += 1
        self.last = (x, y)

    def points(self) -> tuple[list[float], list[float]]:
        """The kept points in order, ending with the last pose."""
        xs, ys = list(self.xs), list(self.ys)
        if self.last is not None and (not xs or (xs[-1], ys[-1]) != self.last):
            xs.append(self.last[0])
            ys.append(self.last[1])
        return xs, ys


@dataclass
class RobotTrace:
    """What a report keeps of one robot, whatever the length of the run: its summary
    record, its last status, its progress (the stall watchdog's, for ``stuck``) and its
    thinned trail."""

    id: int
    record: RobotRecord
    progress: Watchdog
    trail: Trail = field(default_factory=Trail)
    last: protocol.Status | None = None

    @classmethod
    def new(cls, robot: int) -> RobotTrace:
        # Robots are independent in the watchdog: one each, so robots can join as heard.
        # Its window plays no part in ``stuck``.
        return cls(robot, RobotRecord(robot), Watchdog([robot], 1.0, 2 * EPUCK.radius))


@dataclass
class Recording:
    """Everything a report needs from one MCAP file."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False  # the file ends with its footer
    problem: str | None = None  # why reading stopped early, if it did
    messages: Counter[str] = field(default_factory=Counter)  # by schema name
    robots_heard: dict[int, RobotTrace] = field(default_factory=dict)  # by robot id
    opinion_robot: int | None = None  # whose every status is kept, for the opinion figure
    opinions: list[protocol.Status] = field(default_factory=list)  # that robot's statuses
    sense: dict[int, TickSpan] = field(default_factory=dict)
    act: dict[int, TickSpan] = field(default_factory=dict)
    ack: AckTicks = field(default_factory=AckTicks)
    clock: TickSpan = field(default_factory=TickSpan)
    state_ticks: list[int] = field(default_factory=list)
    declared: Declared = field(default_factory=Declared)
    last_clock: protocol.Clock | None = None
    last_state: protocol.WorldState | None = None
    first_clock_wall_ns: int | None = None
    last_clock_wall_ns: int | None = None
    links: dict[int, protocol.LinkStats] = field(default_factory=dict)  # robots outside

    @property
    def undecodable(self) -> int:
        """Recorded messages this report could not decode as their schema's type."""
        return sum(n for name, n in self.messages.items() if name.startswith("undecodable "))

    @property
    def description(self) -> dict[str, str]:
        """The final metadata record if the run finished, else the one written at start."""
        return run_description(self.metadata)

    def _number(self, name: str) -> int | None:
        text = self.description.get(name, "")
        return int(text) if text.isdigit() else None

    @property
    def run_id(self) -> str:
        return self.description.get("run_id") or self.path.stem

    @property
    def seed(self) -> int | None:
        return self._number("seed")

    @property
    def robots(self) -> int | None:
        return self._number("robots")

    @property
    def sites(self) -> int | None:
        return self._number("sites")

    def _json(self, name: str) -> Any:
        text = self.description.get(name)
        if not text:
            return None
        try:
            return json.loads(text)
        except ValueError:
            return None

    @property
    def config(self) -> dict[str, Any]:
        config = self._json("config")
        return config if isinstance(config, dict) else {}

    @property
    def layout(self) -> dict[str, Any] | None:
        layout = self._json("layout")
        return layout if isinstance(layout, dict) else None

    @property
    def summary(self) -> dict[str, Any] | None:
        """The launcher's summary, if the recording was finished with one."""
        summary = self.metadata.get(RUN_METADATA, {}).get("summary")
        if not summary:
            return None
        try:
            value = json.loads(summary)
        except ValueError:
            return None
        return value if isinstance(value, dict) else None


class _Collector:
    """Decodes the messages a report needs, one at a time; counts the rest."""

    def __init__(self, recording: Recording) -> None:
        self.recording = recording
        # --robot: keep that robot's statuses for the opinion figure, and only its.
        self.opinion_robot_fixed = recording.opinion_robot is not None
        self.status = msgspec.json.Decoder(protocol.Status)
        self.sense = msgspec.json.Decoder(protocol.Sense)
        self.act = msgspec.json.Decoder(protocol.Act)
        self.ack = msgspec.json.Decoder(protocol.Ack)
        self.clock = msgspec.json.Decoder(protocol.Clock)
        self.state = msgspec.json.Decoder(protocol.WorldState)
        self.link = msgspec.json.Decoder(protocol.LinkStats)

    def message(self, message: RecordedMessage) -> None:
        recording = self.recording
        topic, schema = message.topic, message.schema
        recording.messages[schema] += 1
        try:
            if schema == "bestofn.Sense":
                sense = self.sense.decode(message.data)
                robot = _robot_of(topic)
                recording.sense.setdefault(robot, TickSpan()).add(sense.tick)
                trace = self._trace(robot)
                trace.trail.add(sense.x, sense.y)
                trace.progress.poses(sense.t, [(robot, sense.x, sense.y)])
                recording.declared.rx += sense.rx
                recording.declared.camera += sense.camera
            elif schema == "bestofn.Act":
                act = self.act.decode(message.data)
                recording.act.setdefault(_robot_of(topic), TickSpan()).add(act.tick)
                recording.declared.tx += act.radio_tx
            elif schema == "bestofn.Status":
                self._status(_robot_of(topic), self.status.decode(message.data))
            elif schema == "bestofn.Ack":
                ack = self.ack.decode(message.data)
                recording.ack.answered(ack.tick, ack.next_tick)
                recording.declared.tx += ack.radio_tx
            elif schema == "bestofn.Clock":
                clock = self.clock.decode(message.data)
                recording.clock.add(clock.tick)
                recording.last_clock = clock
                if recording.first_clock_wall_ns is None:
                    recording.first_clock_wall_ns = message.publish_time
                recording.last_clock_wall_ns = message.publish_time
            elif schema == "bestofn.WorldState":
                state = self.state.decode(message.data)
                recording.state_ticks.append(state.tick)
                recording.last_state = state
            elif schema == "bestofn.LinkStats":
                stats = self.link.decode(message.data)
                recording.links[stats.robot] = stats
        except (msgspec.DecodeError, msgspec.ValidationError, ValueError):
            recording.messages["undecodable " + schema] += 1

    def _trace(self, robot: int) -> RobotTrace:
        trace = self.recording.robots_heard.get(robot)
        if trace is None:
            trace = self.recording.robots_heard[robot] = RobotTrace.new(robot)
        return trace

    def _status(self, robot: int, status: protocol.Status) -> None:
        recording = self.recording
        trace = self._trace(robot)
        previous = trace.last
        if previous is not None:
            skipped = max(status.trips - previous.trips - 1, 0)
            skipped += max(status.poolings - previous.poolings - 1, 0)
            recording.declared.status_gaps += skipped
        trace.last = status
        trace.record.update(status)
        trace.progress.status(status)
        # The opinion figure's robot: the one asked for, else the lowest id heard (a lower
        # one heard later starts its history at its first status, so that is whole too).
        if recording.opinion_robot is None or (
            not self.opinion_robot_fixed and robot < recording.opinion_robot
        ):
            recording.opinion_robot, recording.opinions = robot, []
        if robot == recording.opinion_robot:
            recording.opinions.append(status)


def _robot_of(topic: str) -> int:
    """The robot id in ``<root>/<run>/robot/<id>/<leaf>``."""
    return int(topic.rsplit("/", 2)[-2])


def read_recording(path: Path, opinion_robot: int | None = None) -> Recording:
    """Read one recording as far as it is readable (a truncated file too), one message at
    a time, keeping per robot only what the report needs (``RobotTrace``): its memory
    does not grow with the length of the run. ``opinion_robot``: the robot whose every
    status is kept for the opinion figure (default: the lowest id).

    Raises ValueError if the file is not an MCAP file at all.
    """
    recording = Recording(Path(path), opinion_robot=opinion_robot)
    collector = _Collector(recording)
    reader = RecordingReader(path)
    for message in reader:
        collector.message(message)
    recording.metadata = reader.metadata
    recording.complete = reader.complete
    recording.problem = reader.problem
    return recording


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


def rebuild_summary(recording: Recording) -> dict[str, Any]:
    """The ``swarm run --json`` summary, from the status messages in the recording."""
    records = {robot: RobotRecord(robot) for robot in range(recording.robots or 0)}
    for robot, trace in recording.robots_heard.items():
        if trace.last is not None:  # its statuses, not only its poses
            records[robot] = trace.record
    for robot, stats in recording.links.items():  # robots outside the emulator
        record = records.setdefault(robot, RobotRecord(robot))
        record.outside = stats.transport
    num_sites = recording.sites or _sites_from_statuses(recording) or 2
    num_robots = recording.robots or len(records)
    seed = recording.seed or 0
    layout = recording.layout
    best = (
        layout["best_site"]
        if layout
        else make_layout(num_sites, max(num_robots, 1), seed).best_site
    )
    state = recording.last_state
    clock = recording.last_clock
    wall = 0.0
    if recording.first_clock_wall_ns is not None and recording.last_clock_wall_ns is not None:
        wall = (recording.last_clock_wall_ns - recording.first_clock_wall_ns) / 1e9
    return build_summary(
        RunOutcome(
            run_id=recording.run_id,
            num_robots=num_robots,
            num_sites=num_sites,
            seed=seed,
            best_site=best,
            sim_time_s=clock.t if clock else 0.0,
            wall_time_s=wall,
            timed_out=False,
            radio=state.radio if state else protocol.RadioCounters(),
            world_rejected=state.rejected if state else 0,
            stalls=state.stalls if state else 0,
            departures=state.departures if state else 0,
            observer_rejected=recording.undecodable,
            config=recording.config,
            stuck=_stuck(recording, records),
            byzantine=byzantine_in_config(recording.config),
            links=recording.links,
        ),
        records.values(),
    )


def _stuck(recording: Recording, records: Mapping[int, RobotRecord]) -> list[dict[str, Any]]:
    """Where each undecided robot is stuck, and since when: each robot's watchdog, fed its
    statuses and poses as they were read."""
    stuck: list[dict[str, Any]] = []
    for robot in sorted(records):
        trace = recording.robots_heard.get(robot) or RobotTrace.new(robot)
        stuck += trace.progress.stuck()
    return stuck


def _sites_from_statuses(recording: Recording) -> int | None:
    for trace in recording.robots_heard.values():
        if trace.last is not None:
            return len(trace.last.opinion)
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


def report_row(summary: dict[str, Any], recording: Path | str) -> dict[str, Any]:
    """One run's line of the summary table."""
    steps, pools = steps_of(summary), pools_of(summary)
    half = summary["num_sites"] / 2
    step_stats, pool_stats = _stats(steps), _stats(pools)
    swarm_steps = max(steps) if steps and len(steps) == summary["num_robots"] else None
    return {
        "run_id": summary["run_id"],
        "robots": summary["num_robots"],
        "sites": summary["num_sites"],
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


def group_rows(
    runs: Sequence[dict[str, Any]], summaries: Sequence[dict[str, Any]]
) -> list[dict[str, Any]]:
    """Aggregates per (robots, sites): what the paper's Section 5 text reports.

    Every run is counted by its ending; steps and pool sizes are aggregated over the runs
    that ended in consensus only (``aggregated_runs``), so that a stalled, timed-out or
    aborted run neither shortens nor lengthens the times to consensus.
    """
    groups: dict[tuple[int, int], list[int]] = {}
    for index, row in enumerate(runs):
        groups.setdefault((row["robots"], row["sites"]), []).append(index)
    result = []
    for (robots, sites), all_members in sorted(groups.items()):
        every_row = [runs[i] for i in all_members]
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


def audit(recording: Recording) -> dict[str, dict[str, int]]:
    """Messages recorded against messages their publishers declared or must have sent.

    ``expected`` comes from the recording itself: each tick's Sense says how many radio
    deliveries and camera frames the world published for it; each Act and Ack says how many
    radio messages its controller sent; clock, sense and act ticks must be contiguous, and
    each ack must be followed by one at the tick it named (``Ack.next_tick``);
    a robot's trip and pooling counters step by one per status update.
    """
    counts = recording.messages
    declared = recording.declared
    state_expected = _states_expected(recording.state_ticks)
    return {
        "world/clock": {"expected": recording.clock.expected, "recorded": recording.clock.count},
        "world/state": {"expected": state_expected, "recorded": len(recording.state_ticks)},
        "robot/*/sense": {
            "expected": sum(span.expected for span in recording.sense.values()),
            "recorded": sum(span.count for span in recording.sense.values()),
        },
        "robot/*/act": {
            "expected": sum(span.expected for span in recording.act.values()),
            "recorded": sum(span.count for span in recording.act.values()),
        },
        "beacon/*/ack": {"expected": recording.ack.expected, "recorded": recording.ack.count},
        "robot/*/camera": {
            "expected": declared.camera,
            "recorded": counts["foxglove.CompressedImage"],
        },
        "radio/tx/*": {"expected": declared.tx, "recorded": counts["bestofn.RadioTxRecord"]},
        "radio/rx/*": {"expected": declared.rx, "recorded": counts["bestofn.RadioRxRecord"]},
        "robot/*/status": {
            "expected": counts["bestofn.Status"] + declared.status_gaps,
            "recorded": counts["bestofn.Status"],
        },
    }


def _states_expected(ticks: Sequence[int]) -> int:
    """World states due from the first to the last recorded: one every ``state_every``
    ticks (the most common step) and any off that grid (the world's last state, published
    when it stops), which the recording holds by definition."""
    if not ticks:
        return 0
    steps = Counter(b - a for a, b in itertools.pairwise(ticks) if b > a)
    step = steps.most_common(1)[0][0] if steps else 1
    on_grid = [tick for tick in ticks if (tick - ticks[0]) % step == 0]
    return (max(on_grid) - ticks[0]) // step + 1 + len(ticks) - len(on_grid)


def missing_messages(recording: Recording) -> int:
    """How many messages ``audit`` finds missing from the file, of every kind together."""
    return sum(max(0, entry["expected"] - entry["recorded"]) for entry in audit(recording).values())


# --- figures -------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _natural(text: str) -> list[Any]:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def _panels(summaries: Sequence[dict[str, Any]]) -> list[tuple[int, int, list[dict[str, Any]]]]:
    groups: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for summary in summaries:
        groups.setdefault((summary["num_robots"], summary["num_sites"]), []).append(summary)
    return [
        (robots, sites, sorted(runs, key=lambda s: _natural(s["run_id"])))
        for (robots, sites), runs in sorted(groups.items())
    ]


def save_figure(figure: Any, path: Path, *, private: bool = True) -> None:
    """A figure as a PNG; only its owner can read it, like everything a report writes,
    unless it is for publishing (``swarm section5``'s figures in docs/)."""
    if not private:
        figure.savefig(path, dpi=120)
        return
    with open_private(path, "wb") as stream:
        figure.savefig(stream, dpi=120, format="png")


def plot_boxes(
    summaries: Sequence[dict[str, Any]], path: Path, *, pools: bool, private: bool = True
) -> None:
    """Figure 4 (steps to decision, with the n/2 line) or Figure 5 (pool sizes)."""
    plt = _pyplot()
    panels = _panels(summaries)
    figure, axes = plt.subplots(
        1, max(len(panels), 1), figsize=(5.5 * max(len(panels), 1), 4.2), squeeze=False
    )
    for index, (robots, sites, runs) in enumerate(panels):
        axis = axes[0][index]
        data = [pools_of(run) if pools else steps_of(run) for run in runs]
        labels = [
            f"{number}" + ("" if run.get("ended") == "consensus" and run["complete"] else "*")
            for number, run in enumerate(runs, start=1)
        ]
        axis.boxplot(
            [[float(value) for value in values] or [math.nan] for values in data],
            tick_labels=labels,
            flierprops={"markersize": 3},
        )
        if pools:
            axis.set_ylabel("pool size k")
        else:
            axis.axhline(sites / 2, linestyle="--", color="tab:red", label=f"n/2 = {sites / 2:g}")
            axis.set_ylabel("time steps (trips) to decision")
            axis.legend(loc="upper right")
        axis.set_title(f"({chr(ord('a') + index)}) n = {sites}, N = {robots}")
        axis.set_xlabel(
            "run"
            + ("  (* did not end in consensus, or cut short)" if "*" in "".join(labels) else "")
        )
        axis.set_ylim(bottom=0)
        axis.yaxis.get_major_locator().set_params(integer=True)
    if not panels:
        axes[0][0].text(0.5, 0.5, "no runs", ha="center", va="center")
    figure.tight_layout()
    save_figure(figure, path, private=private)
    plt.close(figure)


def _site_colours(layout: dict[str, Any] | None, sites: int) -> dict[int, tuple[float, ...]]:
    """Each site's rendered colour (red share = quality), for legends and the arena."""
    from world_server.recording.foxglove import site_colour

    if layout is None:
        return {site: (0.5, 0.5, 0.5, 1.0) for site in range(sites)}
    return {site["id"]: site_colour(site["quality"]) for site in layout["sites"]}


def plot_opinion(recording: Recording, robot: int, path: Path) -> None:
    """One robot's opinion of every site over sim time, poolings marked."""
    plt = _pyplot()
    statuses = recording.opinions if robot == recording.opinion_robot else []
    figure, axis = plt.subplots(figsize=(8, 4.2))
    layout = recording.layout
    if statuses:
        sites = len(statuses[0].opinion)
        colours = _site_colours(layout, sites)
        qualities = {s["id"]: s["quality"] for s in layout["sites"]} if layout else {}
        best = layout["best_site"] if layout else None
        times = [status.t for status in statuses]
        for site in range(sites):
            label = f"site {site}" + (f" (rho {qualities[site]:.2f})" if site in qualities else "")
            axis.step(
                times,
                [status.opinion[site] for status in statuses],
                where="post",
                color=colours.get(site, (0.5, 0.5, 0.5, 1.0)),
                linewidth=2.5 if site == best else 1.2,
                label=label,
            )
        for previous, status in itertools.pairwise(statuses):
            if status.poolings > previous.poolings:
                axis.axvline(status.t, color="grey", linestyle=":", linewidth=0.8)
        axis.legend(fontsize="small", ncols=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
    else:
        axis.text(
            0.5, 0.5, f"no status messages of robot {robot}", ha="center", transform=axis.transAxes
        )
    axis.set_ylim(-0.02, 1.02)
    axis.set_xlabel("sim time (s); dotted lines: poolings at the nest")
    axis.set_ylabel(f"robot {robot}'s probability")
    axis.set_title(f"run {recording.run_id}: robot {robot}'s opinion")
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def plot_trajectories(recording: Recording, path: Path) -> None:
    """The robots' paths in the arena, with sites in their colours and the nest."""
    plt = _pyplot()
    from matplotlib.patches import Circle, Wedge

    figure, axis = plt.subplots(figsize=(8, 6.5))
    layout = recording.layout
    radius = layout["arena_radius"] if layout else 1.0
    axis.add_patch(Circle((0, 0), radius, fill=False, color="0.4", linewidth=1.5))
    if layout:
        colours = _site_colours(layout, len(layout["sites"]))
        axis.add_patch(Circle((0, 0), layout["nest_radius"], color=(1.0, 0.85, 0.3), alpha=0.4))
        half = 3.14159 / len(layout["sites"]) * 0.7
        for site in layout["sites"]:
            angle = site["angle"]
            axis.add_patch(
                Wedge(
                    (0, 0),
                    radius * 1.04,
                    _degrees(angle - half),
                    _degrees(angle + half),
                    width=radius * 0.04,
                    color=colours[site["id"]],
                )
            )
            axis.annotate(
                f"{site['id']}\nrho {site['quality']:.2f}",
                (1.14 * site["x"], 1.14 * site["y"]),
                ha="center",
                va="center",
                fontsize=7,
            )
    trails = {robot: trace.trail for robot, trace in recording.robots_heard.items()}
    robots = sorted(robot for robot, trail in trails.items() if trail.last is not None)
    cmap = plt.get_cmap("tab10" if len(robots) <= 10 else "viridis")
    for index, robot in enumerate(robots):
        colour = cmap(index % 10 if len(robots) <= 10 else index / max(len(robots) - 1, 1))
        xs, ys = trails[robot].points()
        axis.plot(
            xs,
            ys,
            color=colour,
            linewidth=0.6,
            alpha=0.8,
            label=f"robot {robot}" if len(robots) <= 10 else None,
        )
        axis.plot(xs[:1], ys[:1], "o", color=colour, markersize=3)
        axis.plot(xs[-1:], ys[-1:], "x", color=colour, markersize=5)
    if not robots:
        axis.text(0, 0, "no robot poses recorded", ha="center")
    axis.set_xlim(-1.3 * radius, 1.3 * radius)
    axis.set_ylim(-1.3 * radius, 1.3 * radius)
    axis.set_aspect("equal")
    axis.set_xlabel("x (m)")
    axis.set_ylabel("y (m)")
    axis.set_title(f"run {recording.run_id}: trajectories (o start, x end)")
    if 0 < len(robots) <= 10:
        axis.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def _degrees(radians: float) -> float:
    return radians * 180.0 / 3.141592653589793


# --- the report ----------------------------------------------------------------------------


@dataclass
class Report:
    runs: list[dict[str, Any]]
    groups: list[dict[str, Any]]
    unreadable: list[str]
    files: list[str]

    def as_json(self) -> dict[str, Any]:
        return {
            "runs": self.runs,
            "groups": self.groups,
            "unreadable": self.unreadable,
            "files": self.files,
        }


def write_report(
    paths: Iterable[Path],
    out: Path,
    *,
    example: str | None = None,
    robot: int | None = None,
    per_run: bool = False,
    warn: Any = None,
    launcher_summaries: Mapping[Path, dict[str, Any]] | None = None,
) -> Report:
    """Read every recording, write the figures and tables into ``out``; a recording
    without the launcher's summary takes it from ``launcher_summaries`` if there."""
    make_private_folder(out)
    recordings: list[Recording] = []
    unreadable: list[str] = []
    for path in paths:
        try:
            recording = read_recording(path, robot)
        except (ValueError, OSError) as error:
            unreadable.append(str(error))
            if warn is not None:
                warn(f"skipping {path}: {error}")
            continue
        if recording.problem and warn is not None:
            warn(f"{path}: {recording.problem}; reporting what was recorded")
        recordings.append(recording)
    launchers = launcher_summaries or {}
    summaries = [
        run_summary(recording, warn, launchers.get(recording.path)) for recording in recordings
    ]
    for recording, summary in zip(recordings, summaries, strict=True):
        if summary["missing_messages"] and warn is not None:
            warn(
                f"{recording.path}: {summary['missing_messages']:,} of the messages its "
                "publishers sent are not in it (a recorder that fell behind drops what it "
                "cannot hold); what is drawn from them has gaps"
            )
    order = sorted(
        range(len(recordings)),
        key=lambda i: (
            summaries[i]["num_robots"],
            summaries[i]["num_sites"],
            _natural(summaries[i]["run_id"]),
        ),
    )
    recordings = [recordings[i] for i in order]
    summaries = [summaries[i] for i in order]
    runs = [
        report_row(summary, recording.path)
        for summary, recording in zip(summaries, recordings, strict=True)
    ]
    files: list[str] = []
    if recordings:
        plot_boxes(summaries, out / "fig4.png", pools=False)
        plot_boxes(summaries, out / "fig5.png", pools=True)
        chosen = _example(recordings, example)
        plot_opinion(chosen, _robot(chosen, robot), out / "fig2.png")
        plot_trajectories(chosen, out / "trajectories.png")
        files += [str(out / name) for name in FIGURES]
        if per_run:
            for recording in recordings:
                folder = out / "runs" / recording.run_id
                make_private_folder(folder)
                plot_opinion(recording, _robot(recording, robot), folder / "opinion.png")
                plot_trajectories(recording, folder / "trajectories.png")
                files += [str(folder / "opinion.png"), str(folder / "trajectories.png")]
    files += [str(out / "summary.csv"), str(out / "summary.json")]
    report = Report(runs, group_rows(runs, summaries), unreadable, files)
    with open_private(out / "summary.csv", "w", newline="") as stream:
        # A run's links (a mapping per outside robot) are for summary.json, not a CSV cell.
        writer = csv.DictWriter(stream, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(runs)
    write_private(out / "summary.json", json.dumps(report.as_json(), indent=2) + "\n")
    return report


def _example(recordings: Sequence[Recording], run_id: str | None) -> Recording:
    if run_id is not None:
        for recording in recordings:
            if recording.run_id == run_id:
                return recording
    return recordings[0]


def _robot(recording: Recording, robot: int | None) -> int:
    if robot is not None:
        return robot
    return 0 if recording.opinion_robot is None else recording.opinion_robot


# --- command line --------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recordings",
        nargs="+",
        type=Path,
        metavar="RUN.mcap",
        help="MCAP recordings of swarm runs (cut-short ones too)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="directory for the figures and the summary table",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print the summary (runs and groups) as one JSON object on stdout",
    )
    parser.add_argument(
        "--example",
        metavar="RUN_ID",
        default=None,
        help="the run shown in fig2.png and trajectories.png (default: the first recording)",
    )
    parser.add_argument(
        "--robot",
        type=int,
        default=None,
        metavar="ID",
        help="the robot whose opinion fig2.png shows (default: the lowest id)",
    )
    parser.add_argument(
        "--per-run",
        action="store_true",
        help="also write an opinion and a trajectories plot for every run",
    )


def run(args: argparse.Namespace) -> int:

    from bestofn_swarm.plumbing.cliargs import UsageError

    missing = [str(path) for path in args.recordings if not path.is_file()]
    if missing:
        raise UsageError(f"no such recording: {', '.join(missing)}")
    if args.robot is not None and args.robot < 0:
        raise UsageError(f"--robot must be a robot id (>= 0), got {args.robot}")
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} exists and is not a directory")

    def warn(text: str) -> None:
        print(f"swarm report: {text}", file=sys.stderr)

    report = write_report(
        args.recordings,
        args.out,
        example=args.example,
        robot=args.robot,
        per_run=args.per_run,
        warn=warn,
    )
    if args.json:
        print(json.dumps(report.as_json()))
    else:
        print_report(report, report_console())
    return 0 if report.runs else 1


REPORT_WIDTH = 200  # characters, when stdout is not a terminal (a log file, a pipe)


def report_console() -> Any:
    """A console for the report: the terminal's width, or wide enough for whole run ids
    and every column when written to a file (rich would assume 80 columns and cut them)."""
    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=REPORT_WIDTH)


def print_report(report: Report, console: Any) -> None:
    from rich.table import Table

    table = Table(title="runs (steps and pool sizes: mean, min-max)")
    table.add_column("run", no_wrap=True)
    for column in ("N", "n", "ended", "consensus", "swarm steps", "robot steps", "pool size"):
        table.add_column(column, justify="right", no_wrap=True)
    table.add_column("digest", no_wrap=True)
    for row in report.runs:
        ended = row["ended"]
        if ended == "timeout" and row.get("timeout_kind"):
            ended += f" ({row['timeout_kind']})"
        if row.get("stuck"):
            ended += f", {row['stuck']} stuck"
        table.add_row(
            row["run_id"] + ("" if row["complete"] else " (cut short)"),
            str(row["robots"]),
            str(row["sites"]),
            ended,
            ("correct" if row["correct"] else "wrong") if row["consensus"] else "none",
            "-" if row["swarm_steps"] is None else str(row["swarm_steps"]),
            "-"
            if row["steps_mean"] is None
            else f"{row['steps_mean']:.1f} {row['steps_min']}-{row['steps_max']}",
            "-"
            if row["pool_mean"] is None
            else f"{row['pool_mean']:.1f} {row['pool_min']}-{row['pool_max']}",
            row["digest"],
        )
    console.print(table)
    for row in report.runs:
        for robot, link in (row.get("links") or {}).items():
            rtt = (
                "-"
                if link.get("rtt_ms") is None
                else f"{link['rtt_ms']:.2f} ms median, {link['rtt_p95_ms']:.2f} ms p95"
            )
            console.print(
                f"{row['run_id']}: robot {robot} outside over {link['transport']}: round trip "
                f"{rtt}, loss {100 * link['loss']:.0f}%, {link['sessions']} session(s), "
                f"{link['refused']} frame(s) refused",
                highlight=False,
            )
    for group in report.groups:
        endings = ", ".join(f"{count} {name}" for name, count in group["endings"].items())
        aggregated = group["aggregated_runs"]
        if aggregated == 0:
            times = "none ended in consensus: no steps or pool sizes to aggregate"
        else:
            apart = f"of the {aggregated} that ended in consensus: "
            times = (
                f"{apart if aggregated != group['runs'] else ''}"
                f"{group['runs_within_half_n']} within n/2 = {group['half_n']:g} steps, "
                f"mean pool size {group['pool_size']['mean']}"
            )
        console.print(
            f"N = {group['robots']}, n = {group['sites']}: {group['runs']} runs ({endings}); "
            f"{group['correct_runs']}/{group['runs']} correct; {times}",
            highlight=False,
        )
    for path in report.files:
        console.print(f"wrote {path}", highlight=False)
