"""``swarm``: the user-facing command. Each subcommand lives in its own module.

A subcommand module provides ``add_arguments(parser)`` and ``run(args) -> int``. Modules
are imported only when their subcommand runs, so ``swarm --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

from bestofn_swarm.plumbing import cores
from bestofn_swarm.plumbing.cliargs import UsageError

__all__ = ["SUBCOMMANDS", "UsageError", "main"]

# name -> (module, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "wellstirred": ("deploy.reports.wellstirred", "the paper's Section 4 well-stirred model"),
    "run": ("deploy.launcher.launcher", "run a swarm of robot processes to consensus"),
    "report": (
        "deploy.reports.report",
        "the paper's Section 5 figures and a summary from recordings",
    ),
    "experiment": (
        "deploy.launcher.experiment",
        "the paper's Section 5 protocol: many runs, one report",
    ),
    "section5": (
        "deploy.reports.section5",
        "the paper's Section 5 numbers and figures, from in-process runs (docs/section5.md)",
    ),
    "study": (
        "deploy.study.cli",
        "the studies behind the published pages: run what is missing, render, check",
    ),
    "conformance": (
        "deploy.conformance.cli",
        "check a program that speaks the link against the controller, tick by tick",
    ),
    "follow": (
        "deploy.launcher.follow",
        "follow a running swarm from any host: its progress, then its summary and exit code",
    ),
    "plugins": (
        "deploy.plugin_list",
        "the plug-ins installed: strategies, pooling operators, controllers (docs/extending.md)",
    ),
    "router": ("deploy.launcher.router", "a Zenoh router (a Python session; no zenohd needed)"),
    "view": ("deploy.viewer.replay", "replay a recording in the browser, on the live view's page"),
    "frame": (
        "deploy.reports.frame",
        "a recorded run's time series as a CSV or Parquet table (one row per robot per sample)",
    ),
}


def main(argv: Sequence[str] | None = None) -> int:
    cores.check()  # stale compiled cores would run old code
    arguments = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(arguments)
    args = parser.parse_args(arguments)
    module = importlib.import_module(args.module)
    try:
        return int(module.run(args) or 0)
    except UsageError as error:
        parser.exit(2, f"swarm {args.command}: error: {error}\n")
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


class ShortUsageParser(argparse.ArgumentParser):
    """An argument parser whose error is a short usage line and one line of error: the
    whole usage of ``swarm run`` is 27 lines, and ``--help`` prints it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{short_usage(self)}\n{self.prog}: error: {message}\n")


def short_usage(parser: argparse.ArgumentParser) -> str:
    """``usage: swarm report [options] RUN.mcap [RUN.mcap ...] (--help: all of them)``."""
    formatter = parser._get_formatter()
    positionals = [
        formatter._format_args(action, action.dest.upper())
        for action in parser._actions
        if not action.option_strings and action.help is not argparse.SUPPRESS
    ]
    words = [parser.prog, "[options]", *positionals]
    return f"usage: {' '.join(words)} ({parser.prog} --help lists the options)"


def build_parser(arguments: Sequence[str]) -> argparse.ArgumentParser:
    """The parser, with full options only for the subcommand being run."""
    parser = ShortUsageParser(
        prog="swarm",
        description="Best-of-n decisions by negative updating and opinion pooling.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    chosen = arguments[0] if arguments else None
    for command, (module_name, summary) in SUBCOMMANDS.items():
        sub = commands.add_parser(command, help=summary, description=summary)
        if command == chosen:
            importlib.import_module(module_name).add_arguments(sub)
        sub.set_defaults(module=module_name)
    return parser


if __name__ == "__main__":
    sys.exit(main())
