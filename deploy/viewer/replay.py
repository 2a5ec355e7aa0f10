"""``swarm view RECORDING.mcap``: the live page, replaying a recording.

The recording is read once, message by message, as far as it is readable (a file cut short
by a crash too, like ``swarm report``: ``world_server/recording/reader.py``), into a
``Timeline``: world states, each robot's statuses, the
clock and the radio deliveries, in sim time. A frame at any sim time is then looked up,
not replayed: poses are interpolated between the two world states around it, each robot
shows its latest status, and poolings and decisions were found once while reading. So
seeking, the speed and jumping to the next pooling or decision cost the same anywhere.

Recordings of every version so far hold the same raw channels (the recorder has written
one channel per key, topic = key, JSON payloads, since it was first written); a recording
without ``world/state`` falls back on the robots' ``sense`` poses.
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.keyspace import Party
from deploy.viewer.core import model
from deploy.viewer.core.series import Series
from deploy.viewer.options import VIEW_PORT
from deploy.viewer.server import ViewServer
from world_server.core.layout import make_layout
from world_server.core.pooling import LINK_SECONDS, Pooling
from world_server.observer.frame import FrameCollector
from world_server.observer.observer import RunObserver
from world_server.recording.frame import collector_for
from world_server.recording.reader import RecordedMessage, RecordingReader, count_of, json_of
from world_server.recording.records import RUN_METADATA

SPEEDS = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
MAX_DELIVERIES_PER_FRAME = 2000


@dataclass
class Timeline:
    """Everything the page shows of a recording, indexed by sim time."""

    path: Path
    run_id: str = ""
    seed: int = 0
    robots: int = 0
    sites: int = 0
    layout: dict[str, Any] | None = None
    summary: dict[str, Any] | None = None
    complete: bool = False
    problem: str | None = None
    dt: float = 0.1
    state_times: list[float] = field(default_factory=list)
    states: list[protocol.WorldState] = field(default_factory=list)
    sense_poses: dict[int, list[tuple[float, float, float, float]]] = field(default_factory=dict)
    statuses: dict[int, list[protocol.Status]] = field(default_factory=dict)
    status_times: dict[int, list[float]] = field(default_factory=dict)
    clock_times: list[float] = field(default_factory=list)
    clock_walls: list[int] = field(default_factory=list)
    deliveries: list[tuple[float, str, int]] = field(default_factory=list)
    poolings: list[Pooling] = field(default_factory=list)
    decisions: list[tuple[float, int]] = field(default_factory=list)
    # The robots decided, as the run's observer counted them after each status in sim time.
    decided: list[tuple[float, int]] = field(default_factory=list)
    # Robots outside the emulator: their links' figures as the bridge reported them.
    link_times: dict[int, list[float]] = field(default_factory=dict)
    links: dict[int, list[protocol.LinkStats]] = field(default_factory=dict)
    # The swarm's curves, one point per world state (world_server/observer/frame.py).
    series: Series = field(default_factory=Series)

    @property
    def start(self) -> float:
        return self.clock_times[0] if self.clock_times else 0.0

    @property
    def end(self) -> float:
        ends = [self.clock_times[-1] if self.clock_times else 0.0]
        ends += [self.state_times[-1]] if self.state_times else []
        ends += [times[-1] for times in self.status_times.values() if times]
        return max(ends)


class _Loader:
    """Puts the messages the page shows into a timeline, one at a time: each through the key
    table's gate (``keyspace.open_recorded``), to the timeline's indexes and to the run's
    observer, which finds the poolings and decisions and counts the robots decided."""

    def __init__(self, timeline: Timeline, reader: RecordingReader, with_sense: bool) -> None:
        self.timeline = timeline
        self.reader = reader
        self.run = RunObserver((), poolings=True, open_roster=True)
        self.collector: FrameCollector | None = None  # made once the description is read
        shown = {*keyspace.heard_by(Party.VIEWER), *([keyspace.SENSE] if with_sense else [])}
        self.kinds = {kind.schema: kind for kind in shown if kind.schema is not None}

    def message(self, message: RecordedMessage) -> None:
        kind = self.kinds.get(message.schema)
        ident = None if kind is None else keyspace.ident_in(kind, message.topic)
        if kind is None or ident is None:
            return
        try:
            opened = keyspace.open_recorded(kind, ident or None, message.data)
        except keyspace.SampleError:
            return  # the report counts these; the page just does not draw them
        timeline, value = self.timeline, opened.message
        if kind in (keyspace.STATE, keyspace.STATUS) and self.collector is None:
            self.collector = collector_for(
                self.reader.description, message.data, every=1, robot_rows=False, keep=False
            )
            self.run.series = self.collector
        if kind is keyspace.STATE:
            timeline.state_times.append(value.t)
            timeline.states.append(value)
            try:
                self.run.state(value)
            except keyspace.SampleError:
                return
            self.chart()
        elif kind is keyspace.STATUS:
            timeline.statuses.setdefault(value.id, []).append(value)
            timeline.status_times.setdefault(value.id, []).append(value.t)
            try:
                noted = self.run.status(value)
            except keyspace.SampleError:
                return
            if noted.pooling is not None:
                timeline.poolings.append(noted.pooling)
            if noted.decided:
                timeline.decisions.append((value.t, value.id))
            timeline.decided.append((value.t, self.run.decided()))
        elif kind is keyspace.CLOCK:
            if value.tick:
                timeline.dt = value.t / value.tick
            timeline.clock_times.append(value.t)
            timeline.clock_walls.append(message.publish_time)
        elif kind is keyspace.RADIO_RX and opened.robot is not None:
            t = opened.meta.tick * timeline.dt
            timeline.deliveries.append((t, opened.meta.sender, opened.robot))
            self.run.delivery(opened.robot, opened.meta.sender, t)
        elif kind is keyspace.LINK:
            timeline.link_times.setdefault(value.robot, []).append(message.log_time / 1e9)
            timeline.links.setdefault(value.robot, []).append(value)
        elif kind is keyspace.SENSE and opened.robot is not None:
            poses = timeline.sense_poses.setdefault(opened.robot, [])
            poses.append((value.t, value.x, value.y, value.theta))

    def chart(self, finish: bool = False) -> None:
        """Take the swarm rows finished (all, once the recording is read) into the timeline."""
        if self.collector is not None:
            if finish:
                self.collector.finish()
            self.timeline.series.extend(self.collector.take()[1])


def load(path: Path) -> Timeline:
    """Read a recording into a timeline. Raises ValueError if it is not a recording."""
    timeline = _read(path, with_sense=False)
    if not timeline.states:  # no world/state recorded: the robots' own poses will do
        timeline = _read(path, with_sense=True)
    _sort(timeline)
    return timeline


def _read(path: Path, with_sense: bool) -> Timeline:
    timeline = Timeline(Path(path))
    reader = RecordingReader(path)
    loader = _Loader(timeline, reader, with_sense)
    for message in reader:
        loader.message(message)
    loader.chart(finish=True)
    timeline.complete = reader.complete
    # The page names only the kind of error that cut the file short.
    stopped = reader.stopped_by
    timeline.problem = (
        f"cut short: {type(stopped).__name__}" if stopped is not None else reader.problem
    )
    description = reader.description
    timeline.run_id = description.get("run_id") or Path(path).stem
    timeline.seed = count_of(description.get("seed"))
    timeline.robots = count_of(description.get("robots")) or len(timeline.statuses)
    timeline.sites = count_of(description.get("sites")) or _sites_of(timeline)
    timeline.layout = json_of(description.get("layout"))
    summary = json_of(reader.metadata.get(RUN_METADATA, {}).get("summary"))
    timeline.summary = summary
    return timeline


def _sites_of(timeline: Timeline) -> int:
    for statuses in timeline.statuses.values():
        if statuses:
            return len(statuses[0].opinion)
    return 2


def _sort(timeline: Timeline) -> None:
    """Samples are recorded in arrival order; lookups need sim-time order."""
    order = sorted(range(len(timeline.states)), key=timeline.state_times.__getitem__)
    timeline.states = [timeline.states[i] for i in order]
    timeline.state_times = [timeline.state_times[i] for i in order]
    for robot, statuses in timeline.statuses.items():
        statuses.sort(key=lambda status: status.t)
        timeline.status_times[robot] = [status.t for status in statuses]
    for poses in timeline.sense_poses.values():
        poses.sort()
    timeline.deliveries.sort(key=lambda delivery: delivery[0])
    timeline.poolings.sort(key=lambda pooling: pooling.t)
    timeline.decisions.sort()
    timeline.decided.sort(key=lambda entry: entry[0])


# --- looking up one moment ---------------------------------------------------------------


def _angle_between(a: float, b: float, share: float) -> float:
    return a + share * ((b - a + 3.141592653589793) % 6.283185307179586 - 3.141592653589793)


def poses_at(timeline: Timeline, t: float) -> dict[int, tuple[float, float, float]]:
    """Every robot's pose at sim time ``t``, interpolated between recorded poses."""
    if timeline.states:
        index = bisect.bisect_right(timeline.state_times, t)
        before = timeline.states[max(index - 1, 0)]
        after = timeline.states[min(index, len(timeline.states) - 1)]
        span = after.t - before.t
        share = min(max((t - before.t) / span, 0.0), 1.0) if span > 0 else 0.0
        later = {pose.id: pose for pose in after.robots}
        poses = {}
        for pose in before.robots:
            nxt = later.get(pose.id, pose)
            poses[pose.id] = (
                pose.x + share * (nxt.x - pose.x),
                pose.y + share * (nxt.y - pose.y),
                _angle_between(pose.theta, nxt.theta, share),
            )
        return poses
    poses = {}
    for robot, recorded in timeline.sense_poses.items():
        index = bisect.bisect_right(recorded, (t, float("inf"), 0.0, 0.0))
        if recorded:
            _, x, y, theta = recorded[max(index - 1, 0)]
            poses[robot] = (x, y, theta)
    return poses


