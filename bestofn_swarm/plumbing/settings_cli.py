"""Command-line options made from config dataclasses (``bestofn_swarm/wire/settings.py``).

``Options(Config)`` gathers the flagged settings of ``Config`` and of the config
dataclasses in its fields. ``add_to(parser)`` declares them: spelling, help section,
metavar, help with the default, and an argparse type that reads and range-checks a value
by the setting's own definition (a bad value: one line, exit code 2). ``build(args)``
makes the ``Config`` from what was given and the dataclass's defaults for the rest
(ValueError when the values do not fit together). ``argv(args)`` gives back the options
that were given, to pass on to another ``swarm run``; ``record(config)`` is the flat
dictionary, keyed like the options, that a run's summary and recording keep.

An option not given is None in the namespace, so that ``build`` can tell it from a
default, and a child process handed ``--config`` can refuse it.
"""

from __future__ import annotations

import argparse
import math
import typing
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from bestofn_swarm.wire import settings
from bestofn_swarm.wire.settings import Setting


@dataclass(frozen=True)
class _Option:
    """One option: the settings it sets (several when joined), and where they live."""

    flag: str  # e.g. --radio-range
    dest: str  # e.g. radio_range
    path: tuple[str, ...]  # fields from the root config to the dataclass holding them
    owner: type  # that dataclass
    members: tuple[Setting, ...]  # the option's settings: one, or the joined ones

    @property
    def setting(self) -> Setting:
        return self.members[0]

    @property
    def spec(self) -> settings.Flag:
        assert self.setting.flag is not None
        return self.setting.flag

    @property
    def repeatable(self) -> bool:
        """A variable-length tuple: the option is given once per item."""
        args = typing.get_args(self.setting.kind)
        return typing.get_origin(self.setting.kind) is tuple and args[-1:] == (Ellipsis,)

    @property
    def element(self) -> Any:
        """The type of one item of a repeatable option."""
        return typing.get_args(self.setting.kind)[0]

    @property
    def switch(self) -> bool:
        return self.setting.kind is bool


class Options:
    """The command-line options of a config dataclass's flagged settings."""

    def __init__(
        self, config_type: type, *, prefix: str = "", exclude: Collection[str] = ()
    ) -> None:
        """``prefix`` goes in front of every option (``beacon-`` makes ``--beacon-period``);
        ``exclude`` names options (without the prefix, e.g. ``--seed``) left out."""
        self.config_type = config_type
        self.prefix = prefix
        self.options = [
            option
            for option in _walk(config_type, (), prefix)
            if option.flag.replace(f"--{prefix}", "--", 1) not in exclude
        ]

    @property
    def dests(self) -> set[str]:
        """The namespace attributes of these options (``radio_range``)."""
        return {option.dest for option in self.options}

    # --- declaring -------------------------------------------------------------------

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        groups: dict[str, Any] = {}  # argparse's argument groups, by title
        for option in self.options:
            title = option.spec.group or getattr(option.owner, "FLAG_GROUP", None)
            if title is None:
                target: Any = parser
            else:
                target = groups.get(title) or groups.setdefault(
                    title, parser.add_argument_group(title)
                )
            target.add_argument(option.flag, dest=option.dest, default=None, **_declare(option))

    # --- reading ---------------------------------------------------------------------

    def given(self, args: argparse.Namespace) -> list[str]:
        """The options given on the command line."""
        return [option.flag for option in self.options if _value(args, option) is not None]

    def build(self, args: argparse.Namespace, fixed: Mapping[str, Any] | None = None) -> Any:
        """The config of the options given, defaults for the rest; ``fixed`` sets fields by
        dotted path (``{"world.seed": 3}``). ValueError if the values do not fit together."""
        given: dict[tuple[str, ...], dict[str, Any]] = {}
        for option in self.options:
            value = _value(args, option)
            if value is None:
                continue
            fields = given.setdefault(option.path, {})
            if option.spec.joined:
                for setting, part in zip(option.members, value, strict=False):
                    fields[setting.name] = part
            elif option.repeatable:
                fields[option.setting.name] = tuple(value)
            else:
                fields[option.setting.name] = value
        for dotted, value in (fixed or {}).items():
            *path, name = dotted.split(".")
            given.setdefault(tuple(path), {})[name] = value
        return _construct(self.config_type, (), given)

    def argv(self, args: argparse.Namespace) -> list[str]:
        """The options given, written out again (for another command line)."""
        argv: list[str] = []
        for option in self.options:
            value = _value(args, option)
            if value is None:
                continue
            if option.switch:
                argv += [option.flag] if value else []
            elif option.repeatable:
                for item in value:
                    argv += [option.flag, _text(option.element, item)]
            elif option.spec.joined:
                texts = [
                    _text(s.hint, part) for s, part in zip(option.members, value, strict=False)
                ]
                argv += [option.flag, ":".join(texts)]
            else:
                argv += [option.flag, _text(option.setting.hint, value)]
        return argv

    def record(self, config: Any) -> dict[str, Any]:
        """The value of every option in ``config``, keyed by option (``radio_range``), as a
        run's summary keeps it: numbers as numbers, the rest as the option is written."""
        record: dict[str, Any] = {}
        for option in self.options:
            holder = config
            for name in option.path:
                holder = getattr(holder, name)
            values = [getattr(holder, setting.name) for setting in option.members]
            if option.spec.joined:
                record[option.dest] = _joined_text(option, values)
            elif option.repeatable:
                record[option.dest] = [_text(option.element, item) for item in values[0]]
            elif isinstance(values[0], bool | int | float | str) or values[0] is None:
                record[option.dest] = values[0]
            else:
                record[option.dest] = _text(option.setting.hint, values[0])
        return record


