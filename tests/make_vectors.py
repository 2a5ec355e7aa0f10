"""Write the protocol's conformance vectors, ``tests/vectors/*.json``.

    python tests/make_vectors.py           # (re)write the files from protocol.py
    python tests/make_vectors.py --check   # exit 1 if a file differs from what it would write

One file per message type of ``bestofn_swarm/wire/protocol.py``, plus ``udp_frame.json`` for the
UDP radio's framing (``examples/udp_radio.py``), ``auth.json`` for run keys and
message tags (``bestofn_swarm/wire/auth.py``), ``batch.json`` for the binary batches of a process
hosting several robots and their host's tag (``bestofn_swarm/wire/batch.py``), ``tick.json`` for one
lockstep tick of a robot on Zenoh: what arrives, what the port contract hands the
controller, what goes out (``robot_agent/core/simulated.py``), ``link_frame.json`` for the
link to a robot outside the emulator (``bestofn_swarm/link/core/codec.py``: frames, and what each
end of a session counts for a frame it refuses) and ``key_file.json`` for the key files such a
robot reads (``bestofn_swarm/plumbing/run_keys.py``). Each message file holds:

* ``valid``: messages with the exact bytes ``protocol.encode`` produces for them (as a
  UTF-8 string and as hex). A decoder must accept them; an encoder that wants to be
  byte-exact must reproduce them.
* ``accepted``: other spellings of a valid message (whitespace, field order, number
  forms) that a decoder must accept; ``canonical_hex`` is what re-encoding gives.
* ``invalid``: bytes a decoder must reject, each with the reason and the category of
  the fault. Every one is a valid vector with one thing changed.

``decoder`` says how to decode: ``message`` is ``protocol.decode(bytes, <type>)``;
``radio`` is ``protocol.decode_radio(bytes)``, which also checks that an opinion sums
to 1 (within 1e-6). docs/porting.md explains how a port in another language uses them.
``tests/test_vectors.py`` checks the files against the codec and against this script.

``numeric.json`` and ``rng.json`` are the portable numeric kernel's and the generator's
(``bestofn_swarm/wire/numeric.py``, ``bestofn_swarm/wire/rng.py``, docs/kernel.md): inputs and
outputs as the hex of their IEEE-754 bits, so that a port compares bit for bit;
``tests/test_numeric.py`` checks them.
"""

from __future__ import annotations

import argparse
import json
import math
import struct
import sys
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

# Run as a script, tests/ is on the path and the repository is not (examples/ is not an
# installed package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bestofn_swarm.link.core import codec
from bestofn_swarm.wire import auth, batch, keyspace, names, numeric, protocol
from bestofn_swarm.wire.endings import Ending, Stop, TimeLimit
from bestofn_swarm.wire.keyspace import Part
from bestofn_swarm.wire.rng import Stream, seed_of
from examples.udp_radio import MAX_RADIO_PAYLOAD_BYTES, encode_frame

VECTORS = Path(__file__).resolve().parent / "vectors"

# Categories of invalid vectors (the fault each one has).
WRONG_VERSION = "wrong_version"
NAN_TOKEN = "nan_token"  # NaN / Infinity are not JSON
NUMBER_OVERFLOW = "number_overflow"  # a literal beyond the range of a double
OUT_OF_RANGE = "out_of_range"
WRONG_LENGTH = "wrong_length"
UNKNOWN_FIELD = "unknown_field"
MISSING_FIELD = "missing_field"
WRONG_TYPE = "wrong_type"
BAD_ENUM = "bad_enum"
BAD_NAME = "bad_name"
OPINION_SUM = "opinion_sum"
MALFORMED_JSON = "malformed_json"
BAD_FRAME = "bad_frame"


def worst_case_opinion(n: int = 100) -> list[float]:
    """The longest opinion over n sites on the wire: n - 1 distinct values of 9 significant
    digits in [1e-5, 1e-4) (15 characters each, the most any value in [0, 1] takes) and
    one value near 1 that makes the sum 1."""
    small = [float(f"{1.00000001e-5 + index * 7.13e-7:.9g}") for index in range(n - 1)]
    return [*small, float(f"{1.0 - math.fsum(small):.9g}")]


@dataclass
class TypeVectors:
    """The vectors of one message type, built from its canonical examples."""

    file: str
    kind: Any  # the msgspec type to decode as
    decoder: str = "message"
    valid: list[dict[str, Any]] = field(default_factory=list)
    accepted: list[dict[str, Any]] = field(default_factory=list)
    invalid: list[dict[str, Any]] = field(default_factory=list)

    def add_valid(self, name: str, message: msgspec.Struct, note: str = "") -> bytes:
        data = protocol.encode(message)
        entry = {"name": name, "message": json.loads(data), **_spelled(data)}
        if note:
            entry["note"] = note
        self.valid.append(entry)
        return data

    def add_accepted(self, name: str, data: bytes, canonical: bytes) -> None:
        self.accepted.append({"name": name, **_spelled(data), "canonical_hex": canonical.hex()})

    def add_invalid(
        self, name: str, category: str, reason: str, data: bytes, at: str | None = None
    ) -> None:
        """``at``: where the fault is (a JSONPath such as ``$.prox[8]``), when it has a place."""
        entry: dict[str, Any] = {"name": name, "category": category, "reason": reason}
        if at is not None:
            entry["at"] = at
        self.invalid.append({**entry, **_spelled(data)})

    def content(self) -> dict[str, Any]:
        return {
            "type": self.kind.__name__,
            "decoder": self.decoder,
            "protocol_version": protocol.VERSION,
            "valid": self.valid,
            "accepted": self.accepted,
            "invalid": self.invalid,
        }


def _spelled(data: bytes) -> dict[str, Any]:
    try:
        text: str | None = data.decode("utf-8")
    except UnicodeDecodeError:
        text = None  # the hex is the vector; there is no UTF-8 spelling
    return {"utf8": text, "hex": data.hex()}


def changed(data: bytes, old: bytes, new: bytes) -> bytes:
    """``data`` with its one occurrence of ``old`` replaced by ``new``."""
    if data.count(old) != 1:
        raise ValueError(f"{old!r} occurs {data.count(old)} times in {data!r}")
    return data.replace(old, new)


def common_faults(vectors: TypeVectors, data: bytes, drop: bytes, at_drop: str) -> None:
    """The faults every message can have: another version, an unknown field, a missing one.

    ``drop`` is the run of ``data`` to remove: a field, its value and one comma.
    """
    vectors.add_invalid(
        "wrong_version",
        WRONG_VERSION,
        "v is 2; this is protocol version 1",
        changed(data, b'"v":1', b'"v":2'),
        at="$.v",
    )
    vectors.add_invalid(
        "unknown_field",
        UNKNOWN_FIELD,
        "a field the message does not define",
        data[:-1] + b',"extra":0}',
    )
    vectors.add_invalid(
        "missing_field",
        MISSING_FIELD,
        f"required field {at_drop} left out",
        changed(data, drop, b""),
    )


# --- per message type ------------------------------------------------------------------


def sense_vectors() -> TypeVectors:
    vectors = TypeVectors("sense.json", protocol.Sense)
    data = vectors.add_valid(
        "typical",
        protocol.Sense(
            v=1,
            tick=42,
            t=4.2,
            x=0.31,
            y=-0.12,
            theta=1.5708,
            prox=[0.0, 0.0, 0.0, 0.000015, 1.5e-6, 0.0, 0.25, 1.0],
            rx=2,
            camera=True,
        ),
        note="0.000015 and 1.5e-6: plain decimals from 1e-5 up, exponent form below",
    )
    vectors.add_accepted(
        "whitespace_and_field_order",
        b'{ "camera": true, "rx": 2,\n  "prox": [0, 0, 0, 1.5E-5, 0.0000015, 0, 0.25, 1],\n'
        b'  "theta": 1.5708, "y": -0.12, "x": 0.31, "t": 4.2, "tick": 42, "v": 1 }\n',
        data,
    )
    common_faults(vectors, data, b'"tick":42,', "tick")
    vectors.add_invalid(
        "nan_token", NAN_TOKEN, "NaN is not JSON", changed(data, b'"x":0.31', b'"x":NaN')
    )
    vectors.add_invalid(
        "infinity_token",
        NAN_TOKEN,
        "Infinity is not JSON",
        changed(data, b'"y":-0.12', b'"y":-Infinity'),
    )
    vectors.add_invalid(
        "number_overflow",
        NUMBER_OVERFLOW,
        "1e999 overflows a double",
        changed(data, b'"theta":1.5708', b'"theta":1e999'),
    )
    vectors.add_invalid(
        "proximity_above_1",
        OUT_OF_RANGE,
        "proximity readings are in [0, 1]",
        changed(data, b"0.25,1.0]", b"0.25,1.5]"),
        at="$.prox[7]",
    )
    vectors.add_invalid(
        "negative_tick",
        OUT_OF_RANGE,
        "ticks are non-negative",
        changed(data, b'"tick":42', b'"tick":-1'),
        at="$.tick",
    )
    vectors.add_invalid(
        "seven_proximity_readings",
        WRONG_LENGTH,
        "prox has exactly 8 readings",
        changed(data, b"[0.0,0.0,0.0,", b"[0.0,0.0,"),
        at="$.prox",
    )
    vectors.add_invalid(
        "nine_proximity_readings",
        WRONG_LENGTH,
        "prox has exactly 8 readings",
        changed(data, b"0.25,1.0]", b"0.25,1.0,0.0]"),
        at="$.prox",
    )
    vectors.add_invalid(
        "float_tick",
        WRONG_TYPE,
        "tick is an integer; 42.0 is a float",
        changed(data, b'"tick":42', b'"tick":42.0'),
        at="$.tick",
    )
    vectors.add_invalid(
        "string_for_bool",
        WRONG_TYPE,
        "camera is true or false",
        changed(data, b'"camera":true', b'"camera":"true"'),
        at="$.camera",
    )
    return vectors


def act_vectors() -> TypeVectors:
    vectors = TypeVectors("act.json", protocol.Act)
    data = vectors.add_valid(
        "typical",
        protocol.Act(
            v=1,
            tick=42,
            left=0.13,
            right=-0.065,
            capture=False,
            radio_tx=1,
        ),
    )
    common_faults(vectors, data, b'"capture":false,', "capture")
    vectors.add_invalid(
        "wheel_too_fast",
        OUT_OF_RANGE,
        "wheel speeds are within +-10 m/s",
        changed(data, b'"left":0.13', b'"left":10.5'),
        at="$.left",
    )
    vectors.add_invalid(
        "too_many_transmissions",
        OUT_OF_RANGE,
        "radio_tx is at most 1000",
        changed(data, b'"radio_tx":1', b'"radio_tx":1001'),
        at="$.radio_tx",
    )
    vectors.add_invalid(
        "null_wheel",
        WRONG_TYPE,
        "right is a number, never null",
        changed(data, b'"right":-0.065', b'"right":null'),
        at="$.right",
    )
    return vectors


def ack_vectors() -> TypeVectors:
    vectors = TypeVectors("ack.json", protocol.Ack)
    data = vectors.add_valid("typical", protocol.Ack(v=1, tick=42, radio_tx=1))
    vectors.add_valid(
        "next_tick",
        protocol.Ack(v=1, tick=45, radio_tx=1, rejected=2, next_tick=50),
        note="the beacon answers tick 50 next: the world skips it on ticks 46-49",
    )
    common_faults(vectors, data, b'"tick":42,', "tick")
    vectors.add_invalid(
        "negative_transmissions",
        OUT_OF_RANGE,
        "radio_tx is non-negative",
        changed(data, b'"radio_tx":1', b'"radio_tx":-1'),
        at="$.radio_tx",
    )
    vectors.add_invalid(
        "invalid_utf8_in_key",
        MALFORMED_JSON,
        "text is UTF-8; 0xff never is",
        changed(data, b'"tick"', b'"tick\xff"'),
    )
    return vectors


