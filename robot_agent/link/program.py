"""``robot-agent --link``: one robot of a run, running outside the emulator, over a link.

    robot-agent --link udp://127.0.0.1:47800 --id 8 --key-file robot-8.key
    robot-agent --link serial:/dev/ttyUSB0@921600 --id 8 --key-file robot-8.key

``swarm run --external 8 --link ...`` keeps robot 8's body in the world and serves it over
the link through its bridge; this program is the robot: the same controller and the same
end of the wire as the emulated robot process (``RobotEndpoint``, robot_agent/core), with
the link in place of Zenoh. It says hello until the bridge welcomes it, asks the world for
its map (``world/info``, relayed), builds its controller (its RNG from the run's seed and
its id, as every robot's), sends its first status, and from then on steps once a tick's
inputs are in: sense, radio, camera frame as the world sealed them for it; act, radio and
status sealed with its own run key. The bridge relays them and can change none of them.

It imports only the portable core, the wire vocabulary and the link's transports: what
would run on a Raspberry Pi robot on Wi-Fi. Its key comes from a key file only (written by
``swarm run`` with mode 0600), never from the command line or the environment. When the
link goes (the bridge silent, restarted, a cable out) it says hello again until it is
answered and carries on from the world's current tick; when the bridge says the run has
ended it prints one JSON line (its decision, trips, pool sizes, link counts) and exits 0.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import secrets
import selectors
import signal
import stat
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from robot_agent.core import byzantine
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.endpoint import InputKind, Outgoing, OutputKind, RobotEndpoint
from robot_agent.link.client import LinkClient, Lost, Received, Welcomed
from robot_agent.link.transport import LinkClosedError, Transport, open_transport
from wire import auth, link, names, protocol, settings
from wire.rng import Stream

log = logging.getLogger("robot_agent.link")

ASK_EVERY = 1.0  # seconds between questions for the map until one is answered
# Seconds between two sendings of the robot's latest status. The robot process publishes a
# status when it changes, over Zenoh, which does not lose it; a link may lose frames, and
# a status lost (a decision) would be lost for good. A repeat changes nothing anywhere.
STATUS_EVERY = 2.0
MAX_WAIT = 0.2  # seconds the loop waits at most (a stop signal is seen within it)
REOPEN_EVERY = 1.0  # seconds between attempts to reopen a transport that closed
DRAIN_WAIT = 2.0  # seconds to let a paced serial line send the goodbye
# The link's kind of each input the robot's endpoint takes, and of each message it sends.
# Inputs that come before the robot can step (none, normally: the bridge makes it present
# only once it has sent its first status) are dropped and counted.
INPUT_OF = {
    link.DataKind.SENSE: InputKind.SENSE,
    link.DataKind.RADIO_RX: InputKind.RADIO_RX,
    link.DataKind.CAMERA: InputKind.CAMERA,
}
OUTPUT_OF = {
    OutputKind.RADIO_TX: link.DataKind.RADIO_TX,
    OutputKind.ACT: link.DataKind.ACT,
}


class KeyFileError(ValueError):
    """A key file that cannot be used (unreadable, not one, not the robot's)."""


def read_key_file(path: Path, robot: int) -> tuple[str, auth.Keyring]:
    """The run and the robot's keyring in a key file; KeyFileError says what is wrong."""
    try:
        text = path.read_text()
        mode = path.stat().st_mode
    except OSError as error:
        raise KeyFileError(f"cannot read key file {path}: {error.strerror}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("key file %s can be read by other users (chmod 600 it)", path)
    try:
        run, keyring = auth.keyring_from_text(text)
    except ValueError as error:
        raise KeyFileError(f"{path}: {error}") from None
    identity = names.robot_identity(robot)
    if not keyring.holds(identity):
        raise KeyFileError(f"{path} holds no key for robot {robot}")
    return run, keyring.only([identity])


@dataclass
class Asking:
    """The question for the map under way: its nonce, and when to ask again."""

    nonce: bytes
    again_at: float


@dataclass
class LinkRobot:
    """The program without its I/O: the link session (``client``), the question for the
    map, and once it is answered the robot's endpoint, fed what the link brings."""

    robot: int
    run: str
    keyring: auth.Keyring
    client: LinkClient
    endpoint: RobotEndpoint | None = None
    worlds: set[str] = field(default_factory=set)  # world instances the bridge reports
    asking: Asking | None = None
    ended: bool = False
    last_status: Outgoing | None = None
    status_again_at: float = 0.0
    dropped: Counter[str] = field(default_factory=Counter)  # inputs it could not use

    @classmethod
    def create(cls, robot: int, run: str, keyring: auth.Keyring) -> LinkRobot:
        key = keyring.key(names.robot_identity(robot))
        assert key is not None  # read_key_file checked it
        return cls(robot, run, keyring, LinkClient(robot, link.link_key(key)))

    @property
    def identity(self) -> str:
        return names.robot_identity(self.robot)

    @property
    def deadline(self) -> float:
        asked = self.asking.again_at if self.asking is not None else math.inf
        status = self.status_again_at if self.last_status is not None else math.inf
        return min(self.client.deadline, asked, status)

    # --- fed by the loop -----------------------------------------------------------

    def wake(self, now: float) -> None:
        for event in self.client.wake(now):
            self._take(event, now)
        if self.asking is not None and now >= self.asking.again_at and self.client.open:
            self._ask(now)
        if self.last_status is not None and now >= self.status_again_at and self.client.open:
            self._send_status(self.last_status, now)

    def receive(self, data: bytes, now: float) -> None:
        for event in self.client.receive(data, now):
            self._take(event, now)

    def stop(self) -> None:
        self.client.bye(link.ByeReason.GOING_AWAY)

    # --- events of the link --------------------------------------------------------

    def _take(self, event: Welcomed | Received | Lost, now: float) -> None:
        if isinstance(event, Welcomed):
            self._welcomed(event.welcome, now)
        elif isinstance(event, Lost):
            self._lost(event)
        else:
            self._received(event, now)

    def _welcomed(self, welcome: link.LinkWelcome, now: float) -> None:
        if welcome.run != self.run:
            log.error("the bridge serves run %s, the key file is of run %s", welcome.run, self.run)
            self.client.bye(link.ByeReason.GOING_AWAY)
            self.ended = True
            return
        log.info("robot %d: link session %d open", self.robot, self.client.sessions)
        if self.endpoint is None:
            self._ask(now)
        else:  # back after a lost link: say where it is, and so be present again
            self._send_status(self.endpoint.status(max(0, self.endpoint.last_tick)), now)

    def _lost(self, event: Lost) -> None:
        self.asking = None
        if self.endpoint is not None:
            for instance in sorted(self.worlds):  # the world is out of reach with the link
                self.endpoint.world_vanished(instance)
        self.worlds.clear()
        if event.ended:
            log.info("robot %d: the run has ended", self.robot)
            self.ended = True

    def _received(self, event: Received, now: float) -> None:
        kind = event.kind
        if kind is link.DataKind.INFO_REPLY:
            self._answered(event.payload, event.attachment, now)
        elif kind is link.DataKind.INFO_ERROR:
            log.warning("the world refused the question for the map: %r", event.payload[:200])
        elif kind in (link.DataKind.WORLD_UP, link.DataKind.WORLD_DOWN):
            self._world(kind, event.payload)
        elif (input_kind := INPUT_OF.get(kind)) is not None:
            if self.endpoint is None:
                self.dropped[kind.name.lower()] += 1
                return
            step = self.endpoint.receive(input_kind, event.payload, event.attachment)
            if step is None:
                return
            for message in step.outgoing:  # its transmissions, its act, its status if new
                if message.kind is OutputKind.STATUS:
                    self._send_status(message, now)
                else:
                    self.client.send(OUTPUT_OF[message.kind], message.payload, message.attachment)

    def _world(self, kind: link.DataKind, payload: bytes) -> None:
        instance = payload.decode(errors="replace")[: names.MAX_NAME_LENGTH]
        if kind is link.DataKind.WORLD_UP:
            self.worlds.add(instance)
            if self.endpoint is not None:
                self.endpoint.world_appeared(instance)
        else:
            self.worlds.discard(instance)
            if self.endpoint is not None:
                self.endpoint.world_vanished(instance)

    # --- the map -------------------------------------------------------------------

    def _keys(self) -> protocol.Keys:
        welcome = self.client.welcome
        assert welcome is not None
        return protocol.Keys(welcome.run, welcome.root)

    def _ask(self, now: float) -> None:
        """Ask ``world/info``, in the robot's name, with a fresh nonce (auth.query_seal)."""
        nonce = secrets.token_bytes(auth.NONCE_BYTES)
        key = self._keys().world_info
        attachment = auth.query_seal(self.keyring, self.identity, key, b"", nonce)
        self.client.send(link.DataKind.INFO_QUERY, b"", attachment)
        self.asking = Asking(nonce, now + ASK_EVERY)

    def _answered(self, payload: bytes, attachment: bytes | None, now: float) -> None:
        if self.asking is None or self.endpoint is not None:
            return  # an answer to a question no longer asked
        keys = self._keys()
        try:
            auth.reply_open(
                self.keyring,
                self.identity,
                keys.world_info,
                payload,
                attachment,
                nonce=self.asking.nonce,
            )
            info = protocol.decode(payload, protocol.WorldInfo)
        except (auth.AuthError, protocol.ProtocolError) as error:
            log.warning(
                "robot %d: an answer on world/info that does not hold: %s", self.robot, error
            )
            return
        self.asking = None
        self.endpoint = self._build(keys, info)
        for instance in sorted(self.worlds):
            self.endpoint.world_appeared(instance)
        self._send_status(self.endpoint.status(0), now)

    def _build(self, keys: protocol.Keys, info: protocol.WorldInfo) -> RobotEndpoint:
        """The robot as every robot of the run is built (robot_agent/node/cli.py): the
        run's controller settings, its RNG from the world's seed and its id."""
        welcome = self.client.welcome
        assert welcome is not None
        config = settings.decode(bytes(welcome.controller), ControllerConfig)
        rng = Stream.named(info.seed, "robot", self.robot)
        controller = byzantine.build_controller(self.robot, info, config, rng)
        log.info(
            "robot %d: %d sites, clock %s, seed %d: running",
            self.robot,
            len(info.sites),
            info.clock,
            info.seed,
        )
        return RobotEndpoint(
            self.robot, keys=keys, controller=controller, world=info, keyring=self.keyring
        )

    def _send_status(self, status: Outgoing, now: float) -> None:
        """Send the robot's status, and again every STATUS_EVERY until it changes."""
        self.client.send(link.DataKind.STATUS, status.payload, status.attachment)
        self.last_status = status
        self.status_again_at = now + STATUS_EVERY

    # --- what it did ---------------------------------------------------------------

    def summary(self) -> dict[str, object]:
        controller = self.endpoint.controller if self.endpoint is not None else None
        status = (
            controller.status(self.endpoint.last_tick) if controller and self.endpoint else None
        )
        return {
            "id": self.robot,
            "phase": status.phase if status else None,
            "decided_site": status.decided_site if status else None,
            "decision_time": status.decision_time if status else None,
            "trips": status.trips if status else 0,
            "last_tick": self.endpoint.last_tick if self.endpoint else None,
            "rejected": self.endpoint.rejects.count if self.endpoint else 0,
            "sessions": self.client.sessions,
            "refused": dict(self.client.refused),
            "dropped": dict(self.dropped),
        }


class Stop:
    """Set by SIGINT or SIGTERM: the loop says goodbye and returns."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, *_: object) -> None:
        self.requested = True


def serve(
    program: LinkRobot,
    address: link.LinkAddress,
    stop: Stop,
    give_up: float | None = None,
) -> int:
    """Run the program on its link until the run ends (0), a stop signal (0), or no session
    for ``give_up`` seconds (1)."""
    transport: Transport | None = None
    reopen_at = 0.0
    selector = selectors.DefaultSelector()
    alone_since = time.monotonic()
    try:
        while not program.ended and not stop.requested:
            now = time.monotonic()
            if transport is None and now >= reopen_at:
                try:
                    transport = open_transport(address)
                    selector.register(transport, selectors.EVENT_READ)
                except OSError as error:
                    log.warning("cannot open the link %s: %s", address, error)
                    reopen_at = now + REOPEN_EVERY
            if program.client.open:
                alone_since = now
            elif give_up is not None and now - alone_since > give_up:
                log.error("no bridge answered on %s for %g s: giving up", address, give_up)
                return 1
            program.wake(now)
            try:
                if transport is not None:
                    _exchange(program, transport, selector, now)
            except LinkClosedError as error:
                log.warning("the link closed: %s; reopening it", error)
                selector.unregister(transport)  # type: ignore[arg-type]
                transport.close()  # type: ignore[union-attr]
                transport = None
                reopen_at = now + REOPEN_EVERY
        if transport is not None:
            program.stop()
            _drain(program, transport)
        return 0
    finally:
        if transport is not None:
            transport.close()
        selector.close()


def _exchange(
    program: LinkRobot, transport: Transport, selector: selectors.BaseSelector, now: float
) -> None:
    """Send what is due, wait for the link until the next deadline, take what came."""
    for frame in program.client.take_outgoing():
        transport.send(frame, now)
    transport.flush(now)
    deadline = min(program.deadline, transport.deadline or math.inf)
    wait = min(max(0.0, deadline - time.monotonic()), MAX_WAIT)
    if selector.select(wait):
        now = time.monotonic()
        for data in transport.receive(now):
            program.receive(data, now)
        for frame in program.client.take_outgoing():  # answer at once
            transport.send(frame, now)
        transport.flush(now)


def _drain(program: LinkRobot, transport: Transport) -> None:
    """Send what is left (the goodbye), waiting for a paced line at most DRAIN_WAIT."""
    now = time.monotonic()
    for frame in program.client.take_outgoing():
        transport.send(frame, now)
    deadline = now + DRAIN_WAIT
    while transport.deadline is not None and time.monotonic() < deadline:
        time.sleep(max(0.0, min(transport.deadline - time.monotonic(), 0.05)))
        transport.flush(time.monotonic())
    transport.flush(time.monotonic())


# --- command line ------------------------------------------------------------------------


def link_address(text: str) -> link.LinkAddress:
    try:
        return link.parse_address(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def robot_id(text: str) -> int:
    robot = names.robot_of_name(text)
    if robot is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a robot id (0 to {names.MAX_ROBOTS - 1})"
        )
    return robot


def seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robot-agent --link",
        description="One robot of a run, outside the emulator: its controller over a link "
        "(UDP or serial) to the run's bridge (swarm run --external ... --link ...).",
    )
    parser.add_argument(
        "--link",
        type=link_address,
        required=True,
        metavar="ADDRESS",
        help="the bridge: udp://HOST:PORT, or serial:PATH[@BAUD] (default baud "
        f"{link.DEFAULT_BAUD})",
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
        type=seconds,
        default=None,
        metavar="SECONDS",
        help="exit with code 1 when no bridge has answered for this long (default: keep trying)",
    )
    parser.add_argument(
        "--log-level",
        default="info",
        choices=["debug", "info", "warning", "error"],
        help="default: info",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(),
        format=f"robot-agent[link {args.id}] %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    try:
        run, keyring = read_key_file(args.key_file, args.id)
    except KeyFileError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    stop = Stop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, stop)
    program = LinkRobot.create(args.id, run, keyring)
    log.info("robot %d of run %s: saying hello on %s", args.id, run, args.link)
    code = serve(program, args.link, stop, args.give_up)
    print(json.dumps(program.summary()), flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
