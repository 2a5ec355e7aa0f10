"""In-memory stand-ins for a robot's world: kinematic bodies, a camera, a radio, a beacon.

They implement the ``ports.Body`` and ``ports.Radio`` protocols so that a swarm of real
``Controller``s runs through ``ports.control_step`` exactly as it would over Zenoh, with
no physics engine, no processes and no clock: ``FakeSwarm.run`` steps simulated time.

* Bodies integrate wheel speeds exactly (arcs), pass through each other (no collisions),
  and sense the arena wall (and optionally each other) with the e-puck's 8 rays; or,
  with ``physics=True``, the world server's pymunk ``Physics`` moves and senses them.
* The camera returns a frame filled with the faced site's colour, BGR = (255 (1 - rho),
  0, 255 rho), when its central ray meets that site's panel within ``CAMERA_REACH`` with
  no robot in the way; otherwise a grey frame (no site in view).
* The radio delivers each broadcast at the next step to every other robot within
  ``robot_range``, dropping each copy with probability ``drop`` (seeded); the beacon
  at the nest broadcasts every ``beacon_period`` seconds to robots within the nest radius.
Every message goes through ``protocol.encode`` and ``ports.decode_received``.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bestofn_swarm.wire import names, protocol
from bestofn_swarm.wire.numeric import wrap_angle
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import ports
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.navigation import EPUCK_PROX_ANGLES

if TYPE_CHECKING:
    from world_server.core.physics import Physics

ROBOT_RADIUS = 0.037
WHEEL_BASE = 0.053
MAX_SPEED = 0.13
PROX_RANGE = 0.06
DT = 0.1
FRAME_SHAPE = (48, 64, 3)
CAMERA_REACH = 0.3  # metres: beyond this a panel is too small to judge
PANEL_FRACTION = 0.7  # of each site's share of the wall, as in world_server.core.layout


def quality_of_rank(rank: int, num_sites: int) -> float:
    """The paper's rho_i for rank i (1 = best)."""
    return ((num_sites - 1) - (rank - 1)) / (num_sites - 1)


def make_world_info(
    num_sites: int, arena_radius: float = 0.75, nest_radius: float = 0.2, dt: float = DT
) -> protocol.WorldInfo:
    sites = [
        protocol.Site(
            index,
            arena_radius * math.cos(2 * math.pi * index / num_sites),
            arena_radius * math.sin(2 * math.pi * index / num_sites),
        )
        for index in range(num_sites)
    ]
    return protocol.WorldInfo(
        v=1,
        run="test",
        seed=0,
        dt=dt,
        arena_radius=arena_radius,
        nest=protocol.Nest(0.0, 0.0, nest_radius),
        sites=sites,
        robot_radius=ROBOT_RADIUS,
        wheel_base=WHEEL_BASE,
        max_wheel_speed=MAX_SPEED,
        camera=protocol.CameraSpec(width=FRAME_SHAPE[1], height=FRAME_SHAPE[0], fov=0.84),
        clock="lockstep",
    )


def shuffled_qualities(num_sites: int, seed: int) -> list[float]:
    """Site id -> quality, with the ranks permuted by ``seed`` (the best is not site 0)."""
    ranks = list(range(1, num_sites + 1))
    random.Random(seed).shuffle(ranks)
    return [quality_of_rank(rank, num_sites) for rank in ranks]


def site_frame(quality: float) -> np.ndarray:
    frame = np.empty(FRAME_SHAPE, dtype=np.uint8)
    frame[...] = (round(255 * (1 - quality)), 0, round(255 * quality))
    return frame


def grey_frame() -> np.ndarray:
    return np.full(FRAME_SHAPE, 128, dtype=np.uint8)


