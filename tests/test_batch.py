"""The batch codec (wire/batch.py): what it encodes reads back, and anything that is
not exactly a valid batch is refused whole, with a BatchError, never another exception."""

from __future__ import annotations

import contextlib
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wire import batch, names, protocol

ENTRIES = [
    batch.Entry(0, b'{"v":1,"tick":3}', b"\x01" * 16),
    batch.Entry(7, b"{}", None),
    batch.Entry(names.MAX_ROBOTS - 1, b"", b"tag"),
]


def test_a_batch_reads_back_entry_for_entry() -> None:
    assert batch.decode(batch.encode(ENTRIES)) == ENTRIES
    assert batch.decode(batch.encode([])) == []


def test_the_wire_format_is_the_documented_one() -> None:
    data = batch.encode([batch.Entry(5, b"{}", b"AB")])
    assert data == b"BNB1" + b"\x00\x01" + b"\x00\x00\x00\x05\x00\x02AB" + b"\x00\x00\x00\x02{}"


def _entry(robot: int, attachment: bytes, payload: bytes) -> bytes:
    length = struct.pack(">I", len(payload))
    return struct.pack(">IH", robot, len(attachment)) + attachment + length + payload


def _header(count: int) -> bytes:
    return b"BNB1" + struct.pack(">H", count)


GOOD = batch.encode(ENTRIES)


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "shorter than its header"),
        (b"BNB2" + GOOD[4:], "wrong magic"),
        (_header(batch.MAX_ENTRIES + 1), "entries exceeds"),
        (_header(2) + _entry(1, b"", b"{}") + b"{}", "cut short"),
        (_header(1) + _entry(1, b"", b"{}")[:-1], "cut short"),
        (GOOD[:-1], "cut short"),
        (GOOD + b"\x00", "1 bytes after the last entry"),
        (_header(1) + _entry(names.MAX_ROBOTS, b"", b""), "out of range"),
        (_header(2) + _entry(3, b"", b"") + _entry(3, b"", b""), "robot 3 twice"),
        (_header(1) + _entry(1, b"x" * 1025, b""), "attachment of 1025 bytes"),
        (
            _header(1)
            + struct.pack(">IH", 1, 0)
            + struct.pack(">I", protocol.MAX_PAYLOAD_BYTES + 1),
            "payload of",
        ),
        (b"\x00" * (batch.MAX_BATCH_BYTES + 1), "exceeds"),
    ],
)
def test_anything_but_a_valid_batch_is_refused_whole(data: bytes, reason: str) -> None:
    with pytest.raises(batch.BatchError, match=reason):
        batch.decode(data)


def test_the_encoder_refuses_more_entries_than_a_batch_may_hold() -> None:
    too_many = [batch.Entry(robot, b"", None) for robot in range(batch.MAX_ENTRIES + 1)]
    with pytest.raises(ValueError):
        batch.encode(too_many)


@given(st.binary(max_size=200))
def test_random_bytes_never_raise_anything_but_a_batch_error(data: bytes) -> None:
    with contextlib.suppress(batch.BatchError):
        batch.decode(b"BNB1" + data)
