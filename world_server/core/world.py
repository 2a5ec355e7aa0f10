"""The world of one run, without any I/O: layout, physics, camera and radio together.

The coordinator (``coordinator.py``) feeds it what arrives, through the world server's
Zenoh adapter, and has what it returns published; the in-process engine, tests and
benchmarks drive it directly. One call to ``advance`` closes one control tick.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Container, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Annotated, ClassVar, Literal

import numpy as np
from msgspec import Meta

from bestofn_swarm.wire import batch, names, numeric, protocol, settings, shape
from bestofn_swarm.wire.rng import Stream, seed_of
from bestofn_swarm.wire.settings import Flag
from world_server.core.body import EpuckSpec
from world_server.core.camera import CameraNoise, CameraRenderer
from world_server.core.layout import Layout, make_layout
from world_server.core.physics import Physics
from world_server.core.radio import Delivery, RadioConfig, RadioMedium, SenderKind

DEFAULT_CAMERA = protocol.CameraSpec(width=64, height=48, fov=0.84)
OCCLUSION_RANGE = 1.0  # metres: robots further away are too small to hide a site


@dataclass(frozen=True)
class WorldConfig:
    """The world of one run; its flagged settings are options of world-server and swarm run."""

    FLAG_GROUP: ClassVar[str] = "world"

    run: Annotated[names.Name, Meta(description="the run id")] = "run"
    seed: Annotated[shape.Seed, Meta(description="run seed"), Flag()] = shape.DEFAULT_SEED
    num_sites: Annotated[shape.Sites, Meta(description="number of sites n"), Flag(name="sites")] = (
        shape.DEFAULT_SITES
    )
    num_robots: Annotated[
        shape.Robots,
        Meta(
            description="expected swarm size: sizes the arena and the nest; the run starts "
            "when this many robots are live",
        ),
        Flag(name="robots"),
    ] = shape.DEFAULT_ROBOTS
    dt: Annotated[
        float,
        Meta(ge=0.001, le=1.0, description="control tick in sim seconds"),
        Flag(group="clock"),
    ] = 0.1
    substeps: Annotated[int, Meta(ge=1, description="physics steps per control tick")] = 2
    clock: Annotated[
        Literal["lockstep", "realtime"],
        Meta(
            description="lockstep: deterministic, waits for every controller each tick, as "
            "fast as the processes go; realtime: follows the wall clock"
        ),
        Flag(group="clock"),
    ] = "lockstep"
    radio: RadioConfig = field(default_factory=RadioConfig)  # its beacon_range is replaced:
    beacon_range: Annotated[
        Annotated[float, Meta(gt=0.0)] | None,
        Meta(description="beacon range in metres"),
        Flag(group=RadioConfig.FLAG_GROUP, default_text="the nest radius"),
    ] = None
    camera: Annotated[
        protocol.CameraSpec, Meta(description="the robots' camera: frame size, field of view")
    ] = DEFAULT_CAMERA
    camera_noise: CameraNoise = field(default_factory=CameraNoise)
    spec: EpuckSpec = field(default_factory=EpuckSpec)

    def __post_init__(self) -> None:
        settings.check(self)


@dataclass(frozen=True)
class Transmission:
    """A radio message a controller sent during the tick being closed."""

    sender: str
    seq: int
    payload: bytes


@dataclass(frozen=True)
class Senses:
    """What the robots sense at the start of a tick, made for all of them at once."""

    tick: int
    t: float
    robots: list[int]  # ascending ids
    values: list[list[float]]  # one row per robot: x, y, theta, then its 8 proximity readings
    rx: list[int]  # radio deliveries of the tick, per robot
    camera: list[bool]  # a frame comes this tick, per robot

    def messages(self) -> list[protocol.Sense]:
        """Each robot's ``Sense``, in the order of ``robots``."""
        tick, t = self.tick, self.t
        return [
            batch.sense_of_row(tick, t, row, rx, camera)
            for row, rx, camera in zip(self.values, self.rx, self.camera, strict=True)
        ]


@dataclass(frozen=True)
class TickResult:
    tick: int  # the tick that now begins
    deliveries: dict[str, list[Delivery]]  # by receiver name, in delivery order
    frames: dict[int, np.ndarray]  # camera frames (BGR images) by robot id


