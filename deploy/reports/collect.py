"""Reading a recording for a report (``swarm report``): one message at a time, with
``world_server/recording/reader.py``, so a file cut short by a crash is read up to its last
complete record, keeping per robot only what a report needs; and the run's summary rebuilt
from its messages when the recording holds none."""

from __future__ import annotations

import itertools
import json
import math
from array import array
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from bestofn_swarm.wire import protocol
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.summary import (
    RobotRecord,
    RunOutcome,
    build_summary,
    byzantine_in_config,
)
from world_server.observer.watchdog import Watchdog
from world_server.recording.reader import RecordedMessage, RecordingReader, run_description
from world_server.recording.records import RUN_METADATA

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
