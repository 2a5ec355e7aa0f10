"""docs/protocol.md: every byte-exact example decodes and re-encodes to the same bytes, the
link's examples are the conformance vectors' bytes, and the tables of every field's bounds
and of the controller's settings are the code's (made here from the types: to change them,
change the code, and paste what the failing test prints)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import msgspec
import msgspec.inspect as mi
import pytest

from bestofn_swarm.link.core import codec
from bestofn_swarm.wire import protocol, settings
from robot_agent.core.controller_config import ControllerConfig

REPO = Path(__file__).resolve().parent.parent
DOC = REPO / "docs" / "protocol.md"
EXAMPLE = re.compile(r"```json (\w+)\n(.*?)\n```", re.DOTALL)
EXAMPLES = EXAMPLE.findall(DOC.read_text())
TYPES = {
    "OpinionPayload": protocol.RadioPayload,
    "BeaconPayload": protocol.RadioPayload,
    "VotePayload": protocol.RadioPayload,
}
LINK = json.loads((REPO / "tests" / "vectors" / "link_frame.json").read_text())


def test_the_document_shows_every_message_type() -> None:
    shown = {name for name, _ in EXAMPLES}
    defined = {
        name
        for name, value in vars(protocol).items()
        if isinstance(value, type)
        and issubclass(value, protocol.Message)
        and value is not protocol.Message
    }
    assert defined <= shown, f"messages without an example: {defined - shown}"
    assert {"OpinionPayload", "BeaconPayload", "VotePayload"} <= shown


@pytest.mark.parametrize(("name", "text"), EXAMPLES, ids=[name for name, _ in EXAMPLES])
def test_an_example_is_exactly_what_the_codec_produces(name: str, text: str) -> None:
    kind = TYPES.get(name, getattr(protocol, name))
    message = protocol.decode(text.encode(), kind)
    assert type(message).__name__ == name
    assert protocol.encode(message) == text.encode()
    assert f"### {name} ({len(text.encode())} bytes)" in DOC.read_text()


def _hex_after(marker: str) -> bytes:
    """The bytes of the first code block after ``marker`` (its first line, as hex pairs)."""
    text = DOC.read_text()
    block = re.search(r"```\n(.*?)\n", text[text.index(marker) :])
    assert block is not None
    return bytes.fromhex(block.group(1))


def test_the_link_examples_are_the_vectors() -> None:
    frames = {vector["name"]: vector for vector in LINK["valid"]}
    assert _hex_after("the 49-byte frame").hex() == frames["hello"]["hex"]
    assert _hex_after("PONG of ping 1").hex() == frames["pong"]["serial_hex"]
    welcome = re.search(r"```json\n(\{\"v\":1,\"run\".*?)\n```", DOC.read_text())
    assert welcome is not None
    assert welcome.group(1) == frames["welcome"]["body_utf8"]


# --- the bounds of every field ---------------------------------------------------------------

BOUNDED: tuple[Any, ...] = (
    protocol.WorldInfo,
    protocol.Site,
    protocol.Nest,
    protocol.CameraSpec,
    protocol.JoinReply,
    protocol.Clock,
    protocol.WorldState,
    protocol.Pose,
    protocol.RadioCounters,
    protocol.Sense,
    protocol.CameraMeta,
    protocol.Act,
    protocol.Ack,
    protocol.Status,
    protocol.Comparison,
    protocol.RadioTxMeta,
    protocol.RadioRxMeta,
    protocol.OpinionPayload,
    protocol.VotePayload,
    protocol.BeaconPayload,
    protocol.LogLine,
    protocol.LinkStats,
    protocol.LinkRefusals,
    protocol.RunEnding,
    protocol.EndingSeals,
    codec.LinkWelcome,
)


def _number(value: float) -> str:
    if isinstance(value, int):
        return {2**53: "2^53", 2**63 - 1: "2^63 - 1"}.get(value, str(value))
    if value == int(value) and abs(value) >= 1e5:
        return f"{value:.0e}".replace("e+0", "e").replace("e+", "e")
    return settings.number_text(value)


def _interval(info: mi.IntType | mi.FloatType) -> str:
    low = info.ge if info.ge is not None else info.gt
    high = info.le if info.le is not None else info.lt
    if low is None and high is None:
        return ""
    left = "[" if info.ge is not None else "("
    right = "]" if info.le is not None else ")"
    low_text = "-inf" if low is None else _number(low)
    high_text = "inf" if high is None else _number(high)
    return f"{left}{low_text}, {high_text}{right}"


def _value(info: mi.Type) -> tuple[str, str]:
    """What a field holds, and its bounds, in words."""
    if isinstance(info, mi.IntType):
        return "integer", _interval(info)
    if isinstance(info, mi.FloatType):
        return "number", _interval(info)
    if isinstance(info, mi.BoolType):
        return "`true` or `false`", ""
    if isinstance(info, mi.LiteralType):
        values = [f'`"{v}"`' if isinstance(v, str) else f"`{v}`" for v in info.values]
        return ("`1`" if values == ["`1`"] else "one of " + ", ".join(values)), ""
    if isinstance(info, mi.EnumType):
        values = [f'`"{member.value}"`' for member in info.cls]
        return "one of " + ", ".join(values), ""
    if isinstance(info, mi.DictType):
        return "a JSON object (the run's summary)", ""
    if isinstance(info, mi.StrType):
        if info.pattern == "^[0-9a-f]{32}$":
            return "hex tag", "32 of `0-9 a-f` (16 bytes)"
        if info.pattern is not None:
            return "name", f"{info.min_length} to {info.max_length} of `A-Z a-z 0-9 _ . -`"
        return "string", f"at most {info.max_length} characters"
    if isinstance(info, mi.ListType):
        least, most = info.min_length or 0, info.max_length
        count = f"{least}" if least == most else f"{least} to {most}" if most else "any number of"
        if isinstance(info.item_type, mi.StructType):
            return f"array of {count} `{info.item_type.cls.__name__}`", ""
        item, bounds = _value(info.item_type)
        return f"array of {count} {item}s", f"each {bounds}" if bounds else ""
    if isinstance(info, mi.StructType):
        return f"`{info.cls.__name__}`", ""
    if isinstance(info, mi.UnionType):
        (inner,) = [item for item in info.types if not isinstance(item, mi.NoneType)]
        value, bounds = _value(inner)
        return f"{value} or `null`", bounds
    if isinstance(info, mi.RawType):
        return "a JSON object (`ControllerConfig`, below)", ""
    raise AssertionError(f"no words for {info!r}")


def field_bounds_table() -> str:
    """Every field of every message, in encoding order: what it holds and its bounds."""
    rows = ["| message | field | value | bounds |", "|---|---|---|---|"]
    for kind in BOUNDED:
        info = mi.type_info(kind)
        assert isinstance(info, mi.StructType)
        name = f"`{kind.__name__}`" + (" (an array)" if info.array_like else "")
        if info.tag_field is not None:
            rows.append(f'| {name} | `{info.tag_field}` | `"{info.tag}"` | |')
        for field in info.fields:
            value, bounds = _value(field.type)
            if not field.required:
                absent = "null" if field.default is None else json.dumps(field.default)
                bounds = f"{bounds}; may be absent ({absent})".lstrip("; ")
            rows.append(f"| {name} | `{field.name}` | {value} | {bounds} |")
    return "\n".join(rows)


# --- the controller's settings -----------------------------------------------------------


def controller_table() -> str:
    """Every field of ``ControllerConfig``: its JSON value, range, default and meaning."""
    rows = ["| field | value | range | default | meaning |", "|---|---|---|---|---|"]
    for setting in settings.settings_of(ControllerConfig):
        kind, constraints = settings.resolved(setting.hint)
        choices = getattr(kind, "__args__", None)
        if choices is not None:
            value, bounds = "one of " + ", ".join(f'`"{choice}"`' for choice in choices), ""
        elif kind is str:  # a plug-in's name (docs/extending.md)
            value = "a name, or `package.module:attribute`"
            bounds = f"{constraints['min_length']} to {constraints['max_length']} characters"
        elif kind is int:
            value, bounds = "integer", settings.interval(constraints)
        else:
            value, bounds = "number", settings.interval(constraints)
        quoted = choices is not None or kind is str
        default = f'`"{setting.default}"`' if quoted else json.dumps(setting.default)
        if kind is float:
            default = msgspec.json.encode(float(setting.default)).decode()
        meaning = setting.description.replace("|", "/")
        rows.append(f"| `{setting.name}` | {value} | {bounds} | {default} | {meaning} |")
    return "\n".join(rows)


def _table(marker: str) -> str:
    """The Markdown table that follows ``marker`` in the page."""
    text = DOC.read_text()
    lines = text[text.index(marker) :].splitlines()[1:]
    start = next(index for index, line in enumerate(lines) if line.startswith("|"))
    table = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        table.append(line)
    return "\n".join(table)


def test_the_table_of_field_bounds_is_the_code_s() -> None:
    expected = field_bounds_table()
    assert _table("<!-- field bounds:") == expected, f"the table is now:\n{expected}"


def test_the_table_of_controller_settings_is_the_code_s() -> None:
    expected = controller_table()
    assert _table("<!-- controller settings:") == expected, f"the table is now:\n{expected}"
    assert len(settings.settings_of(ControllerConfig)) == expected.count("\n") - 1


if __name__ == "__main__":
    print(field_bounds_table(), end="\n\n")
    print(controller_table())
