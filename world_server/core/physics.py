"""The world's bodies: e-puck robots driven as differential drives in a walled disc.

pymunk (Chipmunk 2) resolves robot-robot and robot-wall contacts; the robots' wheel
speeds are reached through forces: at every substep each body gets the force that brings
its velocity to its wheels' velocity, so the contact solver can still push a robot aside
(``Physics.step`` says why not a velocity written straight onto the body). The 8 infrared
proximity rays are computed analytically (robots are discs and the wall is a circle),
which costs far less than 8 pymunk ray queries per robot; ``proximity_raycast``
does the same with pymunk's segment queries and serves as the reference the tests
compare against.

Determinism: bodies are added in call order and pymunk iterates them in that order; every
public result is keyed or sorted by robot id. The same calls in the same order give
bit-identical poses on any x86-64 CPU with the same pymunk build: every sine and cosine
here comes from the portable kernel (``bestofn_swarm.wire.numeric``), every sum is written out in a
fixed order, and inside Chipmunk a body's angle reaches nothing but the rotation of its
shapes' offsets, which are zero for these centred discs (so libm's CPU-dependent cos and
sin, which Chipmunk calls, cannot move a robot). No clock and no randomness here.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Sequence
from typing import Final

import numpy as np
import pymunk
from pymunk import batch

from bestofn_swarm.wire import numeric
from world_server.core.body import EPUCK, EpuckSpec

ROBOT_MASS = 0.15  # kg, about an e-puck
COLLISION_SLOP = 0.001  # metres of allowed overlap; pymunk's default (0.1) is for pixels
WALL_THICKNESS = 0.02  # metres: the segments' radius, thick enough that nothing tunnels
WALL_SAG = 0.0002  # metres the polygonal wall may bulge beyond the ideal circle
MIN_WALL_SEGMENTS = 64
# Contacts are found only once bodies overlap, so a body can sink up to speed * substep
# into whatever it meets before the solver pushes back: 2.6 mm into a wall at 0.13 m/s,
# 5.2 mm between two robots meeting head-on. Shorter substeps cost time linearly.
MAX_SUBSTEP = 0.02  # seconds
# A body's angle accumulates its turns; past this many radians it is wrapped back into
# [-pi, pi], which keeps it inside the portable kernel's range and its precision high.
ANGLE_BOUND = 64 * math.pi

# Row layouts of pymunk's batch buffers: x, y, angle, vx, vy, omega / fx, fy, torque.
_STATE_FIELDS = (
    batch.BodyFields.POSITION
    | batch.BodyFields.ANGLE
    | batch.BodyFields.VELOCITY
    | batch.BodyFields.ANGULAR_VELOCITY
)
_FORCE_FIELDS = batch.BodyFields.FORCE | batch.BodyFields.TORQUE
STATE_ROW: Final = 6  # numbers per body in a state buffer
FORCE_ROW: Final = 3  # and in a force buffer
# The swarm size from which a substep's forces and the proximity readings are worked out
# with numpy for every robot at once; below, robot by robot, where numpy's cost per call
# outweighs its work (measured: robot by robot costs less at 100 robots, more at 200).
# Either way the same operations in the same order: the same bits (tests/test_physics.py
# compares the two).
VECTOR_FROM: Final = 128


def wall_segment_count(arena_radius: float, sag: float = WALL_SAG) -> int:
    """Segments for a polygon whose bulge beyond the circle stays under ``sag`` metres.

    A chord spanning angle 2*pi/n sags by about R * (pi/n)^2 / 2 from its arc.
    """
    return max(MIN_WALL_SEGMENTS, math.ceil(math.pi / math.sqrt(2.0 * sag / arena_radius)))


def wrap_angle(angle: float) -> float:
    """``angle`` in [-pi, pi] (a helper for callers and tests)."""
    return numeric.wrap_angle(angle)


class Physics:
    """A disc arena of e-pucks; see the module docstring for the model."""

    def __init__(
        self,
        arena_radius: float,
        spec: EpuckSpec = EPUCK,  # frozen, so one shared default is safe
        substeps: int = 2,
        *,
        max_substep: float | None = MAX_SUBSTEP,
        wall_segments: int | None = None,
        spatial_hash: bool = True,
    ) -> None:
        """A walled disc of ``arena_radius`` metres, centred on the origin, with no robots.

        ``step(dt)`` splits ``dt`` into ``substeps`` pymunk steps, or more if a step would
        last longer than ``max_substep`` seconds (None: exactly ``substeps``).
        ``spatial_hash`` picks pymunk's spatial hash over its default bounding-box tree.
        """
        if not arena_radius > 2 * spec.radius:
            raise ValueError(f"arena radius {arena_radius!r} cannot hold a robot")
        if substeps < 1:
            raise ValueError(f"substeps must be at least 1, got {substeps}")
        if max_substep is not None and not max_substep > 0:
            raise ValueError(f"max_substep must be positive, got {max_substep!r}")
        if len(spec.prox_angles) != 8:
            raise ValueError(f"an e-puck has 8 proximity sensors, got {len(spec.prox_angles)}")
        self.arena_radius = float(arena_radius)
        self.spec = spec
        self.substeps = substeps
        self.max_substep = max_substep
        self.space = pymunk.Space()
        self.space.collision_slop = COLLISION_SLOP
        if spatial_hash:
            # Cells of about a robot's diameter; the count is a hash-table size hint.
            self.space.use_spatial_hash(2.0 * spec.radius, 4096)
        self._add_wall(wall_segments or wall_segment_count(arena_radius))

        directions = [numeric.sincos(angle) for angle in spec.prox_angles]
        self._sensor_sin = [sin for sin, _ in directions]
        self._sensor_cos = [cos for _, cos in directions]
        self._mass = ROBOT_MASS
        self._moment = float(pymunk.moment_for_circle(ROBOT_MASS, 0.0, spec.radius))
        self._ids: list[int] = []  # robot ids in insertion order == pymunk's body order
        self._index: dict[int, int] = {}
        self._bodies: list[pymunk.Body] = []
        self._left: list[float] = []
        self._right: list[float] = []
        self._sorted_ids: list[int] = []
        # What pymunk's batch API lists, STATE_ROW numbers a body: x, y, angle (unwrapped),
        # vx, vy, omega; the robots first, in insertion order, then the static wall body.
        # Read as a flat list, or for a large swarm as an array of the robots' rows; the
        # other form is made from it when asked for (``_state_rows``, ``_state_array``).
        self._rows: list[float] | None = []
        self._state: np.ndarray | None = None
        self._body_rows = 0
        # Made at most once per step, and cleared by it: every robot's proximity readings,
        # poses, senses and the sine and cosine of its heading.
        self._prox: list[list[float]] | None = None
        self._poses: list[tuple[float, float, float]] | None = None
        self._readings: list[list[float]] | None = None
        self._directions: tuple[list[float], list[float]] | None = None
        self._direction_arrays: tuple[np.ndarray, np.ndarray] | None = None  # the same
        # Per robot, the last angle whose sine and cosine were taken, and them (as lists,
        # and as arrays for the numpy forms).
        self._direction_angle: list[float] = []
        self._direction_sin: list[float] = []
        self._direction_cos: list[float] = []
        self._direction_angle_array = np.zeros(0)
        self._direction_sin_array = np.zeros(0)
        self._direction_cos_array = np.zeros(0)
        self._read_buffer = batch.Buffer()
        self._write_buffer = batch.Buffer()

    # --- set-up ---------------------------------------------------------------------

    def _add_wall(self, segments: int) -> None:
        # Vertices sit far enough out that each chord's inner face touches the circle.
        vertex_radius = (self.arena_radius + WALL_THICKNESS) / numeric.cos(math.pi / segments)
        corners = []
        for k in range(segments):
            sin, cos = numeric.sincos(2 * math.pi * k / segments)
            corners.append((vertex_radius * cos, vertex_radius * sin))
        wall = []
        for k in range(segments):
            segment = pymunk.Segment(
                self.space.static_body, corners[k], corners[(k + 1) % segments], WALL_THICKNESS
            )
            segment.friction = 0.0
            segment.elasticity = 0.0
            wall.append(segment)
        self.space.add(*wall)
        self.wall_segments = segments

    def add_robot(self, robot_id: int, x: float, y: float, theta: float) -> None:
        """Place a stopped robot; it must lie inside the arena (it may touch others)."""
        if robot_id in self._index:
            raise ValueError(f"robot {robot_id} already exists")
        if robot_id < 0:
            raise ValueError(f"robot ids are >= 0, got {robot_id}")
        if not all(math.isfinite(value) for value in (x, y, theta)):
            raise ValueError(f"robot {robot_id}: pose must be finite, got {(x, y, theta)!r}")
        if numeric.hypot(x, y) > self.arena_radius - self.spec.radius:
            raise ValueError(f"robot {robot_id} at ({x}, {y}) does not fit inside the arena")
        radius = self.spec.radius
        body = pymunk.Body(ROBOT_MASS, self._moment)
        body.position = (x, y)
        body.angle = theta
        shape = pymunk.Circle(body, radius)
        shape.friction = 0.0  # a push slides a robot; it does not spin it
        shape.elasticity = 0.0
        # Same non-zero group as its own filter, so raycasts skip the robot's own body.
        shape.filter = pymunk.ShapeFilter(group=robot_id + 1)
        self.space.add(body, shape)
        self._index[robot_id] = len(self._ids)
        self._ids.append(robot_id)
        self._bodies.append(body)
        self._sorted_ids = sorted(self._ids)
        self._left.append(0.0)
        self._right.append(0.0)
        self._direction_angle.append(math.nan)  # no angle's sine taken yet
        self._direction_sin.append(0.0)
        self._direction_cos.append(0.0)
        self._direction_angle_array = np.append(self._direction_angle_array, math.nan)
        self._direction_sin_array = np.append(self._direction_sin_array, 0.0)
        self._direction_cos_array = np.append(self._direction_cos_array, 0.0)
        self._read_state()
        row = STATE_ROW * (len(self._ids) - 1)
        if self._state_rows()[row : row + 3] != [x, y, theta]:
            # pymunk's batch API must list robots first, in insertion order; refuse if not.
            raise RuntimeError("pymunk body order differs from insertion order")

    # --- queries --------------------------------------------------------------------

    def has_robot(self, robot_id: int) -> bool:
        return robot_id in self._index

    def robot_ids(self) -> list[int]:
        return list(self._sorted_ids)

    def pose(self, robot_id: int) -> tuple[float, float, float]:
        """x, y (metres) and heading theta in [-pi, pi] (radians, counter-clockwise from +x)."""
        return self._pose_list()[self._index[robot_id]]

    def poses(self) -> dict[int, tuple[float, float, float]]:
        poses = self._pose_list()
        return {robot_id: poses[self._index[robot_id]] for robot_id in self._sorted_ids}

    def _pose_list(self) -> list[tuple[float, float, float]]:
        # Wrapped once per step for all robots, so pose(), poses() and readings() agree.
        poses = self._poses
        if poses is None:
            rows = self._state_rows()
            wrap = numeric.wrap_angle
            poses = [
                (rows[row], rows[row + 1], wrap(rows[row + 2]))
                for row in range(0, STATE_ROW * len(self._ids), STATE_ROW)
            ]
            self._poses = poses
        return poses

    def _heading_directions(self) -> tuple[list[float], list[float]]:
        """Sine and cosine of every robot's angle, in insertion order (once per state).
        A robot standing still (waiting, sensing, parked) keeps its angle, and with it
        the sine and cosine it had: the kernel's sine is a large part of a small swarm's
        physics."""
        directions = self._directions
        if directions is None:
            rows = self._state_rows()
            angles, sines, cosines = self._direction_angle, self._direction_sin, self._direction_cos
            for index in range(len(self._ids)):
                angle = rows[STATE_ROW * index + 2]
                if angle != angles[index]:
                    sines[index], cosines[index] = numeric.sincos(angle)
                    angles[index] = angle
            directions = (sines, cosines)
            self._directions = directions
        return directions

    def _heading_direction_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``_heading_directions`` as arrays, for the numpy forms (the same values)."""
        directions = self._direction_arrays
        if directions is None:
            angle = self._state_array()[:, 2]
            changed = np.flatnonzero(angle != self._direction_angle_array)
            if changed.size:
                sin, cos = numeric.sincos_array(angle[changed])
                self._direction_sin_array[changed] = sin
                self._direction_cos_array[changed] = cos
                self._direction_angle_array[changed] = angle[changed]
            directions = (self._direction_sin_array, self._direction_cos_array)
            self._direction_arrays = directions
        return directions

    def _state_rows(self) -> list[float]:
        """The state as a flat list (STATE_ROW numbers a robot), made once per state."""
        rows = self._rows
        if rows is None:
            assert self._state is not None  # one of the two forms is always there
            rows = self._state.ravel().tolist()
            self._rows = rows
        return rows

    def _state_array(self) -> np.ndarray:
        """The robots' state as an array (a row of STATE_ROW each), made once per state."""
        state = self._state
        if state is None:
            robots = len(self._ids)
            state = np.array(self._state_rows()[: STATE_ROW * robots]).reshape(robots, STATE_ROW)
            self._state = state
        return state

    def readings(self, robot_ids: list[int]) -> list[list[float]]:
        """One row per robot of ``robot_ids``: its x, y, heading (as ``pose``) and its 8
        proximity readings (as ``proximity``), made for every robot at once."""
        readings = self._readings
        if readings is None:
            proximity = self._proximity_rows()
            readings = [[*pose, *proximity[index]] for index, pose in enumerate(self._pose_list())]
            self._readings = readings
        index = self._index
        return [readings[index[robot]] for robot in robot_ids]

    def wheels(self, robot_id: int) -> tuple[float, float]:
        """The wheel speeds in force (after clamping)."""
        index = self._index[robot_id]
        return self._left[index], self._right[index]

    # --- driving --------------------------------------------------------------------

    def set_wheels(self, robot_id: int, left: float, right: float) -> None:
        """Wheel speeds in m/s, clamped to the e-puck's maximum; they hold until changed."""
        self.set_all_wheels([robot_id], [left], [right])

    def set_all_wheels(
        self, robot_ids: Sequence[int], left: Sequence[float], right: Sequence[float]
    ) -> None:
        """Wheel speeds in m/s for many robots at once, each clamped to the e-puck's
        maximum; they hold until changed. ValueError (nothing set) if any is not finite."""
        if len(left) != len(robot_ids) or len(right) != len(robot_ids):
            raise ValueError("one left and one right wheel speed per robot")
        for robot, wheel_left, wheel_right in zip(robot_ids, left, right, strict=True):
            if not (math.isfinite(wheel_left) and math.isfinite(wheel_right)):
                raise ValueError(f"robot {robot}: wheel speeds must be finite")
        limit = self.spec.max_wheel_speed
        for robot, wheel_left, wheel_right in zip(robot_ids, left, right, strict=True):
            index = self._index[robot]
            self._left[index] = _clamp(float(wheel_left), limit)
            self._right[index] = _clamp(float(wheel_right), limit)

    def substeps_for(self, dt: float) -> int:
        """How many pymunk steps ``step(dt)`` takes."""
        if self.max_substep is None:
            return self.substeps
        return max(self.substeps, math.ceil(dt / self.max_substep - 1e-9))

    def step(self, dt: float) -> None:
        """Advance ``dt`` seconds in ``substeps_for(dt)`` equal pymunk steps.

        Chipmunk moves bodies at the start of a step and solves contacts at its end, so a
        velocity written straight onto a body would carry it into a wall before any
        contact could stop it (about 25 mm deep at 0.13 m/s). Instead each substep sets
        the force that makes the velocity update reach the wheel velocity exactly; the
        contact solver then corrects that velocity before it moves anything. The price is
        that a new wheel command starts moving the body one substep later.
        """
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt!r}")
        robots = len(self._ids)
        if not robots:
            return
        substeps = self.substeps_for(dt)
        substep = dt / substeps
        if robots >= VECTOR_FROM:
            self._step_vectorised(substeps, substep)
        else:
            self._step_robot_by_robot(substeps, substep)
        self._wrap_angles()

    def _step_robot_by_robot(self, substeps: int, substep: float) -> None:
        robots = len(self._ids)
        wheel_base = self.spec.wheel_base
        speeds = [0.5 * (left + right) for left, right in zip(self._left, self._right, strict=True)]
        turn_rates = [
            (right - left) / wheel_base for left, right in zip(self._left, self._right, strict=True)
        ]
        # A velocity change per second times mass (or moment of inertia) is a force.
        push = self._mass / substep
        twist = self._moment / substep
        # One row per body pymunk lists; rows past the robots (the static wall body) stay 0.
        padding = [0.0] * (FORCE_ROW * (self._body_rows - robots))
        for _ in range(substeps):
            # The heading changes every substep, so the target velocity follows it.
            sines, cosines = self._heading_directions()
            rows = self._state_rows()
            forces: list[float] = []
            for index in range(robots):
                row = STATE_ROW * index
                speed = speeds[index]
                forces.append((speed * cosines[index] - rows[row + 3]) * push)
                forces.append((speed * sines[index] - rows[row + 4]) * push)
                forces.append((turn_rates[index] - rows[row + 5]) * twist)
            forces.extend(padding)
            self._write_buffer.set_float_buf(array("d", forces))
            batch.set_space_bodies(self.space, _FORCE_FIELDS, self._write_buffer)
            self.space.step(substep)
            self._read_state()

    def _step_vectorised(self, substeps: int, substep: float) -> None:
        """``_step_robot_by_robot`` with numpy over every robot at once: the same
        operations, element by element."""
        robots = len(self._ids)
        left, right = np.array(self._left), np.array(self._right)
        speed = 0.5 * (left + right)
        turn_rate = (right - left) / self.spec.wheel_base
        inertia = np.array([self._mass, self._mass, self._moment])
        forces = np.zeros((self._body_rows, FORCE_ROW))
        for _ in range(substeps):
            sin, cos = self._heading_direction_arrays()
            state = self._state_array()
            forces[:robots, 0] = speed * cos - state[:, 3]
            forces[:robots, 1] = speed * sin - state[:, 4]
            forces[:robots, 2] = turn_rate - state[:, 5]
            forces[:robots] *= inertia / substep
            self._write_buffer.set_float_buf(forces.reshape(-1))
            batch.set_space_bodies(self.space, _FORCE_FIELDS, self._write_buffer)
            self.space.step(substep)
            self._read_state(vectorised=True)

    def _read_state(self, *, vectorised: bool = False) -> None:
        self._read_buffer.clear()
        batch.get_space_bodies(self.space, _STATE_FIELDS, self._read_buffer)
        buffer = self._read_buffer.float_buf()
        # pymunk lists the dynamic bodies (the robots, in insertion order) before the
        # static body that holds the wall.
        self._body_rows = len(buffer) // (8 * STATE_ROW)
        if vectorised:
            rows = np.frombuffer(buffer, dtype=np.float64).reshape(-1, STATE_ROW)
            self._state = rows[: len(self._ids)].copy()
            self._rows = None
        else:
            state = array("d")
            state.frombytes(buffer)
            self._rows = state.tolist()
            self._state = None
        self._direction_arrays = None
        self._prox = None
        self._poses = None
        self._readings = None
        self._directions = None

    def _wrap_angles(self) -> None:
        """Wraps every angle past ``ANGLE_BOUND`` into [-pi, pi], in pymunk and here (a
        step turns a robot by well under a radian, so checking after each is enough)."""
        state = self._state
        if state is not None and np.abs(state[:, 2]).max() <= ANGLE_BOUND:
            return  # a large swarm's state is an array: looked at all at once
        rows = self._state_rows()
        for index in range(len(self._ids)):
            row = STATE_ROW * index + 2
            angle = rows[row]
            if not -ANGLE_BOUND <= angle <= ANGLE_BOUND:
                wrapped = numeric.wrap_angle(angle)
                self._bodies[index].angle = wrapped
                rows[row] = wrapped
                if self._state is not None:
                    self._state[index, 2] = wrapped
                self._poses = None
                self._readings = None
                self._directions = None
                self._direction_arrays = None
                self._prox = None

    # --- proximity ------------------------------------------------------------------

    def proximity(self, robot_id: int) -> tuple[float, ...]:
        """8 readings in [0, 1], e-puck order: 0 = nothing in range, 1 = touching.

        A reading falls linearly with the gap between the body's surface and the nearest
        wall or robot along the ray: 1 - gap / prox_range.
        """
        return tuple(self._proximity_rows()[self._index[robot_id]])

    def proximity_all(self) -> dict[int, tuple[float, ...]]:
        rows = self._proximity_rows()
        return {robot_id: tuple(rows[self._index[robot_id]]) for robot_id in self._sorted_ids}

    def _proximity_rows(self) -> list[list[float]]:
        """Every robot's 8 readings, in insertion order (once per state)."""
        proximity = self._prox
        if proximity is None:
            if len(self._ids) >= VECTOR_FROM:
                proximity = self._compute_proximity_vectorised().tolist()
            else:
                proximity = self._compute_proximity()
            self._prox = proximity
        return proximity

    def _compute_proximity(self) -> list[list[float]]:
        """The analytic ray casts, robot by robot: the wall first, then every robot within
        reach of a sensor (found on a grid of cells as wide as that reach)."""
        radius = self.spec.radius
        reach = self.spec.prox_range
        inside_reach = radius + reach
        radius_squared = radius * radius
        wall_squared = self.arena_radius * self.arena_radius
        robots = len(self._ids)
        rows = self._state_rows()
        sines, cosines = self._heading_directions()
        sensor_sines, sensor_cosines = self._sensor_sin, self._sensor_cos
        sensors = len(sensor_sines)
        near = self._neighbours(2.0 * radius + reach)
        readings: list[list[float]] = []
        for index in range(robots):
            x, y = rows[STATE_ROW * index], rows[STATE_ROW * index + 1]
            sin, cos = sines[index], cosines[index]
            # Each sensor's direction: the robot's heading turned by the sensor's angle.
            rays_x = [cos * sensor_cosines[k] - sin * sensor_sines[k] for k in range(sensors)]
            rays_y = [sin * sensor_cosines[k] + cos * sensor_sines[k] for k in range(sensors)]
            # Wall: the ray from a centre p inside the circle |q| = R leaves it at distance
            # s = -b + sqrt(b^2 - (|p|^2 - R^2)), with b = p . u.
            inside = wall_squared - (x * x + y * y)
            row: list[float] = []
            for k in range(sensors):
                along = x * rays_x[k] + y * rays_y[k]
                to_wall = -along + math.sqrt(_at_least_zero(along * along + inside))
                reading = 1.0 - (to_wall - radius) / reach
                # Clamped to [0, 1], the larger (then the smaller) bound on a tie.
                reading = reading if reading > 0.0 else 0.0
                row.append(reading if reading < 1.0 else 1.0)
            for other in near[index]:
                offset_x = rows[STATE_ROW * other] - x
                offset_y = rows[STATE_ROW * other + 1] - y
                # The ray meets the other disc where s^2 - 2 b s + |c|^2 - r^2 = 0.
                clearance = (offset_x * offset_x + offset_y * offset_y) - radius_squared
                for k in range(sensors):
                    along = offset_x * rays_x[k] + offset_y * rays_y[k]
                    discriminant = along * along - clearance
                    root = math.sqrt(_at_least_zero(discriminant))
                    # A hit needs a real root, the disc not behind the sensor, and the disc
                    # within reach; a disc already over the sensor reads as touching.
                    if discriminant >= 0.0 and along + root >= radius:
                        first = along - root
                        if first <= inside_reach:
                            gap = (first if first >= radius else radius) - radius
                            row[k] = max(row[k], 1.0 - gap / reach)
            readings.append(row)
        return readings

    def _neighbours(self, cutoff: float) -> list[list[int]]:
        """For each robot (insertion order), the robots closer than ``cutoff``.

        A uniform grid with cells of side ``cutoff``: each body looks only in its own and
        the 8 neighbouring cells, so the cost grows with the bodies, not their square.
        """
        robots = len(self._ids)
        rows = self._state_rows()
        reach = cutoff * cutoff
        # Cells numbered row by row, with a border of empty ones: no neighbour wraps round.
        width = math.ceil(2.0 * self.arena_radius / cutoff) + 3
        cells: dict[int, list[int]] = {}
        keys: list[int] = []
        for index in range(robots):
            column = math.floor((rows[STATE_ROW * index] + self.arena_radius) / cutoff) + 1
            line = math.floor((rows[STATE_ROW * index + 1] + self.arena_radius) / cutoff) + 1
            key = column * width + line
            keys.append(key)
            members = cells.get(key)
            if members is None:
                cells[key] = [index]
            else:
                members.append(index)
        near: list[list[int]] = []
        empty: list[int] = []
        for index in range(robots):
            x, y = rows[STATE_ROW * index], rows[STATE_ROW * index + 1]
            key = keys[index]
            found: list[int] = []
            for offset in (-width - 1, -width, -width + 1, -1, 0, 1, width - 1, width, width + 1):
                for other in cells.get(key + offset, empty):
                    if other != index:
                        dx = rows[STATE_ROW * other] - x
                        dy = rows[STATE_ROW * other + 1] - y
                        if dx * dx + dy * dy < reach:
                            found.append(other)
            near.append(found)
        return near

    def _compute_proximity_vectorised(self) -> np.ndarray:
        """``_compute_proximity`` with numpy over every robot and pair at once: the same
        operations, element by element, and the same largest reading of each ray."""
        radius = self.spec.radius
        reach = self.spec.prox_range
        state = self._state_array()
        centres = state[:, :2]
        sin, cos = self._heading_direction_arrays()
        sin, cos = sin[:, None], cos[:, None]
        sensor_sin, sensor_cos = np.array(self._sensor_sin), np.array(self._sensor_cos)
        ray_x = cos * sensor_cos - sin * sensor_sin  # (robots, 8)
        ray_y = sin * sensor_cos + cos * sensor_sin
        along = centres[:, :1] * ray_x + centres[:, 1:2] * ray_y
        squared = centres[:, 0] * centres[:, 0] + centres[:, 1] * centres[:, 1]
        inside = (self.arena_radius * self.arena_radius - squared)[:, None]
        to_wall = -along + np.sqrt(np.maximum(along * along + inside, 0.0))
        readings: np.ndarray = np.clip(1.0 - (to_wall - radius) / reach, 0.0, 1.0)

        owners, others = self._neighbour_pairs(2.0 * radius + reach)
        if owners.size:
            offset = centres[others] - centres[owners]  # (pairs, 2)
            along = offset[:, :1] * ray_x[owners] + offset[:, 1:2] * ray_y[owners]
            squared = offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1]
            discriminant = along * along - (squared - radius * radius)[:, None]
            root = np.sqrt(np.maximum(discriminant, 0.0))
            near = along - root
            far = along + root
            hit = (discriminant >= 0.0) & (far >= radius) & (near <= radius + reach)
            gap = np.maximum(near, radius) - radius
            pair_readings = np.where(hit, 1.0 - gap / reach, 0.0)
            # owners is sorted, so each robot's pairs form one run: reduce each run by max.
            starts = np.flatnonzero(np.r_[True, owners[1:] != owners[:-1]])
            best = np.maximum.reduceat(pair_readings, starts, axis=0)
            rows = owners[starts]
            readings[rows] = np.maximum(readings[rows], best)
        return readings

    def _neighbour_pairs(self, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
        """``_neighbours`` as ordered pairs (i, j), i != j, i ascending, with numpy: the
        same grid of cells of side ``cutoff``."""
        count = len(self._ids)
        centres = self._state_array()[:, :2]
        cells = np.floor((centres + self.arena_radius) / cutoff).astype(np.int64) + 1
        width = math.ceil(2 * self.arena_radius / cutoff) + 3  # padded: no wrap-around
        keys = cells[:, 0] * width + cells[:, 1]
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        offsets = np.array([dx * width + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
        wanted = (keys[:, None] + offsets).reshape(-1)
        first = np.searchsorted(sorted_keys, wanted, side="left")
        counts = np.searchsorted(sorted_keys, wanted, side="right") - first
        total = int(counts.sum())
        owners = np.repeat(np.repeat(np.arange(count), len(offsets)), counts)
        run_starts = np.repeat(np.cumsum(counts) - counts, counts)
        others = order[np.repeat(first, counts) + np.arange(total) - run_starts]
        offset = centres[others] - centres[owners]
        squared = offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1]
        close = (owners != others) & (squared < cutoff * cutoff)
        return owners[close], others[close]

    def proximity_raycast(self, robot_id: int) -> tuple[float, ...]:
        """The same 8 readings from pymunk segment queries (slow; a reference for tests).

        Differs from ``proximity`` only by the polygonal wall's sag (under ``WALL_SAG``).
        """
        body = self._bodies[self._index[robot_id]]
        row = STATE_ROW * self._index[robot_id]
        rows = self._state_rows()
        x, y, angle = rows[row], rows[row + 1], rows[row + 2]
        radius = self.spec.radius
        reach = self.spec.prox_range
        own = pymunk.ShapeFilter(group=robot_id + 1)
        readings = []
        for sensor_angle in self.spec.prox_angles:
            uy, ux = numeric.sincos(angle + sensor_angle)
            start = (x + radius * ux, y + radius * uy)
            end = (x + (radius + reach) * ux, y + (radius + reach) * uy)
            hit = self.space.segment_query_first(start, end, 0.0, own)
            if hit is None or hit.shape is None or hit.shape.body is body:
                readings.append(0.0)
            else:
                readings.append(1.0 - hit.alpha)
        return tuple(readings)


def _at_least_zero(value: float) -> float:
    """``value``, or 0.0 if it is below (a square root's argument that rounding pushed
    just under zero)."""
    return value if value >= 0.0 else 0.0


def _clamp(speed: float, limit: float) -> float:
    """``speed`` within [-limit, limit]."""
    speed = speed if speed >= -limit else -limit
    return speed if speed <= limit else limit
