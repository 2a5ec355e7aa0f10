"""The nest beacon on Zenoh: a thin adapter around its endpoint.

``nest_beacon.core.endpoint.BeaconEndpoint`` decides what a clock message is worth and
what to send for its tick; ``BeaconNode`` subscribes to the clock the world sends it
(``beacon/<name>/clock``, on the ticks it answers) and to the world's liveliness, hands
them over, and publishes what comes back. The clock is answered in the Zenoh
callback that brings it, under the beacon's lock (a wake-up of the main thread per tick
was most of the beacon's answer time, and it is in the lockstep barrier); the main
thread handles what is rare (the world's liveliness, stop) from a bounded inbox; a world
token is followed only once its world answers for it (a token is only a hint).
"""

from __future__ import annotations

import logging
import queue
import threading
from dataclasses import dataclass

import zenoh

from bestofn_swarm.plumbing.ending import hear_ending
from bestofn_swarm.plumbing.inbox import STOP, BoundedInbox, Stop
from bestofn_swarm.plumbing.world_info import world_proved
from bestofn_swarm.plumbing.zenoh_session import reliable_publisher
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.names import Role
from nest_beacon.core.endpoint import BeaconEndpoint

log = logging.getLogger("nest_beacon")
INBOX_BYTES = 16 * 2**20
MAX_MESSAGE_BYTES = 1024  # a clock and its tag are under 100 bytes


@dataclass(frozen=True)
class Event:
    """What reaches the beacon process: its clock, a world server's liveliness token that
    appeared or went (``gone``), or its stop."""

    kind: keyspace.KeyKind | Stop
    payload: bytes = b""
    attachment: bytes | None = None
    gone: bool = False
    code: int = 0  # a stop: the process's exit code (the run's, when it ended)


class BeaconNode:
    """The beacon's session: subscribers and publishers around its endpoint."""

    def __init__(
        self,
        endpoint: BeaconEndpoint,
        *,
        session: zenoh.Session,
        keys: keyspace.Keys,
        inbox: BoundedInbox[Event],
    ) -> None:
        self.endpoint = endpoint
        self.session = session
        self.keys = keys
        self.inbox = inbox
        self.lock = threading.Lock()  # the beacon: one thread at a time
        self.stopped = False  # set under the lock: later clocks are not answered
        self._refusals = 0  # endings not believed
        self._publishers = {
            kind: reliable_publisher(session, key) for kind, key in endpoint.output_keys.items()
        }

    def start(self) -> None:
        """Subscribe first, then announce liveliness, so no tick is missed."""
        keys, session = self.keys, self.session

        def on_clock(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            size = len(payload) + len(extra or b"")
            if size > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                self.inbox.put(Event(keyspace.BEACON_CLOCK, payload, extra), size)
                return
            with self.lock:
                if not self.stopped:
                    self._answer(payload, extra)

        def on_world(sample: zenoh.Sample) -> None:
            gone = sample.kind != zenoh.SampleKind.PUT
            instance = (keys.ident_of(keyspace.ALIVE_WORLD, str(sample.key_expr)) or "").encode()
            self.inbox.put(
                Event(keyspace.ALIVE_WORLD, instance, gone=gone), len(instance), once=True
            )

        self._declared = [
            session.liveliness().declare_subscriber(
                keys.every(keyspace.ALIVE_WORLD), on_world, history=True
            ),
            session.declare_subscriber(self.endpoint.clock_key, on_clock),
        ]
        self._token = session.liveliness().declare_token(
            keys.token(Role.BEACON, self.endpoint.name)
        )
        self._ending = hear_ending(session, keys, self.endpoint.keyring, self._ended, self._refused)

    def _ended(self, ending: protocol.RunEnding) -> None:
        log.info("the run ended: %s (exit code %d)", ending.ended, ending.code)
        self.inbox.put(Event(STOP, code=ending.code), control=True)

    def _refused(self, reason: str) -> None:
        with self.lock:
            self.endpoint.count_dropped(1)
            first = not self._refusals
            self._refusals += 1
        if first:
            log.warning("refused an ending (logged once): %s", reason[:300])

    def close(self) -> None:
        self._ending.undeclare()
        self._token.undeclare()

    def serve(self) -> int:
        """Handle the inbox's events until a stop event arrives (a stop signal, or the
        run's ending); the clock is answered in its callback. The process's exit code: the
        run's, when it ended."""
        while True:
            try:
                event = self.inbox.get(timeout=0.5)
            except queue.Empty:
                event = None
            if event is not None and event.kind == STOP:
                with self.lock:
                    self.stopped = True
                return event.code
            if (
                event is not None
                and event.kind is keyspace.ALIVE_WORLD
                and not event.gone
                and not self._proved(event)
            ):
                with self.lock:
                    self.endpoint.world_unproven(event.payload.decode(errors="replace"))
                continue
            with self.lock:
                if event is not None:
                    self.handle(event)
                self.endpoint.count_dropped(self.inbox.take_dropped(None))

    def _proved(self, event: Event) -> bool:
        """Whether a world token is a world's: it answers for it, asked as this beacon
        (which also proves the beacon present to it). Asked outside the lock."""
        endpoint = self.endpoint
        instance = event.payload.decode(errors="replace")
        return world_proved(self.session, self.keys, endpoint.keyring, endpoint.identity, instance)

    def handle(self, event: Event) -> None:
        """One event, under the lock."""
        if event.kind is keyspace.ALIVE_WORLD:
            instance = event.payload.decode(errors="replace")
            if event.gone:
                self.endpoint.world_vanished(instance)
            else:
                self.endpoint.world_appeared(instance)
        elif event.kind is keyspace.BEACON_CLOCK:
            self._answer(event.payload, event.attachment)

    def _answer(self, payload: bytes, attachment: bytes | None) -> None:
        for message in self.endpoint.receive_clock(payload, attachment):
            self._publishers[message.kind].put(message.payload, attachment=message.attachment)