def links_at(timeline: Timeline, t: float) -> dict[int, protocol.LinkStats]:
    """Each outside robot's link as last reported by sim time ``t`` (its first report
    before that)."""
    found = {}
    for robot, times in timeline.link_times.items():
        index = max(bisect.bisect_right(times, t) - 1, 0)
        found[robot] = timeline.links[robot][index]
    return found


def decided_at(timeline: Timeline, t: float) -> int:
    """The robots decided at sim time ``t``, as the run's observer counted them."""
    index = bisect.bisect_right(timeline.decided, (t, 1 << 62))
    return timeline.decided[index - 1][1] if index else 0


def counters_at(timeline: Timeline, t: float) -> protocol.WorldState | None:
    index = bisect.bisect_right(timeline.state_times, t)
    return timeline.states[index - 1] if index else None


def real_time_factor_at(timeline: Timeline, t: float) -> float | None:
    """How fast the recorded run went up to ``t``: sim seconds per wall second."""
    index = bisect.bisect_right(timeline.clock_times, t) - 1
    if index <= 0:
        return None
    wall = (timeline.clock_walls[index] - timeline.clock_walls[0]) / 1e9
    return (timeline.clock_times[index] - timeline.clock_times[0]) / wall if wall > 0.5 else None


class ReplaySource:
    """A ``FrameSource`` that plays a timeline at a chosen speed."""

    def __init__(self, timeline: Timeline, speed: float = 10.0) -> None:
        self.timeline = timeline
        layout = make_layout(max(timeline.sites, 2), max(timeline.robots, 1), timeline.seed)
        self.scene = model.Scene(
            timeline.run_id, timeline.seed, timeline.robots, layout, mode="replay"
        )
        self.t = timeline.start
        self.speed = speed
        self.playing = True
        self._last_wall = time.monotonic()
        self._last_t = self.t

    def hello(self) -> dict[str, Any]:
        timeline = self.timeline
        return self.scene.hello(
            {
                "recording": {
                    "path": str(timeline.path),
                    "complete": timeline.complete,
                    "problem": timeline.problem,
                    "poolings": len(timeline.poolings),
                    "decisions": len(timeline.decisions),
                }
            }
        )

    def _advance(self) -> None:
        now = time.monotonic()
        if self.playing:
            self.t = min(self.t + self.speed * (now - self._last_wall), self.timeline.end)
            if self.t >= self.timeline.end:
                self.playing = False
        self._last_wall = now

    def robots_at(self, t: float) -> dict[int, model.RobotView]:
        timeline = self.timeline
        views = {robot: model.RobotView(pose=pose) for robot, pose in poses_at(timeline, t).items()}
        for robot, times in timeline.status_times.items():
            index = bisect.bisect_right(times, t)
            if index:
                views.setdefault(robot, model.RobotView()).status = timeline.statuses[robot][
                    index - 1
                ]
        return views

    def frame(self) -> dict[str, Any]:
        self._advance()
        timeline, t = self.timeline, self.t
        previous, self._last_t = self._last_t, t
        low = bisect.bisect_right(timeline.deliveries, (min(previous, t), "\uffff", 1 << 62))
        high = bisect.bisect_right(timeline.deliveries, (t, "\uffff", 1 << 62))
        deliveries = [
            (sender, receiver)
            for _, sender, receiver in timeline.deliveries[
                max(low, high - MAX_DELIVERIES_PER_FRAME) : high
            ]
        ]
        recent = bisect.bisect_left([p.t for p in timeline.poolings], t - LINK_SECONDS)
        at_end = t >= timeline.end
        return model.frame(
            self.scene,
            t=t,
            tick=round(t / timeline.dt) if timeline.dt else 0,
            robots=self.robots_at(t),
            decided=decided_at(timeline, t),
            counters=counters_at(timeline, t),
            poolings=timeline.poolings[recent:],
            deliveries=deliveries,
            real_time_factor=real_time_factor_at(timeline, t),
            ended=self._ending() if at_end else None,
            links=links_at(timeline, t),
            extra={
                "replay": {
                    "playing": self.playing,
                    "speed": self.speed,
                    "start": timeline.start,
                    "end": timeline.end,
                }
            },
        )

    def _ending(self) -> dict[str, Any]:
        if self.timeline.summary is not None:
            return model.ending(self.timeline.summary)
        return {
            "reason": "cut short",
            "text": f"recording {self.timeline.problem or 'ends here'}, no run summary",
        }

    def series_since(self, epoch: int, count: int) -> dict[str, Any] | None:
        """The whole run's curves (the page draws them up to the sim time shown)."""
        return self.timeline.series.since(epoch, count)

    def page_connected(self) -> None:
        """A replay is held by no one."""

    def opinion(self, robot: int) -> dict[str, Any]:
        view = self.robots_at(self.t).get(robot)
        return model.opinion_message(robot, None if view is None else view.status)

    def command(self, message: dict[str, Any]) -> None:
        op = message.get("op")
        timeline = self.timeline
        if op == "play":
            if self.t >= timeline.end:
                self.t = timeline.start
            self.playing = True
        elif op == "pause":
            self.playing = False
        elif op == "seek" and isinstance(message.get("t"), int | float):
            self.t = min(max(float(message["t"]), timeline.start), timeline.end)
            self._last_t = self.t
        elif op == "speed" and isinstance(message.get("speed"), int | float):
            self.speed = min(max(float(message["speed"]), SPEEDS[0]), SPEEDS[-1])
        elif op == "next" and message.get("kind") in ("pooling", "decision"):
            times = (
                [pooling.t for pooling in timeline.poolings]
                if message["kind"] == "pooling"
                else [t for t, _ in timeline.decisions]
            )
            index = bisect.bisect_right(times, self.t + 1e-6)
            if index < len(times):
                self.t = times[index]
                self._last_t = self.t
                self.playing = False  # stop on it, so that it can be looked at


