"""``swarm run``: a whole swarm on this machine, to a stated ending.

Starts the world server (the Zenoh router of the run, on a free loopback port), the nest
beacon and the robot processes; watches their status over Zenoh; shows progress; stops
every process it started, by pid, however the run ends; prints a summary that says how
it ended (``deploy/summary.py``: consensus, split, stalled, timeout, interrupted,
crashed), and exits with that ending's code (wire/endings.py).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh
from rich.console import Console
from rich.table import Table

from deploy import zenoh_acl
from deploy.credentials import RunNetwork
from deploy.inprocess import add_engine_option, refuse_unsupported, run_inprocess
from deploy.processes import Child, ProcessGroup, free_port, python_module, wait_for_port
from deploy.run_progress import decided_progress
from deploy.run_switches import SWITCHES, RunSwitches, add_swarm_switches, run_switches
from deploy.summary import RobotRecord, RunOutcome, build_summary, describe
from deploy.watchdog import Watchdog, default_stall_window
from nest_beacon.node.options import NestBeaconConfig
from plumbing import cliargs
from plumbing.cliargs import UsageError
from plumbing.inbox import BoundedInbox
from plumbing.lifecycle import die_with_launcher
from plumbing.world_info import ask, fetch_world_info
from plumbing.zenoh_session import open_session
from robot_agent.core import byzantine
from robot_agent.node.options import RobotAgentConfig
from viewer.options import VIEW_OPTIONS, Observer, add_view_options, observers
from wire import auth, names, protocol, settings, shape
from wire.endings import Ending, Halt, Look, Stop, exit_codes_help, stop_reason
from wire.names import Role
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.recording.writer import DEFAULT_NICENESS, RunDescription

log = logging.getLogger("swarm.run")
STATS_ATTEMPTS, STATS_RETRY_PAUSE = 5, 0.2

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
CONNECT_WAIT = 5.0  # wall seconds to wait for the router given by --connect
# Robot processes exchange one batch of senses and acts per tick with the world, so fewer,
# fuller processes are faster: a process carries at least ROBOTS_PER_PROCESS robots (all of
# a small swarm), and larger swarms spread over ROBOT_PROCESSES_PER_CORE per core
# (benchmarks/swarm_speed.py, docs/performance.md).
ROBOTS_PER_PROCESS = 25
ROBOT_PROCESSES_PER_CORE = 2
RUN_ID_ENV = "BESTOFN_RUN_ID"
# Waiting for the recorder after the run: given up once its file has not grown for
# RECORDER_PATIENCE wall seconds, and after RECORDER_LONGEST_WAIT in any case.
RECORDER_PATIENCE = 60.0
RECORDER_LONGEST_WAIT = 3600.0
RECORDER_REPORT_EVERY = 10.0
# Processes that only watch: they stay to the end, and their crash does not end the run.
OBSERVERS = ("viewer", "foxglove")
# Each observer's certificate in secure mode: a reader with its own token (and the page
# its finish queryable), nothing else.
OBSERVER_CERTIFICATES = {"viewer": zenoh_acl.VIEWER, "foxglove": zenoh_acl.FOXGLOVE}
# What the launcher takes in (status, clock, state, acks), at most: junk cannot grow it.
EVENTS_BYTES, MAX_EVENT_BYTES = 64 * 2**20, protocol.MAX_PAYLOAD_BYTES + 1024


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = exit_codes_help()
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    swarm = parser.add_argument_group("swarm")
    cliargs.add_run_shape(swarm)
    add_engine_option(swarm)
    swarm.add_argument(
        "--run-id",
        type=cliargs.name,
        default=None,
        help="names this swarm on the network (default: run-<seed>-<time>)",
    )
    swarm.add_argument(
        "--timeout",
        type=cliargs.positive_float,
        default=shape.DEFAULT_TIMEOUT,
        metavar="SIM_SECONDS",
        help=f"give up after this much sim time (default: {shape.DEFAULT_TIMEOUT:g})",
    )
    swarm.add_argument(
        "--wall-timeout",
        type=cliargs.positive_float,
        default=None,
        metavar="SECONDS",
        help="give up after this much wall time since the launch, so that an unattended "
        "sweep cannot hang (default: no limit)",
    )
    swarm.add_argument(
        "--stall-window",
        type=cliargs.positive_float,
        default=None,
        metavar="SIM_SECONDS",
        help="end the run as stalled when no undecided robot made progress (a leg, a "
        "comparison, a pooling, or two body lengths of travel) for this much sim time "
        "(default: twice the time a robot may take for a leg across the arena, plus two "
        "arena crossings at full speed, plus any --beacon-outage)",
    )
    add_swarm_switches(parser)
    processes = parser.add_argument_group("processes")
    processes.add_argument(
        "--robots-per-process",
        type=cliargs.int_range(1, 1000),
        default=None,
        metavar="K",
        help="host K robots in each robot process, each robot still with "
        "its own Zenoh session, keys and RNG (default: chosen from the "
        "swarm size and the cores)",
    )
    processes.add_argument(
        "--no-batch",
        action="store_true",
        help="a process hosting several robots answers on each robot's own keys, one message "
        "per robot per tick, instead of one batch per tick (docs/protocol.md); for comparison",
    )
    processes.add_argument(
        "--spawn",
        choices=["fork", "exec"],
        default="fork",
        help="start robot processes by forking a preloaded server (fast) "
        "or as fresh interpreters (default: fork)",
    )
    network = parser.add_argument_group("network")
    network.add_argument(
        "--connect",
        type=cliargs.endpoint,
        default=None,
        metavar="ENDPOINT",
        help="use this existing Zenoh router instead of making the world "
        "server the router of the run (several runs can share one router)",
    )
    network.add_argument(
        "--secure",
        action="store_true",
        help="TLS on loopback with certificates made for this run, and Zenoh access "
        "control: each process may publish only on its own keys (docs/security.md)",
    )
    network.add_argument(
        "--no-keys",
        action="store_true",
        help="do not tag and check messages with run keys (every message is believed, "
        "as before run keys; for measuring what they cost)",
    )
    output = parser.add_argument_group("output")
    recording = output.add_mutually_exclusive_group()
    recording.add_argument(
        "--record",
        metavar="PATH",
        default=None,
        help="MCAP recording of the run (default: runs/<run-id>.mcap)",
    )
    recording.add_argument("--no-record", action="store_true", help="do not record the run")
    output.add_argument(
        "--json", action="store_true", help="print one JSON object with the summary on stdout"
    )
    output.add_argument("--quiet", action="store_true", help="no progress display")
    output.add_argument("--verbose", action="store_true", help="echo the processes' logs on stderr")
    output.add_argument(
        "--trace",
        type=Path,
        default=None,
        metavar="DIR",
        help="write each tick's timeline to DIR: world.jsonl from the world server, "
        "robot-<ids>.jsonl from each robot process (benchmarks/tick_timeline.py reads them; "
        "docs/performance.md)",
    )
    add_view_options(parser.add_argument_group("watching"))


@dataclass(frozen=True)
class Fault:
    robot: int
    action: str  # kill | restart
    at: float  # sim seconds


@dataclass
class RunPlan:
    """Everything needed to start one run, derived from the command line."""

    run_id: str
    robots: int
    sites: int
    seed: int
    timeout: float
    stall_window: float
    connect: str | None  # an existing router; None: the world server is the run's router
    record: Path | None
    switches: RunSwitches  # the world's, the robots' and the beacon's configs
    recorder_args: list[str] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
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

    def world_argv(self) -> list[str]:
        """The world server's run and configuration (its network options come later)."""
        return ["--run-id", self.run_id, "--config", settings.encode(self.switches.world)]

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
        agent = RobotAgentConfig(self.seed, self.switches.controller, hosted)
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
    faults = sorted(
        [Fault(robot, "kill", at) for robot, at in robot_faults.kill]
        + [Fault(robot, "restart", at) for robot, at in robot_faults.restart],
        key=lambda fault: fault.at,
    )
    for fault in faults:
        if fault.robot >= args.robots:
            raise ValueError(
                f"--{fault.action} {fault.robot}@...: there is no robot "
                f"{fault.robot} in a swarm of {args.robots}"
            )
    byzantine_robots = byzantine_plan(robot_faults.byzantine, args.robots, args.sites, args.seed)
    # A fault acts on one robot's process: one robot per process unless told otherwise.
    per_process = args.robots_per_process or (
        1 if faults else default_robots_per_process(args.robots)
    )
    if faults and per_process > 1:
        raise ValueError(
            "--kill and --restart act on one robot's process: use them with --robots-per-process 1"
        )
    if args.secure and args.connect:
        raise ValueError("--secure makes the run's own TLS router: it cannot use --connect")
    if args.secure and args.no_keys:
        raise ValueError("--secure authenticates every message: it cannot go with --no-keys")
    record = None if args.no_record else Path(args.record or f"runs/{run_id}.mcap")
    if record is not None:
        check_recording_path(record)
    if args.trace is not None:
        try:  # now, so that a bad --trace is a usage error, not a crashed world server
            args.trace.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise ValueError(f"--trace {args.trace}: {error.strerror}") from None
    arena_radius = make_layout(args.sites, args.robots, args.seed).arena_radius
    stall_window = args.stall_window or default_stall_window(
        arena_radius,
        EPUCK.max_wheel_speed,
        # The longest leg a robot may take before it gives up: across the arena.
        switches.controller.leg_allowance(2 * arena_radius),
        switches.beacon.outages,
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
    config["byzantine"] = [f"{robot}:{how}" for robot, how in byzantine_robots.items()]
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
        connect=args.connect,
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
    )


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
    """All of a small swarm in one process; larger ones in ROBOT_PROCESSES_PER_CORE
    processes per core of at least ROBOTS_PER_PROCESS robots each, which measured fastest
    on a 2-core machine once senses and acts travel in batches (docs/performance.md)."""
    cores = cores or os.cpu_count() or 1
    spread = math.ceil(robots / (ROBOT_PROCESSES_PER_CORE * cores))
    return max(1, min(robots, max(ROBOTS_PER_PROCESS, spread)))


