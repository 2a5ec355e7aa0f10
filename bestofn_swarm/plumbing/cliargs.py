"""Argument types and shared options for every command-line entry point.

Each type raises ``argparse.ArgumentTypeError`` with a message that says what was
wrong, so argparse prints one line and exits with code 2. The options of a run's
settings are not written here but made from their definitions
(``bestofn_swarm/plumbing/settings_cli.py``).
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Callable

from bestofn_swarm.wire import names, protocol, shape

ZENOH_PORT = 7447  # Zenoh's own default port
LOCAL_ENDPOINT = f"tcp/127.0.0.1:{ZENOH_PORT}"  # a router of this host, on loopback


class UsageError(Exception):
    """A bad argument found after parsing: printed as one line, exit code 2."""


def _number(kind: type[int] | type[float], text: str) -> float:
    try:
        value: float = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a valid {kind.__name__}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def int_range(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An integer in [low, high] (either bound may be open)."""

    def parse(text: str) -> int:
        value = int(_number(int, text))
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{value} is outside {_bounds(low, high)}")
        return value

    return parse


def float_range(
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> Callable[[str], float]:
    """A finite float within the given bounds (closed unless marked open)."""

    def parse(text: str) -> float:
        value = float(_number(float, text))
        too_low = low is not None and (value <= low if low_open else value < low)
        too_high = high is not None and (value >= high if high_open else value > high)
        if too_low or too_high:
            raise argparse.ArgumentTypeError(
                f"{value:g} is outside {_bounds(low, high, low_open, high_open)}"
            )
        return value

    return parse


def _bounds(low: object, high: object, low_open: bool = False, high_open: bool = False) -> str:
    left = "(" if low_open or low is None else "["
    right = ")" if high_open or high is None else "]"
    return f"{left}{'-inf' if low is None else low}, {'inf' if high is None else high}{right}"


def name(text: str) -> str:
    """A name (run id, key root, beacon): the one rule of ``names.check_name``."""
    try:
        return names.check_name(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def endpoint(text: str) -> str:
    """A Zenoh endpoint such as ``tcp/127.0.0.1:7447`` (Zenoh's port)."""
    proto, sep, rest = text.partition("/")
    if not sep or proto not in {"tcp", "udp", "tls", "quic", "ws", "unixsock-stream"} or not rest:
        raise argparse.ArgumentTypeError(
            f"invalid Zenoh endpoint {text!r}: expected e.g. tcp/127.0.0.1:7447"
        )
    return text


alpha = float_range(0.0, 0.5)
probability = float_range(0.0, 1.0)
threshold = float_range(0.0, 1.0, low_open=True)
seed = int_range(0, shape.MAX_SEED)
robots = int_range(1, shape.MAX_SWARM)  # a run's swarm size
sites = int_range(2, protocol.MAX_OPTIONS)  # a run's number of sites n
positive_int = int_range(1)
positive_float = float_range(0.0, low_open=True)


def add_zenoh_options(parser: argparse.ArgumentParser, *, default_mode: str = "client") -> None:
    """--connect/--listen/--mode/--zenoh-config, --root and --run-id, shared by all processes."""
    group = parser.add_argument_group("Zenoh")
    group.add_argument(
        "--connect",
        type=endpoint,
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="router endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    group.add_argument(
        "--listen",
        type=endpoint,
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable)",
    )
    group.add_argument(
        "--mode",
        choices=["client", "peer", "router"],
        default=None,
        help=f"Zenoh session mode (default: the --zenoh-config file's, else {default_mode})",
    )
    group.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="a Zenoh JSON5 configuration file (TLS, access control); "
        "--connect/--listen/--mode override it; '{id}' in the name is replaced by the "
        "robot id, so each hosted robot can have its own certificate",
    )
    parser.set_defaults(default_zenoh_mode=default_mode)
    group.add_argument(
        "--root",
        type=name,
        default=protocol.DEFAULT_ROOT,
        help=f"key expression root (default: {protocol.DEFAULT_ROOT})",
    )
    group.add_argument(
        "--run-id", type=name, default="run", help="names one swarm on the network (default: run)"
    )
    group.add_argument(
        "--key-file",
        metavar="FILE",
        help="this process's run keys (python -m bestofn_swarm.plumbing.run_keys writes them); "
        "every message is then tagged and checked. Without one (and not started by swarm run) "
        "the process runs unauthenticated",
    )


def add_run_shape(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, what: str = ""
) -> None:
    """``--robots``, ``--sites`` and ``--seed``: a run's shape (bestofn_swarm/wire/shape.py), read
    and bounded the same way by every command that takes it. ``what`` ends each help line."""
    suffix = f" {what}" if what else ""
    parser.add_argument(
        "--robots",
        type=robots,
        default=shape.DEFAULT_ROBOTS,
        help=f"number of robots{suffix} (default: {shape.DEFAULT_ROBOTS})",
    )
    parser.add_argument(
        "--sites",
        type=sites,
        default=shape.DEFAULT_SITES,
        help=f"number of sites n{suffix} (default: {shape.DEFAULT_SITES})",
    )
    parser.add_argument(
        "--seed",
        type=seed,
        default=shape.DEFAULT_SEED,
        help=f"run seed{suffix} (default: {shape.DEFAULT_SEED})",
    )


def add_log_level(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--log-level",
        default="INFO",
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="how much to log on stderr (default: INFO)",
    )


def configure_logging(program: str, level: str) -> None:
    """One log format for every process: time, program, level, message."""
    logging.basicConfig(level=level, format=f"%(asctime)s {program} %(levelname)s %(message)s")
