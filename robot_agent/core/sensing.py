"""The controller's sensing: estimating one site's quality by camera, with retries.

At the viewpoint the robot turns to face the site's panel and requests a frame. A frame
that does not come within ``capture_timeout``, or that shows no site (a malformed frame,
grey wall, a robot in the way), is a failed attempt: the robot aims up to ``wiggle``
either side of the site (a draw from the controller's RNG: an occluder or a pose error
may hide the panel) and tries again, and after ``capture_attempts`` failures gives the
site up.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Final

import numpy as np

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import ports
from robot_agent.core.motion import STOP, TIME_EPSILON, Motion

if TYPE_CHECKING:
    from robot_agent.core.controller_config import ControllerConfig

QualityEstimator = Callable[[np.ndarray], "float | None"]


class Look:
    """One control period of sensing: what to do, and what came of it (a plain class: a
    compiled dataclass's __init__ runs interpreted)."""

    command: Final[ports.Command]
    quality: Final[float | None]  # the site's quality in [0, 1], once a frame showed it
    gave_up: Final[bool]  # capture_attempts frames failed: the site cannot be seen

    def __init__(
        self, command: ports.Command, quality: float | None = None, gave_up: bool = False
    ) -> None:
        self.command = command
        self.quality = quality
        self.gave_up = gave_up


class Sensing:
    """Looking at one site at a time; ``begin`` at its viewpoint, then ``step`` each period."""

    def __init__(
        self,
        motion: Motion,
        config: ControllerConfig,
        rng: Stream,
        estimate_quality: QualityEstimator,
    ) -> None:
        self._motion = motion
        self._config = config
        self._rng = rng  # the controller's own: retries draw from the stream pairs draw from
        self._estimate_quality = estimate_quality
        self._site = (0.0, 0.0)
        self._attempts = 0
        self._capture_time: float | None = None  # when the awaited frame was requested
        self._aim = 0.0

    def begin(self, reading: ports.BodyReading, site: tuple[float, float]) -> None:
        """Start looking at the site panel at ``site`` (x, y) from where the robot stands."""
        self._site = site
        self._attempts = 0
        self._capture_time = None
        self._aim = self._site_heading(reading)

    def step(self, reading: ports.BodyReading) -> Look:
        failed = False
        if self._capture_time is not None:
            if reading.frame is not None:
                self._capture_time = None
                quality = self._estimate(reading.frame)
                if quality is not None:
                    return Look(STOP, quality=quality)
                failed = True
            elif reading.t - self._capture_time > self._config.capture_timeout + TIME_EPSILON:
                self._capture_time = None
                failed = True
            else:
                return Look(STOP)  # the frame is on its way
        if failed:
            self._attempts += 1
            if self._attempts >= self._config.capture_attempts:
                return Look(STOP, gave_up=True)
            # Look slightly to one side: an occluder or a pose error may hide the panel.
            self._aim = self._site_heading(reading) + self._rng.uniform(
                -self._config.wiggle, self._config.wiggle
            )
        left, right, facing = self._motion.turn_to(reading, self._aim)
        if facing:
            self._capture_time = reading.t
            return Look(ports.Command(0.0, 0.0, capture=True))
        return Look(ports.Command(left, right))

    def _estimate(self, frame: np.ndarray) -> float | None:
        try:
            quality = self._estimate_quality(frame)
        except ValueError:
            return None  # a malformed frame is no view of the site
        if quality is None or not math.isfinite(quality):
            return None
        return min(max(float(quality), 0.0), 1.0)

    def _site_heading(self, reading: ports.BodyReading) -> float:
        """Facing the site's panel from where the robot stands (radially at the viewpoint)."""
        return numeric.atan2(self._site[1] - reading.y, self._site[0] - reading.x)


__all__ = ["Look", "QualityEstimator", "Sensing"]
