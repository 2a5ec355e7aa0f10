"""One robot's end of the wire, whatever carries it (pure: no I/O, no clock).

A transport hands ``RobotEndpoint`` each message it receives for the robot as (input
kind, payload, attachment) and sends what comes back: Zenoh in ``robot_agent/node``, and
any link that carries the same (key, payload, attachment) triples. The endpoint

* checks every input in one place: the tag of the robot's own run key (``bestofn_swarm.wire.auth``),
  the decoding (``bestofn_swarm.wire.protocol``), sim time against the tick
  (``bestofn_swarm.wire.guard``), the tick window and the budget of pending inputs
  (``tick_assembly``); a refusal is counted in ``rejects`` and reported in the robot's status, never
  raised;
* gathers inputs into ticks (``tick_assembly``) and steps the controller once a tick is
  complete, through ``SimulatedPorts`` (the port contract's control step);
* follows one world server (``bestofn_swarm.wire.guard.WorldFollower``): a new one counts ticks from
  zero, so the pending ticks are forgotten and its sim time is shifted by the last time
  seen (the controller's clock never runs backwards); the same one back after an outage
  is rejoined at whatever tick it has reached;
* returns what the robot sends for a step as data (``Step``): its radio transmissions, its
  act and, when it changed, its status, each sealed with the robot's key. A robot whose
  process answers for it in batches (``hosting.HostedRobots``: ``batched``) takes its
  senses from the batch, already checked against the process's key and decoded
  (``receive_sense``), and leaves its act to the batch.

Time comes only from the messages. ``arrived`` is an opaque mark a tracing transport may
attach to an input (its clock's reading); it comes back in the ``Step`` untouched.
"""

from __future__ import annotations

import logging
from typing import Any, Final, TypeVar

import msgspec

from bestofn_swarm.wire import auth, guard, keyspace, names, protocol
from bestofn_swarm.wire.keyspace import Party
from bestofn_swarm.wire.parcel import Encoder, Parcel
from robot_agent.core.ports import RejectCounter, RobotController
from robot_agent.core.simulated import SimulatedPorts
from robot_agent.core.tick_assembly import ReadyTick, TickAssembly

log = logging.getLogger(__name__)
Meta = TypeVar("Meta", protocol.RadioRxMeta, protocol.CameraMeta)


class Outgoing(Parcel):
    """One message to send, of ``kind``: ``message`` for a core in the same process,
    ``payload`` with ``attachment`` (sealed) for a transport (``bestofn_swarm.wire.parcel``)."""

    def __init__(
        self,
        kind: keyspace.KeyKind,
        key: str,
        message: Any,
        encode: Encoder,
        *,
        identity: str,
        keyring: auth.Keyring | None,
        meta: Any = None,
        meta_encode: Encoder = None,
    ) -> None:
        super().__init__(
            key,
            message,
            encode,
            identity=identity,
            keyring=keyring,
            meta=meta,
            meta_encode=meta_encode,
        )
        self.kind = kind


class Step:
    """What one control step of a robot sends, in sending order: its transmissions, its
    act, and its status if it changed (a plain class: one per robot per tick, and a
    NamedTuple's constructor runs interpreted in the compiled cores)."""

    robot: Final[int]
    tick: Final[int]
    arrived: Final[float]  # the latest mark of the tick's inputs (0.0 unless the transport marks)
    transmissions: Final[tuple[Outgoing, ...]]
    answer: Final[protocol.Act]  # the act itself
    act: Final[Outgoing | None]  # the act as sent on the robot's key; None: in its host's batch
    status: Final[Outgoing | None]

    def __init__(
        self,
        *,
        robot: int,
        tick: int,
        arrived: float,
        transmissions: tuple[Outgoing, ...],
        answer: protocol.Act,
        act: Outgoing | None,
        status: Outgoing | None,
    ) -> None:
        self.robot = robot
        self.tick = tick
        self.arrived = arrived
        self.transmissions = transmissions
        self.answer = answer
        self.act = act
        self.status = status

    @property
    def outgoing(self) -> list[Outgoing]:
        act = [] if self.act is None else [self.act]
        status = [] if self.status is None else [self.status]
        return [*self.transmissions, *act, *status]


