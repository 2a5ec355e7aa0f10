"""The world server on Zenoh: a thin adapter around the coordinator (world_server/core).

Each Zenoh callback hands what it brings to the coordinator at once, under one lock, and
publishes what comes back: the answer that completes a tick closes it and opens the next
in the callback that brought it, with no hand-off to another thread (a wake-up per answer
was a large part of a tick: docs/performance.md). The process's own thread only wakes
the coordinator at its deadlines (the stall timeout, real-time pacing, the start timeout)
and stops it. ``world/info`` is answered without the lock: it needs nothing of the tick.
What is checked, and how, is the coordinator's (``world_server/core/intake.py``).

The world also ends its run (``world_server/observer/referee.py``): the robots' statuses
and their links' figures go to its referee, not the coordinator, and after each event
that opened a tick or changed who is live (and at each wake-up) the referee looks at the
run. When it ends, the coordinator stops, and the ending goes out on ``world/ending``,
tagged for everyone (``keyspace.seal_for_everyone``); so does a stop signal's, as an
interrupted run.

The callbacks run on zenoh-python's own threads, one per subscriber, not on Zenoh's
network threads, so a tick's work in one of them holds up only the samples of that
subscriber, which the tick waits for anyway.
"""

from __future__ import annotations

import signal
import threading
import time
from typing import Any, cast

import zenoh

from bestofn_swarm.plumbing.trace import TraceWriter, now
from bestofn_swarm.plumbing.world_info import NOT_THIS_INSTANCE
from bestofn_swarm.plumbing.zenoh_session import reliable_publisher, reliable_put
from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from bestofn_swarm.wire.endings import Halt, Stop
from bestofn_swarm.wire.keyspace import How, Party
from bestofn_swarm.wire.names import Role
from world_server.core.coordinator import UNAUTHENTICATED, Coordinator, Phase
from world_server.core.events import (
    Event,
    Happening,
    Output,
    Publish,
    Reply,
    ReplyError,
)
from world_server.core.world import World
from world_server.observer.referee import Referee
from world_server.server.options import WorldServerConfig
from world_server.server.timeline import TickTimeline

# The largest valid message: a batch of acts (a radio payload and its attachment, alone).
MAX_MESSAGE_BYTES = max(batch.MAX_BATCH_BYTES, protocol.MAX_PAYLOAD_BYTES + 1024)
MAX_WAIT = 0.5  # seconds the thread sleeps at most, whatever the deadline
# What the world hears for its referee rather than its coordinator; and what for both
# (a beacon's ack: the coordinator's barrier, the referee's count of what beacons refused).
JUDGED = frozenset({keyspace.STATUS, keyspace.LINK})
BOTH = frozenset({keyspace.ACK})


