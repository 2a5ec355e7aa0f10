"""Finding plug-ins by name: installed entry points and ``package.module:attribute``.

A name with a colon is where the object is: its module is imported and the attribute (a
dotted path) taken from it. Any other name is an entry point's of the kind's group
(``robot_agent.core.plugin.GROUPS``), from any installed distribution: the project's own
built-ins are entry points too (pyproject.toml), and from a checkout that is not installed
the built-ins are found by name all the same. Two distributions that register one name
make it ambiguous: refused, with both named.

Every plug-in found says where it came from (``Origin``): the distribution that provides it
and its version, and the SHA-256 of the source file that defines it, so that a result says
what made it and a robot started on another host can be checked to run the same code
(``check_sources``). Importing runs the plug-in's module: whatever goes wrong there is one
line naming the plug-in (``PluginError``), never a traceback.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.machinery
import importlib.metadata
import inspect
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from robot_agent.core import plugins
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import (
    DEFAULTS,
    GROUPS,
    KINDS,
    OPTIONS,
    Kind,
    Origin,
    Plugin,
    PluginError,
    error_text,
)
from robot_agent.core.plugins import Plugins

# Hex digits of a source's SHA-256 that a result keeps (as a run's digest: 64 bits).
SOURCE_DIGITS = 16


@dataclass(frozen=True)
class Entry:
    """One installed entry point of a plug-in group: its name, what it points at, and the
    distribution that registers it."""

    kind: Kind
    name: str
    value: str
    distribution: str | None
    version: str | None


def entries(kind: Kind) -> list[Entry]:
    """Every entry point of ``kind``'s group, from every installed distribution, by name."""
    found = [
        Entry(
            kind,
            point.name,
            point.value,
            point.dist.name if point.dist is not None else None,
            point.dist.version if point.dist is not None else None,
        )
        for point in importlib.metadata.entry_points(group=GROUPS[kind])
    ]
    return sorted(found, key=lambda entry: (entry.name, entry.distribution or ""))


def names(kind: Kind) -> list[str]:
    """The names a plug-in of ``kind`` can be given by: the installed entry points' and the
    built-ins'."""
    return sorted({entry.name for entry in entries(kind)} | set(plugins.BUILTINS[kind]))


def resolve(kind: Kind, name: str) -> Plugin:
    """The plug-in of ``kind`` called ``name``, checked to be of its kind; PluginError in
    one line (it does not resolve, its import fails, it is of another kind)."""
    if kind not in KINDS:
        raise ValueError(f"no plug-in kind {kind!r} (there are {', '.join(KINDS)})")
    if ":" in name:
        target = _load(kind, name, name)
        origin = origin_of(target, None)
    else:
        matching = {entry.value: entry for entry in entries(kind) if entry.name == name}
        if len(matching) > 1:
            sources = ", ".join(
                f"{entry.value} ({entry.distribution})" for entry in matching.values()
            )
            raise PluginError(f"{kind} plug-in {name!r} is ambiguous: {sources} register it")
        if matching:
            (entry,) = matching.values()
            target = _load(kind, name, entry.value)
            origin = origin_of(target, entry)
        elif name in plugins.BUILTINS[kind]:  # a checkout that is not installed
            target = plugins.BUILTINS[kind][name]
            origin = origin_of(target, None)
        else:
            raise PluginError(
                f"no {kind} plug-in {name!r} ({OPTIONS[kind]}): installed are "
                f"{', '.join(names(kind))}; or name one as package.module:attribute"
            )
    plugins.check_kind(kind, name, target)
    return Plugin(
        kind,
        name,
        target,
        where=plugins.where_of(target) or name,
        origin=origin,
        builtin=plugins.is_builtin(kind, target),
    )


def resolve_plugins(config: ControllerConfig, controller: str = DEFAULTS["controller"]) -> Plugins:
    """A run's plug-ins: ``config``'s strategy and pooling operator, and ``controller``."""
    return Plugins(
        resolve("strategy", config.strategy),
        resolve("pooling", config.pooling),
        resolve("controller", controller),
    )


