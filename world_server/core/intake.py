"""What the world takes in during a tick, each input checked here and nowhere else (no I/O).

Trust: a message is taken only with its sender's run-key tag (in a keyed run), from a
robot of the swarm or a beacon, for the tick under way (lockstep), or (real time) for a
tick the world has reached, not too far behind it and after the sender's last message
taken (``bestofn_swarm.wire.guard.realtime_refused``: an authentic message replayed is refused); a
radio sender sends at most MAX_TX_PER_TICK messages in a tick, each sequence number once.
An input that fails a check is rejected and counted (``Counters``; a radio message also
by the radio); a sender's own message that comes after its tick, or after it left (or
in real time lags more than a tick window), is counted late.
What is taken waits here for the tick to close: acts by robot, radio transmissions, and
the barrier's book of who answered (lockstep).
"""

from __future__ import annotations

import msgspec

from bestofn_swarm.wire import auth, batch, guard, keyspace, names, protocol
from world_server.core.clock import Barrier
from world_server.core.counters import Counters
from world_server.core.events import Event
from world_server.core.roster import Host
from world_server.core.world import Transmission, World

MAX_TX_PER_TICK = 1000  # radio messages one sender may send in one tick (Act.radio_tx's bound)


class TickIntake:
    def __init__(
        self,
        world: World,
        keys: keyspace.Keys,
        counters: Counters,
        keyring: auth.Keyring | None = None,
    ) -> None:
        self.world = world
        self.keys = keys
        self.counters = counters
        self.keyring = keyring  # None: an unauthenticated run
        self.lockstep = world.config.clock == "lockstep"
        self.barrier = Barrier()
        self.acts: dict[int, protocol.Act] = {}
        self.transmissions: list[Transmission] = []
        self.sent_this_tick: dict[str, int] = {}  # radio messages per sender in this tick
        self.seqs_this_tick: set[tuple[str, int]] = set()  # (sender, seq): each once
        # Real time: the (tick, seq) of each sender's last act, ack and radio message taken.
        self.last_act: dict[int, tuple[int, int]] = {}
        self.last_ack: dict[str, tuple[int, int]] = {}
        self.last_tx: dict[str, tuple[int, int]] = {}

    # --- acts --------------------------------------------------------------------------

    def take_act(self, event: Event) -> int | None:
        """Take one robot's act; the robot, if its act was taken as its answer to the tick
        under way."""
        robot = self.keys.robot_of(keyspace.ACT, event.key)
        if robot is None or not self.world.is_member(robot):
            self.counters.reject(event.key, "not a robot of the swarm")
            return None
        act = event.message
        if not isinstance(act, protocol.Act):
            if not self._authentic(event, names.robot_identity(robot)):
                return None
            try:
                act = protocol.decode(event.payload, protocol.Act)
            except protocol.ProtocolError as error:
                self.counters.reject(event.key, error)
                return None
        return robot if self._answer(robot, act, event.key) else None

    def take_acts(self, event: Event) -> dict[int, Host]:
        """Take a batch of acts from a process hosting the robots ``first`` to ``last``
        (``host/<first>/act``, its identity's tag over it; bestofn_swarm/wire/batch.py), each entry
        as that robot's act; an entry of any other robot is refused and counted. The batch
        routes it teaches: robot -> the process, for each robot whose act was taken as its
        answer to the tick under way. Only such an act teaches a route: an old batch,
        replayed, must not divert the senses of robots that answer elsewhere now."""
        first = self.keys.robot_of(keyspace.HOST_ACT, event.key)
        if first is None or not self.world.is_member(first):
            self.counters.reject(event.key, "not a robot of the swarm")
            return {}
        acts = event.message
        typed = isinstance(acts, batch.ActBatch)
        if not typed:
            try:
                acts = batch.decode_acts(event.payload)
            except batch.BatchError as error:
                self.counters.reject(event.key, error)
                return {}
        assert isinstance(acts, batch.ActBatch)
        if not first <= acts.last or not self.world.is_member(acts.last):
            self.counters.reject(event.key, f"no process hosts robots {first} to {acts.last}")
            return {}
        host = Host(first, acts.last)
        if not typed and not self._authentic(event, host.identity):
            return {}
        routes = {}
        for robot, act in acts.acts:
            if not host.hosts(robot):
                self.counters.reject(event.key, f"robot {robot} is not one {host.identity} hosts")
            elif self._answer(robot, act, event.key):
                routes[robot] = host
        return routes

    def _answer(self, robot: int, act: protocol.Act, key: str) -> bool:
        """Take an authentic act of ``robot``: whether it is its answer to the tick under
        way (in real time: whether it is for the current tick)."""
        if not self.lockstep:
            if not self.world.is_live(robot):
                return False
            if not self._fresh(key, (act.tick, 0), self.last_act.get(robot)):
                return False
            self.last_act[robot] = (act.tick, 0)
            self.acts[robot] = act
            return act.tick == self.world.tick
        who = names.robot_identity(robot)
        self.counters.missed.pop(who, None)  # it is alive: wait for it again
        if self.barrier.answer(act.tick, who, act.radio_tx):
            self.acts[robot] = act
            return True
        self._unexpected_answer(key, act.tick)
        return False

    def take_ack(self, event: Event) -> tuple[str, protocol.Ack] | None:
        """Take a beacon's answer: its identity and its ack if the tick under way took it
        (lockstep) or it came from a beacon taking part (real time)."""
        name = self.keys.ident_of(keyspace.ACK, event.key) or ""
        if not names.is_beacon_name(name):
            self.counters.reject(event.key, f"no beacon of this run is called {name!r}")
            return None
        who = names.beacon_identity(name)
        typed = isinstance(event.message, protocol.Ack)
        if not typed and not self._authentic(event, who):
            return None
        if name not in self.world.beacons():
            self.counters.late += 1  # its own, but it has left (or not joined yet)
            return None
        try:
            ack = event.message if typed else protocol.decode(event.payload, protocol.Ack)
            assert isinstance(ack, protocol.Ack)
            if ack.next_tick is not None and ack.next_tick <= ack.tick:
                raise protocol.ProtocolError(f"next tick {ack.next_tick} is not after {ack.tick}")
        except protocol.ProtocolError as error:
            self.counters.reject(event.key, error)
            return None
        self.counters.missed.pop(who, None)
        if self.lockstep and not self.barrier.answer(ack.tick, who, ack.radio_tx):
            self._unexpected_answer(event.key, ack.tick)
            return None
        if not self.lockstep:
            if not self._fresh(event.key, (ack.tick, 0), self.last_ack.get(name)):
                return None
            self.last_ack[name] = (ack.tick, 0)
        return who, ack

    # --- radio -------------------------------------------------------------------------

    def take_tx(self, event: Event) -> None:
        """Take a radio message for the medium, to transmit when the tick closes."""
        sender = self.keys.ident_of(keyspace.RADIO_TX, event.key) or ""
        robot = names.robot_of_name(sender)
        if robot is not None and not self.world.is_member(robot):
            robot = None
        if robot is None and not names.is_beacon_name(sender):
            self._reject_tx(event.key, f"no robot or beacon of this run is called {sender!r}")
            return
        identity = names.beacon_identity(sender) if robot is None else names.robot_identity(robot)
        try:
            meta = event.message
            if not isinstance(meta, protocol.RadioTxMeta):
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
        if not self.lockstep:
            stamp = (meta.tick, meta.seq)
            if not self._fresh(event.key, stamp, self.last_tx.get(sender), radio=True):
                return
            self.last_tx[sender] = stamp
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

    # --- the tick ----------------------------------------------------------------------

    def leave(self, who: str, robot: int | None = None) -> None:
        """``who`` left: the tick under way does not wait for it, nor moves its robot, nor
        transmits what it sent this tick (late, like a message that comes after it left:
        there is no transmitter any more, and none of it is a forgery)."""
        if robot is not None:
            self.acts.pop(robot, None)
        kept = [tx for tx in self.transmissions if names.sender_identity(tx.sender) != who]
        self.counters.late += len(self.transmissions) - len(kept)
        self.transmissions = kept
        self.barrier.leave(who)

    def close(self) -> tuple[dict[int, protocol.Act], list[Transmission]]:
        """The acts and transmissions of the tick that closes; the next tick starts empty
        but in real time, where a command holds until replaced but a capture happens once."""
        acts, transmissions = self.acts, self.transmissions
        self.transmissions = []
        self.sent_this_tick = {}
        self.seqs_this_tick = set()
        if self.lockstep:
            self.acts = {}
        else:
            self.acts = {
                robot: msgspec.structs.replace(act, capture=False, radio_tx=0)
                for robot, act in acts.items()
            }
        return acts, transmissions

    def open(self, tick: int, participants: list[str]) -> None:
        self.barrier.open(tick, participants)

    # --- checks ------------------------------------------------------------------------

    def _authentic(self, event: Event, identity: str) -> bool:
        """Whether the event carries ``identity``'s tag (always, in an unkeyed run)."""
        try:
            auth.unseal(self.keyring, identity, event.key, event.payload, event.attachment)
        except auth.AuthError as error:
            self.counters.reject(event.key, error)
            return False
        return True

    def _fresh(
        self, key: str, stamp: tuple[int, int], last: tuple[int, int] | None, radio: bool = False
    ) -> bool:
        """Real time: whether a sender's authentic message stamped ``stamp`` is fresh; a
        replay or a tick to come is rejected (by the radio too, for a radio message), a
        message of a sender lagging too far is late."""
        refused = guard.realtime_refused(stamp, last, self.world.tick)
        if refused is None:
            return True
        reason, late = refused
        if late:
            self.counters.late += 1
        elif radio:
            self._reject_tx(key, reason)
        else:
            self.counters.reject(key, reason)
        return False

    def _unexpected_answer(self, key: str, tick: int) -> None:
        """An answer the barrier did not take: stale, repeated, or from a newcomer (late),
        or for a tick that has not begun (rejected)."""
        if tick <= self.barrier.tick:
            self.counters.late += 1
        else:
            self.counters.reject(key, f"answer for tick {tick} while at tick {self.barrier.tick}")

    def _reject_tx(self, key: str, reason: object) -> None:
        """A radio message the medium refuses: counted by the world and by the radio."""
        self.counters.reject(key, reason)
        self.world.radio.reject()
