"""The world's options: one definition for ``world-server``, ``swarm run`` and sweeps.

``add_world_options`` declares them, ``world_config`` builds the WorldConfig, and
``cliargs.forward_argv`` passes a launcher's choices on to the world-server process.
"""

from __future__ import annotations

import argparse

from plumbing import cliargs
from world_server.camera import CameraNoise
from world_server.radio import RadioConfig
from world_server.world import DEFAULT_CAMERA, WorldConfig


def _pair(text: str) -> tuple[float, float]:
    first, sep, second = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return float(first), float(second)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not two numbers A:B") from None


def burst_loss(text: str) -> str:
    """``ENTER:EXIT[:LOSS_GOOD:LOSS_BAD]``, Gilbert-Elliott probabilities."""
    parts = text.split(":")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) not in (2, 4) or not all(0.0 <= value <= 1.0 for value in values):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not ENTER:EXIT or ENTER:EXIT:LOSS_GOOD:LOSS_BAD, each in [0, 1]"
        )
    return text


def range_loss(text: str) -> str:
    """``START[:EXPONENT]``: loss rises from START (fraction of range) to 1 at the edge."""
    start, _, exponent = text.partition(":")
    try:
        valid = 0.0 <= float(start) < 1.0 and (not exponent or float(exponent) > 0)
    except ValueError:
        valid = False
    if not valid:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not START[:EXPONENT] with START in [0, 1) and EXPONENT > 0"
        )
    return text


def add_world_options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """Declare the world's options (clock, physics, radio faults, camera noise)."""
    actions = []
    clock = parser.add_argument_group("clock")
    add = clock.add_argument
    actions += [
        add(
            "--clock",
            choices=["lockstep", "realtime"],
            default="lockstep",
            help="lockstep: deterministic, waits for every controller each tick, as fast as "
            "the processes go; realtime: follows the wall clock (default: lockstep)",
        ),
        add(
            "--speed",
            type=cliargs.float_range(0.01, 1000.0),
            default=1.0,
            help="real-time speed factor, realtime clock only (default: 1)",
        ),
        add(
            "--stall-timeout",
            type=cliargs.positive_float,
            default=5.0,
            help="lockstep: wall seconds to wait for a silent controller before closing the "
            "tick without it; after 3 such ticks it is not waited for until it answers "
            "again (default: 5)",
        ),
        add(
            "--dt",
            type=cliargs.float_range(0.001, 1.0),
            default=0.1,
            help="control tick in sim seconds (default: 0.1)",
        ),
        add(
            "--state-every",
            type=cliargs.positive_int,
            default=10,
            help="publish world/state every N ticks (default: 10)",
        ),
    ]
    radio = parser.add_argument_group("radio medium (all faults off by default)")
    add = radio.add_argument
    actions += [
        add(
            "--radio-range",
            type=cliargs.positive_float,
            default=0.5,
            help="robot radio range in metres (default: 0.5)",
        ),
        add(
            "--beacon-range",
            type=cliargs.positive_float,
            default=None,
            help="beacon range in metres (default: the nest radius)",
        ),
        add(
            "--drop",
            type=cliargs.probability,
            default=0.0,
            help="iid loss probability per message and receiver (default: 0)",
        ),
        add(
            "--burst-loss",
            type=burst_loss,
            default=None,
            metavar="ENTER:EXIT[:LG:LB]",
            help="Gilbert-Elliott burst loss per link: P(good->bad), P(bad->good), and "
            "loss probability in the good and bad states (default loss 0 and 1)",
        ),
        add(
            "--latency",
            type=cliargs.non_negative_int,
            default=0,
            metavar="TICKS",
            help="extra delivery latency in ticks (default: 0)",
        ),
        add(
            "--jitter",
            type=cliargs.non_negative_int,
            default=0,
            metavar="TICKS",
            help="a further uniform 0..TICKS delay per copy; copies overtake (default: 0)",
        ),
        add(
            "--duplicate",
            type=cliargs.probability,
            default=0.0,
            help="probability that a delivered copy arrives twice (default: 0)",
        ),
        add(
            "--reorder",
            action="store_true",
            help="shuffle each tick's deliveries (seeded) instead of sorting them",
        ),
        add(
            "--range-loss",
            type=range_loss,
            default=None,
            metavar="START[:EXPONENT]",
            help="loss rising with distance: 0 up to START x range, 1 at the range's edge, "
            "((d/range - START)/(1 - START))^EXPONENT between (default: off)",
        ),
    ]
    camera = parser.add_argument_group("camera")
    add = camera.add_argument
    actions += [
        add(
            "--camera-noise",
            type=cliargs.float_range(0.0, 255.0),
            default=0.0,
            metavar="SIGMA",
            help="Gaussian pixel noise, std-dev on the 0..255 scale (default: 0)",
        ),
        add(
            "--lighting",
            type=cliargs.float_range(0.0, 1.0, high_open=True),
            default=0.0,
            help="per-site lighting variation amplitude in [0, 1): biases each site's "
            "colour for the whole run (default: 0)",
        ),
    ]
    return actions


def world_config(
    args: argparse.Namespace, *, run: str, seed: int, sites: int, robots: int
) -> WorldConfig:
    """The WorldConfig for the options of ``add_world_options``."""
    radio: dict[str, float | int | bool] = {
        "robot_range": args.radio_range,
        "drop": args.drop,
        "latency": args.latency,
        "jitter": args.jitter,
        "duplicate": args.duplicate,
        "reorder": args.reorder,
    }
    if args.burst_loss:
        values = [float(part) for part in args.burst_loss.split(":")]
        radio["burst_enter"], radio["burst_exit"] = values[0], values[1]
        if len(values) == 4:
            radio["burst_loss_good"], radio["burst_loss_bad"] = values[2], values[3]
    if args.range_loss:
        start, _, exponent = args.range_loss.partition(":")
        radio["range_loss_start"] = float(start)
        if exponent:
            radio["range_loss_exponent"] = float(exponent)
    return WorldConfig(
        run=run,
        seed=seed,
        num_sites=sites,
        num_robots=robots,
        dt=args.dt,
        clock=args.clock,
        radio=RadioConfig(**radio),  # type: ignore[arg-type]
        beacon_range=args.beacon_range,
        camera=DEFAULT_CAMERA,
        camera_noise=CameraNoise(pixel_sigma=args.camera_noise, lighting=args.lighting),
    )
