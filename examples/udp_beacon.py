"""The nest beacon on a UDP radio: the other half of the worked example (docs/porting.md).

    python examples/udp_beacon.py --interface wlan0

It broadcasts a ``BeaconPayload`` every ``--period`` seconds, under the sender name
``--name``, on the group and port the robots use (examples/udp_robot.py). It runs until
SIGINT/SIGTERM or ``--max-seconds``, then prints one JSON line with its radio counts.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

# Run as a script (python examples/udp_beacon.py), the repository root is not on the path.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from examples.udp_radio import DEFAULT_GROUP, DEFAULT_PORT, UdpRadio
from nest_beacon.core.beacon import Beacon, BeaconConfig

STOP = threading.Event()


def run(args: argparse.Namespace) -> dict[str, object]:
    beacon = Beacon(
        BeaconConfig(name=args.name, period=args.period),
        Stream.named(args.seed, "beacon", args.name),
    )
    with UdpRadio(
        args.name, address=args.address, port=args.port, interface=args.interface
    ) as radio:
        start = time.monotonic()
        tick = 0
        while not STOP.is_set():
            t = tick * args.dt  # clock seconds at this tick
            if t >= args.max_seconds:
                break
            for message in beacon.on_tick(t):
                radio.send(protocol.encode(message))
            radio.poll()  # drain what the robots say: the beacon listens to no one
            tick += 1
            delay = start + tick * args.dt / args.speed - time.monotonic()
            if delay > 0:
                STOP.wait(delay)
        return {"name": args.name, "transmissions": beacon.seq, "radio": asdict(radio.stats)}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="udp_beacon", description="The nest beacon of a swarm on a UDP radio."
    )
    parser.add_argument(
        "--name",
        type=cliargs.name,
        default="nest",
        help="sender name; not all digits, which are robot ids (default: nest)",
    )
    parser.add_argument(
        "--period",
        type=cliargs.positive_float,
        default=0.5,
        help="clock seconds between transmissions (default: 0.5)",
    )
    parser.add_argument(
        "--dt",
        type=cliargs.positive_float,
        default=0.1,
        help="clock seconds between checks (default: 0.1)",
    )
    parser.add_argument("--seed", type=cliargs.seed, default=0)
    parser.add_argument(
        "--address",
        default=DEFAULT_GROUP,
        help=f"multicast group or broadcast address (default: {DEFAULT_GROUP})",
    )
    parser.add_argument("--port", type=cliargs.int_range(1, 65535), default=DEFAULT_PORT)
    parser.add_argument(
        "--interface",
        default=None,
        help="network interface: IPv4 address, or name (Linux, multicast)",
    )
    parser.add_argument(
        "--speed",
        type=cliargs.positive_float,
        default=1.0,
        help="clock seconds per wall second (default: 1, real time)",
    )
    parser.add_argument(
        "--max-seconds",
        type=cliargs.positive_float,
        default=float("inf"),
        help="stop after this many clock seconds (default: never)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        BeaconConfig(name=args.name, period=args.period)
    except ValueError as error:
        parser.exit(2, f"udp_beacon: error: {error}\n")
    # Not STOP.set() in a handler: it could wait for the lock of the STOP.wait it interrupts.
    on_stop_signals(lambda _: STOP.set())
    try:
        summary = run(args)
    except (ValueError, OSError) as error:
        parser.exit(2, f"udp_beacon: error: {error}\n")
    print(json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
