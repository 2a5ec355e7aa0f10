"""``robot-agent``: the command that runs robots on Zenoh (``python -m robot_agent.node``).

It opens one Zenoh session per robot it hosts, asks the world server for what its robots
need (an id for ``--id auto``, the world's map), builds each robot's controller and
endpoint, and runs them as ``RobotNode`` s (``robot_node.py``) until it is stopped.

Trust: in a keyed run a robot holds only its own run key; it believes an input only with
that key's tag (bestofn_swarm/wire/auth.py), only for a tick within reach of its last one, and holds
at most PENDING_BYTES of inputs for ticks it has not reached (robot_agent/core/endpoint.py).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import zenoh

from bestofn_swarm.plumbing import cliargs, process_main, settings_cli
from bestofn_swarm.plumbing.ending import hear_ending
from bestofn_swarm.plumbing.inbox import STOP, BoundedInbox
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.plumbing.trace import open_trace
from bestofn_swarm.plumbing.world_info import ask, fetch_world_info
from bestofn_swarm.plumbing.zenoh_session import certificate_name, open_from_args
from bestofn_swarm.wire import auth, keyspace, names, protocol
from robot_agent.core import builder, byzantine
from robot_agent.core.plugin import PLUGIN_FAILED, PluginError
from robot_agent.core.plugins import Plugins
from robot_agent.node.options import AGENT_OPTIONS, RobotAgentConfig, hosted_byzantine
from robot_agent.node.robot_node import (
    INBOX_BYTES,
    INBOX_BYTES_PER_ROBOT,
    MAX_MESSAGE_BYTES,
    Event,
    HostBatch,
    LatestSenses,
    RobotNode,
    serve,
)
from robot_agent.plugins import registry

log = logging.getLogger("robot_agent")


def robot_id(text: str) -> int | None:
    """A robot id, or None for ``auto``."""
    if text == "auto":
        return None
    return cliargs.int_range(0, names.MAX_ROBOTS - 1)(text)


class NoKeyError(Exception):
    """The world assigned an id whose key this process does not hold."""


def ask_for_id(
    session: zenoh.Session,
    keys: keyspace.Keys,
    timeout: float,
    keyring: auth.Keyring | None = None,
) -> int:
    """Ask the world server for a free robot id (``--id auto``).

    In a keyed run the question is asked in the name of a robot whose key this process
    holds (robot 0 with the run secret), and the id is only taken if its key is held too.
    """
    asker = ""
    if keyring is not None:
        robots = [name for name in keyring.identities if name.startswith("robot/")]
        asker = robots[0] if robots else names.robot_identity(0)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        answers, refused = ask(session, keys.of(keyspace.JOIN), keyring, asker)
        for answer in answers:
            try:
                robot = protocol.decode(answer, protocol.JoinReply).id
            except protocol.ProtocolError as error:
                raise TimeoutError(f"invalid answer on {keys.of(keyspace.JOIN)}: {error}") from None
            if keyring is not None and not keyring.holds(names.robot_identity(robot)):
                raise NoKeyError(f"the world server gave id {robot}, whose key this process lacks")
            return robot
        if refused and not answers:
            raise TimeoutError(f"the world server gave no id: {refused[-1]}")
        time.sleep(0.2)
    raise TimeoutError(f"no world server answered on {keys.of(keyspace.JOIN)}")


def certificate_robot(config_file: str | None) -> int | None:
    """The robot a Zenoh configuration's client certificate names (``CN=robot-<id>``).

    Under the access control a robot may speak only as the robot of its certificate, so
    ``--id auto`` takes that id rather than ask the world for one it could not use."""
    if not config_file:
        return None
    return names.robot_of_certificate(certificate_name(config_file))


def host_batch(
    nodes: list[RobotNode], inbox: BoundedInbox[Event], keyring: auth.Keyring | None
) -> HostBatch | None:
    """The batched path of a process hosting ``nodes``, or None (with a warning) when it
    cannot have one: its robots are not every id from the first to the last, or its run
    keys hold no key for its host identity; each robot then answers on its own keys."""
    hosted = names.hosted_range([node.robot_id for node in nodes])
    identity = names.host_identity(*hosted) if hosted is not None else None
    if identity is None or (keyring is not None and not keyring.holds(identity)):
        log.warning(
            "robots %s answer on their own keys: a batch needs robots first to last and "
            "the key of their host identity",
            ", ".join(str(node.robot_id) for node in nodes),
        )
        return None
    return HostBatch(nodes, inbox, keyring.only([identity]) if keyring is not None else None)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robot-agent",
        description="A robot of the swarm: the decision controller on Zenoh. Several --id "
        "options host several robots in this process, each with its own Zenoh session.",
        epilog="With --link ADDRESS the robot runs outside the emulator instead, over UDP or "
        "a serial line to the run's bridge, without Zenoh (robot-agent --link ADDRESS --help).",
    )
    parser.add_argument(
        "--id",
        dest="ids",
        type=robot_id,
        action="append",
        required=True,
        metavar="N|auto",
        help="robot id, or 'auto' to be given one by the world server "
        "(repeatable to host several robots)",
    )
    parser.add_argument(
        "--info-timeout",
        type=cliargs.positive_float,
        default=60.0,
        help="wall seconds to wait for the world server (default: 60)",
    )
    AGENT_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, RobotAgentConfig)
    parser.add_argument(
        "--no-batch",
        action="store_true",
        help="answer on each robot's own keys even when hosting several robots (by default "
        "a process hosting robots N to M exchanges one batch per step with the world, sealed "
        "with the key of its host identity host/N-M)",
    )
    parser.add_argument(
        "--trace",
        metavar="PATH",
        default=None,
        help="write a timeline of every control step to PATH as JSON lines (docs/performance.md)",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


@dataclass(frozen=True)
class AgentSettings:
    """What robot-agent's command line asks for, checked."""

    agent: RobotAgentConfig
    fixed: list[int]  # the robots given by id (not ``--id auto``)
    misbehaving: dict[int, byzantine.Behaviour]
    plugins: Plugins  # found before anything is opened: the run's sources if given