def _walk(config_type: type, path: tuple[str, ...], prefix: str) -> Iterator[_Option]:
    """Every flagged setting of ``config_type`` and of the config dataclasses it holds."""
    by_name = {setting.name: setting for setting in settings.settings_of(config_type)}
    for setting in by_name.values():
        inner = setting.config_type
        if inner is not None and setting.flag is None:
            yield from _walk(inner, (*path, setting.name), prefix)
        if setting.flag is None:
            continue
        name = setting.flag.name or setting.name.replace("_", "-")
        joined = tuple(by_name[other] for other in setting.flag.joined)
        yield _Option(
            f"--{prefix}{name}",
            f"{prefix}{name}".replace("-", "_"),
            path,
            config_type,
            (setting, *joined),
        )


def _value(args: argparse.Namespace, option: _Option) -> Any:
    return getattr(args, option.dest, None)


def _construct(
    config_type: type, path: tuple[str, ...], given: Mapping[tuple[str, ...], dict[str, Any]]
) -> Any:
    values = dict(given.get(path, {}))
    for setting in settings.settings_of(config_type):
        inner = setting.config_type
        inside = (*path, setting.name)
        nested_given = any(key[: len(inside)] == inside for key in given)
        if setting.name not in values and inner is not None and nested_given:
            values[setting.name] = _construct(inner, inside, given)
    for setting in settings.settings_of(config_type):
        flag = setting.flag
        if setting.name not in values and flag is not None and flag.default_from is not None:
            values[setting.name] = flag.default_from(values)
    return config_type(**values)


# --- declaring one option ------------------------------------------------------------------


def _declare(option: _Option) -> dict[str, Any]:
    """The add_argument keywords of an option: action, type or choices, metavar, help."""
    spec = option.spec
    keywords: dict[str, Any] = {"help": _help(option).replace("%", "%%")}
    if spec.metavar:
        keywords["metavar"] = spec.metavar
    if option.switch:
        keywords["action"] = "store_true"
        return keywords
    if option.repeatable:
        keywords["action"] = "append"
        keywords["type"] = _reader(option.element, spec, option.flag)
        return keywords
    if spec.joined:
        keywords["type"] = _joined_reader(option)
        return keywords
    kind = settings.resolved(option.setting.hint)[0]
    if typing.get_origin(kind) is Literal and spec.parse is None:
        keywords["choices"] = list(typing.get_args(kind))
        return keywords
    keywords["type"] = _reader(option.setting.hint, spec, option.flag)
    return keywords


def _help(option: _Option) -> str:
    spec = option.spec
    text = spec.help or option.setting.description
    if option.switch:
        return text
    if option.repeatable:
        return f"{text} (repeatable)"
    default = spec.default_text
    if default is None:
        default = _text(option.setting.hint, option.setting.default)
    return f"{text} (default: {default})"


def _reader(hint: Any, spec: settings.Flag, flag: str) -> Any:
    """The argparse type of one value: read ``text`` and check it by ``hint``."""

    def read(text: str) -> Any:
        try:
            value = _read(hint, text, spec)
            _check_number(hint, value)
            settings.check_value(hint, value, flag)
        except ValueError as error:
            raise argparse.ArgumentTypeError(_plain(error, flag)) from None
        return value

    read.__name__ = flag  # what argparse names in its own messages
    return read