class RobotEndpoint:
    """One robot: its controller, its checks of what it receives, its tick assembly."""

    def __init__(
        self,
        robot_id: int,
        *,
        keys: keyspace.Keys,
        controller: RobotController,
        world: protocol.WorldInfo,
        keyring: auth.Keyring | None = None,
    ) -> None:
        self.robot_id = robot_id
        self.identity = names.robot_identity(robot_id)
        self.keys = keys
        self.controller = controller
        self.keyring = keyring  # None: an unauthenticated run
        self.dt = world.dt
        self.rejects = RejectCounter()
        self.ports = SimulatedPorts(self.rejects)  # the body and radio control_step drives
        self.assembly = TickAssembly(world.clock == "lockstep")
        self.worlds = guard.WorldFollower()  # the world server's instance (its Zenoh id)
        self.time_offset = 0.0  # keeps the controller's clock monotonic across world restarts
        self.last_t = 0.0
        self.batched = False  # its process answers for it in batches (hosting.py)
        name = names.robot_name(robot_id)
        # The key each input comes on (its tag covers it), and the key each of its own
        # messages goes out on: the key table says which.
        self.input_keys = {kind: keys.of(kind, name) for kind in keyspace.heard_by(Party.ROBOT)}
        self.output_keys = {
            kind: keys.of(kind, name) for kind in keyspace.published_by(Party.ROBOT, Party.SENDER)
        }
        self._tx_key = self.output_keys[keyspace.RADIO_TX]
        self._act_key = self.output_keys[keyspace.ACT]
        self._status_key = self.output_keys[keyspace.STATUS]

    @property
    def last_tick(self) -> int:
        return self.assembly.last_tick

    # --- inputs --------------------------------------------------------------------

    def receive(
        self,
        kind: keyspace.KeyKind,
        payload: bytes,
        attachment: bytes | None,
        arrived: float = 0.0,
    ) -> Step | None:
        """Take one message the world sent this robot; the step it completes, if any."""
        tick = self._hold(kind, payload, attachment, arrived)
        if tick is None:
            return None
        ready = self.assembly.take_ready(tick)
        if ready is None:
            return None
        return self._step(ready)

    def receive_sense(self, sense: protocol.Sense, arrived: float = 0.0) -> Step | None:
        """Take a sense from a batch of senses that passed its process's checks (its tag,
        its decoding: ``hosting.HostedRobots``); the step it completes, if any."""
        assembly = self.assembly
        try:
            refused = guard.time_refused(sense.tick, sense.t, self.dt)
            if refused:
                raise protocol.ProtocolError(refused)
            alone = assembly.step_alone(sense, arrived)
            if alone is not None:
                return self._step(alone)
            held = assembly.add_sense(sense, arrived)
        except protocol.ProtocolError as error:
            self.reject(keyspace.SENSE.name, error)
            return None
        ready = assembly.take_ready(sense.tick) if held else None
        return None if ready is None else self._step(ready)

    def receive_message(
        self, kind: keyspace.KeyKind, message: Any, meta: Any = None, arrived: float = 0.0
    ) -> Step | None:
        """Take one message the world sent this robot, handed over typed by a core in the
        same process (the in-process engine): a ``Sense``, or a radio payload or camera
        frame with its ``RadioRxMeta`` or ``CameraMeta``. It is taken without decoding or
        a tag, as the process's own; every other check applies. The step it completes,
        if any."""
        try:
            tick, held = self._hold_message(kind, message, meta, arrived)
        except protocol.ProtocolError as error:
            self.reject(kind.name, error)
            return None
        if not held:
            return None
        ready = self.assembly.take_ready(tick)
        return None if ready is None else self._step(ready)

    def _hold(
        self, kind: keyspace.KeyKind, payload: bytes, attachment: bytes | None, arrived: float
    ) -> int | None:
        """Check an input and hold it for its tick: the tick, or None if it was refused
        (counted) or is stale (a tick already stepped)."""
        try:
            metadata = auth.unseal(
                self.keyring, self.identity, self.input_keys[kind], payload, attachment
            )
            if kind is keyspace.SENSE:
                message: Any = protocol.decode(payload, protocol.Sense)
                meta: Any = None
            elif kind is keyspace.RADIO_RX:
                message, meta = payload, _metadata(metadata, protocol.RadioRxMeta)
            else:
                message, meta = payload, _metadata(metadata, protocol.CameraMeta)
            tick, held = self._hold_message(kind, message, meta, arrived)
        except (auth.AuthError, protocol.ProtocolError) as error:
            self.reject(kind.name, error)
            return None
        return tick if held else None

    def _hold_message(
        self, kind: keyspace.KeyKind, message: Any, meta: Any, arrived: float
    ) -> tuple[int, bool]:
        """Hold a decoded input for its tick: its tick, and whether it was held (False:
        stale). ProtocolError if it is refused."""
        if kind is keyspace.SENSE:
            sense: protocol.Sense = message
            refused = guard.time_refused(sense.tick, sense.t, self.dt)
            if refused:
                raise protocol.ProtocolError(refused)
            return sense.tick, self.assembly.add_sense(sense, arrived)
        if kind is keyspace.RADIO_RX:
            radio: protocol.RadioRxMeta = meta
            return radio.tick, self.assembly.add_rx(radio.tick, radio.sender, message, arrived)
        camera: protocol.CameraMeta = meta
        return camera.tick, self.assembly.add_frame(camera.tick, message, arrived)

    def reject(self, source: str, error: Exception) -> None:
        """Count a refused input (``source``: what it came as), logged once per source."""
        self.rejects.reject(f"robot {self.robot_id} {source}", error)

    def count_dropped(self, count: int) -> None:
        """Count inputs the transport dropped on arrival (too big, or no room to queue)."""
        for _ in range(count):
            self.reject("inbox", protocol.ProtocolError("dropped on arrival"))

    # --- the world server ----------------------------------------------------------

    def world_appeared(self, instance: str) -> None:
        """A world server's liveliness token, proved the world's (it answered for it with
        the run's key: ``bestofn_swarm.plumbing.world_info.world_proved``): the first is
        followed; when the followed one is gone, another is a new world; the followed one
        again is the same world back. A token alone is a hint anyone can give: see
        world_unproven."""
        seen = self.worlds.appeared(instance)
        if seen == "new":
            log.warning("robot %d: a new world server appeared; resuming", self.robot_id)
            self.assembly.follow_new_world()
            self.time_offset = self.last_t
        elif seen == "back":
            log.warning("robot %d: the world server is back; resuming", self.robot_id)
            self.assembly.rejoin()
        elif instance != self.worlds.followed:
            log.warning(
                "robot %d: ignoring a second world token %s while following %s",
                self.robot_id,
                instance,
                self.worlds.followed,
            )

    def world_unproven(self, instance: str) -> None:
        """A world server's token that no world answered for: someone else's, ignored and
        counted (it must neither shift the robot's clock nor take it off its world)."""
        self.reject("world token", protocol.ProtocolError(f"no world answers for {instance!r}"))

    def world_vanished(self, instance: str) -> None:
        """A world server's token went: if it was the followed one, wait for it."""
        if self.worlds.vanished(instance):
            log.warning("robot %d lost the world server; waiting", self.robot_id)

    # --- outputs -------------------------------------------------------------------

    def _step(self, ready: ReadyTick) -> Step:
        sense = ready.sense
        if self.time_offset:
            sense = msgspec.structs.replace(sense, t=sense.t + self.time_offset)
        self.last_t = sense.t
        answer = self.ports.answer(self.controller, sense, ready.rx, ready.frame)
        transmissions = tuple(
            Outgoing(
                keyspace.RADIO_TX,
                self._tx_key,
                sent.payload,
                None,
                identity=self.identity,
                keyring=self.keyring,
                meta=sent.meta,
                meta_encode=protocol.encode,
            )
            for sent in answer.transmissions
        )
        act_message = None
        if not self.batched:
            act_message = Outgoing(
                keyspace.ACT,
                self._act_key,
                answer.act,
                protocol.encode,
                identity=self.identity,
                keyring=self.keyring,
            )
        status = self.status(sense.tick) if self.controller.take_status_change() else None
        return Step(
            robot=self.robot_id,
            tick=sense.tick,
            arrived=ready.arrived,
            transmissions=transmissions,
            answer=answer.act,
            act=act_message,
            status=status,
        )

    def status(self, tick: int) -> Outgoing:
        """The robot's status at ``tick``, its rejections included, sealed."""
        status = self.controller.status(tick)
        if self.rejects.count:
            status = msgspec.structs.replace(status, rejected=status.rejected + self.rejects.count)
        return Outgoing(
            keyspace.STATUS,
            self._status_key,
            status,
            protocol.encode,
            identity=self.identity,
            keyring=self.keyring,
        )


def _metadata(metadata: bytes | None, kind: type[Meta]) -> Meta:
    """An input's metadata (after its tag, in its attachment) as ``kind``; ProtocolError
    if there is none or it is not one."""
    if metadata is None:
        raise protocol.ProtocolError("missing attachment")
    return protocol.decode(metadata, kind)
