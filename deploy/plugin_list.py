"""``swarm plugins``: the plug-ins that can be named here, by kind: the built-ins and those of
every installed package (entry points of the groups ``bestofn_swarm.strategies``,
``bestofn_swarm.pooling`` and ``bestofn_swarm.controllers``), each with where it is, its
distribution and version, and the hash of its source, as a run's results record them
(docs/extending.md). One that cannot be loaded is listed with why; the exit code is then 1.
"""

from __future__ import annotations

import argparse
import json
import sys

from robot_agent.core.plugin import GROUPS, KINDS, OPTIONS, Kind
from robot_agent.plugins import registry


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "kind",
        nargs="?",
        choices=KINDS,
        help="only this kind (default: every kind)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per plug-in, a line each: kind, name and its record (or error)",
    )


def run(args: argparse.Namespace) -> int:
    kinds: tuple[Kind, ...] = (args.kind,) if args.kind else KINDS
    listed = registry.installed(kinds)
    if args.json:
        for item in listed:
            record = item.plugin.record() if item.plugin is not None else None
            line = {"kind": item.kind, "name": item.name, "builtin": _builtin(item)}
            line |= record or {"error": item.error}
            print(json.dumps(line))
    else:
        print(table(listed, kinds))
    broken = [item for item in listed if item.error is not None]
    for item in broken:
        print(f"swarm plugins: {item.error}", file=sys.stderr)
    return 1 if broken else 0


def _builtin(item: registry.Listed) -> bool:
    return item.plugin is not None and item.plugin.builtin


def table(listed: list[registry.Listed], kinds: tuple[Kind, ...]) -> str:
    """The plug-ins as text: a heading per kind, a line per plug-in."""
    lines: list[str] = []
    for kind in kinds:
        mine = [item for item in listed if item.kind == kind]
        lines.append(f"{kind} ({OPTIONS[kind]}; entry points {GROUPS[kind]})")
        width = max((len(item.name) for item in mine), default=0)
        for item in mine:
            plugin = item.plugin
            if plugin is None:
                lines.append(f"  {item.name:<{width}}  cannot be loaded: {item.error}")
                continue
            origin = plugin.origin
            made = " ".join(part for part in (origin.distribution, origin.version) if part)
            source = f"source {origin.source}" if origin.source else "no source file"
            built = ", built in" if plugin.builtin else ""
            lines.append(
                f"  {item.name:<{width}}  {plugin.where}  ({made or 'not installed'}, "
                f"{source}{built})"
            )
    return "\n".join(lines)


__all__ = ["add_arguments", "run", "table"]
