"""The one vocabulary of the swarm: key expressions, message types, codec, schemas.

Every process imports its keys and messages from here and nowhere else. Messages are
versioned JSON objects (field ``v``) defined once as ``msgspec`` structs; the same
definitions validate what arrives, encode what leaves and produce the JSON Schemas
that recordings carry. No Zenoh here: a port to another transport reuses this file.

Bounds on every number make a decoded message safe to use: NaN, infinities,
negative counts and over-long vectors are rejected at the edge, never passed on.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal, TypeVar

import msgspec

from bestofn_swarm.wire import names
from bestofn_swarm.wire.endings import Ending, Stop, TimeLimit

VERSION: Literal[1] = 1
DEFAULT_ROOT = "bestofn"

# Limits a decoder enforces. An opinion for n = 100 must fit a 2 KB zenoh-pico batch,
# so options are capped at 1000 and every opinion value is sent with 9 significant
# digits (float32 round-trip precision; zeros stay exact, so alpha = 0 logic is exact).
MAX_OPTIONS = 1000
MAX_PAYLOAD_BYTES = 64 * 1024
MAX_CAMERA_FRAME_BYTES = 1024 * 1024
# A run's ending carries its summary, a few hundred bytes per robot (docs/running.md): room
# for the largest swarm a run may have (bestofn_swarm/wire/shape.py), many times over.
MAX_ENDING_BYTES = 4 * 1024 * 1024
OPINION_DIGITS = 9

# The bounds, by name where the binary batches (bestofn_swarm/wire/batch.py) check them too.
MAX_COORD = 1e6  # metres, either sign
MAX_ANGLE = 1e3  # radians, either sign
MAX_SIM_TIME = 1e9  # seconds
MAX_TICK = 2**53
MAX_WHEEL = 10.0  # m/s, either sign
MAX_RX = 10_000  # radio messages delivered to one robot in one tick
MAX_TX = 1000  # radio messages one controller sends in one tick

_Coord = Annotated[float, msgspec.Meta(ge=-MAX_COORD, le=MAX_COORD)]
_Angle = Annotated[float, msgspec.Meta(ge=-MAX_ANGLE, le=MAX_ANGLE)]
_SimTime = Annotated[float, msgspec.Meta(ge=0.0, le=MAX_SIM_TIME)]
_Tick = Annotated[int, msgspec.Meta(ge=0, le=MAX_TICK)]
_Count = Annotated[int, msgspec.Meta(ge=0, le=2**53)]
_Unit = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
_Wheel = Annotated[float, msgspec.Meta(ge=-MAX_WHEEL, le=MAX_WHEEL)]
_RobotId = Annotated[int, msgspec.Meta(ge=0, lt=names.MAX_ROBOTS)]
_SiteId = Annotated[int, msgspec.Meta(ge=0, lt=MAX_OPTIONS)]
_Positive = Annotated[float, msgspec.Meta(gt=0.0, le=1e6)]
_Opinion = Annotated[list[_Unit], msgspec.Meta(min_length=2, max_length=MAX_OPTIONS)]

_Name = names.Name


MAX_SEED = 2**63 - 1
Seed = Annotated[int, msgspec.Meta(ge=0, le=MAX_SEED)]  # a run seed


class Message(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """Base of every message: a version field first, unknown fields refused.

    Fields encode in declaration order, base class first, so ``v`` always leads. Every
    subclass repeats ``frozen=True``: msgspec would inherit it anyway, but a type checker
    reads a Struct as a dataclass and would take a subclass without it as mutable.
    """

    v: Literal[1]


# --- world -> everyone ---------------------------------------------------------------


class Site(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    id: _SiteId
    x: _Coord
    y: _Coord


class Nest(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    x: _Coord
    y: _Coord
    radius: _Positive


class CameraSpec(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    width: Annotated[int, msgspec.Meta(ge=8, le=1024)]
    height: Annotated[int, msgspec.Meta(ge=8, le=1024)]
    fov: Annotated[float, msgspec.Meta(gt=0.0, lt=3.2)]


class WorldInfo(Message, frozen=True):
    """Answer of the ``world/info`` queryable: the map a robot is given (never qualities)."""

    run: _Name
    seed: Seed
    dt: _Positive
    arena_radius: _Positive
    nest: Nest
    sites: Annotated[list[Site], msgspec.Meta(min_length=2, max_length=MAX_OPTIONS)]
    robot_radius: _Positive
    wheel_base: _Positive
    max_wheel_speed: _Positive
    camera: CameraSpec
    clock: Literal["lockstep", "realtime"]


class JoinReply(Message, frozen=True):
    """Answer of the ``world/join`` queryable: an id for a robot started with ``--id auto``."""

    id: _RobotId


class Clock(Message, frozen=True):
    tick: _Tick
    t: _SimTime


class Pose(msgspec.Struct, forbid_unknown_fields=True, frozen=True, array_like=True):
    """A robot pose in ``world/state``, sent as ``[id, x, y, theta]`` to keep it small."""

    id: _RobotId
    x: _Coord
    y: _Coord
    theta: _Angle


class RadioCounters(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    sent: _Count = 0
    delivered: _Count = 0
    dropped: _Count = 0
    rejected: _Count = 0


class WorldState(Message, frozen=True):
    """All poses (decimated) plus the world's counters, for recorders and viewers."""

    tick: _Tick
    t: _SimTime
    robots: list[Pose]
    radio: RadioCounters
    rejected: _Count
    stalls: _Count
    # Robots and beacons whose liveliness token went while the world ran (a crash, a kill,
    # a lost connection). Absent from recordings made before it was counted.
    departures: _Count = 0


