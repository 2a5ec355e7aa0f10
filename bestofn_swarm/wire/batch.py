"""Batches: a tick's senses and acts of the robots one process hosts, each way in one Zenoh
message of a fixed binary layout (no Zenoh here).

A process hosting the robots ``first`` to ``last`` gets their senses from the world as one
batch on ``host/<first>/sense`` and answers with one batch of their acts on
``host/<first>/act`` (docs/protocol.md). The process is the trust boundary: its robots share
its memory, and so its keys, so a batch carries one tag, of the host identity
``host/<first>-<last>`` (``bestofn_swarm/wire/names.py``), and the world takes from a batch of acts
only entries of the robots ``first`` to ``last``. Batching saves Zenoh ``put`` calls, wake-ups,
per-robot tags and JSON, nothing else: what a robot decides cannot depend on it (the
numbers are the same 64-bit floats as in the JSON messages).

Layout (little-endian; ``f64`` an IEEE 754 double)::

    senses = "BNS1" u32(last) u32(count) u64(tick) f64(t)
             f64[count][11]   x, y, theta, prox[0..7] of each robot, row by row
             u32[count]       robot ids
             u16[count]       rx (radio deliveries of the tick)
             u8[count]        camera (0 or 1: a frame comes this tick)
    acts   = "BNA1" u32(last) u32(count)
             count x (u32 robot, u64 tick, f64 left, f64 right, u8 capture, u16 radio_tx)

A batch is refused whole (``BatchError``) unless it is exactly that: the magic, a count of
at most MAX_ENTRIES, every byte accounted for, each robot once and below ``names.MAX_ROBOTS``,
and every number within the bounds of the message it stands for (``protocol.Sense``,
``protocol.Act``; NaN and infinities never are).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from bestofn_swarm.wire import names, protocol, shape

SENSE_MAGIC = b"BNS1"
ACT_MAGIC = b"BNA1"
MAX_ENTRIES = shape.MAX_SWARM  # robots one host may carry: a whole swarm at most
SENSE_VALUES = 11  # x, y, theta and the 8 proximity readings

_SENSE_HEADER = struct.Struct("<4sIIQd")
_SENSE_ROW_BYTES = 8 * SENSE_VALUES + 4 + 2 + 1
_ACT_HEADER = struct.Struct("<4sII")
_ACT_ROW = struct.Struct("<IQddBH")
MAX_BATCH_BYTES = _SENSE_HEADER.size + MAX_ENTRIES * _SENSE_ROW_BYTES  # the larger kind


class BatchError(protocol.ProtocolError):
    """A batch that is not exactly a valid one: the whole batch is dropped."""


class SenseBatch(NamedTuple):
    """The senses of one tick for robots of one host, in the batch's order."""

    last: int  # the host's last robot: with the key's first, its identity
    robots: list[int]
    senses: list[protocol.Sense]


class SenseRows(NamedTuple):
    """The senses of one tick for robots of one host as the world makes them: a row of
    ``values`` per robot (x, y, theta, 8 proximity readings), in the order of ``robots``."""

    last: int
    tick: int
    t: float
    robots: list[int]
    values: list[list[float]]
    rx: list[int]
    camera: list[bool]

    def batch(self) -> SenseBatch:
        """The same senses as ``decode_senses`` of their encoding gives them."""
        tick, t = self.tick, self.t
        senses = [
            sense_of_row(tick, t, row, rx, camera)
            for row, rx, camera in zip(self.values, self.rx, self.camera, strict=True)
        ]
        return SenseBatch(self.last, self.robots, senses)


class ActBatch(NamedTuple):
    """Acts of robots of one host, in the batch's order."""

    last: int
    acts: list[tuple[int, protocol.Act]]  # (robot, its act)


# --- senses ------------------------------------------------------------------------------


def encode_senses(
    last: int,
    *,
    tick: int,
    t: float,
    robots: Sequence[int] | np.ndarray,
    values: Sequence[Sequence[float]] | np.ndarray,
    rx: Sequence[int] | np.ndarray,
    camera: Sequence[bool] | np.ndarray,
) -> bytes:
    """One batch of senses: ``values`` is a (count, 11) array of each robot's x, y, theta
    and 8 proximity readings, in the order of ``robots``."""
    count = len(robots)
    if count > MAX_ENTRIES:
        raise ValueError(f"a batch holds at most {MAX_ENTRIES} entries, not {count}")
    if np.shape(values) != (count, SENSE_VALUES) or len(rx) != count or len(camera) != count:
        raise ValueError("one row of values, one rx and one camera flag per robot")
    return b"".join(
        (
            _SENSE_HEADER.pack(SENSE_MAGIC, last, count, tick, t),
            np.ascontiguousarray(values, dtype="<f8").tobytes(),
            np.asarray(robots, dtype="<u4").tobytes(),
            np.asarray(rx, dtype="<u2").tobytes(),
            np.asarray(camera, dtype="u1").tobytes(),
        )
    )


def encode_sense_rows(rows: SenseRows) -> bytes:
    """``encode_senses`` of a batch held as ``SenseRows``."""
    return encode_senses(
        rows.last,
        tick=rows.tick,
        t=rows.t,
        robots=rows.robots,
        values=rows.values,
        rx=rows.rx,
        camera=rows.camera,
    )


