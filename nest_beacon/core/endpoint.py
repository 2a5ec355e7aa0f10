"""The nest beacon's end of the wire, whatever carries it (pure: no I/O, no clock).

The beacon follows the world's clock on its own key (``beacon/<name>/clock``): for each
tick it believes, it transmits when due (``Beacon.on_tick``) and answers the tick with an
``Ack``, so it takes part in the lockstep barrier like any controller. The ack names the
next tick it answers, the next with a transmission due (``Ack.next_tick``): the world sends
it no clock and does not wait for it before then, so the beacon follows one tick in five
(its period over the world's step), not every tick. ``BeaconEndpoint`` takes each clock
message as (payload, attachment) and returns what to send as data: the tick's radio
transmissions, then the ack, each sealed with the beacon's key.

It believes a clock only with the world's tag (``bestofn_swarm.wire.auth``), as a ``Clock`` whose
sim time is its tick's, within the tick window of its last tick (``bestofn_swarm.wire.guard``); a
refusal is counted (``rejected``, reported in every ack), a tick already answered is stale and
dropped quietly. It follows one world server: a new one counts ticks and sim time from
zero again (the window is forgotten, and the beacon transmits on its next tick); the same
one back after an outage is rejoined at whatever tick it has reached.
"""

from __future__ import annotations

import logging
import math
from typing import NamedTuple

from bestofn_swarm.wire import auth, guard, keyspace, names, protocol
from bestofn_swarm.wire.keyspace import Party
from nest_beacon.core.beacon import Beacon

log = logging.getLogger(__name__)


class Outgoing(NamedTuple):
    """One message to send: on ``key``, ``payload`` with ``attachment`` (sealed)."""

    kind: keyspace.KeyKind
    key: str
    payload: bytes
    attachment: bytes | None


class BeaconEndpoint:
    """The beacon's checks of the clock it follows, and its answers to each tick."""

    def __init__(
        self, beacon: Beacon, keys: keyspace.Keys, dt: float, keyring: auth.Keyring | None
    ) -> None:
        self.beacon = beacon
        self.name = beacon.config.name
        self.identity = names.beacon_identity(self.name)
        self.dt = dt
        self.keyring = keyring  # None: an unauthenticated run
        # It answers a tick per period: the next one it believes may be that far ahead.
        self.window = guard.TICK_WINDOW + math.ceil(beacon.config.period / dt)
        self.ticks = guard.TickWindow(self.window)
        self.worlds = guard.WorldFollower()
        self.rejected = 0
        # The key of its one input, and those of what it sends: the key table says which.
        (heard,) = keyspace.heard_by(Party.BEACON)
        self.clock_key = keys.of(heard, self.name)
        self.output_keys = {
            kind: keys.of(kind, self.name)
            for kind in keyspace.published_by(Party.BEACON, Party.SENDER)
        }

    def receive_clock(self, payload: bytes, attachment: bytes | None) -> list[Outgoing]:
        """Take one clock message; what to send for its tick (nothing if it was refused or
        the tick was answered already)."""
        try:
            auth.unseal(self.keyring, names.WORLD, self.clock_key, payload, attachment)
            clock = protocol.decode(payload, protocol.Clock)
            refused = guard.time_refused(clock.tick, clock.t, self.dt) or self.ticks.refuses(
                clock.tick
            )
            if refused:
                raise protocol.ProtocolError(refused)
        except (auth.AuthError, protocol.ProtocolError) as error:
            self._reject(error)
            return []
        if not self.ticks.ahead(clock.tick):
            return []  # a tick already answered
        self.ticks.acted(clock.tick)
        outgoing = []
        tx_key = self.output_keys[keyspace.RADIO_TX]
        for message in self.beacon.on_tick(clock.t):
            sent = protocol.encode(message)
            meta = protocol.encode(
                protocol.RadioTxMeta(v=protocol.VERSION, tick=clock.tick, seq=message.seq)
            )
            outgoing.append(
                Outgoing(keyspace.RADIO_TX, tx_key, sent, self._seal(tx_key, sent, meta))
            )
        ack = protocol.encode(
            protocol.Ack(
                v=protocol.VERSION,
                tick=clock.tick,
                radio_tx=len(outgoing),
                rejected=self.rejected,
                next_tick=self.beacon.next_tick(clock.tick, self.dt),
            )
        )
        ack_key = self.output_keys[keyspace.ACK]
        outgoing.append(Outgoing(keyspace.ACK, ack_key, ack, self._seal(ack_key, ack)))
        return outgoing

    def count_dropped(self, count: int) -> None:
        """Count clock messages the transport dropped on arrival (too big, or no room)."""
        self.rejected += count

    def world_appeared(self, instance: str) -> None:
        """A world server's liveliness token, proved the world's (it answered for it with
        the run's key: ``bestofn_swarm.plumbing.world_info.world_proved``): the first is followed;
        when the followed one is gone, another is a new world; the followed one again is the
        same world back."""
        seen = self.worlds.appeared(instance)
        if seen == "new":
            log.warning("beacon %s: a new world server appeared; following it", self.name)
            self.ticks = guard.TickWindow(self.window)
            self.beacon.follow_new_world()
        elif seen == "back":  # its ticks went on while this beacon was cut off
            log.warning("beacon %s: the world server is back; following it", self.name)
            self.ticks.rejoin()

    def world_unproven(self, instance: str) -> None:
        """A world server's token that no world answered for: someone else's, ignored and
        counted (it must not make the beacon forget its ticks)."""
        self._reject(protocol.ProtocolError(f"no world answers for world token {instance!r}"))

    def world_vanished(self, instance: str) -> None:
        self.worlds.vanished(instance)

    def _reject(self, error: Exception) -> None:
        self.rejected += 1
        if self.rejected == 1:
            log.warning(
                "rejected message on %s: %s (further ones not logged)", self.clock_key, error
            )

    def _seal(self, key: str, payload: bytes, metadata: bytes = b"") -> bytes | None:
        return auth.seal(self.keyring, self.identity, key, payload, metadata)