# --- command line --------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", type=Path, metavar="RECORDING.mcap", help="a run's recording")
    parser.add_argument(
        "--port",
        type=_port,
        default=VIEW_PORT,
        help=f"TCP port of the page (default: {VIEW_PORT}; 0: any free port)",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default: 127.0.0.1, this machine only)",
    )
    parser.add_argument(
        "--speed",
        type=float,
        choices=SPEEDS,
        default=10.0,
        help="sim seconds per wall second to start with (default: 10)",
    )


def _port(text: str) -> int:
    if not text.isdigit() or int(text) > 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port (0 to 65535)")
    return int(text)


def run(args: argparse.Namespace) -> int:
    from bestofn_swarm.plumbing.cliargs import UsageError

    if not args.recording.is_file():
        raise UsageError(f"no such recording: {args.recording}")
    try:
        timeline = load(args.recording)
    except (ValueError, OSError) as error:
        print(f"swarm view: {error}", file=sys.stderr)
        return 1
    if timeline.problem:
        print(f"swarm view: {args.recording}: {timeline.problem}; showing what was recorded")
    source = ReplaySource(timeline, args.speed)
    try:
        asyncio.run(_serve(source, args.host, args.port))
    except OSError as error:
        print(f"swarm view: cannot serve on {args.host}:{args.port}: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    return 0


async def _serve(source: ReplaySource, host: str, port: int) -> None:
    server = ViewServer(source)
    bound = await server.start(host, port)
    shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else host
    print(f"swarm view: replaying {source.timeline.run_id} at http://{shown}:{bound}/", flush=True)
    try:
        await asyncio.Event().wait()  # until Ctrl-C or a signal
    finally:
        await server.close()