def link_stats_vectors() -> TypeVectors:
    vectors = TypeVectors("link_stats.json", protocol.LinkStats)
    data = vectors.add_valid("typical", LINK_STATS)
    vectors.add_valid(
        "never_connected",
        protocol.LinkStats(
            v=1,
            robot=9,
            transport="serial",
            address="serial:/dev/ttyUSB0@921600",
            connected=False,
            sessions=0,
            rtt_ms=None,
            rtt_p95_ms=None,
            pings=0,
            loss=0.0,
            frames_in=0,
            frames_out=0,
            bytes_in=0,
            bytes_out=0,
            impaired=0,
            refused=protocol.LinkRefusals(),
        ),
    )
    common_faults(vectors, data, b'"sessions":1,', "sessions")
    vectors.add_invalid(
        "loss_above_one",
        OUT_OF_RANGE,
        "loss is a share of the pings, in [0, 1]",
        changed(data, b'"loss":0.05', b'"loss":1.5'),
        at="$.loss",
    )
    vectors.add_invalid(
        "unknown_transport",
        BAD_ENUM,
        "a link is udp or serial",
        changed(data, b'"transport":"udp"', b'"transport":"tcp"'),
        at="$.transport",
    )
    return vectors


def pace_vectors() -> TypeVectors:
    vectors = TypeVectors("pace.json", protocol.Pace)
    data = vectors.add_valid("playing", protocol.Pace(v=1, playing=True, speed=4.0))
    vectors.add_valid(
        "paused",
        protocol.Pace(v=1, playing=False),
        note="speed null: as fast as the swarm answers (lockstep), or the world's --speed",
    )
    common_faults(vectors, data, b'"playing":true,', "playing")
    vectors.add_invalid(
        "speed_zero",
        OUT_OF_RANGE,
        "a speed is above 0 sim seconds a wall second",
        changed(data, b'"speed":4.0', b'"speed":0.0'),
        at="$.speed",
    )
    vectors.add_invalid(
        "speed_too_high",
        OUT_OF_RANGE,
        f"a speed is at most {protocol.MAX_PACE_SPEED:g} sim seconds a wall second",
        changed(data, b'"speed":4.0', b'"speed":1000.5'),
        at="$.speed",
    )
    vectors.add_invalid(
        "playing_as_number",
        WRONG_TYPE,
        "playing is true or false, never a number",
        changed(data, b'"playing":true', b'"playing":1'),
        at="$.playing",
    )
    return vectors


RUN_ENDING = protocol.RunEnding(
    v=1,
    run="seed0",
    ended=Ending.CONSENSUS,
    code=0,
    stop=Stop.DECIDED,
    timeout_kind=None,
    tick=1117,
    t=111.7,
    signal=None,
    lost=[],
    summary={
        "run_id": "seed0",
        "ended": "consensus",
        "chosen_site": 3,
        "digest": "063adecf824bce0b",
    },
)


def run_ending_vectors() -> TypeVectors:
    vectors = TypeVectors("run_ending.json", protocol.RunEnding)
    data = vectors.add_valid("consensus", RUN_ENDING)
    vectors.add_valid(
        "lost_beacon",
        protocol.RunEnding(
            v=1,
            run="seed0",
            ended=Ending.CRASHED,
            code=1,
            stop=Stop.CRASHED,
            timeout_kind=None,
            tick=412,
            t=41.2,
            signal=None,
            lost=["nest"],
            summary={"run_id": "seed0", "ended": "crashed"},
        ),
        note="the beacon's liveliness went: the world ends the run crashed at once",
    )
    vectors.add_valid(
        "sim_timeout",
        protocol.RunEnding(
            v=1,
            run="seed0",
            ended=Ending.TIMEOUT,
            code=5,
            stop=Stop.TIMEOUT,
            timeout_kind=TimeLimit.SIM,
            tick=6000,
            t=600.0,
            signal=None,
            lost=["7"],
            summary={"run_id": "seed0", "ended": "timeout", "timeout_kind": "sim"},
        ),
    )
    common_faults(vectors, data, b'"code":0,', "code")
    vectors.add_invalid(
        "unknown_ending",
        BAD_ENUM,
        "ended names one of the endings (docs/running.md)",
        changed(data, b'"ended":"consensus","code"', b'"ended":"won","code"'),
        at="$.ended",
    )
    vectors.add_invalid(
        "code_above_255",
        OUT_OF_RANGE,
        "an exit code is 0 to 255",
        changed(data, b'"code":0', b'"code":256'),
        at="$.code",
    )
    vectors.add_invalid(
        "lost_bad_name",
        BAD_NAME,
        "a lost robot or beacon is named as on its keys",
        changed(data, b'"lost":[]', b'"lost":["a/b"]'),
        at="$.lost[0]",
    )
    vectors.add_invalid(
        "summary_not_an_object",
        WRONG_TYPE,
        "summary is a JSON object",
        changed(data, data[data.index(b'"summary":') : -1], b'"summary":[]'),
        at="$.summary",
    )
    return vectors


TAG_A = "00112233445566778899aabbccddeeff"
TAG_B = "ffeeddccbbaa99887766554433221100"


def ending_seals_vectors() -> TypeVectors:
    vectors = TypeVectors("ending_seals.json", protocol.EndingSeals)
    data = vectors.add_valid(
        "keyed", protocol.EndingSeals(v=1, robots=[TAG_A, TAG_B], bridge=TAG_A)
    )
    vectors.add_valid(
        "unkeyed",
        protocol.EndingSeals(v=1, robots=[], bridge=None),
        note="an unkeyed run: no tags",
    )
    common_faults(vectors, data, f'"robots":["{TAG_A}","{TAG_B}"],'.encode(), "robots")
    vectors.add_invalid(
        "short_tag",
        WRONG_LENGTH,
        "a tag is 16 bytes: 32 lowercase hex digits",
        changed(data, f'"bridge":"{TAG_A}"'.encode(), f'"bridge":"{TAG_A[:30]}"'.encode()),
        at="$.bridge",
    )
    return vectors


LINK_STATS = protocol.LinkStats(
    v=1,
    robot=8,
    transport="udp",
    address="udp://127.0.0.1:47800",
    connected=True,
    sessions=1,
    rtt_ms=0.85,
    rtt_p95_ms=2.1,
    pings=120,
    loss=0.05,
    frames_in=4012,
    frames_out=4410,
    bytes_in=612000,
    bytes_out=1840000,
    impaired=0,
    refused=protocol.LinkRefusals(forged=2, replayed=1),
)


def join_reply_vectors() -> TypeVectors:
    vectors = TypeVectors("join_reply.json", protocol.JoinReply)
    data = vectors.add_valid("typical", protocol.JoinReply(v=1, id=7))
    common_faults(vectors, data, b',"id":7', "id")
    vectors.add_invalid(
        "negative_id",
        OUT_OF_RANGE,
        "robot ids are non-negative",
        changed(data, b'"id":7', b'"id":-7'),
        at="$.id",
    )
    return vectors


def clock_vectors() -> TypeVectors:
    vectors = TypeVectors("clock.json", protocol.Clock)
    data = vectors.add_valid(
        "typical",
        protocol.Clock(v=1, tick=3, t=0.30000000000000004),
        note="a sum of 0.1 s ticks: the shortest round-trip text has 17 digits",
    )
    vectors.add_valid("start", protocol.Clock(v=1, tick=0, t=0.0))
    vectors.add_accepted(
        "integer_for_float",
        b'{"v":1,"tick":7,"t":1}',
        protocol.encode(protocol.Clock(v=1, tick=7, t=1.0)),
    )
    vectors.add_accepted(
        "exponent_form",
        b'{"v":1,"tick":7,"t":12E-1}',
        protocol.encode(protocol.Clock(v=1, tick=7, t=1.2)),
    )
    common_faults(vectors, data, b'"tick":3,', "tick")
    vectors.add_invalid(
        "missing_version", MISSING_FIELD, "every message carries v", changed(data, b'"v":1,', b"")
    )
    vectors.add_invalid(
        "float_version",
        WRONG_TYPE,
        "v is the integer 1",
        changed(data, b'"v":1', b'"v":1.0'),
        at="$.v",
    )
    vectors.add_invalid(
        "negative_time",
        OUT_OF_RANGE,
        "sim time is non-negative",
        changed(data, b'"t":0.30000000000000004', b'"t":-0.1'),
        at="$.t",
    )
    vectors.add_invalid("empty", MALFORMED_JSON, "no bytes at all", b"")
    vectors.add_invalid("truncated", MALFORMED_JSON, "the object never closes", data[:-1])
    vectors.add_invalid(
        "trailing_garbage", MALFORMED_JSON, "bytes after the JSON value", data + b"x"
    )
    vectors.add_invalid(
        "top_level_array", WRONG_TYPE, "a message is a JSON object", b"[1,3,0.30000000000000004]"
    )
    vectors.add_invalid(
        "single_quotes",
        MALFORMED_JSON,
        "JSON strings use double quotes",
        changed(data, b'"tick"', b"'tick'"),
    )
    return vectors


def demo_world_info(sites: list[protocol.Site], seed: int) -> protocol.WorldInfo:
    """Run "demo"'s world: the arena, nest, robot and camera of the defaults."""
    return protocol.WorldInfo(
        v=1,
        run="demo",
        seed=seed,
        dt=0.1,
        arena_radius=0.75,
        nest=protocol.Nest(0.0, 0.0, 0.2),
        sites=sites,
        robot_radius=0.037,
        wheel_base=0.053,
        max_wheel_speed=0.13,
        camera=protocol.CameraSpec(width=64, height=48, fov=0.84),
        clock="lockstep",
    )


def world_info_vectors() -> TypeVectors:
    vectors = TypeVectors("world_info.json", protocol.WorldInfo)
    sites = [
        protocol.Site(
            index,
            0.75 * math.cos(2 * math.pi * index / 3),
            0.75 * math.sin(2 * math.pi * index / 3),
        )
        for index in range(3)
    ]
    data = vectors.add_valid(
        "three_sites",
        demo_world_info(sites, seed=12345678901234567),
        note="site coordinates are full doubles: only opinions are rounded",
    )
    common_faults(vectors, data, b'"dt":0.1,', "dt")
    one_site = json.loads(data)
    one_site["sites"] = one_site["sites"][:1]
    vectors.add_invalid(
        "one_site",
        WRONG_LENGTH,
        "a choice needs at least 2 sites",
        _compact(one_site),
        at="$.sites",
    )
    vectors.add_invalid(
        "bad_clock",
        BAD_ENUM,
        "clock is lockstep or realtime",
        changed(data, b'"lockstep"', b'"fast"'),
        at="$.clock",
    )
    vectors.add_invalid(
        "run_with_slash",
        BAD_NAME,
        "names are letters, digits, '_', '.', '-'",
        changed(data, b'"run":"demo"', b'"run":"de/mo"'),
        at="$.run",
    )
    vectors.add_invalid(
        "nest_unknown_field",
        UNKNOWN_FIELD,
        "nested objects refuse them too",
        changed(data, b'"radius":0.2}', b'"radius":0.2,"z":0.0}'),
        at="$.nest",
    )
    vectors.add_invalid(
        "zero_nest_radius",
        OUT_OF_RANGE,
        "radii are positive",
        changed(data, b'"radius":0.2', b'"radius":0.0'),
        at="$.nest.radius",
    )
    vectors.add_invalid(
        "wide_camera",
        OUT_OF_RANGE,
        "the field of view is below 3.2 rad",
        changed(data, b'"fov":0.84', b'"fov":3.5'),
        at="$.camera.fov",
    )
    return vectors


