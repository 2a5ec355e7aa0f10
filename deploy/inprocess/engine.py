"""A whole lockstep run in one process: the processes of ``swarm run`` on an in-memory bus.

The world's ``Coordinator``, one process's ``HostedRobots`` over every robot's
``RobotEndpoint``, and the beacon's ``BeaconEndpoint`` exchange the same messages as over
Zenoh (the same keys and messages; the robots' senses and acts in batches, as a process
hosting them does), handed from one to the other in memory as they are made, typed: the
bytes, tags and decoding a transport needs are not made for the world's and the robots'
messages (``bestofn_swarm.wire.parcel``); the beacon, which answers one tick in five, still takes
its clock and answers in bytes, and a tap sees every message as it would be sent. Nothing of the
tick is coded here: opening and closing ticks, the barrier, the radio and the checks of
every input are the coordinator's and the endpoints', so a seed gives the same per-robot
results as ``swarm run`` by construction. Like the launcher, this engine learns the run
from what is published (every status, the world's state, the beacon's acks) and decides
when the run ends with the same watchdog and stop rule; ``EngineHooks.tap`` sees every
message, which is how ``swarm run --engine inprocess --record`` records one.

Time: lockstep only. The coordinator is never told a time that passes, so no tick closes
early; a tick closes once every robot and the beacon answered it, which in memory is at
once.
"""

from __future__ import annotations

import gc
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from bestofn_swarm.wire import batch, keyspace, protocol, shape
from bestofn_swarm.wire.endings import Halt, Look, Stop, stop_reason
from bestofn_swarm.wire.names import Role
from bestofn_swarm.wire.rng import Stream
from nest_beacon.core.beacon import Beacon, BeaconConfig
from nest_beacon.core.endpoint import BeaconEndpoint
from nest_beacon.core.endpoint import Outgoing as BeaconOutgoing
from robot_agent.core import builder, byzantine, faults
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.endpoint import Outgoing, RobotEndpoint, Step
from robot_agent.core.hosting import HostedRobots
from robot_agent.core.parking import ParkingSlots
from robot_agent.core.plugin import PluginError
from robot_agent.core.plugins import Plugins
from world_server.core.coordinator import Coordinator
from world_server.core.events import Event, Output, Publish
from world_server.core.world import World, WorldConfig
from world_server.observer.frame import FrameCollector
from world_server.observer.observer import RunObserver
from world_server.observer.watchdog import Watchdog, default_stall_window

# The watchdog sees the robots' positions as often as ``swarm run``'s launcher sees them in
# world/state (the world server's default --state-every): both see the same samples.
POSES_EVERY = 10

# Allocations between two collections of the youngest generation during a run.
RUN_COLLECT_THRESHOLD = 50_000

# What a tap is handed: every message of the run as a subscriber would see it.
Tap = Callable[[str, bytes, bytes | None], None]


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
    tap: Tap | None = None  # every message of the run, as published (a recorder)
    wall_clock: Callable[[], float] | None = None  # measures wall_time_s when given
    config: dict[str, Any] = field(default_factory=dict)  # the summary's "config"
    poses_every: int = POSES_EVERY  # swarm run's --state-every: how often the watchdog looks
    # The run's time series: fed every status and world state, as a recording of the run
    # would feed it (finished when the run ends).
    frame: FrameCollector | None = None