def _joined_reader(option: _Option) -> Any:
    """``A:B[:C:D]``: the values of the joined settings, each read and checked by its own."""
    spec = option.spec
    counts = {spec.least or len(option.members), len(option.members)}
    shape = spec.metavar or ":".join(setting.name.upper() for setting in option.members)

    def read(text: str) -> tuple[Any, ...]:
        parts = text.split(":")
        if len(parts) not in counts:
            raise argparse.ArgumentTypeError(f"{text!r} is not {shape}")
        values = []
        for setting, part in zip(option.members, parts, strict=False):
            try:
                value = _read(setting.hint, part, settings.Flag())
                _check_number(setting.hint, value)
                settings.check_value(setting.hint, value, setting.name)
            except ValueError as error:
                raise argparse.ArgumentTypeError(f"{text!r} ({shape}): {error}") from None
            values.append(value)
        return tuple(values)

    read.__name__ = option.flag
    return read


def _read(hint: Any, text: str, spec: settings.Flag) -> Any:
    """The value ``text`` writes, by the type of ``hint`` (not yet range-checked)."""
    if spec.parse is not None:
        return spec.parse(text)
    kind = settings.resolved(hint)[0]
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if kind is int:
        try:
            return int(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a valid int") from None
    if kind is float:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a valid float") from None
        if not math.isfinite(value):
            raise ValueError(f"{text!r} is not a finite number")
        return value
    if kind is str or origin is Literal:
        return text
    if origin is tuple and args and args[-1] is not Ellipsis:
        parts = text.split(":")
        if len(parts) != len(args):
            raise ValueError(f"{text!r} is not {spec.metavar or ':'.join('ABCD'[: len(args)])}")
        return tuple(
            _read(arg, part, settings.Flag()) for arg, part in zip(args, parts, strict=True)
        )
    parse = getattr(kind, "parse", None)
    if parse is not None:
        return parse(text)
    raise TypeError(f"no command-line form for {kind!r}")


def _check_number(hint: Any, value: Any) -> None:
    """ValueError ``V is outside [A, B]`` for a number out of its setting's range."""
    kind, constraints = settings.resolved(hint)
    if kind in (int, float) and not settings.in_range(value, constraints):
        raise ValueError(
            f"{settings.number_text(value)} is outside {settings.interval(constraints)}"
        )


def _text(hint: Any, value: Any) -> str:
    """``value`` as its option writes it."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int | float):
        return settings.number_text(value)
    if hasattr(type(value), "parse"):  # a type with a text form of its own: str() writes it
        return str(value)
    if isinstance(value, tuple):
        kind = settings.resolved(hint)[0]
        args = typing.get_args(kind) or (Any,) * len(value)
        return ":".join(_text(arg, item) for arg, item in zip(args, value, strict=False))
    return str(value)


def _joined_text(option: _Option, values: list[Any]) -> str | None:
    """``A:B`` or ``A:B:C:D`` of joined settings; None when all are at their defaults."""
    defaults = [setting.default for setting in option.members]
    if values == defaults:
        return None
    least = option.spec.least or len(values)
    shown = values if values[least:] != defaults[least:] else values[:least]
    return ":".join(_text(s.hint, v) for s, v in zip(option.members, shown, strict=False))


def _plain(error: ValueError, flag: str) -> str:
    """A check's message without the option's name, which argparse puts in front."""
    text = str(error)
    return text[len(flag) + 1 :] if text.startswith(f"{flag} ") else text


# --- a child's configuration as one object -------------------------------------------------


def add_config_option(parser: argparse.ArgumentParser, config_type: type) -> None:
    """``--config JSON``: the whole configuration as one object, as ``swarm run`` hands it
    to the processes it starts."""
    parser.add_argument(
        "--config",
        metavar="JSON",
        default=None,
        help=f"the whole configuration as one JSON object (a {config_type.__name__}), as "
        "swarm run hands it over; the options it sets cannot be given with it",
    )


def config_from(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace,
    options: Options,
    fixed: Mapping[str, Any] | None = None,
) -> Any:
    """The process's configuration: ``--config``'s, or its options' (with ``fixed``). A
    usage error (one line, exit code 2) if it is not valid."""
    try:
        if args.config is None:
            return options.build(args, fixed)
        given = options.given(args)
        if given:
            raise ValueError(f"{given[0]} cannot be given with --config, which sets it")
        try:
            return settings.decode(args.config, options.config_type)
        except ValueError as error:
            raise ValueError(f"--config: {error}") from None
    except ValueError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
