"""A controller that changes what another one does: the base of every robot that is made to
misbehave (a Byzantine robot, robot_agent/core/byzantine.py) or to fail (a fault,
deploy/faults). It keeps the port contract (``ports.RobotController``) by handing every
call to the controller it wraps; a wrapper overrides only what it changes."""

from __future__ import annotations

from collections.abc import Sequence

from bestofn_swarm.wire import protocol
from robot_agent.core import ports


class WrappedController:
    """Every call handed to ``inner``, unchanged."""

    def __init__(self, inner: ports.RobotController) -> None:
        self._controller = inner

    @property
    def inner(self) -> ports.RobotController:
        """The controller this one wraps."""
        return self._controller

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        return self._controller.step(reading, received)

    def status(self, tick: int) -> protocol.Status:
        return self._controller.status(tick)

    def take_status_change(self) -> bool:
        return self._controller.take_status_change()

    @property
    def decided_site(self) -> int | None:
        return self._controller.decided_site


__all__ = ["WrappedController"]