def unicycle(
    pose: tuple[float, float, float], left: float, right: float, dt: float
) -> tuple[float, float, float]:
    """Exact differential-drive motion over ``dt`` with constant wheel speeds."""
    left = min(max(left, -MAX_SPEED), MAX_SPEED)
    right = min(max(right, -MAX_SPEED), MAX_SPEED)
    x, y, theta = pose
    speed = (left + right) / 2
    rate = (right - left) / WHEEL_BASE
    if abs(rate) < 1e-12:
        return x + speed * dt * math.cos(theta), y + speed * dt * math.sin(theta), theta
    new_theta = theta + rate * dt
    x += speed / rate * (math.sin(new_theta) - math.sin(theta))
    y -= speed / rate * (math.cos(new_theta) - math.cos(theta))
    return x, y, wrap_angle(new_theta)


def proximity(
    pose: tuple[float, float, float],
    arena_radius: float,
    obstacles: Sequence[tuple[float, float, float]] = (),
) -> tuple[float, ...]:
    """The 8 e-puck readings (1 - gap / range) from the arena wall and disc obstacles.

    ``obstacles`` are (x, y, radius) discs.
    """
    x, y, theta = pose
    readings = []
    for sensor in EPUCK_PROX_ANGLES:
        ux, uy = math.cos(theta + sensor), math.sin(theta + sensor)
        along = x * ux + y * uy
        reach = -along + math.sqrt(max(along * along + arena_radius**2 - x * x - y * y, 0.0))
        for ox, oy, radius in obstacles:
            cx, cy = ox - x, oy - y
            b = cx * ux + cy * uy
            disc = b * b - (cx * cx + cy * cy - radius * radius)
            if disc >= 0.0 and b + math.sqrt(disc) >= ROBOT_RADIUS:
                reach = min(reach, max(b - math.sqrt(disc), ROBOT_RADIUS))
        readings.append(min(max(1.0 - (reach - ROBOT_RADIUS) / PROX_RANGE, 0.0), 1.0))
    return tuple(readings)


@dataclass
class FakeBody:
    """A ``ports.Body``: one robot's pose, wheels, sensors and camera in the fake world."""

    world: FakeWorld
    robot_id: int
    pose: tuple[float, float, float]
    left: float = 0.0
    right: float = 0.0
    frame_requested: bool = False
    pending_frame: np.ndarray | None = None
    capture_poses: list[tuple[float, float, float]] = field(default_factory=list)

    def read(self) -> ports.BodyReading:
        frame, self.pending_frame = self.pending_frame, None
        return ports.BodyReading(
            t=self.world.t,
            x=self.pose[0],
            y=self.pose[1],
            theta=self.pose[2],
            proximity=self.world.proximity_of(self),
            frame=frame,
        )

    def drive(self, left: float, right: float) -> None:
        assert math.isfinite(left) and math.isfinite(right)
        assert abs(left) <= MAX_SPEED + 1e-9 and abs(right) <= MAX_SPEED + 1e-9
        self.left, self.right = left, right

    def request_frame(self) -> None:
        self.frame_requested = True
        self.capture_poses.append(self.pose)


@dataclass
class FakeRadio:
    """A ``ports.Radio``: one robot's transceiver on the shared fake medium."""

    world: FakeWorld
    name: str
    inbox: list[tuple[str, bytes]] = field(default_factory=list)

    def send(self, payload: bytes) -> None:
        self.world.outbox.append((self.name, payload))

    def poll(self) -> list[tuple[str, bytes]]:
        messages, self.inbox = self.inbox, []
        return messages