class _Bus:
    """The run's processes and what passes between them, in one thread.

    Whatever the coordinator gives out waits in a queue until the tick's work reaches it,
    so the coordinator is never re-entered: an answer it takes is handed to it with
    ``take``, which never closes a tick; the engine closes ticks with ``wake``.
    """

    def __init__(
        self,
        world: World,
        robots: list[RobotEndpoint],
        beacon: BeaconEndpoint,
        *,
        run: RunObserver,
        hooks: EngineHooks,
        rebuild: Callable[[int], RobotEndpoint] | None = None,
    ) -> None:
        keys = robots[0].keys
        self.keys = keys
        self.world = world
        self.run = run
        self.rebuild = rebuild  # a robot started afresh (a fault)
        self.tap = hooks.tap
        self.queue: deque[Output] = deque()
        self.coordinator = Coordinator(
            world,
            keys,
            self.queue.append,
            stall_timeout=math.inf,
            start_timeout=math.inf,
            state_every=hooks.poses_every,
            expect_robots=len(robots),
            expect_beacons=1,
        )
        self.host = HostedRobots(robots, keyring=None)
        self.beacon = beacon
        self.beacon_name = beacon.name
        # Where each robot's inputs come in: its own keys (its senses, until the world has
        # learnt the batched path; camera frames; radio deliveries).
        self.inputs: dict[str, tuple[RobotEndpoint, keyspace.KeyKind]] = {}
        for endpoint in robots:
            for kind, key in endpoint.input_keys.items():
                self.inputs[key] = (endpoint, kind)
        self.state_key = keys.of(keyspace.STATE)
        self.last_state: protocol.WorldState | None = None

    # --- faults.Engine: what a fault may do to this run, at a tick boundary ----------

    def kill(self, robot: int) -> bool:
        """The robot stops for good, as when its process dies over Zenoh: the world sees its
        token go (its body stays, a stopped obstacle), and nothing reaches it any more.
        Whether it was running."""
        was_running = self.world.is_live(robot)
        if was_running:
            token = self.keys.token(Role.ROBOT, robot)
            self._event(Event(keyspace.ALIVE_ROBOT, token, gone=True))
        self.run.killed(robot)
        return was_running

    def restart(self, robot: int) -> None:
        """The robot afresh: a new controller (as the robot builder makes it) in its old
        body, which joins at the next tick as a restarted process's token does."""
        if self.rebuild is None:
            raise ValueError("this run cannot start a robot afresh")
        endpoint = self.rebuild(robot)
        endpoint.batched = True  # its acts go in the batch, as its predecessor's did
        self.host.by_id[robot] = endpoint
        for kind, key in endpoint.input_keys.items():
            self.inputs[key] = (endpoint, kind)
        endpoint.world_appeared("in-process")
        self.run.restarted(robot)
        self._event(Event(keyspace.ALIVE_ROBOT, self.keys.token(Role.ROBOT, robot)))

    def start(self) -> None:
        """The processes' liveliness, as the coordinator would see their tokens; tick 0."""
        keys = self.keys
        instance = "in-process"
        for endpoint in self.host.by_id.values():
            endpoint.world_appeared(instance)
            self._event(Event(keyspace.ALIVE_ROBOT, keys.token(Role.ROBOT, endpoint.robot_id)))
        self.beacon.world_appeared(instance)
        self._event(Event(keyspace.ALIVE_BEACON, keys.token(Role.BEACON, self.beacon_name)))
        self.coordinator.begin(0.0)

    def run_tick(self) -> None:
        """Deliver everything the tick under way put out, until every answer is in."""
        queue = self.queue
        while queue:
            output = queue.popleft()
            if isinstance(output, Publish):
                self._deliver(output)

    def close_tick(self) -> None:
        """Close the tick under way (every answer is in) and open the next."""
        self.coordinator.wake(0.0)

    def stop(self) -> None:
        """Stop the world, which publishes its state a last time."""
        self.coordinator.stop()
        self.run_tick()

    # --- the wire --------------------------------------------------------------------

    def _deliver(self, output: Publish) -> None:
        """One message the world published, to whoever subscribes to its key."""
        if self.tap is not None:
            self.tap(output.key, output.payload, output.attachment)
        key = output.key
        if key == self.host.sense_key:
            rows: batch.SenseRows = output.message
            for endpoint, sense in self.host.senses_of(rows.batch()):
                self._stepped(endpoint.receive_sense(sense))
            self._send_acts()  # as the hosting process does after each batch
        elif key in self.inputs:
            endpoint, kind = self.inputs[key]
            self._stepped(endpoint.receive_message(kind, output.message, output.meta))
            self._send_acts()
        elif key == self.beacon.clock_key:
            for message in self.beacon.receive_clock(output.payload, output.attachment):
                self._beacon_sent(message)
        elif key == self.state_key:
            self.last_state = output.message

    def _stepped(self, step: Step | None) -> None:
        if step is None:
            return
        for message in step.transmissions:
            self._sent(message, message.meta)
        if step.act is not None:
            self._sent(step.act, step.act.message)
        else:
            self.host.hold(step)
        if step.status is not None:
            self._status(step.status)

    def _send_acts(self) -> None:
        acts = self.host.take_acts()
        if acts is not None:
            self._sent(acts, acts.message)

    def _status(self, message: Outgoing, published: bool = True) -> None:
        """A robot's status: to the tap (if it was published), and to what follows the run."""
        if published and self.tap is not None:
            self.tap(message.key, message.payload, message.attachment)
        self.run.status(message.message)

    def _sent(self, message: Outgoing, typed: object) -> None:
        """A robot's message (or its host's batch): to the tap, and to the world, typed
        (a radio message as its payload and its ``RadioTxMeta``)."""
        if self.tap is not None:
            self.tap(message.key, message.payload, message.attachment)
        kind = message.kind
        payload = message.message if kind is keyspace.RADIO_TX else b""
        self._event(Event(kind, message.key, payload, message=typed))

    def _beacon_sent(self, message: BeaconOutgoing) -> None:
        """The beacon's message, as bytes: to the tap, and to the world."""
        if self.tap is not None:
            self.tap(message.key, message.payload, message.attachment)
        self._event(Event(message.kind, message.key, message.payload, message.attachment))

    def _event(self, event: Event) -> None:
        self.coordinator.take(event, 0.0)


