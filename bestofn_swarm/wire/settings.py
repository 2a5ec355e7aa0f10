"""Settings, each defined once: type, range, default and help, on its config dataclass.

A setting is a field of a frozen config dataclass (``ControllerConfig``, ``RadioConfig``,
``BeaconConfig``, ...) whose type carries its range and its help as ``msgspec.Meta``::

    dwell: Annotated[float, Meta(gt=0.0, description="sim seconds at the nest ...")] = 3.0

and, if it is on command lines, a ``Flag`` that says how it is spelled there. From that
one definition:

* ``check(config)``, which the dataclass's ``__post_init__`` calls, refuses a value of the
  wrong type or out of range, whoever made the config;
* ``decode(text, Config)`` reads a config handed over as one JSON object (a child
  process's ``--config``), refusing unknown fields, wrong types and values out of range
  (msgspec reads the same ``Meta``); ``encode(config)`` writes one;
* ``bestofn_swarm/plumbing/settings_cli.py`` makes the command-line options of the flagged settings:
  spelling, type, range, default and help.

Rules between settings (alpha > 0 needs a threshold below 1) stay in ``__post_init__``.
Pure: no I/O.
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal, TypeVar

import msgspec

T = TypeVar("T")

# A configuration as one JSON text (``--config``, ``--config-json``), at most: what swarm run
# hands a process is a few kilobytes.
MAX_TEXT_BYTES = 2**20

_BOUNDS = ("ge", "gt", "le", "lt")
_CONSTRAINTS = (*_BOUNDS, "pattern", "min_length", "max_length", "description")


@dataclass(frozen=True)
class Flag:
    """How a setting is spelled on command lines: ``--<name>``.

    ``joined`` names further fields of the same dataclass that the same option sets, as
    ``A:B[:C:D]``: ``least`` values must be given, the others all or none (defaults).
    ``default_from`` gives the default from the settings given with it (the threshold's
    depends on alpha); ``default_text`` is what the help says the default is when the
    value alone does not say it. ``parse`` reads the option's text when the type alone
    does not say how.
    """

    name: str | None = None  # default: the field's name with '-' for '_'
    group: str | None = None  # the --help section; default: the dataclass's FLAG_GROUP
    metavar: str | None = None
    help: str | None = None  # default: the setting's description
    default_text: str | None = None
    joined: tuple[str, ...] = ()
    least: int = 0
    default_from: Callable[[Mapping[str, Any]], Any] | None = None
    parse: Callable[[str], Any] | None = None


@dataclass(frozen=True)
class Setting:
    """One field of a config dataclass, read from its declaration."""

    name: str
    hint: Any  # the declared type, with its Annotated metadata
    kind: Any  # the type without Annotated
    constraints: Mapping[str, Any]  # ge, gt, le, lt, pattern, min/max_length, description
    flag: Flag | None
    default: Any  # dataclasses.MISSING when there is none

    @property
    def description(self) -> str:
        return str(self.constraints.get("description") or "")

    @property
    def config_type(self) -> type | None:
        """The config dataclass this setting holds, if it holds one (even as ``X | None``)."""
        kind = resolved(self.hint)[0]
        return kind if dataclasses.is_dataclass(kind) and isinstance(kind, type) else None


def split(hint: Any) -> tuple[Any, dict[str, Any], list[Any]]:
    """``hint`` without Annotated, its merged msgspec constraints, its other metadata."""
    constraints: dict[str, Any] = {}
    extras: list[Any] = []
    if typing.get_origin(hint) is Annotated:
        for item in hint.__metadata__:
            if isinstance(item, msgspec.Meta):
                for name in _CONSTRAINTS:
                    value = getattr(item, name)
                    if value is not None:
                        constraints[name] = value
            else:
                extras.append(item)
        hint = hint.__origin__
    return hint, constraints, extras


def resolved(hint: Any) -> tuple[Any, dict[str, Any]]:
    """The type of ``hint`` without Annotated and without ``| None``, with its constraints
    (for ``Annotated[Annotated[float, Meta(gt=0)] | None, ...]``: float and gt=0)."""
    kind, constraints, _ = split(hint)
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        options = [arg for arg in typing.get_args(kind) if arg is not type(None)]
        if len(options) == 1:
            inner, inner_constraints, _ = split(options[0])
            return inner, {**constraints, **inner_constraints}
    return kind, constraints


_SETTINGS: dict[type, tuple[Setting, ...]] = {}


def settings_of(config_type: type) -> tuple[Setting, ...]:
    """The settings of a config dataclass, in declaration order."""
    known = _SETTINGS.get(config_type)
    if known is None:
        known = _SETTINGS[config_type] = _read_settings(config_type)
    return known


def _read_settings(config_type: type) -> tuple[Setting, ...]:
    # Annotations name the module's names, never the class's: a field called ``byzantine``
    # must not hide the module ``byzantine`` (and a lambda in one sees the module).
    module = vars(sys.modules[config_type.__module__])
    hints = typing.get_type_hints(config_type, globalns=module, localns=module, include_extras=True)
    found = []
    for field in dataclasses.fields(config_type):
        hint = hints[field.name]
        kind, constraints, extras = split(hint)
        flags = [item for item in extras if isinstance(item, Flag)]
        if field.default is not dataclasses.MISSING:
            default = field.default
        elif field.default_factory is not dataclasses.MISSING:
            default = field.default_factory()
        else:
            default = dataclasses.MISSING
        found.append(
            Setting(field.name, hint, kind, constraints, flags[0] if flags else None, default)
        )
    return tuple(found)


# --- checking ----------------------------------------------------------------------------


def check(config: object) -> None:
    """ValueError naming the first setting of ``config`` of the wrong type or out of range."""
    for setting in settings_of(type(config)):
        check_value(setting.hint, getattr(config, setting.name), setting.name)


def check_value(hint: Any, value: Any, label: str) -> None:
    """ValueError unless ``value`` is a ``hint`` (type and constraints); ``label`` names it."""
    kind, constraints, _ = split(hint)
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if kind is Any:
        return
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return
        options = [arg for arg in args if arg is not type(None)]
        errors = []
        for option in options:
            try:
                check_value(option, value, label)
                return
            except ValueError as error:
                errors.append(str(error))
        raise ValueError(errors[0] if len(errors) == 1 else f"{label} is invalid, got {value!r}")
    if origin is Literal:
        if isinstance(value, bool) or not any(
            type(value) is type(arg) and value == arg for arg in args
        ):
            raise ValueError(f"{label} must be one of {', '.join(map(str, args))}, got {value!r}")
        return
    if kind is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{label} must be true or false, got {value!r}")
        return
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{label} must be a whole number, got {value!r}")
        _check_bounds(value, constraints, label)
        return
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{label} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ValueError(f"{label} must be a finite number, got {value!r}")
        _check_bounds(value, constraints, label)
        return
    if kind is str:
        if not isinstance(value, str):
            raise ValueError(f"{label} must be text, got {value!r}")
        _check_length(value, constraints, label)
        pattern = constraints.get("pattern")
        if pattern is not None and not re.search(pattern, value):
            raise ValueError(f"{label} {value!r} does not match {pattern}")
        return
    if origin is tuple:
        if not isinstance(value, tuple):
            raise ValueError(f"{label} must be a tuple, got {value!r}")
        _check_length(value, constraints, label)
        if len(args) == 2 and args[1] is Ellipsis:
            for index, item in enumerate(value):
                check_value(args[0], item, f"{label}[{index}]")
        elif len(value) != len(args):
            raise ValueError(f"{label} must have {len(args)} items, got {value!r}")
        else:
            for index, (item_hint, item) in enumerate(zip(args, value, strict=True)):
                check_value(item_hint, item, f"{label}[{index}]")
        return
    if origin is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{label} must be a mapping, got {value!r}")
        for key, item in value.items():
            check_value(args[0], key, f"{label} key")
            check_value(args[1], item, f"{label}[{key!r}]")
        return
    if isinstance(kind, type) and not isinstance(value, kind):
        raise ValueError(f"{label} must be a {kind.__name__}, got {value!r}")


def interval(constraints: Mapping[str, Any]) -> str:
    """The range of ``constraints`` as an interval, e.g. ``[0, 0.5]`` or ``(0, inf)``."""
    low, high = constraints.get("ge", constraints.get("gt")), constraints.get("le")
    high = constraints.get("lt") if high is None else high
    left = "[" if "ge" in constraints else "("
    right = "]" if "le" in constraints else ")"
    low_text = "-inf" if low is None else number_text(low)
    high_text = "inf" if high is None else number_text(high)
    return f"{left}{low_text}, {high_text}{right}"


def in_range(value: float, constraints: Mapping[str, Any]) -> bool:
    """Whether ``value`` is within the bounds (ge, gt, le, lt) of ``constraints``."""
    ge, gt = constraints.get("ge"), constraints.get("gt")
    le, lt = constraints.get("le"), constraints.get("lt")
    return (
        (ge is None or value >= ge)
        and (gt is None or value > gt)
        and (le is None or value <= le)
        and (lt is None or value < lt)
    )


def _check_bounds(value: float, constraints: Mapping[str, Any], label: str) -> None:
    if not in_range(value, constraints):
        raise ValueError(f"{label} must be in {interval(constraints)}, got {value!r}")


def _check_length(value: str | tuple[Any, ...], constraints: Mapping[str, Any], label: str) -> None:
    least, most = constraints.get("min_length"), constraints.get("max_length")
    if (least is not None and len(value) < least) or (most is not None and len(value) > most):
        raise ValueError(f"{label} must have a length in [{least or 0}, {most}], got {value!r}")


def number_text(value: float) -> str:
    """A number as short as it can be written and still read back the same (``3``, ``0.5``)."""
    if isinstance(value, int):
        return str(value)
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


# --- one JSON object ---------------------------------------------------------------------


def encode(config: object) -> str:
    """``config`` as one JSON object, for ``decode`` in another process."""
    return msgspec.json.encode(config).decode()


def check_text_size(text: str | bytes) -> None:
    """ValueError if a configuration's text is longer than any configuration can be."""
    if len(text) > MAX_TEXT_BYTES:
        raise ValueError(f"longer than {MAX_TEXT_BYTES} bytes: not a configuration")


