"""The run ``swarm run``'s options ask for (``plan_from_args``): its shape, limits,
faults, Byzantine robots, processes, recording and configuration, checked before
anything starts (a ValueError is a usage error).

Here rather than in ``deploy/launcher/`` for the same reason as ``deploy/launcher/options.py``:
``swarm experiment`` checks each of its runs with it before starting any.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing.cliargs import LOCAL_ENDPOINT
from bestofn_swarm.plumbing.private_files import make_private_folder
from bestofn_swarm.plumbing.tcp import free_port
from bestofn_swarm.wire import settings
from deploy.launcher.dask_worker import ROUTER_ENV
from deploy.launcher.outside import OutsidePlan, outside_plan
from deploy.launcher.switches import SWITCHES, RunSwitches, run_switches
from deploy.viewer.options import VIEW_OPTIONS, Observer, holds, observers, view_linger
from nest_beacon.node.options import NestBeaconConfig
from robot_agent.core import byzantine
from robot_agent.core.faults import RobotFault
from robot_agent.core.plugin import ControllerChoice
from robot_agent.core.plugins import Plugins, builtin_plugins
from robot_agent.node.options import RobotAgentConfig
from robot_agent.plugins import registry
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.observer.referee import (
    EndingRules,
    LostRobot,
    OutsideRobot,
    PlannedDeparture,
)
from world_server.observer.watchdog import default_stall_window, default_world_stop_window
from world_server.recorder.options import DEFAULT_NICENESS
from world_server.recording.description import RunDescription

# Every robot is its own process up to ONE_PROCESS_PER_ROBOT_UP_TO robots, as a real swarm
# is (a robot's crash costs that robot alone). A larger swarm is hosted: processes of at
# least ROBOTS_PER_PROCESS robots each, ROBOT_PROCESSES_PER_CORE per core, which exchange
# one batch of senses and acts per tick with the world; above the threshold that was
# faster on a 2-core machine (benchmarks/swarm_speed.py, docs/performance.md).
ONE_PROCESS_PER_ROBOT_UP_TO = 25
ROBOTS_PER_PROCESS = 25
ROBOT_PROCESSES_PER_CORE = 2
# The recorder runs at nice 10 up to this many robots (recorder_niceness).
NICE_RECORDER_UP_TO = 25
# Wall seconds the world waits for its robots beyond the launcher's wait for the outside
# ones: the launcher, not the world, gives up on a robot that never connects.
OUTSIDE_START_MARGIN = 30.0


@dataclass
class RunPlan:
    """Everything needed to start one run, derived from the command line."""

    run_id: str
    robots: int
    sites: int
    seed: int
    timeout: float
    stall_window: float
    world_stop_window: float  # wall seconds without a new tick: the world stopped
    connect: str | None  # an existing router; None: the world server is the run's router
    record: Path | None
    switches: RunSwitches  # the world's, the robots' and the beacon's configs
    recorder_args: list[str] = field(default_factory=list)
    faults: list[RobotFault] = field(default_factory=list)  # robot_agent/core/faults.py
    robots_per_process: int = 1
    batch: bool = True  # a process hosting several robots exchanges batches with the world
    byzantine_robots: dict[int, byzantine.Behaviour] = field(default_factory=dict)
    spawn: str = "fork"
    config: dict[str, Any] = field(default_factory=dict)
    observers: list[Observer] = field(default_factory=list)  # the page, Foxglove live
    wall_timeout: float | None = None
    keyed: bool = True  # run keys: every message tagged and checked
    secure: bool = False  # TLS and access control
    trace: Path | None = None  # --trace DIR: the world's and robot hosts' tick timelines
    outside: OutsidePlan | None = None  # --external: robots served to programs outside
    lost_robot: LostRobot = LostRobot.CONTINUE  # what a robot lost mid-run does to the run
    dask: str | None = None  # --dask: the scheduler whose workers host the robots
    dask_world: str | None = None  # --dask-world: the worker of the world and the beacon
    hold: bool = False  # --view: the world waits at tick 0 until the page says play
    view_linger: float | None = 0.0  # wall seconds the page stays up after (None: until stopped)

    # The run's plug-ins, resolved here (the built-ins unless --strategy, --pooling or
    # --controller name others): the in-process engine runs them, the robot processes find
    # them again and check their sources against these.
    plugins: Plugins | None = None

    @property
    def page(self) -> Observer | None:
        """The live page, if the run serves one."""
        return next((o for o in self.observers if o.name == "viewer"), None)

    @property
    def external(self) -> list[int]:
        return self.outside.ids if self.outside is not None else []

    @property
    def emulated(self) -> list[int]:
        """The robots the run starts processes for (all but the outside ones)."""
        outside = set(self.external)
        return [robot for robot in range(self.robots) if robot not in outside]

    @property
    def robot_processes(self) -> int:
        """How many processes the robots are started in."""
        return math.ceil(self.robots / self.robots_per_process)

    def world_argv(self) -> list[str]:
        """The world server's run and configuration (its network options come later)."""
        world = dataclasses.replace(self.switches.world, rules=self.ending_rules())
        if self.outside is not None:  # it waits for the outside robots as long as we do
            start = max(world.start_timeout, self.outside.wait + OUTSIDE_START_MARGIN)
            world = dataclasses.replace(world, start_timeout=start)
        if self.hold:
            world = dataclasses.replace(world, hold=True)
        return ["--run-id", self.run_id, "--config", settings.encode(world)]

    def ending_rules(self) -> EndingRules:
        """How the world is to end the run: this run's limits, robots and faults."""
        return EndingRules(
            timeout=self.timeout,
            stall_window=self.stall_window,
            lost_robot=self.lost_robot,
            controller=self.switches.controller,
            byzantine=tuple(
                byzantine.ByzantineRobot(robot, how) for robot, how in self.byzantine_robots.items()
            ),
            # The faults the engine applies stop a robot's process (and a restart starts
            # another): departures the world expects, not losses.
            departures=tuple(
                PlannedDeparture(fault.robot, fault.at, fault.RESTARTS)
                for fault in self.faults
                if fault.BY_ENGINE
            ),
            outside=tuple(
                OutsideRobot(linked.robot, linked.address.transport)
                for linked in (self.outside.robots if self.outside is not None else ())
            ),
        )

    def beacon_argv(self) -> list[str]:
        beacon = NestBeaconConfig(seed=self.seed, beacon=self.switches.beacon)
        return ["--run-id", self.run_id, "--config", settings.encode(beacon)]

    def robot_argv(self, robots: Sequence[int]) -> list[str]:
        """A robot process's: the robots it hosts, and its configuration, which names only
        its own robots' Byzantine behaviour."""
        hosted = tuple(
            byzantine.ByzantineRobot(robot, self.byzantine_robots[robot])
            for robot in robots
            if robot in self.byzantine_robots
        )
        own = tuple(
            fault.spec for fault in self.faults if fault.robot in robots and not fault.BY_ENGINE
        )
        plugins = self.plugins or builtin_plugins(self.switches.controller)
        choice = ControllerChoice(self.switches.plugins.controller, plugins.sources())
        agent = RobotAgentConfig(
            self.seed, self.switches.controller, hosted, plugins=choice, faults=own
        )
        ids = [arg for robot in robots for arg in ("--id", str(robot))]
        batching = [] if self.batch else ["--no-batch"]
        return [*ids, *batching, "--run-id", self.run_id, "--config", settings.encode(agent)]

    def trace_args(self, process: str) -> list[str]:
        """``--trace DIR/<process>.jsonl`` for a process, when tracing."""
        return [] if self.trace is None else ["--trace", str(self.trace / f"{process}.jsonl")]


