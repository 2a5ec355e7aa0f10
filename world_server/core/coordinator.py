"""The world's coordinator: one run's ticks as a state machine fed events and a clock (no I/O).

It is fed ``Event``s with the time each is handled at, and ``wake`` calls when its
``deadline`` passes; it gives back ``Output``s (messages to publish, replies to queries,
the timeline of ``--trace``) through its outbox as soon as each is made. It never reads
a clock: every time it knows is one it was given.

Its life: it waits for the expected robots and beacons (or ``start_timeout``), opens
tick 0, then closes and opens ticks. Lockstep closes a tick when every participant
answered it and every radio message they announced arrived, or when the stall deadline
passes (a participant that misses SUSPEND_AFTER ticks in a row is not waited for until it
answers again); with nobody left it idles, and the next token that comes back closes the
tick at once. Real time closes a tick when the pacer says so, with whatever arrived.
Closing advances the World and delivers the radio; opening sends the clock first (to
each beacon that answers the tick, and on ``world/clock`` for observers), the camera
frames, every robot's senses, made for all of them at once (in its process's batch, sealed
with that process's key, if it answers in batches), and every ``state_every`` ticks the
world's state.

The live page paces it (``viewer/pace``, the page's tag): while paused no tick closes, and
a speed closes a tick no sooner than its share of wall time; a run started with ``hold``
opens tick 0 and waits there until the page says play. In lockstep this changes only when
ticks close, never what they hold: the run is the seed's, paced or not.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from enum import StrEnum

import msgspec
import numpy as np

from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from bestofn_swarm.wire.keyspace import How, Party
from bestofn_swarm.wire.names import Role
from world_server.core.clock import Pacer
from world_server.core.counters import Counters
from world_server.core.events import (
    Answered,
    Event,
    Happening,
    Mark,
    Moment,
    Opened,
    Outbox,
    Publish,
    Reply,
    ReplyError,
)
from world_server.core.intake import TickIntake
from world_server.core.roster import SUSPEND_AFTER, Host, Roster
from world_server.core.world import World

log = logging.getLogger("world_server")

UNAUTHENTICATED = b"unauthenticated query"
NO_ID_LEFT = b"no robot id left"


class Phase(StrEnum):
    WAITING = "waiting"  # for the expected robots and beacons
    RUNNING = "running"  # ticking
    STOPPED = "stopped"


class Coordinator:
    """Runs the ticks of one World."""

    def __init__(
        self,
        world: World,
        keys: keyspace.Keys,
        outbox: Outbox,
        *,
        stall_timeout: float,
        start_timeout: float,
        state_every: int,
        speed: float = 1.0,
        expect_robots: int = 0,
        expect_beacons: int = 0,
        keyring: auth.Keyring | None = None,
        traced: bool = False,
        hold: bool = False,
    ) -> None:
        """The run starts once ``expect_robots`` robots and ``expect_beacons`` beacons are
        live (0: as soon as one robot is), or ``start_timeout`` after ``begin`` with at
        least one robot; ``traced`` adds the timeline outputs (Mark, Opened, Answered);
        ``hold``: tick 0 closes only once the live page says play."""
        self.world = world
        self.keys = keys
        self.outbox = outbox
        self.keyring = keyring  # None: an unauthenticated run
        self.lockstep = world.config.clock == "lockstep"
        self.speed = speed
        self.pacer = Pacer(world.config.dt, speed)
        self.playing = not hold  # the live page's pause (a held run starts paused)
        # Lockstep at the page's speed: a tick closes no sooner than its pacer says (None:
        # as soon as every answer is in).
        self.lockstep_pacer: Pacer | None = None
        self.stall_timeout = stall_timeout
        self.start_timeout = start_timeout
        self.state_every = state_every
        self.expect_robots = expect_robots
        self.expect_beacons = expect_beacons
        self.traced = traced
        self.counters = Counters()
        self.roster = Roster(world, keys, self.counters, proof=keyring is not None)
        self.intake = TickIntake(world, keys, self.counters, keyring)
        self.phase = Phase.WAITING
        self.start_deadline = 0.0
        self.stall_deadline = 0.0  # lockstep: when the tick under way closes without all
        self.now = 0.0  # the time of the last event or wake-up
        # What the world takes in, by the kind of the key table it came on, or happening.
        self._handlers: dict[keyspace.KeyKind | Happening, Callable[[Event], None]] = {
            keyspace.ACT: self._act,
            keyspace.HOST_ACT: self._acts,
            keyspace.ACK: self._ack,
            keyspace.RADIO_TX: self.intake.take_tx,
            keyspace.STATS: self._stats,
            keyspace.JOIN: self._join,
            keyspace.INFO: self._info,
            keyspace.PACE: self._pace,
            Happening.REFUSED: lambda event: self.counters.reject(
                event.key, event.payload.decode(errors="replace")
            ),
            Happening.STOP: lambda event: self.stop(),
        }
        for kind in keyspace.heard_by(Party.WORLD, how=How.TOKEN):
            self._handlers[kind] = self._token

    # --- fed from outside --------------------------------------------------------------

    def begin(self, now: float) -> None:
        """Start waiting for the expected robots and beacons."""
        self.now = now
        self.start_deadline = now + self.start_timeout
        log.info(
            "waiting for %d robot(s) and %d beacon(s)", self.expect_robots, self.expect_beacons
        )
        self.wake(now)

    def handle(self, event: Event, now: float) -> None:
        """Take one event handled at ``now``, then close and open ticks as due."""
        self.take(event, now)
        self.wake(now)

    def take(self, event: Event, now: float) -> None:
        """Take one event handled at ``now``, without closing a tick."""
        self.now = now
        handler = self._handlers.get(event.kind)
        # A stopped world still says its counters (the launcher asks them at the end).
        if handler is not None and (self.phase != Phase.STOPPED or event.kind is keyspace.STATS):
            handler(event)

    def wake(self, now: float) -> None:
        """Time is ``now``: start, close and open ticks as due."""
        self.now = now
        if self.phase == Phase.WAITING:
            self._wait(now)
        elif self.phase == Phase.RUNNING:
            if not self.playing:
                # Paused: nothing closes, and no one is late for a tick that waits.
                self.stall_deadline = now + self.stall_timeout
            elif self.lockstep:
                self._lockstep(now)
            elif now >= self.pacer.deadline(self.world.tick, now):
                self.close_tick()

    def dropped(self, count: int) -> None:
        """The transport dropped ``count`` messages on arrival (too big, or over its cap)."""
        self.counters.dropped(count)

    def stop(self) -> None:
        """Stop; a running world publishes its state a last time."""
        if self.phase == Phase.RUNNING:
            self._publish_state()
        self.phase = Phase.STOPPED

    @property
    def stopped(self) -> bool:
        return self.phase == Phase.STOPPED

    @property
    def deadline(self) -> float | None:
        """When to wake the coordinator if no event comes first; None: only an event."""
        if self.phase == Phase.WAITING:
            return self.start_deadline if self.now < self.start_deadline else None
        if self.phase == Phase.STOPPED or not self.playing:
            return None
        if self.lockstep:
            paced = self.lockstep_pacer
            if paced is not None and self.intake.barrier.complete:
                return min(self.stall_deadline, paced.deadline(self.world.tick, self.now))
            return self.stall_deadline
        return self.pacer.deadline(self.world.tick, self.now)

    # --- the start ---------------------------------------------------------------------

    def _wait(self, now: float) -> None:
        """Start at tick 0 once the expected robots and beacons are live, or once the
        start timeout passed with at least one robot."""
        self.roster.apply_joins()
        robots, beacons = len(self.world.live_robots()), len(self.world.beacons())
        if robots == 0:
            return
        if robots >= self.expect_robots and beacons >= self.expect_beacons:
            log.info("starting with %d robot(s), %d beacon(s)", robots, beacons)
        elif now >= self.start_deadline:
            log.warning(
                "start timeout: starting with %d of %d robot(s), %d of %d beacon(s)",
                robots,
                self.expect_robots,
                beacons,
                self.expect_beacons,
            )
        else:
            return
        self.phase = Phase.RUNNING
        self._open_tick(self.world.tick, rx_counts={}, frames={})
        self.stall_deadline = now + self.stall_timeout
        if not self.lockstep:
            self.pacer.deadline(self.world.tick, now)  # the pacer's clock starts now

    # --- lockstep ----------------------------------------------------------------------

    def _lockstep(self, now: float) -> None:
        if (
            not self.intake.barrier.answers
            and not self.world.live_robots()
            and not self.roster.pending
        ):
            # Nobody to wait for: idle. Robots that join while nobody is left (every token
            # went at once: this process or its links were frozen longer than Zenoh's
            # lease) find the next tick open for them at once: joins take effect when a
            # tick closes.
            self.stall_deadline = now + self.stall_timeout
            return
        complete = self.intake.barrier.complete
        paced = self.lockstep_pacer
        if complete and paced is not None and now < paced.deadline(self.world.tick, now):
            return  # in before its time at the page's speed: it closes at its deadline
        if complete or now >= self.stall_deadline:
            if not complete:
                self._log_stall()
            self.close_tick()
            self.stall_deadline = now + self.stall_timeout

    def _log_stall(self) -> None:
        self.counters.stalls += 1
        missing = self.intake.barrier.missing()
        for who in missing:
            self.counters.missed[who] = self.counters.missed.get(who, 0) + 1
            if self.counters.missed[who] == SUSPEND_AFTER:
                log.warning(
                    "%s missed %d ticks in a row: not waiting for it until it answers again",
                    who,
                    SUSPEND_AFTER,
                )
        if self.counters.stalls <= 5 or self.counters.stalls % 100 == 0:
            log.warning(
                "tick %d stalled for %.1fs waiting for %s (stall #%d)",
                self.world.tick,
                self.stall_timeout,
                ", ".join(missing[:10]),
                self.counters.stalls,
            )

    # --- inputs ------------------------------------------------------------------------

    def _act(self, event: Event) -> None:
        robot = self.intake.take_act(event)
        if robot is not None and self.lockstep and self.traced:
            self._answered(event, names.robot_identity(robot))

    def _acts(self, event: Event) -> None:
        routes = self.intake.take_acts(event)
        self.roster.hosts.update(routes)
        if self.lockstep and self.traced:
            for robot in routes:
                self._answered(event, names.robot_identity(robot))

    def _ack(self, event: Event) -> None:
        taken = self.intake.take_ack(event)
        if taken is None:
            return
        who, ack = taken
        name = who.partition("/")[2]
        if ack.next_tick is None:
            self.roster.beacon_next.pop(name, None)
        else:
            self.roster.beacon_next[name] = ack.next_tick
        if self.traced:
            self._answered(event, who)

    def _answered(self, event: Event, who: str) -> None:
        self.outbox(Answered(who, event.arrived, self.now))

    def _token(self, event: Event) -> None:
        """A robot's or a beacon's liveliness token appeared, or went."""
        if not event.gone:
            self.roster.appeared(event.key)
            return
        token = self.roster.went(event.key)
        if token is None:
            return
        if token.role == Role.ROBOT:
            robot = int(token.ident)
            self.intake.leave(names.robot_identity(robot), robot)
        else:
            self.intake.leave(names.beacon_identity(token.ident))

    def _asker(self, event: Event) -> tuple[str, bytes] | None:
        """Who asked the query (identity, nonce); None (rejected, refused) without its
        asker's tag."""
        try:
            return auth.query_open(self.keyring, event.key, event.payload, event.attachment)
        except auth.AuthError as error:
            self.counters.reject(event.key, error)
            self.outbox(ReplyError(event.query, UNAUTHENTICATED))
            return None

    def _join(self, event: Event) -> None:
        """Give a robot started with ``--id auto`` an id."""
        asker = self._asker(event)
        if asker is None:
            return
        robot = self.roster.assign_id()
        if robot is None:
            self.outbox(ReplyError(event.query, NO_ID_LEFT))
            return
        self._reply(event, asker, protocol.encode(protocol.JoinReply(v=protocol.VERSION, id=robot)))

    def _info(self, event: Event) -> None:
        """A world/info query (answered by the transport): its asker proved itself present."""
        try:
            identity, _ = auth.query_open(self.keyring, event.key, event.payload, event.attachment)
        except auth.AuthError as error:
            self.counters.reject(event.key, error)
            return
        self.roster.proved(identity)

    def _stats(self, event: Event) -> None:
        asker = self._asker(event)
        if asker is not None:
            self._reply(event, asker, protocol.encode(self.state()))

    def _pace(self, event: Event) -> None:
        """The live page's pause, play or speed (its tag checked; refused and counted
        otherwise). Going on after a pause or at a new speed, the pacing starts again from
        the tick under way."""
        try:
            metadata = auth.unseal(
                self.keyring, names.VIEWER, event.key, event.payload, event.attachment
            )
            if metadata:
                raise auth.AuthError("a pace carries no metadata")
            pace = protocol.decode(event.payload, protocol.Pace)
        except (auth.AuthError, protocol.ProtocolError) as error:
            self.counters.reject(event.key, error)
            return
        resumed = pace.playing and not self.playing
        if resumed or pace.speed != self._paced_speed():
            self.stall_deadline = self.now + self.stall_timeout
            if self.lockstep:
                self.lockstep_pacer = (
                    None if pace.speed is None else Pacer(self.world.config.dt, pace.speed)
                )
            else:
                self.pacer = Pacer(
                    self.world.config.dt, self.speed if pace.speed is None else pace.speed
                )
        if pace.playing != self.playing:
            log.info(
                "%s by the live page at tick %d",
                "playing" if pace.playing else "paused",
                self.world.tick,
            )
        self.playing = pace.playing

    def _paced_speed(self) -> float | None:
        if self.lockstep:
            return None if self.lockstep_pacer is None else self.lockstep_pacer.speed
        return None if self.pacer.speed == self.speed else self.pacer.speed

    def _reply(self, event: Event, asker: tuple[str, bytes], payload: bytes) -> None:
        identity, nonce = asker
        attachment = auth.reply_seal(self.keyring, identity, event.key, payload, nonce)
        self.outbox(Reply(event.query, event.key, payload, attachment))

    # --- closing and opening ticks -----------------------------------------------------

    def close_tick(self) -> None:
        """Close the tick under way with what arrived: advance the world, let the joins
        take effect, deliver the radio; then open the next tick."""
        if self.traced:
            self.outbox(Mark(Moment.CLOSE_START))
        acts, transmissions = self.intake.close()
        result = self.world.advance(acts, transmissions)
        if self.traced:
            self.outbox(Mark(Moment.ADVANCED))
        self.roster.apply_joins()
        rx_counts = {name: len(items) for name, items in result.deliveries.items()}
        for name, deliveries in result.deliveries.items():
            key = self.keys.of(keyspace.RADIO_RX, name)
            receiver = names.robot_identity(int(name))  # only robots receive
            for delivery in deliveries:
                meta = protocol.RadioRxMeta(
                    v=protocol.VERSION,
                    tick=result.tick,
                    sender=delivery.sender,
                    seq=delivery.seq,
                    sent_tick=delivery.sent_tick,
                )
                self.outbox(
                    Publish(
                        key,
                        delivery.payload,
                        None,
                        identity=receiver,
                        keyring=self.keyring,
                        meta=meta,
                        meta_encode=protocol.encode,
                    )
                )
        if self.traced:
            self.outbox(Mark(Moment.DELIVERED))
        self._open_tick(result.tick, rx_counts, result.frames)

    def _open_tick(
        self, tick: int, rx_counts: dict[str, int], frames: dict[int, np.ndarray]
    ) -> None:
        if self.traced:
            self.outbox(Mark(Moment.OPEN_START))
        # The clock first: a beacon that answers this tick does so while the senses go out.
        # Each beacon is sent it only for the ticks it answers; world/clock is for observers.
        clock = protocol.Clock(v=protocol.VERSION, tick=tick, t=self.world.t)
        for beacon in self.roster.beacons_answering(tick):
            key = self.keys.of(keyspace.BEACON_CLOCK, beacon)
            self.outbox(self._world_message(key, clock))
        self.outbox(self._world_message(self.keys.of(keyspace.CLOCK), clock, if_heard=True))
        spec = self.world.config.camera
        for robot, frame in frames.items():
            meta = protocol.CameraMeta(
                v=protocol.VERSION,
                tick=tick,
                width=spec.width,
                height=spec.height,
                encoding="png",
            )
            self.outbox(
                Publish(
                    self.keys.of(keyspace.CAMERA, robot),
                    frame,
                    self.world.camera.encode,  # PNG, lossless: the robot sees what was rendered
                    identity=names.robot_identity(robot),
                    keyring=self.keyring,
                    meta=meta,
                    meta_encode=protocol.encode,
                )
            )
        batched = self._send_senses(rx_counts, frames)
        self.intake.open(tick, self.roster.participants(tick))
        if tick % self.state_every == 0:
            self._publish_state()
        if self.traced:
            rx = sum(rx_counts.values())
            robots = len(self.world.live_robots())
            self.outbox(Opened(tick, robots, len(frames), rx, batched))
            self.outbox(Mark(Moment.OPENED))

    def _send_senses(self, rx_counts: dict[str, int], frames: dict[int, np.ndarray]) -> int:
        """Send every live robot its senses, made for all of them at once: on its own key,
        or in its process's batch, sealed with that process's key; how many went in
        batches. Batches go first, each as soon as it is made, so their processes step
        while the rest are made."""
        robots = self.world.live_robots()
        rx = {robot: rx_counts.get(names.robot_name(robot), 0) for robot in robots}
        senses = self.world.senses(robots, rx, frames)
        hosts = self.roster.hosts
        alone: list[int] = []  # indices in ``robots`` of those sensed on their own keys
        batches: dict[Host, list[int]] = {}
        for index, robot in enumerate(robots):
            host = hosts.get(robot)
            if host is None:
                alone.append(index)
            else:
                batches.setdefault(host, []).append(index)
        for host, rows in batches.items():
            message = batch.SenseRows(
                host.last,
                senses.tick,
                senses.t,
                [robots[row] for row in rows],
                [senses.values[row] for row in rows],
                [senses.rx[row] for row in rows],
                [senses.camera[row] for row in rows],
            )
            self.outbox(
                Publish(
                    self.keys.of(keyspace.HOST_SENSE, host.first),
                    message,
                    batch.encode_sense_rows,
                    identity=host.identity,
                    keyring=self.keyring,
                    steady=True,
                )
            )
        if alone:
            messages = senses.messages()
            for index in alone:
                robot = robots[index]
                self.outbox(
                    Publish(
                        self.keys.of(keyspace.SENSE, robot),
                        messages[index],
                        protocol.encode,
                        identity=names.robot_identity(robot),
                        keyring=self.keyring,
                        steady=True,
                    )
                )
        return len(robots) - len(alone)

    def _publish_state(self) -> None:
        self.outbox(self._world_message(self.keys.of(keyspace.STATE), self.state()))

    def _world_message(
        self, key: str, message: msgspec.Struct, *, if_heard: bool = False
    ) -> Publish:
        """A message of the world's own, sent tick after tick, tagged with its key."""
        return Publish(
            key,
            message,
            protocol.encode,
            identity=names.WORLD,
            keyring=self.keyring,
            steady=True,
            if_heard=if_heard,
        )

    def state(self) -> protocol.WorldState:
        """The world's poses and counters (world/state, world/stats)."""
        counters = self.counters
        return self.world.state(counters.rejected, counters.stalls, counters.departures)