class World:
    def __init__(self, config: WorldConfig) -> None:
        self.config = config
        self.layout: Layout = make_layout(
            config.num_sites, config.num_robots, config.seed, config.spec.radius
        )
        self.physics = Physics(self.layout.arena_radius, config.spec, config.substeps)
        # The beacon reaches exactly the nest unless a range was chosen.
        radio = dataclasses.replace(
            config.radio, beacon_range=config.beacon_range or self.layout.nest_radius
        )
        self.radio = RadioMedium(radio, seed_of(config.seed, "radio"))
        self.camera = CameraRenderer(
            self.layout,
            config.camera,
            robot_radius=config.spec.radius,
            noise=config.camera_noise,
            seed=seed_of(config.seed, "camera"),
        )
        self._camera_rng = Stream.named(config.seed, "frames")
        self.tick = 0
        # Bodies of the expected swarm are created now, in id order: pymunk's contact
        # solving depends on the order bodies were added, and the order in which robot
        # processes happen to join must not change a run.
        for robot_id, pose in enumerate(self.layout.start_poses):
            self.physics.add_robot(robot_id, *pose)
        self._live_robots: set[int] = set()
        self._beacons: set[str] = set()
        self.info = protocol.WorldInfo(
            v=protocol.VERSION,
            run=config.run,
            seed=config.seed,
            dt=config.dt,
            arena_radius=self.layout.arena_radius,
            nest=protocol.Nest(0.0, 0.0, self.layout.nest_radius),
            sites=self.layout.info_sites(),
            robot_radius=config.spec.radius,
            wheel_base=config.spec.wheel_base,
            max_wheel_speed=config.spec.max_wheel_speed,
            camera=config.camera,
            clock=config.clock,
        )

    @property
    def t(self) -> float:
        return self.tick * self.config.dt

    # --- membership ----------------------------------------------------------------

    def is_member(self, robot_id: int) -> bool:
        """Whether ``robot_id`` is one of the swarm's robots (ids 0 to num_robots - 1)."""
        return 0 <= robot_id < self.config.num_robots

    def join_robot(self, robot_id: int) -> None:
        """A controller for ``robot_id`` is live: its body, made at the start, answers to it.

        Only the swarm's own ids have a body (an arena sized for N robots has no room
        for a robot 99999); ValueError for any other."""
        if not self.is_member(robot_id):
            raise ValueError(f"robot {robot_id} is not one of the {self.config.num_robots}")
        self._live_robots.add(robot_id)

    def leave_robot(self, robot_id: int) -> None:
        """Its controller is gone: the body stops and stays as an obstacle."""
        self._live_robots.discard(robot_id)
        if self.physics.has_robot(robot_id):
            self.physics.set_wheels(robot_id, 0.0, 0.0)

    def join_beacon(self, name: str) -> None:
        self._beacons.add(name)

    def leave_beacon(self, name: str) -> None:
        self._beacons.discard(name)

    def live_robots(self) -> list[int]:
        return sorted(self._live_robots)

    def is_live(self, robot_id: int) -> bool:
        return robot_id in self._live_robots

    def beacons(self) -> list[str]:
        return sorted(self._beacons)

    # --- one tick ------------------------------------------------------------------

    def senses(self, robots: list[int], rx: Mapping[int, int], frames: Container[int]) -> Senses:
        """What ``robots`` sense now: with ``rx[robot]`` radio deliveries (none if absent)
        and a camera frame for those in ``frames``; made with numpy over every body at once."""
        return Senses(
            self.tick,
            self.t,
            robots,
            self.physics.readings(robots),
            [rx.get(robot, 0) for robot in robots],
            [robot in frames for robot in robots],
        )

    def sense(self, robot_id: int, rx: int, camera: bool) -> protocol.Sense:
        """One robot's ``Sense`` (``senses`` makes many at once)."""
        frames = (robot_id,) if camera else ()
        return self.senses([robot_id], {robot_id: rx}, frames).messages()[0]

    def advance(
        self, acts: Mapping[int, protocol.Act], transmissions: Sequence[Transmission]
    ) -> TickResult:
        """Close the current tick: transmit, move, render, and deliver what is due next."""
        if transmissions:
            self._transmit(transmissions)
        live = self._live_robots
        moving = [(robot, act) for robot, act in sorted(acts.items()) if robot in live]
        self.physics.set_all_wheels(
            [robot for robot, _ in moving],
            [act.left for _, act in moving],
            [act.right for _, act in moving],
        )
        self.physics.step(self.config.dt)
        self.tick += 1
        frames = {robot: self._render(robot) for robot, act in moving if act.capture}
        deliveries: dict[str, list[Delivery]] = {}
        for delivery in self.radio.deliveries(self.tick):
            deliveries.setdefault(delivery.receiver, []).append(delivery)
        return TickResult(self.tick, deliveries, frames)

    def _transmit(self, transmissions: Sequence[Transmission]) -> None:
        """Hand the tick's radio messages to the medium, in the medium's order, each from
        where its sender is now."""
        receivers = {
            names.robot_name(robot): self.physics.pose(robot)[:2]
            for robot in sorted(self._live_robots)
        }
        for message in sorted(transmissions, key=_transmission_order):
            kind: SenderKind
            if message.sender in self._beacons:
                position, kind = (self.info.nest.x, self.info.nest.y), "beacon"
            elif message.sender in receivers:
                position, kind = receivers[message.sender], "robot"
            else:  # its sender left after sending it: there is no transmitter any more
                self.radio.reject()
                continue
            self.radio.transmit(
                self.tick, message.sender, message.seq, message.payload, position, kind, receivers
            )

    def is_sender(self, name: str) -> bool:
        """Whether ``name`` may transmit now (a live robot or a known beacon)."""
        if name in self._beacons:
            return True
        robot = names.robot_of_name(name)
        return robot is not None and robot in self._live_robots

    def _render(self, robot_id: int) -> np.ndarray:
        x, y, theta = self.physics.pose(robot_id)
        others = [
            (ox, oy)
            for other, (ox, oy, _) in sorted(self.physics.poses().items())
            if other != robot_id and numeric.hypot(ox - x, oy - y) < OCCLUSION_RANGE
        ]
        return self.camera.render(x, y, theta, others, rng=self._camera_rng)

    def state(self, rejected: int = 0, stalls: int = 0, departures: int = 0) -> protocol.WorldState:
        counters = self.radio.counters
        return protocol.WorldState(
            v=protocol.VERSION,
            tick=self.tick,
            t=self.t,
            robots=[
                protocol.Pose(robot, x, y, theta)
                for robot, (x, y, theta) in sorted(self.physics.poses().items())
            ],
            radio=protocol.RadioCounters(
                sent=counters.sent,
                delivered=counters.delivered,
                dropped=counters.dropped,
                rejected=counters.rejected,
            ),
            rejected=rejected,
            stalls=stalls,
            departures=departures,
        )


def _transmission_order(message: Transmission) -> tuple[object, ...]:
    return (*RadioMedium.sender_order(message.sender), message.seq)
