"""The controller's options, shared by ``robot-agent`` and ``swarm run``."""

from __future__ import annotations

import argparse

from plumbing import cliargs
from robot_agent import decision
from robot_agent.controller import ControllerConfig


def add_controller_options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    group = parser.add_argument_group("decision")
    add = group.add_argument
    return [
        add(
            "--alpha",
            type=cliargs.alpha,
            default=0.0,
            help="evidence reliability parameter of Definition 1, in [0, 0.5] (default: 0)",
        ),
        add(
            "--threshold",
            type=cliargs.threshold,
            default=None,
            help="decide when an option reaches this probability "
            "(default: 1, or 0.99 when alpha > 0)",
        ),
        add(
            "--pooling",
            choices=list(decision.POOLING_OPERATORS),
            default="mprodop",
            help="opinion pooling at the nest: mprodop (Definition 2, evidence preserving) "
            "or loglinear (diluting: neighbours' opinions count with weight "
            f"{decision.LOGLINEAR_NEIGHBOUR_WEIGHT:g}; use with --alpha > 0) "
            "(default: mprodop)",
        ),
        add(
            "--dwell",
            type=cliargs.positive_float,
            default=3.0,
            help="sim seconds at the nest broadcasting and listening (default: 3)",
        ),
        add(
            "--broadcast-period",
            type=cliargs.positive_float,
            default=0.5,
            help="sim seconds between opinion broadcasts at the nest (default: 0.5)",
        ),
        add(
            "--linger",
            type=cliargs.non_negative_float,
            default=0.0,
            help="sim seconds broadcasting at the nest after deciding, the paper's fix "
            "for isolated robots (default: 0)",
        ),
    ]


def controller_config(args: argparse.Namespace) -> ControllerConfig:
    """The ControllerConfig for these options; ValueError if they do not fit together."""
    threshold = args.threshold
    if threshold is None:
        threshold = 1.0 if args.alpha == 0 else 0.99
    return ControllerConfig(
        alpha=args.alpha,
        threshold=threshold,
        pooling=args.pooling,
        dwell=args.dwell,
        broadcast_period=args.broadcast_period,
        linger=args.linger,
    )