def agent_settings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> AgentSettings:
    fixed = [robot for robot in args.ids if robot is not None]
    if len(set(fixed)) != len(fixed):
        parser.exit(2, "robot-agent: error: the same --id is given twice\n")
    if None in args.ids and "{id}" in (args.zenoh_config or ""):
        parser.exit(2, "robot-agent: error: --id auto cannot fill '{id}' in --zenoh-config\n")
    agent: RobotAgentConfig = settings_cli.config_from(parser, args, AGENT_OPTIONS)
    try:
        misbehaving = hosted_byzantine(agent.byzantine, fixed)
        plugins = registry.resolve_plugins(agent.controller, agent.plugins.controller)
        registry.check_sources(plugins, agent.plugins.sources)
    except ValueError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    return AgentSettings(agent, fixed, misbehaving, plugins)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin(
        "robot-agent", parser, argv, agent_settings, config_robots=lambda found: found.fixed
    )
    args, keyring, keys = begun.args, begun.keyring, begun.keys
    agent, misbehaving = begun.settings.agent, begun.settings.misbehaving
    plugins = begun.settings.plugins
    config = agent.controller
    for given in begun.settings.fixed:
        if keyring is not None and not keyring.holds(names.robot_identity(given)):
            parser.exit(2, f"robot-agent: error: the run keys hold no key for robot {given}\n")
    inbox: BoundedInbox[Event] = BoundedInbox(
        INBOX_BYTES + INBOX_BYTES_PER_ROBOT * len(args.ids), MAX_MESSAGE_BYTES
    )
    lock = threading.Lock()  # the robots of this process: one thread at a time
    on_stop_signals(lambda _: inbox.put(Event(-1, STOP), control=True))
    sessions: list[zenoh.Session] = []
    nodes: list[RobotNode] = []
    host: HostBatch | None = None
    trace = open_trace(args.trace)
    latest: LatestSenses | None = None  # real time: newest senses only (robot_node.py)
    code = 0
    try:
        for requested in args.ids:
            session = open_from_args(args, requested)
            sessions.append(session)
            robot = requested
            if robot is None:
                robot = certificate_robot(args.zenoh_config)
            if robot is None:
                robot = ask_for_id(session, keys, args.info_timeout, keyring)
            identity = names.robot_identity(robot)
            info = fetch_world_info(session, keys, args.info_timeout, keyring, identity)
            try:
                builder.run_seed(info, agent.seed)
                endpoint = builder.build_robot(
                    robot,
                    info,
                    config,
                    keys=keys,
                    keyring=keyring.only([identity]) if keyring is not None else None,
                    behaviour=misbehaving.get(robot),
                    plugins=plugins,
                    robot_faults=[spec.fault() for spec in agent.faults],
                )
            except PluginError as error:  # a plug-in that cannot make this robot
                print(f"robot-agent: error: {error}", file=sys.stderr)
                return PLUGIN_FAILED
            except ValueError as error:  # another run's seed; a liar's site; a fault unknown
                print(f"robot-agent: error: {error}", file=sys.stderr)
                return 2
            if info.clock == "realtime" and latest is None:
                latest = LatestSenses()
                latest.start()
            node = RobotNode(
                endpoint, session=session, inbox=inbox, lock=lock, trace=trace, latest=latest
            )
            nodes.append(node)
        # The batch path is ready before any robot announces itself: once every robot's
        # token is up the world may tick, and a robot's act goes out in the batch.
        if len(nodes) > 1 and not args.no_batch:
            host = host_batch(nodes, inbox, keyring)
            if host is not None:
                host.start()
        for node in nodes:
            node.start()
        ending = _hear_ending(nodes[0], inbox)
        log.info("robot(s) %s running", ", ".join(str(node.robot_id) for node in nodes))
        stopped = serve(nodes, inbox)
        ending.undeclare()
        code = stopped.code
        if stopped.failure is not None:  # a plug-in failed in a robot's step: the run ends
            print(f"robot-agent: error: {stopped.failure}", file=sys.stderr)
            return PLUGIN_FAILED
    except (zenoh.ZError, TimeoutError, NoKeyError) as error:
        print(f"robot-agent: {error}", file=sys.stderr)
        return 1
    finally:
        with lock:  # once held, no callback is stepping a robot, and none will after
            for node in nodes:
                node.closed = True
        if latest is not None:
            latest.stop()
            if latest.skipped:
                log.info("stepped the newest sense, skipping %d older ones", latest.skipped)
        if host is not None:
            host.close()
        for node in nodes:
            node.close()
        for session in sessions:
            session.close()
        if trace is not None:
            trace.close()
    process_main.end(code)


def _hear_ending(node: RobotNode, inbox: BoundedInbox[Event]) -> zenoh.Subscriber:
    """The run's ending, heard on the process's first robot's session and checked with its
    key: the process stops with the run's exit code. An ending not believed is counted as
    that robot's rejection (and logged once)."""
    refused: list[str] = []

    def ended(ending: protocol.RunEnding) -> None:
        log.info("the run ended: %s (exit code %d)", ending.ended, ending.code)
        inbox.put(Event(-1, STOP, code=ending.code), control=True)

    def refuse(reason: str) -> None:
        with node.lock:
            node.endpoint.count_dropped(1)
        if not refused:
            refused.append(reason)
            log.warning("refused an ending (logged once): %s", reason[:300])

    return hear_ending(node.session, node.keys, node.endpoint.keyring, ended, refuse)


if __name__ == "__main__":
    sys.exit(main())
