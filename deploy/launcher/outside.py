"""Robots outside the emulator (hardware in the loop): what ``swarm run --external`` asks for.

``--external 8,9`` leaves robots 8 and 9 to programs outside the run (``robot-agent
--link``, or a port's firmware): the world keeps their bodies and a bridge process
(world_server/bridge) serves each over its link. ``--link`` says where: one UDP address
for every outside robot (``udp://127.0.0.1:PORT``, loopback by default, a free port if
none is given) and, robot by robot, serial lines (``--link 9=serial:/dev/ttyUSB0@921600``).
The run writes each outside robot's run key to ``robot-ID.key`` (mode 0600) in
``--link-keys DIR`` (by default the run's private directory), prints the command that
starts each program, and waits ``--link-wait`` seconds for them all to connect before it
gives up with an error that names the robot and its link.
"""

from __future__ import annotations

import argparse
import os
import shlex
import socket
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from bestofn_swarm.link.core import codec
from bestofn_swarm.wire import auth, names
from world_server.bridge import keys as link_keys
from world_server.bridge.bridge import LinkedRobot
from world_server.bridge.cli import add_impairment_options, impairment_of
from world_server.bridge.core.impairment import LinkImpairment

DEFAULT_LINK_HOST = "127.0.0.1"  # the bridge listens on loopback unless told otherwise
DEFAULT_WAIT = 60.0  # wall seconds for every outside robot to connect
KEY_FILE = "robot-{robot}.key"


@dataclass(frozen=True)
class OutsidePlan:
    """The outside robots of a run, their links, and how long to wait for them."""

    robots: tuple[LinkedRobot, ...]
    wait: float = DEFAULT_WAIT
    keys_dir: Path | None = None  # None: the run's private directory
    impairment: LinkImpairment = field(default_factory=LinkImpairment)

    @property
    def ids(self) -> list[int]:
        return [linked.robot for linked in self.robots]

    def address_of(self, robot: int) -> codec.LinkAddress:
        return next(linked.address for linked in self.robots if linked.robot == robot)

    def bridge_argv(self, run_id: str, seed: int, controller: str, encrypted: bool) -> list[str]:
        """The bridge's run, robots, controller settings and impairment (its network later)."""
        argv = ["--run-id", run_id, "--seed", str(seed), "--controller", controller]
        for linked in self.robots:
            argv += ["--robot", f"{linked.robot}={linked.address}"]
        impairment = self.impairment
        argv += [
            "--link-delay",
            repr(impairment.delay * 1000),
            "--link-jitter",
            repr(impairment.jitter * 1000),
            "--link-loss",
            repr(impairment.loss),
        ]
        return [*argv, "--encrypt"] if encrypted else argv

    def command(self, robot: int, key_file: Path) -> str:
        """The command that starts robot ``robot``'s program, as a porter types it."""
        address = self.address_of(robot)
        if address.transport == "serial":
            target = f"serial:DEVICE@{address.baud}"  # the robot's end of the line
        elif address.host in ("0.0.0.0", "::"):
            target = f"udp://THIS_HOST:{address.port}"
        else:
            target = str(address)
        return shlex.join(
            ["robot-agent", "--link", target, "--id", str(robot), "--key-file", str(key_file)]
        )


def add_outside_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("robots outside the emulator (hardware in the loop)")
    group.add_argument(
        "--external",
        type=robot_ids,
        default=None,
        metavar="IDS",
        help="leave these robots (e.g. 8,9) to programs outside the run, served over "
        "--link by a bridge; the run prints the command that starts each (docs/porting.md)",
    )
    group.add_argument(
        "--link",
        dest="links",
        action="append",
        default=None,
        metavar="[ID=]ADDRESS",
        help="where the outside robots connect: udp://HOST:PORT for all of them (default "
        f"udp://{DEFAULT_LINK_HOST}:<free port>), or ID=serial:PATH[@BAUD] for one "
        "(repeatable)",
    )
    group.add_argument(
        "--link-wait",
        type=positive_seconds,
        default=DEFAULT_WAIT,
        metavar="SECONDS",
        help="give up (exit 1, naming the robot) when an outside robot has not connected "
        f"this long after the run started (default: {DEFAULT_WAIT:g})",
    )
    group.add_argument(
        "--link-keys",
        type=Path,
        default=None,
        metavar="DIR",
        help="write each outside robot's key to DIR/robot-ID.key (default: the run's private "
        "directory, removed when the run ends)",
    )
    add_impairment_options(group)


