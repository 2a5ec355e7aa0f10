"""How the programs of a run begin: the world server, the nest beacon, robot-agent, the
recorder, the bridge, the live page and Foxglove live each start their ``main`` with
``begin``.

In this order, so that a wrong command line gives one line and exit code 2 before
anything is said or opened: stale compiled cores refused (by the programs that run them),
the launcher's death made ours too, the command line parsed and then checked by the
program itself (``settings(parser, args)``: its settings, or ``parser.exit(2, ...)``), one
log format, a ``--zenoh-config`` that can be read, the run keys (the run secret, for a
program that checks everyone's tags), a lower CPU priority (``--niceness``, before Zenoh
starts threads that would not inherit it), and the run's keys. What comes next (the stop
signals, the Zenoh sessions, what the program serves) is each program's own.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, NoReturn, TypeVar

from bestofn_swarm.plumbing import cliargs, cores, run_keys
from bestofn_swarm.plumbing.lifecycle import die_with_launcher
from bestofn_swarm.wire import auth, keyspace

Settings = TypeVar("Settings")


@dataclass(frozen=True)
class Begun(Generic[Settings]):
    """What a program starts from: its command line, its settings, run keys and keys."""

    args: argparse.Namespace
    settings: Settings
    keyring: auth.Keyring | None  # None: an unauthenticated run (said in the log)
    keys: keyspace.Keys


def begin(
    program: str,
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    settings: Callable[[argparse.ArgumentParser, argparse.Namespace], Settings],
    *,
    runs_cores: bool = True,
    config_robots: Callable[[Settings], Sequence[int]] | None = None,
    needs_secret: str | None = None,
    lower_priority: bool = False,
) -> Begun[Settings]:
    """The start of ``program``'s main (see the module's docstring); exits with code 2 and
    one line on what is wrong.

    ``config_robots``: the robots whose ``--zenoh-config`` (``{id}`` standing for each)
    must be readable; ``needs_secret``: who needs the run secret, e.g. "the recorder";
    ``lower_priority``: the program has ``--niceness``."""
    if runs_cores:
        cores.check()  # stale compiled cores would run old code
    die_with_launcher()
    args = parser.parse_args(argv)
    found = settings(parser, args)
    cliargs.configure_logging(program, args.log_level)
    # Imported here: opening the configuration needs Zenoh, which only a process needs.
    from bestofn_swarm.plumbing.zenoh_session import check_config_files

    # Before the run keys, whose absence is a warning: one line if the configuration fails.
    check_config_files(parser, args, config_robots(found) if config_robots else ())
    keyring = run_keys.from_args(parser, args, program)
    if needs_secret is not None and keyring is not None and keyring.secret is None:
        parser.exit(2, f"{program}: error: {needs_secret} needs the run secret\n")
    if lower_priority and args.niceness:
        _lower_priority(program, args.niceness)
    return Begun(args, found, keyring, keyspace.Keys(args.run_id, args.root))


def no_settings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """The ``settings`` of a program whose options need no check of their own."""


def _lower_priority(program: str, niceness: int) -> None:
    """Yield the CPU to the swarm; a platform without nice() runs at full priority."""
    try:
        os.nice(niceness)
    except (AttributeError, OSError) as error:
        logging.getLogger(program).info("could not lower the %s's priority: %s", program, error)


def end(code: int) -> NoReturn:
    """The end of a program's main once its Zenoh sessions are closed and its files
    written: its log and output flushed, then the exit with ``code`` at once, without the
    interpreter's finalization. A Zenoh thread still finishing a callback as the
    interpreter finalizes is stopped inside Zenoh's own code, which aborts the process
    (glibc: "FATAL: exception not rethrown", exit code -6): a process that ends on a run's
    ending, as every process of the run now hears it, met that one exit in a few."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(code)
