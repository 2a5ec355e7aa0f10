"""The controller's options, shared by ``robot-agent`` and ``swarm run``."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from plumbing import cliargs
from robot_agent import byzantine, decision
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


def byzantine_robot(text: str) -> byzantine.ByzantineRobot:
    """``--byzantine ROBOT[:MODE]``, e.g. ``3``, ``3:liar=0``, ``3:inverted``."""
    try:
        return byzantine.ByzantineRobot.parse(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_byzantine_option(parser: argparse.ArgumentParser) -> None:
    """``robot-agent --byzantine ROBOT:MODE``: which hosted robots misbehave, and how."""
    parser.add_argument(
        "--byzantine",
        type=byzantine_robot,
        action="append",
        default=[],
        metavar="ROBOT:MODE",
        help="hosted robot ROBOT misbehaves (repeatable): liar=SITE, inverted or silent "
        "(a fault experiment; swarm run --byzantine chooses a liar's site itself)",
    )


def hosted_byzantine(
    switches: Sequence[byzantine.ByzantineRobot], hosted: Sequence[int]
) -> dict[int, byzantine.Behaviour]:
    """The ``--byzantine`` switches by robot; ValueError unless each names a robot hosted
    here (by a fixed --id) once, and each liar names its site."""
    chosen: dict[int, byzantine.Behaviour] = {}
    for switch in switches:
        if switch.robot not in hosted:
            raise ValueError(f"--byzantine {switch}: robot {switch.robot} is not hosted here")
        if switch.robot in chosen:
            raise ValueError(f"--byzantine names robot {switch.robot} twice")
        if switch.behaviour.mode == "liar" and switch.behaviour.site is None:
            raise ValueError(f"--byzantine {switch}: name the site it claims, e.g. liar=0")
        chosen[switch.robot] = switch.behaviour
    return chosen
