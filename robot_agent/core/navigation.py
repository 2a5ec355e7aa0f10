"""Go-to-goal for a differential-drive robot, with obstacle avoidance from 8 IR sensors.

Pure Python (no numpy, no clock): it runs on a robot's own computer. The navigator is
called once per control period and returns wheel speeds. It steers straight for the goal
until an obstacle is sensed whose direction lies between the robot and the goal; then it
follows the obstacle's boundary on one side (the side the goal lies on, or a side drawn
from the seeded RNG when the goal is dead ahead behind it) until the goal is clear again.
Three things break the deadlocks and dithering that crowds produce:

* the side is kept while the obstacle stays in sight, so a robot does not dither between
  left and right in front of another robot;
* the obstacle's direction is smoothed over a few calls in the world frame: the 8 rays
  leave gaps, and the raw direction jumping between them would make a robot wedged among
  others swing back and forth on the spot;
* a robot that has barely moved for ``stuck_time`` seconds while trying to reach a goal
  escapes: it heads off in a random direction (seeded RNG) for ``escape_time`` seconds,
  then draws a new side and tries again. Two robots blocking each other thus separate
  after a few seconds instead of pushing forever;
* a robot whose last ``push_after`` escapes all began within a body radius of each other
  is wedged among bodies with no gap its avoidance will take (in a large swarm, the
  crowd pressed it between robots parked against the wall): its next escapes push,
  straight for the goal and blind to the sensors, until it has moved a body radius.
  Bodies give way to a push, and a crowd never keeps a robot this still for this long
  otherwise.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.numeric import wrap_angle
from bestofn_swarm.wire.rng import Stream

# e-puck sensors ps0..ps7 in the robot's frame (radians, 0 = ahead, counter-clockwise
# positive). Mirrors world_server.core.physics.EPUCK_PROX_ANGLES, which robot_agent must not
# import; a test checks that the two agree.
EPUCK_PROX_ANGLES: tuple[float, ...] = (-0.30, -0.80, -1.57, -2.64, 2.64, 1.57, 0.80, 0.30)
# Radians: a goal this close to the obstacle's direction lies behind it, and the side to go
# round is drawn; farther off, the goal's side is taken.
TOSS_UP_ANGLE = 0.15
# Radians: the extra turn away from (or, negative, towards) a boundary being followed is
# clamped to this range.
MIN_CLEARANCE_TURN = -math.pi / 4
MAX_CLEARANCE_TURN = math.pi / 2


@dataclass(frozen=True)
class NavParams:
    """Body geometry, sensor layout and gains of the navigator (SI units, radians)."""

    # The body: no defaults, a robot's own (the world's WorldInfo, or a port's hardware).
    max_speed: float  # wheel speed limit, m/s
    wheel_base: float  # distance between the wheels, m
    robot_radius: float  # body radius, m
    prox_angles: tuple[float, ...] = EPUCK_PROX_ANGLES  # sensor directions, robot frame
    control_period: float = 0.1  # nominal seconds between calls; caps steps so none overshoots
    turn_gain: float = 4.0  # rad/s of turning per radian of heading error
    min_turn_rate: float = 0.4  # rad/s floor when turning on the spot, so turns finish
    slow_radius: float = 0.08  # m: full speed beyond this distance to the goal, slower inside
    min_speed: float = 0.015  # m/s floor of the forward speed while approaching a goal
    detect_level: float = 0.05  # a reading above this is an obstacle to avoid (~5.7 cm gap)
    clearance_level: float = 0.35  # reading kept while following a boundary (~3.9 cm gap)
    clearance_gain: float = 1.6  # rad of extra turn away per unit of reading above clearance
    front_half_angle: float = 0.9  # rad: sensors within this of ahead slow the robot down
    forget_steps: int = 15  # calls without an obstacle before the avoid side is forgotten
    obstacle_memory: float = 0.6  # weight of the past in the smoothed obstacle direction
    stuck_time: float = 3.0  # s of trying with less than stuck_distance of progress -> escape
    stuck_distance: float = 0.02  # m
    escape_time: float = 1.5  # s spent heading in a random direction to get unstuck
    push_after: int = 3  # escapes begun within robot_radius of each other -> push instead

    def __post_init__(self) -> None:
        positive = {
            "max_speed": self.max_speed,
            "wheel_base": self.wheel_base,
            "robot_radius": self.robot_radius,
            "control_period": self.control_period,
            "turn_gain": self.turn_gain,
            "slow_radius": self.slow_radius,
            "clearance_gain": self.clearance_gain,
            "front_half_angle": self.front_half_angle,
            "stuck_time": self.stuck_time,
            "stuck_distance": self.stuck_distance,
            "escape_time": self.escape_time,
        }
        for name, value in positive.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"NavParams.{name} must be a positive number, got {value!r}")
        if not 0.0 <= self.min_turn_rate <= 2 * self.max_speed / self.wheel_base:
            raise ValueError(
                f"NavParams.min_turn_rate must be in [0, {2 * self.max_speed / self.wheel_base}]"
                f" rad/s (turning on the spot at full wheel speed), got {self.min_turn_rate!r}"
            )
        if not 0.0 <= self.min_speed <= self.max_speed:
            raise ValueError(
                f"NavParams.min_speed must be in [0, max_speed], got {self.min_speed!r}"
            )
        for name, level in (
            ("detect_level", self.detect_level),
            ("clearance_level", self.clearance_level),
        ):
            if not 0.0 <= level < 1.0:
                raise ValueError(f"NavParams.{name} must be in [0, 1), got {level!r}")
        if not 0.0 <= self.obstacle_memory < 1.0:
            raise ValueError(
                f"NavParams.obstacle_memory must be in [0, 1), got {self.obstacle_memory!r}"
            )
        if not self.prox_angles or not all(math.isfinite(a) for a in self.prox_angles):
            raise ValueError(f"NavParams.prox_angles must be finite angles, got {self.prox_angles}")
        if self.push_after < 1:
            raise ValueError(f"NavParams.push_after must be at least 1, got {self.push_after}")
        if self.forget_steps < 1:
            raise ValueError(f"NavParams.forget_steps must be at least 1, got {self.forget_steps}")

    @property
    def max_turn_rate(self) -> float:
        """Turning on the spot with both wheels at full speed, rad/s."""
        return 2.0 * self.max_speed / self.wheel_base


class Navigator:
    """Stateful go-to-goal steering; call one method once per control period."""

    def __init__(self, params: NavParams, rng: Stream) -> None:
        self.params = params
        self._rng = rng
        directions = [numeric.sincos(angle) for angle in params.prox_angles]
        self._cos = [cos for _, cos in directions]
        self._sin = [sin for sin, _ in directions]
        self._sensors = len(params.prox_angles)
        # The sensors that look ahead: they slow the robot down.
        self._front = [
            index
            for index, angle in enumerate(params.prox_angles)
            if abs(wrap_angle(angle)) <= params.front_half_angle
        ]
        self._stuck_window = max(2, round(params.stuck_time / params.control_period))
        self._escape_steps_total = max(1, round(params.escape_time / params.control_period))
        self._goal: tuple[float, float] | None = None
        self._trail: deque[tuple[float, float]] = deque(maxlen=self._stuck_window + 1)
        self._avoid_side = 0  # +1: keep the obstacle on the right (turn left), -1: mirrored
        self._obstacle = (0.0, 0.0)  # smoothed obstacle vector, world frame
        self._steps_clear = 0
        self._escape_steps = 0
        self._escape_heading = 0.0
        # Where the current run of escapes began, how many began near there since, and
        # whether the escape under way is a push.
        self._escape_origin: tuple[float, float] | None = None
        self._fruitless_escapes = 0
        self._pushing = False
        self.escapes = 0  # how many times it had to escape (for tests and diagnostics)
        self.pushes = 0  # how many of them were pushes

    def reset(self) -> None:
        """Forget progress and avoidance state (call when a new leg of travel starts)."""
        self._goal = None
        self._trail.clear()
        self._avoid_side = 0
        self._obstacle = (0.0, 0.0)
        self._steps_clear = 0
        self._escape_steps = 0
        self._escape_origin = None
        self._fruitless_escapes = 0
        self._pushing = False

    def drive_to(  # noqa: PLR0917 -- pose, sensors, goal: the ports' shared signature
        self,
        x: float,
        y: float,
        theta: float,
        proximity: Sequence[float],
        goal: tuple[float, float],
        tolerance: float,
    ) -> tuple[float, float, bool]:
        """Wheel speeds (left, right) in m/s towards ``goal``, and whether it is reached.

        Arrival means being within ``tolerance`` metres of the goal; the wheels are then
        zero. A goal that is occupied by another body is never reached: the caller decides
        when close is close enough.
        """
        if len(proximity) != self._sensors:
            self._check_proximity(proximity)
        if not tolerance > 0:
            raise ValueError(f"tolerance must be positive, got {tolerance!r}")
        params = self.params
        goal = (float(goal[0]), float(goal[1]))
        if goal != self._goal:
            self.reset()
            self._goal = goal
        dx, dy = goal[0] - x, goal[1] - y
        distance = math.sqrt(dx * dx + dy * dy)  # numeric.hypot, written out
        if distance <= tolerance:
            self._trail.clear()
            self._escape_steps = 0
            return 0.0, 0.0, True

        if self._escape_steps > 0:
            self._escape_steps -= 1
            bearing = wrap_angle(self._escape_heading - theta)
        else:
            self._pushing = False
            bearing = wrap_angle(numeric.atan2(dy, dx) - theta)
            if self._is_stuck(x, y):
                self._start_escape(x, y, theta, numeric.atan2(dy, dx))
                bearing = wrap_angle(self._escape_heading - theta)
        self._trail.append((x, y))

        # A push goes through whatever is in the way.
        heading_error = bearing if self._pushing else self._steer(bearing, proximity, theta)
        # The min() and max() of these lines are written as comparisons: the same values
        # (Python's min and max keep the first of equals), without a call each.
        ratio = distance / params.slow_radius
        cap = params.max_speed * (ratio if ratio < 1.0 else 1.0)
        cap = params.min_speed if params.min_speed > cap else cap
        reach = distance / params.control_period
        cap = reach if reach < cap else cap
        # No forward speed while facing more than a right angle away (the cosine is then
        # negative, so this skips only the work, not a value).
        facing = numeric.cos(heading_error) if -1.58 < heading_error < 1.58 else 0.0
        forward = cap * (facing if facing > 0.0 else 0.0)
        if not self._pushing:
            forward *= 1.0 - self._front_reading(proximity)
        left, right = self._wheels(forward, self._turn_rate(heading_error))
        return left, right, False

    def turn_to(
        self, theta: float, heading: float, tolerance: float = 0.05
    ) -> tuple[float, float, bool]:
        """Wheel speeds that turn on the spot towards ``heading``, and whether it is faced."""
        if not tolerance > 0:
            raise ValueError(f"tolerance must be positive, got {tolerance!r}")
        error = wrap_angle(heading - theta)
        if abs(error) <= tolerance:
            return 0.0, 0.0, True
        left, right = self._wheels(0.0, self._turn_rate(error))
        return left, right, False

    # --- steering ------------------------------------------------------------------

    def _steer(self, bearing: float, proximity: Sequence[float], theta: float) -> float:
        """The heading error (robot frame) to steer by: the goal, or along an obstacle."""
        nearest = max(proximity)
        if nearest <= self.params.detect_level:
            self._obstacle = (0.0, 0.0)
            self._steps_clear += 1
            if self._steps_clear >= self.params.forget_steps:
                self._avoid_side = 0
            return bearing
        self._steps_clear = 0
        # Where the obstacles are, in the world frame, averaged over the last few calls: the
        # 8 rays leave gaps, so as the robot turns the raw direction jumps from ray to ray
        # and would make it swing back and forth on the spot.
        # Summed one by one, in sensor order: Python's sum() of floats rounds otherwise
        # since 3.12, and a port adds in this order too.
        ahead = left = 0.0
        for reading, cos, sin in zip(proximity, self._cos, self._sin, strict=True):
            ahead += reading * cos
            left += reading * sin
        sin_theta, cos_theta = numeric.sincos(theta)
        memory = self.params.obstacle_memory
        self._obstacle = (
            memory * self._obstacle[0] + (1 - memory) * (ahead * cos_theta - left * sin_theta),
            memory * self._obstacle[1] + (1 - memory) * (ahead * sin_theta + left * cos_theta),
        )
        if self._obstacle == (0.0, 0.0):
            return bearing
        obstacle = wrap_angle(numeric.atan2(self._obstacle[1], self._obstacle[0]) - theta)
        goal_vs_obstacle = wrap_angle(bearing - obstacle)
        if abs(goal_vs_obstacle) >= math.pi / 2:
            return bearing  # the goal lies away from the obstacle: nothing in the way
        if self._avoid_side == 0:
            # Go round on the goal's side; a goal straight behind the obstacle is a toss-up.
            if abs(goal_vs_obstacle) > TOSS_UP_ANGLE:
                self._avoid_side = 1 if goal_vs_obstacle > 0 else -1
            else:
                self._avoid_side = self._rng.choice((-1, 1))
        push = self.params.clearance_gain * (nearest - self.params.clearance_level)
        push = min(max(push, MIN_CLEARANCE_TURN), MAX_CLEARANCE_TURN)
        return wrap_angle(obstacle + self._avoid_side * (math.pi / 2 + push))

    def _front_reading(self, proximity: Sequence[float]) -> float:
        nearest = 0.0  # max(front readings, default=0.0), as comparisons
        first = True
        for index in self._front:
            reading = proximity[index]
            if first or reading > nearest:
                nearest, first = reading, False
        return nearest

    def _turn_rate(self, error: float) -> float:
        params = self.params
        size = abs(error)
        rate = params.turn_gain * size
        rate = params.min_turn_rate if params.min_turn_rate > rate else rate
        settle = size / params.control_period  # min(rate, settle, max_turn_rate)
        rate = settle if settle < rate else rate
        rate = params.max_turn_rate if params.max_turn_rate < rate else rate
        return math.copysign(rate, error)

    def _wheels(self, forward: float, turn_rate: float) -> tuple[float, float]:
        """Wheel speeds for a forward speed and a turn rate; turning wins at the limit."""
        limit = self.params.max_speed
        spin = turn_rate * self.params.wheel_base / 2.0
        spin = -limit if -limit > spin else spin
        spin = limit if limit < spin else spin
        forward = 0.0 if forward < 0.0 else forward
        room = limit - abs(spin)
        forward = room if room < forward else forward
        return forward - spin, forward + spin

    # --- getting unstuck -----------------------------------------------------------

    def _is_stuck(self, x: float, y: float) -> bool:
        if len(self._trail) < self._stuck_window:
            return False
        old_x, old_y = self._trail[0]
        return numeric.hypot(x - old_x, y - old_y) < self.params.stuck_distance

    def _start_escape(self, x: float, y: float, theta: float, goal_heading: float) -> None:
        origin = self._escape_origin
        if origin is not None and numeric.hypot(x - origin[0], y - origin[1]) < (
            self.params.robot_radius
        ):
            self._fruitless_escapes += 1
        else:
            self._escape_origin = (x, y)
            self._fruitless_escapes = 0
        self._pushing = self._fruitless_escapes >= self.params.push_after
        if self._pushing:
            self._escape_heading = goal_heading
            self.pushes += 1
        else:
            turn = self._rng.uniform(math.pi / 2, math.pi) * self._rng.choice((-1, 1))
            self._escape_heading = wrap_angle(theta + turn)
            self._avoid_side = self._rng.choice((-1, 1))
        self._escape_steps = self._escape_steps_total
        self._trail.clear()
        self.escapes += 1

    def _check_proximity(self, proximity: Sequence[float]) -> None:
        if len(proximity) != len(self.params.prox_angles):
            raise ValueError(
                f"expected {len(self.params.prox_angles)} proximity readings, got {len(proximity)}"
            )
