"""The world's bodies: e-puck robots driven as differential drives in a walled disc.

pymunk (Chipmunk 2) resolves robot-robot and robot-wall contacts; the robots' wheel
speeds are reached through forces: at every substep each body gets the force that brings
its velocity to its wheels' velocity, so the contact solver can still push a robot aside
(``Physics.step`` says why not a velocity written straight onto the body). The 8 infrared
proximity rays are computed analytically with numpy (robots are discs and the wall is a
circle), which costs far less than 8 pymunk ray queries per robot; ``proximity_raycast``
does the same with pymunk's segment queries and serves as the reference the tests
compare against.

Determinism: bodies are added in call order and pymunk iterates them in that order; every
public result is keyed or sorted by robot id. The same calls in the same order give
bit-identical poses on any x86-64 CPU with the same pymunk build: every sine and cosine
here comes from the portable kernel (``wire.numeric``), every sum is written out in a
fixed order, and inside Chipmunk a body's angle reaches nothing but the rotation of its
shapes' offsets, which are zero for these centred discs (so libm's CPU-dependent cos and
sin, which Chipmunk calls, cannot move a robot). No clock and no randomness here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pymunk
from pymunk import batch

from wire import numeric
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
ALL_PAIRS_UP_TO = 48  # robots: up to here proximity compares every pair, past it a grid

# Row layouts of pymunk's batch buffers: x, y, angle, vx, vy, omega / fx, fy, torque.
_STATE_FIELDS = (
    batch.BodyFields.POSITION
    | batch.BodyFields.ANGLE
    | batch.BodyFields.VELOCITY
    | batch.BodyFields.ANGULAR_VELOCITY
)
_FORCE_FIELDS = batch.BodyFields.FORCE | batch.BodyFields.TORQUE


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
        self._prox_sin = np.array([sin for sin, _ in directions])
        self._prox_cos = np.array([cos for _, cos in directions])
        # Mass, mass, moment of inertia: turns a velocity change per second into a force.
        self._inertia = np.array(
            [ROBOT_MASS, ROBOT_MASS, pymunk.moment_for_circle(ROBOT_MASS, 0.0, spec.radius)]
        )
        self._ids: list[int] = []  # robot ids in insertion order == pymunk's body order
        self._index: dict[int, int] = {}
        self._bodies: list[pymunk.Body] = []
        self._left = np.zeros(0)
        self._right = np.zeros(0)
        self._sorted_ids: list[int] = []
        self._state = np.zeros((0, 3))  # x, y, angle (unwrapped) per robot, insertion order
        self._velocity = np.zeros((0, 3))  # vx, vy, omega per robot, as the solver left them
        self._body_rows = 0  # bodies pymunk's batch API lists: the robots, then static ones
        self._prox: np.ndarray | None = None  # cache of proximity_all, cleared by step()
        self._poses: list[tuple[float, float, float]] | None = None  # likewise, of pose()
        self._readings: np.ndarray | None = None  # likewise, of readings()
        self._directions: tuple[np.ndarray, np.ndarray] | None = None  # sin, cos of angles
        # Per robot, the last angle whose sine and cosine were taken, and them: a robot
        # standing still (waiting, sensing, parked) keeps its angle, and the kernel's sine
        # is the physics' largest cost in a small swarm.
        self._direction_angle = np.zeros(0)
        self._direction_sin = np.zeros(0)
        self._direction_cos = np.zeros(0)
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
        body = pymunk.Body(ROBOT_MASS, float(self._inertia[2]))
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
        self._left = np.append(self._left, 0.0)
        self._right = np.append(self._right, 0.0)
        self._read_state()
        if not np.array_equal(self._state[len(self._ids) - 1], (x, y, theta)):
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
        if self._poses is None:
            state = self._state
            self._poses = list(
                zip(
                    state[:, 0].tolist(),
                    state[:, 1].tolist(),
                    self._headings().tolist(),
                    strict=True,
                )
            )
        return self._poses

    def _headings(self) -> np.ndarray:
        """Every robot's heading in [-pi, pi], in insertion order."""
        return numeric.wrap_angle_array(self._state[:, 2])

    def _heading_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Sine and cosine of every robot's angle, in insertion order (once per state; use
        them before the next step, which updates them in place)."""
        if self._directions is None:
            angle = self._state[:, 2]
            if len(self._direction_angle) != len(angle):
                self._direction_angle = np.full(len(angle), np.nan)
                self._direction_sin = np.zeros(len(angle))
                self._direction_cos = np.zeros(len(angle))
            changed = np.flatnonzero(angle != self._direction_angle)
            if changed.size:
                sin, cos = numeric.sincos_array(angle[changed])
                self._direction_sin[changed] = sin
                self._direction_cos[changed] = cos
                self._direction_angle[changed] = angle[changed]
            self._directions = (self._direction_sin, self._direction_cos)
        return self._directions

    def readings(self, robot_ids: list[int]) -> np.ndarray:
        """One row per robot of ``robot_ids``: its x, y, heading (as ``pose``) and its 8
        proximity readings (as ``proximity``), made for every robot at once."""
        if self._readings is None:
            state = self._state
            self._readings = np.column_stack(
                (state[:, 0], state[:, 1], self._headings(), self._proximity_array())
            )
        index = self._index
        return self._readings[[index[robot] for robot in robot_ids]]

    def wheels(self, robot_id: int) -> tuple[float, float]:
        """The wheel speeds in force (after clamping)."""
        index = self._index[robot_id]
        return float(self._left[index]), float(self._right[index])

    # --- driving --------------------------------------------------------------------

    def set_wheels(self, robot_id: int, left: float, right: float) -> None:
        """Wheel speeds in m/s, clamped to the e-puck's maximum; they hold until changed."""
        if not (math.isfinite(left) and math.isfinite(right)):
            raise ValueError(f"robot {robot_id}: wheel speeds must be finite")
        index = self._index[robot_id]
        limit = self.spec.max_wheel_speed
        self._left[index] = min(max(left, -limit), limit)
        self._right[index] = min(max(right, -limit), limit)

    def set_all_wheels(
        self, robot_ids: Sequence[int], left: Sequence[float], right: Sequence[float]
    ) -> None:
        """``set_wheels`` for many robots at once (the same clamping, done with numpy)."""
        if not robot_ids:
            return
        lefts = np.asarray(left, dtype=np.float64)
        rights = np.asarray(right, dtype=np.float64)
        if not (np.isfinite(lefts).all() and np.isfinite(rights).all()):
            bad = next(
                robot
                for robot, pair in zip(robot_ids, zip(left, right, strict=True), strict=True)
                if not (math.isfinite(pair[0]) and math.isfinite(pair[1]))
            )
            raise ValueError(f"robot {bad}: wheel speeds must be finite")
        index = [self._index[robot] for robot in robot_ids]
        limit = self.spec.max_wheel_speed
        self._left[index] = np.minimum(np.maximum(lefts, -limit), limit)
        self._right[index] = np.minimum(np.maximum(rights, -limit), limit)

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
        if not self._ids:
            return
        substeps = self.substeps_for(dt)
        substep = dt / substeps
        robots = len(self._ids)
        speed = 0.5 * (self._left + self._right)
        turn_rate = (self._right - self._left) / self.spec.wheel_base
        # One row per body pymunk lists; rows past the robots (the static wall body) stay 0.
        forces = np.zeros((self._body_rows, 3))
        for _ in range(substeps):
            # The heading changes every substep, so the target velocity follows it.
            sin, cos = self._heading_directions()
            forces[:robots, 0] = speed * cos - self._velocity[:, 0]
            forces[:robots, 1] = speed * sin - self._velocity[:, 1]
            forces[:robots, 2] = turn_rate - self._velocity[:, 2]
            forces[:robots] *= self._inertia / substep
            self._write_buffer.set_float_buf(forces.reshape(-1))
            batch.set_space_bodies(self.space, _FORCE_FIELDS, self._write_buffer)
            self.space.step(substep)
            self._read_state()
        if not np.abs(self._state[:, 2]).max() <= ANGLE_BOUND:
            self._wrap_angles()

    def _read_state(self) -> None:
        self._read_buffer.clear()
        batch.get_space_bodies(self.space, _STATE_FIELDS, self._read_buffer)
        rows = np.frombuffer(self._read_buffer.float_buf(), dtype=np.float64).reshape(-1, 6)
        # pymunk lists the dynamic bodies (the robots, in insertion order) before the
        # static body that holds the wall.
        self._body_rows = len(rows)
        self._state = rows[: len(self._ids), :3].copy()
        self._prox = None
        self._poses = None
        self._readings = None
        self._directions = None
        self._velocity = rows[: len(self._ids), 3:].copy()

    def _wrap_angles(self) -> None:
        """Wraps every angle past ``ANGLE_BOUND`` into [-pi, pi], in pymunk and here (a
        step turns a robot by well under a radian, so checking after each is enough)."""
        for index in np.flatnonzero(~(np.abs(self._state[:, 2]) <= ANGLE_BOUND)).tolist():
            angle = numeric.wrap_angle(float(self._state[index, 2]))
            self._bodies[index].angle = angle
            self._state[index, 2] = angle
        self._poses = None
        self._readings = None
        self._prox = None
        self._directions = None

    # --- proximity ------------------------------------------------------------------

    def proximity(self, robot_id: int) -> tuple[float, ...]:
        """8 readings in [0, 1], e-puck order: 0 = nothing in range, 1 = touching.

        A reading falls linearly with the gap between the body's surface and the nearest
        wall or robot along the ray: 1 - gap / prox_range.
        """
        readings = self._proximity_array()[self._index[robot_id]]
        return tuple(float(value) for value in readings)

    def proximity_all(self) -> dict[int, tuple[float, ...]]:
        readings = self._proximity_array().tolist()
        return {robot_id: tuple(readings[self._index[robot_id]]) for robot_id in self._sorted_ids}

    def _proximity_array(self) -> np.ndarray:
        if self._prox is None:
            self._prox = self._compute_proximity()
        return self._prox

    def _compute_proximity(self) -> np.ndarray:
        radius = self.spec.radius
        reach = self.spec.prox_range
        centres = self._state[:, :2]
        # Each sensor's direction: the robot's heading turned by the sensor's angle.
        sin, cos = self._heading_directions()
        sin, cos = sin[:, None], cos[:, None]
        ray_x = cos * self._prox_cos - sin * self._prox_sin  # (robots, 8)
        ray_y = sin * self._prox_cos + cos * self._prox_sin

        # Wall: the ray from a centre p inside the circle |q| = R leaves it at distance
        # s = -b + sqrt(b^2 - (|p|^2 - R^2)), with b = p . u.
        along = centres[:, :1] * ray_x + centres[:, 1:2] * ray_y
        squared = centres[:, 0] * centres[:, 0] + centres[:, 1] * centres[:, 1]
        inside = (self.arena_radius * self.arena_radius - squared)[:, None]
        to_wall = -along + np.sqrt(np.maximum(along * along + inside, 0.0))
        readings: np.ndarray = np.clip(1.0 - (to_wall - radius) / reach, 0.0, 1.0)

        owners, others = self._neighbour_pairs(2.0 * radius + reach)
        if owners.size:
            offset = centres[others] - centres[owners]  # (pairs, 2)
            along = offset[:, :1] * ray_x[owners] + offset[:, 1:2] * ray_y[owners]
            # Ray meets the other disc where s^2 - 2 b s + |c|^2 - r^2 = 0.
            squared = offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1]
            discriminant = along * along - (squared - radius * radius)[:, None]
            root = np.sqrt(np.maximum(discriminant, 0.0))
            near = along - root
            far = along + root
            # A hit needs a real root, the disc not behind the sensor, and the disc within
            # reach; a disc already over the sensor (near < radius < far) reads as touching.
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
        """Ordered pairs (i, j), i != j, of bodies closer than ``cutoff``; i ascending.

        A uniform grid with cells of side ``cutoff``: each body looks only in its own and
        the 8 neighbouring cells, so the cost grows with the bodies, not their square. A
        small swarm compares every pair instead, in fewer numpy calls.
        """
        count = len(self._ids)
        if count < 2:
            empty = np.zeros(0, dtype=np.intp)
            return empty, empty
        centres = self._state[:, :2]
        if count <= ALL_PAIRS_UP_TO:
            dx = centres[:, 0][:, None] - centres[:, 0]
            dy = centres[:, 1][:, None] - centres[:, 1]
            close = dx * dx + dy * dy < cutoff * cutoff
            np.fill_diagonal(close, False)
            owners, others = np.nonzero(close)
            return owners, others
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
        x, y, angle = self._state[self._index[robot_id]]
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
