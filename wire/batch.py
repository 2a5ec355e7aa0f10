"""Batches: several robots' messages of one tick in one Zenoh message (no Zenoh here).

A process hosting several robots gets their senses from the world as one batch on
``host/<lead>/sense`` and answers with one batch of their acts on ``host/<lead>/act``
(``<lead>``: the first robot it hosts; docs/protocol.md). Each entry is exactly the message
the robot would have sent or received on its own key: the JSON payload and the attachment
sealed with that robot's run key over that robot's key expression (``robot/<id>/sense`` or
``robot/<id>/act``), so a receiver checks every entry as if it had come alone, and one bad
entry costs only itself. Batching saves Zenoh ``put`` calls and wake-ups, nothing else:
what a robot decides cannot depend on it.

Wire format (all integers big-endian)::

    batch = "BNB1" u16(count) entry*count
    entry = u32(robot) u16(len A) A u32(len P) P      A: attachment (empty: none), P: payload
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

from wire import names, protocol, shape

MAGIC = b"BNB1"
MAX_ENTRIES = shape.MAX_SWARM  # robots one host may carry: a whole swarm at most
MAX_ATTACHMENT_BYTES = 1024  # a tag and, for what is batched today, no metadata
MAX_BATCH_BYTES = 4 * 2**20

_HEADER = struct.Struct(">4sH")
_ROBOT_AND_ATTACHMENT = struct.Struct(">IH")
_PAYLOAD_LENGTH = struct.Struct(">I")


class BatchError(protocol.ProtocolError):
    """A batch that is not exactly a valid one: the whole batch is dropped."""


class Entry(NamedTuple):
    robot: int
    payload: bytes
    attachment: bytes | None  # what the robot's own message would carry on its key


def encode(entries: Sequence[Entry]) -> bytes:
    """One batch of ``entries`` (at most MAX_ENTRIES, each robot once)."""
    if len(entries) > MAX_ENTRIES:
        raise ValueError(f"a batch holds at most {MAX_ENTRIES} entries, not {len(entries)}")
    parts = [_HEADER.pack(MAGIC, len(entries))]
    for robot, payload, attachment in entries:
        attachment = attachment or b""
        parts.append(_ROBOT_AND_ATTACHMENT.pack(robot, len(attachment)))
        parts.append(attachment)
        parts.append(_PAYLOAD_LENGTH.pack(len(payload)))
        parts.append(payload)
    return b"".join(parts)


def decode(data: bytes) -> list[Entry]:
    """The entries of a batch; BatchError unless ``data`` is exactly one valid batch: the
    magic, a count within MAX_ENTRIES, robot ids of the protocol, each robot at most once,
    attachments and payloads within their bounds, nothing left over."""
    if len(data) > MAX_BATCH_BYTES:
        raise BatchError(f"batch of {len(data)} bytes exceeds {MAX_BATCH_BYTES}")
    if len(data) < _HEADER.size:
        raise BatchError("batch shorter than its header")
    magic, count = _HEADER.unpack_from(data, 0)
    if magic != MAGIC:
        raise BatchError("not a batch (wrong magic)")
    if count > MAX_ENTRIES:
        raise BatchError(f"batch of {count} entries exceeds {MAX_ENTRIES}")
    offset = _HEADER.size
    entries: list[Entry] = []
    seen: set[int] = set()
    for _ in range(count):
        if offset + _ROBOT_AND_ATTACHMENT.size > len(data):
            raise BatchError("batch cut short")
        robot, attachment_length = _ROBOT_AND_ATTACHMENT.unpack_from(data, offset)
        offset += _ROBOT_AND_ATTACHMENT.size
        if robot >= names.MAX_ROBOTS:
            raise BatchError(f"robot id {robot} out of range")
        if robot in seen:
            raise BatchError(f"robot {robot} twice in one batch")
        seen.add(robot)
        if attachment_length > MAX_ATTACHMENT_BYTES:
            raise BatchError(f"attachment of {attachment_length} bytes")
        attachment = data[offset : offset + attachment_length]
        offset += attachment_length
        if offset + _PAYLOAD_LENGTH.size > len(data):
            raise BatchError("batch cut short")
        (payload_length,) = _PAYLOAD_LENGTH.unpack_from(data, offset)
        offset += _PAYLOAD_LENGTH.size
        if payload_length > protocol.MAX_PAYLOAD_BYTES:
            raise BatchError(f"payload of {payload_length} bytes")
        if offset + payload_length > len(data):
            raise BatchError("batch cut short")
        payload = data[offset : offset + payload_length]
        offset += payload_length
        entries.append(Entry(robot, payload, attachment or None))
    if offset != len(data):
        raise BatchError(f"{len(data) - offset} bytes after the last entry")
    return entries