# --- world <-> robot body (reliable) -------------------------------------------------


class Sense(Message, frozen=True):
    """World -> robot at the start of tick ``tick``: its body's readings.

    ``rx`` radio messages and, when ``camera`` is true, one frame are delivered for
    this tick on their own keys; a lockstep controller waits for all of them before it
    steps, which keeps runs deterministic whatever order Zenoh delivers keys in.
    """

    tick: _Tick
    t: _SimTime
    x: _Coord
    y: _Coord
    theta: _Angle
    prox: Annotated[list[_Unit], msgspec.Meta(min_length=8, max_length=8)]
    rx: Annotated[int, msgspec.Meta(ge=0, le=MAX_RX)]
    camera: bool


class Act(Message, frozen=True):
    """Robot -> world: the answer to tick ``tick``.

    ``radio_tx`` says how many radio messages the robot sent during this tick, so the
    world can close the tick only once all of them have arrived.
    """

    tick: _Tick
    left: _Wheel
    right: _Wheel
    capture: bool
    radio_tx: Annotated[int, msgspec.Meta(ge=0, le=MAX_TX)]


class Ack(Message, frozen=True):
    """A body-less controller's (the nest beacon's) answer to tick ``tick``.

    ``next_tick``: the next tick it answers, for it sends nothing before then; the world
    neither waits for it nor sends it the clock until that tick. None: the next tick.
    """

    tick: _Tick
    radio_tx: Annotated[int, msgspec.Meta(ge=0, le=MAX_TX)]
    rejected: _Count = 0  # invalid messages the beacon dropped so far
    next_tick: _Tick | None = None


class CameraMeta(Message, frozen=True):
    """Zenoh attachment of a camera frame; the payload is the encoded image."""

    tick: _Tick
    width: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    height: Annotated[int, msgspec.Meta(ge=1, le=4096)]
    encoding: Literal["png", "jpeg"]


# --- radio ---------------------------------------------------------------------------


class RadioTxMeta(Message, frozen=True):
    """Zenoh attachment of ``radio/tx/<sender>``; the payload is opaque to the medium."""

    tick: _Tick
    seq: _Count


class RadioRxMeta(Message, frozen=True):
    """Zenoh attachment of ``radio/rx/<receiver>``: who sent it, and when."""

    tick: _Tick
    sender: _Name
    seq: _Count
    sent_tick: _Tick


class OpinionPayload(
    msgspec.Struct,
    tag_field="kind",
    tag="opinion",
    kw_only=True,
    forbid_unknown_fields=True,
    frozen=True,
):
    """A robot's broadcast at the nest: its current opinion over the sites."""

    v: Literal[1]
    id: _RobotId
    trip: _Count
    decided: bool
    opinion: _Opinion