class WorldServer:
    """Runs the tick loop of one World over a Zenoh session."""

    def __init__(
        self,
        session: zenoh.Session,
        world: World,
        keys: keyspace.Keys,
        *,
        config: WorldServerConfig | None = None,
        expect_robots: int = 0,
        expect_beacons: int = 0,
        keyring: auth.Keyring | None = None,
        trace: TraceWriter | None = None,
        referee: Referee | None = None,
    ) -> None:
        """``config`` says how to pace and publish ``world`` (its own world is not used);
        the run starts once ``expect_robots`` robots and ``expect_beacons`` beacons are live
        (0: at once); ``referee`` ends it (None: it runs until stopped)."""
        config = config or WorldServerConfig()
        self.session = session
        self.keys = keys
        self.keyring = keyring  # None: an unauthenticated run
        # Held while the coordinator takes an event or wakes: one thread at a time.
        self.lock = threading.Lock()
        self._stopping = threading.Event()  # set by stop(), from a signal handler too
        self._signal: int | None = None  # the stop signal, if one stopped it
        self.referee = referee
        self.ending: protocol.RunEnding | None = None  # once the run ended
        self.ended = threading.Event()  # set once the ending went out
        self._looked = (-1, 0)  # the tick and roster changes of the referee's last look
        self._roster_changes = 0  # liveliness tokens that came or went
        self._first_tick_at: float | None = None  # wall time of the first tick
        self.timeline = TickTimeline(trace) if trace is not None else None
        self.coordinator = Coordinator(
            world,
            keys,
            self._send,
            stall_timeout=config.stall_timeout,
            start_timeout=config.start_timeout,
            state_every=config.state_every,
            speed=config.speed,
            expect_robots=expect_robots,
            expect_beacons=expect_beacons,
            keyring=keyring,
            traced=trace is not None,
            hold=config.hold,
        )
        self._info_bytes = protocol.encode(world.info)
        # Publishers kept per key, for what goes out tick after tick (Publish.steady).
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._declared: list[Any] = []
        # This world's instance: its liveliness token's last chunk, its Zenoh id.
        self.instance = str(session.info.zid())

    # --- Zenoh side: callbacks hand their input to the coordinator --------------------

    def _feed(self, event: Event) -> None:
        """Hand one event to the coordinator, which closes and opens ticks as it is due;
        then let the referee look, if a tick opened or who is live changed."""
        with self.lock:
            self.coordinator.handle(event, time.monotonic())
            self._judge()

    def _on_sample(self, kind: keyspace.KeyKind) -> Any:
        def callback(sample: zenoh.Sample) -> None:
            attachment = sample.attachment
            payload = sample.payload.to_bytes()
            extra = attachment.to_bytes() if attachment is not None else None
            if len(payload) + len(extra or b"") > MAX_MESSAGE_BYTES:  # never a valid input
                with self.lock:
                    self.coordinator.dropped(1)
                return
            if kind in JUDGED:
                self._judged_sample(str(sample.key_expr), payload, extra)
                return
            arrived = now() if self.timeline is not None else 0.0
            self._feed(Event(kind, str(sample.key_expr), payload, extra, arrived=arrived))
            if kind in BOTH:
                self._judged_sample(str(sample.key_expr), payload, extra)

        return callback

    def _on_token(self, kind: keyspace.KeyKind) -> Any:
        def callback(sample: zenoh.Sample) -> None:
            gone = sample.kind != zenoh.SampleKind.PUT
            with self.lock:
                self._roster_changes += 1
            self._feed(Event(kind, str(sample.key_expr), gone=gone))

        return callback

    def _judged_sample(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        """A robot's status or a link's figures, for the referee (a sample it does not
        believe is counted as its observer's rejection)."""
        referee = self.referee
        if referee is None:
            return
        with self.lock:
            if self.ending is not None:
                return
            try:
                opened = keyspace.open_sample(
                    self.keys, key, payload, attachment, keyring=self.keyring, kinds=JUDGED | BOTH
                )
                if opened is not None:
                    referee.take(opened)
            except keyspace.SampleError:
                referee.observer.rejected += 1

    def _on_query(self, kind: keyspace.KeyKind, key: str) -> Any:
        def callback(query: zenoh.Query) -> None:
            payload, attachment = _query_bytes(query)
            self._feed(Event(kind, key, payload, attachment, query=query))

        return callback

    def _on_info(self, query: zenoh.Query) -> None:
        """Answer ``world/info`` at once (on Zenoh's thread: it needs nothing of the tick),
        then tell the coordinator its asker is present. A query that names a world
        instance (its payload) is answered only by that instance: a robot or beacon asks
        so to prove that a world token it saw is this world's (docs/security.md)."""
        key = self.keys.of(keyspace.INFO)
        payload, attachment = _query_bytes(query)
        try:
            identity, nonce = auth.query_open(self.keyring, key, payload, attachment)
        except auth.AuthError as error:
            self._feed(Event(Happening.REFUSED, key, str(error).encode()))
            query.reply_err(UNAUTHENTICATED)
            return
        if payload and payload != self.instance.encode():
            query.reply_err(NOT_THIS_INSTANCE.encode())
        else:
            sealed = auth.reply_seal(self.keyring, identity, key, self._info_bytes, nonce)
            query.reply(key, self._info_bytes, attachment=sealed)
        self._feed(Event(keyspace.INFO, key, payload, attachment))

    def declare(self) -> None:
        keys, session = self.keys, self.session
        for key in (keys.of(keyspace.CLOCK), keys.of(keyspace.STATE)):
            self._publishers[key] = reliable_publisher(session, key)
        # What the world hears, asks and watches: the key table says.
        self._declared = [
            *(
                session.declare_subscriber(keys.every(kind), self._on_sample(kind))
                for kind in keyspace.heard_by(Party.WORLD)
            ),
            *(
                session.liveliness().declare_subscriber(
                    keys.every(kind), self._on_token(kind), history=True
                )
                for kind in keyspace.heard_by(Party.WORLD, how=How.TOKEN)
            ),
            session.declare_queryable(keys.of(keyspace.INFO), self._on_info),
            *(
                session.declare_queryable(keys.of(kind), self._on_query(kind, keys.of(kind)))
                for kind in (keyspace.STATS, keyspace.JOIN)
            ),
            # The token names this world instance, so robots can tell a restarted world.
            session.liveliness().declare_token(keys.token(Role.WORLD, self.instance)),
        ]

    def stop(self, signum: int | None = None) -> None:
        """Stop the loop (from any thread; not from a signal handler: ``Event.set`` takes a
        lock, bestofn_swarm/plumbing/stop_signals.py); ``signum``: the stop signal that
        asked it, which ends a run still going as interrupted."""
        if self._signal is None:
            self._signal = signum
        self._stopping.set()

    # --- the ending --------------------------------------------------------------------

    def _judge(self, wake: bool = False) -> None:
        """Let the referee look at the run (under the lock): at a wake-up, or once a tick
        opened or a token came or went since its last look; end the run if it says so."""
        referee, coordinator = self.referee, self.coordinator
        if referee is None or self.ending is not None or coordinator.phase is not Phase.RUNNING:
            return
        world = coordinator.world
        looked = (world.tick, self._roster_changes)
        if looked == self._looked and not wake:
            return
        self._looked = looked
        if self._first_tick_at is None:
            self._first_tick_at = time.monotonic()
        referee.now(world.tick, world.t, world.live_robots(), world.beacons(), time.monotonic())
        halt = referee.look()
        if halt is not None:
            self._end(halt)

    def _end(self, halt: Halt, signum: int | None = None) -> None:
        """End the run (under the lock): stop the coordinator (it publishes its state a
        last time), and publish the referee's ending, tagged for everyone."""
        referee = self.referee
        assert referee is not None and self.ending is None
        coordinator = self.coordinator
        running = coordinator.phase is Phase.RUNNING
        coordinator.stop()
        if running:  # what the world did up to now: its last state and counters
            world = coordinator.world
            referee.now(world.tick, world.t, world.live_robots(), world.beacons(), time.monotonic())
        wall = time.monotonic() - self._first_tick_at if self._first_tick_at else 0.0
        name = signal.Signals(signum).name if signum is not None else None
        ending = referee.ending(halt, coordinator.state(), wall, signum, name)
        self.ending = ending
        key = self.keys.of(keyspace.ENDING)
        payload = protocol.encode(ending)
        attachment = keyspace.seal_for_everyone(
            self.keyring, key, payload, referee.shape.num_robots, names.WORLD
        )
        reliable_put(self.session, key, payload, attachment)
        self.ended.set()

    # --- the loop ----------------------------------------------------------------------

    def run(self) -> int:
        """Wake the coordinator at its deadlines until it is stopped; its inputs come in
        the callbacks meanwhile. Returns the run's exit code once its ending went out (a
        stop signal ends a run still going as interrupted), else 0."""
        coordinator = self.coordinator
        with self.lock:
            coordinator.begin(time.monotonic())
        self.declare()  # the callbacks feed it from now on
        while True:
            with self.lock:
                deadline = coordinator.deadline
            wait = MAX_WAIT if deadline is None else deadline - time.monotonic()
            stopping = self._stopping.wait(min(max(0.0, wait), MAX_WAIT))
            with self.lock:
                if stopping:
                    if self.ending is None and self.referee is not None:
                        self._end(Halt(Stop.INTERRUPTED), self._signal)
                    coordinator.stop()
                    return self.ending.code if self.ending is not None else 0
                coordinator.wake(time.monotonic())
                self._judge(wake=True)

    def _send(self, output: Output) -> None:
        """Publish, reply or note (``--trace``) what the coordinator gave back."""
        if isinstance(output, Publish):
            if self.referee is not None and isinstance(output.message, protocol.WorldState):
                self.referee.state(output.message)  # its state, as the launcher sees it
            if not output.steady:
                reliable_put(self.session, output.key, output.payload, output.attachment)
                return
            publisher = self._publishers.get(output.key)
            if publisher is None:
                publisher = self._publishers[output.key] = reliable_publisher(
                    self.session, output.key
                )
            if output.if_heard and not publisher.matching_status:
                return
            publisher.put(output.payload, attachment=output.attachment)
        elif isinstance(output, Reply):
            query = cast(zenoh.Query, output.query)
            query.reply(output.key, output.payload, attachment=output.attachment)
        elif isinstance(output, ReplyError):
            cast(zenoh.Query, output.query).reply_err(output.reason)
        elif self.timeline is not None:
            self.timeline.note(output)

    def undeclare(self) -> None:
        """Undeclare what it hears and serves, and its token: no callback comes after, so
        none is under way as the session closes and the interpreter exits."""
        declared, self._declared = self._declared, []
        for entity in declared:
            entity.undeclare()

    def close_trace(self) -> None:
        if self.timeline is not None:
            self.timeline.close()


def _query_bytes(query: zenoh.Query) -> tuple[bytes, bytes | None]:
    """A query's payload and attachment, copied."""
    payload = query.payload.to_bytes() if query.payload is not None else b""
    attachment = query.attachment.to_bytes() if query.attachment is not None else None
    return payload, attachment
