"""``python -m world_server.bridge``: serve robots of a run to programs outside the emulator.

    python -m world_server.bridge --run-id R --robot 8=udp://127.0.0.1:47800 \\
        --robot 9=serial:/dev/ttyUSB0@921600 --connect tcp/127.0.0.1:7447 --key-file bridge.json

``swarm run --external ... --link ...`` starts it with the run's keys, the robots'
controller settings and, with ``--secure``, a certificate per robot. The run's ending
(``world/ending``, checked with the bridge's key), SIGINT or SIGTERM end it saying the run
has ended (the programs then exit); SIGHUP ends it saying it is going away (they keep
trying, and find the next bridge on the same link). It exits with the run's exit code
once it heard the ending.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import zenoh

from bestofn_swarm.link.core import codec
from bestofn_swarm.plumbing import cliargs, process_main
from bestofn_swarm.plumbing.ending import hear_ending
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.plumbing.zenoh_session import open_from_args, open_session, session_mode
from bestofn_swarm.wire import names, protocol
from world_server.bridge import keys as link_keys
from world_server.bridge.bridge import Bridge, BridgeConfig, LinkedRobot
from world_server.bridge.core.impairment import LinkImpairment

log = logging.getLogger("bridge")


def linked_robot(text: str) -> LinkedRobot:
    """``ID=ADDRESS``: a robot and its link."""
    robot_text, equals, address = text.partition("=")
    robot = names.robot_of_name(robot_text)
    if not equals or robot is None:
        raise argparse.ArgumentTypeError(f"{text!r}: give ID=ADDRESS, e.g. 8=udp://127.0.0.1:47800")
    try:
        return LinkedRobot(robot, codec.parse_address(address))
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bridge",
        description="Serve robots of a run to programs outside the emulator, over UDP or "
        "serial links (docs/porting.md).",
    )
    parser.add_argument(
        "--robot",
        dest="robots",
        type=linked_robot,
        action="append",
        required=True,
        metavar="ID=ADDRESS",
        help="a robot outside and its link: udp://HOST:PORT (one address for every UDP "
        "robot) or serial:PATH[@BAUD] (repeatable)",
    )
    parser.add_argument(
        "--controller",
        default="{}",
        metavar="JSON",
        help="the run's controller settings (a ControllerConfig), handed to each program",
    )
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="the run's seed")
    parser.add_argument(
        "--encrypt",
        action="store_true",
        help="encrypt every link session (ChaCha20-Poly1305), as swarm run --secure does",
    )
    parser.add_argument(
        "--ping-every",
        type=cliargs.float_range(0.01, 60.0),
        default=codec.PING_EVERY,
        metavar="SECONDS",
        help=f"seconds between pings of each program (default: {codec.PING_EVERY:g})",
    )
    parser.add_argument(
        "--silence",
        type=cliargs.float_range(0.1, 600.0),
        default=codec.SILENCE,
        metavar="SECONDS",
        help=f"a link silent this long is gone (default: {codec.SILENCE:g})",
    )
    add_impairment_options(parser)
    parser.add_argument(
        "--link-keys",
        type=Path,
        default=None,
        metavar="FILE",
        help=f"the robots' link keys (default: ${link_keys.LINK_KEYS_ENV}, as swarm run "
        "hands them over)",
    )
    parser.add_argument(
        "--robot-zenoh-config",
        metavar="FILE",
        default=None,
        help="the Zenoh configuration of each robot's session, '{id}' standing for its id "
        "(--secure: its certificate)",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


def add_impairment_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--link-delay``, ``--link-jitter``, ``--link-loss``: shared with ``swarm run``."""
    parser.add_argument(
        "--link-delay",
        type=cliargs.float_range(0.0, 10_000.0),
        default=0.0,
        metavar="MS",
        help="hold every link frame this many milliseconds, each way (default: 0)",
    )
    parser.add_argument(
        "--link-jitter",
        type=cliargs.float_range(0.0, 10_000.0),
        default=0.0,
        metavar="MS",
        help="and a uniform draw within this many milliseconds either side (default: 0)",
    )
    parser.add_argument(
        "--link-loss",
        type=cliargs.probability,
        default=0.0,
        metavar="P",
        help="lose each link frame with this probability, each way (default: 0)",
    )