# Launcher options that shape no run: kept out of its recorded configuration.
NOT_CONFIG = {
    "module",
    "command",
    "json",
    "quiet",
    "verbose",
    "trace",
    "no_batch",
    "link_keys",  # where the outside robots' keys go
    "dask",  # recorded only when given (where the robots ran)
    "dask_world",
    *VIEW_OPTIONS,
}


def plan_from_args(args: argparse.Namespace) -> RunPlan:
    """The run the options ask for; ValueError (a usage error) if they do not fit."""
    if args.engine == "inprocess":
        refuse_unsupported(args)
    run_id = args.run_id or f"run-{args.seed}-{int(time.time() * 1000) % 10**9}"
    switches = run_switches(
        args, run_id=run_id, seed=args.seed, sites=args.sites, robots=args.robots
    )
    robot_faults = switches.faults
    faults = sorted(robot_faults.robot_faults(), key=lambda fault: fault.at)
    for fault in faults:
        if fault.robot >= args.robots:
            raise ValueError(
                f"--{fault.SWITCH} {fault.robot}@...: there is no robot "
                f"{fault.robot} in a swarm of {args.robots}"
            )
    byzantine_robots = byzantine_plan(robot_faults.byzantine, args.robots, args.sites, args.seed)
    # The plug-ins, found now: one that does not resolve, or is of another kind, is a usage
    # error before anything starts (PluginError is a ValueError).
    plugins = registry.resolve_plugins(switches.controller, switches.plugins.controller)
    outside = outside_plan(args, args.robots)
    for robot in outside.ids if outside is not None else []:
        for fault in faults:
            if fault.robot == robot:
                raise ValueError(f"--{fault.SWITCH} {robot}@...: the robot is outside")
        if robot in byzantine_robots:
            raise ValueError(f"--byzantine {robot}: the robot is outside; its program decides")
    # Over Zenoh, a fault the engine applies acts on one robot's process: one robot per
    # process unless told otherwise.
    on_processes = [fault for fault in faults if fault.BY_ENGINE]
    per_process = args.robots_per_process or (
        1 if on_processes else default_robots_per_process(args.robots)
    )
    if on_processes and per_process > 1 and args.engine != "inprocess":
        raise ValueError(
            f"--{on_processes[0].SWITCH} acts on one robot's process: use it with "
            "--robots-per-process 1"
        )
    if args.view is None and (args.no_wait or args.view_linger is not None):
        raise ValueError("--no-wait and --view-linger go with --view")
    connect = args.connect
    if args.dask_world is not None and args.dask is None:
        raise ValueError("--dask-world names a worker of the cluster --dask gives: give --dask")
    if args.dask is not None:
        refuse_on_dask(args, on_processes)
        # The world, beacon and recorder are clients of this host's router, as the robots
        # are of their hosts' (deploy/launcher/dask_worker.py).
        connect = connect or os.environ.get(ROUTER_ENV) or LOCAL_ENDPOINT
    elif args.secure and args.connect:
        raise ValueError("--secure makes the run's own TLS router: it cannot use --connect")
    if args.secure and args.no_keys:
        raise ValueError("--secure authenticates every message: it cannot go with --no-keys")
    record = None if args.no_record else Path(args.record or f"runs/{run_id}.mcap")
    if record is not None:
        check_recording_path(record)
    if args.trace is not None:
        try:  # now, so that a bad --trace is a usage error, not a crashed world server
            make_private_folder(args.trace)
        except OSError as error:
            raise ValueError(f"--trace {args.trace}: {error.strerror}") from None
    arena_radius = make_layout(args.sites, args.robots, args.seed).arena_radius
    stall_window = args.stall_window or default_stall_window(
        arena_radius,
        EPUCK.max_wheel_speed,
        # The longest leg a robot may take before it gives up: across the arena.
        switches.controller.leg_allowance(2 * arena_radius),
        switches.beacon.outages,
        time_limit=args.timeout,
    )
    world_stop_window = args.world_stop_window or default_world_stop_window(
        switches.world.stall_timeout
    )
    # The run's configuration as its summary and recording keep it: the launcher's own
    # options and every setting in force, keyed like the options.
    launcher_options = {
        key: value
        for key, value in vars(args).items()
        if key not in NOT_CONFIG and not any(key in options.dests for options in SWITCHES)
    }
    config = {**launcher_options, **switches.record()}
    config["run_id"] = run_id
    config["stall_window"] = stall_window  # the one in force, also when defaulted
    config["world_stop_window"] = world_stop_window
    config["byzantine"] = [f"{robot}:{how}" for robot, how in byzantine_robots.items()]
    config["links"] = (
        [f"{linked.robot}={linked.address}" for linked in outside.robots] if outside else []
    )
    config["plugins"] = plugins.record()  # what made the run: names, versions, sources
    if args.dask is not None:
        config["dask"] = args.dask
    if args.dask_world is not None:
        config["dask_world"] = args.dask_world
    recorded = RunDescription(run_id, args.seed, args.robots, args.sites, config)
    recorder_args = [
        "--run-id",
        run_id,
        "--out",
        str(record),
        "--config",
        settings.encode(recorded),
        "--niceness",
        str(recorder_niceness(args.robots)),
    ]
    common = ["--run-id", run_id, "--seed", str(args.seed)]
    return RunPlan(
        run_id=run_id,
        robots=args.robots,
        sites=args.sites,
        seed=args.seed,
        timeout=args.timeout,
        stall_window=stall_window,
        world_stop_window=world_stop_window,
        connect=connect,
        record=record,
        switches=switches,
        recorder_args=recorder_args,
        faults=faults,
        config=config,
        robots_per_process=per_process,
        batch=not args.no_batch,
        byzantine_robots=byzantine_robots,
        spawn=args.spawn,
        observers=observers(args, common, free_port(), free_port()),
        wall_timeout=args.wall_timeout,
        keyed=not args.no_keys,
        secure=args.secure,
        trace=args.trace,
        outside=outside,
        # A lost host takes its robots with it: the run has no result left to wait for.
        lost_robot=LostRobot.END if args.dask is not None else LostRobot.CONTINUE,
        dask=args.dask,
        dask_world=args.dask_world,
        hold=holds(args),
        view_linger=view_linger(args),
        plugins=plugins,
    )


