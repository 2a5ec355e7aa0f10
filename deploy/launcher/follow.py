"""``swarm follow``: a running swarm, followed from any host that reaches one of its routers.

It connects to the router it is given (``--connect``), asks the run's world server for its
map (``world/info``: the run exists, and answers), then follows what the launcher follows
(``follower.py``: the robots' status, the world's state, the beacons' acks, the links) and
shows the same progress as ``swarm run``, until the world publishes the run's ending
(``world/ending``, which the world decides: world_server/observer/referee.py). It then
prints the summary the ending carries (the table, or ``--json`` one object on stdout) and
exits with the run's exit code. In a keyed run it needs the run secret (``--key-file
secret.json``), as every process that checks everyone's tags; without keys it follows an
unauthenticated run. A stop signal ends the following, not the run (exit code 128 + the
signal).
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import time
from typing import Any

from rich.console import Console

from bestofn_swarm.plumbing import cliargs, run_keys
from bestofn_swarm.plumbing.cliargs import UsageError
from bestofn_swarm.plumbing.ending import MAX_ENDING_SAMPLE_BYTES
from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.wire import keyspace, names, protocol
from bestofn_swarm.wire.endings import SIGNAL_EXIT_BASE
from deploy.launcher.console import decided_progress, describe_ending, print_summary
from deploy.launcher.follower import Follower, Heard, subscribe
from deploy.launcher.signals import Signalled, StopSignals

__all__ = ["add_arguments", "follow", "run"]

LOOK_EVERY = 0.1  # wall seconds between two updates of the progress display
EVENTS_BYTES = 64 * 2**20  # what may wait for the main thread, at most


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Follow a running swarm from any host: its progress, then its summary when the world "
        "ends the run; the exit code is the run's (swarm run --help lists them)."
    )
    parser.add_argument(
        "--json", action="store_true", help="print the summary as one JSON object on stdout"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    parser.add_argument(
        "--wait",
        type=cliargs.positive_float,
        default=60.0,
        metavar="SECONDS",
        help="wall seconds to wait for the run's world server to answer (default: 60)",
    )
    cliargs.add_zenoh_options(parser)


def run(args: argparse.Namespace) -> int:
    if not args.connect and not args.zenoh_config:
        raise UsageError("give --connect ROUTER (a router of the run, on any host)")
    try:
        keyring = run_keys.load(args.run_id, args.key_file, "swarm follow")
    except ValueError as error:
        raise UsageError(str(error)) from None
    if keyring is not None and keyring.secret is None:
        raise UsageError("following a keyed run checks everyone's tags: give the run secret")
    return follow(args, keyring)


def follow(args: argparse.Namespace, keyring: Any) -> int:
    """Follow the run until its ending; the run's exit code (or 128 + a stop signal)."""
    import zenoh

    from bestofn_swarm.plumbing.world_info import fetch_world_info
    from bestofn_swarm.plumbing.zenoh_session import open_from_args

    keys = keyspace.Keys(args.run_id, args.root)
    console = Console(stderr=True)
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"swarm follow: cannot open a Zenoh session: {error}", file=sys.stderr)
        return 1
    inbox: BoundedInbox[Heard | Signalled] = BoundedInbox(EVENTS_BYTES, MAX_ENDING_SAMPLE_BYTES)
    follower = Follower.of_run(keys, time.monotonic)

    def signalled(signum: int) -> None:
        inbox.put(Signalled(signum), control=True)

    with session, StopSignals(notify=signalled):
        declared = subscribe(session, keys, inbox, clock=False)
        try:
            info = fetch_world_info(session, keys, args.wait, keyring, names.LAUNCHER)
        except TimeoutError as error:
            print(f"swarm follow: {error}", file=sys.stderr)
            return 1
        ending, signum = _watch(
            follower, inbox=inbox, keyring=keyring, info=info, console=console, quiet=args.quiet
        )
        for entity in declared:
            entity.undeclare()
    if ending is None:
        assert signum is not None
        print(f"swarm follow: stopped following run {args.run_id}", file=sys.stderr)
        return SIGNAL_EXIT_BASE + signum
    summary = ending.summary
    if not args.quiet:
        print(f"swarm follow: {describe_ending(summary)}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        print_summary(summary, Console())
    return ending.code


def _watch(
    follower: Follower,
    *,
    inbox: BoundedInbox[Heard | Signalled],
    keyring: Any,
    info: protocol.WorldInfo,
    console: Console,
    quiet: bool,
) -> tuple[protocol.RunEnding | None, int | None]:
    """Show progress until the ending comes (or a stop signal: its number)."""
    run = follower.run
    with decided_progress(console, quiet) as progress:
        task = progress.add_task("decided", total=None, info="waiting for the world to tick")
        while follower.ending is None:
            try:
                item = inbox.get(timeout=LOOK_EVERY)
            except queue.Empty:
                continue
            while True:
                if isinstance(item, Signalled):
                    return None, item.signum
                follower.take(item, keyring)
                try:
                    item = inbox.get(timeout=0)
                except queue.Empty:
                    break
            run.rejected += inbox.take_dropped(None)
            state = run.last_state
            robots = len(state.robots) if state is not None else len(run.records)
            if follower.started:
                progress.update(
                    task,
                    total=robots or None,
                    completed=run.decided(),
                    info=f"run {info.run}: {run.decided()}/{robots} decided, {run.trips()} "
                    f"trips, sim {run.sim_time:.0f}s",
                )
    return follower.ending, None