class Swarm:
    """One local run: its processes, its observer session, its progress."""

    def __init__(self, plan: RunPlan, echo: Callable[[str, str], None] | None = None) -> None:
        self.plan = plan
        self.keys = protocol.Keys(plan.run_id)
        self.echo = echo
        self.group = ProcessGroup(self._on_log_line)
        self.records = {robot: RobotRecord(robot) for robot in range(plan.robots)}
        self.watchdog = Watchdog(
            range(plan.robots), plan.stall_window, body_length=2 * EPUCK.radius
        )
        self.robot_children: dict[int, Child] = {}
        self.world: Child | None = None
        self.recorder: Child | None = None
        self.recording_problem = "it was not running"
        self.network: RunNetwork | None = None  # made when the run starts
        self.events: BoundedInbox[tuple[str, str, bytes, bytes | None]] = BoundedInbox(
            EVENTS_BYTES, MAX_EVENT_BYTES
        )
        self.beacon_rejected: dict[str, int] = {}  # the beacons' own counts, from their acks
        self._logged_rejections: set[str] = set()
        self.session: zenoh.Session | None = None
        self._declared: list[Any] = []
        self.sim_time = 0.0
        self.launched_at = time.monotonic()
        self.started_at: float | None = None
        self.ended_at: float | None = None
        self.last_state: protocol.WorldState | None = None
        self.rejected = 0  # invalid messages the launcher itself received
        self.final_stats: protocol.WorldState | None = None
        # Departures the world counted before the run was stopped (stopping makes more).
        self.departures = 0
        self.pending_faults = list(plan.faults)
        self.fault_log: list[dict[str, Any]] = []
        # Log lines from before the recorder listens, held back so that the recording has
        # them too (None: pass lines straight on). Reader threads append; hence the lock.
        self._held_logs: list[protocol.LogLine] | None = [] if plan.record else None
        self._log_lock = threading.Lock()

    def _on_log_line(self, process: str, line: str) -> None:
        """Echo a child's log line, and publish it so that the recorder keeps it."""
        if self.echo is not None:
            self.echo(process, line)
        if not line:
            return
        message = protocol.LogLine(
            v=protocol.VERSION, process=process, wall_time=time.time(), line=line[:4096]
        )
        with self._log_lock:
            if self._held_logs is not None:
                self._held_logs.append(message)
                return
        self._publish_log(message)

    def _publish_log(self, message: protocol.LogLine) -> None:
        session = self.session
        if session is not None:
            key, payload = self.keys.log(message.process), protocol.encode(message)
            with contextlib.suppress(zenoh.ZError):
                session.put(key, payload, attachment=self._seal(names.LAUNCHER, key, payload))

    @property
    def keyring(self) -> auth.Keyring | None:
        return self.network.keyring if self.network is not None else None

    def _seal(self, identity: str, key: str, payload: bytes) -> bytes | None:
        return auth.seal(self.keyring, identity, key, payload)

    def _release_held_logs(self) -> None:
        """Publish the lines held back until the recorder listened, in their order."""
        with self._log_lock:
            held, self._held_logs = self._held_logs or [], None
            for message in held:  # under the lock, so no newer line overtakes them
                self._publish_log(message)

    # --- start -----------------------------------------------------------------------

    def start(self) -> None:
        plan = self.plan
        # Every process of the run carries its id in its environment (forked robots have
        # no command line of their own), so it can be found by run id, e.g. by tests.
        os.environ[RUN_ID_ENV] = plan.run_id
        if plan.connect is not None:
            wait_for_router(plan.connect)
        self.network = network = RunNetwork.create(
            plan.run_id, plan.robots, connect=plan.connect, keyed=plan.keyed, secure=plan.secure
        )
        world = self.group.start(
            "world",
            python_module(
                "world_server.server",
                *plan.world_argv(),
                *network.world_args(),
                *plan.trace_args("world"),
            ),
            env=network.env(),
        )
        self.world = world
        if not network.wait_for_router(30.0, world.alive):
            raise StartError("the world server did not start", world)
        config = network.config_of(zenoh_acl.LAUNCHER)
        opening = time.monotonic()
        try:
            self.session = open_session(
                "client", [network.endpoint], config_file=str(config) if config else None
            )
        except zenoh.ZError as error:
            raise StartError(
                f"could not connect to {network.endpoint} (tried for "
                f"{time.monotonic() - opening:.0f} s): {str(error).split(' at ')[0]}"
            ) from None
        try:
            fetch_world_info(self.session, self.keys, 30.0, self.keyring, names.LAUNCHER)
        except TimeoutError as error:
            raise StartError(str(error), world) from None
        watched = {
            "status": self.keys.status("*"),
            "clock": self.keys.world_clock,
            "state": self.keys.world_state,
            "ack": self.keys.beacon_ack("*"),
        }
        self._declared = [
            self.session.declare_subscriber(key, self._on(kind)) for kind, key in watched.items()
        ]
        if plan.record is not None:
            plan.record.parent.mkdir(parents=True, exist_ok=True)
            self.recorder = self.group.start(
                "recorder",
                python_module(
                    "world_server.recorder",
                    *plan.recorder_args,
                    *network.client_args(zenoh_acl.RECORDER),
                ),
                env=network.env(),
            )
            if not self._wait_alive(Role.RECORDER, 0, 30.0, self.recorder):
                raise StartError("the recorder did not start", self.recorder)
            self._release_held_logs()
        self._start_observers()
        beacon = names.beacon_certificate(names.DEFAULT_BEACON)
        self.group.start(
            "beacon",
            python_module("nest_beacon", *plan.beacon_argv(), *network.client_args(beacon)),
            env=network.env(),
        )
        hosts = range(0, plan.robots, plan.robots_per_process)
        for first in hosts:
            robots = list(range(first, min(first + plan.robots_per_process, plan.robots)))
            child = self._start_robots(robots)
            for robot in robots:
                self.robot_children[robot] = child

    def _start_observers(self) -> None:
        """The page and Foxglove live: listening before the robots start, like the recorder."""
        network = self.network
        assert network is not None
        for observer in self.plan.observers:
            identity = OBSERVER_CERTIFICATES[observer.name]
            argv = [*observer.argv, *network.client_args(identity)]
            child = self.group.start(
                observer.name, python_module(observer.module, *argv), env=network.env()
            )
            if not self._wait_alive(observer.role, 0, 30.0, child):
                raise StartError(f"the {observer.name} did not start", child)
            print(f"swarm run: {observer.name} at {observer.url}", file=sys.stderr, flush=True)

    def finish_observers(self, summary: dict[str, Any]) -> None:
        """Tell the page how the run ended; it answers once every page was sent that."""
        if self.session is None or not any(o.name == "viewer" for o in self.plan.observers):
            return
        payload = json.dumps(summary).encode()
        with contextlib.suppress(zenoh.ZError):  # sealed: the view believes only the launcher
            ask(
                self.session,
                self.keys.viewer_finish,
                self.keyring,
                names.LAUNCHER,
                payload=payload,
                timeout=5.0,
            )

    def _on(self, kind: str) -> Callable[[zenoh.Sample], None]:
        def callback(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            size = len(payload) + len(extra or b"")
            self.events.put((kind, str(sample.key_expr), payload, extra), size)

        return callback

    def _wait_alive(self, role: Role, ident: int | str, timeout: float, child: Child) -> bool:
        """Wait for a liveliness token, as long as the process that should declare it lives."""
        assert self.session is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and child.alive():
            if list(self.session.liveliness().get(self.keys.alive(role, ident), timeout=1.0)):
                return True
            time.sleep(0.05)
        return False

    # --- watch -----------------------------------------------------------------------

    def poll(self) -> None:
        """Take in everything that arrived; note crashed robots."""
        while True:
            try:
                event = self.events.get(timeout=0)
            except queue.Empty:
                break
            try:
                self._take(*event)
            except (protocol.ProtocolError, auth.AuthError) as error:
                self.rejected += 1
                if event[0] not in self._logged_rejections:  # once per kind of message
                    self._logged_rejections.add(event[0])
                    log.warning("rejected a message on %s: %s", event[1], error)
        self.rejected += self.events.take_dropped(None)
        for robot, child in self.robot_children.items():
            if not child.alive() and not child.expected_exit:
                self.records[robot].crashed = True
                self.watchdog.retired(robot)

    def _take(self, kind: str, key: str, payload: bytes, attachment: bytes | None) -> None:
        """Believe one status, clock, state or beacon ack, if its sender's tag says so."""
        keyring = self.keyring
        if kind == "status":
            robot = self.keys.robot_of(key)
            if robot not in self.records:
                raise protocol.ProtocolError(f"no robot {robot} in this run")
            auth.unseal(keyring, names.robot_identity(robot), key, payload, attachment)
            status = protocol.decode(payload, protocol.Status)
            if status.id != robot:
                raise protocol.ProtocolError(f"status of robot {status.id} on {key}")
            record = self.records[robot]
            if record.status and status.tick < record.status.tick and not record.restarting:
                # Authentic but old: someone replaying what it heard, not the robot.
                raise protocol.ProtocolError(f"status of tick {status.tick}, older than the last")
            record.update(status)
            self.watchdog.status(status)
            self.watchdog.status(status)
        elif kind == "ack":
            identity = names.beacon_identity(key.rsplit("/", 2)[-2])
            try:
                names.check_identity(identity)
            except ValueError as error:
                raise protocol.ProtocolError(str(error)) from None
            auth.unseal(keyring, identity, key, payload, attachment)
            name = identity.partition("/")[2]
            ack = protocol.decode(payload, protocol.Ack)
            self.beacon_rejected[name] = max(self.beacon_rejected.get(name, 0), ack.rejected)
        else:
            auth.unseal(keyring, names.WORLD, key, payload, attachment)
            if kind == "clock":
                clock = protocol.decode(payload, protocol.Clock)
                if self.started_at is None:
                    self.started_at = time.monotonic()
                self.sim_time = clock.t
            else:
                state = protocol.decode(payload, protocol.WorldState)
                self.last_state = state
                self.watchdog.poses(state.t, ((pose.id, pose.x, pose.y) for pose in state.robots))

    def apply_faults(self) -> None:
        """Kill and restart robots whose time has come (in sim time)."""
        while self.pending_faults and self.pending_faults[0].at <= self.sim_time:
            fault = self.pending_faults.pop(0)
            child = self.robot_children[fault.robot]
            was_alive = child.alive()
            self.group.kill(child)
            record = self.records[fault.robot]
            record.killed = fault.action == "kill"
            self.watchdog.retired(fault.robot)
            if fault.action == "restart":
                record.restarted()
                self.watchdog.restarted(fault.robot, self.sim_time)
                self.robot_children[fault.robot] = self._start_robots([fault.robot])
            self.fault_log.append(
                {
                    "robot": fault.robot,
                    "action": fault.action,
                    "at_s": fault.at,
                    "applied_at_s": round(self.sim_time, 3),
                    "was_running": was_alive,
                }
            )
            log.info("%s robot %d at sim time %.1f", fault.action, fault.robot, self.sim_time)

    def _start_robots(self, robots: list[int]) -> Child:
        """One process for ``robots`` (each with its own Zenoh session inside it)."""
        name = f"robot-{robots[0]}" + (f"-{robots[-1]}" if len(robots) > 1 else "")
        network = self.network
        assert network is not None
        # In secure mode each hosted robot's session presents its own certificate: '{id}'.
        argv = [
            *self.plan.robot_argv(robots),
            *network.client_args(names.robot_certificate("{id}")),
        ]
        argv += self.plan.trace_args(name)
        # Only the keys of its own robots: whatever it says can only be in their names.
        env = network.env(names.robot_identity(robot) for robot in robots)
        if self.plan.spawn == "fork":
            return self.group.fork(name, "robot_agent.node.robot_node", argv, env=env)
        return self.group.start(name, python_module("robot_agent.node", *argv), env=env)

    def infrastructure_crash(self) -> Child | None:
        for child in self.group.crashed():
            if not child.name.startswith("robot-") and child.name not in OBSERVERS:
                return child
        return None

    def live_robots(self) -> list[int]:
        return [robot for robot, child in self.robot_children.items() if child.alive()]

    def decided(self) -> int:
        return sum(1 for record in self.records.values() if record.decided_site is not None)

    def restart_pending(self) -> bool:
        return any(fault.action == "restart" for fault in self.pending_faults)

    def all_live_decided(self) -> bool:
        """Every running robot has decided, and no restart is still to come."""
        if self.restart_pending():
            return False
        return all(
            self.records[robot].decided_site is not None
            for robot in self.live_robots()
            if robot not in self.plan.byzantine_robots
        )

    def last_decision_time(self) -> float:
        """The sim time at which the last running robot decided (0 if none did)."""
        return max(
            (
                status.decision_time or 0.0
                for robot in self.live_robots()
                if (status := self.records[robot].status) is not None
            ),
            default=0.0,
        )

    def stalled(self) -> bool:
        """No undecided robot made progress for the stall window (a restart to come will)."""
        return (
            self.started_at is not None
            and not self.restart_pending()
            and self.watchdog.stalled(self.sim_time)
        )

    def trips(self) -> int:
        return sum(record.status.trips for record in self.records.values() if record.status)

    # --- stop ------------------------------------------------------------------------

    def stop_swarm(self) -> protocol.WorldState | None:
        """Stop the robots and the beacon, and read the world's final counters.

        Safe to call again: later calls return the counters read by the first.
        """
        if self.ended_at is not None:
            return self.final_stats
        self.ended_at = time.monotonic()
        if self.world is not None and self.world.alive():
            before = self._query_world_stats() or self.last_state
            self.departures = before.departures if before else 0
        swarm = [
            child
            for child in self.group.children
            if child.name not in ("world", "recorder", *OBSERVERS)
        ]
        self.group.stop(swarm)
        self.poll()
        world_running = self.session is not None and self.world is not None and self.world.alive()
        self.final_stats = (self._world_stats() if world_running else None) or self.last_state
        return self.final_stats

    def _world_stats(self) -> protocol.WorldState | None:
        """The world's final counters. Asked again on no answer: once in a few 100-robot
        runs the query came back empty at once while a hundred sessions were closing."""
        for _ in range(STATS_ATTEMPTS):
            stats = self._query_world_stats()
            if stats is not None:
                return stats
            time.sleep(STATS_RETRY_PAUSE)
        log.warning(
            "the world did not answer on world/stats; the summary's counters are "
            "those of its last world/state"
        )
        return None

    def _query_world_stats(self) -> protocol.WorldState | None:
        if self.session is None:
            return None
        try:
            answers, _ = ask(
                self.session, self.keys.world_stats, self.keyring, names.LAUNCHER, timeout=2.0
            )
            for answer in answers:
                return protocol.decode(answer, protocol.WorldState)
        except (zenoh.ZError, protocol.ProtocolError):
            return None
        return None

    def finish_recording(
        self, summary: dict[str, Any], say: Callable[[str], None] | None = None
    ) -> bool:
        """Hand the summary to the recorder and wait until the file is complete: as long as
        the recorder is alive and its file grows (it writes what it fell behind on first)."""
        if self.session is None or self.recorder is None or not self.recorder.alive():
            return False
        assert self.plan.record is not None  # a recorder runs only with a file to write
        waiting = RecorderProgress(self.plan.record, self.recorder.alive, say)
        payload = json.dumps(summary).encode()
        key = self.keys.recorder_finish
        answers, _ = ask(
            self.session,
            key,
            self.keyring,
            names.LAUNCHER,
            payload=payload,
            timeout=RECORDER_LONGEST_WAIT,
            worth_waiting=waiting,
        )
        if not answers:
            self.recording_problem = waiting.why_not()
        return bool(answers)

    def close(self) -> None:
        """Stop every process still running and close the observer session."""
        swarm = [child for child in self.group.children if child.name not in ("world", "recorder")]
        self.group.stop(swarm)  # the robots first: the world stays their barrier meanwhile
        if self.session is not None:
            for entity in self._declared:
                entity.undeclare()
            self.session.close()
            self.session = None
        self.group.stop_all()
        if self.network is not None:
            self.network.close()  # its socket, certificates and keys


def recorder_niceness(robots: int) -> int:
    """The recorder's CPU priority. A swarm of one robot process leaves idle time in
    which a low-priority recorder catches up, and costs less with it (docs/recording.md).
    A larger one keeps the cores busy: a recorder at nice 10 then gets so little CPU that
    it falls behind by more than the 256 MiB it may hold and drops samples (200 robots,
    two runs at a time: 29% of the senses); at normal priority it kept every one."""
    return DEFAULT_NICENESS if robots <= ROBOTS_PER_PROCESS else 0


class RecorderProgress:
    """Whether waiting for the recorder still makes sense: it is alive and its file grew
    within ``RECORDER_PATIENCE`` wall seconds. A recorder at low priority falls behind a
    large swarm (docs/recording.md) and catches up once the swarm stops; ``say`` hears how
    far it got every ``RECORDER_REPORT_EVERY`` seconds."""

    def __init__(
        self,
        path: Path,
        alive: Callable[[], bool],
        say: Callable[[str], None] | None = None,
        patience: float = RECORDER_PATIENCE,
    ) -> None:
        self.path = path
        self.alive = alive
        self.say = say
        self.patience = patience
        self.started = self.grew_at = self.reported_at = time.monotonic()
        self.size = self._size()
        self.died = False

    def _size(self) -> int:
        try:
            return self.path.stat().st_size
        except OSError:
            return 0

    def __call__(self) -> bool:
        now = time.monotonic()
        if not self.alive():
            self.died = True
            return False
        size = self._size()
        if size > self.size:
            self.size, self.grew_at = size, now
        if self.say is not None and now - self.reported_at >= RECORDER_REPORT_EVERY:
            self.reported_at = now
            self.say(
                f"waiting for the recorder to write what it fell behind on: "
                f"{self.size / 2**20:.0f} MB written, {now - self.started:.0f} s so far"
            )
        return now - self.grew_at < self.patience

    def why_not(self) -> str:
        if self.died:
            return "exited before it confirmed the file"
        return (
            f"did not confirm the file: it did not grow for {self.patience:g} s "
            f"({self.size / 2**20:.0f} MB written)"
        )


class StartError(Exception):
    def __init__(self, message: str, child: Child | None = None) -> None:
        super().__init__(message)
        self.child = child


def wait_for_router(endpoint: str, timeout: float = CONNECT_WAIT) -> None:
    """StartError unless the router of ``--connect`` accepts connections within ``timeout``.

    Checked before anything starts: a Zenoh session would otherwise try for half a minute
    and fail with an error that names no cause. Only TCP-based endpoints can be probed
    this way; others are left to the session, which reports its own failure.
    """
    protocol_name, _, rest = endpoint.partition("/")
    if protocol_name not in ("tcp", "tls"):
        return
    address = rest.split("#")[0].split("?")[0]
    host, _, port = address.rpartition(":")
    if not port.isdigit():
        return
    if not wait_for_port(int(port), timeout, lambda: True, host=host.strip("[]")):
        raise StartError(f"no Zenoh router answers at {endpoint} (tried for {timeout:g} s)")


class Interrupted(BaseException):
    """A stop signal reached the launcher: raised in the main thread, like KeyboardInterrupt
    (a BaseException, so that no ``except Exception`` swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class StopSignals:
    """SIGINT, SIGTERM and SIGHUP end a run in order, like Ctrl-C always did.

    The first one raises Interrupted in the main thread. Any later one, and any after
    ``hold()`` (the run is already ending), is only noted: the ending is bounded in time
    (processes get a grace period, then SIGKILL), and cutting it short would lose the
    summary and the recording's end. SIGKILL needs no handler: every child dies with the
    launcher (plumbing/lifecycle.py).
    """

    def __init__(self) -> None:
        self.received: int | None = None
        self._raising = True
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._on_signal)
        return self

    def __exit__(self, *exc_info: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def hold(self) -> None:
        self._raising = False

    def _on_signal(self, signum: int, frame: object) -> None:
        if self.received is not None:
            return
        self.received = signum
        if self._raising:
            self._raising = False
            raise Interrupted(signum)


@dataclass(frozen=True)
class Ended:
    """Why the launcher stopped following the run."""

    halt: Halt
    signum: int | None = None  # the signal that interrupted the run
    crashed: Child | None = None  # the infrastructure process that died


def run(args: argparse.Namespace) -> int:
    if args.engine == "inprocess":
        return run_inprocess(args)
    try:
        plan = plan_from_args(args)
    except ValueError as error:
        raise UsageError(str(error)) from None
    console = Console(stderr=True)
    echo = (
        (lambda name, line: console.print(f"[dim]{name}:[/] {line}", highlight=False))
        if args.verbose
        else None
    )
    # Started by `swarm experiment`: end in order if it dies (a SIGTERM then, see above).
    die_with_launcher()
    swarm = Swarm(plan, echo)
    with StopSignals() as signals:
        try:
            return _run_swarm(swarm, args, console, signals)
        except Interrupted as interrupt:  # between the steps that handle it themselves
            return 128 + interrupt.signum
        finally:
            signals.hold()
            swarm.close()


def _run_swarm(
    swarm: Swarm, args: argparse.Namespace, console: Console, signals: StopSignals
) -> int:
    try:
        swarm.start()
        ending = _watch(swarm, console, quiet=args.quiet)
    except StartError as error:
        signals.hold()
        print(f"swarm run: could not start: {error}", file=sys.stderr)
        if error.child is not None and error.child.tail():
            print(error.child.tail(), file=sys.stderr)
        return Ending.CRASHED.code
    except Interrupted as interrupt:
        ending = Ended(Halt(Stop.INTERRUPTED), signum=interrupt.signum)
    signals.hold()
    return _finish(swarm, args, ending)


def _finish(swarm: Swarm, args: argparse.Namespace, ending: Ended) -> int:
    """Stop the swarm, build and print the summary, finish the recording; the exit code."""
    plan = swarm.plan
    if ending.signum is not None:
        print(
            f"swarm run: {signal.Signals(ending.signum).name}: stopping every process",
            file=sys.stderr,
        )
    if ending.crashed is not None:
        print(
            f"swarm run: the {ending.crashed.name} process crashed (exit code "
            f"{ending.crashed.process.returncode}):\n{ending.crashed.tail()}",
            file=sys.stderr,
        )
    stats = swarm.stop_swarm()
    robot_crashes = [record.id for record in swarm.records.values() if record.crashed]
    stop = ending.halt.stop
    if robot_crashes and stop is not Stop.INTERRUPTED:
        stop = Stop.CRASHED
    wall = (swarm.ended_at or 0.0) - swarm.started_at if swarm.started_at else 0.0
    summary = build_summary(
        RunOutcome(
            run_id=plan.run_id,
            num_robots=plan.robots,
            num_sites=plan.sites,
            seed=plan.seed,
            best_site=make_layout(plan.sites, plan.robots, plan.seed).best_site,
            sim_time_s=swarm.sim_time,
            wall_time_s=wall,
            timed_out=stop is Stop.TIMEOUT,
            radio=stats.radio if stats else protocol.RadioCounters(),
            world_rejected=stats.rejected if stats else 0,
            stalls=stats.stalls if stats else 0,
            departures=swarm.departures,
            observer_rejected=swarm.rejected,
            beacon_rejected=sum(swarm.beacon_rejected.values()),
            config=plan.config,
            stop=stop,
            timeout_kind=ending.halt.limit if stop is Stop.TIMEOUT else None,
            stuck=swarm.watchdog.stuck(),
            byzantine={robot: str(how) for robot, how in plan.byzantine_robots.items()},
        ),
        swarm.records.values(),
    )
    if ending.signum is not None:
        summary["signal"] = signal.Signals(ending.signum).name
    summary["faults"] = swarm.fault_log
    summary["recording"] = str(plan.record) if plan.record else None
    swarm.finish_observers(summary)
    if not args.quiet:
        print(f"swarm run: {describe_ending(summary)}", file=sys.stderr)
    if plan.record is not None and not swarm.finish_recording(summary, _say(args.quiet)):
        print(
            f"swarm run: the recorder did not confirm {plan.record}: {swarm.recording_problem}",
            file=sys.stderr,
        )
        summary["recording"] = None
    if args.json:
        print(json.dumps(summary))
    else:
        print_summary(summary, Console())
    if robot_crashes:
        print(f"swarm run: robot process(es) {robot_crashes} crashed", file=sys.stderr)
    return Ending(summary["ended"]).exit_code(ending.signum)


def _say(quiet: bool) -> Callable[[str], None] | None:
    """A line on stderr from ``swarm run``, or nothing with ``--quiet``."""
    if quiet:
        return None
    return lambda line: print(f"swarm run: {line}", file=sys.stderr, flush=True)


def describe_ending(summary: dict[str, Any]) -> str:
    """One line: how the run ended, and what held it up."""
    ended = Ending.named(summary["ended"])
    at = f"at sim {summary['sim_time_s']:.0f} s"
    stuck = summary.get("stuck") or []
    undecided = f"; {len(stuck)} robot(s) undecided" if stuck else ""
    if ended is Ending.CONSENSUS:
        return f"ended in consensus on site {summary['chosen_site']} {at}"
    if ended is Ending.SPLIT:
        sites = sorted({r["decided_site"] for r in summary["per_robot"]} - {None})
        return f"ended split: the robots decided on different sites ({sites}) {at}"
    if ended is Ending.STALLED:
        window = summary["config"].get("stall_window")
        quiet = f" for {window:g} s of sim time" if window else ""
        return f"ended stalled {at}: no undecided robot made progress{quiet}{undecided}"
    if ended is Ending.TIMEOUT:
        limit = "wall time limit (--wall-timeout)"
        if summary.get("timeout_kind") != "wall":
            limit = "sim time limit (--timeout)"
        return f"ended at the {limit} {at}{undecided}"
    if ended is Ending.INTERRUPTED:
        return f"interrupted by {summary.get('signal', 'a signal')} {at}{undecided}"
    return f"ended crashed {at}: a process of the run died{undecided}"


def _watch(swarm: Swarm, console: Console, quiet: bool) -> Ended:
    """Follow the run until every live robot decided, it stalls, a time limit, or a crash."""
    plan = swarm.plan
    progress = decided_progress(console, quiet)
    with progress:
        task = progress.add_task("decided", total=plan.robots, info="starting")
        while True:
            # Poll often while a fault is due, so it lands close to its sim time.
            time.sleep(0.005 if swarm.pending_faults else 0.1)
            swarm.poll()
            swarm.apply_faults()
            crashed = swarm.infrastructure_crash()
            elapsed = time.monotonic() - swarm.started_at if swarm.started_at else 0.0
            factor = swarm.sim_time / elapsed if elapsed > 0 else 0.0
            progress.update(
                task,
                completed=swarm.decided(),
                info=f"{swarm.decided()}/{plan.robots} decided, {swarm.trips()} trips, "
                f"sim {swarm.sim_time:.0f}s, {factor:.0f}x real time"
                if swarm.started_at
                else "waiting for the robots to join",
            )
            decided = swarm.started_at is not None and swarm.all_live_decided()
            halt = stop_reason(
                Look(
                    sim_time=swarm.sim_time,
                    sim_limit=plan.timeout,
                    all_decided=decided,
                    last_decision=swarm.last_decision_time() if decided else 0.0,
                    stalled=swarm.stalled(),
                    wall_time=time.monotonic() - swarm.launched_at,
                    wall_limit=plan.wall_timeout,
                    crashed=crashed is not None,
                )
            )
            if halt is not None:
                return Ended(halt, crashed=crashed)


def print_summary(summary: dict[str, Any], console: Console) -> None:
    robots = summary["per_robot"]
    table = Table(
        title=f"run {summary['run_id']}: {summary['num_robots']} robots, "
        f"{summary['num_sites']} sites, seed {summary['seed']}"
    )
    for column in ("robot", "decided site", "steps", "decision time (s)", "pool sizes"):
        table.add_column(column, justify="right")
    for robot in robots:
        table.add_row(
            str(robot["id"]),
            "-" if robot["decided_site"] is None else str(robot["decided_site"]),
            "-" if robot["steps"] is None else str(robot["steps"]),
            "-" if robot["decision_time_s"] is None else f"{robot['decision_time_s']:.1f}",
            " ".join(map(str, robot["pool_sizes"])) or "-",
        )
    console.print(table)
    print_stuck(summary.get("stuck") or [], console)
    steps = [robot["steps"] for robot in robots if robot["steps"] is not None]
    pools = [size for robot in robots for size in robot["pool_sizes"]]
    verdict = (
        f"consensus on site {summary['chosen_site']}, the best"
        if summary["correct"]
        else f"consensus on site {summary['chosen_site']}, NOT the best ({summary['best_site']})"
        if summary["consensus"]
        else "no consensus"
    )
    console.print(
        f"ended: {summary['ended']}; {verdict}{' (timed out)' if summary['timed_out'] else ''}; "
        f"steps to decision {describe(steps)}; pool size {describe(pools)}; "
        f"sim {summary['sim_time_s']:.1f}s in {summary['wall_time_s']:.1f}s wall "
        f"({summary['real_time_factor']:.0f}x); radio sent {summary['radio']['sent']}, "
        f"delivered {summary['radio']['delivered']}, dropped {summary['radio']['dropped']}, "
        f"rejected {summary['radio']['rejected']}"
    )
    departures = summary["world"].get("departures", 0)
    if departures:
        console.print(
            f"[yellow]{departures} robot(s) or beacon(s) left while the world ran (killed, "
            "crashed, or their connection lost): a lockstep run is then not the seed's "
            "deterministic one[/]"
        )
    if summary.get("recording"):
        console.print(f"recording: {summary['recording']} (swarm report, or open in Foxglove)")


STUCK_ROWS_SHOWN = 20


def print_stuck(stuck: list[dict[str, Any]], console: Console) -> None:
    """The undecided robots: where each is, in what phase, since when without progress."""
    if not stuck:
        return
    table = Table(title=f"undecided robots ({len(stuck)})")
    for column in ("robot", "phase", "position (m)", "trips", "last progress (sim s)"):
        table.add_column(column, justify="right")
    for robot in stuck[:STUCK_ROWS_SHOWN]:
        position = "-" if robot["x"] is None else f"({robot['x']:.2f}, {robot['y']:.2f})"
        table.add_row(
            str(robot["id"]),
            robot["phase"] or "-",
            position,
            str(robot["trips"]),
            f"{robot['last_progress_s']:.1f}",
        )
    if len(stuck) > STUCK_ROWS_SHOWN:
        table.caption = f"and {len(stuck) - STUCK_ROWS_SHOWN} more (see --json)"
    console.print(table)
