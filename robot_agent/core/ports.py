"""The port contract: the ports a robot's controller talks through, and the one loop
that drives it.

A port implements ``Body`` (the robot's own sensors and motors) and ``Radio`` (a lossy
broadcast medium), and calls ``control_step`` once per control period. Every transport
does exactly that: a robot on hardware or UDP (examples/udp_robot.py), and, through
``robot_agent/core/simulated.py``, the Zenoh robot process and the in-process engine. The
controller never sees Zenoh, sockets or clocks.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from wire import protocol

if TYPE_CHECKING:
    import numpy as np

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BodyReading:
    """What the body senses at one control step."""

    t: float  # seconds since the run started, from the port's clock
    x: float  # metres, world frame (odometry or a positioning system on hardware)
    y: float
    theta: float  # radians, counter-clockwise from +x
    proximity: tuple[float, ...]  # 8 infrared readings in [0, 1]; 1 = touching
    frame: np.ndarray | None = None  # BGR camera frame, present once after a request


@dataclass(frozen=True)
class Received:
    """A radio message that passed validation."""

    sender: str
    payload: protocol.OpinionPayload | protocol.BeaconPayload | protocol.VotePayload


@dataclass(frozen=True)
class Command:
    """What the controller wants done until its next step."""

    left: float  # wheel speeds, m/s
    right: float
    capture: bool = False  # request a camera frame (arrives with a later reading)
    broadcasts: tuple[protocol.RobotBroadcast, ...] = ()


class RobotController(Protocol):
    """What a transport drives each control period: the honest ``Controller``, or one
    wrapped to misbehave (``robot_agent.core.byzantine``)."""

    def step(self, reading: BodyReading, received: Sequence[Received]) -> Command: ...

    def status(self, tick: int) -> protocol.Status: ...

    def take_status_change(self) -> bool: ...

    @property
    def decided_site(self) -> int | None: ...


class Body(Protocol):
    def read(self) -> BodyReading: ...

    def drive(self, left: float, right: float) -> None: ...

    def request_frame(self) -> None: ...


class Radio(Protocol):
    def send(self, payload: bytes) -> None: ...

    def poll(self) -> list[tuple[str, bytes]]:
        """Every (sender, payload) received since the last poll, in delivery order."""
        ...


@dataclass
class RejectCounter:
    """Counts invalid messages; logs the first one from each source (sender or key)."""

    count: int = 0
    logged: set[str] = field(default_factory=set)

    def reject(self, sender: str, error: Exception) -> None:
        self.count += 1
        if sender not in self.logged:
            self.logged.add(sender)
            log.warning(
                "dropped an invalid message from %s: %s (further ones not logged)", sender, error
            )


def decode_received(raw: Sequence[tuple[str, bytes]], rejects: RejectCounter) -> list[Received]:
    """Validate raw radio messages; invalid ones are dropped and counted, never raised."""
    received = []
    for sender, payload in raw:
        try:
            received.append(Received(sender, protocol.decode_radio(payload)))
        except protocol.ProtocolError as error:
            rejects.reject(sender, error)
    return received


def control_step(
    controller: RobotController, body: Body, radio: Radio, rejects: RejectCounter
) -> Command:
    """One control period on any transport: sense, receive, decide, act, transmit."""
    reading = body.read()
    command = controller.step(reading, decode_received(radio.poll(), rejects))
    body.drive(command.left, command.right)
    if command.capture:
        body.request_frame()
    for payload in command.broadcasts:
        radio.send(protocol.encode(payload))
    return command
