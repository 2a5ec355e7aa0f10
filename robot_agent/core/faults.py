"""Faults of robots, as plug-ins of both engines (pure: no I/O, no clock).

A fault is one object, declared by one switch of ``swarm run`` (``RobotFaults`` in
deploy/launcher/switches.py), that both engines call the same way: ``swarm run`` over Zenoh
(the launcher, deploy/launcher/launcher.py) and the in-process engine
(deploy/inprocess/engine.py) each hand it, at every tick boundary once its sim time has come,
an ``Engine``: what may be done to a run's robots there (kill one, start it afresh). A fault
that changes what a robot does rather than whether it runs wraps the robot's controller
where every robot is built (``wrap``, robot_agent/core/builder.py), in the robot's own
process or in the engine's; it reaches a robot process in its configuration
(``FaultSpec``). The faults of the world and the beacon (radio loss, bursts and noise; the
beacon's outages) are declared on their configurations and applied by their cores, the
same in both engines; Byzantine robots are declared once too (``ByzantineRobot``) and built
by ``byzantine.build_controller``.

A new fault of a robot is one class here, added to ``FAULTS``, and its switch.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

from robot_agent.core import ports
from robot_agent.core.wrapped import WrappedController


class Engine(Protocol):
    """What a fault may do to a run at a tick boundary, whatever the engine."""

    def kill(self, robot: int) -> bool:
        """Stop the robot for good (its body stays, a stopped obstacle); whether it was
        running."""
        ...

    def restart(self, robot: int) -> None:
        """Start the robot afresh: a new controller, undecided, in its old body."""
        ...


@dataclass(frozen=True)
class Applied:
    """A fault as the summary lists it (``faults``)."""

    robot: int
    action: str  # the fault's switch: kill, restart, motor-failure
    at_s: float  # its sim time
    applied_at_s: float  # the sim time of the tick boundary it was applied at
    was_running: bool

    def record(self) -> dict[str, object]:
        return {
            "robot": self.robot,
            "action": self.action,
            "at_s": self.at_s,
            "applied_at_s": round(self.applied_at_s, 3),
            "was_running": self.was_running,
        }


@dataclass(frozen=True)
class RobotFault:
    """A fault of robot ``robot`` from sim time ``at``: the base of every fault of a robot.
    A subclass sets its switch (``SWITCH``, ``HELP``) and overrides ``apply``, ``wrap`` or
    both."""

    robot: int
    at: float  # sim seconds

    SWITCH: ClassVar[str] = ""  # its swarm run option, without the dashes
    HELP: ClassVar[str] = ""
    RESTARTS: ClassVar[bool] = False  # a robot will take part again: the run waits for it
    # Applied by the engine at a tick boundary (else it lives in the robot's controller).
    BY_ENGINE: ClassVar[bool] = True

    def apply(self, engine: Engine) -> bool:
        """Do it to the run (an engine's fault); whether the robot was running."""
        return True

    def wrap(self, controller: ports.RobotController) -> ports.RobotController:
        """The robot's controller with this fault (a controller's fault)."""
        return controller

    @property
    def spec(self) -> FaultSpec:
        return FaultSpec(self.SWITCH, self.robot, self.at)


class Kill(RobotFault):
    SWITCH = "kill"
    HELP = (
        "stop robot ROBOT for good at SIMTIME sim seconds (over Zenoh: SIGKILL its "
        "process); the swarm goes on without it"
    )

    def apply(self, engine: Engine) -> bool:
        return engine.kill(self.robot)


class Restart(RobotFault):
    SWITCH = "restart"
    HELP = (
        "start robot ROBOT afresh at SIMTIME (over Zenoh: a new process, after killing the "
        "old one if it still runs): a new controller in its old body"
    )
    RESTARTS = True

    def apply(self, engine: Engine) -> bool:
        was_running = engine.kill(self.robot)
        engine.restart(self.robot)
        return was_running


class StoppedMotors(WrappedController):
    """A controller whose wheels no longer turn from sim time ``at``: its commands are
    given as ever, and the motors do not follow them."""

    def __init__(self, inner: ports.RobotController, at: float) -> None:
        super().__init__(inner)
        self._at = at

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        command = self._controller.step(reading, received)
        if reading.t < self._at:
            return command
        return ports.Command(0.0, 0.0, command.capture, command.broadcasts)


class MotorFailure(RobotFault):
    SWITCH = "motor-failure"
    HELP = (
        "robot ROBOT's wheels stop from SIMTIME sim seconds: its controller goes on, its "
        "motors do not follow"
    )
    BY_ENGINE = False

    def wrap(self, controller: ports.RobotController) -> ports.RobotController:
        return StoppedMotors(controller, self.at)


class SilentRadio(WrappedController):
    """A controller whose broadcasts no longer leave the robot from sim time ``at``."""

    def __init__(self, inner: ports.RobotController, at: float) -> None:
        super().__init__(inner)
        self._at = at

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        command = self._controller.step(reading, received)
        if reading.t < self._at or not command.broadcasts:
            return command
        return command.with_broadcasts(())


class RadioFailure(RobotFault):
    SWITCH = "radio-failure"
    HELP = (
        "robot ROBOT's radio stops sending from SIMTIME sim seconds: it still hears the others "
        "and the beacon"
    )
    BY_ENGINE = False

    def wrap(self, controller: ports.RobotController) -> ports.RobotController:
        return SilentRadio(controller, self.at)


# Every fault of a robot, by its switch.
FAULTS: tuple[type[RobotFault], ...] = (Kill, Restart, MotorFailure, RadioFailure)
BY_SWITCH: dict[str, type[RobotFault]] = {fault.SWITCH: fault for fault in FAULTS}


@dataclass(frozen=True)
class FaultSpec:
    """A fault as a robot process's configuration carries it: its switch, robot and time."""

    switch: str
    robot: int
    at: float

    def fault(self) -> RobotFault:
        """The fault it names; ValueError for a switch no fault has."""
        kind = BY_SWITCH.get(self.switch)
        if kind is None:
            raise ValueError(f"no fault of a robot is called {self.switch!r}")
        return kind(self.robot, self.at)


def wrapping(faults: Iterable[RobotFault], robot: int) -> list[RobotFault]:
    """The faults that change what ``robot``'s controller does, in the order given."""
    return [fault for fault in faults if fault.robot == robot and not fault.BY_ENGINE]


def wrapped(
    controller: ports.RobotController, faults: Iterable[RobotFault]
) -> ports.RobotController:
    """``controller`` with each of ``faults``'s wrappers around it."""
    for fault in faults:
        controller = fault.wrap(controller)
    return controller


class Schedule:
    """The faults an engine applies, still to come in sim-time order, and those applied."""

    def __init__(self, faults: Iterable[RobotFault]) -> None:
        declared = sorted(faults, key=lambda fault: fault.at)
        self.pending = [fault for fault in declared if fault.BY_ENGINE]
        # A controller's fault acts from the robot's first step at or after its time, in the
        # robot's own controller: listed as applied then.
        self.applied: list[Applied] = [
            Applied(fault.robot, fault.SWITCH, fault.at, fault.at, True)
            for fault in declared
            if not fault.BY_ENGINE
        ]

    def apply_due(self, engine: Engine, sim_time: float) -> list[Applied]:
        """Apply the faults whose time has come (at this tick boundary); those applied."""
        count = next(
            (index for index, fault in enumerate(self.pending) if fault.at > sim_time),
            len(self.pending),
        )
        due, self.pending = self.pending[:count], self.pending[count:]
        done = []
        for fault in due:
            was_running = fault.apply(engine)
            done.append(Applied(fault.robot, fault.SWITCH, fault.at, sim_time, was_running))
        self.applied += done
        return done

    def restart_pending(self) -> bool:
        """A robot is still to be restarted: it will take part again."""
        return any(fault.RESTARTS for fault in self.pending)


__all__ = [
    "BY_SWITCH",
    "FAULTS",
    "Applied",
    "Engine",
    "FaultSpec",
    "Kill",
    "MotorFailure",
    "RadioFailure",
    "Restart",
    "RobotFault",
    "Schedule",
    "SilentRadio",
    "StoppedMotors",
    "wrapped",
    "wrapping",
]
