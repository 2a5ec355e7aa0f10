"""Following a run from what its processes publish: the robots' status, the world's state
(every ``--state-every`` ticks: its sim time and poses), the beacons' acks, the live page's
pause and play, the world's clock only when faults are to fall due at a sim time (the
launcher need not follow every tick, and costs the run nothing on the ticks in between),
and the run's ending, which the world decides (``world/ending``).

The subscription is thin (``subscribe``): Zenoh's callbacks only copy each sample, as it
came, into the launcher's inbox. The launcher's main thread hands them to
``Follower.take``, which passes each through the key table's gate (its tag, its decoding)
to the run's observer (``world_server/observer/observer.py``), which keeps the books: a
sample is believed only if its sender's tag says so and it makes sense (a robot's status
on its own key, not older than its last; a world state not older than the last), and what
is not believed is counted and, once per kind, logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from bestofn_swarm.plumbing.ending import open_ending
from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.wire import auth, keyspace, protocol
from bestofn_swarm.wire.keyspace import Party
from deploy.launcher.plan import RunPlan
from robot_agent.core.parking import ParkingSlots
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.observer import RunObserver
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

    # What the launcher hears, the key table says; the clock only when it is needed; and
    # the run's ending, which every process hears.
    watched = [
        kind for kind in keyspace.heard_by(Party.LAUNCHER) if clock or kind is not keyspace.CLOCK
    ] + [keyspace.ENDING]
    return [session.declare_subscriber(keys.every(kind), queue_as(kind)) for kind in watched]


class Follower:
    """The launcher's adapter of the run's observer (``RunObserver``): it hands over what
    Zenoh brought through the key table's gate, and keeps what only the launcher knows, the
    wall time of the world's ticks."""

    def __init__(self, plan: RunPlan, clock: Callable[[], float]) -> None:
        layout = make_layout(plan.sites, plan.robots, plan.seed)
        slots = ParkingSlots(
            [(site.x, site.y) for site in sorted(layout.sites, key=lambda site: site.id)],
            arena_radius=layout.arena_radius,
            nest_radius=layout.nest_radius,
            robot_radius=EPUCK.radius,
            config=plan.switches.controller,
        )
        outside = (
            {linked.robot: linked.address.transport for linked in plan.outside.robots}
            if (plan.outside)
            else {}
        )
        run = RunObserver(
            range(plan.robots),
            watchdog=Watchdog(
                range(plan.robots),
                plan.stall_window,
                body_length=2 * EPUCK.radius,
                slot_of=slots.slot,
            ),
            byzantine=plan.byzantine_robots,
            outside=outside,
        )
        self._begin(keyspace.Keys(plan.run_id), run, clock, hold=plan.hold)

    @classmethod
    def of_run(cls, keys: keyspace.Keys, clock: Callable[[], float]) -> Follower:
        """A follower of a run it knows only by its keys (``swarm follow``): its robots
        join as they are heard."""
        follower = cls.__new__(cls)
        follower._begin(keys, RunObserver((), open_roster=True), clock)
        return follower

    def _begin(
        self,
        keys: keyspace.Keys,
        run: RunObserver,
        clock: Callable[[], float],
        hold: bool = False,
    ) -> None:
        self.keys = keys
        self.clock = clock  # wall seconds: when the run started ticking
        self.run = run
        # Held for the live page, or paused from it: the world's clock stands still on
        # purpose. ``paused_since``: the wall time it was; ``paused_s``: paused before that.
        self.held = hold  # waiting for the first play
        self.paused_since: float | None = clock() if hold else None
        self.paused_s = 0.0
        self.started_at: float | None = None  # the wall time of the first clock or state
        self.ticked_at: float | None = None  # the wall time the sim clock last advanced
        self.ending: protocol.RunEnding | None = None  # the world's, once heard
        self._logged_rejections: set[keyspace.KeyKind] = set()

    def take(self, heard: Heard, keyring: auth.Keyring | None) -> bool:
        """Believe one sample, or count it as rejected; whether it was believed."""
        run = self.run
        before = run.sim_time
        try:
            if heard.kind is keyspace.ENDING:
                ending = open_ending(self.keys, heard.key, heard.payload, heard.attachment, keyring)
                self.ending = self.ending or ending
                return True
            opened = keyspace.open_sample(
                self.keys,
                heard.key,
                heard.payload,
                heard.attachment,
                keyring=keyring,
                kinds=frozenset({heard.kind}),
            )
            if opened is None:
                raise keyspace.SampleError(
                    f"{heard.key} is not a key of this run's {heard.kind.name}"
                )
            if heard.kind is keyspace.PACE:
                self._paced(opened.message)
            else:
                run.take(opened)
        except keyspace.SampleError as error:
            run.rejected += 1
            if heard.kind not in self._logged_rejections:  # once per kind of message
                self._logged_rejections.add(heard.kind)
                log.warning("rejected a message on %s: %s", heard.key, error)
            return False
        if heard.kind is keyspace.CLOCK or heard.kind is keyspace.STATE:
            self._ticked(opened.message.t, before)
        return True

    def _ticked(self, sim_time: float, before: float) -> None:
        """The world said its sim time (its clock and its state may come in either order)."""
        now = self.clock()
        if self.started_at is None:
            self.started_at = now
            if self.paused_since is not None:  # held: the run's time starts here
                self.paused_since = now
        if self.ticked_at is None or sim_time > before:
            self.ticked_at = now

    def _paced(self, pace: protocol.Pace) -> None:
        """The live page paused or played the run."""
        now = self.clock()
        if pace.playing and self.paused_since is not None:
            self.paused_s += now - self.paused_since
            self.paused_since = None
            self.held = False
            self.ticked_at = now if self.ticked_at is not None else None
        elif not pace.playing and self.paused_since is None:
            self.paused_since = now

    @property
    def paused(self) -> bool:
        """Held or paused by the live page: the world's clock stands still on purpose."""
        return self.paused_since is not None

    def paused_for(self) -> float:
        """Wall seconds the run has been held or paused so far."""
        since = self.paused_since
        return self.paused_s + (self.clock() - since if since is not None else 0.0)

    @property
    def started(self) -> bool:
        """The world has ticked: the robots have joined."""
        return self.started_at is not None

    def world_stopped(self, window: float) -> bool:
        """The world ticked, then its clock did not advance for ``window`` wall seconds
        (not while the live page holds or pauses it)."""
        return (
            not self.paused
            and self.ticked_at is not None
            and self.clock() - self.ticked_at >= window
        )
