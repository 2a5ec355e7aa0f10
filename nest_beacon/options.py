"""The beacon's options, shared by ``nest-beacon`` and ``swarm run`` (as --beacon-*)."""

from __future__ import annotations

import argparse

from nest_beacon.beacon import BeaconConfig, parse_outages
from plumbing import cliargs


def outage(text: str) -> str:
    try:
        parse_outages([text])
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    start, _, end = text.partition(":")
    if not 0 <= float(start) < float(end):
        raise argparse.ArgumentTypeError(f"outage {text!r} must have 0 <= START < END")
    return text


def add_beacon_options(parser: argparse.ArgumentParser, prefix: str = "") -> list[argparse.Action]:
    group = parser.add_argument_group("nest beacon")
    add = group.add_argument
    return [
        add(
            f"--{prefix}period",
            dest="beacon_period",
            type=cliargs.positive_float,
            default=0.5,
            help="sim seconds between beacon transmissions (default: 0.5)",
        ),
        add(
            f"--{prefix}outage",
            dest="beacon_outage",
            type=outage,
            action="append",
            default=[],
            metavar="START:END",
            help="the beacon is silent from START to END sim seconds (repeatable)",
        ),
        add(
            f"--{prefix}flaky",
            dest="beacon_flaky",
            type=cliargs.probability,
            default=0.0,
            help="probability that a due beacon transmission is skipped (default: 0)",
        ),
    ]


def beacon_config(args: argparse.Namespace, name: str = "nest") -> BeaconConfig:
    return BeaconConfig(
        name=name,
        period=args.beacon_period,
        outages=parse_outages(args.beacon_outage),
        flaky=args.beacon_flaky,
    )
