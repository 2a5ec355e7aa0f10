"""A whole lockstep run in one process, without Zenoh: for tests, sweeps and benchmarks.

It drives the same World, the same controllers (through the port contract's
``control_step`` on ``robot_agent.core.simulated``'s body and radio, as the robot's
endpoint does) and the same beacon logic as ``swarm run``, tick by tick in the same order,
so a seed gives the same per-robot results here as over Zenoh.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from deploy.summary import RobotRecord, RunOutcome, build_summary
from deploy.watchdog import Watchdog, default_stall_window
from deploy.wire_tap import WireTap, with_rejects
from nest_beacon.core.beacon import Beacon, BeaconConfig
from robot_agent.core import byzantine
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.parking import ParkingSlots
from robot_agent.core.ports import RejectCounter, RobotController
from robot_agent.core.simulated import SimulatedPorts
from wire import names, protocol, shape
from wire.endings import Look, Stop, stop_reason
from wire.rng import Stream
from world_server.core.world import Transmission, World, WorldConfig

# The watchdog sees the robots' positions as often as ``swarm run``'s launcher sees them in
# world/state (the world server's default --state-every): both see the same samples.
POSES_EVERY = 10


@dataclass(frozen=True)
class Progress:
    sim_time: float
    decided: int
    trips: int


@dataclass
class EngineHooks:
    """What ``swarm run --engine inprocess`` adds to a bare run (every part optional)."""

    stop_signal: Callable[[], bool] | None = None  # asked every tick: has a stop signal come?
    since_launch: Callable[[], float] | None = None  # wall seconds, for wall_timeout
    wall_timeout: float | None = None  # --wall-timeout (with since_launch)
    progress: Callable[[Progress], None] | None = None  # told every ``poses_every`` ticks
    wire: WireTap | None = None  # every message as the processes would publish it
    wall_clock: Callable[[], float] | None = None  # measures wall_time_s when given
    config: dict[str, Any] = field(default_factory=dict)  # the summary's "config"
    poses_every: int = POSES_EVERY  # swarm run's --state-every: how often the watchdog looks


@dataclass
class _Robot:
    controller: RobotController
    record: RobotRecord
    rejects: RejectCounter = field(default_factory=RejectCounter)
    ports: SimulatedPorts = field(init=False)

    def __post_init__(self) -> None:
        self.ports = SimulatedPorts(self.rejects)


def run_in_memory(
    world_config: WorldConfig,
    controller_config: ControllerConfig,
    beacon_config: BeaconConfig | None = None,
    *,
    timeout: float = shape.DEFAULT_TIMEOUT,
    stall_window: float | None = None,
    on_tick: Callable[[World], None] | None = None,
    controller_factory: type[Controller] = Controller,
    byzantine_robots: Mapping[int, byzantine.Behaviour] | None = None,
    hooks: EngineHooks | None = None,
) -> dict[str, Any]:
    """Run until every robot decided, the watchdog finds the run stalled (no undecided
    robot made progress for ``stall_window`` sim seconds; default: ``default_stall_window``
    for this arena and beacon) or ``timeout`` sim seconds; the summary is the
    ``swarm run --json`` object (wall-clock fields are zero).

    ``controller_factory`` lets a study observe the controllers (a subclass of
    Controller); ``on_tick`` sees the world before each tick closes.
    ``byzantine_robots`` makes those robots misbehave as ``swarm run --byzantine`` does (a
    liar without a site claims ``byzantine.default_liar_site``); the run ends when every
    honest robot has decided. ``hooks``: progress, an outside stop, recording, wall time.
    """
    hooks = hooks or EngineHooks()
    wire = hooks.wire
    started = hooks.wall_clock() if hooks.wall_clock is not None else 0.0
    world = World(world_config)
    beacon_config = beacon_config or BeaconConfig()
    beacon = Beacon(
        beacon_config,
        Stream.named(world_config.seed, "beacon", beacon_config.name),
    )
    world.join_beacon(beacon_config.name)
    behaviours = byzantine.resolve_liar_sites(
        byzantine_robots or {}, world_config.num_sites, world.layout.best_site, world_config.seed
    )
    robots: dict[int, _Robot] = {}
    for robot_id in range(world_config.num_robots):
        world.join_robot(robot_id)
        rng = Stream.named(world_config.seed, "robot", robot_id)
        behaviour = behaviours.get(robot_id)
        controller = (
            controller_factory(robot_id, world.info, controller_config, rng)
            if behaviour is None
            else byzantine.build_controller(robot_id, world.info, controller_config, rng, behaviour)
        )
        robots[robot_id] = _Robot(controller, RobotRecord(robot_id))
    if stall_window is None:
        stall_window = default_stall_window(
            world.layout.arena_radius,
            world_config.spec.max_wheel_speed,
            # The longest leg a robot may take before it gives up: across the arena.
            controller_config.leg_allowance(2 * world.layout.arena_radius),
            beacon_config.outages,
            time_limit=timeout,
        )
    watchdog = Watchdog(
        robots,
        stall_window,
        body_length=2 * world_config.spec.radius,
        slot_of=ParkingSlots.of_world(world.info, controller_config).slot,
    )
    honest = [robot for robot_id, robot in robots.items() if robot_id not in behaviours]
    deliveries: dict[str, list[tuple[str, bytes]]] = {}
    frames: dict[int, bytes] = {}
    robot_ids = list(robots)
    robot_names = {robot_id: names.robot_name(robot_id) for robot_id in robot_ids}
    beacon_tick = 0  # the next tick the beacon answers (Ack.next_tick)
    while True:
        acts: dict[int, protocol.Act] = {}
        transmissions: list[Transmission] = []
        # The world's readings of the tick, taken before any robot answers, all at once.
        rx = {robot_id: len(deliveries.get(name, [])) for robot_id, name in robot_names.items()}
        senses = list(zip(robot_ids, world.senses(robot_ids, rx, frames).messages(), strict=True))
        if wire is not None:
            wire.tick_opened(world, senses, frames)
        for robot_id, sense in senses:
            robot = robots[robot_id]
            name = robot_names[robot_id]
            radio = deliveries.get(name, [])
            answer = robot.ports.answer(robot.controller, sense, radio, frames.get(robot_id))
            acts[robot_id] = answer.act
            transmissions += [
                Transmission(name, sent.seq, sent.payload) for sent in answer.transmissions
            ]
            status = None
            if robot.controller.take_status_change():
                status = with_rejects(robot.controller.status(world.tick), robot.rejects.count)
                robot.record.update(status)
                watchdog.status(status)
            if wire is not None:
                wire.robot_answered(robot_id, answer, status)
        if world.tick >= beacon_tick:  # the ticks the beacon answers, as over Zenoh
            beacon_messages = beacon.on_tick(world.t)
            for message in beacon_messages:
                transmissions.append(
                    Transmission(beacon_config.name, message.seq, protocol.encode(message))
                )
            beacon_tick = beacon.next_tick(world.tick, world_config.dt)
            if wire is not None:
                wire.beacon_answered(beacon_config.name, world.tick, beacon_messages, beacon_tick)
        if on_tick is not None:
            on_tick(world)
        if world.tick % hooks.poses_every == 0:
            watchdog.poses(world.t, _positions(world))
            if hooks.progress is not None:
                hooks.progress(_progress(world, robots))
        halt = stop_reason(_look(world.t, timeout, honest, watchdog, hooks))
        if halt is not None:
            break
        result = world.advance(acts, transmissions)
        if wire is not None:
            wire.delivered(result.tick, result.deliveries)
        deliveries = {
            receiver: [(item.sender, item.payload) for item in items]
            for receiver, items in result.deliveries.items()
        }
        frames = result.frames
    for robot in robots.values():
        status = with_rejects(robot.controller.status(world.tick), robot.rejects.count)
        robot.record.update(status)
        watchdog.status(status)
    watchdog.poses(world.t, _positions(world))
    if wire is not None:
        wire.state(world)  # as the world server does when it stops
    wall = hooks.wall_clock() - started if hooks.wall_clock is not None else 0.0
    state = world.state()
    return build_summary(
        RunOutcome(
            run_id=world_config.run,
            num_robots=world_config.num_robots,
            num_sites=world_config.num_sites,
            seed=world_config.seed,
            best_site=world.layout.best_site,
            sim_time_s=world.t,
            wall_time_s=wall,
            timed_out=halt.stop is Stop.TIMEOUT,
            radio=state.radio,
            world_rejected=0,
            stalls=0,
            observer_rejected=0,
            config=hooks.config,
            stop=halt.stop,
            timeout_kind=halt.limit,
            stuck=watchdog.stuck(),
            byzantine={robot: str(behaviour) for robot, behaviour in behaviours.items()},
        ),
        [robot.record for robot in robots.values()],
    )


def _look(
    sim_time: float, timeout: float, honest: list[_Robot], watchdog: Watchdog, hooks: EngineHooks
) -> Look:
    """What this engine sees at the end of a tick (``wire.endings.stop_reason`` decides)."""
    decided = all(robot.controller.decided_site is not None for robot in honest)
    return Look(
        sim_time=sim_time,
        sim_limit=timeout,
        all_decided=decided,
        last_decision=_last_decision(honest) if decided else 0.0,
        stalled=watchdog.stalled(sim_time),
        wall_time=hooks.since_launch() if hooks.since_launch is not None else 0.0,
        wall_limit=hooks.wall_timeout,
        signalled=hooks.stop_signal() if hooks.stop_signal is not None else False,
    )


def _last_decision(robots: list[_Robot]) -> float:
    """The sim time at which the last of ``robots`` decided (0 if none did)."""
    return max(
        (r.record.status.decision_time or 0.0 for r in robots if r.record.status is not None),
        default=0.0,
    )


def _progress(world: World, robots: Mapping[int, _Robot]) -> Progress:
    decided = sum(1 for robot in robots.values() if robot.record.decided_site is not None)
    trips = sum(robot.record.status.trips for robot in robots.values() if robot.record.status)
    return Progress(world.t, decided, trips)


def _positions(world: World) -> list[tuple[int, float, float]]:
    return [(robot, x, y) for robot, (x, y, _) in sorted(world.physics.poses().items())]