def world_state_vectors() -> TypeVectors:
    vectors = TypeVectors("world_state.json", protocol.WorldState)
    data = vectors.add_valid(
        "two_robots",
        protocol.WorldState(
            v=1,
            tick=420,
            t=42.0,
            robots=[protocol.Pose(0, 0.31, -0.12, 1.5708), protocol.Pose(1, -0.2, 0.05, -3.1)],
            radio=protocol.RadioCounters(sent=120, delivered=310, dropped=4, rejected=0),
            rejected=0,
            stalls=1,
        ),
        note="a pose is the array [id, x, y, theta]",
    )
    vectors.add_valid(
        "no_robots",
        protocol.WorldState(
            v=1,
            tick=0,
            t=0.0,
            robots=[],
            radio=protocol.RadioCounters(),
            rejected=0,
            stalls=0,
        ),
    )
    common_faults(vectors, data, b',"stalls":1', "stalls")
    vectors.add_invalid(
        "short_pose",
        WRONG_LENGTH,
        "a pose has 4 entries",
        changed(data, b"[1,-0.2,0.05,-3.1]", b"[1,-0.2,0.05]"),
        at="$.robots[1]",
    )
    vectors.add_invalid(
        "pose_as_object",
        WRONG_TYPE,
        "poses are arrays",
        changed(data, b"[0,0.31,-0.12,1.5708]", b'{"id":0,"x":0.31,"y":-0.12,"theta":1.5708}'),
        at="$.robots[0]",
    )
    vectors.add_invalid(
        "robot_id_too_large",
        OUT_OF_RANGE,
        "robot ids are below 100000",
        changed(data, b"[1,-0.2", b"[100000,-0.2"),
        at="$.robots[1][0]",
    )
    return vectors


def status_vectors() -> TypeVectors:
    vectors = TypeVectors("status.json", protocol.Status)
    vectors.add_valid(
        "initial",
        protocol.Status(
            v=1,
            id=0,
            tick=0,
            t=0.0,
            phase="to_site",
            trips=0,
            opinion=[0.25, 0.25, 0.25, 0.25],
            pool_size=0,
            poolings=0,
            decided_site=None,
            decision_time=None,
            decision_trips=None,
            comparison=None,
        ),
    )
    data = vectors.add_valid(
        "decided",
        protocol.Status(
            v=1,
            id=3,
            tick=455,
            t=45.5,
            phase="to_decision",
            trips=3,
            opinion=[0.0, 1.0, 0.0, 0.0],
            pool_size=3,
            poolings=3,
            decided_site=1,
            decision_time=45.5,
            decision_trips=3,
            comparison=protocol.Comparison(0, 0.666666667, 1, 1.0, 0),
            rejected=2,
        ),
    )
    common_faults(vectors, data, b'"poolings":3,', "poolings")
    vectors.add_invalid(
        "bad_phase",
        BAD_ENUM,
        "phase is one of the eight controller phases",
        changed(data, b'"to_decision"', b'"dancing"'),
        at="$.phase",
    )
    vectors.add_invalid(
        "one_option",
        WRONG_LENGTH,
        "an opinion has at least 2 entries",
        changed(data, b"[0.0,1.0,0.0,0.0]", b"[1.0]"),
        at="$.opinion",
    )
    vectors.add_invalid(
        "negative_probability",
        OUT_OF_RANGE,
        "probabilities are in [0, 1]",
        changed(data, b"[0.0,1.0,0.0,0.0]", b"[-0.5,1.5,0.0,0.0]"),
        at="$.opinion[0]",
    )
    vectors.add_invalid(
        "comparison_unknown_field",
        UNKNOWN_FIELD,
        "nested objects refuse them",
        changed(data, b'"eliminated":0}', b'"eliminated":0,"why":"red"}'),
        at="$.comparison",
    )
    return vectors


def camera_meta_vectors() -> TypeVectors:
    vectors = TypeVectors("camera_meta.json", protocol.CameraMeta)
    data = vectors.add_valid(
        "png",
        protocol.CameraMeta(
            v=1,
            tick=43,
            width=64,
            height=48,
            encoding="png",
        ),
    )
    common_faults(vectors, data, b'"height":48,', "height")
    vectors.add_invalid(
        "gif",
        BAD_ENUM,
        "frames are png or jpeg",
        changed(data, b'"png"', b'"gif"'),
        at="$.encoding",
    )
    vectors.add_invalid(
        "zero_width",
        OUT_OF_RANGE,
        "frames are 1..4096 pixels wide",
        changed(data, b'"width":64', b'"width":0'),
        at="$.width",
    )
    return vectors


def radio_tx_meta_vectors() -> TypeVectors:
    vectors = TypeVectors("radio_tx_meta.json", protocol.RadioTxMeta)
    data = vectors.add_valid("typical", protocol.RadioTxMeta(v=1, tick=42, seq=7))
    vectors.add_valid(
        "largest",
        protocol.RadioTxMeta(v=1, tick=2**53, seq=2**53),
        note="the longest attachment: counts go up to 2^53",
    )
    common_faults(vectors, data, b',"seq":7', "seq")
    vectors.add_invalid(
        "count_beyond_2_53",
        OUT_OF_RANGE,
        "counts are at most 2^53",
        changed(data, b'"seq":7', b'"seq":9007199254740993'),
        at="$.seq",
    )
    return vectors


def radio_rx_meta_vectors() -> TypeVectors:
    vectors = TypeVectors("radio_rx_meta.json", protocol.RadioRxMeta)
    data = vectors.add_valid(
        "typical",
        protocol.RadioRxMeta(
            v=1,
            tick=43,
            sender="3",
            seq=7,
            sent_tick=42,
        ),
    )
    common_faults(vectors, data, b',"sent_tick":42', "sent_tick")
    vectors.add_invalid(
        "sender_with_space",
        BAD_NAME,
        "names are letters, digits, '_.-'",
        changed(data, b'"sender":"3"', b'"sender":"robot 3"'),
        at="$.sender",
    )
    vectors.add_invalid(
        "sender_too_long",
        BAD_NAME,
        "names are at most 64 characters",
        changed(data, b'"sender":"3"', b'"sender":"' + b"a" * 65 + b'"'),
        at="$.sender",
    )
    vectors.add_invalid(
        "empty_sender",
        BAD_NAME,
        "names are not empty",
        changed(data, b'"sender":"3"', b'"sender":""'),
        at="$.sender",
    )
    return vectors


def log_line_vectors() -> TypeVectors:
    vectors = TypeVectors("log_line.json", protocol.LogLine)
    data = vectors.add_valid(
        "escapes",
        protocol.LogLine(
            v=1,
            process="robot-3",
            wall_time=1795000000.5,
            line='said "hi"\tto the nest — naïve\\ok \x01',
        ),
        note="UTF-8 stays as is; quote, backslash and control characters are escaped",
    )
    common_faults(vectors, data, b'"wall_time":1795000000.5,', "wall_time")
    vectors.add_invalid(
        "line_too_long",
        WRONG_LENGTH,
        "a line is at most 4096 characters",
        _compact({"v": 1, "process": "robot-3", "wall_time": 1.0, "line": "x" * 4097}),
        at="$.line",
    )
    vectors.add_invalid(
        "invalid_utf8",
        MALFORMED_JSON,
        "text is UTF-8; 0xff never is",
        changed(data, b"na\xc3\xafve", b"na\xffve"),
    )
    vectors.add_invalid(
        "raw_control_character",
        MALFORMED_JSON,
        "control characters in strings must be escaped",
        changed(data, b"\\t", b"\t"),
    )
    return vectors


def opinion_vectors() -> TypeVectors:
    vectors = TypeVectors("opinion_payload.json", protocol.OpinionPayload, decoder="radio")
    data = vectors.add_valid(
        "five_sites",
        protocol.OpinionPayload(
            v=1,
            id=3,
            trip=2,
            decided=False,
            opinion=[0.0, 0.333333333, 0.333333333, 0.0, 0.333333333],
        ),
        note="9 significant digits: protocol.wire_opinion",
    )
    vectors.add_valid(
        "decided",
        protocol.OpinionPayload(
            v=1,
            id=12,
            trip=5,
            decided=True,
            opinion=[0.0, 1.0],
        ),
    )
    vectors.add_valid(
        "tiny_values",
        protocol.OpinionPayload(
            v=1,
            id=4,
            trip=1,
            decided=False,
            opinion=protocol.wire_opinion([0.99998485, 0.000015, 1.5e-7, 1.23456789e-100]),
        ),
        note="below 1e-5 a value takes the exponent form: 1.5e-7, not 1.5e-07",
    )
    worst = worst_case_opinion()
    worst_data = vectors.add_valid(
        "worst_case_n100",
        protocol.OpinionPayload(
            v=1,
            id=names.MAX_ROBOTS - 1,
            trip=2**53,
            decided=False,
            opinion=worst,
        ),
        note="the longest opinion over 100 sites",
    )
    assert len(worst_data) <= MAX_RADIO_PAYLOAD_BYTES
    vectors.add_accepted(
        "kind_last",
        (
            b'{"v":1,"id":3,"trip":2,"decided":false,'
            b'"opinion":[0,0.333333333,0.333333333,0,0.333333333],"kind":"opinion"}'
        ),
        data,
    )
    common_faults(vectors, data, b'"trip":2,', "trip")
    vectors.add_invalid(
        "no_kind",
        MISSING_FIELD,
        "kind tells the two payloads apart",
        changed(data, b'"kind":"opinion",', b""),
    )
    vectors.add_invalid(
        "unknown_kind",
        BAD_ENUM,
        "kind is opinion, beacon or vote",
        changed(data, b'"kind":"opinion"', b'"kind":"rumour"'),
        at="$.kind",
    )
    vectors.add_invalid(
        "sum_below_1",
        OPINION_SUM,
        "an opinion sums to 1 (within 1e-6)",
        changed(data, b",0.333333333]", b",0.3]"),
    )
    vectors.add_invalid(
        "sum_above_1",
        OPINION_SUM,
        "an opinion sums to 1 (within 1e-6)",
        changed(data, b"[0.0,", b"[0.1,"),
    )
    vectors.add_invalid(
        "negative_value",
        OUT_OF_RANGE,
        "probabilities are in [0, 1]",
        changed(data, b"[0.0,0.333333333", b"[-1.0,1.333333333"),
        at="$.opinion[0]",
    )
    vectors.add_invalid(
        "nan_value", NAN_TOKEN, "NaN is not JSON", changed(data, b"[0.0,", b"[NaN,")
    )
    vectors.add_invalid(
        "single_option",
        WRONG_LENGTH,
        "an opinion has at least 2 entries",
        _compact({**json.loads(data), "opinion": [1.0]}),
        at="$.opinion",
    )
    too_many = [0.0] * protocol.MAX_OPTIONS + [1.0]
    vectors.add_invalid(
        "too_many_options",
        WRONG_LENGTH,
        f"an opinion has at most {protocol.MAX_OPTIONS} entries",
        _compact({**json.loads(data), "opinion": too_many}),
        at="$.opinion",
    )
    vectors.add_invalid(
        "id_as_string",
        WRONG_TYPE,
        "a robot id is an integer",
        changed(data, b'"id":3', b'"id":"3"'),
        at="$.id",
    )
    return vectors