def run_in_process(
    world_config: WorldConfig,
    controller_config: ControllerConfig,
    beacon_config: BeaconConfig | None = None,
    *,
    timeout: float = shape.DEFAULT_TIMEOUT,
    stall_window: float | None = None,
    on_tick: Callable[[World], None] | None = None,
    controller_factory: type[Controller] | None = None,
    byzantine_robots: Mapping[int, byzantine.Behaviour] | None = None,
    robot_faults: Sequence[faults.RobotFault] = (),
    hooks: EngineHooks | None = None,
    plugins: Plugins | None = None,
) -> dict[str, Any]:
    """Run until every robot decided, the watchdog finds the run stalled (no undecided
    robot made progress for ``stall_window`` sim seconds; default: ``default_stall_window``
    for this arena and beacon) or ``timeout`` sim seconds; the summary is the
    ``swarm run --json`` object.

    ``controller_factory`` lets a study observe the controllers (a subclass of
    Controller); ``on_tick`` sees the world once every answer of a tick is in, before it
    closes. ``byzantine_robots`` makes those robots misbehave as ``swarm run --byzantine``
    does (a liar without a site claims ``byzantine.default_liar_site``); the run ends when
    every honest robot has decided. ``robot_faults``: the faults of robots the run declares
    (``swarm run --kill``, ``--restart``, ``--motor-failure``: robot_agent/core/faults.py),
    applied at tick boundaries as the launcher applies them, or built into the robots'
    controllers; the summary's ``faults`` lists those applied. ``hooks``: progress, an
    outside stop, a tap of every message (a recording), wall time, the run's time series
    (``hooks.frame``). ``plugins``: the run's plug-ins, resolved
    (``robot_agent.plugins.registry``; None: the built-ins ``controller_config`` names); one
    that fails ends the run crashed, its one line the summary's ``error``.
    """
    hooks = hooks or EngineHooks()
    started = hooks.wall_clock() if hooks.wall_clock is not None else 0.0
    world = World(world_config)
    keys = keyspace.Keys(world_config.run)
    beacon_config = beacon_config or BeaconConfig()
    beacon = Beacon(beacon_config, Stream.named(world_config.seed, "beacon", beacon_config.name))
    behaviours = byzantine.resolve_liar_sites(
        byzantine_robots or {}, world_config.num_sites, world.layout.best_site, world_config.seed
    )

    def build(robot_id: int) -> RobotEndpoint:
        return builder.build_robot(
            robot_id,
            world.info,
            controller_config,
            keys=keys,
            behaviour=behaviours.get(robot_id),
            factory=controller_factory,
            plugins=plugins,
            robot_faults=robot_faults,
        )

    endpoints: list[RobotEndpoint] = []
    failure: PluginError | None = None
    try:
        for robot_id in range(world_config.num_robots):
            endpoints.append(build(robot_id))
    except PluginError as error:  # a plug-in that cannot make a robot: no tick is run
        failure = error
    if stall_window is None:
        stall_window = default_stall_window(
            world.layout.arena_radius,
            world_config.spec.max_wheel_speed,
            # The longest leg a robot may take before it gives up: across the arena.
            controller_config.leg_allowance(2 * world.layout.arena_radius),
            beacon_config.outages,
            time_limit=timeout,
        )
    robots = range(world_config.num_robots)
    run = RunObserver(
        robots,
        watchdog=Watchdog(
            robots,
            stall_window,
            body_length=2 * world_config.spec.radius,
            slot_of=ParkingSlots.of_world(world.info, controller_config).slot,
        ),
        byzantine=behaviours,
        series=hooks.frame,
    )
    if failure is not None:  # no tick is run
        ending = _Ending(Halt(Stop.CRASHED), None, (), failure)
        return _summary(ending, world, run=run, hooks=hooks, behaviours=behaviours, started=started)
    bus = _Bus(
        world,
        endpoints,
        BeaconEndpoint(beacon, keys, world_config.dt, keyring=None),
        run=run,
        hooks=hooks,
        rebuild=build,
    )
    schedule = faults.Schedule(robot_faults)
    bus.start()
    # Everything made so far lives for the whole run: the collector need not look at it
    # again until the run ends, and what a tick makes is freed by reference counting, so
    # the collector may wait for more of it than its default 700 (a large swarm spent a
    # tenth of its time collecting).
    thresholds = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(RUN_COLLECT_THRESHOLD, *thresholds[1:])
    try:
        halt = _run_ticks(bus, schedule, timeout=timeout, hooks=hooks, on_tick=on_tick)
    except PluginError as error:  # a robot's plug-in failed in a step (or a restart): the run ends
        failure = error
        halt = Halt(Stop.CRASHED)
        bus.queue.clear()  # the rest of the tick is not delivered
        if error.robot is not None:
            run.crashed(error.robot)  # as its process would have, over Zenoh
    finally:
        gc.set_threshold(*thresholds)
        gc.unfreeze()
    # Every robot's state at the end (not published: its status changes are), as the
    # robot runs now (a robot started afresh: its new controller's); a robot whose plug-in
    # fails to say it keeps the last it published.
    for endpoint in bus.host.by_id.values():
        try:
            bus._status(endpoint.status(world.tick), published=False)
        except PluginError:
            continue
    bus.stop()
    state = bus.last_state
    if state is not None:
        run.state(state)
    if hooks.frame is not None:
        hooks.frame.finish()
    ending = _Ending(halt, bus.coordinator, schedule.applied, failure)
    return _summary(ending, world, run=run, hooks=hooks, behaviours=behaviours, started=started)


