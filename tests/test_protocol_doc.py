"""docs/protocol.md: every byte-exact example decodes and re-encodes to the same bytes."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from wire import protocol

DOC = Path(__file__).resolve().parent.parent / "docs" / "protocol.md"
EXAMPLE = re.compile(r"```json (\w+)\n(.*?)\n```", re.DOTALL)
EXAMPLES = EXAMPLE.findall(DOC.read_text())
TYPES = {
    "OpinionPayload": protocol.RadioPayload,
    "BeaconPayload": protocol.RadioPayload,
    "VotePayload": protocol.RadioPayload,
}


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