def vote_vectors() -> TypeVectors:
    vectors = TypeVectors("vote_payload.json", protocol.VotePayload, decoder="radio")
    data = vectors.add_valid(
        "typical",
        protocol.VotePayload(v=1, id=3, trip=2, decided=False, site=4, quality=0.75),
        note="--strategy dmvd, dmmd or dc: the site a robot favours and its quality estimate",
    )
    vectors.add_valid(
        "decided",
        protocol.VotePayload(v=1, id=12, trip=7, decided=True, site=0, quality=1.0),
    )
    vectors.add_accepted(
        "kind_last",
        b'{"v":1,"id":3,"trip":2,"decided":false,"site":4,"quality":0.75,"kind":"vote"}',
        data,
    )
    common_faults(vectors, data, b',"quality":0.75', "quality")
    vectors.add_invalid(
        "quality_above_1",
        OUT_OF_RANGE,
        "a quality is in [0, 1]",
        changed(data, b'"quality":0.75', b'"quality":1.5'),
        at="$.quality",
    )
    vectors.add_invalid(
        "negative_site",
        OUT_OF_RANGE,
        "a site id is non-negative",
        changed(data, b'"site":4', b'"site":-1'),
        at="$.site",
    )
    vectors.add_invalid(
        "site_too_large",
        OUT_OF_RANGE,
        f"a site id is below {protocol.MAX_OPTIONS}",
        changed(data, b'"site":4', f'"site":{protocol.MAX_OPTIONS}'.encode()),
        at="$.site",
    )
    vectors.add_invalid(
        "opinion_in_a_vote",
        UNKNOWN_FIELD,
        "a vote has a site, not an opinion",
        changed(data, b'"site":4', b'"opinion":[0.5,0.5]'),
    )
    return vectors


def beacon_vectors() -> TypeVectors:
    vectors = TypeVectors("beacon_payload.json", protocol.BeaconPayload, decoder="radio")
    data = vectors.add_valid("typical", protocol.BeaconPayload(v=1, id="nest", seq=12))
    common_faults(vectors, data, b',"seq":12', "seq")
    vectors.add_invalid(
        "empty_name",
        BAD_NAME,
        "the beacon has a name",
        changed(data, b'"id":"nest"', b'"id":""'),
        at="$.id",
    )
    vectors.add_invalid(
        "negative_seq",
        OUT_OF_RANGE,
        "seq is non-negative",
        changed(data, b'"seq":12', b'"seq":-12'),
        at="$.seq",
    )
    vectors.add_invalid(
        "invalid_utf8",
        MALFORMED_JSON,
        "text is UTF-8; 0xff never is",
        changed(data, b'"nest"', b'"n\xffst"'),
    )
    return vectors


def udp_frame_vectors() -> dict[str, Any]:
    """Frames of the UDP radio: header, sender, payload (docs/porting.md)."""
    opinion = protocol.encode(
        protocol.OpinionPayload(
            v=1,
            id=3,
            trip=2,
            decided=False,
            opinion=[0.5, 0.5],
        )
    )
    beacon = protocol.encode(protocol.BeaconPayload(v=1, id="nest", seq=12))
    worst = protocol.encode(
        protocol.OpinionPayload(
            v=1,
            id=names.MAX_ROBOTS - 1,
            trip=2**53,
            decided=False,
            opinion=worst_case_opinion(),
        )
    )
    valid = [
        {
            "name": name,
            "sender": sender,
            "payload_utf8": payload.decode(),
            "hex": encode_frame(sender, payload).hex(),
        }
        for name, sender, payload in (
            ("opinion", "3", opinion),
            ("beacon", "nest", beacon),
            ("worst_case_n100", str(names.MAX_ROBOTS - 1), worst),
        )
    ]
    good = encode_frame("3", opinion)
    bad: list[tuple[str, str, bytes]] = [
        ("shorter_than_header", "a frame has a 4-byte header", b"BN\x01"),
        ("bad_magic", "a frame starts with 'BN'", b"XY" + good[2:]),
        ("unknown_version", "the frame version is 1", good[:2] + b"\x02" + good[3:]),
        ("empty_sender", "the sender length is 1..64", b"BN\x01\x00" + opinion),
        ("sender_past_the_end", "the sender length runs past the datagram", b"BN\x01\x09nest"),
        (
            "sender_with_space",
            "sender names are letters, digits, '_.-'",
            b"BN\x01\x03a b" + opinion,
        ),
        ("sender_too_long", "the sender length is at most 64", b"BN\x01\x41" + b"a" * 65 + opinion),
        ("empty_payload", "a frame carries a payload", b"BN\x01\x013"),
        (
            "payload_too_long",
            f"payloads are at most {MAX_RADIO_PAYLOAD_BYTES} bytes",
            b"BN\x01\x013" + b" " * (MAX_RADIO_PAYLOAD_BYTES + 1),
        ),
    ]
    return {
        "type": "UdpFrame",
        "decoder": "udp_frame",
        "frame_version": 1,
        "valid": valid,
        "invalid": [
            {"name": name, "category": BAD_FRAME, "reason": reason, "hex": data.hex()}
            for name, reason, data in bad
        ],
    }


AUTH_SECRET = bytes(range(32))  # 00 01 02 ... 1f: a test secret, never a real one


def auth_vectors() -> dict[str, Any]:
    """Run keys derived from a fixed secret, and tags of typical messages (docs/protocol.md)."""
    keyring = auth.Keyring(secret=AUTH_SECRET)
    sense = protocol.encode(
        protocol.Sense(
            v=1, tick=42, t=4.2, x=0.31, y=-0.12, theta=1.5708, prox=[0.0] * 8, rx=0, camera=False
        )
    )
    rx_meta = protocol.encode(protocol.RadioRxMeta(v=1, tick=43, sender="3", seq=7, sent_tick=42))
    opinion = protocol.encode(
        protocol.OpinionPayload(v=1, id=3, trip=2, decided=False, opinion=[0.5, 0.5])
    )
    clock = protocol.encode(protocol.Clock(v=1, tick=42, t=4.2))
    cases = [
        ("sense_to_robot_3", "robot/3", "bestofn/demo/robot/3/sense", b"", sense),
        ("radio_rx_to_robot_5", "robot/5", "bestofn/demo/radio/rx/5", rx_meta, opinion),
        ("world_clock", "world", "bestofn/demo/world/clock", b"", clock),
    ]
    tags = []
    for name, identity, key_expr, metadata, payload in cases:
        key = keyring.key(identity)
        assert key is not None
        framed = b"".join(
            len(part).to_bytes(4, "big") + part for part in (key_expr.encode(), metadata, payload)
        )
        tags.append(
            {
                "name": name,
                "identity": identity,
                "key_expr": key_expr,
                "metadata_utf8": metadata.decode(),
                "payload_utf8": payload.decode(),
                "framed_hex": framed.hex(),
                "tag_hex": auth.tag(key, key_expr, metadata, payload).hex(),
                "attachment_hex": keyring.seal(identity, key_expr, payload, metadata).hex(),
            }
        )
    return {
        "type": "RunKeys",
        "decoder": "auth",
        "secret_hex": AUTH_SECRET.hex(),
        "key_label_utf8": auth.KEY_LABEL.decode(),
        "tag_bytes": auth.TAG_BYTES,
        "keys": [
            {"identity": identity, "key_hex": (keyring.key(identity) or b"").hex()}
            for identity in ("world", "robot/3", "robot/5", "beacon/nest", "launcher", "recorder")
        ],
        "tags": tags,
    }


def batch_vectors() -> dict[str, Any]:
    """Batches of a process hosting robots 3 to 4 (bestofn_swarm/wire/batch.py), byte for byte: what
    each decodes to (the robots' own messages), the host's tag over it, and bytes to refuse."""
    keyring = auth.Keyring(secret=AUTH_SECRET)
    identity = names.host_identity(3, 4)
    senses = [
        protocol.Sense(
            v=1,
            tick=42,
            t=4.2,
            x=0.31,
            y=-0.12,
            theta=1.5708,
            prox=[0.0, 0.0, 0.0, 0.000015, 1.5e-6, 0.0, 0.25, 1.0],
            rx=2,
            camera=True,
        ),
        protocol.Sense(
            v=1, tick=42, t=4.2, x=-0.5, y=0.25, theta=-3.0, prox=[0.0] * 8, rx=0, camera=False
        ),
    ]
    sense_batch = batch.encode_senses(
        4,
        tick=42,
        t=4.2,
        robots=[3, 4],
        values=[[sense.x, sense.y, sense.theta, *sense.prox] for sense in senses],
        rx=[sense.rx for sense in senses],
        camera=[sense.camera for sense in senses],
    )
    acts = [
        (3, protocol.Act(v=1, tick=42, left=0.13, right=-0.065, capture=False, radio_tx=1)),
        (4, protocol.Act(v=1, tick=42, left=0.0, right=0.0, capture=True, radio_tx=0)),
    ]
    act_batch = batch.encode_acts(4, acts)
    valid = []
    for name, kind, data, messages in (
        ("senses", "senses", sense_batch, list(zip([3, 4], senses, strict=True))),
        ("acts", "acts", act_batch, acts),
    ):
        key_expr = f"bestofn/demo/host/3/{'sense' if kind == 'senses' else 'act'}"
        valid.append(
            {
                "name": name,
                "kind": kind,
                "hex": data.hex(),
                "last": 4,
                "entries": [
                    {"robot": robot, "message": json.loads(protocol.encode(message))}
                    for robot, message in messages
                ],
                "identity": identity,
                "key_expr": key_expr,
                "tag_hex": keyring.seal(identity, key_expr, data).hex(),
            }
        )
    one_sense = batch.encode_senses(
        4, tick=1, t=0.1, robots=[3], values=[[0.0] * 11], rx=[0], camera=[False]
    )
    one_act = batch.encode_acts(4, acts[:1])

    def with_value(index: int, value: float) -> bytes:
        offset = 28 + 8 * index
        return one_sense[:offset] + struct.pack("<d", value) + one_sense[offset + 8 :]

    invalid = [
        ("senses", "wrong_magic", "a batch of senses starts with BNS1", b"BNA1" + one_sense[4:]),
        ("senses", "cut_short", "one byte of the last row missing", one_sense[:-1]),
        ("senses", "left_over", "a byte after the last row", one_sense + b"\x00"),
        ("senses", "nan_x", "NaN is no coordinate", with_value(0, math.nan)),
        ("senses", "infinite_theta", "an angle is finite", with_value(2, math.inf)),
        ("senses", "proximity_above_1", "proximity readings are in [0, 1]", with_value(10, 1.5)),
        (
            "senses",
            "camera_2",
            "the camera flag is 0 or 1",
            one_sense[:-1] + b"\x02",
        ),
        (
            "senses",
            "robot_twice",
            "each robot once",
            batch.encode_senses(
                4,
                tick=1,
                t=0.1,
                robots=[3, 3],
                values=[[0.0] * 11] * 2,
                rx=[0, 0],
                camera=[False, False],
            ),
        ),
        ("acts", "wrong_magic", "a batch of acts starts with BNA1", b"BNS1" + one_act[4:]),
        ("acts", "cut_short", "one byte of the row missing", one_act[:-1]),
        (
            "acts",
            "wheel_too_fast",
            "wheel speeds are within +-10 m/s",
            one_act[:24] + struct.pack("<d", 10.5) + one_act[32:],
        ),
        ("acts", "capture_2", "the capture flag is 0 or 1", one_act[:-3] + b"\x02" + one_act[-2:]),
        (
            "acts",
            "too_many_transmissions",
            "radio_tx is at most 1000",
            one_act[:-2] + struct.pack("<H", 1001),
        ),
    ]
    return {
        "type": "Batch",
        "decoder": "batch",
        "secret_hex": AUTH_SECRET.hex(),
        "valid": valid,
        "invalid": [
            {"name": name, "kind": kind, "reason": reason, "hex": data.hex()}
            for kind, name, reason, data in invalid
        ],
    }


