"""``world-server``: the world of one run on Zenoh (the only Zenoh code of the world).

Zenoh callbacks only copy bytes into one inbox; a single thread owns the World and does
everything else, so there are no locks around the simulation. By default the server is
the Zenoh router of a local run, listening on loopback.

Trust: it takes a message only with its sender's run-key tag (in a keyed run), from a
robot of its own swarm or a beacon, for the tick it is in; it answers queries only to
identities of the run; it drops a departed sender's queued transmissions. Every
rejection is counted (``WorldState.rejected``, the radio's ``rejected``).
"""

from __future__ import annotations

import argparse
import logging
import queue
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec
import zenoh

from plumbing import cliargs, run_keys, settings_cli
from plumbing.inbox import BoundedInbox
from plumbing.lifecycle import die_with_launcher
from plumbing.trace import TraceWriter, now, open_trace
from plumbing.zenoh_session import (
    open_from_args,
    reliable_publisher,
    reliable_put,
    session_mode,
)
from wire import auth, batch, names, protocol
from wire.names import Role
from world_server.core.clock import Barrier, Pacer
from world_server.core.world import Transmission, World, WorldConfig
from world_server.server.options import WORLD_SERVER_OPTIONS, WorldServerConfig, world_server_config

log = logging.getLogger("world_server")

SUSPEND_AFTER = 3  # consecutive stalled ticks before the barrier stops waiting
MAX_BEACONS = 16  # beacon tokens the world takes part in its barrier
MAX_TX_PER_TICK = 1000  # radio messages one sender may send in one tick (Act.radio_tx's bound)
MAX_LOGGED_KEYS = 1000  # keys whose first rejection is logged; then one line says so
INBOX_BYTES = 256 * 2**20  # what may wait for the world's thread, at most
# The largest valid message: a batch of acts (a radio payload and its attachment, alone).
MAX_MESSAGE_BYTES = max(batch.MAX_BATCH_BYTES, protocol.MAX_PAYLOAD_BYTES + 1024)


@dataclass(frozen=True)
class Event:
    kind: str  # act | acts | ack | tx | alive | gone | stats | stop
    key: str = ""
    payload: bytes = b""
    attachment: bytes | None = None
    query: Any = None
    arrived: float = 0.0  # monotonic time the callback took it (only when tracing)


@dataclass
class Counters:
    rejected: int = 0
    late: int = 0
    stalls: int = 0
    departures: int = 0  # robots and beacons whose liveliness token went while it ran
    missed: dict[str, int] = field(default_factory=dict)  # consecutive stalled ticks
    logged_keys: set[str] = field(default_factory=set)