def robot_ids(text: str) -> list[int]:
    ids = [names.robot_of_name(part.strip()) for part in text.split(",")]
    if not ids or None in ids:
        raise argparse.ArgumentTypeError(f"{text!r}: give robot ids separated by commas, e.g. 8,9")
    return [robot for robot in ids if robot is not None]


def positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value < 1e6:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def outside_plan(args: argparse.Namespace, robots: int) -> OutsidePlan | None:
    """The outside robots ``args`` ask for (None: none); ValueError (a usage error)."""
    external: list[int] | None = args.external
    if not external:
        if args.links:
            raise ValueError("--link says where outside robots connect: give --external too")
        return None
    if len(set(external)) != len(external):
        raise ValueError("--external names a robot twice")
    for robot in external:
        if robot >= robots:
            raise ValueError(
                f"--external {robot}: there is no robot {robot} in a swarm of {robots}"
            )
    if args.no_keys:
        raise ValueError("--external: the link is authenticated with run keys; drop --no-keys")
    if args.connect is not None and args.link_keys is None:
        raise ValueError("--external with --connect: say where the keys go (--link-keys DIR)")
    shared, own = links_of(args.links or [], external)
    if shared is None:
        shared = codec.LinkAddress("udp", host=DEFAULT_LINK_HOST, port=0)
    if shared.transport != "udp":
        raise ValueError("--link without ID= is the UDP address of every outside robot")
    if shared.port == 0 and any(robot not in own for robot in external):
        shared = codec.LinkAddress("udp", host=shared.host, port=free_udp_port(shared.host))
    linked = tuple(LinkedRobot(robot, own.get(robot, shared)) for robot in sorted(external))
    return OutsidePlan(linked, args.link_wait, args.link_keys, impairment_of(args))


def links_of(
    texts: Sequence[str], external: Sequence[int]
) -> tuple[codec.LinkAddress | None, dict[int, codec.LinkAddress]]:
    """The shared UDP address and the links given robot by robot."""
    shared: codec.LinkAddress | None = None
    own: dict[int, codec.LinkAddress] = {}
    for text in texts:
        robot_text, equals, address_text = text.partition("=")
        if not equals or "://" in robot_text or ":" in robot_text:
            address = codec.parse_address(text)
            if shared is not None:
                raise ValueError("--link: one address for every outside robot on UDP")
            shared = address
            continue
        robot = names.robot_of_name(robot_text)
        if robot is None or robot not in external:
            raise ValueError(f"--link {text}: robot {robot_text} is not one of --external")
        if robot in own:
            raise ValueError(f"--link names robot {robot} twice")
        own[robot] = codec.parse_address(address_text)
    udp = {address for address in own.values() if address.transport == "udp"}
    if shared is not None:
        udp.add(shared)
    if len(udp) > 1:
        raise ValueError("--link: every outside robot on UDP shares one address")
    if udp and shared is None:
        (shared,) = udp
    return shared, own


def free_udp_port(host: str) -> int:
    """A UDP port on ``host`` that is free right now."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


# --- keys --------------------------------------------------------------------------------


def write_key_files(
    directory: Path, keyring: auth.Keyring, run_id: str, robots: Iterable[int]
) -> dict[int, Path]:
    """Each robot's run key in ``directory``/robot-ID.key, readable by this user only."""
    directory.mkdir(parents=True, exist_ok=True)
    written = {}
    for robot in robots:
        path = directory / KEY_FILE.format(robot=robot)
        text = auth.keyring_to_text(keyring.only([names.robot_identity(robot)]), run_id)
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(descriptor, "w") as file:
            file.write(text + "\n")
        path.chmod(0o600)
        written[robot] = path
    return written


def link_keys_env(keyring: auth.Keyring, run_id: str, robots: Iterable[int]) -> dict[str, str]:
    """The bridge's link keys (never the robots' run keys), for its environment."""
    keys = {}
    for robot in robots:
        key = keyring.key(names.robot_identity(robot))
        assert key is not None  # the launcher holds the run secret
        keys[robot] = codec.link_key(key)
    return {link_keys.LINK_KEYS_ENV: link_keys.to_text(run_id, keys)}
