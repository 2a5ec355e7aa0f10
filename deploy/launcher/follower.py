"""Following a run from what its processes publish: the robots' status, the world's state
(every ``--state-every`` ticks: its sim time and poses), the beacons' acks, and the world's
clock only when faults are to fall due at a sim time: the launcher need not follow every
tick, and costs the run nothing on the ticks in between.

The subscription is thin (``subscribe``): Zenoh's callbacks only copy each sample, as it
came, into the launcher's inbox. The launcher's main thread hands them to
``Follower.take``, which does the checks and the bookkeeping, with no I/O and its clock
given: a sample is believed only if its sender's tag says so and it makes sense (a
robot's status on its own key, not older than its last; a world state not older than
the last), and what is not believed is
counted and, once per kind, logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import zenoh

from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.wire import auth, keyspace, protocol
from bestofn_swarm.wire.keyspace import Party
from deploy.launcher.plan import RunPlan
from robot_agent.core.parking import ParkingSlots
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.summary import RobotRecord
from world_server.observer.watchdog import Watchdog

log = logging.getLogger("swarm.run")


@dataclass(frozen=True)
class Heard:
    """One sample as it came, not yet checked."""

    kind: keyspace.KeyKind
    key: str
    payload: bytes
    attachment: bytes | None = None

    @property
    def size(self) -> int:
        return message_bytes(self.payload, self.attachment, self.key)


def subscribe(
    session: zenoh.Session, keys: keyspace.Keys, inbox: BoundedInbox[Any], clock: bool
) -> list[Any]:
    """Queue every status, state and ack of the run in ``inbox``, and every clock if
    ``clock`` (a fault falls due at a sim time); the subscribers."""

    def queue_as(kind: keyspace.KeyKind) -> Callable[[zenoh.Sample], None]:
        def callback(sample: zenoh.Sample) -> None:
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            heard = Heard(kind, str(sample.key_expr), sample.payload.to_bytes(), extra)
            inbox.put(heard, heard.size)

        return callback

    # What the launcher hears, the key table says; the clock only when it is needed.
    watched = [
        kind for kind in keyspace.heard_by(Party.LAUNCHER) if clock or kind is not keyspace.CLOCK
    ]
    return [session.declare_subscriber(keys.every(kind), queue_as(kind)) for kind in watched]


class Follower:
    """What the launcher knows of the run: each robot's record, the stall watchdog, the
    sim time, the world's last state, the beacons' reject counts, and how many samples
    it rejected itself."""

    def __init__(self, plan: RunPlan, clock: Callable[[], float]) -> None:
        self.keys = keyspace.Keys(plan.run_id)
        self.clock = clock  # wall seconds: when the run started ticking
        self.byzantine = frozenset(plan.byzantine_robots)
        self.records = {robot: RobotRecord(robot) for robot in range(plan.robots)}
        layout = make_layout(plan.sites, plan.robots, plan.seed)
        slots = ParkingSlots(
            [(site.x, site.y) for site in sorted(layout.sites, key=lambda site: site.id)],
            arena_radius=layout.arena_radius,
            nest_radius=layout.nest_radius,
            robot_radius=EPUCK.radius,
            config=plan.switches.controller,
        )
        self.outside = (
            {linked.robot: linked for linked in plan.outside.robots} if plan.outside else {}
        )
        for robot, linked in self.outside.items():
            self.records[robot].outside = linked.address.transport
        self.links: dict[int, protocol.LinkStats] = {}  # the bridge's latest of each link
        self.watchdog = Watchdog(
            range(plan.robots),
            plan.stall_window,
            body_length=2 * EPUCK.radius,
            slot_of=slots.slot,
        )
        self.sim_time = 0.0  # the latest of the world's clock and state
        self.started_at: float | None = None  # the wall time of the first clock or state
        self.ticked_at: float | None = None  # the wall time the sim clock last advanced
        self.last_state: protocol.WorldState | None = None
        self.beacon_rejected: dict[str, int] = {}  # the beacons' own counts, from their acks
        self.rejected = 0  # samples the launcher did not believe (or had no room for)
        self._logged_rejections: set[keyspace.KeyKind] = set()

    # --- taking samples -------------------------------------------------------------

    def take(self, heard: Heard, keyring: auth.Keyring | None) -> bool:
        """Believe one sample, or count it as rejected; whether it was believed."""
        try:
            self._believe(heard, keyring)
        except (protocol.ProtocolError, auth.AuthError) as error:
            self.rejected += 1
            if heard.kind not in self._logged_rejections:  # once per kind of message
                self._logged_rejections.add(heard.kind)
                log.warning("rejected a message on %s: %s", heard.key, error)
            return False
        return True

    def _believe(self, heard: Heard, keyring: auth.Keyring | None) -> None:
        key, payload, attachment = heard.key, heard.payload, heard.attachment
        # Whose tag the key carries, and the robot or beacon it names: the key table says.
        found = keyspace.classify(self.keys, key)
        if found is None or found.kind is not heard.kind or found.speaker is None:
            raise protocol.ProtocolError(f"{key} is not a key of this run's {heard.kind.name}")
        identity, robot = found.speaker, found.robot
        if heard.kind is keyspace.STATUS:
            if robot not in self.records:
                raise protocol.ProtocolError(f"no robot {robot} in this run")
            auth.unseal(keyring, identity, key, payload, attachment)
            status = protocol.decode(payload, protocol.Status)
            if status.id != robot:
                raise protocol.ProtocolError(f"status of robot {status.id} on {key}")
            record = self.records[robot]
            if record.status and status.tick < record.status.tick and not record.restarting:
                # Authentic but old: someone replaying what it heard, not the robot.
                raise protocol.ProtocolError(f"status of tick {status.tick}, older than the last")
            record.update(status)
            self.watchdog.status(status)
        elif heard.kind is keyspace.ACK:
            auth.unseal(keyring, identity, key, payload, attachment)
            name = identity.partition("/")[2]
            ack = protocol.decode(payload, protocol.Ack)
            self.beacon_rejected[name] = max(self.beacon_rejected.get(name, 0), ack.rejected)
        elif heard.kind is keyspace.LINK:
            if robot not in self.outside:
                raise protocol.ProtocolError(f"robot {robot} is not outside the emulator")
            auth.unseal(keyring, identity, key, payload, attachment)
            stats = protocol.decode(payload, protocol.LinkStats)
            if stats.robot != robot:
                raise protocol.ProtocolError(f"the link of robot {stats.robot} on {key}")
            self.links[robot] = stats
        elif heard.kind is keyspace.CLOCK:
            auth.unseal(keyring, identity, key, payload, attachment)
            self._ticked(protocol.decode(payload, protocol.Clock).t)
        else:
            auth.unseal(keyring, identity, key, payload, attachment)
            state = protocol.decode(payload, protocol.WorldState)
            last = self.last_state
            if last is not None and state.tick < last.tick:
                # Authentic but old: someone replaying what it heard, not the world, whose
                # ticks only go forward (a replayed state's poses would look like progress).
                raise protocol.ProtocolError(
                    f"world state of tick {state.tick}, older than the last ({last.tick})"
                )
            self._ticked(state.t)
            self.last_state = state
            self.watchdog.poses(state.t, ((pose.id, pose.x, pose.y) for pose in state.robots))

    def _ticked(self, sim_time: float) -> None:
        """The world said its sim time (its clock and its state may come in either order)."""
        now = self.clock()
        if self.started_at is None:
            self.started_at = now
        if self.ticked_at is None or sim_time > self.sim_time:
            self.ticked_at = now
        self.sim_time = max(self.sim_time, sim_time)

    # --- what happened to robots' processes -----------------------------------------

    def crashed(self, robot: int) -> None:
        """The robot's process died on its own: it holds nothing up."""
        self.records[robot].crashed = True
        self.watchdog.retired(robot)

    def killed(self, robot: int, *, restarting: bool) -> None:
        """The robot's process was killed on purpose (``--kill``, ``--restart``); a
        restarted robot starts afresh, undecided, from now."""
        record = self.records[robot]
        record.killed = not restarting
        self.watchdog.retired(robot)
        if restarting:
            record.restarted()
            self.watchdog.restarted(robot, self.sim_time)

    def outside_present(self) -> list[int]:
        """The outside robots whose program is connected now (as the bridge last said)."""
        return [
            robot for robot in self.outside if robot in self.links and self.links[robot].connected
        ]

    def departed(self) -> None:
        """The run ends: an outside robot whose link is down is not among those that
        decide, as a robot whose process went."""
        for robot in self.outside:
            self.records[robot].departed = robot not in self.outside_present()

    # --- what the launcher asks -----------------------------------------------------

    @property
    def started(self) -> bool:
        """The world has ticked: the robots have joined."""
        return self.started_at is not None

    def world_stopped(self, window: float) -> bool:
        """The world ticked, then its clock did not advance for ``window`` wall seconds."""
        return self.ticked_at is not None and self.clock() - self.ticked_at >= window

    def decided(self) -> int:
        return sum(1 for record in self.records.values() if record.decided_site is not None)

    def trips(self) -> int:
        return sum(record.status.trips for record in self.records.values() if record.status)

    def all_decided(self, live: Iterable[int]) -> bool:
        """Every honest robot among ``live`` (those whose process runs) has decided."""
        return all(
            self.records[robot].decided_site is not None
            for robot in live
            if robot not in self.byzantine
        )

    def last_decision_time(self, live: Iterable[int]) -> float:
        """The sim time at which the last of ``live`` decided (0 if none did)."""
        return max(
            (
                status.decision_time or 0.0
                for robot in live
                if (status := self.records[robot].status) is not None
            ),
            default=0.0,
        )