LINK_ROBOT = 8
LINK_ROBOT_NONCE = bytes.fromhex("0102030405060708")
LINK_BRIDGE_NONCE = bytes.fromhex("1112131415161718")
LINK_OTHER_NONCE = bytes.fromhex("2122232425262728")  # another session's (robot or bridge)
LINK_MAP_NONCE = bytes(range(0x30, 0x40))  # the query nonce of the question for the map
LINK_PROOF_NONCE = bytes(range(0x40, 0x50))  # the query nonce of a world token's proof
LINK_WORLD = "8d2f5e4a1b3c6d7e"  # a world server's instance (its Zenoh id), as WORLD_UP says
# What a receiver of an invalid frame or of a sequence is, before the frame arrives. Each
# frame of ``invalid`` goes to a fresh receiver in its ``session``; the counter it adds one
# to is the vector's ``refusal`` for that end.
LINK_RECEIVERS = {
    "robot": (
        "robot 8's program (bestofn_swarm/link/core/session.py LinkClient): it said hello with "
        "robot_nonce_hex and took the vector 'welcome' (session 'plain') or "
        "'welcome_encrypted' (session 'encrypted'), and no frame of the bridge since; in "
        "session 'hello' it said hello and took nothing yet"
    ),
    "bridge": (
        "the bridge's end of robot 8 (world_server/bridge/core/peer.py LinkPeer), serving the "
        "welcome of the vector 'welcome' (session 'plain') or 'welcome_encrypted' (session "
        "'encrypted') with the bridge nonce bridge_nonce_hex: it answered the vector "
        "'hello' and took 'ping_from_the_robot' (or 'ping_from_the_robot_encrypted'), so "
        "the session is open and the robot's sequence number 1 is taken"
    ),
}


def _link_world_info() -> bytes:
    """The WorldInfo the world answers with (docs/protocol.md's example)."""
    sites = [
        protocol.Site(0, 0.75, 0.0),
        protocol.Site(1, -0.375, 0.649519053),
        protocol.Site(2, -0.375, -0.649519053),
    ]
    return protocol.encode(demo_world_info(sites, seed=0))


