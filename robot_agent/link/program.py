"""``robot-agent --link``: one robot of a run, running outside the emulator, over a link.

    robot-agent --link udp://127.0.0.1:47800 --id 8 --key-file robot-8.key
    robot-agent --link serial:/dev/ttyUSB0@921600 --id 8 --key-file robot-8.key

``swarm run --external 8 --link ...`` keeps robot 8's body in the world and serves it over
the link through its bridge; this program is the robot: ``robot_agent.core.link_robot.LinkRobot``
(the same controller and the same end of the wire as the emulated robot process, with the link
in place of Zenoh) on the link's loop (``bestofn_swarm.link.io.hub``). It imports no Zenoh: what
would run on a Raspberry Pi robot on Wi-Fi. Its key comes from a key file only (written by
``swarm run`` with mode 0600), never from the command line or the environment. When the
link goes (the bridge silent, restarted, a cable out) it says hello again until it is
answered and carries on from the world's current tick; when the bridge says the run has
ended it prints one JSON line (its decision, trips, link counts) and exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import logging
import signal
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.io.hub import Hub
from bestofn_swarm.link.io.transport import open_transport
from bestofn_swarm.plumbing import cliargs, cores
from bestofn_swarm.plumbing.run_keys import read_key_file
from bestofn_swarm.wire import names
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.link_robot import LinkRobot
from robot_agent.core.plugin import KINDS, OPTIONS, PLUGIN_FAILED, PluginError
from robot_agent.core.plugins import Plugins
from robot_agent.plugins import registry

log = logging.getLogger("link.program")


class StopRequest:
    """Set by SIGINT or SIGTERM: the loop says goodbye and returns."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, *_: object) -> None:
        self.requested = True


def serve(
    program: LinkRobot,
    address: codec.LinkAddress,
    stop: StopRequest,
    give_up: float | None = None,
) -> int:
    """Run the program on its link until the run ends (0), a stop signal (0), the program
    cannot go on (1), or no session for ``give_up`` seconds (1)."""
    hub = Hub()
    hub.add("link", lambda: open_transport(address))
    alone_since = time.monotonic()
    try:
        while not program.ended and not stop.requested:
            now = time.monotonic()
            if program.client.open:
                alone_since = now
            elif give_up is not None and now - alone_since > give_up:
                log.error("no bridge answered on %s for %g s: giving up", address, give_up)
                return 1
            program.wake(now)
            _send(program, hub, now)
            for name in hub.poll(program.deadline):
                now = time.monotonic()
                for data, _ in hub.receive(name, now):
                    program.receive(data, now)
                if hub.receiving(name):
                    program.hearing(now)  # a long frame under way is not silence
                _send(program, hub, now)  # answer at once
            hub.take_closed()  # the session notices by the bridge's silence, and says hello
        if hub.is_open("link"):
            program.stop()
            _send(program, hub, time.monotonic())
            hub.drain()
        return 1 if program.failed else 0
    finally:
        hub.close()


def _send(program: LinkRobot, hub: Hub, now: float) -> None:
    for frame in program.client.take_outgoing():
        hub.send("link", frame, None, now)
    hub.flush(now)


# --- command line ------------------------------------------------------------------------


def robot_id(text: str) -> int:
    robot = names.robot_of_name(text)
    if robot is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a robot id (0 to {names.MAX_ROBOTS - 1})"
        )
    return robot


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robot-agent",
        description="One robot of a run, outside the emulator: its controller over a link "
        "(UDP or serial) to the run's bridge (swarm run --external ... --link ...).",
    )
    parser.add_argument(
        "--link",
        required=True,
        metavar="ADDRESS",
        help="the bridge: udp://HOST:PORT, or serial:PATH[@BAUD] (default baud "
        f"{codec.DEFAULT_BAUD})",
    )
    parser.add_argument("--id", type=robot_id, required=True, help="the robot's id")
    parser.add_argument(
        "--key-file",
        type=Path,
        required=True,
        metavar="FILE",
        help="the robot's run key (swarm run writes robot-ID.key; never on a command line)",
    )
    parser.add_argument(
        "--give-up",
        type=cliargs.float_range(0.0, low_open=True),
        default=None,
        metavar="SECONDS",
        help="exit with code 1 when no bridge has answered for this long (default: keep trying)",
    )
    plugins = parser.add_argument_group(
        "plug-ins",
        "what this robot runs in place of the run's (the bridge gives the run's settings): a "
        "whole controller of one's own is how a port written in Python is checked by swarm "
        "conformance (docs/extending.md)",
    )
    for kind in KINDS:
        plugins.add_argument(
            OPTIONS[kind],
            metavar="NAME",
            default=None,
            help=f"the {kind}: an installed plug-in's name or package.module:attribute "
            f"(default: the run's; swarm plugins lists them)",
        )
    parser.add_argument(
        "--log-level",
        default="info",
        choices=["debug", "info", "warning", "error"],
        help="default: info",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    cores.check()  # stale compiled cores would run old code
    parser = build_parser()
    args = parser.parse_args(argv)
    try:  # checked after parsing, so that --help works wherever it stands
        address = codec.parse_address(args.link)
    except ValueError as error:
        parser.error(f"argument --link: {error}")
    logging.basicConfig(
        level=args.log_level.upper(),
        format=f"robot-agent[link {args.id}] %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    try:
        run, keyring = read_key_file(args.key_file, names.robot_identity(args.id))
    except ValueError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    chosen: dict[str, str] = {
        kind: getattr(args, kind) for kind in KINDS if getattr(args, kind) is not None
    }
    try:  # what the options name is found now, before the link: a bad name is one line
        for kind in KINDS:
            if kind in chosen:
                registry.resolve(kind, chosen[kind])
    except PluginError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    stop = StopRequest()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, stop)
    prepare = functools.partial(run_settings, chosen) if chosen else None
    program = LinkRobot.create(args.id, run, keyring, prepare)
    log.info("robot %d of run %s: saying hello on %s", args.id, run, address)
    code = serve(program, address, stop, args.give_up)
    print(json.dumps(program.summary()), flush=True)
    if program.failure is not None:
        print(f"robot-agent: error: {program.failure}", file=sys.stderr, flush=True)
        return PLUGIN_FAILED
    return code


def run_settings(
    chosen: Mapping[str, str], config: ControllerConfig
) -> tuple[ControllerConfig, Plugins]:
    """The run's controller settings with this program's own strategy and pooling
    operator, and the plug-ins they and its controller name, resolved."""
    settings = dataclasses.replace(
        config,
        strategy=chosen.get("strategy", config.strategy),
        pooling=chosen.get("pooling", config.pooling),
    )
    return settings, registry.resolve_plugins(settings, chosen.get("controller", "paper"))


if __name__ == "__main__":
    sys.exit(main())