@dataclass(frozen=True)
class _Ending:
    """How a run in process ended: why, its world's coordinator (None: no tick was run),
    the faults applied, and the plug-in that failed, if one did."""

    halt: Halt
    coordinator: Coordinator | None
    applied: Sequence[faults.Applied]
    failure: PluginError | None


def _summary(
    ending: _Ending,
    world: World,
    *,
    run: RunObserver,
    hooks: EngineHooks,
    behaviours: Mapping[int, byzantine.Behaviour],
    started: float,
) -> dict[str, Any]:
    """The run's summary: the ``swarm run --json`` object."""
    config, coordinator = world.config, ending.coordinator
    wall = hooks.wall_clock() - started if hooks.wall_clock is not None else 0.0
    summary = run.summary(
        run_id=config.run,
        num_robots=config.num_robots,
        num_sites=config.num_sites,
        seed=config.seed,
        best_site=world.layout.best_site,
        sim_time_s=world.t,
        wall_time_s=wall,
        world=coordinator.state() if coordinator is not None else None,
        departures=coordinator.counters.departures if coordinator is not None else 0,
        observer_rejected=0,
        config=hooks.config,
        stop=ending.halt.stop,
        timeout_kind=ending.halt.limit,
        byzantine={robot: str(behaviour) for robot, behaviour in behaviours.items()},
    )
    summary["faults"] = [applied.record() for applied in ending.applied]
    if ending.failure is not None:
        summary["error"] = str(ending.failure)
    return summary


def _run_ticks(
    bus: _Bus,
    schedule: faults.Schedule,
    *,
    timeout: float,
    hooks: EngineHooks,
    on_tick: Callable[[World], None] | None,
) -> Halt:
    """Tick until the stop rule says the run ends; why it ended."""
    world, run = bus.world, bus.run
    honest = run.honest()
    while True:
        bus.run_tick()
        if schedule.pending and schedule.apply_due(bus, world.t):
            honest = [robot for robot in run.honest() if not run.records[robot].killed]
        if on_tick is not None:
            on_tick(world)
        if world.tick % hooks.poses_every == 0:
            # The watchdog sees the robots' positions once a tick's statuses are all in,
            # as the launcher does when world/state comes.
            state = bus.last_state
            if state is not None and state.tick == world.tick:
                run.state(state)
            if hooks.progress is not None:
                hooks.progress(Progress(world.t, run.decided(), run.trips()))
        look = _look(world.t, timeout, run=run, honest=honest, hooks=hooks, schedule=schedule)
        halt = stop_reason(look)
        if halt is not None:
            return halt
        bus.close_tick()


def _look(
    sim_time: float,
    timeout: float,
    *,
    run: RunObserver,
    honest: list[int],
    hooks: EngineHooks,
    schedule: faults.Schedule,
) -> Look:
    """What this engine sees at the end of a tick (``bestofn_swarm.wire.endings.stop_reason``
    decides): ``honest``, the honest robots still running."""
    # A restart to come will make progress: the run waits for it, as the launcher does.
    decided = run.all_decided(honest) and not schedule.restart_pending()
    return Look(
        sim_time=sim_time,
        sim_limit=timeout,
        all_decided=decided,
        last_decision=run.last_decision(honest) if decided else 0.0,
        stalled=run.stalled(sim_time),
        wall_time=hooks.since_launch() if hooks.since_launch is not None else 0.0,
        wall_limit=hooks.wall_timeout,
        signalled=hooks.stop_signal() if hooks.stop_signal is not None else False,
    )


__all__ = ["POSES_EVERY", "EngineHooks", "Progress", "Tap", "run_in_process"]