def link_frame_vectors() -> dict[str, Any]:
    """Frames of the link to a robot outside the emulator (bestofn_swarm/link/core/codec.py,
    docs/protocol.md): the keys, a session's frames both ways (plain and encrypted, the questions on
    world/info and their answers), their serial encoding, frames a receiver refuses with the counter
    each end adds it to, and sequences of frames with what a receiver does with each."""
    keyring = auth.Keyring(secret=AUTH_SECRET)
    identity = names.robot_identity(LINK_ROBOT)
    robot_key = keyring.key(identity)
    assert robot_key is not None
    key = codec.link_key(robot_key)
    cipher_key = codec.session_key(key, LINK_ROBOT_NONCE, LINK_BRIDGE_NONCE)
    other_key = codec.link_key(keyring.key(names.robot_identity(9)) or b"")
    keys = keyspace.Keys("demo")
    act = protocol.encode(
        protocol.Act(v=1, tick=42, left=0.13, right=0.1, capture=False, radio_tx=0)
    )
    act_tag = keyring.seal(identity, keys.of(keyspace.ACT, LINK_ROBOT), act)
    sense = protocol.encode(
        protocol.Sense(
            v=1, tick=42, t=4.2, x=0.31, y=-0.12, theta=1.5708, prox=[0.0] * 8, rx=0, camera=False
        )
    )
    sense_tag = keyring.seal(identity, keys.of(keyspace.SENSE, LINK_ROBOT), sense)

    def welcome_body(cipher: codec.Cipher) -> bytes:
        return codec.encode_welcome(
            codec.LinkWelcome(
                v=1,
                run="demo",
                root="bestofn",
                cipher=cipher,
                ping_every=0.5,
                silence=3.0,
                controller=msgspec.Raw(b'{"dwell":3.0}'),
            )
        )

    def frame(
        kind: codec.FrameType,
        from_bridge: bool,
        seq: int,
        body: bytes = b"",
        *,
        robot_nonce: bytes = LINK_ROBOT_NONCE,
        bridge_nonce: bytes = LINK_BRIDGE_NONCE,
        encrypted: bool = False,
        robot: int = LINK_ROBOT,
    ) -> codec.Frame:
        return codec.Frame(
            kind, from_bridge, robot, robot_nonce, bridge_nonce, seq, body, encrypted
        )

    def data(kind: keyspace.LinkCode, payload: bytes, attachment: bytes | None = None) -> bytes:
        return codec.encode_data(kind, payload, attachment)

    world_up = keyspace.link(keyspace.ALIVE_WORLD)
    world_down = keyspace.link(keyspace.ALIVE_WORLD, Part.GONE)

    def sealed(item: codec.Frame, with_key: bytes = key) -> bytes:
        cipher = codec.session_key(with_key, item.robot_nonce, item.bridge_nonce)
        return codec.seal(item, with_key, cipher if item.encrypted else None)

    # The questions on world/info (kind 19) and the world's answers (kind 4): a query's
    # attachment is tag || nonce || identity, its answer's tag || nonce, both tags under
    # the robot's run key (bestofn_swarm/wire/auth.py query_seal, reply_seal).
    world_info = _link_world_info()
    instance = LINK_WORLD.encode()
    questions = {
        "map": (b"", LINK_MAP_NONCE),
        "proof": (instance, LINK_PROOF_NONCE),
    }
    query: dict[str, dict[str, Any]] = {}
    for purpose, (payload, nonce) in questions.items():
        asked = auth.query_seal(keyring, identity, keys.of(keyspace.INFO), payload, nonce)
        answer = auth.reply_seal(keyring, identity, keys.of(keyspace.INFO), world_info, nonce)
        assert asked is not None and answer is not None
        query[purpose] = {
            "question": (payload, asked, nonce),
            "answer": (world_info, answer, nonce),
        }

    def query_vector(purpose: str, part: str) -> dict[str, Any]:
        _, attachment, nonce = query[purpose][part]
        return {
            "key_expr": keys.of(keyspace.INFO),
            "identity": identity,
            "nonce_hex": nonce.hex(),
            "metadata_hex": attachment[auth.TAG_BYTES :].hex(),
            "tag_hex": attachment[: auth.TAG_BYTES].hex(),
        }

    act_body = data(keyspace.link(keyspace.ACT), act, act_tag)
    sense_body = data(keyspace.link(keyspace.SENSE), sense, sense_tag)
    map_question = data(keyspace.link(keyspace.INFO), *query["map"]["question"][:2])
    map_answer = data(keyspace.link(keyspace.INFO, Part.REPLY), *query["map"]["answer"][:2])
    proof_question = data(keyspace.link(keyspace.INFO), *query["proof"]["question"][:2])
    proof_answer = data(keyspace.link(keyspace.INFO, Part.REPLY), *query["proof"]["answer"][:2])
    ping_one = (1).to_bytes(8, "big")
    run_ended = bytes((codec.ByeReason.RUN_ENDED,))
    cases: list[tuple[str, codec.Frame, dict[str, Any] | None]] = [
        ("hello", frame(codec.FrameType.HELLO, False, 0, bridge_nonce=codec.NO_NONCE), None),
        ("welcome", frame(codec.FrameType.WELCOME, True, 0, welcome_body("none")), None),
        (
            "welcome_encrypted",
            frame(codec.FrameType.WELCOME, True, 0, welcome_body("chacha20-poly1305")),
            None,
        ),
        ("ping_from_the_robot", frame(codec.FrameType.PING, False, 1, bytes(8)), None),
        (
            "ping_from_the_robot_encrypted",
            frame(codec.FrameType.PING, False, 1, bytes(8), encrypted=True),
            None,
        ),
        (
            "world_info_question",
            frame(codec.FrameType.DATA, False, 2, map_question),
            query_vector("map", "question"),
        ),
        (
            "world_info_answer",
            frame(codec.FrameType.DATA, True, 1, map_answer),
            query_vector("map", "answer"),
        ),
        ("act", frame(codec.FrameType.DATA, False, 2, act_body), None),
        ("sense", frame(codec.FrameType.DATA, True, 1, sense_body), None),
        ("sense_encrypted", frame(codec.FrameType.DATA, True, 1, sense_body, encrypted=True), None),
        ("ping_from_the_bridge", frame(codec.FrameType.PING, True, 2, ping_one), None),
        ("pong", frame(codec.FrameType.PONG, False, 3, ping_one), None),
        (
            "world_up",
            frame(codec.FrameType.DATA, True, 2, data(world_up, instance)),
            None,
        ),
        (
            "world_proof_question",
            frame(codec.FrameType.DATA, False, 4, proof_question),
            query_vector("proof", "question"),
        ),
        (
            "world_proof_answer",
            frame(codec.FrameType.DATA, True, 3, proof_answer),
            query_vector("proof", "answer"),
        ),
        (
            "world_info_error",
            frame(
                codec.FrameType.DATA,
                True,
                3,
                data(keyspace.link(keyspace.INFO, Part.ERROR), b"not this world instance"),
            ),
            None,
        ),
        (
            "world_down",
            frame(codec.FrameType.DATA, True, 4, data(world_down, instance)),
            None,
        ),
        ("bye_run_ended", frame(codec.FrameType.BYE, True, 3, run_ended), None),
        ("act_encrypted", frame(codec.FrameType.DATA, False, 2, act_body, encrypted=True), None),
    ]  # fmt: skip
    valid = []
    frames: dict[str, bytes] = {}
    for name, item, query_info in cases:
        sealed_frame = sealed(item)
        frames[name] = sealed_frame
        vector: dict[str, Any] = {
            "name": name,
            "type": item.type.name,
            "from_bridge": item.from_bridge,
            "robot": item.robot,
            "robot_nonce_hex": item.robot_nonce.hex(),
            "bridge_nonce_hex": item.bridge_nonce.hex(),
            "seq": item.seq,
            "encrypted": item.encrypted,
            "body_hex": item.body.hex(),
            "hex": sealed_frame.hex(),
            "serial_hex": codec.serial_encode(sealed_frame).hex(),
        }
        if item.type is codec.FrameType.DATA:
            kind, payload, attachment = codec.decode_data(item.body)
            vector["data"] = {
                "kind": kind.name,
                "kind_byte": kind.code,
                "attachment_hex": (attachment or b"").hex(),
                "payload_utf8": payload.decode(),
            }
            if query_info is not None:
                vector["data"]["query"] = query_info
        if item.type is codec.FrameType.WELCOME:
            vector["body_utf8"] = item.body.decode()
        valid.append(vector)

    def flipped(data: bytes, at: int, bit: int = 0x01) -> bytes:
        changed_data = bytearray(data)
        changed_data[at] ^= bit
        return bytes(changed_data)

    act_frame, sense_frame = frames["act"], frames["sense"]
    plain, encrypted = "plain", "encrypted"
    malformed, unexpected = codec.Refusal.MALFORMED, codec.Refusal.UNEXPECTED
    forged, oversize = codec.Refusal.FORGED, codec.Refusal.OVERSIZE
    # (name, reason, session, robot's refusal, bridge's refusal, bytes): the robot checks
    # the robot id and the direction before the tag, so a robot's frame is unexpected at
    # the robot whatever else is wrong with it, as a bridge's frame is at the bridge.
    raw: list[tuple[str, str, str, codec.Refusal, codec.Refusal, bytes]] = [
        ("shorter_than_a_frame", "a frame has at least 49 bytes", plain, malformed, malformed,
         act_frame[:48]),
        ("bad_magic", "a frame starts with 'BL'", plain, malformed, malformed,
         b"BX" + act_frame[2:]),
        ("version_2", "the frame version is 1", plain, malformed, malformed,
         act_frame[:2] + b"\x02" + act_frame[3:]),
        ("unknown_type", "frame types are 1 to 6", plain, malformed, malformed,
         act_frame[:3] + b"\x07" + act_frame[4:]),
        ("unknown_flag", "flags other than 0x01 and 0x02 are 0", plain, malformed, malformed,
         act_frame[:4] + b"\x04" + act_frame[5:]),
        ("robot_id_out_of_range", "robot ids are below 100000", plain, malformed, malformed,
         act_frame[:5] + (100_000).to_bytes(4, "big") + act_frame[9:]),
        ("oversize", f"a frame has at most {codec.MAX_FRAME_BYTES} bytes", plain, oversize,
         oversize, act_frame + bytes(codec.MAX_FRAME_BYTES)),
        ("robot_frame_over_32_kib", "the bridge refuses a robot's frame over 32 KiB before "
         "reading it; the robot reads the header first", plain, unexpected, oversize,
         sealed(frame(codec.FrameType.DATA, False, 4, data(keyspace.link(keyspace.STATUS),
                                                              bytes(32 * 1024))))),
        ("tag_changed", "the tag does not check out", plain, unexpected, forged,
         flipped(act_frame, -1)),
        ("body_changed", "the tag covers the body", plain, unexpected, forged,
         flipped(act_frame, codec.HEADER_BYTES + 10, 0x20)),
        ("tag_changed_from_the_bridge", "the tag does not check out", plain, forged, unexpected,
         flipped(sense_frame, -1)),
        ("body_changed_from_the_bridge", "the tag covers the body", plain, forged, unexpected,
         flipped(sense_frame, codec.HEADER_BYTES + 10, 0x20)),
        ("direction_changed", "the tag covers the flags: a robot's frame cannot be reflected",
         plain, forged, unexpected, act_frame[:4] + b"\x01" + act_frame[5:]),
        ("ciphertext_changed", "Poly1305 covers the ciphertext", encrypted, unexpected, forged,
         flipped(frames["act_encrypted"], codec.HEADER_BYTES)),
        ("ciphertext_changed_from_the_bridge", "Poly1305 covers the ciphertext", encrypted,
         forged, unexpected, flipped(frames["sense_encrypted"], codec.HEADER_BYTES)),
        ("encrypted_in_a_plain_session", "every frame is protected as its session is", plain,
         unexpected, unexpected, frames["sense_encrypted"]),
        ("plain_in_an_encrypted_session", "every frame is protected as its session is",
         encrypted, unexpected, unexpected, sense_frame),
        ("robot_plain_in_an_encrypted_session", "every frame is protected as its session is",
         encrypted, unexpected, unexpected, act_frame),
        ("another_robot", "a frame of robot 9 (under robot 9's link key)", plain, unexpected,
         unexpected, codec.seal(frame(codec.FrameType.DATA, True, 1, sense_body, robot=9),
                                other_key)),
        ("another_bridge_session", "a frame of another session of the bridge", plain,
         unexpected, unexpected, sealed(frame(codec.FrameType.DATA, True, 1, sense_body,
                                              bridge_nonce=LINK_OTHER_NONCE))),
        ("another_robot_session", "a frame of another session of the robot", plain, unexpected,
         unexpected, sealed(frame(codec.FrameType.DATA, False, 2, act_body,
                                  robot_nonce=LINK_OTHER_NONCE))),
        ("welcome_of_another_session", "a second welcome for one hello", plain, unexpected,
         unexpected, sealed(frame(codec.FrameType.WELCOME, True, 0, welcome_body("none"),
                                  bridge_nonce=LINK_OTHER_NONCE))),
        ("hello_with_a_body", "a hello has no body", plain, unexpected, malformed,
         sealed(frame(codec.FrameType.HELLO, False, 0, b"x", bridge_nonce=codec.NO_NONCE))),
        ("hello_from_the_bridge", "only the robot says hello", plain, unexpected, unexpected,
         sealed(frame(codec.FrameType.HELLO, True, 0, bridge_nonce=codec.NO_NONCE))),
        ("welcome_from_the_robot", "only the bridge welcomes", plain, unexpected, unexpected,
         sealed(frame(codec.FrameType.WELCOME, False, 0, welcome_body("none")))),
        ("welcome_with_sequence_number_1", "a welcome has sequence number 0", plain, malformed,
         unexpected, sealed(frame(codec.FrameType.WELCOME, True, 1, welcome_body("none")))),
        ("ping_of_seven_bytes", "a ping carries 8 bytes", plain, unexpected, malformed,
         sealed(frame(codec.FrameType.PING, False, 4, bytes(7)))),
        ("ping_of_seven_bytes_from_the_bridge", "a ping carries 8 bytes", plain, malformed,
         unexpected, sealed(frame(codec.FrameType.PING, True, 4, bytes(7)))),
        ("bye_of_an_unknown_reason", "a bye's reason is 1, 2 or 3", plain, malformed,
         unexpected, sealed(frame(codec.FrameType.BYE, True, 4, b"\x09"))),
        ("bye_of_an_unknown_reason_from_the_robot", "a bye's reason is 1, 2 or 3", plain,
         unexpected, malformed, sealed(frame(codec.FrameType.BYE, False, 4, b"\x09"))),
        ("data_with_sequence_number_zero", "frames of a session count from 1", plain,
         unexpected, malformed, sealed(frame(codec.FrameType.DATA, False, 0, act_body))),
        ("data_with_sequence_number_zero_from_the_bridge", "frames of a session count from 1",
         plain, malformed, unexpected, sealed(frame(codec.FrameType.DATA, True, 0, sense_body))),
        ("data_of_an_unknown_kind", "data kinds are 1-7 (to the robot) and 16-19 (from it)",
         plain, unexpected, malformed, sealed(frame(codec.FrameType.DATA, False, 4,
                                                    b"\x63\x00\x00{}"))),
        ("data_of_an_unknown_kind_from_the_bridge", "data kinds are 1-7 (to the robot) and "
         "16-19 (from it)", plain, malformed, unexpected,
         sealed(frame(codec.FrameType.DATA, True, 4, b"\x63\x00\x00{}"))),
        ("attachment_past_the_body", "the attachment length runs past the body", plain,
         unexpected, malformed, sealed(frame(codec.FrameType.DATA, False, 4,
                                             b"\x10\x00\x20short"))),
        ("attachment_past_the_body_from_the_bridge", "the attachment length runs past the "
         "body", plain, malformed, unexpected, sealed(frame(codec.FrameType.DATA, True, 4,
                                                            b"\x01\x00\x20short"))),
        ("attachment_over_1024_bytes", "an attachment has at most 1024 bytes", plain,
         unexpected, malformed, sealed(frame(codec.FrameType.DATA, False, 4,
                                             b"\x10\x04\x01" + bytes(1025) + b"{}"))),
        ("attachment_over_1024_bytes_from_the_bridge", "an attachment has at most 1024 bytes",
         plain, malformed, unexpected, sealed(frame(codec.FrameType.DATA, True, 4,
                                                    b"\x01\x04\x01" + bytes(1025) + b"{}"))),
        ("robot_kind_from_the_bridge", "kind 16 (act) is the robot's to send", plain,
         unexpected, unexpected, sealed(frame(codec.FrameType.DATA, True, 4, act_body))),
        ("bridge_kind_from_the_robot", "kind 1 (sense) is the bridge's to send", plain,
         unexpected, unexpected, sealed(frame(codec.FrameType.DATA, False, 4, sense_body))),
    ]  # fmt: skip
    invalid = [
        {
            "name": name,
            "reason": reason,
            "session": session,
            "refusal": {"robot": by_robot.value, "bridge": by_bridge.value},
            "hex": data_.hex(),
        }
        for name, reason, session, by_robot, by_bridge, data_ in raw
    ]

    def pings(from_bridge: bool, seqs: list[tuple[int, str | None]]) -> list[dict[str, Any]]:
        return [
            {
                "note": f"ping {seq}",
                "refused": refused,
                "hex": sealed(frame(codec.FrameType.PING, from_bridge, seq, bytes(8))).hex(),
            }
            for seq, refused in seqs
        ]

    replayed = codec.Refusal.REPLAYED.value
    edge = [(100, None), (37, None), (36, replayed), (37, replayed), (101, None), (38, None),
            (37, replayed), (100, replayed)]  # fmt: skip
    bad_welcome = sealed(frame(codec.FrameType.WELCOME, True, 0, b'{"v":1}'))
    sequences = [
        {
            "name": "replay_window_edge_at_the_robot",
            "receiver": "robot",
            "session": plain,
            "note": "63 behind the highest taken is taken once; 64 behind is refused",
            "frames": pings(True, edge),
        },
        {
            "name": "replay_window_edge_at_the_bridge",
            "receiver": "bridge",
            "session": plain,
            "note": "63 behind the highest taken is taken once; 64 behind is refused",
            "frames": pings(False, edge),
        },
        {
            "name": "welcomes",
            "receiver": "robot",
            "session": "hello",
            "note": "before its welcome a robot takes nothing of a session; a welcome that "
            "does not decode is malformed; the same welcome again is ignored, another refused",
            "frames": [
                {"note": "data before a welcome", "refused": unexpected.value,
                 "hex": sense_frame.hex()},
                {"note": "a welcome whose body is no LinkWelcome", "refused": malformed.value,
                 "hex": bad_welcome.hex()},
                {"note": "the welcome", "refused": None, "hex": frames["welcome"].hex()},
                {"note": "the same welcome again", "refused": None,
                 "hex": frames["welcome"].hex()},
                {"note": "a welcome of another bridge nonce", "refused": unexpected.value,
                 "hex": sealed(frame(codec.FrameType.WELCOME, True, 0, welcome_body("none"),
                                     bridge_nonce=LINK_OTHER_NONCE)).hex()},
                {"note": "data of the session", "refused": None, "hex": sense_frame.hex()},
                {"note": "the same data again", "refused": replayed,
                 "hex": sense_frame.hex()},
            ],
        },
        {
            "name": "hellos",
            "receiver": "bridge",
            "session": plain,
            "note": "a hello whose nonce the bridge answered before is a replay",
            "frames": [
                {"note": "the session's hello again", "refused": replayed,
                 "hex": frames["hello"].hex()},
                {"note": "a hello with a new nonce", "refused": None,
                 "hex": sealed(frame(codec.FrameType.HELLO, False, 0,
                                     robot_nonce=LINK_OTHER_NONCE,
                                     bridge_nonce=codec.NO_NONCE)).hex()},
            ],
        },
    ]  # fmt: skip
    good = codec.serial_encode(act_frame)
    bad_crc = bytearray(good)
    bad_crc[-3] ^= 0x01
    serial_invalid = [
        {"name": "crc_wrong", "category": "corrupt", "hex": bytes(bad_crc).hex()},
        {"name": "not_cobs", "category": "corrupt", "hex": "05010200"},
        {"name": "shorter_than_a_crc", "category": "corrupt", "hex": "03010200"},
    ]
    return {
        "type": "LinkFrame",
        "decoder": "link_frame",
        "frame_version": codec.VERSION,
        "robot": LINK_ROBOT,
        "robot_key_hex": robot_key.hex(),
        "link_key_label_utf8": codec.LINK_KEY_LABEL.decode(),
        "link_key_hex": key.hex(),
        "robot_nonce_hex": LINK_ROBOT_NONCE.hex(),
        "bridge_nonce_hex": LINK_BRIDGE_NONCE.hex(),
        "session_key_label_utf8": codec.SESSION_KEY_LABEL.decode(),
        "session_key_hex": cipher_key.hex(),
        "max_frame_bytes": codec.MAX_FRAME_BYTES,
        "max_encoded_bytes": codec.MAX_ENCODED_BYTES,
        "max_attachment_bytes": codec.MAX_ATTACHMENT_BYTES,
        "replay_window": codec.REPLAY_WINDOW,
        "valid": valid,
        "receivers": LINK_RECEIVERS,
        "invalid": invalid,
        "sequences": sequences,
        "serial_invalid": serial_invalid,
    }


# --- key files ---------------------------------------------------------------------------


