"""The messages a lockstep run puts on the wire, rebuilt in one process for a recorder.

``swarm run --engine inprocess --record`` has no Zenoh and no processes, but its
recording must read like one of ``swarm run``: the same keys, the same payloads and
attachments (world/clock and world/state, each robot's sense, camera, act and status,
radio tx and rx with their metadata, the beacon's ack), in the order the processes
publish them within a tick. ``deploy/inmemory.py`` calls a WireTap at those points; it
encodes each message as the world server, the robot processes and the beacon
do (an unkeyed run: attachments carry only metadata) and hands it on.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import msgspec

from robot_agent.core.simulated import TickAnswer
from wire import names, protocol
from world_server.core.radio import Delivery
from world_server.core.world import World

# key, payload, attachment: a sample as a Zenoh subscriber would see it.
Put = Callable[[str, bytes, bytes | None], None]


class WireTap:
    """Encodes one run's messages as the processes of ``swarm run`` publish them."""

    def __init__(self, keys: protocol.Keys, put: Put, state_every: int) -> None:
        self.keys = keys
        self.put = put
        self.state_every = state_every

    def tick_opened(
        self, world: World, senses: Sequence[tuple[int, protocol.Sense]], frames: dict[int, bytes]
    ) -> None:
        """The world opens a tick: camera frames, each robot's sense, the clock, the state."""
        spec = world.config.camera
        for robot, frame in frames.items():
            meta = protocol.CameraMeta(
                v=protocol.VERSION,
                tick=world.tick,
                width=spec.width,
                height=spec.height,
                encoding="png",
            )
            self.put(self.keys.camera(robot), frame, protocol.encode(meta))
        for robot, sense in senses:
            self.put(self.keys.sense(robot), protocol.encode(sense), None)
        clock = protocol.Clock(v=protocol.VERSION, tick=world.tick, t=world.t)
        self.put(self.keys.world_clock, protocol.encode(clock), None)
        if world.tick % self.state_every == 0:
            self.state(world)

    def state(self, world: World) -> None:
        self.put(self.keys.world_state, protocol.encode(world.state()), None)

    def robot_answered(
        self, robot: int, answer: TickAnswer, status: protocol.Status | None
    ) -> None:
        """A robot's answer: its radio messages, its act, and its status if it changed."""
        name = names.robot_name(robot)
        for sent in answer.transmissions:
            self.put(self.keys.radio_tx(name), sent.payload, sent.meta)
        self.put(self.keys.act(robot), protocol.encode(answer.act), None)
        if status is not None:
            self.put(self.keys.status(robot), protocol.encode(status), None)

    def beacon_answered(
        self, name: str, tick: int, messages: Iterable[protocol.BeaconPayload], next_tick: int
    ) -> None:
        """The beacon's answer to a tick it answers: its radio messages, its ack."""
        sent = 0
        for message in messages:
            meta = protocol.RadioTxMeta(v=protocol.VERSION, tick=tick, seq=message.seq)
            self.put(self.keys.radio_tx(name), protocol.encode(message), protocol.encode(meta))
            sent += 1
        ack = protocol.Ack(v=protocol.VERSION, tick=tick, radio_tx=sent, next_tick=next_tick)
        self.put(self.keys.beacon_ack(name), protocol.encode(ack), None)

    def delivered(self, tick: int, deliveries: dict[str, list[Delivery]]) -> None:
        """The medium's deliveries of the tick that now begins, on each receiver's key."""
        for name, items in deliveries.items():
            key = self.keys.radio_rx(name)
            for item in items:
                meta = protocol.RadioRxMeta(
                    v=protocol.VERSION,
                    tick=tick,
                    sender=item.sender,
                    seq=item.seq,
                    sent_tick=item.sent_tick,
                )
                self.put(key, item.payload, protocol.encode(meta))


def with_rejects(status: protocol.Status, rejected: int) -> protocol.Status:
    """A status as a robot publishes it (``RobotEndpoint.status``): the controller's rejects
    plus its endpoint's."""
    return (
        msgspec.structs.replace(status, rejected=status.rejected + rejected) if rejected else status
    )