class BeaconPayload(
    msgspec.Struct,
    tag_field="kind",
    tag="beacon",
    kw_only=True,
    forbid_unknown_fields=True,
    frozen=True,
):
    """The nest beacon's broadcast: hearing it means being at the nest."""

    v: Literal[1]
    id: _Name
    seq: _Count


class VotePayload(
    msgspec.Struct,
    tag_field="kind",
    tag="vote",
    kw_only=True,
    forbid_unknown_fields=True,
    frozen=True,
):
    """A voting robot's broadcast at the nest (``--strategy dmvd``, ``dmmd`` or ``dc``): the
    one site it favours and its own estimate of that site's quality."""

    v: Literal[1]
    id: _RobotId
    trip: _Count
    decided: bool
    site: _SiteId
    quality: _Unit


RadioPayload = OpinionPayload | BeaconPayload | VotePayload
# What a robot broadcasts: its opinion (the paper's strategy) or its vote (the others).
RobotBroadcast = OpinionPayload | VotePayload


class RadioTxRecord(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """A ``radio/tx/<sender>`` sample as a recording keeps it: its metadata and payload."""

    meta: RadioTxMeta
    payload: RadioPayload


class RadioRxRecord(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """A ``radio/rx/<receiver>`` sample as a recording keeps it: its metadata and payload."""

    meta: RadioRxMeta
    payload: RadioPayload


# --- robot -> anyone -----------------------------------------------------------------

Phase = Literal[
    "waiting", "to_site", "sensing", "to_nest", "at_nest", "lingering", "to_decision", "stopped"
]


class Comparison(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """The last pairwise comparison: both sites and their estimated qualities."""

    site_a: _SiteId
    quality_a: _Unit
    site_b: _SiteId
    quality_b: _Unit
    eliminated: _SiteId


class Status(Message, frozen=True):
    id: _RobotId
    tick: _Tick
    t: _SimTime
    phase: Phase
    trips: _Count
    opinion: _Opinion
    pool_size: _Count
    poolings: _Count
    decided_site: _SiteId | None
    decision_time: _SimTime | None
    decision_trips: _Count | None
    comparison: Comparison | None
    rejected: _Count = 0  # invalid messages this robot dropped so far


MAX_PACE_SPEED = 1000.0  # sim seconds per wall second


class Pace(Message, frozen=True):
    """The live page's pause, play and speed, for the world: whether ticks go on, and at
    most how many sim seconds a wall second (None: as fast as the swarm answers, in
    lockstep; the world's own ``--speed`` in real time). A lockstep run is the same run
    however it is paced: only when its ticks close changes."""

    playing: bool
    speed: Annotated[float, msgspec.Meta(gt=0.0, le=MAX_PACE_SPEED)] | None = None


class LogLine(Message, frozen=True):
    """One line a process of the run wrote to its log (published by the launcher)."""

    process: _Name
    wall_time: Annotated[float, msgspec.Meta(ge=0.0, le=1e11)]
    line: Annotated[str, msgspec.Meta(max_length=4096)]


class LinkRefusals(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """Link frames a bridge refused, by reason (bestofn_swarm/link/core/codec.py ``Refusal``)."""

    malformed: _Count = 0
    oversize: _Count = 0
    corrupt: _Count = 0
    forged: _Count = 0
    replayed: _Count = 0
    unexpected: _Count = 0
    rate: _Count = 0


_Millis = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]


class LinkStats(Message, frozen=True):
    """A robot outside the emulator, as its bridge sees its link (published on change and
    every second): whether its program is connected, the round trip of the bridge's pings
    (median and 95th percentile of the last ones, in wall milliseconds), the share of pings
    never answered, what went through and what was refused."""

    robot: _RobotId
    transport: Literal["udp", "serial"]
    address: Annotated[str, msgspec.Meta(max_length=256)]  # where the bridge serves it
    connected: bool
    sessions: _Count  # sessions opened so far (a reconnection opens another)
    rtt_ms: _Millis | None
    rtt_p95_ms: _Millis | None
    pings: _Count  # pings answered or given up
    loss: _Unit  # of those, the share never answered
    frames_in: _Count
    frames_out: _Count
    bytes_in: _Count
    bytes_out: _Count
    impaired: _Count  # frames dropped on purpose (--link-loss)
    refused: LinkRefusals


# --- world -> every process of the run --------------------------------------------------

_Tag = Annotated[str, msgspec.Meta(pattern="^[0-9a-f]{32}$")]


class RunEnding(Message, frozen=True):
    """``world/ending``: how the run ended, as its world decided it, once; every process of
    the run exits on it with ``code``, the run's exit code (bestofn_swarm/wire/endings.py).

    ``stop`` is why the world stopped the run (``timeout_kind``: which limit, for a
    timeout), ``tick`` and ``t`` when; ``signal`` names the stop signal that ended it, if
    one did; ``lost`` the robots (by id) and beacons (by name) whose liveliness went while
    the run went on, not as a fault of its plan; ``summary`` is the run's summary as the
    world knows it (the ``swarm run --json`` object, docs/running.md).
    """

    run: _Name
    ended: Ending
    code: Annotated[int, msgspec.Meta(ge=0, le=255)]
    stop: Stop
    timeout_kind: TimeLimit | None
    tick: _Tick
    t: _SimTime
    signal: Annotated[str, msgspec.Meta(max_length=16)] | None
    lost: Annotated[list[_Name], msgspec.Meta(max_length=names.MAX_ROBOTS)]
    summary: dict[str, Any]


class EndingSeals(Message, frozen=True):
    """The metadata of ``world/ending``: the ending's tag (hex) with each robot's key, robot
    by robot from 0, and with the bridge's, for processes that hold neither the world's key
    nor the run secret (empty, and null, in an unkeyed run)."""

    robots: Annotated[list[_Tag], msgspec.Meta(max_length=names.MAX_ROBOTS)]
    bridge: _Tag | None


# --- codec ---------------------------------------------------------------------------

M = TypeVar("M")
_encoder = msgspec.json.Encoder()
_decoders: dict[Any, msgspec.json.Decoder[Any]] = {}


class ProtocolError(ValueError):
    """A payload that is not a valid message of the expected type."""


def encode(message: msgspec.Struct) -> bytes:
    return _encoder.encode(message)


# The messages that may be larger than MAX_PAYLOAD_BYTES, and how large.
_LARGER: dict[Any, int] = {RunEnding: MAX_ENDING_BYTES, EndingSeals: MAX_ENDING_BYTES}


def decode(payload: bytes | bytearray | memoryview, kind: type[M]) -> M:
    """Decode and validate ``payload`` as ``kind``; raise ProtocolError if it is not one."""
    decoder: msgspec.json.Decoder[M] | None = _decoders.get(kind)
    if decoder is None:
        decoder = _decoders[kind] = msgspec.json.Decoder(kind)
    return _decode(decoder, payload, _LARGER.get(kind, MAX_PAYLOAD_BYTES))


def _decode(
    decoder: msgspec.json.Decoder[M],
    payload: bytes | bytearray | memoryview,
    limit: int = MAX_PAYLOAD_BYTES,
) -> M:
    if len(payload) > limit:
        raise ProtocolError(f"payload of {len(payload)} bytes exceeds {limit}")
    try:
        return decoder.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError, UnicodeDecodeError) as error:
        raise ProtocolError(str(error)) from None


_radio_decoder: msgspec.json.Decoder[OpinionPayload | BeaconPayload | VotePayload] = (
    msgspec.json.Decoder(RadioPayload)
)


def decode_radio(
    payload: bytes | bytearray | memoryview,
) -> OpinionPayload | BeaconPayload | VotePayload:
    message = _decode(_radio_decoder, payload)
    if isinstance(message, OpinionPayload) and abs(math.fsum(message.opinion) - 1.0) > 1e-6:
        raise ProtocolError(f"opinion sums to {math.fsum(message.opinion)!r}, not 1")
    return message


def wire_opinion(opinion: list[float] | tuple[float, ...]) -> list[float]:
    """Round an opinion to the wire's precision (``OPINION_DIGITS`` significant digits)."""
    return [float(f"{value:.{OPINION_DIGITS}g}") for value in opinion]


def json_schema(kind: Any) -> dict[str, Any]:
    """The JSON Schema of a message type, from its one definition above."""
    return msgspec.json.schema(kind)


# --- seeds ---------------------------------------------------------------------------
