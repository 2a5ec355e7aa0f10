"""One plug-in of a run, resolved: its kind, the name it was asked for, the object and
where it came from; and the errors a plug-in ends a run with (pure). ``plugins.py`` says
what plug-ins are and makes robots with them; ``robot_agent/plugins/registry.py`` finds them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Literal

from msgspec import Meta

from bestofn_swarm.wire import settings
from bestofn_swarm.wire.settings import Flag
from robot_agent.core.controller_config import PluginName

Kind = Literal["strategy", "pooling", "controller"]
KINDS: tuple[Kind, ...] = ("strategy", "pooling", "controller")
GROUPS: Mapping[Kind, str] = {
    "strategy": "bestofn_swarm.strategies",
    "pooling": "bestofn_swarm.pooling",
    "controller": "bestofn_swarm.controllers",
}
OPTIONS: Mapping[Kind, str] = {
    "strategy": "--strategy",
    "pooling": "--pooling",
    "controller": "--controller",
}
DEFAULTS: Mapping[Kind, str] = {"strategy": "paper", "pooling": "mprodop", "controller": "paper"}
# The exit code of a robot process (or a robot on a link) whose plug-in failed: the launcher
# tells it from a crash and takes the process's last line as the run's error.
PLUGIN_FAILED = 3


@dataclass(frozen=True)
class ControllerChoice:
    """Which controller a robot runs (``--controller``; the built-in controller's strategy
    and pooling operator are ``ControllerConfig``'s settings), and the source hashes of the
    run's plug-ins, by kind, that a robot must find in its own (``swarm run`` gives them to
    the robots it starts)."""

    FLAG_GROUP: ClassVar[str] = "plug-ins"

    controller: Annotated[
        PluginName,
        Meta(
            description="the robot's whole controller: paper (the built-in, which takes "
            "--strategy and --pooling) or a plug-in that meets the port contract "
            "(docs/porting.md): an installed one's name or package.module:attribute "
            "(swarm plugins lists them; docs/extending.md)"
        ),
        Flag(metavar="NAME"),
    ] = "paper"
    sources: Annotated[
        dict[str, str],
        Meta(description="the source hash of each of the run's plug-ins, by kind"),
    ] = field(default_factory=dict)

    def __post_init__(self) -> None:
        settings.check(self)


class PluginError(ValueError):
    """A plug-in that cannot be found, is not of its kind, or failed in a run. Its text is
    the one line a program prints: it names the plug-in (and the robot and tick, which
    ``robot`` and ``tick`` hold when known)."""

    def __init__(self, message: str, robot: int | None = None, tick: int | None = None) -> None:
        super().__init__(message)
        self.robot = robot
        self.tick = tick


@dataclass(frozen=True)
class Origin:
    """Where a plug-in came from: its distribution and that distribution's version (None:
    not from an installed distribution), and ``source``, the first 16 hex digits of the
    SHA-256 of the source file that defines it (None: no source file)."""

    distribution: str | None = None
    version: str | None = None
    source: str | None = None


@dataclass(frozen=True)
class Plugin:
    """A resolved plug-in: its kind, the name it was asked for, the object, where that is
    (``target``: ``module:attribute``), where it came from, and whether it is a built-in
    (the very object the project registers: a built-in runs unchecked)."""

    kind: Kind
    name: str
    target: Any = field(compare=False)
    where: str = ""
    origin: Origin = Origin()
    builtin: bool = False

    def describe(self) -> str:
        """``pooling plug-in 'linear'``: how an error names it."""
        return f"{self.kind} plug-in {self.name!r}"

    def record(self) -> dict[str, Any]:
        """What a result keeps of it: name, target, distribution, version, source hash."""
        return {
            "name": self.name,
            "target": self.where,
            "distribution": self.origin.distribution,
            "version": self.origin.version,
            "source": self.origin.source,
        }


def error_text(error: BaseException) -> str:
    """An exception as part of one line: its type and its first line, at most 160 chars."""
    text = " ".join(str(error).split())
    if len(text) > 160:
        text = text[:157] + "..."
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


class PluginCallError(Exception):
    """Raised inside a robot's step by a checked plug-in (``plugin_checks.py``) that raised
    or gave what it may not; the robot's checked controller adds its robot and tick
    (``at``) and raises the ``PluginError`` that ends the run."""

    def __init__(self, plugin: Plugin, what: str) -> None:
        super().__init__(f"{plugin.describe()} {what}")
        self.plugin = plugin
        self.what = what

    def at(self, robot: int, tick: int | None) -> PluginError:
        where = f"robot {robot}" + ("" if tick is None else f", tick {tick}")
        return PluginError(f"{self.plugin.describe()} {self.what} ({where})", robot, tick)


__all__ = [
    "DEFAULTS",
    "GROUPS",
    "KINDS",
    "OPTIONS",
    "PLUGIN_FAILED",
    "ControllerChoice",
    "Kind",
    "Origin",
    "Plugin",
    "PluginCallError",
    "PluginError",
    "error_text",
]