def key_file_vectors() -> dict[str, Any]:
    """Key files as ``robot-agent --link`` reads them (bestofn_swarm/plumbing/run_keys.py
    read_key_file, bestofn_swarm/wire/auth.py keyring_from_text): the run, and the key of the robot
    it is for; and files it refuses (the program exits 2)."""
    keyring = auth.Keyring(secret=AUTH_SECRET)
    identity = names.robot_identity(LINK_ROBOT)
    robot_key = keyring.key(identity) or b""
    other_key = keyring.key(names.robot_identity(9)) or b""
    host_key = keyring.key(names.host_identity(8, 9)) or b""
    own = robot_key.hex()

    def text(content: dict[str, Any], separators: tuple[str, str] = (",", ":")) -> str:
        return json.dumps(content, separators=separators)

    valid = [
        ("one_robot", "what swarm run writes (robot-8.key)",
         text({"v": 1, "run": "demo", "keys": {identity: own}})),
        ("the_secret",
         "the run secret: the robot derives its key (bestofn_swarm/wire/auth.py derive_key)",
         text({"v": 1, "run": "demo", "secret": AUTH_SECRET.hex()})),
        ("a_host", "a process's keys: its robots' and its host identity's",
         text({"v": 1, "run": "demo",
               "keys": {"host/8-9": host_key.hex(), identity: own, "robot/9": other_key.hex()}})),
        ("spaced_and_reordered", "any JSON spelling; hex in either case",
         text({"keys": {identity: own.upper()}, "run": "demo", "v": 1}, (", ", ": "))
         + "\n"),
    ]  # fmt: skip
    invalid = [
        ("not_json", "not JSON", '{"v": 1, "run": "demo",'),
        ("not_an_object", "one JSON object", "[1]"),
        ("version_2", '"v" is 1', text({"v": 2, "run": "demo", "keys": {identity: own}})),
        ("no_run", "the run is named", text({"v": 1, "keys": {identity: own}})),
        ("run_not_a_string", "the run is a string",
         text({"v": 1, "run": 7, "keys": {identity: own}})),
        ("neither_secret_nor_keys", '"secret" or "keys"', text({"v": 1, "run": "demo"})),
        ("no_keys", '"keys" holds at least one', text({"v": 1, "run": "demo", "keys": {}})),
        ("no_key_for_the_robot", "the file holds the robot's key",
         text({"v": 1, "run": "demo", "keys": {"robot/9": other_key.hex()}})),
        ("key_not_hex", "a key is 64 hex digits",
         text({"v": 1, "run": "demo", "keys": {identity: "zz" * 32}})),
        ("key_of_31_bytes", "a key is 32 bytes",
         text({"v": 1, "run": "demo", "keys": {identity: own[:62]}})),
        ("not_an_identity", "keys are by identity (robot/08 is none)",
         text({"v": 1, "run": "demo", "keys": {identity: own, "robot/08": own}})),
        ("secret_of_31_bytes", "a secret is 32 bytes",
         text({"v": 1, "run": "demo", "secret": AUTH_SECRET.hex()[:62]})),
    ]  # fmt: skip
    return {
        "type": "KeyFile",
        "decoder": "key_file",
        "identity": identity,
        "run": "demo",
        "key_hex": own,
        "valid": [{"name": name, "note": note, "utf8": body} for name, note, body in valid],
        "invalid": [
            {"name": name, "reason": reason, "utf8": body} for name, reason, body in invalid
        ],
    }


def uniform_png(width: int, height: int, bgr: tuple[int, int, int]) -> bytes:
    """A one-colour 8-bit RGB PNG, its image data stored uncompressed (deflate level 0), so
    its bytes depend on no image library's encoder."""
    blue, green, red = bgr
    rows = b"".join(b"\x00" + bytes((red, green, blue)) * width for _ in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data).to_bytes(4, "big")
        return len(data).to_bytes(4, "big") + kind + data + crc

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes((8, 2, 0, 0, 0))
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows, 0))
        + chunk(b"IEND", b"")
    )


@dataclass
class Tick:
    """One tick's inputs and the controller's command; the expected outputs follow from
    the rules of docs/porting.md, written out here, not computed by the code under test."""

    name: str
    note: str
    sent_before: int  # broadcasts the robot sent in earlier ticks
    sense: protocol.Sense
    rx: list[tuple[str, bytes]]  # (sender, payload) in the medium's order
    frame: bytes | None
    frame_seen: tuple[int, int, tuple[int, int, int]] | None  # width, height, BGR; None: no image
    received: list[int]  # which of rx reach the controller (the others are invalid)
    rejected: int  # inputs dropped as invalid: payloads and frames
    left: float
    right: float
    capture: bool
    broadcasts: list[protocol.OpinionPayload]

    def content(self) -> dict[str, Any]:
        sense, tick = self.sense, self.sense.tick
        rx = [
            {
                "sender": sender,
                "meta_hex": protocol.encode(
                    # seq: the sender's numbering, which the robot does not use
                    protocol.RadioRxMeta(
                        v=1, tick=tick, sender=sender, seq=index + 20, sent_tick=tick - 1
                    )
                ).hex(),
                **_spelled(payload),
            }
            for index, (sender, payload) in enumerate(self.rx)
        ]
        camera = None
        if self.frame is not None:
            camera_meta = protocol.CameraMeta(v=1, tick=tick, width=4, height=3, encoding="png")
            camera = {"meta_hex": protocol.encode(camera_meta).hex(), "hex": self.frame.hex()}
        frame = None
        if self.frame_seen is not None:
            width, height, bgr = self.frame_seen
            frame = {"width": width, "height": height, "bgr": list(bgr)}
        radio_tx = []
        for offset, payload in enumerate(self.broadcasts, start=1):
            seq = self.sent_before + offset
            meta = protocol.RadioTxMeta(v=1, tick=tick, seq=seq)
            radio_tx.append(
                {
                    "seq": seq,
                    "meta_hex": protocol.encode(meta).hex(),
                    **_spelled(protocol.encode(payload)),
                }
            )
        act = protocol.Act(
            v=1,
            tick=tick,
            left=self.left,
            right=self.right,
            capture=self.capture,
            radio_tx=len(self.broadcasts),
        )
        return {
            "name": self.name,
            "note": self.note,
            "sent_before": self.sent_before,
            "in": {"sense": _spelled(protocol.encode(sense)), "radio_rx": rx, "camera": camera},
            "reading": {
                "t": sense.t,
                "x": sense.x,
                "y": sense.y,
                "theta": sense.theta,
                "proximity": list(sense.prox),
                "frame": frame,
            },
            "received": [
                {"sender": self.rx[index][0], "message": json.loads(self.rx[index][1])}
                for index in self.received
            ],
            "rejected": self.rejected,
            "command": {
                "left": self.left,
                "right": self.right,
                "capture": self.capture,
                "broadcasts": [json.loads(protocol.encode(payload)) for payload in self.broadcasts],
            },
            "out": {"radio_tx": radio_tx, "act": _spelled(protocol.encode(act))},
        }


def tick_vectors() -> dict[str, Any]:
    """One lockstep tick of a robot on Zenoh, in bytes (docs/porting.md)."""
    heard = protocol.encode(
        protocol.OpinionPayload(
            v=1,
            id=3,
            trip=2,
            decided=False,
            opinion=[0.0, 0.333333333, 0.333333333, 0.0, 0.333333333],
        )
    )
    beacon = protocol.encode(protocol.BeaconPayload(v=1, id="nest", seq=12))
    own = protocol.OpinionPayload(
        v=1, id=7, trip=3, decided=False, opinion=[0.1, 0.2, 0.3, 0.2, 0.2]
    )
    prox = [0.0, 0.0, 0.0, 0.000015, 1.5e-6, 0.0, 0.25, 1.0]
    panel = (64, 0, 191)  # BGR of a site of quality 0.75: red 255 x 0.75, blue 255 x 0.25
    ticks = [
        Tick(
            name="typical",
            note="sense.json's tick 42 with its two deliveries and frame; act.json's act",
            sent_before=4,
            sense=protocol.Sense(
                v=1, tick=42, t=4.2, x=0.31, y=-0.12, theta=1.5708, prox=prox, rx=2, camera=True
            ),
            rx=[("3", heard), ("nest", beacon)],
            frame=uniform_png(4, 3, panel),
            frame_seen=(4, 3, panel),
            received=[0, 1],
            rejected=0,
            left=0.13,
            right=-0.065,
            capture=False,
            broadcasts=[own],
        ),
        Tick(
            name="invalid_inputs_are_counted",
            note="an opinion that does not sum to 1 and a frame that is no image are dropped "
            "and counted, never raised; broadcasts are numbered on from the last",
            sent_before=5,
            sense=protocol.Sense(
                v=1, tick=43, t=4.3, x=0.31, y=-0.12, theta=1.5708, prox=prox, rx=2, camera=True
            ),
            rx=[
                ("3", changed(heard, b"[0.0,0.333333333,", b"[0.5,0.333333333,")),
                ("nest", beacon),
            ],
            frame=b"not an image",
            frame_seen=None,
            received=[1],
            rejected=2,
            left=0.0,
            right=0.0,
            capture=True,
            broadcasts=[own, msgspec.structs.replace(own, decided=True)],
        ),
        Tick(
            name="nothing_heard_nothing_said",
            note="no deliveries, no frame, no broadcasts: the act alone, radio_tx 0",
            sent_before=7,
            sense=protocol.Sense(
                v=1, tick=44, t=4.4, x=0.32, y=-0.12, theta=1.6, prox=[0.0] * 8, rx=0, camera=False
            ),
            rx=[],
            frame=None,
            frame_seen=None,
            received=[],
            rejected=0,
            left=0.05,
            right=0.05,
            capture=False,
            broadcasts=[],
        ),
    ]
    return {
        "type": "Tick",
        "decoder": "tick",
        "protocol_version": protocol.VERSION,
        "ticks": [tick.content() for tick in ticks],
    }


def _bits(value: float) -> str:
    """A double as the 16 hex digits of its IEEE-754 bits (big-endian); a NaN as "nan"
    (its payload is not specified)."""
    return "nan" if math.isnan(value) else struct.pack(">d", value).hex()


def _u64(value: int) -> str:
    """A 64-bit unsigned integer as 16 hex digits (JSON numbers lose bits past 2^53)."""
    return f"{value:016x}"


def numeric_inputs() -> dict[str, list[tuple[float, ...]]]:
    """Inputs of each kernel function: edges, then values drawn from a fixed stream."""
    stream = Stream(20260101)
    angles = [
        0.0,
        -0.0,
        0.5,
        -0.75,
        numeric.PI / 4,
        numeric.HALF_PI,
        numeric.PI,
        -numeric.PI,
        3.0 * numeric.HALF_PI,
        numeric.TWO_PI,
        1e-9,
        100.0,
        -1234.5,
        7.5e5,
        numeric.MAX_ANGLE,
    ]
    angles += [stream.uniform(-20.0, 20.0) for _ in range(40)]
    tangents = [0.0, -0.0, 0.4375, 0.6875, 1.0, 1.1875, 2.4375, 1e-30, 1e30, -3.0, math.inf]
    tangents += [stream.uniform(-1.0, 1.0) * 10.0 ** stream.uniform(-6.0, 6.0) for _ in range(30)]
    points = [
        (0.0, 0.0),
        (-0.0, 0.0),
        (0.0, -0.0),
        (-0.0, -0.0),
        (0.0, 1.0),
        (1.0, 0.0),
        (0.0, -1.0),
        (-1.0, 0.0),
        (1.0, 1.0),
        (-1.0, -1e-300),
        (1e300, 1e-300),
        (math.inf, 1.0),
        (1.0, -math.inf),
        (math.inf, -math.inf),
    ]
    points += [(stream.uniform(-3.0, 3.0), stream.uniform(-3.0, 3.0)) for _ in range(40)]
    exponents = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.3465,
        -0.3466,
        1.5,
        700.0,
        709.78,
        709.8,
        -745.0,
        -745.2,
        -708.5,
        1e-12,
        math.inf,
        -math.inf,
    ]
    exponents += [stream.uniform(-50.0, 50.0) for _ in range(30)]
    positives = [
        1.0,
        2.0,
        0.5,
        numeric.SQRT_HALF,
        2.0 * numeric.SQRT_HALF,
        0.7071067811865476,
        1e-300,
        5e-324,
        1.7976931348623157e308,
        0.0,
        -1.0,
        math.inf,
    ]
    positives += [
        math.ldexp(1.0 + stream.random(), int(stream.uniform(-60.0, 60.0))) for _ in range(30)
    ]
    powers = [(0.5, 2.0), (0.25, 0.5), (1.0, 7.0), (0.0, 3.0), (0.3, 0.0), (2.0, -1.0)]
    powers += [(stream.random(), stream.uniform(0.1, 5.0)) for _ in range(20)]
    return {
        "sincos": [(x,) for x in angles],
        "atan": [(x,) for x in tangents],
        "atan2": [tuple(point) for point in points],
        "exp": [(x,) for x in exponents],
        "log": [(x,) for x in positives],
        "power": [tuple(pair) for pair in powers],
        "wrap_angle": [(x,) for x in angles],
    }  # fmt: skip


