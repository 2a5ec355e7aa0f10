"""The processes of one local run and the launcher's own Zenoh session: started in order,
and stopped, each by pid, however the run ends.

The world server first (the run's router, unless ``--connect``), then the launcher's
session (the follower's subscriptions, the children's log lines), the recorder, the
observers, the beacon and the robot processes. Each step waits for its process to show
up, and gives up early when a stop signal came (``stopping``): the run then ends as
interrupted with what was started. The process group owns the threads that read the
children's stderr and joins them; the log relay stops publishing before the session
closes.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.plumbing.private_files import make_private_folder
from bestofn_swarm.plumbing.tcp import wait_for_port
from bestofn_swarm.plumbing.world_info import ask, fetch_world_info
from bestofn_swarm.plumbing.zenoh_session import open_session
from bestofn_swarm.wire import auth, keyspace, names, protocol, settings
from bestofn_swarm.wire.names import Role
from deploy.launcher.follower import subscribe
from deploy.launcher.log_relay import LogRelay
from deploy.launcher.outside import link_keys_env, write_key_files
from deploy.launcher.plan import RunPlan
from deploy.launcher.processes import Child, ProcessGroup, python_module
from deploy.security import zenoh_acl
from deploy.security.credentials import RunNetwork
from robot_agent.core.plugin import PLUGIN_FAILED

log = logging.getLogger("swarm.run")

RUN_ID_ENV = "BESTOFN_RUN_ID"
CONNECT_WAIT = 5.0  # wall seconds to wait for the router given by --connect
START_WAIT = 30.0  # wall seconds a process of the run may take to show up
BRIDGE_RESTARTS = 5  # a bridge that dies on its own is started again this many times
PUMP_WAIT = 2.0  # wall seconds to wait for the last lines of a robot process that failed
STATS_ATTEMPTS, STATS_RETRY_PAUSE = 5, 0.2
# Processes that only watch: they stay to the end, and their crash does not end the run.
OBSERVERS = ("viewer", "foxglove")
# Each observer's certificate in secure mode: a reader with its own token (and the page
# its finish queryable), nothing else.
OBSERVER_CERTIFICATES = {"viewer": zenoh_acl.VIEWER, "foxglove": zenoh_acl.FOXGLOVE}

Stopping = Callable[[], bool]  # whether a stop signal came: starting is then given up


class StartError(Exception):
    def __init__(self, message: str, child: Child | None = None) -> None:
        super().__init__(message)
        self.child = child


class Supervisor:
    """One local run's processes, network and session."""

    def __init__(
        self,
        plan: RunPlan,
        inbox: BoundedInbox[Any],
        echo: Callable[[str, str], None] | None = None,
    ) -> None:
        self.plan = plan
        self.keys = keyspace.Keys(plan.run_id)
        self.inbox = inbox  # where the follower's subscriptions queue what they hear
        self.logs = LogRelay(self.keys, echo, hold=plan.record is not None)
        self.group = ProcessGroup(self.logs.line)
        self.robot_children: dict[int, Child] = {}
        self.world: Child | None = None
        self.recorder: Child | None = None
        self.bridge: Child | None = None
        self.bridge_restarts = 0
        self.key_files: dict[int, Path] = {}  # the outside robots' keys
        self.network: RunNetwork | None = None  # made when the run starts
        self.session: zenoh.Session | None = None
        self._declared: list[Any] = []
        self.placement: Any = None  # --dask: the robots on the cluster (dask_placement.py)

    @property
    def keyring(self) -> auth.Keyring | None:
        return self.network.keyring if self.network is not None else None

    # --- start -----------------------------------------------------------------------

    def start(self, stopping: Stopping) -> bool:
        """Start every process of the run, in order; False if a stop signal came first.
        StartError if one does not start."""
        plan = self.plan
        # Every process of the run carries its id in its environment (forked robots have
        # no command line of their own), so it can be found by run id, e.g. by tests.
        os.environ[RUN_ID_ENV] = plan.run_id
        if plan.connect is not None:
            wait_for_router(plan.connect, stopping=stopping)
        steps = (
            self._start_world,
            self._connect,
            self._start_recorder,
            self._start_observers,
            self._start_beacon,
            self._start_bridge,
        )
        for step in steps:
            if stopping():
                return False
            step(stopping)
        if plan.dask is not None:
            self._place("robots")
            return not stopping()
        emulated = plan.emulated
        for first in range(0, len(emulated), plan.robots_per_process):
            if stopping():
                return False
            robots = emulated[first : first + plan.robots_per_process]
            child = self.start_robots(robots)
            for robot in robots:
                self.robot_children[robot] = child
        if plan.outside is not None and not stopping():
            self._wait_for_outside(stopping)
        return not stopping()

    def _start_world(self, stopping: Stopping) -> None:
        """The run's network (keys, private socket, certificates), then the world server
        (--dask-world: with the beacon, on that worker of the cluster)."""
        plan = self.plan
        self.network = network = RunNetwork.create(
            plan.run_id, plan.robots, connect=plan.connect, keyed=plan.keyed, secure=plan.secure
        )
        if plan.dask_world is not None:
            self._place("world")
            return
        world = self.group.start(
            "world",
            python_module(
                "world_server.server",
                *plan.world_argv(),
                # It ends the run, and stays: the run's router until the recording is done.
                "--until-stopped",
                *network.world_args(),
                *plan.trace_args("world"),
            ),
            env=network.env(),
        )
        self.world = world
        if not network.wait_for_router(START_WAIT, lambda: world.alive() and not stopping()):
            _unless(stopping, StartError("the world server did not start", world))

    def _connect(self, stopping: Stopping) -> None:
        """The launcher's session, once the world answers: the follower's subscriptions,
        the children's lines. (Each wait here is bounded, and short once the world runs.)"""
        network, world = self.network, self.world
        assert network is not None
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
        self.logs.attach(self.session, self.keyring)
        try:
            fetch_world_info(self.session, self.keys, START_WAIT, self.keyring, names.LAUNCHER)
        except TimeoutError as error:
            raise StartError(str(error), world) from None
        # The clock only when a fault falls due at a sim time; world/state says the rest.
        self._declared = subscribe(self.session, self.keys, self.inbox, bool(self.plan.faults))

    def _start_recorder(self, stopping: Stopping) -> None:
        plan, network = self.plan, self.network
        if plan.record is None:
            return
        assert network is not None
        make_private_folder(plan.record.parent)
        self.recorder = self.group.start(
            "recorder",
            python_module(
                "world_server.recorder",
                *plan.recorder_args,
                "--await-finish",  # the launcher closes it with its summary (finish_recording)
                *network.client_args(zenoh_acl.RECORDER),
            ),
            env=network.env(),
        )
        if not self._wait_alive(Role.RECORDER, 0, self.recorder, stopping):
            _unless(stopping, StartError("the recorder did not start", self.recorder))
            return
        self.logs.release()

    def _start_observers(self, stopping: Stopping) -> None:
        """The page and Foxglove live: listening before the robots start, like the recorder."""
        network = self.network
        assert network is not None
        for observer in self.plan.observers:
            if stopping():
                return
            identity = OBSERVER_CERTIFICATES[observer.name]
            argv = [*observer.argv, *network.client_args(identity)]
            child = self.group.start(
                observer.name, python_module(observer.module, *argv), env=network.env()
            )
            if not self._wait_alive(observer.role, 0, child, stopping):
                _unless(stopping, StartError(f"the {observer.name} did not start", child))
                return
            print(f"swarm run: {observer.name} at {observer.url}", file=sys.stderr, flush=True)

    def _start_beacon(self, stopping: Stopping) -> None:
        network = self.network
        assert network is not None
        if self.plan.dask_world is not None:
            return  # with the world, on its worker
        beacon = names.beacon_certificate(names.DEFAULT_BEACON)
        self.group.start(
            "beacon",
            python_module("nest_beacon", *self.plan.beacon_argv(), *network.client_args(beacon)),
            env=network.env(),
        )

    def _start_bridge(self, stopping: Stopping) -> None:
        """The bridge to the outside robots (--external), their key files, and the command
        that starts each of their programs."""
        plan, network = self.plan, self.network
        if plan.outside is None:
            return
        assert network is not None and network.keyring is not None  # --external needs keys
        directory = plan.outside.keys_dir or network.directory
        assert directory is not None  # --connect runs give --link-keys (run_plan checks)
        self.key_files = write_key_files(directory, network.keyring, plan.run_id, plan.external)
        self.bridge = self._launch_bridge()
        if not self._wait_alive(Role.BRIDGE, 0, self.bridge, stopping):
            _unless(stopping, StartError("the bridge did not start", self.bridge))
            return
        outside = ", ".join(map(str, plan.external))
        lines = [
            f"swarm run: robot(s) {outside} run outside the emulator; start each with:",
            *(f"  {plan.outside.command(robot, path)}" for robot, path in self.key_files.items()),
            f"swarm run: waiting up to {plan.outside.wait:g} s for them to connect",
        ]
        print("\n".join(lines), file=sys.stderr, flush=True)

    def _launch_bridge(self) -> Child:
        plan, network = self.plan, self.network
        assert plan.outside is not None and network is not None and network.keyring is not None
        argv = plan.outside.bridge_argv(
            plan.run_id, plan.seed, settings.encode(plan.switches.controller), plan.secure
        )
        argv += network.client_args(zenoh_acl.BRIDGE)
        robot_config = network.config_of(names.robot_certificate("{id}"))
        if robot_config is not None:  # --secure: each robot's session, its certificate
            argv += ["--robot-zenoh-config", str(robot_config)]
        env = {
            **network.env([names.BRIDGE]),
            **link_keys_env(network.keyring, plan.run_id, plan.external),
        }
        return self.group.start("bridge", python_module("world_server.bridge", *argv), env=env)

    def _wait_for_outside(self, stopping: Stopping) -> None:
        """Wait until every outside robot is present (its program connected and spoke), for
        at most --link-wait; StartError naming the robots that did not, and their links."""
        plan, bridge = self.plan, self.bridge
        assert plan.outside is not None and self.session is not None and bridge is not None
        deadline = time.monotonic() + plan.outside.wait
        missing = list(plan.external)
        while missing and time.monotonic() < deadline and not stopping():
            if not bridge.alive():
                raise StartError("the bridge died", bridge)
            missing = [
                robot
                for robot in missing
                if not list(
                    self.session.liveliness().get(self.keys.token(Role.ROBOT, robot), timeout=1.0)
                )
            ]
            if missing:
                time.sleep(0.1)
        if missing and not stopping():
            named = "; ".join(
                f"robot {robot} on {plan.outside.address_of(robot)}" for robot in missing
            )
            raise StartError(
                f"outside robot(s) did not connect within {plan.outside.wait:g} s: {named}"
            )

    def restart_bridge(self) -> bool:
        """Start the bridge again if it died on its own (its robots find it again: their
        programs say hello until answered); False once it died too often."""
        bridge = self.bridge
        if bridge is None or bridge.alive() or bridge.expected_exit:
            return True
        if self.bridge_restarts >= BRIDGE_RESTARTS:
            return False
        self.bridge_restarts += 1
        log.warning(
            "the bridge died (exit code %s): starting it again (%d of %d)",
            bridge.process.returncode,
            self.bridge_restarts,
            BRIDGE_RESTARTS,
        )
        bridge.expected_exit = True  # replaced, not a crash of the run
        self.bridge = self._launch_bridge()
        return True

    def _place(self, part: str) -> None:
        """--dask: the robot processes (or with --dask-world the world server and the
        beacon) on the cluster's workers (Dask is needed only now)."""
        try:
            from deploy.launcher.dask_placement import DaskError, DaskPlacement
        except ImportError as error:
            raise StartError(f"--dask needs Dask: pip install '.[dask]' ({error})") from None
        if self.placement is None:
            self.placement = DaskPlacement(self.plan)
        try:
            if part == "world":
                worker = self.placement.start_world(self.keyring)
                print(
                    f"swarm run: the world server and the beacon on worker {worker.address} "
                    f"(host {worker.host})",
                    file=sys.stderr,
                    flush=True,
                )
                return
            placed = self.placement.start(self.keyring)
        except DaskError as error:
            raise StartError(str(error)) from None
        for share in placed:
            robots = ", ".join(str(robot) for robot in share.robots)
            print(
                f"swarm run: robots {robots} on worker {share.worker.address} "
                f"(host {share.worker.host}), {len(share.processes)} process(es)",
                file=sys.stderr,
                flush=True,
            )

    @property
    def robot_processes(self) -> int:
        """How many processes host the robots."""
        if self.placement is not None:
            return sum(len(share.processes) for share in self.placement.placed)
        return self.plan.robot_processes

    def start_robots(self, robots: list[int]) -> Child:
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
        # Only the keys of its own robots, and of its host identity when it hosts several
        # (the key of its batches): whatever it says can only be in their names.
        identities = [names.robot_identity(robot) for robot in robots]
        if len(robots) > 1 and self.plan.batch:
            identities.append(names.host_identity(robots[0], robots[-1]))
        env = network.env(identities)
        if self.plan.spawn == "fork":
            return self.group.fork(name, "robot_agent.node.cli", argv, env=env)
        return self.group.start(name, python_module("robot_agent.node", *argv), env=env)

    def _wait_alive(self, role: Role, ident: int | str, child: Child, stopping: Stopping) -> bool:
        """Wait for a liveliness token, as long as the process that should declare it lives."""
        assert self.session is not None
        deadline = time.monotonic() + START_WAIT
        while time.monotonic() < deadline and child.alive() and not stopping():
            if list(self.session.liveliness().get(self.keys.token(role, ident), timeout=1.0)):
                return True
            time.sleep(0.05)
        return False

    # --- during the run --------------------------------------------------------------

    def infrastructure_crash(self) -> Child | None:
        """A process other than a robot's or an observer that died on its own (the bridge
        only once it died more often than it is restarted)."""
        for child in self.group.crashed():
            if child.name == "bridge" and self.restart_bridge():
                continue
            if not child.name.startswith("robot-") and child.name not in OBSERVERS:
                return child
        return None

    def crashed_observer(self, name: str) -> Child | None:
        """The observer ``name`` if its process died on its own."""
        return next((child for child in self.group.crashed() if child.name == name), None)

    def observer_alive(self, name: str) -> bool:
        return any(child.name == name and child.alive() for child in self.group.children)

    def plugin_failure(self) -> str | None:
        """What a robot process whose plug-in failed said (its last line, which names the
        plug-in, the robot and the tick), if one did: it exits with PLUGIN_FAILED. Of
        several, the first in the run (the earliest tick, then the lowest robot), as the
        in-process engine, which stops at the first, reports it."""
        failures = []
        for child in {id(child): child for child in self.robot_children.values()}.values():
            if child.alive() or child.expected_exit or child.process.returncode != PLUGIN_FAILED:
                continue
            if child.pump is not None:
                child.pump.join(PUMP_WAIT)  # its last line may still be in the pipe
            said = [line for line in child.log if line.strip()]
            line = said[-1] if said else f"{child.name}: a plug-in failed"
            failures.append(line.removeprefix("robot-agent: error: "))
        return min(failures, key=_when_failed) if failures else None

    def crashed_robots(self) -> list[int]:
        return [
            robot
            for robot, child in self.robot_children.items()
            if not child.alive() and not child.expected_exit
        ]

    def live_robots(self) -> list[int]:
        return [robot for robot, child in self.robot_children.items() if child.alive()]

    def kill_robot(self, robot: int) -> bool:
        """SIGKILL the robot's process on purpose; whether it was running."""
        child = self.robot_children[robot]
        was_alive = child.alive()
        self.group.kill(child)
        return was_alive

    def restart_robot(self, robot: int) -> None:
        """A fresh process for a robot whose process was killed."""
        self.robot_children[robot] = self.start_robots([robot])

    # --- stop ------------------------------------------------------------------------

    def world_running(self) -> bool:
        return self.session is not None and self.world is not None and self.world.alive()

    def stop_swarm(self) -> None:
        """Stop the robots and the beacon (--dask: the tasks stop what the run's ending
        did not); the world, the recorder and the observers stay."""
        if self.placement is not None:
            self.placement.stop()
        swarm = [
            child
            for child in self.group.children
            if child.name not in ("world", "recorder", *OBSERVERS)
        ]
        self.group.stop(swarm)

    def world_stats(self) -> protocol.WorldState | None:
        """The world's final counters. Asked again on no answer: once in a few 100-robot
        runs the query came back empty at once while a hundred sessions were closing."""
        for _ in range(STATS_ATTEMPTS):
            stats = self.query_world_stats()
            if stats is not None:
                return stats
            time.sleep(STATS_RETRY_PAUSE)
        log.warning(
            "the world did not answer on world/stats; the summary's counters are "
            "those of its last world/state"
        )
        return None

    def query_world_stats(self) -> protocol.WorldState | None:
        if self.session is None:
            return None
        try:
            answers, _ = ask(
                self.session,
                self.keys.of(keyspace.STATS),
                self.keyring,
                names.LAUNCHER,
                timeout=2.0,
            )
            for answer in answers:
                return protocol.decode(answer, protocol.WorldState)
        except (zenoh.ZError, protocol.ProtocolError):
            return None
        return None

    def finish_observers(self, summary: dict[str, Any]) -> None:
        """Tell the page how the run ended; it answers once every page was sent that."""
        if self.session is None or not any(o.name == "viewer" for o in self.plan.observers):
            return
        payload = json.dumps(summary).encode()
        with contextlib.suppress(zenoh.ZError):  # sealed: the view believes only the launcher
            ask(
                self.session,
                self.keys.of(keyspace.VIEWER_FINISH),
                self.keyring,
                names.LAUNCHER,
                payload=payload,
                timeout=5.0,
            )

    def close(self) -> None:
        """Stop every process still running and close the session."""
        swarm = [child for child in self.group.children if child.name not in ("world", "recorder")]
        self.group.stop(swarm)  # the robots first: the world stays their barrier meanwhile
        self.logs.detach()  # no line may go out on the closing session
        if self.session is not None:
            for entity in self._declared:
                entity.undeclare()
            self.session.close()
            self.session = None
        self.group.stop_all()
        if self.placement is not None:
            self.placement.stop()  # (at once if it stopped already)
            self.placement.close()
        if self.network is not None:
            self.network.close()  # its socket, certificates and keys


def _when_failed(line: str) -> tuple[int, int]:
    """The tick and robot a plug-in's failure names (``(robot 3, tick 120)``; one that could
    not make robot 3 failed before tick 0)."""
    step = re.search(r"\(robot (\d+), tick (\d+)\)$", line)
    if step is not None:
        return int(step.group(2)), int(step.group(1))
    making = re.search(r"making robot (\d+)", line)
    return -1, int(making.group(1)) if making is not None else names.MAX_ROBOTS


def _unless(stopping: Stopping, error: StartError) -> None:
    """Raise ``error``, unless the step failed because a stop signal came."""
    if not stopping():
        raise error


def wait_for_router(
    endpoint: str, timeout: float = CONNECT_WAIT, stopping: Stopping = lambda: False
) -> None:
    """StartError unless the router of ``--connect`` accepts connections within ``timeout``
    (or a stop signal came first).

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
    if not wait_for_port(int(port), timeout, lambda: not stopping(), host=host.strip("[]")):
        tried = f"no Zenoh router answers at {endpoint} (tried for {timeout:g} s)"
        _unless(stopping, StartError(tried))
