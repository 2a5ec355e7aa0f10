"""The controller's driving: legs of travel on the navigator, and turning on the spot.

A leg is one drive to a goal (a viewpoint, the nest, a parking slot). Where the paper
leaves the robot to its path planner, a crowded arena needs two guards, both measured
from the leg's start: a goal that another robot stands on is never reached, so a robot
stalled near it for ``stall_timeout`` may take it as reached (``stalled_near``); and a leg
that takes longer than ``ControllerConfig.leg_allowance`` of its length is given up
(``timed_out``). Time is the reading's ``t``; nothing here reads a clock.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from bestofn_swarm.wire import numeric
from robot_agent.core import ports
from robot_agent.core.navigation import Navigator

if TYPE_CHECKING:
    from robot_agent.core.controller_config import ControllerConfig

TIME_EPSILON = 1e-9  # seconds: sums of control periods are not exact in binary
PROGRESS_STEP = 0.01  # metres a leg must gain on its best distance to count as progress
STOP = ports.Command(0.0, 0.0)  # stand still


class Motion:
    """One robot's legs of travel, on its navigator."""

    def __init__(self, navigator: Navigator, config: ControllerConfig) -> None:
        self.navigator = navigator
        self._config = config
        self.leg_start = 0.0  # sim seconds when the current leg began
        self._allowance: float | None = None  # seconds this leg may take
        self._best_distance = math.inf
        self._last_progress = 0.0

    @property
    def escapes(self) -> int:
        """How often the navigator had to break out of a stall (a diagnostic)."""
        return self.navigator.escapes

    def start_leg(self, t: float) -> None:
        """A new leg begins at sim time ``t``: forget the last one's progress and avoidance."""
        self.navigator.reset()
        self.leg_start = t
        self._allowance = None
        self._best_distance = math.inf
        self._last_progress = t

    def drive_to(
        self,
        reading: ports.BodyReading,
        goal: tuple[float, float],
        tolerance: float,
        *,
        avoid: bool = True,
    ) -> tuple[float, float, bool]:
        """Wheel speeds towards ``goal``, and whether it is within ``tolerance``; with
        ``avoid`` off the proximity sensors are ignored (drive straight in)."""
        proximity = reading.proximity if avoid else (0.0,) * len(reading.proximity)
        return self.navigator.drive_to(
            reading.x, reading.y, reading.theta, proximity, goal, tolerance
        )

    def turn_to(self, reading: ports.BodyReading, heading: float) -> tuple[float, float, bool]:
        """Wheel speeds that turn on the spot towards ``heading``, and whether it is faced."""
        return self.navigator.turn_to(reading.theta, heading, self._config.heading_tolerance)

    def timed_out(self, reading: ports.BodyReading, goal: tuple[float, float]) -> bool:
        """Whether the current leg has taken longer than ``leg_allowance`` of its length,
        measured when the leg's first step saw where it starts."""
        if self._allowance is None:
            self._allowance = self._config.leg_allowance(distance(reading, goal))
        return reading.t - self.leg_start > self._allowance

    def stalled_near(
        self, reading: ports.BodyReading, goal: tuple[float, float], near: float
    ) -> bool:
        """Within ``near`` of ``goal`` but no closer for ``stall_timeout``: someone is there."""
        gap = distance(reading, goal)
        if gap < self._best_distance - PROGRESS_STEP:
            self._best_distance = gap
            self._last_progress = reading.t
            return False
        return gap <= near and reading.t - self._last_progress >= self._config.stall_timeout


def along_radius(x: float, y: float, radius: float) -> tuple[float, float]:
    """The point at ``radius`` from the centre on the ray through (x, y) (on the +x axis
    for the centre itself)."""
    length = numeric.hypot(x, y)
    if length == 0.0:
        return radius, 0.0
    return radius * (x / length), radius * (y / length)


def distance(reading: ports.BodyReading, point: tuple[float, float]) -> float:
    return numeric.hypot(reading.x - point[0], reading.y - point[1])


__all__ = ["PROGRESS_STEP", "STOP", "TIME_EPSILON", "Motion", "along_radius", "distance"]