def numeric_vectors() -> dict[str, Any]:
    functions: dict[str, Callable[..., float | tuple[float, ...]]] = {
        "sincos": numeric.sincos,
        "atan": numeric.atan,
        "atan2": numeric.atan2,
        "exp": numeric.exp,
        "log": numeric.log,
        "power": numeric.power,
        "wrap_angle": numeric.wrap_angle,
    }
    cases: dict[str, list[dict[str, Any]]] = {}
    for name, inputs in numeric_inputs().items():
        cases[name] = []
        for arguments in inputs:
            result = functions[name](*arguments)
            outputs = result if isinstance(result, tuple) else (result,)
            cases[name].append(
                {
                    "in": [_bits(value) for value in arguments],
                    "out": [_bits(value) for value in outputs],
                    "readable": [repr(value) for value in (*arguments, *outputs)],
                }
            )
    return {
        "type": "NumericKernel",
        "about": "inputs and outputs of bestofn_swarm/wire/numeric.py as the hex of their "
        'IEEE-754 bits (big-endian; any NaN is "nan"); sincos gives (sin, cos); atan2 takes '
        "(y, x); power takes (x, y)",
        "cases": cases,
    }


def rng_vectors() -> dict[str, Any]:
    """Each case: a seed, the calls made on one stream in order, and what they return."""
    cases: list[dict[str, Any]] = []

    def case(name: str, seed: int, calls: list[tuple[str, list[Any]]]) -> None:
        stream = Stream(seed)
        drawn: list[Any] = []
        for method, arguments in calls:
            arguments = json.loads(json.dumps(arguments))  # shuffle works on its own copy
            value = getattr(stream, method)(*arguments)
            if method == "shuffle":
                value = arguments[0]
            elif method == "fork":
                value = _u64(value.state)
            elif method == "next_u64":
                value = _u64(value)
            drawn.append(_bits(value) if isinstance(value, float) else value)
        cases.append(
            {
                "name": name,
                "seed": _u64(seed),
                "calls": [[method, arguments] for method, arguments in calls],
                "returns": drawn,
                "state_after": _u64(stream.state),
            }
        )

    case("next_u64 from 0", 0, [("next_u64", [])] * 5)
    case("next_u64 from 1234567 (SplitMix64's reference seed)", 1234567, [("next_u64", [])] * 5)
    case("next_u64 near the top", 2**64 - 1, [("next_u64", [])] * 3)
    case("random", 42, [("random", [])] * 6)
    case("uniform", 7, [("uniform", [-1.0, 1.0]), ("uniform", [0.5, 3.25])] * 3)
    case("randrange", 99, [("randrange", [n]) for n in (1, 2, 3, 5, 10, 100, 1000, 2**40 + 1)])
    case("choice", 5, [("choice", [[-1, 1]])] * 6 + [("choice", [["a", "b", "c"]])] * 3)
    case("shuffle", 11, [("shuffle", [list(range(10))]), ("shuffle", [list(range(3))])])
    case("sample", 13, [("sample", [list(range(20)), 5]), ("sample", [[4, 8, 15], 3])])
    case("expovariate", 17, [("expovariate", [1.0]), ("expovariate", [0.5])] * 3)
    case("normal", 19, [("normal", [])] * 6)
    case("fork", 23, [("fork", []), ("next_u64", [])])
    seeds = [
        {"run_seed": run, "parts": list(parts), "seed": _u64(seed_of(run, *parts))}
        for run, parts in ((0, ("robot", 3)), (42, ("robot", 0)), (7, ("radio", "drop")),
                           (0, ("layout",)), (2**63 - 1, ("beacon", "nest")))
    ]  # fmt: skip
    return {
        "type": "Stream",
        "about": "bestofn_swarm/wire/rng.py: each case seeds a Stream, makes the calls in order "
        "and lists what each returned (floats as the hex of their IEEE-754 bits; 64-bit "
        "integers (seeds, states, next_u64) as 16 hex digits; shuffle: the list after it; "
        "fork: the new stream's state); seed_of: run seed and parts to seed",
        "cases": cases,
        "seed_of": seeds,
    }


def _compact(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":"), ensure_ascii=False).encode()


BUILDERS: tuple[Callable[[], TypeVectors], ...] = (
    world_info_vectors,
    link_stats_vectors,
    join_reply_vectors,
    clock_vectors,
    world_state_vectors,
    sense_vectors,
    camera_meta_vectors,
    act_vectors,
    ack_vectors,
    status_vectors,
    radio_tx_meta_vectors,
    radio_rx_meta_vectors,
    log_line_vectors,
    opinion_vectors,
    vote_vectors,
    beacon_vectors,
    pace_vectors,
    run_ending_vectors,
    ending_seals_vectors,
)


# --- the controller ------------------------------------------------------------------------


@dataclass(frozen=True)
class ControllerTrack:
    """One robot of one run, from its first step to ``AFTER`` steps past the first time it
    fired ``until`` (phase, event)."""

    name: str
    about: str
    sites: int
    seed: int
    robot: int
    until: tuple[str, str]
    # ControllerConfig's settings beyond the defaults
    settings: dict[str, Any] = field(default_factory=dict)


# Every run: ten robots, the paper's settings (swarm run's defaults), a radio that loses 30 %
# of the copies it delivers and camera noise of 10 (docs/robustness.md's settings).
CONTROLLER_RUN: dict[str, Any] = {"robots": 10, "drop": 0.3, "camera_noise": 10.0}
AFTER = 10
CONTROLLER_TRACKS = (
    ControllerTrack(
        "displaced",
        "three trips, a decision, parking, and a crowd pushing the parked robot out of its "
        "slot: it drives back",
        sites=10,
        seed=13,
        robot=5,
        until=("stopped", "displaced"),
    ),
    ControllerTrack(
        "lingering",
        "the paper's fix for isolated robots (linger 10 s, n = 5): a decided robot stays at "
        "the nest broadcasting before it parks",
        sites=5,
        seed=69,
        robot=9,
        until=("lingering", "lingered"),
        settings={"linger": 10.0},
    ),
    ControllerTrack(
        "site_unseen",
        "three frames of a site in a row show no panel (robots in the way): the pair is "
        "given up and the robot goes home",
        sites=10,
        seed=532,
        robot=4,
        until=("sensing", "site_unseen"),
    ),
    ControllerTrack(
        "waiting",
        "home at the nest's centre without having heard the beacon (lost copies): the robot "
        "waits there until it hears it",
        sites=10,
        seed=436,
        robot=2,
        until=("waiting", "heard_beacon"),
    ),
    ControllerTrack(
        "leg_timed_out",
        "a leg given 10 s (travel_timeout 10, travel_crawl 0.1 m/s; the default 120 s never "
        "runs out in a swarm of ten): the robot gives the site up and goes home",
        sites=10,
        seed=0,
        robot=1,
        until=("to_site", "leg_timed_out"),
        settings={"travel_timeout": 10.0, "travel_crawl": 0.1},
    ),
)


def controller_vectors() -> str:
    """Tracks of real runs, step by step (deploy/conformance/vectors.py, docs/controller.md)."""
    from deploy.conformance import capture, vectors
    from robot_agent.core.controller import ControllerConfig
    from world_server.core.camera import CameraNoise
    from world_server.core.radio import RadioConfig
    from world_server.core.world import World, WorldConfig

    tracks = []
    for spec in CONTROLLER_TRACKS:
        world = WorldConfig(
            run="vectors",
            seed=spec.seed,
            num_sites=spec.sites,
            num_robots=CONTROLLER_RUN["robots"],
            radio=RadioConfig(drop=CONTROLLER_RUN["drop"]),
            camera_noise=CameraNoise(pixel_sigma=CONTROLLER_RUN["camera_noise"]),
        )
        config = ControllerConfig(**spec.settings)
        caught = capture.capture_run(world, config, [spec.robot])
        steps = caught.steps[spec.robot]
        end = next(index for index, step in enumerate(steps) if tuple(spec.until) in step.events)
        tracks.append(
            vectors.track_from_steps(
                name=spec.name,
                about=spec.about,
                run={**CONTROLLER_RUN, "sites": spec.sites, "seed": spec.seed, **spec.settings},
                robot=spec.robot,
                world=World(world).info,
                controller=config,
                steps=steps[: end + 1 + AFTER],
            )
        )
    about = [
        "Tracks of real runs (tests/make_vectors.py, CONTROLLER_TRACKS): one robot each, "
        "from its first step to 10 steps past the transition it was chosen for.",
        "in: the step's reading (t, x, y, theta, prox), the radio messages in delivery "
        "order ([sender, payload]), the frame (an index into frames: PNG, base64) or null.",
        "out: what the controller gives: wheel speeds, capture, broadcasts, the phase after "
        "the step; events, opinion (full precision) and status only when there are any, or "
        "they changed.",
        "docs/controller.md says how a port uses them; swarm conformance drives a program "
        "with them over the link.",
    ]
    return vectors.dump(about, tracks)


def build(*, controller: bool = True) -> dict[str, str]:
    """File name -> the text of that vector file (``controller``: the controller vectors
    too, which run swarms)."""
    files = {vectors.file: vectors.content() for vectors in (make() for make in BUILDERS)}
    files["udp_frame.json"] = udp_frame_vectors()
    files["auth.json"] = auth_vectors()
    files["link_frame.json"] = link_frame_vectors()
    files["key_file.json"] = key_file_vectors()
    files["tick.json"] = tick_vectors()
    files["batch.json"] = batch_vectors()
    files["numeric.json"] = numeric_vectors()
    files["rng.json"] = rng_vectors()
    texts = {
        name: json.dumps(content, indent=1, ensure_ascii=False) + "\n"
        for name, content in files.items()
    }
    if controller:
        texts["controller.json"] = controller_vectors()
    return texts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write or check tests/vectors/*.json.")
    parser.add_argument(
        "--check", action="store_true", help="only compare; exit 1 if a file is missing or differs"
    )
    args = parser.parse_args(argv)
    stale = []
    for name, text in build().items():
        path = VECTORS / name
        if path.exists() and path.read_text(encoding="utf-8") == text:
            continue
        stale.append(name)
        if not args.check:
            VECTORS.mkdir(exist_ok=True)
            path.write_text(text, encoding="utf-8")
    if args.check and stale:
        print(f"out of date: {', '.join(stale)} (run python tests/make_vectors.py)")
        return 1
    print(f"{'stale' if args.check else 'wrote'}: {', '.join(stale) or 'nothing'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