@dataclass
class FakeWorld:
    """Kinematic arena, camera, radio medium and nest beacon."""

    info: protocol.WorldInfo
    qualities: list[float]
    seed: int = 0
    drop: float = 0.0
    robot_range: float = 0.5
    beacon_period: float = 0.5
    beacon_on: bool = True
    robots_sense_each_other: bool = False
    # Overrides the default camera; returning None loses the frame.
    camera: Callable[[FakeBody], np.ndarray | None] | None = None
    physics: bool = False  # move and sense with world_server.core.physics instead of kinematics
    t: float = 0.0
    tick: int = 0
    bodies: list[FakeBody] = field(default_factory=list)
    radios: list[FakeRadio] = field(default_factory=list)
    outbox: list[tuple[str, bytes]] = field(default_factory=list)
    delivered: int = 0
    dropped: int = 0

    def __post_init__(self) -> None:
        self._drop_rng = Stream.named(self.seed, "fake-radio")
        self._beacon_seq = 0
        self._next_beacon = 0.0
        self._physics: Physics | None = None
        if self.physics:
            from world_server.core.physics import Physics

            self._physics = Physics(self.info.arena_radius)

    def add_robot(
        self, robot_id: int, pose: tuple[float, float, float]
    ) -> tuple[FakeBody, FakeRadio]:
        body = FakeBody(self, robot_id, pose)
        if self._physics is not None:
            self._physics.add_robot(robot_id, *pose)
        radio = FakeRadio(self, names.robot_name(robot_id))
        self.bodies.append(body)
        self.radios.append(radio)
        return body, radio

    def proximity_of(self, body: FakeBody) -> tuple[float, ...]:
        if self._physics is not None:
            return self._physics.proximity(body.robot_id)
        others = (
            [(o.pose[0], o.pose[1], ROBOT_RADIUS) for o in self.bodies if o is not body]
            if self.robots_sense_each_other
            else []
        )
        return proximity(body.pose, self.info.arena_radius, others)

    def default_camera(self, body: FakeBody) -> np.ndarray:
        """The faced site's colour if the camera's central ray meets its panel unblocked.

        Panels span ``PANEL_FRACTION`` of each site's share of the wall, as in the layout;
        a panel further than ``CAMERA_REACH`` away, or a robot on the ray, gives grey.
        """
        x, y, theta = body.pose
        ux, uy = math.cos(theta), math.sin(theta)
        along = x * ux + y * uy
        radius = self.info.arena_radius
        to_wall = -along + math.sqrt(max(along * along + radius**2 - x * x - y * y, 0.0))
        if to_wall > CAMERA_REACH:
            return grey_frame()
        for other in self.bodies:
            if other is body:
                continue
            cx, cy = other.pose[0] - x, other.pose[1] - y
            b = cx * ux + cy * uy
            if 0.0 < b < to_wall and (cx * cx + cy * cy - b * b) < ROBOT_RADIUS**2:
                return grey_frame()  # another robot hides the wall
        hit = math.atan2(y + to_wall * uy, x + to_wall * ux)
        half_width = PANEL_FRACTION * math.pi / len(self.info.sites)
        for site in self.info.sites:
            if abs(wrap_angle(hit - math.atan2(site.y, site.x))) <= half_width:
                return site_frame(self.qualities[site.id])
        return grey_frame()

    def advance(self) -> None:
        """Close a step: move bodies, render requested frames, deliver radio traffic."""
        if self._physics is not None:
            for body in self.bodies:
                self._physics.set_wheels(body.robot_id, body.left, body.right)
            self._physics.step(self.info.dt)
        for body in self.bodies:
            if self._physics is None:
                body.pose = unicycle(body.pose, body.left, body.right, self.info.dt)
            else:
                body.pose = self._physics.pose(body.robot_id)
            if body.frame_requested:
                body.frame_requested = False
                body.pending_frame = (self.camera or self.default_camera)(body)
        positions = {
            radio.name: body.pose[:2] for body, radio in zip(self.bodies, self.radios, strict=True)
        }
        for sender, payload in sorted(self.outbox, key=lambda item: int(item[0])):
            for radio in self.radios:
                if radio.name == sender:
                    continue
                (sx, sy), (rx, ry) = positions[sender], positions[radio.name]
                if math.hypot(sx - rx, sy - ry) <= self.robot_range:
                    self._deliver(radio, sender, payload)
        self.outbox = []
        self.tick += 1
        self.t = self.tick * self.info.dt
        if self.beacon_on and self.t + 1e-9 >= self._next_beacon:
            self._next_beacon = self.t + self.beacon_period
            beacon = protocol.encode(protocol.BeaconPayload(v=1, id="nest", seq=self._beacon_seq))
            self._beacon_seq += 1
            nest = self.info.nest
            for radio in self.radios:
                x, y = positions[radio.name]
                if math.hypot(x - nest.x, y - nest.y) <= nest.radius:
                    self._deliver(radio, "nest", beacon)

    def _deliver(self, radio: FakeRadio, sender: str, payload: bytes) -> None:
        if self.drop > 0.0 and self._drop_rng.random() < self.drop:
            self.dropped += 1
            return
        self.delivered += 1
        radio.inbox.append((sender, payload))


