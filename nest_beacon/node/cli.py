"""``nest-beacon``: the command that runs the nest's radio transmitter as its own process
(``python -m nest_beacon``).

It follows ``world/clock``: for every tick it transmits when due (through the radio
medium, like a robot) and answers the tick on ``beacon/<name>/ack``, so it takes part in
the lockstep barrier like any controller (nest_beacon/core/endpoint.py; on Zenoh,
beacon_node.py).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

import zenoh

from bestofn_swarm.plumbing import cliargs, process_main, settings_cli
from bestofn_swarm.plumbing.inbox import STOP, BoundedInbox
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.plumbing.world_info import fetch_world_info
from bestofn_swarm.plumbing.zenoh_session import open_from_args
from bestofn_swarm.wire import names
from bestofn_swarm.wire.rng import Stream
from nest_beacon.core.beacon import Beacon
from nest_beacon.core.endpoint import BeaconEndpoint
from nest_beacon.node.beacon_node import (
    INBOX_BYTES,
    MAX_MESSAGE_BYTES,
    BeaconNode,
    Event,
)
from nest_beacon.node.options import NEST_BEACON_OPTIONS, NestBeaconConfig

log = logging.getLogger("nest_beacon")


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


def beacon_config(parser: argparse.ArgumentParser, args: argparse.Namespace) -> NestBeaconConfig:
    config: NestBeaconConfig = settings_cli.config_from(parser, args, NEST_BEACON_OPTIONS)
    return config


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin("nest-beacon", parser, argv, beacon_config)
    args, process_config, keyring, keys = begun.args, begun.settings, begun.keyring, begun.keys
    config = process_config.beacon
    name = config.name
    identity = names.beacon_identity(name)
    if keyring is not None and not (keyring.holds(identity) and keyring.holds(names.WORLD)):
        parser.exit(2, "nest-beacon: error: the beacon needs its own key and the world's\n")
    inbox: BoundedInbox[Event] = BoundedInbox(INBOX_BYTES, MAX_MESSAGE_BYTES)
    on_stop_signals(lambda _: inbox.put(Event(STOP), control=True))
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
        if process_config.seed is not None and process_config.seed != info.seed:
            print(
                f"nest-beacon: error: --seed {process_config.seed} is not the seed of the world "
                f"of run {info.run} ({info.seed}); leave --seed out to take the world's",
                file=sys.stderr,
            )
            return 2
        beacon = Beacon(config, Stream.named(info.seed, "beacon", name))
        endpoint = BeaconEndpoint(beacon, keys, info.dt, keyring)
        node = BeaconNode(endpoint, session=session, keys=keys, inbox=inbox)
        node.start()
        log.info("beacon %s transmitting every %.2fs of sim time", name, config.period)
        code = node.serve()
        node.close()
    log.info("beacon %s stopped (%d rejected clock messages)", name, endpoint.rejected)
    process_main.end(code)


if __name__ == "__main__":
    sys.exit(main())
