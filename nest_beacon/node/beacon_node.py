"""``nest-beacon``: the nest's radio transmitter as its own process.

It follows ``world/clock``: for every tick it transmits when due (through the radio
medium, like a robot) and answers the tick on ``beacon/<name>/ack``, so it takes part in
the lockstep barrier like any controller.
"""

from __future__ import annotations

import argparse
import logging
import queue
import random
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import zenoh

from nest_beacon.core.beacon import Beacon
from nest_beacon.node.options import NEST_BEACON_OPTIONS, NestBeaconConfig
from plumbing import cliargs, run_keys, settings_cli
from plumbing.inbox import BoundedInbox
from plumbing.lifecycle import die_with_launcher
from plumbing.world_info import fetch_world_info
from plumbing.zenoh_session import open_from_args, reliable_publisher
from wire import auth, guard, names, protocol
from wire.names import Role

log = logging.getLogger("nest_beacon")
INBOX_BYTES = 16 * 2**20
MAX_MESSAGE_BYTES = 1024  # a clock and its tag are under 100 bytes


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="nest-beacon",
        description="The nest beacon: robots that hear it know they are at the nest.",
    )
    NEST_BEACON_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, NestBeaconConfig)
    parser.add_argument(
        "--info-timeout",
        type=cliargs.positive_float,
        default=60.0,
        help="wall seconds to wait for the world server (default: 60)",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


@dataclass(frozen=True)
class _Input:
    kind: str  # clock | world | no-world | stop
    payload: bytes = b""
    attachment: bytes | None = None


class BeaconNode:
    """The beacon on Zenoh: believes a clock only if it is the followed world's next tick."""

    def __init__(
        self,
        beacon: Beacon,
        keys: protocol.Keys,
        dt: float,
        keyring: auth.Keyring | None,
        *,
        transmit: Callable[[bytes, bytes | None], None],
        acknowledge: Callable[[bytes, bytes | None], None],
    ) -> None:
        self.beacon = beacon
        self.name = beacon.config.name
        self.keys = keys
        self.dt = dt
        self.keyring = keyring
        self.transmit = transmit
        self.acknowledge = acknowledge
        self.ticks = guard.TickWindow()
        self.worlds = guard.WorldFollower()
        self.rejected = 0

    def handle(self, item: _Input) -> None:
        if item.kind in ("world", "no-world"):
            instance = item.payload.decode(errors="replace")
            present = item.kind == "world"
            seen = self.worlds.appeared(instance) if present else None
            if seen == "new":
                log.warning("beacon %s: a new world server appeared; following it", self.name)
                self.ticks = guard.TickWindow()
                self.beacon.follow_new_world()
            elif seen == "back":  # its ticks went on while this beacon was cut off
                log.warning("beacon %s: the world server is back; following it", self.name)
                self.ticks.rejoin()
            elif not present:
                self.worlds.vanished(instance)
            return
        try:
            auth.unseal(
                self.keyring, names.WORLD, self.keys.world_clock, item.payload, item.attachment
            )
            clock = protocol.decode(item.payload, protocol.Clock)
            refused = guard.time_refused(clock.tick, clock.t, self.dt) or self.ticks.refuses(
                clock.tick
            )
            if refused:
                raise protocol.ProtocolError(refused)
        except (auth.AuthError, protocol.ProtocolError) as error:
            self._reject(error)
            return
        if not self.ticks.ahead(clock.tick):
            return  # a tick already answered
        self.ticks.acted(clock.tick)
        sent = 0
        for message in self.beacon.on_tick(clock.t):
            payload = protocol.encode(message)
            meta = protocol.encode(
                protocol.RadioTxMeta(v=protocol.VERSION, tick=clock.tick, seq=message.seq)
            )
            self.transmit(payload, self._seal(self.keys.radio_tx(self.name), payload, meta))
            sent += 1
        ack = protocol.encode(
            protocol.Ack(v=protocol.VERSION, tick=clock.tick, radio_tx=sent, rejected=self.rejected)
        )
        self.acknowledge(ack, self._seal(self.keys.beacon_ack(self.name), ack))

    def _reject(self, error: Exception) -> None:
        self.rejected += 1
        if self.rejected == 1:
            log.warning(
                "rejected message on %s: %s (further ones not logged)", self.keys.world_clock, error
            )

    def _seal(self, key: str, payload: bytes, metadata: bytes = b"") -> bytes | None:
        return auth.seal(self.keyring, names.beacon_identity(self.name), key, payload, metadata)


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    parser = build_parser()
    args = parser.parse_args(argv)
    process_config: NestBeaconConfig = settings_cli.config_from(parser, args, NEST_BEACON_OPTIONS)
    config = process_config.beacon
    name = config.name
    cliargs.configure_logging("nest-beacon", args.log_level)
    keyring = run_keys.from_args(parser, args, "nest-beacon")
    identity = names.beacon_identity(name)
    if keyring is not None and not (keyring.holds(identity) and keyring.holds(names.WORLD)):
        parser.exit(2, "nest-beacon: error: the beacon needs its own key and the world's\n")
    rng = random.Random(protocol.derive_seed(process_config.seed, "beacon", name))
    beacon = Beacon(config, rng)
    keys = protocol.Keys(args.run_id, args.root)
    inbox: BoundedInbox[_Input] = BoundedInbox(INBOX_BYTES, MAX_MESSAGE_BYTES)
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: inbox.put(_Input("stop")))
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"nest-beacon: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    with session:
        try:
            info = fetch_world_info(session, keys, args.info_timeout, keyring, identity)
        except TimeoutError as error:
            print(f"nest-beacon: {error}", file=sys.stderr)
            return 1
        transmitter = reliable_publisher(session, keys.radio_tx(name))
        acknowledger = reliable_publisher(session, keys.beacon_ack(name))
        node = BeaconNode(
            beacon,
            keys,
            info.dt,
            keyring,
            transmit=lambda payload, attachment: transmitter.put(payload, attachment=attachment),
            acknowledge=lambda payload, attachment: acknowledger.put(
                payload, attachment=attachment
            ),
        )

        lock = threading.Lock()  # the beacon: one thread at a time
        stopped = threading.Event()  # set under the lock: later clocks are not answered

        def on_clock(sample: zenoh.Sample) -> None:
            """Answered in Zenoh's callback: a wake-up of the main thread per tick was most
            of the beacon's answer time, and it is in the lockstep barrier."""
            payload = sample.payload.to_bytes()
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            item = _Input("clock", payload, extra)
            size = len(payload) + len(extra or b"")
            if size > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                inbox.put(item, size)
                return
            with lock:
                if not stopped.is_set():
                    node.handle(item)

        def on_world(sample: zenoh.Sample) -> None:
            kind = "world" if sample.kind == zenoh.SampleKind.PUT else "no-world"
            inbox.put(_Input(kind, keys.last_chunk(str(sample.key_expr)).encode()))

        session.liveliness().declare_subscriber(keys.alive(Role.WORLD, "*"), on_world, history=True)
        session.declare_subscriber(keys.world_clock, on_clock)
        token = session.liveliness().declare_token(keys.alive(Role.BEACON, name))
        log.info("beacon %s transmitting every %.2fs of sim time", name, config.period)
        while True:
            try:
                item = inbox.get(timeout=0.5)
            except queue.Empty:
                item = None
            if item is not None and item.kind == "stop":
                with lock:
                    stopped.set()
                break
            with lock:
                if item is not None:
                    node.handle(item)
                node.rejected += inbox.take_dropped(None)
        token.undeclare()
    log.info("beacon %s stopped (%d rejected clock messages)", name, node.rejected)
    return 0


if __name__ == "__main__":
    sys.exit(main())
