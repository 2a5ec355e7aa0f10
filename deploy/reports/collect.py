"""Reading a recording for a report (``swarm report``): one message at a time, with
``world_server/recording/reader.py``, so a file cut short by a crash is read up to its last
complete record, keeping per robot only what a report needs and the swarm's curves (one
row per world state: ``world_server/observer/frame.py``); and the run's summary rebuilt
from its messages when the recording holds none."""

from __future__ import annotations

import itertools
import json
import math
from array import array
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.wire import keyspace, protocol
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.frame import FrameCollector
from world_server.observer.observer import RunObserver
from world_server.observer.summary import byzantine_in_config
from world_server.observer.watchdog import Watchdog
from world_server.recording.frame import collector_for
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
    """What a report keeps of one robot beyond what the run's observer keeps, whatever the
    length of the run: its last status (for the gaps in its counters) and its thinned
    trail."""

    id: int
    trail: Trail = field(default_factory=Trail)
    last: protocol.Status | None = None


def _observer() -> RunObserver:
    """The observer a report feeds: robots join as they are heard, and the watchdog only
    says where each undecided robot is stuck (its window plays no part)."""
    return RunObserver((), watchdog=Watchdog((), math.inf, 2 * EPUCK.radius), open_roster=True)


@dataclass
class Recording:
    """Everything a report needs from one MCAP file."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False  # the file ends with its footer
    problem: str | None = None  # why reading stopped early, if it did
    messages: Counter[str] = field(default_factory=Counter)  # by kind, or by schema name
    robots_heard: dict[int, RobotTrace] = field(default_factory=dict)  # by robot id
    observer: RunObserver = field(default_factory=_observer)  # the run, as its messages tell it
    opinion_robot: int | None = None  # whose every status is kept, for the opinion figure
    opinions: list[protocol.Status] = field(default_factory=list)  # that robot's statuses
    sense: dict[int, TickSpan] = field(default_factory=dict)
    act: dict[int, TickSpan] = field(default_factory=dict)
    ack: AckTicks = field(default_factory=AckTicks)
    clock: TickSpan = field(default_factory=TickSpan)
    state_ticks: list[int] = field(default_factory=list)
    declared: Declared = field(default_factory=Declared)
    first_clock_wall_ns: int | None = None
    last_clock_wall_ns: int | None = None
    # The swarm's curves (robots decided, each site's share of the opinions), one row per
    # world state; None until the first status or state.
    curves: FrameCollector | None = None

    @property
    def last_clock(self) -> protocol.Clock | None:
        return self.observer.last_clock

    @property
    def last_state(self) -> protocol.WorldState | None:
        return self.observer.last_state

    @property
    def links(self) -> dict[int, protocol.LinkStats]:
        """The robots outside the emulator: their links, as the bridge last reported."""
        return self.observer.links

    @property
    def undecodable(self) -> int:
        """Recorded messages this report could not take: not valid messages of their kind,
        or making no sense against the run (a status older than the robot's last)."""
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
    """Takes the messages a report needs, one at a time, through the key table's gate
    (``keyspace.open_recorded``) to the run's observer and the report's own counts; counts
    the rest by kind."""

    # What a report reads of a recording (the rest it only counts).
    READS = (
        keyspace.SENSE,
        keyspace.ACT,
        keyspace.STATUS,
        keyspace.ACK,
        keyspace.CLOCK,
        keyspace.STATE,
        keyspace.LINK,
    )

    def __init__(self, recording: Recording, reader: RecordingReader) -> None:
        self.recording = recording
        self.reader = reader
        # --robot: keep that robot's statuses for the opinion figure, and only its.
        self.opinion_robot_fixed = recording.opinion_robot is not None
        self.kinds = keyspace.by_schema()
        self.reads = frozenset(self.READS)

    def message(self, message: RecordedMessage) -> None:
        recording = self.recording
        kind = self.kinds.get(message.schema)
        recording.messages[kind.name if kind is not None else message.schema] += 1
        if kind is None or kind not in self.reads:
            return
        ident = keyspace.ident_in(kind, message.topic)
        if recording.curves is None and kind in (keyspace.STATUS, keyspace.STATE):
            recording.curves = collector_for(
                self.reader.description, message.data, every=1, robot_rows=False, keep=True
            )
        try:
            if ident is None:
                raise keyspace.SampleError(f"{message.topic} is no key of {kind.name}")
            opened = keyspace.open_recorded(kind, ident or None, message.data)
            self._take(opened, message.publish_time)
        except keyspace.SampleError:
            recording.messages["undecodable " + kind.name] += 1

    def _take(self, opened: keyspace.Opened, publish_time: int) -> None:
        recording, kind, value, robot = self.recording, opened.kind, opened.message, opened.robot
        observer = recording.observer
        if kind is keyspace.SENSE and robot is not None:
            recording.sense.setdefault(robot, TickSpan()).add(value.tick)
            self._trace(robot).trail.add(value.x, value.y)
            observer.pose(robot, value.t, (value.x, value.y, value.theta))
            recording.declared.rx += value.rx
            recording.declared.camera += value.camera
        elif kind is keyspace.ACT and robot is not None:
            recording.act.setdefault(robot, TickSpan()).add(value.tick)
            recording.declared.tx += value.radio_tx
        elif kind is keyspace.STATUS and robot is not None:
            self._status(robot, value)
        elif kind is keyspace.ACK:
            recording.ack.answered(value.tick, value.next_tick)
            recording.declared.tx += value.radio_tx
        elif kind is keyspace.CLOCK:
            recording.clock.add(value.tick)
            observer.clock(value)
            if recording.first_clock_wall_ns is None:
                recording.first_clock_wall_ns = publish_time
            recording.last_clock_wall_ns = publish_time
        elif kind is keyspace.STATE:
            recording.state_ticks.append(value.tick)
            observer.last_state = value  # its poses are not the report's: senses are
            if recording.curves is not None:
                recording.curves.state(value)
        elif kind is keyspace.LINK:
            observer.link(value)

    def _trace(self, robot: int) -> RobotTrace:
        trace = self.recording.robots_heard.get(robot)
        if trace is None:
            trace = self.recording.robots_heard[robot] = RobotTrace(robot)
            watchdog = self.recording.observer.watchdog
            if watchdog is not None:  # where the robot is, for where it is stuck
                watchdog.join(robot)
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
        recording.observer.status(status)
        if recording.curves is not None:
            recording.curves.status(status)
        # The opinion figure's robot: the one asked for, else the lowest id heard (a lower
        # one heard later starts its history at its first status, so that is whole too).
        if recording.opinion_robot is None or (
            not self.opinion_robot_fixed and robot < recording.opinion_robot
        ):
            recording.opinion_robot, recording.opinions = robot, []
        if robot == recording.opinion_robot:
            recording.opinions.append(status)


def read_recording(path: Path, opinion_robot: int | None = None) -> Recording:
    """Read one recording as far as it is readable (a truncated file too), one message at
    a time, keeping per robot only what the report needs (``RobotTrace``): its memory
    does not grow with the length of the run. ``opinion_robot``: the robot whose every
    status is kept for the opinion figure (default: the lowest id).

    Raises ValueError if the file is not an MCAP file at all.
    """
    recording = Recording(Path(path), opinion_robot=opinion_robot)
    reader = RecordingReader(path)
    collector = _Collector(recording, reader)
    for message in reader:
        collector.message(message)
    if recording.curves is not None:
        recording.curves.finish()
    recording.metadata = reader.metadata
    recording.complete = reader.complete
    recording.problem = reader.problem
    return recording


def rebuild_summary(recording: Recording) -> dict[str, Any]:
    """The ``swarm run --json`` summary, from the messages in the recording (the run's
    observer, as they fed it)."""
    observer = recording.observer
    for robot in range(recording.robots or 0):
        observer.join(robot)
    num_sites = recording.sites or _sites_from_statuses(recording) or 2
    num_robots = recording.robots or len(observer.records)
    seed = recording.seed or 0
    layout = recording.layout
    best = (
        layout["best_site"]
        if layout
        else make_layout(num_sites, max(num_robots, 1), seed).best_site
    )
    clock = recording.last_clock
    wall = 0.0
    if recording.first_clock_wall_ns is not None and recording.last_clock_wall_ns is not None:
        wall = (recording.last_clock_wall_ns - recording.first_clock_wall_ns) / 1e9
    return observer.summary(
        run_id=recording.run_id,
        num_robots=num_robots,
        num_sites=num_sites,
        seed=seed,
        best_site=best,
        sim_time_s=clock.t if clock else 0.0,
        wall_time_s=wall,
        world=recording.last_state,
        observer_rejected=recording.undecodable,
        config=recording.config,
        byzantine=byzantine_in_config(recording.config),
    )


def _sites_from_statuses(recording: Recording) -> int | None:
    for trace in recording.robots_heard.values():
        if trace.last is not None:
            return len(trace.last.opinion)
    return None