class WorldServer:
    """Runs the tick loop of one World over a Zenoh session."""

    def __init__(
        self,
        session: zenoh.Session,
        world: World,
        keys: protocol.Keys,
        *,
        config: WorldServerConfig | None = None,
        expect_robots: int = 0,
        expect_beacons: int = 0,
        keyring: auth.Keyring | None = None,
        trace: TraceWriter | None = None,
    ) -> None:
        """``config`` says how to pace and publish ``world`` (its own world is not used);
        the run starts once ``expect_robots`` robots and ``expect_beacons`` beacons are live
        (0: at once)."""
        config = config or WorldServerConfig()
        self.session = session
        self.world = world
        self.keys = keys
        self.keyring = keyring  # None: an unauthenticated run
        self.lockstep = world.config.clock == "lockstep"
        self.pacer = Pacer(world.config.dt, config.speed)
        self.stall_timeout = config.stall_timeout
        self.start_timeout = config.start_timeout
        self.expect_robots = expect_robots
        self.expect_beacons = expect_beacons
        self.state_every = config.state_every
        self.inbox: BoundedInbox[Event] = BoundedInbox(INBOX_BYTES, MAX_MESSAGE_BYTES)
        self.counters = Counters()
        self.barrier = Barrier()
        self.acts: dict[int, protocol.Act] = {}
        self.transmissions: list[Transmission] = []
        self.sent_this_tick: dict[str, int] = {}  # radio messages per sender in this tick
        self.seqs_this_tick: set[tuple[str, int]] = set()  # (sender, seq): each once
        self.pending_joins: list[tuple[str, str]] = []
        self.assigned: set[int] = set()  # ids handed out on world/join
        self._info_bytes = protocol.encode(world.info)
        self._sense_publishers: dict[int, zenoh.Publisher] = {}
        # Robots whose process answers in batches: robot -> the process's lead robot. Their
        # senses go out in one batch per process; learnt from the first authentic act in a
        # batch, forgotten when the lead's liveliness goes (wire/batch.py).
        self.hosts: dict[int, int] = {}
        self._batch_publishers: dict[int, zenoh.Publisher] = {}
        self._declared: list[Any] = []
        self.trace = trace  # --trace: one line per tick (plumbing/trace.py)
        self._tick_trace: dict[str, Any] = {}
        # Built once: every act and radio message of every tick goes through it.
        self._handlers: dict[str, Callable[[Event], object]] = {
            "act": self._handle_act,
            "acts": self._handle_acts,
            "ack": self._handle_ack,
            "tx": self._handle_tx,
            "alive": self._handle_alive,
            "gone": self._handle_gone,
            "stats": self._handle_stats,
            "join": self._handle_join,
            "refused": lambda event: self._reject(event.key, event.payload.decode()),
        }

    # --- Zenoh side: callbacks copy bytes and return ----------------------------------

    def _on_sample(self, kind: str) -> Any:
        def callback(sample: zenoh.Sample) -> None:
            attachment = sample.attachment
            payload = sample.payload.to_bytes()
            extra = attachment.to_bytes() if attachment is not None else None
            size = len(payload) + len(extra or b"")
            arrived = now() if self.trace is not None else 0.0
            event = Event(kind, str(sample.key_expr), payload, extra, arrived=arrived)
            self.inbox.put(event, size, "arrival")

        return callback

    def _on_alive(self, sample: zenoh.Sample) -> None:
        kind = "alive" if sample.kind == zenoh.SampleKind.PUT else "gone"
        self.inbox.put(Event(kind, str(sample.key_expr)))

    def _on_info(self, query: zenoh.Query) -> None:
        """Answer ``world/info`` at once (on Zenoh's thread: it needs nothing of the tick)."""
        key = self.keys.world_info
        try:
            identity, nonce = self._asker(query, key)
        except auth.AuthError as error:
            self.inbox.put(Event("refused", key, str(error).encode()))
            query.reply_err(b"unauthenticated query")
            return
        attachment = auth.reply_seal(self.keyring, identity, key, self._info_bytes, nonce)
        query.reply(key, self._info_bytes, attachment=attachment)

    def _asker(self, query: zenoh.Query, key: str) -> tuple[str, bytes]:
        """Who asked (identity, nonce); AuthError for a query without its asker's tag."""
        payload = query.payload.to_bytes() if query.payload is not None else b""
        attachment = query.attachment.to_bytes() if query.attachment is not None else None
        return auth.query_open(self.keyring, key, payload, attachment)

    def declare(self) -> None:
        keys, session = self.keys, self.session
        self._declared = [
            session.declare_subscriber(keys.act("*"), self._on_sample("act")),
            session.declare_subscriber(keys.host_act("*"), self._on_sample("acts")),
            session.declare_subscriber(keys.beacon_ack("*"), self._on_sample("ack")),
            session.declare_subscriber(keys.radio_tx("*"), self._on_sample("tx")),
            session.liveliness().declare_subscriber(
                f"{keys.prefix}/alive/**", self._on_alive, history=True
            ),
            session.declare_queryable(keys.world_info, self._on_info),
            session.declare_queryable(
                keys.world_stats, lambda query: self.inbox.put(Event("stats", query=query))
            ),
            session.declare_queryable(
                keys.world_join, lambda query: self.inbox.put(Event("join", query=query))
            ),
            # The token names this world instance, so robots can tell a restarted world.
            session.liveliness().declare_token(keys.alive(Role.WORLD, str(session.info.zid()))),
        ]
        self._clock_publisher = reliable_publisher(session, keys.world_clock)
        self._state_publisher = reliable_publisher(session, keys.world_state)

    def stop(self) -> None:
        self.inbox.put(Event("stop"))

    # --- the loop ----------------------------------------------------------------------

    def run(self) -> int:
        self.declare()
        if not self._wait_for_start():
            return 0
        self._open_tick(self.world.tick, rx_counts={}, frames={})
        stall_deadline = time.monotonic() + self.stall_timeout
        while True:
            now = time.monotonic()
            if self.lockstep:
                timeout = max(0.0, stall_deadline - now)
            else:
                timeout = max(0.0, self.pacer.deadline(self.world.tick, now) - now)
            try:
                event = self.inbox.get(timeout=min(timeout, 0.5))
            except queue.Empty:
                event = None
            if event is not None:
                if event.kind == "stop":
                    break
                self._handle(event)
            now = time.monotonic()
            if self.lockstep:
                if (
                    not self.barrier.answers
                    and not self.world.live_robots()
                    and not self.pending_joins
                ):
                    stall_deadline = now + self.stall_timeout  # nobody to wait for: idle
                    continue
                # Robots that join while nobody is left (every token went at once: this
                # process or its links were frozen longer than Zenoh's lease) find the next
                # tick open for them at once: joins take effect when a tick closes.
                stalled = now >= stall_deadline
                if self.barrier.complete or stalled:
                    if stalled and not self.barrier.complete:
                        self._log_stall()
                    self._close_tick()
                    stall_deadline = time.monotonic() + self.stall_timeout
            elif now >= self.pacer.deadline(self.world.tick, now):
                self._close_tick()
        self._publish_state()
        return 0

    def _wait_for_start(self) -> bool:
        """Wait until the expected robots and beacons are live, then start at tick 0."""
        deadline = time.monotonic() + self.start_timeout
        log.info(
            "waiting for %d robot(s) and %d beacon(s)", self.expect_robots, self.expect_beacons
        )
        while True:
            self._apply_joins()
            robots, beacons = len(self.world.live_robots()), len(self.world.beacons())
            if robots >= self.expect_robots and beacons >= self.expect_beacons and robots > 0:
                log.info("starting with %d robot(s), %d beacon(s)", robots, beacons)
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0 and robots > 0:
                log.warning(
                    "start timeout: starting with %d of %d robot(s), %d of %d beacon(s)",
                    robots,
                    self.expect_robots,
                    beacons,
                    self.expect_beacons,
                )
                return True
            try:
                event = self.inbox.get(timeout=0.5 if remaining <= 0 else min(remaining, 0.5))
            except queue.Empty:
                continue
            if event.kind == "stop":
                return False
            self._handle(event)

    def _handle(self, event: Event) -> None:
        self._handlers[event.kind](event)

    def _reject(self, key: str, reason: object) -> None:
        self.counters.rejected += 1
        logged = self.counters.logged_keys
        if key in logged or len(logged) > MAX_LOGGED_KEYS:
            return
        logged.add(key)
        if len(logged) > MAX_LOGGED_KEYS:
            log.warning("rejected messages on more than %d keys: no longer logged", MAX_LOGGED_KEYS)
        else:
            log.warning(
                "rejected message on %s: %s (further ones on this key not logged)", key, reason
            )

    def _take_dropped(self) -> None:
        """Count what the inbox dropped on arrival (too big, or over its memory cap)."""
        dropped = self.inbox.take_dropped("arrival")
        if dropped:
            self.counters.rejected += dropped - 1
            self._reject("(arrival)", f"{dropped} message(s) too big or over the inbox's cap")

    def _authentic(self, event: Event, identity: str) -> bool:
        """Whether the event carries ``identity``'s tag (always, in an unkeyed run)."""
        try:
            auth.unseal(self.keyring, identity, event.key, event.payload, event.attachment)
        except auth.AuthError as error:
            self._reject(event.key, error)
            return False
        return True

    def _robot_sender(self, name: str) -> int | None:
        """The robot id a radio name or key chunk stands for, if one of the swarm's."""
        robot = names.robot_of_name(name)
        return robot if robot is not None and self.world.is_member(robot) else None

    def _handle_acts(self, event: Event) -> None:
        """A batch of acts from a process hosting several robots: each entry is checked as
        the act it carries (its robot's tag on ``robot/<id>/act``), and the robots of the
        authentic ones get their next senses in one batch to that process."""
        lead = self.keys.robot_of(event.key, "host")
        if lead is None or not self.world.is_member(lead):
            self._reject(event.key, "not a robot of the swarm")
            return
        try:
            entries = batch.decode(event.payload)
        except batch.BatchError as error:
            self._reject(event.key, error)
            return
        for robot, payload, attachment in entries:
            act_event = Event(
                "act", self.keys.act(robot), payload, attachment, arrived=event.arrived
            )
            if self._handle_act(act_event):
                self.hosts[robot] = lead

    def _handle_act(self, event: Event) -> bool:
        """Take one robot's act; whether it was taken as the robot's answer to the tick
        under way. Only such an act teaches the world a batch route: an old act of robot r,
        copied into a batch on another process's key, must not divert r's senses there."""
        robot = self.keys.robot_of(event.key)
        if robot is None or not self.world.is_member(robot):
            self._reject(event.key, "not a robot of the swarm")
            return False
        if not self._authentic(event, names.robot_identity(robot)):
            return False
        try:
            act = protocol.decode(event.payload, protocol.Act)
        except protocol.ProtocolError as error:
            self._reject(event.key, error)
            return False
        if not self.lockstep:
            if robot not in self.world.live_robots():
                return False
            self.acts[robot] = act
            return act.tick == self.world.tick
        who = names.robot_identity(robot)
        self.counters.missed.pop(who, None)  # it is alive: wait for it again
        if self.barrier.answer(act.tick, who, act.radio_tx):
            self.acts[robot] = act
            if self.trace is not None:
                self._trace_answer(event, who)
            return True
        self._unexpected_answer(event.key, act.tick)
        return False

    def _handle_ack(self, event: Event) -> None:
        name = self.keys.last_chunk(event.key.rsplit("/", 1)[0])
        if not names.is_beacon_name(name):
            self._reject(event.key, f"no beacon of this run is called {name!r}")
            return
        identity = names.beacon_identity(name)
        if not self._authentic(event, identity):
            return
        if name not in self.world.beacons():
            self.counters.late += 1  # its own, but it has left (or not joined yet)
            return
        try:
            ack = protocol.decode(event.payload, protocol.Ack)
        except protocol.ProtocolError as error:
            self._reject(event.key, error)
            return
        self.counters.missed.pop(identity, None)
        if self.lockstep and not self.barrier.answer(ack.tick, identity, ack.radio_tx):
            self._unexpected_answer(event.key, ack.tick)
        elif self.trace is not None:
            self._trace_answer(event, identity)

    def _trace_answer(self, event: Event, who: str) -> None:
        """Note when an answer reached the callback and this thread (``--trace``)."""
        answers = self._tick_trace.setdefault("answers", [])
        answers.append([who, round(event.arrived, 6), round(now(), 6)])

    def _unexpected_answer(self, key: str, tick: int) -> None:
        """An answer the barrier did not take: stale, repeated, or from a newcomer (late),
        or for a tick that has not begun (rejected)."""
        if tick <= self.barrier.tick:
            self.counters.late += 1
        else:
            self._reject(key, f"answer for tick {tick} while at tick {self.barrier.tick}")

    def _handle_tx(self, event: Event) -> None:
        sender = self.keys.last_chunk(event.key)
        robot = self._robot_sender(sender)
        if robot is None and not names.is_beacon_name(sender):
            self._reject_tx(event.key, f"no robot or beacon of this run is called {sender!r}")
            return
        identity = names.beacon_identity(sender) if robot is None else names.robot_identity(robot)
        try:
            metadata = auth.unseal(
                self.keyring, identity, event.key, event.payload, event.attachment
            )
            if metadata is None:
                raise protocol.ProtocolError("missing attachment")
            meta = protocol.decode(metadata, protocol.RadioTxMeta)
            if len(event.payload) > protocol.MAX_PAYLOAD_BYTES:
                raise protocol.ProtocolError(f"payload of {len(event.payload)} bytes")
            if self.sent_this_tick.get(sender, 0) >= MAX_TX_PER_TICK:
                raise protocol.ProtocolError(f"more than {MAX_TX_PER_TICK} messages in a tick")
            if (sender, meta.seq) in self.seqs_this_tick:
                raise protocol.ProtocolError(f"message {meta.seq} again: a replay")
        except (auth.AuthError, protocol.ProtocolError) as error:
            self._reject_tx(event.key, error)
            return
        if not self.world.is_sender(sender):
            # Its own, but it has left (or not joined yet): late, like an act after a tick.
            self.counters.late += 1
            return
        self.sent_this_tick[sender] = self.sent_this_tick.get(sender, 0) + 1
        self.seqs_this_tick.add((sender, meta.seq))
        if self.lockstep:
            role = "beacon" if sender in self.world.beacons() else "robot"
            if not self.barrier.transmitted(meta.tick, f"{role}/{sender}"):
                if meta.tick < self.barrier.tick:
                    self.counters.late += 1
                else:
                    reason = f"tx for tick {meta.tick} at tick {self.barrier.tick}"
                    self._reject_tx(event.key, reason)
                return
        self.transmissions.append(Transmission(sender, meta.seq, event.payload))

    def _reject_tx(self, key: str, reason: object) -> None:
        """A radio message the medium refuses: counted by the world and by the radio."""
        self._reject(key, reason)
        self.world.radio.reject()

    def _token(self, event: Event, count: bool) -> tuple[str, str] | None:
        """(role, id) of a robot's or beacon's liveliness token; None for other roles (the
        world, the recorder), which the barrier does not involve, and for a robot outside
        the swarm or a beacon name no beacon can have (rejected if ``count``)."""
        parts = event.key[len(self.keys.prefix) + 1 :].split("/")
        if len(parts) != 3 or parts[0] != "alive" or parts[1] not in ("robot", "beacon"):
            return None
        role, ident = parts[1], parts[2]
        if role == "robot":
            valid = self._robot_sender(ident) is not None
        else:
            valid = names.is_beacon_name(ident)
        if not valid:
            if count:
                self._reject(event.key, f"no {role} of this run is called {ident!r}")
            return None
        return role, ident

    def _handle_alive(self, event: Event) -> None:
        token = self._token(event, count=True)
        if token is not None:
            self.pending_joins.append(token)

    def _handle_gone(self, event: Event) -> None:
        """A liveliness token went. A robot's process that answered in batches may be gone
        with it (its lead's token), so its robots' senses go to their own keys again until
        a batch says otherwise (a restarted process may host other robots, or none)."""
        token = self._token(event, count=False)
        if token is None:
            return
        role, ident = token
        self.pending_joins = [join for join in self.pending_joins if join != token]
        if role == "robot":
            gone = int(ident)
            self.hosts = {
                robot: lead for robot, lead in self.hosts.items() if gone not in (robot, lead)
            }
            if gone in self.world.live_robots():
                self.counters.departures += 1
            log.warning("robot %s left (liveliness lost); its body stays as an obstacle", ident)
            self.world.leave_robot(gone)
            self.acts.pop(gone, None)
            self.barrier.leave(names.robot_identity(gone))
        elif ident in self.world.beacons():
            self.counters.departures += 1
            log.warning("beacon %s left", ident)
            self.world.leave_beacon(ident)
            self.barrier.leave(names.beacon_identity(ident))

    def _handle_join(self, event: Event) -> None:
        """Give a robot started with ``--id auto`` an id: the smallest never handed out,
        else (a replacement container) the smallest whose robot is not running."""
        key = self.keys.world_join
        try:
            identity, nonce = self._asker(event.query, key)
        except auth.AuthError as error:
            self._reject(key, error)
            event.query.reply_err(b"unauthenticated query")
            return
        live = set(self.world.live_robots())
        members = range(self.world.config.num_robots)
        free = next((robot for robot in members if robot not in self.assigned | live), None)
        if free is None:
            free = next((robot for robot in sorted(self.assigned) if robot not in live), None)
        if free is None:
            event.query.reply_err(b"no robot id left")
            return
        self.assigned.add(free)
        log.info("assigned id %d to a robot that asked for one", free)
        payload = protocol.encode(protocol.JoinReply(v=protocol.VERSION, id=free))
        attachment = auth.reply_seal(self.keyring, identity, key, payload, nonce)
        event.query.reply(key, payload, attachment=attachment)

    def _handle_stats(self, event: Event) -> None:
        key = self.keys.world_stats
        try:
            identity, nonce = self._asker(event.query, key)
        except auth.AuthError as error:
            self._reject(key, error)
            event.query.reply_err(b"unauthenticated query")
            return
        self._take_dropped()
        payload = protocol.encode(self._state())
        attachment = auth.reply_seal(self.keyring, identity, key, payload, nonce)
        event.query.reply(key, payload, attachment=attachment)

    def _apply_joins(self) -> None:
        for role, ident in self.pending_joins:
            if role == "robot":
                robot = int(ident)
                self.assigned.add(robot)
                if robot not in self.world.live_robots():
                    log.info("robot %s joined at tick %d", ident, self.world.tick)
                self.world.join_robot(robot)
            elif ident not in self.world.beacons() and len(self.world.beacons()) >= MAX_BEACONS:
                self._reject(
                    self.keys.alive(Role.BEACON, ident), f"more than {MAX_BEACONS} beacons"
                )
            else:
                self.world.join_beacon(ident)
        self.pending_joins.clear()

    def _log_stall(self) -> None:
        self.counters.stalls += 1
        missing = self.barrier.missing()
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

    def _close_tick(self) -> None:
        started = now() if self.trace is not None else 0.0
        result = self.world.advance(self.acts, self.transmissions)
        advanced = now() if self.trace is not None else 0.0
        self.transmissions = []
        self.sent_this_tick = {}
        self.seqs_this_tick = set()
        if self.lockstep:
            self.acts = {}
        else:  # real time: a command holds until replaced, but a capture happens once
            self.acts = {
                robot: msgspec.structs.replace(act, capture=False, radio_tx=0)
                for robot, act in self.acts.items()
            }
        self._apply_joins()
        rx_counts = {name: len(items) for name, items in result.deliveries.items()}
        for name, deliveries in result.deliveries.items():
            key = self.keys.radio_rx(name)
            receiver = names.robot_identity(int(name))  # only robots receive
            for delivery in deliveries:
                meta = protocol.RadioRxMeta(
                    v=protocol.VERSION,
                    tick=result.tick,
                    sender=delivery.sender,
                    seq=delivery.seq,
                    sent_tick=delivery.sent_tick,
                )
                attachment = self._seal(receiver, key, delivery.payload, protocol.encode(meta))
                reliable_put(self.session, key, delivery.payload, attachment)
        if self.trace is not None:
            self.trace.write(
                **self._tick_trace,
                close_start=round(started, 6),
                advanced=round(advanced, 6),
                delivered=round(now(), 6),
            )
        self._open_tick(result.tick, rx_counts, result.frames)

    def _open_tick(self, tick: int, rx_counts: dict[str, int], frames: dict[int, bytes]) -> None:
        opening = now() if self.trace is not None else 0.0
        # The clock first: the beacon, in the barrier too, answers while the senses go out.
        clock = protocol.encode(protocol.Clock(v=protocol.VERSION, tick=tick, t=self.world.t))
        self._clock_publisher.put(
            clock, attachment=self._seal(names.WORLD, self.keys.world_clock, clock)
        )
        spec = self.world.config.camera
        for robot, frame in frames.items():
            meta = protocol.CameraMeta(
                v=protocol.VERSION,
                tick=tick,
                width=spec.width,
                height=spec.height,
                encoding="png",
            )
            key = self.keys.camera(robot)
            attachment = self._seal(names.robot_identity(robot), key, frame, protocol.encode(meta))
            reliable_put(self.session, key, frame, attachment)
        robots = self.world.live_robots()
        batches: dict[int, list[batch.Entry]] = {}
        # A process's batch leaves as soon as its robots' senses are made, so it steps them
        # while this thread makes the next process's.
        batch_sizes = Counter(self.hosts[robot] for robot in robots if robot in self.hosts)
        for robot in robots:
            sense = self.world.sense(
                robot, rx_counts.get(names.robot_name(robot), 0), robot in frames
            )
            payload = protocol.encode(sense)
            key = self.keys.sense(robot)
            attachment = self._seal(names.robot_identity(robot), key, payload)
            lead = self.hosts.get(robot)
            if lead is None:
                publisher = self._sense_publishers.get(robot)
                if publisher is None:
                    publisher = reliable_publisher(self.session, key)
                    self._sense_publishers[robot] = publisher
                publisher.put(payload, attachment=attachment)
                continue
            entries = batches.setdefault(lead, [])
            entries.append(batch.Entry(robot, payload, attachment))
            if len(entries) == batch_sizes[lead]:
                publisher = self._batch_publishers.get(lead)
                if publisher is None:
                    publisher = reliable_publisher(self.session, self.keys.host_sense(lead))
                    self._batch_publishers[lead] = publisher
                publisher.put(batch.encode(entries))
        participants = [names.robot_identity(robot) for robot in robots]
        participants += [names.beacon_identity(name) for name in self.world.beacons()]
        # A controller that went silent (hung, not gone) is not waited for until it
        # answers again, so one stuck process cannot slow the swarm to its stall timeout.
        self.barrier.open(
            tick,
            [who for who in participants if self.counters.missed.get(who, 0) < SUSPEND_AFTER],
        )
        if tick % self.state_every == 0:
            self._publish_state()
        if self.trace is not None:
            self._tick_trace = {
                "tick": tick,
                "robots": len(robots),
                "frames": len(frames),
                "rx": sum(rx_counts.values()),
                "batched": sum(len(entries) for entries in batches.values()),
                "open_start": round(opening, 6),
                "opened": round(now(), 6),
            }

    def _publish_state(self) -> None:
        self._take_dropped()
        state = protocol.encode(self._state())
        self._state_publisher.put(
            state, attachment=self._seal(names.WORLD, self.keys.world_state, state)
        )

    def _state(self) -> protocol.WorldState:
        counters = self.counters
        return self.world.state(counters.rejected, counters.stalls, counters.departures)

    def _seal(self, identity: str, key: str, payload: bytes, metadata: bytes = b"") -> bytes | None:
        return auth.seal(self.keyring, identity, key, payload, metadata)


