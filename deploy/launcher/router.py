"""``python -m deploy.launcher.router``: a Zenoh router that several runs on one machine share.

A Python Zenoh session in router mode (no zenohd needed), listening on loopback TCP by
default. ``swarm experiment`` starts one on a Unix socket in a private directory (only its
user can reach it) and points every run at it with ``--connect``;
each run keeps to its own keys (``<root>/<run-id>/...``). It stops on SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections.abc import Sequence

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.lifecycle import die_with_launcher
from bestofn_swarm.plumbing.stop_signals import on_stop_signals

log = logging.getLogger("router")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--listen",
        type=cliargs.endpoint,
        action="append",
        default=[],
        metavar="ENDPOINT",
        help=f"endpoint to listen on, repeatable (default: {cliargs.LOCAL_ENDPOINT}); "
        f"use tcp/0.0.0.0:{cliargs.ZENOH_PORT} to accept other hosts",
    )
    parser.add_argument(
        "--connect",
        type=cliargs.endpoint,
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="another router to connect to (repeatable)",
    )
    parser.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="a Zenoh JSON5 configuration file (TLS, access control)",
    )
    cliargs.add_log_level(parser)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="router", description="A Zenoh router for swarm runs that share one network."
    )
    add_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    return run(build_parser().parse_args(argv))


def run(args: argparse.Namespace) -> int:
    """``swarm router``: route until SIGINT or SIGTERM."""
    cliargs.configure_logging("router", args.log_level)
    import zenoh

    from bestofn_swarm.plumbing.zenoh_session import open_session

    listen = args.listen or ([] if args.zenoh_config else [cliargs.LOCAL_ENDPOINT])
    stop = threading.Event()
    on_stop_signals(lambda _: stop.set())
    try:
        session = open_session("router", args.connect, listen, args.zenoh_config)
    except ValueError as error:  # a configuration file that cannot be read
        print(f"router: error: {error}", file=sys.stderr)
        return 2
    except zenoh.ZError as error:
        print(f"router: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    with session:
        log.info("routing on %s", ", ".join(listen) or "(configured endpoints)")
        while not stop.wait(0.5):
            pass
    log.info("router stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
