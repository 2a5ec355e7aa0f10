"""The robot's body: the e-puck's geometry, said once (metres, metres per second, radians).

Every part of the world that needs a robot's size or speed reads it from here (or, on the
robot's side, from ``WorldInfo``, which the world fills in from it)."""

from __future__ import annotations

from dataclasses import dataclass

# e-puck sensors ps0..ps7 in the robot's frame (radians, 0 = ahead, counter-clockwise
# positive): ps0-ps3 on the right side, front to back, ps4-ps7 on the left, back to front.
EPUCK_PROX_ANGLES: tuple[float, ...] = (-0.30, -0.80, -1.57, -2.64, 2.64, 1.57, 0.80, 0.30)


@dataclass(frozen=True)
class EpuckSpec:
    """Body and sensor geometry of one e-puck (metres, metres per second, radians)."""

    radius: float = 0.037
    wheel_base: float = 0.053
    max_wheel_speed: float = 0.13
    prox_range: float = 0.06  # how far beyond the body a proximity ray reaches
    prox_angles: tuple[float, ...] = EPUCK_PROX_ANGLES


EPUCK = EpuckSpec()  # the default body of every run
