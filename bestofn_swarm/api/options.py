"""``swarm run``'s options from keyword arguments: ``drop=0.2`` is ``--drop 0.2``,
``no_keys=True`` is ``--no-keys``, a list repeats its option (``byzantine=["3:liar"]``); and
the run's plan from them, with a one-line ValueError for what the command line would
refuse."""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from typing import Any, NoReturn

from deploy.launcher.options import add_arguments
from deploy.launcher.plan import RunPlan, plan_from_args


def tokens(options: Mapping[str, Any]) -> list[str]:
    """The command-line tokens of ``options`` (None and False leave an option out)."""
    found: list[str] = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            found.append(flag)
        elif isinstance(value, list | tuple):
            for item in value:
                found += [flag, text(item)]
        else:
            found += [flag, text(value)]
    return found


def text(value: Any) -> str:
    """A value as its option is written: 0.2, 10, linear."""
    return format(value, ".12g") if isinstance(value, float) else str(value)


class _Refusing(argparse.ArgumentParser):
    """``swarm run``'s parser, whose errors are ValueErrors rather than an exit."""

    def error(self, message: str) -> NoReturn:
        raise ValueError(message)


def plan(argv: Sequence[str]) -> RunPlan:
    """The plan of ``swarm run ARGV``; ValueError in one line for what it refuses (an
    unknown option, a bad value, a plug-in that does not resolve)."""
    parser = _Refusing(prog="swarm run")
    add_arguments(parser)
    return plan_from_args(parser.parse_args(list(argv)))


__all__ = ["plan", "text", "tokens"]
