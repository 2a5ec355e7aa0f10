"""The ``Body`` and ``Radio`` of a robot whose body the world simulates: one adapter of the
port contract (``ports.control_step``), used by the robot's endpoint (``endpoint.py``, and
so by the robot process over Zenoh) and by ``deploy/inprocess/engine.py`` in one process, so both
run exactly the loop a port runs.

Each tick the world sends a ``Sense`` (time, pose, proximity), the radio medium's
deliveries and, after a capture request, a camera frame (PNG over a transport, the image
itself in one process). ``SimulatedBody`` reads them as a ``BodyReading`` and turns
``drive`` and ``request_frame`` into the tick's ``Act``; ``SimulatedRadio`` hands the
deliveries to ``poll`` and numbers what ``send`` broadcasts, from 1 over the robot's life.
``tests/vectors/tick.json`` gives ticks in bytes, in and out (docs/porting.md).
"""

from __future__ import annotations

from typing import Final

import numpy as np

from bestofn_swarm.wire import protocol
from robot_agent.core import ports, vision
from robot_agent.core.ports import BodyReading, RejectCounter, RobotController
from robot_agent.core.tick_assembly import Frame

# Plain classes with read-only attributes, not frozen dataclasses: a tick makes one per
# robot, and a dataclass's generated __init__ runs interpreted in the compiled cores.


class Broadcast:
    """One broadcast as the robot publishes it on ``radio/tx/<id>``."""

    seq: Final[int]  # from 1 over the robot's life
    payload: Final[bytes]
    meta: Final[protocol.RadioTxMeta]  # {tick, seq}: what the sample's attachment carries

    def __init__(self, seq: int, payload: bytes, meta: protocol.RadioTxMeta) -> None:
        self.seq = seq
        self.payload = payload
        self.meta = meta

    def __repr__(self) -> str:
        return f"Broadcast(seq={self.seq!r}, payload={self.payload!r}, meta={self.meta!r})"


class TickAnswer:
    """What a robot publishes for one tick: its broadcasts, then its act."""

    act: Final[protocol.Act]
    transmissions: Final[tuple[Broadcast, ...]]  # in sending order

    def __init__(self, act: protocol.Act, transmissions: tuple[Broadcast, ...]) -> None:
        self.act = act
        self.transmissions = transmissions

    def __repr__(self) -> str:
        return f"TickAnswer(act={self.act!r}, transmissions={self.transmissions!r})"


class SimulatedBody:
    """``ports.Body`` over the world's messages of one tick."""

    def __init__(self, rejects: RejectCounter) -> None:
        self._rejects = rejects
        self._sense: protocol.Sense | None = None
        self._frame: Frame | None = None
        self.left = 0.0
        self.right = 0.0
        self.capture = False

    def arrive(self, sense: protocol.Sense, frame: Frame | None) -> None:
        """The tick's sense and camera frame; the command starts afresh."""
        self._sense, self._frame = sense, frame
        self.left = self.right = 0.0
        self.capture = False

    def read(self) -> BodyReading:
        sense = self._sense
        if sense is None:
            raise RuntimeError("read before the world's first sense arrived")
        image = None
        frame = self._frame
        if isinstance(frame, np.ndarray):
            image = frame  # the world's own image, in the same process
        elif frame is not None:
            try:
                image = vision.decode_frame(frame)
            except ValueError as error:  # a frame that is no image: counted, not raised
                self._rejects.reject("camera", error)
        return BodyReading(
            t=sense.t,
            x=sense.x,
            y=sense.y,
            theta=sense.theta,
            proximity=tuple(sense.prox),
            frame=image,
        )

    def drive(self, left: float, right: float) -> None:
        self.left, self.right = left, right

    def request_frame(self) -> None:
        self.capture = True  # the world renders it for the next tick


class SimulatedRadio:
    """``ports.Radio`` over the medium's deliveries of one tick."""

    def __init__(self) -> None:
        self.seq = 0  # the last broadcast's number
        self._delivered: list[tuple[str, bytes]] = []
        self._sent: list[tuple[int, bytes]] = []

    def arrive(self, delivered: list[tuple[str, bytes]]) -> None:
        """The tick's deliveries, in the medium's order (by sender, then sequence)."""
        self._delivered = delivered

    def poll(self) -> list[tuple[str, bytes]]:
        delivered, self._delivered = self._delivered, []
        return delivered

    def send(self, payload: bytes) -> None:
        self.seq += 1
        self._sent.append((self.seq, payload))

    def take_sent(self) -> list[tuple[int, bytes]]:
        """What was sent since the last call, in sending order."""
        sent = self._sent
        if sent:  # most ticks send nothing: keep the empty list
            self._sent = []
        return sent


class SimulatedPorts:
    """One robot's simulated body and radio, and its answer to each tick."""

    def __init__(self, rejects: RejectCounter) -> None:
        self.rejects = rejects
        self.body = SimulatedBody(rejects)
        self.radio = SimulatedRadio()

    def answer(
        self,
        controller: RobotController,
        sense: protocol.Sense,
        delivered: list[tuple[str, bytes]],
        frame: Frame | None,
    ) -> TickAnswer:
        """Run the contract's control step on tick ``sense.tick``'s inputs."""
        self.body.arrive(sense, frame)
        self.radio.arrive(delivered)
        ports.control_step(controller, self.body, self.radio, self.rejects)
        sent = self.radio.take_sent()
        transmissions = (
            tuple(
                Broadcast(
                    seq, payload, protocol.RadioTxMeta(v=protocol.VERSION, tick=sense.tick, seq=seq)
                )
                for seq, payload in sent
            )
            if sent
            else ()
        )
        act = protocol.Act(
            v=protocol.VERSION,
            tick=sense.tick,
            left=self.body.left,
            right=self.body.right,
            capture=self.body.capture,
            radio_tx=len(transmissions),
        )
        return TickAnswer(act, transmissions)