@dataclass
class Event:
    """A status change seen after a step."""

    t: float
    robot: int
    phase: str
    trips: int
    opinion: list[float]
    decided_site: int | None


@dataclass
class FakeSwarm:
    """Controllers on fake bodies, stepped together in simulated time."""

    world: FakeWorld
    controllers: list[Controller]
    bodies: list[FakeBody]
    radios: list[FakeRadio]
    rejects: list[ports.RejectCounter]
    events: list[Event] = field(default_factory=list)
    inject: Callable[[int, Controller], list[ports.Received]] | None = None

    def step(self) -> None:
        for controller, body, radio, rejects in zip(
            self.controllers, self.bodies, self.radios, self.rejects, strict=True
        ):
            if self.inject is None:
                ports.control_step(controller, body, radio, rejects)
            else:
                # Extra messages a transport's validation let through, e.g. impostors.
                reading = body.read()
                received = ports.decode_received(radio.poll(), rejects)
                received += self.inject(self.world.tick, controller)
                command = controller.step(reading, received)
                body.drive(command.left, command.right)
                if command.capture:
                    body.request_frame()
                for payload in command.broadcasts:
                    radio.send(protocol.encode(payload))
            if controller.take_status_change():
                self.events.append(
                    Event(
                        self.world.t,
                        controller.robot_id,
                        controller.phase,
                        controller.trips,
                        controller.opinion,
                        controller.decided_site,
                    )
                )
        self.world.advance()

    def run(self, seconds: float, until_all_stopped: bool = True) -> None:
        for _ in range(round(seconds / self.world.info.dt)):
            self.step()
            if until_all_stopped and all(c.phase == "stopped" for c in self.controllers):
                return

    @property
    def best_site(self) -> int:
        return max(range(len(self.world.qualities)), key=self.world.qualities.__getitem__)


def make_swarm(
    num_robots: int,
    num_sites: int,
    seed: int,
    config: ControllerConfig | None = None,
    *,
    arena_radius: float = 0.75,
    nest_radius: float = 0.2,
    start_poses: Sequence[tuple[float, float, float]] | None = None,
    **world_options: Any,
) -> FakeSwarm:
    """``num_robots`` controllers, by default on a ring just outside the nest, facing out."""
    info = make_world_info(num_sites, arena_radius, nest_radius)
    world = FakeWorld(info, shuffled_qualities(num_sites, seed), seed=seed, **world_options)
    if start_poses is None:
        ring = info.nest.radius + 2 * ROBOT_RADIUS
        angles = [2 * math.pi * robot / num_robots for robot in range(num_robots)]
        start_poses = [(ring * math.cos(a), ring * math.sin(a), a) for a in angles]
    controllers, bodies, radios, rejects = [], [], [], []
    for robot in range(num_robots):
        body, radio = world.add_robot(robot, start_poses[robot])
        rng = Stream.named(seed, "robot", robot)
        controllers.append(Controller(robot, info, config or ControllerConfig(), rng))
        bodies.append(body)
        radios.append(radio)
        rejects.append(ports.RejectCounter())
    return FakeSwarm(world, controllers, bodies, radios, rejects)
