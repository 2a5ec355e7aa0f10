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
from typing import TYPE_CHECKING, Final, Protocol

from bestofn_swarm.wire import protocol

if TYPE_CHECKING:
    import numpy as np

log = logging.getLogger(__name__)


# The values a control step is made of are plain classes with read-only attributes, not
# frozen dataclasses: the compiled cores (bestofn_swarm/plumbing/cores.py) make several per robot
# per tick, and a dataclass's generated __init__ runs interpreted, an order slower.


class BodyReading:
    """What the body senses at one control step."""

    t: Final[float]  # seconds since the run started, from the port's clock
    x: Final[float]  # metres, world frame (odometry or a positioning system on hardware)
    y: Final[float]
    theta: Final[float]  # radians, counter-clockwise from +x
    proximity: Final[tuple[float, ...]]  # 8 infrared readings in [0, 1]; 1 = touching
    frame: Final[np.ndarray | None]  # BGR camera frame, present once after a request

    def __init__(
        self,
        *,
        t: float,
        x: float,
        y: float,
        theta: float,
        proximity: tuple[float, ...],
        frame: np.ndarray | None = None,
    ) -> None:
        self.t = t
        self.x = x
        self.y = y
        self.theta = theta
        self.proximity = proximity
        self.frame = frame

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BodyReading):
            return NotImplemented
        return _same_frame(self.frame, other.frame) and (
            self.t,
            self.x,
            self.y,
            self.theta,
            self.proximity,
        ) == (
            other.t,
            other.x,
            other.y,
            other.theta,
            other.proximity,
        )

    __hash__ = None  # type: ignore[assignment]  # equal readings may hold unhashable frames

    def __repr__(self) -> str:
        frame = "None" if self.frame is None else f"<{'x'.join(map(str, self.frame.shape))}>"
        return (
            f"BodyReading(t={self.t!r}, x={self.x!r}, y={self.y!r}, theta={self.theta!r}, "
            f"proximity={self.proximity!r}, frame={frame})"
        )


def _same_frame(first: np.ndarray | None, second: np.ndarray | None) -> bool:
    if first is None or second is None:
        return first is second
    return first.shape == second.shape and bool((first == second).all())


class Received:
    """A radio message that passed validation."""

    sender: Final[str]
    payload: Final[protocol.OpinionPayload | protocol.BeaconPayload | protocol.VotePayload]

    def __init__(
        self,
        sender: str,
        payload: protocol.OpinionPayload | protocol.BeaconPayload | protocol.VotePayload,
    ) -> None:
        self.sender = sender
        self.payload = payload

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Received):
            return NotImplemented
        return (self.sender, self.payload) == (other.sender, other.payload)

    def __hash__(self) -> int:
        return hash((self.sender, self.payload))

    def __repr__(self) -> str:
        return f"Received(sender={self.sender!r}, payload={self.payload!r})"


class Command:
    """What the controller wants done until its next step."""

    left: Final[float]  # wheel speeds, m/s
    right: Final[float]
    capture: Final[bool]  # request a camera frame (arrives with a later reading)
    broadcasts: Final[tuple[protocol.RobotBroadcast, ...]]

    def __init__(
        self,
        left: float,
        right: float,
        capture: bool = False,
        broadcasts: tuple[protocol.RobotBroadcast, ...] = (),
    ) -> None:
        self.left = left
        self.right = right
        self.capture = capture
        self.broadcasts = broadcasts

    def with_broadcasts(self, broadcasts: tuple[protocol.RobotBroadcast, ...]) -> Command:
        """The same command with other broadcasts."""
        return Command(self.left, self.right, self.capture, broadcasts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Command):
            return NotImplemented
        return (self.left, self.right, self.capture, self.broadcasts) == (
            other.left,
            other.right,
            other.capture,
            other.broadcasts,
        )

    def __hash__(self) -> int:
        return hash((self.left, self.right, self.capture, self.broadcasts))

    def __repr__(self) -> str:
        return (
            f"Command(left={self.left!r}, right={self.right!r}, capture={self.capture!r}, "
            f"broadcasts={self.broadcasts!r})"
        )


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