def impairment_of(args: argparse.Namespace) -> LinkImpairment:
    return LinkImpairment(args.link_delay / 1000, args.link_jitter / 1000, args.link_loss)


def robots_of(parser: argparse.ArgumentParser, args: argparse.Namespace) -> tuple[LinkedRobot, ...]:
    """The robots outside and their links, each robot once."""
    robots = tuple(args.robots)
    if len({linked.robot for linked in robots}) != len(robots):
        parser.exit(2, "bridge: error: a robot is given twice\n")
    return robots


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin("bridge", parser, argv, robots_of)
    args, robots, keyring = begun.args, begun.settings, begun.keyring
    if keyring is not None and not keyring.holds(names.BRIDGE):
        parser.exit(2, "bridge: error: the run keys hold no key for the bridge\n")
    try:
        keys = link_keys.load(args.run_id, args.link_keys)
    except ValueError as error:
        parser.exit(2, f"bridge: error: {error}\n")
    missing = [linked.robot for linked in robots if linked.robot not in keys]
    if missing:
        parser.exit(2, f"bridge: error: no link key for robot(s) {missing}\n")
    config = BridgeConfig(
        run_id=args.run_id,
        robots=robots,
        controller=args.controller,
        root=args.root,
        seed=args.seed,
        encrypted=args.encrypt,
        ping_every=args.ping_every,
        silence=args.silence,
        impairment=impairment_of(args),
    )
    sessions: list[zenoh.Session] = []
    try:
        session = open_from_args(args)
        sessions.append(session)
        robot_sessions: dict[int, zenoh.Session] = {}
        for linked in robots:
            config_file = args.robot_zenoh_config
            if config_file:
                config_file = config_file.replace("{id}", str(linked.robot))
            robot_sessions[linked.robot] = open_session(
                session_mode(args), args.connect, args.listen, config_file
            )
            sessions.append(robot_sessions[linked.robot])
        bridge = Bridge(
            config,
            session=session,
            robot_sessions=robot_sessions,
            link_keys={robot: keys[robot] for robot in robot_sessions},
            keyring=keyring.only([names.BRIDGE]) if keyring is not None else None,
        )
        try:
            bridge.open_links()
        except (OSError, ValueError) as error:
            print(f"bridge: cannot open the links: {error}", file=sys.stderr)
            return 1
        on_stop_signals(
            lambda signum: bridge.stop(
                codec.ByeReason.GOING_AWAY if signum == signal.SIGHUP else codec.ByeReason.RUN_ENDED
            ),
            (signal.SIGINT, signal.SIGTERM, signal.SIGHUP),
        )
        bridge.declare()
        ended: list[int] = []  # the run's exit code, once its ending came

        def on_ending(ending: protocol.RunEnding) -> None:
            log.info("the run ended: %s (exit code %d)", ending.ended, ending.code)
            ended.append(ending.code)
            bridge.stop(codec.ByeReason.RUN_ENDED)  # the programs outside exit too

        hearing = hear_ending(session, begun.keys, keyring, on_ending)
        served = ", ".join(f"{linked.robot} on {linked.address}" for linked in robots)
        log.info("serving robot(s) %s", served)
        # The loop runs in its own thread so that this one stays free for the signals.
        failed: list[BaseException] = []

        def serve() -> None:
            try:
                bridge.run()
            except BaseException as error:  # said below; the launcher starts a new bridge
                failed.append(error)
                raise

        worker = threading.Thread(target=serve, daemon=True)
        worker.start()
        while worker.is_alive():
            worker.join(0.2)
        hearing.undeclare()
        bridge.close()
        if failed:
            print(f"bridge: the loop failed: {failed[0]!r}", file=sys.stderr)
            return 1
    except zenoh.ZError as error:
        print(f"bridge: {error}", file=sys.stderr)
        return 1
    finally:
        for opened in sessions:
            opened.close()
    return ended[0] if ended else 0


if __name__ == "__main__":
    process_main.end(main())
