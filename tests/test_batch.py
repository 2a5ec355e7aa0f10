"""The batch codec (bestofn_swarm/wire/batch.py): what it encodes reads back as the very messages a
robot would send or receive alone, and anything that is not exactly a valid batch is refused
whole, with a BatchError, never another exception."""

from __future__ import annotations

import contextlib
import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bestofn_swarm.wire import batch, names, protocol

VALUES = np.array(
    [
        [0.31, -0.12, 1.5708, 0.0, 0.0, 0.0, 0.000015, 1.5e-6, 0.0, 0.25, 1.0],
        [-1e6, 1e6, -3.141592653589793, *[0.5] * 8],
    ]
)


def senses(**changes: object) -> bytes:
    fields: dict[str, object] = {
        "tick": 42,
        "t": 4.2,
        "robots": [3, 4],
        "values": VALUES,
        "rx": [2, 0],
        "camera": [True, False],
    }
    fields.update(changes)
    return batch.encode_senses(4, **fields)  # type: ignore[arg-type]


ACTS = [
    (3, protocol.Act(v=1, tick=42, left=0.13, right=-0.065, capture=False, radio_tx=1)),
    (4, protocol.Act(v=1, tick=41, left=-10.0, right=10.0, capture=True, radio_tx=0)),
]


def test_a_batch_of_senses_reads_back_as_each_robot_s_sense() -> None:
    decoded = batch.decode_senses(senses())
    assert (decoded.last, decoded.robots) == (4, [3, 4])
    assert decoded.senses[0] == protocol.Sense(
        v=1,
        tick=42,
        t=4.2,
        x=0.31,
        y=-0.12,
        theta=1.5708,
        prox=[0.0, 0.0, 0.0, 0.000015, 1.5e-6, 0.0, 0.25, 1.0],
        rx=2,
        camera=True,
    )
    # The JSON of each is the robot's own message, byte for byte: the same doubles.
    assert protocol.decode(protocol.encode(decoded.senses[1]), protocol.Sense) == decoded.senses[1]
    assert batch.decode_senses(senses(robots=[], values=np.zeros((0, 11)), rx=[], camera=[])) == (
        4,
        [],
        [],
    )


def test_a_batch_of_acts_reads_back_act_for_act() -> None:
    assert batch.decode_acts(batch.encode_acts(7, ACTS)) == (7, ACTS)
    assert batch.decode_acts(batch.encode_acts(7, [])) == (7, [])


def test_the_wire_format_is_the_documented_one() -> None:
    data = batch.encode_acts(5, ACTS[:1])
    assert data == (
        b"BNA1" + struct.pack("<II", 5, 1) + struct.pack("<IQddBH", 3, 42, 0.13, -0.065, 0, 1)
    )
    assert len(data) == 12 + 31
    data = senses()
    head = b"BNS1" + struct.pack("<IIQd", 4, 2, 42, 4.2)
    rows = struct.pack("<22d", *VALUES.reshape(-1))
    assert data == head + rows + struct.pack("<II", 3, 4) + struct.pack("<HH", 2, 0) + b"\x01\x00"
    assert len(data) == 28 + 2 * 95


def _sense_header(last: int = 4, count: int = 1, tick: int = 1, t: float = 0.1) -> bytes:
    return b"BNS1" + struct.pack("<IIQd", last, count, tick, t)


ONE_SENSE = _sense_header() + struct.pack("<11d", *[0.0] * 11) + b"\x03\x00\x00\x00\x00\x00\x00"


