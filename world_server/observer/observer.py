"""The one observer of a run (pure: no I/O, no clock): what anyone who follows a run knows
of it, fed the run's messages, and how the run ended.

Everything that watches a run feeds one ``RunObserver`` through a thin adapter: the
launcher (``deploy/launcher/follower.py``, from what Zenoh brings), the in-process engine
(the cores' own messages, typed), ``swarm report`` and the replay (a recording, message by
message), the live page (``deploy/viewer/live.py``) and the recorder's scene
(``world_server/recording/writer.py``). A sample reaches it through the key table's gate
(``keyspace.open_message``, after its tag was checked where there is one), as an
``Opened``; ``take`` hands it to the part it feeds. It owns:

* each robot's record (``RobotRecord``: its latest status, the pools it joined, its
  restarts and how it left) and its latest pose;
* the poolings and decisions (``PoolingTracker``: whom each pooling joined, from the
  radio deliveries), for those that draw them;
* the stall watchdog (``Watchdog``), when the observer is to say whether the run stalled;
* the world's latest clock and state (sim time, counters), the beacons' reject counts and
  the links of the robots outside the emulator;
* the progress (robots decided, trips) and the run's outcome and summary;
* the run's time series (``frame.FrameCollector``), when it is given one: every status
  and world state it believes is handed on.

A sample that is authentic but makes no sense against what the observer knows (a status
older than the robot's last, a world state older than the last, a status of a robot not
in the run) raises ``keyspace.SampleError``: the adapter counts it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.endings import Stop, TimeLimit
from world_server.core.pooling import Pooling, PoolingTracker
from world_server.observer.frame import FrameCollector
from world_server.observer.summary import RobotRecord, RunOutcome, build_summary
from world_server.observer.watchdog import Watchdog

Pose = tuple[float, float, float]  # x, y, theta


@dataclass(frozen=True)
class Noted:
    """What one status told beyond the robot's record: a pooling it reports (whom it
    joined), and whether the robot just decided."""

    pooling: Pooling | None = None
    decided: bool = False


NOTHING = Noted()


class RunObserver:
    """A run as its messages tell it."""

    def __init__(
        self,
        robots: Iterable[int],
        *,
        watchdog: Watchdog | None = None,
        byzantine: Iterable[int] = (),
        outside: Mapping[int, str] | None = None,
        poolings: bool = False,
        open_roster: bool = False,
        series: FrameCollector | None = None,
    ) -> None:
        """``robots``: the run's robots. ``watchdog``: whether the run stalled is asked of
        it. ``byzantine``: the robots that lie (their decisions are not the swarm's).
        ``outside``: robots outside the emulator, with their link's transport.
        ``poolings``: track whom each pooling joined (views draw it). ``open_roster``: a
        robot heard that is not among ``robots`` joins (a recording read without its
        description), rather than being refused. ``series``: the run's time series, fed
        what is believed here."""
        self.records: dict[int, RobotRecord] = {robot: RobotRecord(robot) for robot in robots}
        self.poses: dict[int, Pose] = {}
        self.watchdog = watchdog
        self.byzantine = frozenset(byzantine)
        self.outside = dict(outside or {})
        for robot, transport in self.outside.items():
            self.records.setdefault(robot, RobotRecord(robot)).outside = transport
        self.tracker = PoolingTracker() if poolings else None
        self.open_roster = open_roster
        self.series = series
        self.sim_time = 0.0  # the latest sim time the world's clock or state said
        self.last_clock: protocol.Clock | None = None
        self.last_state: protocol.WorldState | None = None
        self.links: dict[int, protocol.LinkStats] = {}  # the bridge's latest of each link
        self.beacon_rejected: dict[str, int] = {}  # the beacons' own counts, from their acks
        self.rejected = 0  # samples the adapter did not believe (or had no room for)

    # --- fed -------------------------------------------------------------------------

    def take(self, opened: keyspace.Opened, t: float | None = None) -> Noted:
        """One sample through the key table's gate (``t``: its sim time, for a radio
        delivery; default: the latest the world said). Raises SampleError for one that
        makes no sense against what is known."""
        kind, message = opened.kind, opened.message
        if kind is keyspace.STATUS:
            return self.status(message)
        if kind is keyspace.STATE:
            self.state(message)
        elif kind is keyspace.CLOCK:
            self.clock(message)
        elif kind is keyspace.ACK:
            self.ack(opened.ident or "", message)
        elif kind is keyspace.LINK:
            self.link(message)
        elif kind is keyspace.SENSE and opened.robot is not None:
            self.pose(opened.robot, message.t, (message.x, message.y, message.theta))
        elif kind is keyspace.RADIO_RX and opened.robot is not None:
            self.delivery(opened.robot, opened.meta.sender, self.sim_time if t is None else t)
        return NOTHING

    def join(self, robot: int) -> RobotRecord:
        """A robot of the run not known until now (a recording read without its
        description): its record."""
        record = self.records.get(robot)
        if record is None:
            record = self.records[robot] = RobotRecord(robot)
        if self.watchdog is not None:
            self.watchdog.join(robot)
        return record

    def status(self, status: protocol.Status) -> Noted:
        """A robot's status."""
        record = self.records.get(status.id)
        if record is None:
            if not self.open_roster:
                raise keyspace.SampleError(f"no robot {status.id} in this run")
            record = self.join(status.id)
        if record.status and status.tick < record.status.tick and not record.restarting:
            # Authentic but old: someone replaying what it heard, not the robot.
            raise keyspace.SampleError(f"status of tick {status.tick}, older than the last")
        record.update(status)
        if self.watchdog is not None:
            self.watchdog.status(status)
        if self.series is not None:
            self.series.status(status)
        if self.tracker is None:
            return NOTHING
        pooling, decided = self.tracker.on_status(status)
        return Noted(pooling, decided) if pooling is not None or decided else NOTHING

    def state(self, state: protocol.WorldState) -> None:
        """The world's state: every pose, its counters, its sim time."""
        last = self.last_state
        if last is not None and state.tick < last.tick:
            # Authentic but old: someone replaying what it heard, not the world, whose ticks
            # only go forward (a replayed state's poses would look like progress).
            raise keyspace.SampleError(
                f"world state of tick {state.tick}, older than the last ({last.tick})"
            )
        self.last_state = state
        self.sim_time = max(self.sim_time, state.t)
        if self.series is not None:
            self.series.state(state)
        for pose in state.robots:
            self.poses[pose.id] = (pose.x, pose.y, pose.theta)
        if self.watchdog is not None:
            self.watchdog.poses(state.t, ((pose.id, pose.x, pose.y) for pose in state.robots))

    def clock(self, clock: protocol.Clock) -> None:
        self.last_clock = clock
        self.sim_time = max(self.sim_time, clock.t)

    def pose(self, robot: int, t: float, pose: Pose) -> None:
        """One robot's pose at sim time ``t`` (its senses, where no world state is had)."""
        self.poses[robot] = pose
        if self.watchdog is not None:
            self.watchdog.poses(t, [(robot, pose[0], pose[1])])

    def ack(self, beacon: str, ack: protocol.Ack) -> None:
        self.beacon_rejected[beacon] = max(self.beacon_rejected.get(beacon, 0), ack.rejected)

    def link(self, stats: protocol.LinkStats) -> None:
        """A robot outside the emulator: its link, as its bridge reports it."""
        if stats.robot not in self.outside and not self.open_roster:
            raise keyspace.SampleError(f"robot {stats.robot} is not outside the emulator")
        self.links[stats.robot] = stats
        self.join(stats.robot).outside = stats.transport

    def delivery(self, receiver: int, sender: str, t: float) -> None:
        """A radio message the medium delivered at sim time ``t`` (whom poolings joined)."""
        if self.tracker is not None:
            self.tracker.on_delivery(receiver, sender, t)

    # --- what happened to robots' processes ------------------------------------------

    def crashed(self, robot: int) -> None:
        """The robot's process died on its own: it holds nothing up."""
        self.records[robot].crashed = True
        if self.watchdog is not None:
            self.watchdog.retired(robot)

    def killed(self, robot: int) -> None:
        """The robot was stopped on purpose (a fault): it holds nothing up."""
        self.records[robot].killed = True
        if self.watchdog is not None:
            self.watchdog.retired(robot)

    def restarted(self, robot: int) -> None:
        """The robot was started afresh (a fault): it starts undecided, from now."""
        record = self.records[robot]
        record.killed = False
        record.restarted()
        if self.watchdog is not None:
            self.watchdog.restarted(robot, self.sim_time)

    def returned(self, robot: int) -> None:
        """A robot given up as crashed runs again (its process was only cut off)."""
        self.records[robot].crashed = False
        if self.watchdog is not None:
            self.watchdog.resumed(robot)

    def departed(self, present: Iterable[int]) -> None:
        """The run ends: an outside robot whose link is down is not among those that
        decide, as a robot whose process went."""
        here = set(present)
        for robot in self.outside:
            self.records[robot].departed = robot not in here

    def outside_present(self) -> list[int]:
        """The outside robots whose program is connected now (as the bridge last said)."""
        return [
            robot for robot in self.outside if robot in self.links and self.links[robot].connected
        ]

    # --- asked -----------------------------------------------------------------------

    def decided(self) -> int:
        """Robots that decided."""
        return sum(1 for record in self.records.values() if record.decided_site is not None)

    def trips(self) -> int:
        return sum(record.status.trips for record in self.records.values() if record.status)

    def all_decided(self, live: Iterable[int]) -> bool:
        """Every honest robot among ``live`` (those still running) decided."""
        return all(
            self.records[robot].decided_site is not None
            for robot in live
            if robot not in self.byzantine
        )

    def last_decision(self, live: Iterable[int]) -> float:
        """The sim time at which the last of ``live`` decided (0 if none did)."""
        return max(
            (
                status.decision_time or 0.0
                for robot in live
                if (status := self.records[robot].status) is not None
            ),
            default=0.0,
        )

    def stalled(self, now: float) -> bool:
        """The watchdog: no robot at work progressed for its window (False without one)."""
        return self.watchdog is not None and self.watchdog.stalled(now)

    def stuck(self) -> list[dict[str, Any]]:
        """Where each undecided robot is, and since when (the watchdog's view)."""
        return [] if self.watchdog is None else self.watchdog.stuck()

    def honest(self) -> list[int]:
        return [robot for robot in self.records if robot not in self.byzantine]

    def summary(
        self,
        *,
        run_id: str,
        num_robots: int,
        num_sites: int,
        seed: int,
        best_site: int,
        wall_time_s: float,
        config: dict[str, Any],
        sim_time_s: float | None = None,
        stop: Stop | None = None,
        timeout_kind: TimeLimit | None = None,
        world: protocol.WorldState | None,
        departures: int | None = None,
        byzantine: Mapping[int, str] | None = None,
        robot_processes: int = 0,
        observer_rejected: int | None = None,
    ) -> dict[str, Any]:
        """The run's summary (the ``swarm run --json`` object), from what was observed:
        ``world``, the world's final counters (None: not known)."""
        outcome = RunOutcome(
            run_id=run_id,
            num_robots=num_robots,
            num_sites=num_sites,
            seed=seed,
            best_site=best_site,
            sim_time_s=self.sim_time if sim_time_s is None else sim_time_s,
            wall_time_s=wall_time_s,
            timed_out=stop is Stop.TIMEOUT,
            radio=world.radio if world is not None else protocol.RadioCounters(),
            world_rejected=world.rejected if world is not None else 0,
            stalls=world.stalls if world is not None else 0,
            departures=(world.departures if world is not None else 0)
            if departures is None
            else departures,
            links=self.links,
            observer_rejected=self.rejected if observer_rejected is None else observer_rejected,
            beacon_rejected=sum(self.beacon_rejected.values()),
            config=config,
            stop=stop,
            timeout_kind=timeout_kind if stop is Stop.TIMEOUT else None,
            stuck=self.stuck(),
            byzantine=dict(byzantine or {}),
            robot_processes=robot_processes,
        )
        return build_summary(outcome, self.records.values())


__all__ = ["NOTHING", "Noted", "RunObserver"]