def decode(text: str | bytes, config_type: type[T]) -> T:
    """The ``config_type`` in ``text``; ValueError for bad JSON, an unknown field, a value
    of the wrong type or out of range, or values that do not fit together, or a text
    longer than ``MAX_TEXT_BYTES``."""
    check_text_size(text)
    try:
        raw = msgspec.json.decode(text)
        _refuse_unknown(raw, config_type, "")
        return msgspec.convert(raw, config_type)
    except (msgspec.DecodeError, msgspec.ValidationError) as error:
        raise ValueError(str(error)) from None


def _refuse_unknown(raw: Any, hint: Any, path: str) -> None:
    """ValueError for a field in ``raw`` that the dataclasses of ``hint`` do not have."""
    kind = resolved(hint)[0]
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if dataclasses.is_dataclass(kind) and isinstance(raw, dict):
        known = {setting.name: setting for setting in settings_of(kind)}  # type: ignore[arg-type]
        for name, value in raw.items():
            if name not in known:
                raise ValueError(f"unknown setting '{path}{name}'")
            _refuse_unknown(value, known[name].hint, f"{path}{name}.")
    elif origin is dict and isinstance(raw, dict):
        for key, value in raw.items():
            _refuse_unknown(value, args[1], f"{path}{key}.")
    elif origin is tuple and isinstance(raw, list) and args:
        for item in raw:
            _refuse_unknown(item, args[0], path)