# --- command line ------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="world-server",
        description="The world of one swarm: physics, cameras, the radio medium and the clock. "
        "By default it is the Zenoh router of a local run.",
    )
    WORLD_SERVER_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, WorldServerConfig)
    parser.add_argument(
        "--trace",
        metavar="PATH",
        default=None,
        help="write a timeline of every tick to PATH as JSON lines: when it opened, when "
        "each answer arrived, how long the world's own work took (docs/performance.md)",
    )
    cliargs.add_zenoh_options(parser, default_mode="router")
    cliargs.add_log_level(parser)
    return parser


def config_from_args(args: argparse.Namespace) -> WorldConfig:
    """The WorldConfig of ``world-server``'s options."""
    return world_server_config(args).world


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    parser = build_parser()
    args = parser.parse_args(argv)
    config: WorldServerConfig = settings_cli.config_from(
        parser, args, WORLD_SERVER_OPTIONS, {"world.run": args.run_id}
    )
    if config.world.run != args.run_id:
        parser.exit(
            2,
            f"world-server: error: --config is of run {config.world.run!r}, "
            f"not --run-id {args.run_id!r}\n",
        )
    if session_mode(args) == "router" and not args.listen and not args.zenoh_config:
        args.listen = [cliargs.LOCAL_ENDPOINT]
    cliargs.configure_logging("world-server", args.log_level)
    keyring = run_keys.from_args(parser, args, "world-server")
    if keyring is not None and keyring.secret is None:
        parser.exit(2, "world-server: error: the world server needs the run secret\n")
    world = World(config.world)
    keys = protocol.Keys(args.run_id, args.root)
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"world-server: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    with session:
        server = WorldServer(
            session,
            world,
            keys,
            config=config,
            expect_robots=config.world.num_robots,
            expect_beacons=config.beacons,
            keyring=keyring,
            trace=open_trace(args.trace),
        )
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: server.stop())
        log.info(
            "run %s: %d sites, arena radius %.2f m, best site %d, listening on %s",
            args.run_id,
            config.world.num_sites,
            world.layout.arena_radius,
            world.layout.best_site,
            ", ".join(args.listen) or "(client)",
        )
        thread_result: list[int] = []
        worker = threading.Thread(target=lambda: thread_result.append(server.run()), daemon=True)
        worker.start()
        while worker.is_alive():
            worker.join(0.2)
        if server.trace is not None:
            server.trace.close()
        return thread_result[0] if thread_result else 1


if __name__ == "__main__":
    sys.exit(main())