def refuse_on_dask(args: argparse.Namespace, on_processes: Sequence[RobotFault]) -> None:
    """ValueError naming the first option that cannot go with ``--dask`` (``on_processes``:
    the faults the launcher applies to a robot's process)."""
    if not args.dask.startswith(("tcp://", "tls://", "ws://", "wss://")):
        raise ValueError(f"--dask {args.dask}: give a scheduler address, tcp://HOST:PORT")
    refused = [
        *(
            (True, f"--{fault.SWITCH}", "it acts on a robot's process on this machine")
            for fault in on_processes[:1]
        ),
        (args.external is not None, "--external", "the bridge serves robots on this machine"),
        (args.trace is not None, "--trace", "the robots' timelines would stay on the workers"),
        (args.robots_per_process is not None, "--robots-per-process", "the workers' cores say"),
        (args.secure and args.no_keys, "--no-keys", "--secure tags every message"),
    ]
    for refuse, option, why in refused:
        if refuse:
            raise ValueError(f"{option} cannot go with --dask: {why}")


def check_recording_path(path: Path) -> None:
    """ValueError unless a recording can be written at ``path``: say so now, not after the
    run (the recorder would fail to open it, and the launcher would report a crash)."""
    target = path.absolute()
    if target.is_dir():
        raise ValueError(f"--record {path}: is a directory")
    if target.exists():
        if not os.access(target, os.W_OK):
            raise ValueError(f"--record {path}: the file is not writable")
        return
    existing = target.parent
    while not existing.exists():  # the launcher creates the missing directories
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"--record {path}: {existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"--record {path}: no permission to write in {existing}")


