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
from collections.abc import Sequence

import zenoh

from nest_beacon.beacon import Beacon
from nest_beacon.options import add_beacon_options, beacon_config
from plumbing import cliargs
from plumbing.lifecycle import die_with_launcher
from plumbing.zenoh_session import open_from_args, reliable_publisher
from robot_agent import protocol

log = logging.getLogger("nest_beacon")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="nest-beacon",
        description="The nest beacon: robots that hear it know they are at the nest.",
    )
    parser.add_argument(
        "--name",
        type=cliargs.name,
        default="nest",
        help="beacon id on the radio; not all digits (default: nest)",
    )
    add_beacon_options(parser)
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="run seed (default: 0)")
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config = beacon_config(args, args.name)
    except ValueError as error:
        parser.exit(2, f"nest-beacon: error: {error}\n")
    cliargs.configure_logging("nest-beacon", args.log_level)
    beacon = Beacon(config, random.Random(protocol.derive_seed(args.seed, "beacon", args.name)))
    keys = protocol.Keys(args.run_id, args.root)
    clocks: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: clocks.put(None))
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"nest-beacon: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    rejected = 0
    with session:
        transmitter = reliable_publisher(session, keys.radio_tx(args.name))
        acknowledger = reliable_publisher(session, keys.beacon_ack(args.name))
        session.declare_subscriber(
            keys.world_clock, lambda sample: clocks.put(sample.payload.to_bytes())
        )
        token = session.liveliness().declare_token(keys.alive("beacon", args.name))
        log.info("beacon %s transmitting every %.2fs of sim time", args.name, config.period)
        while True:
            try:
                payload = clocks.get(timeout=0.5)
            except queue.Empty:
                continue
            if payload is None:
                break
            try:
                clock = protocol.decode(payload, protocol.Clock)
            except protocol.ProtocolError as error:
                rejected += 1
                if rejected == 1:
                    log.warning("rejected message on %s: %s", keys.world_clock, error)
                continue
            sent = 0
            for message in beacon.on_tick(clock.t):
                meta = protocol.RadioTxMeta(v=protocol.VERSION, tick=clock.tick, seq=message.seq)
                transmitter.put(protocol.encode(message), attachment=protocol.encode(meta))
                sent += 1
            acknowledger.put(
                protocol.encode(protocol.Ack(v=protocol.VERSION, tick=clock.tick, radio_tx=sent))
            )
        token.undeclare()
    log.info("beacon %s stopped (%d rejected clock messages)", args.name, rejected)
    return 0


if __name__ == "__main__":
    sys.exit(main())