def _one_sense_with(value_index: int, value: float) -> bytes:
    values = [0.0] * 11
    values[value_index] = value
    return _sense_header() + struct.pack("<11d", *values) + b"\x03\x00\x00\x00\x00\x00\x00"


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "shorter than its header"),
        (b"BNA1" + ONE_SENSE[4:], "wrong magic"),
        (_sense_header(count=batch.MAX_ENTRIES + 1), "exceeds"),
        (_sense_header(last=names.MAX_ROBOTS), "last robot"),
        (ONE_SENSE[:-1], "not 1 x 95"),
        (ONE_SENSE + b"\x00", "not 1 x 95"),
        (_sense_header(tick=2**53 + 1) + ONE_SENSE[28:], "out of range"),
        (_sense_header(t=-0.1) + ONE_SENSE[28:], "out of range"),
        (_sense_header(t=math.nan) + ONE_SENSE[28:], "out of range"),
        (_one_sense_with(0, math.nan), "out of range"),
        (_one_sense_with(1, -math.inf), "out of range"),
        (_one_sense_with(0, 1e6 + 1), "out of range"),
        (_one_sense_with(2, 1001.0), "out of range"),
        (_one_sense_with(10, 1.5), "out of range"),
        (_one_sense_with(3, -0.001), "out of range"),
        (ONE_SENSE[:-3] + b"\x11\x27\x00", "rx or camera"),  # rx 10001
        (ONE_SENSE[:-1] + b"\x02", "rx or camera"),  # camera 2
        (ONE_SENSE[:-7] + struct.pack("<I", names.MAX_ROBOTS) + b"\x00" * 3, "robot id"),
    ],
)
def test_anything_but_a_valid_batch_of_senses_is_refused_whole(data: bytes, reason: str) -> None:
    batch.decode_senses(ONE_SENSE)  # the one they change is valid
    with pytest.raises(batch.BatchError, match=reason):
        batch.decode_senses(data)


def test_a_robot_twice_in_a_batch_of_senses_is_refused() -> None:
    with pytest.raises(batch.BatchError, match="twice"):
        batch.decode_senses(senses(robots=[3, 3]))


def _act_row(**changes: float) -> bytes:
    row: dict[str, float] = {
        "robot": 3,
        "tick": 42,
        "left": 0.1,
        "right": 0.1,
        "capture": 0,
        "radio_tx": 0,
    }
    row.update(changes)
    return struct.pack("<IQddBH", *row.values())


def _acts(*rows: bytes, count: int | None = None) -> bytes:
    return b"BNA1" + struct.pack("<II", 4, len(rows) if count is None else count) + b"".join(rows)


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"BNA", "shorter than its header"),
        (b"BNS1" + _acts(_act_row())[4:], "wrong magic"),
        (_acts(count=batch.MAX_ENTRIES + 1), "exceeds"),
        (_acts(_act_row())[:-1], "not 1 x 31"),
        (_acts(_act_row(), count=2), "not 2 x 31"),
        (_acts(_act_row(left=10.5)), "out of range"),
        (_acts(_act_row(right=math.nan)), "out of range"),
        (_acts(_act_row(left=-math.inf)), "out of range"),
        (_acts(_act_row(capture=2)), "out of range"),
        (_acts(_act_row(radio_tx=1001)), "out of range"),
        (_acts(_act_row(tick=2**53 + 1)), "out of range"),
        (_acts(_act_row(), _act_row()), "twice"),
        (_acts(_act_row(robot=names.MAX_ROBOTS)), "robot id"),
    ],
)
def test_anything_but_a_valid_batch_of_acts_is_refused_whole(data: bytes, reason: str) -> None:
    with pytest.raises(batch.BatchError, match=reason):
        batch.decode_acts(data)


def test_the_encoders_refuse_more_entries_than_a_batch_may_hold() -> None:
    too_many = range(batch.MAX_ENTRIES + 1)
    with pytest.raises(ValueError):
        batch.encode_acts(0, [(robot, ACTS[0][1]) for robot in too_many])
    with pytest.raises(ValueError):
        senses(
            robots=list(too_many),
            values=np.zeros((len(too_many), 11)),
            rx=[0] * len(too_many),
            camera=[False] * len(too_many),
        )
    with pytest.raises(ValueError, match="one row"):
        senses(rx=[0])


@given(st.binary(max_size=300))
def test_random_bytes_never_raise_anything_but_a_batch_error(data: bytes) -> None:
    with contextlib.suppress(batch.BatchError):
        batch.decode_senses(b"BNS1" + data)
    with contextlib.suppress(batch.BatchError):
        batch.decode_acts(b"BNA1" + data)