def byzantine_plan(
    switches: Sequence[byzantine.ByzantineRobot], robots: int, sites: int, seed: int
) -> dict[int, byzantine.Behaviour]:
    """The ``--byzantine`` robots with their liars' sites chosen; ValueError: usage."""
    chosen: dict[int, byzantine.Behaviour] = {}
    for switch in switches:
        if switch.robot >= robots:
            raise ValueError(
                f"--byzantine {switch}: there is no robot {switch.robot} in a swarm of {robots}"
            )
        if switch.robot in chosen:
            raise ValueError(f"--byzantine names robot {switch.robot} twice")
        chosen[switch.robot] = switch.behaviour
    best = make_layout(sites, robots, seed).best_site
    try:
        resolved = byzantine.resolve_liar_sites(chosen, sites, best, seed)
    except ValueError as error:
        raise ValueError(f"--byzantine: {error}") from None
    return dict(sorted(resolved.items()))


def default_robots_per_process(robots: int, cores: int | None = None) -> int:
    """One robot per process up to ONE_PROCESS_PER_ROBOT_UP_TO robots; a larger swarm in
    ROBOT_PROCESSES_PER_CORE processes per core of at least ROBOTS_PER_PROCESS robots each,
    which measured faster on a 2-core machine (docs/performance.md)."""
    if robots <= ONE_PROCESS_PER_ROBOT_UP_TO:
        return 1
    cores = cores or os.cpu_count() or 1
    spread = math.ceil(robots / (ROBOT_PROCESSES_PER_CORE * cores))
    return max(1, min(robots, max(ROBOTS_PER_PROCESS, spread)))


def recorder_niceness(robots: int) -> int:
    """The recorder's CPU priority. A swarm of one robot process leaves idle time in
    which a low-priority recorder catches up, and costs less with it (docs/recording.md).
    A larger one keeps the cores busy: a recorder at nice 10 then gets so little CPU that
    it falls behind by more than the 256 MiB it may hold and drops samples (200 robots,
    two runs at a time: 29% of the senses); at normal priority it kept every one."""
    return DEFAULT_NICENESS if robots <= NICE_RECORDER_UP_TO else 0


def refuse_unsupported(args: argparse.Namespace) -> None:
    """ValueError naming the first option of ``args`` the in-process engine cannot honour."""
    refused = [
        (args.clock == "realtime", "--clock realtime", "it runs in lockstep only"),
        (args.robots_per_process is not None, "--robots-per-process", "there are no processes"),
        (args.no_batch, "--no-batch", "there are no processes"),
        (args.spawn != "fork", "--spawn", "there are no processes to start"),
        (args.connect is not None, "--connect", "it uses no network"),
        (args.dask is not None, "--dask", "it runs in this process"),
        (args.secure, "--secure", "it uses no network"),
        (args.view is not None, "--view", "the live page follows a run over Zenoh"),
        (args.foxglove is not None, "--foxglove", "Foxglove live follows a run over Zenoh"),
        (args.trace is not None, "--trace", "the timeline is of the processes' messages"),
        (bool(args.external), "--external", "no program outside can reach it"),
    ]
    for refuse, option, reason in refused:
        if refuse:
            raise ValueError(f"--engine inprocess cannot honour {option}: {reason}")