def check_sources(found: Plugins, expected: Mapping[str, str]) -> None:
    """PluginError unless each plug-in whose source hash ``expected`` gives (by kind: what
    the run's launcher found) has that source here: a robot on another host must run the
    code the run says it ran."""
    for kind in KINDS:
        wanted = expected.get(kind)
        plugin = found.of(kind)
        if wanted is not None and plugin.origin.source != wanted:
            raise PluginError(
                f"{plugin.describe()}: its source here ({plugin.origin.source}) is not the "
                f"run's ({wanted}): install the same version on every host"
            )


def _load(kind: Kind, name: str, value: str) -> Any:
    """The object ``module:attribute`` names (the attribute may be dotted)."""
    module_name, _, attribute = value.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name is not None and module_name.startswith(error.name):
            raise PluginError(
                f"{kind} plug-in {name!r}: no module {error.name!r} (is its package installed "
                "in this environment?)"
            ) from None
        raise PluginError(
            f"{kind} plug-in {name!r}: importing {module_name} raised {error_text(error)}"
        ) from None
    except Exception as error:
        raise PluginError(
            f"{kind} plug-in {name!r}: importing {module_name} raised {error_text(error)}"
        ) from None
    target: Any = module
    for part in attribute.split(".") if attribute else []:
        try:
            target = getattr(target, part)
        except AttributeError:
            raise PluginError(
                f"{kind} plug-in {name!r}: {module_name} has no attribute {attribute!r}"
            ) from None
    if not attribute:
        raise PluginError(f"{kind} plug-in {name!r}: give package.module:attribute")
    return target


# --- where a plug-in came from -------------------------------------------------------------


def origin_of(target: object, entry: Entry | None) -> Origin:
    """The distribution (the entry point's, else the one that installs the object's top
    package), its version, and the hash of the object's source file."""
    distribution = entry.distribution if entry is not None else None
    version = entry.version if entry is not None else None
    module = _module_of(target)
    if distribution is None and module is not None:
        distribution, version = _distribution_of(module.__name__)
    return Origin(distribution, version, source_hash(target))


def source_hash(target: object) -> str | None:
    """The first SOURCE_DIGITS hex digits of the SHA-256 of the source file that defines
    ``target`` (for a compiled module, the source it was compiled from); None if it has
    none."""
    path = source_file(target)
    if path is None:
        return None
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()[:SOURCE_DIGITS]
    except OSError:
        return None


def source_file(target: object) -> Path | None:
    """The source file that defines ``target``."""
    try:
        found = inspect.getsourcefile(target)  # type: ignore[arg-type]
    except TypeError:
        found = None
    if found is not None:
        return Path(found)
    module = _module_of(target)
    file = getattr(module, "__file__", None)
    if not file:
        return None
    path = Path(file)
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:  # a compiled core: its source
        if path.name.endswith(suffix):
            path = path.with_name(path.name.removesuffix(suffix) + ".py")
    return path if path.suffix == ".py" and path.is_file() else None


def _module_of(target: object) -> ModuleType | None:
    name = getattr(target, "__module__", None)
    return sys.modules.get(name) if isinstance(name, str) else None


def _distribution_of(module: str) -> tuple[str | None, str | None]:
    top = module.partition(".")[0]
    found = importlib.metadata.packages_distributions().get(top, [])
    if len(found) != 1:
        return None, None
    try:
        return found[0], importlib.metadata.version(found[0])
    except importlib.metadata.PackageNotFoundError:
        return found[0], None


# --- what is installed (swarm plugins) -----------------------------------------------------


@dataclass(frozen=True)
class Listed:
    """A plug-in as ``swarm plugins`` lists it: its entry (or built-in), and what resolving
    it gave (``plugin``) or why it failed (``error``)."""

    kind: Kind
    name: str
    plugin: Plugin | None
    error: str | None


def installed(kinds: Iterable[Kind] = KINDS) -> list[Listed]:
    """Every plug-in that can be named, by kind and name, each resolved."""
    listed = []
    for kind in kinds:
        for name in names(kind):
            try:
                listed.append(Listed(kind, name, resolve(kind, name), None))
            except PluginError as error:
                listed.append(Listed(kind, name, None, str(error)))
    return listed


__all__ = [
    "SOURCE_DIGITS",
    "Entry",
    "Listed",
    "check_sources",
    "entries",
    "installed",
    "names",
    "origin_of",
    "resolve",
    "resolve_plugins",
    "source_file",
    "source_hash",
]