def decode_senses(data: bytes) -> SenseBatch:
    """The senses of a batch; BatchError unless ``data`` is exactly one valid batch."""
    if len(data) < _SENSE_HEADER.size:
        raise BatchError("batch shorter than its header")
    magic, last, count, tick, t = _SENSE_HEADER.unpack_from(data, 0)
    if magic != SENSE_MAGIC:
        raise BatchError("not a batch of senses (wrong magic)")
    _check_header(last, count, len(data) - _SENSE_HEADER.size, _SENSE_ROW_BYTES)
    if tick > protocol.MAX_TICK or not 0.0 <= t <= protocol.MAX_SIM_TIME:
        raise BatchError(f"tick {tick} at sim time {t!r} is out of range")
    offset = _SENSE_HEADER.size
    values = np.frombuffer(data, "<f8", count * SENSE_VALUES, offset).reshape(count, SENSE_VALUES)
    offset += values.nbytes
    robots = np.frombuffer(data, "<u4", count, offset).tolist()
    rx = np.frombuffer(data, "<u2", count, offset + 4 * count).tolist()
    camera = np.frombuffer(data, "u1", count, offset + 6 * count).tolist()
    _check_robots(robots)
    coords, angles, prox = values[:, :2], values[:, 2], values[:, 3:]
    if not (
        np.isfinite(values).all()
        and (np.abs(coords) <= protocol.MAX_COORD).all()
        and (np.abs(angles) <= protocol.MAX_ANGLE).all()
        and ((prox >= 0.0) & (prox <= 1.0)).all()
    ):
        raise BatchError("a sense's pose or proximity reading is out of range")
    if any(count > protocol.MAX_RX for count in rx) or any(flag > 1 for flag in camera):
        raise BatchError("a sense's rx or camera flag is out of range")
    senses = [
        sense_of_row(tick, t, row, deliveries, flag == 1)
        for row, deliveries, flag in zip(values.tolist(), rx, camera, strict=True)
    ]
    return SenseBatch(last, robots, senses)


def sense_of_row(tick: int, t: float, row: list[float], rx: int, camera: bool) -> protocol.Sense:
    """One robot's ``Sense`` from its row of a batch (x, y, theta, then proximity): the one
    place a row becomes a message, for the world's senses and a decoded batch alike."""
    return protocol.Sense(
        v=protocol.VERSION,
        tick=tick,
        t=t,
        x=row[0],
        y=row[1],
        theta=row[2],
        prox=row[3:],
        rx=rx,
        camera=camera,
    )


# --- acts --------------------------------------------------------------------------------


def encode_acts(last: int, acts: Sequence[tuple[int, protocol.Act]]) -> bytes:
    """One batch of ``(robot, act)`` entries (at most MAX_ENTRIES, each robot once)."""
    if len(acts) > MAX_ENTRIES:
        raise ValueError(f"a batch holds at most {MAX_ENTRIES} entries, not {len(acts)}")
    pack = _ACT_ROW.pack
    rows = [
        pack(robot, act.tick, act.left, act.right, act.capture, act.radio_tx) for robot, act in acts
    ]
    return _ACT_HEADER.pack(ACT_MAGIC, last, len(acts)) + b"".join(rows)


def encode_act_batch(acts: ActBatch) -> bytes:
    """``encode_acts`` of a batch held as an ``ActBatch``."""
    return encode_acts(acts.last, acts.acts)


def decode_acts(data: bytes) -> ActBatch:
    """The acts of a batch; BatchError unless ``data`` is exactly one valid batch."""
    if len(data) < _ACT_HEADER.size:
        raise BatchError("batch shorter than its header")
    magic, last, count = _ACT_HEADER.unpack_from(data, 0)
    if magic != ACT_MAGIC:
        raise BatchError("not a batch of acts (wrong magic)")
    _check_header(last, count, len(data) - _ACT_HEADER.size, _ACT_ROW.size)
    acts = []
    wheel = protocol.MAX_WHEEL
    rows = _ACT_ROW.iter_unpack(memoryview(data)[_ACT_HEADER.size :])
    for robot, tick, left, right, capture, radio_tx in rows:
        # A NaN fails every comparison, so it is refused here too.
        if not (
            -wheel <= left <= wheel
            and -wheel <= right <= wheel
            and tick <= protocol.MAX_TICK
            and capture <= 1
            and radio_tx <= protocol.MAX_TX
        ):
            raise BatchError(f"robot {robot}'s act is out of range")
        act = protocol.Act(
            v=protocol.VERSION,
            tick=tick,
            left=left,
            right=right,
            capture=capture == 1,
            radio_tx=radio_tx,
        )
        acts.append((robot, act))
    _check_robots([robot for robot, _ in acts])
    return ActBatch(last, acts)


# --- checks ------------------------------------------------------------------------------


def _check_header(last: int, count: int, body: int, row: int) -> None:
    if last >= names.MAX_ROBOTS:
        raise BatchError(f"host's last robot {last} out of range")
    if count > MAX_ENTRIES:
        raise BatchError(f"batch of {count} entries exceeds {MAX_ENTRIES}")
    if body != count * row:
        raise BatchError(f"{body} bytes after the header, not {count} x {row}")


def _check_robots(robots: list[int]) -> None:
    if any(robot >= names.MAX_ROBOTS for robot in robots):
        raise BatchError("a robot id out of range")
    if len(set(robots)) != len(robots):
        raise BatchError("a robot twice in one batch")
