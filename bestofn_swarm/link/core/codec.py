"""The link between a robot program outside the emulator and the run's bridge (pure).

A robot outside the emulator (``robot-agent --link``, or firmware on a real robot) talks
to the run over one link: UDP datagrams or a serial byte stream. Every link message is
one *frame*; docs/protocol.md specifies it byte for byte and tests/vectors/link_frame.json
holds conformance vectors. In short::

    offset  size  field
    0       2     magic, ASCII "BL" (0x42 0x4C)
    2       1     version, 0x01
    3       1     type: 1 HELLO, 2 WELCOME, 3 DATA, 4 PING, 5 PONG, 6 BYE
    4       1     flags: 0x01 sent by the bridge (clear: by the robot); 0x02 body encrypted
    5       4     robot id, u32 big-endian
    9       8     the robot's session nonce
    17      8     the bridge's session nonce (zero in a HELLO)
    25      8     sequence number, u64 big-endian (0 in HELLO and WELCOME; from 1 after)
    33      n     body
    33 + n  16    tag

The tag is the first 16 bytes of HMAC-SHA256 under the robot's *link key* over the header
and body, or, in an encrypted session, the Poly1305 tag of ChaCha20-Poly1305 under the
session key (the body is then the ciphertext and the header the associated data). The link
key is ``HMAC-SHA256(robot key, "bestofn-link")``: the bridge holds it, never the robot's
run key, so it can check and make frames but not forge what the robot says to the world.

A UDP datagram is one frame. On a serial line a frame travels as
``COBS(frame + CRC-32(frame)) 0x00`` (CRC-32 of zlib, big-endian): the zero byte ends
each frame, so a receiver finds the next frame after any corruption.

Nothing here does I/O or reads a clock: the two ends (``robot_agent/link/program.py`` for the
robot, ``world_server/bridge`` for the world's side) give the time where it matters.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct
import zlib
from dataclasses import dataclass, field
from typing import Annotated, Literal

import msgspec
from cobs import cobs
from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives.ciphers.aead import ChaCha20Poly1305

from bestofn_swarm.wire import keyspace, names

MAGIC = b"BL"
VERSION = 1
HEADER = struct.Struct(">2sBBBI8s8sQ")
HEADER_BYTES = HEADER.size  # 33
TAG_BYTES = 16
NONCE_BYTES = 8
# The largest UDP payload over IPv4: a frame always fits one datagram.
MAX_FRAME_BYTES = 65507
MAX_BODY_BYTES = MAX_FRAME_BYTES - HEADER_BYTES - TAG_BYTES
MIN_FRAME_BYTES = HEADER_BYTES + TAG_BYTES
CRC_BYTES = 4
# On a serial line: COBS adds at most one byte in 254, and the frame ends with a zero.
MAX_ENCODED_BYTES = MAX_FRAME_BYTES + CRC_BYTES + (MAX_FRAME_BYTES + CRC_BYTES + 253) // 254
DATA_HEADER = struct.Struct(">BH")  # kind, attachment length
MAX_ATTACHMENT_BYTES = 1024
PING_BODY_BYTES = 8
LINK_KEY_LABEL = b"bestofn-link"
SESSION_KEY_LABEL = b"bestofn-link-session"
NO_NONCE = bytes(NONCE_BYTES)
PING_EVERY = 0.5  # seconds between the bridge's pings, unless its welcome says otherwise
SILENCE = 3.0  # seconds of silence that end a session (before the welcome: always this)
REPLAY_WINDOW = 64  # sequence numbers behind the highest that may still arrive (reordering)

FROM_BRIDGE = 0x01
ENCRYPTED = 0x02
KNOWN_FLAGS = FROM_BRIDGE | ENCRYPTED


class FrameType(enum.IntEnum):
    HELLO = 1  # robot -> bridge: open a session (with a fresh robot nonce)
    WELCOME = 2  # bridge -> robot: the session (its own fresh nonce) and the run's settings
    DATA = 3  # a message of the run, either way
    PING = 4  # either way: answer with a PONG carrying the same 8 bytes
    PONG = 5
    BYE = 6  # either way: the session ends now (the body says why)


# What a DATA frame carries, a message on one of the robot's keys or the world's, is a
# frame code of the key table (bestofn_swarm/wire/keyspace.py ``LINK_CODES``): codes below
# 16 go to the robot, the others come from it.


class ByeReason(enum.IntEnum):
    RUN_ENDED = 1  # the run is over: the program may exit
    GOING_AWAY = 2  # this end stops (a restart, a program stopped): try again later
    REPLACED = 3  # a newer session of the same robot took over


class Refusal(enum.StrEnum):
    """Why a frame was refused: each is counted by the receiving end."""

    MALFORMED = "malformed"  # not a frame: short, bad magic, version, type, flags, body
    OVERSIZE = "oversize"  # longer than MAX_FRAME_BYTES (or its serial encoding)
    CORRUPT = "corrupt"  # serial: bad COBS or CRC
    FORGED = "forged"  # its tag does not check out under the robot's link key
    REPLAYED = "replayed"  # a sequence number (or a hello's nonce) already seen
    UNEXPECTED = "unexpected"  # authentic, but not now: another session, robot, direction
    RATE = "rate"  # over the link's rate bound


class LinkError(ValueError):
    """A frame that is refused, and why (``refusal``)."""

    def __init__(self, refusal: Refusal, message: str) -> None:
        super().__init__(message)
        self.refusal = refusal


Cipher = Literal["none", "chacha20-poly1305"]


class LinkWelcome(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """The body of a WELCOME (JSON): what the robot program needs of the run besides the
    map, which it asks the world for (``world/info``, relayed)."""

    v: Literal[1]
    run: names.Name
    root: names.Name
    cipher: Cipher  # what protects the session's frames after this one
    ping_every: Annotated[float, msgspec.Meta(gt=0.0, le=60.0)]  # seconds between pings
    silence: Annotated[float, msgspec.Meta(gt=0.0, le=600.0)]  # seconds: then the link is gone
    controller: msgspec.Raw  # the run's ControllerConfig, as one JSON object


def encode_welcome(welcome: LinkWelcome) -> bytes:
    return msgspec.json.encode(welcome)


def decode_welcome(body: bytes) -> LinkWelcome:
    try:
        return msgspec.json.decode(body, type=LinkWelcome)
    except (msgspec.DecodeError, msgspec.ValidationError) as error:
        raise LinkError(Refusal.MALFORMED, f"welcome: {error}") from None


# --- keys ----------------------------------------------------------------------------------


def link_key(robot_key: bytes) -> bytes:
    """The key that tags a robot's link frames, derived from its run key (one way: the
    bridge holds this, and cannot make the robot's run-key tags)."""
    return hmac.digest(robot_key, LINK_KEY_LABEL, hashlib.sha256)


def session_key(key: bytes, robot_nonce: bytes, bridge_nonce: bytes) -> bytes:
    """The key of one encrypted session: fresh for each pair of nonces, so sequence
    numbers (the cipher's nonces) never repeat under one key."""
    return hmac.digest(key, SESSION_KEY_LABEL + robot_nonce + bridge_nonce, hashlib.sha256)


# --- frames --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    """One link frame, decoded (its tag checked)."""

    type: FrameType
    from_bridge: bool
    robot: int
    robot_nonce: bytes
    bridge_nonce: bytes
    seq: int
    body: bytes = b""
    encrypted: bool = False

    @property
    def session(self) -> tuple[bytes, bytes]:
        return self.robot_nonce, self.bridge_nonce


@dataclass(frozen=True)
class Header:
    """A frame's header, read before its tag is checked (to find the robot's key)."""

    type: FrameType
    from_bridge: bool
    encrypted: bool
    robot: int
    robot_nonce: bytes
    bridge_nonce: bytes
    seq: int


def _header_bytes(frame: Frame) -> bytes:
    flags = (FROM_BRIDGE if frame.from_bridge else 0) | (ENCRYPTED if frame.encrypted else 0)
    return HEADER.pack(
        MAGIC,
        VERSION,
        frame.type,
        flags,
        frame.robot,
        frame.robot_nonce,
        frame.bridge_nonce,
        frame.seq,
    )


def _cipher_nonce(from_bridge: bool, seq: int) -> bytes:
    """ChaCha20-Poly1305's 12-byte nonce: the direction (u32: 1 from the bridge) and the
    sequence number (u64), both big-endian."""
    return struct.pack(">IQ", 1 if from_bridge else 0, seq)


def _tag(key: bytes, data: bytes) -> bytes:
    return hmac.digest(key, data, hashlib.sha256)[:TAG_BYTES]


def seal(frame: Frame, key: bytes, cipher_key: bytes | None = None) -> bytes:
    """The bytes of ``frame``, tagged under the link ``key`` (or, when ``frame.encrypted``,
    encrypted under ``cipher_key``, its session key)."""
    _check_frame(frame)
    header = _header_bytes(frame)
    if frame.encrypted:
        if cipher_key is None:
            raise ValueError("an encrypted frame needs its session key")
        nonce = _cipher_nonce(frame.from_bridge, frame.seq)
        return header + ChaCha20Poly1305(cipher_key).encrypt(nonce, frame.body, header)
    data = header + frame.body
    return data + _tag(key, data)


def _check_frame(frame: Frame) -> None:
    if not 0 <= frame.robot < names.MAX_ROBOTS:
        raise ValueError(f"robot id {frame.robot} out of range")
    if len(frame.robot_nonce) != NONCE_BYTES or len(frame.bridge_nonce) != NONCE_BYTES:
        raise ValueError(f"session nonces have {NONCE_BYTES} bytes")
    if len(frame.body) > MAX_BODY_BYTES:
        raise LinkError(Refusal.OVERSIZE, f"a body of {len(frame.body)} bytes")
    if not 0 <= frame.seq < 2**64:
        raise ValueError("sequence numbers are u64")


def read_header(data: bytes) -> Header:
    """The header of ``data``, checked for form only (LinkError if it is not a frame)."""
    if len(data) > MAX_FRAME_BYTES:
        raise LinkError(Refusal.OVERSIZE, f"{len(data)} bytes, more than {MAX_FRAME_BYTES}")
    if len(data) < MIN_FRAME_BYTES:
        raise LinkError(Refusal.MALFORMED, f"{len(data)} bytes, fewer than {MIN_FRAME_BYTES}")
    magic, version, kind, flags, robot, robot_nonce, bridge_nonce, seq = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise LinkError(Refusal.MALFORMED, f"bad magic {magic!r}")
    if version != VERSION:
        raise LinkError(Refusal.MALFORMED, f"frame version {version}, not {VERSION}")
    if kind not in FrameType._value2member_map_:
        raise LinkError(Refusal.MALFORMED, f"unknown frame type {kind}")
    if flags & ~KNOWN_FLAGS:
        raise LinkError(Refusal.MALFORMED, f"unknown flags 0x{flags:02x}")
    if robot >= names.MAX_ROBOTS:
        raise LinkError(Refusal.MALFORMED, f"robot id {robot} out of range")
    return Header(
        FrameType(kind),
        bool(flags & FROM_BRIDGE),
        bool(flags & ENCRYPTED),
        robot,
        robot_nonce,
        bridge_nonce,
        seq,
    )


def open_frame(data: bytes, key: bytes, cipher_key: bytes | None = None) -> Frame:
    """The frame in ``data`` once its tag checks out under the link ``key`` (or, if it is
    encrypted, it decrypts under ``cipher_key``); LinkError otherwise."""
    header = read_header(data)
    head = data[:HEADER_BYTES]
    if header.encrypted:
        if cipher_key is None:
            raise LinkError(Refusal.UNEXPECTED, "an encrypted frame outside an encrypted session")
        nonce = _cipher_nonce(header.from_bridge, header.seq)
        try:
            body = ChaCha20Poly1305(cipher_key).decrypt(nonce, data[HEADER_BYTES:], head)
        except InvalidTag:
            raise LinkError(Refusal.FORGED, "does not decrypt under the session key") from None
    else:
        body = data[HEADER_BYTES:-TAG_BYTES]
        if not hmac.compare_digest(data[-TAG_BYTES:], _tag(key, data[:-TAG_BYTES])):
            raise LinkError(Refusal.FORGED, "its tag does not check out")
    return Frame(
        header.type,
        header.from_bridge,
        header.robot,
        header.robot_nonce,
        header.bridge_nonce,
        header.seq,
        body,
        header.encrypted,
    )


# --- bodies --------------------------------------------------------------------------------


def encode_data(kind: keyspace.LinkCode, payload: bytes, attachment: bytes | None) -> bytes:
    """A DATA body: kind, the attachment's length (0: none), the attachment, the payload."""
    extra = attachment or b""
    if len(extra) > MAX_ATTACHMENT_BYTES:
        raise LinkError(Refusal.OVERSIZE, f"an attachment of {len(extra)} bytes")
    body = DATA_HEADER.pack(kind.code, len(extra)) + extra + payload
    if len(body) > MAX_BODY_BYTES:
        raise LinkError(Refusal.OVERSIZE, f"a message of {len(body)} bytes")
    return body


def decode_data(body: bytes) -> tuple[keyspace.LinkCode, bytes, bytes | None]:
    """(kind, payload, attachment or None) of a DATA body; LinkError if it is not one."""
    if len(body) < DATA_HEADER.size:
        raise LinkError(Refusal.MALFORMED, "a data body shorter than its header")
    code, length = DATA_HEADER.unpack_from(body)
    kind = keyspace.LINK_CODES.get(code)
    if kind is None:
        raise LinkError(Refusal.MALFORMED, f"unknown data kind {code}")
    if length > MAX_ATTACHMENT_BYTES:
        raise LinkError(Refusal.MALFORMED, f"an attachment of {length} bytes")
    end = DATA_HEADER.size + length
    if len(body) < end:
        raise LinkError(Refusal.MALFORMED, "the attachment runs past the body")
    attachment = body[DATA_HEADER.size : end] if length else None
    return kind, body[end:], attachment


def check_body(frame: Frame) -> None:
    """LinkError unless the body has the form its frame type requires."""
    kind, body = frame.type, frame.body
    if kind is FrameType.HELLO and (body or frame.seq or frame.bridge_nonce != NO_NONCE):
        raise LinkError(Refusal.MALFORMED, "a hello has no body, sequence or bridge nonce")
    if kind is FrameType.WELCOME and frame.seq:
        raise LinkError(Refusal.MALFORMED, "a welcome has sequence number 0")
    if kind in (FrameType.PING, FrameType.PONG) and len(body) != PING_BODY_BYTES:
        raise LinkError(Refusal.MALFORMED, f"a ping or pong carries {PING_BODY_BYTES} bytes")
    if kind is FrameType.BYE and (len(body) != 1 or body[0] not in ByeReason._value2member_map_):
        raise LinkError(Refusal.MALFORMED, "a bye carries one known reason byte")
    if kind in (FrameType.DATA, FrameType.PING, FrameType.PONG, FrameType.BYE) and not frame.seq:
        raise LinkError(Refusal.MALFORMED, "frames of a session count from sequence number 1")
    if (kind is FrameType.HELLO and frame.from_bridge) or (
        kind is FrameType.WELCOME and not frame.from_bridge
    ):
        raise LinkError(Refusal.UNEXPECTED, f"a {kind.name.lower()} in the wrong direction")


# --- replays -------------------------------------------------------------------------------


@dataclass
class ReplayWindow:
    """Sequence numbers seen in one direction of one session: each is taken once, and one
    more than REPLAY_WINDOW behind the highest is refused (the anti-replay window of IPsec
    and DTLS), so a datagram that overtook another does not cost the later one."""

    highest: int = 0
    seen: int = 0  # bit i: highest - i was seen

    def refuses(self, seq: int) -> str | None:
        if seq > self.highest:
            return None
        behind = self.highest - seq
        if behind >= REPLAY_WINDOW:
            return f"sequence number {seq} is too far behind {self.highest}"
        if self.seen >> behind & 1:
            return f"sequence number {seq} was already taken"
        return None

    def admit(self, frame: Frame, encrypted: bool) -> None:
        """The checks every frame of an open session passes at either end, in this order:
        protected as the session is, and its sequence number not taken before (it is then
        taken). LinkError otherwise."""
        if frame.encrypted != encrypted:
            raise LinkError(Refusal.UNEXPECTED, "not protected as the session is")
        refused = self.refuses(frame.seq)
        if refused is not None:
            raise LinkError(Refusal.REPLAYED, refused)
        self.take(frame.seq)

    def take(self, seq: int) -> None:
        if seq > self.highest:
            shift = seq - self.highest
            self.seen = ((self.seen << shift) | 1) & ((1 << REPLAY_WINDOW) - 1)
            self.highest = seq
        else:
            self.seen |= 1 << (self.highest - seq)


@dataclass
class RecentNonces:
    """The last few hello nonces of one robot, so that a recorded hello replayed later is
    refused (a program makes a fresh nonce for each session)."""

    size: int = 64
    nonces: list[bytes] = field(default_factory=list)

    def __contains__(self, nonce: object) -> bool:
        return nonce in self.nonces

    def add(self, nonce: bytes) -> None:
        self.nonces.append(nonce)
        del self.nonces[: -self.size]


# --- serial framing ------------------------------------------------------------------------


def crc32(data: bytes) -> bytes:
    """CRC-32 (ISO-HDLC, as zlib and Ethernet), big-endian."""
    return zlib.crc32(data).to_bytes(CRC_BYTES, "big")


def serial_encode(frame: bytes) -> bytes:
    """A frame as it goes on a serial line: COBS of the frame and its CRC, then a zero."""
    return bytes(cobs.encode(frame + crc32(frame))) + b"\0"


def serial_decode(chunk: bytes) -> bytes:
    """The frame in one zero-delimited chunk (without the zero); LinkError if the chunk is
    corrupt."""
    if len(chunk) > MAX_ENCODED_BYTES:
        raise LinkError(Refusal.OVERSIZE, f"{len(chunk)} bytes before the next zero")
    try:
        decoded = bytes(cobs.decode(chunk))
    except cobs.DecodeError as error:
        raise LinkError(Refusal.CORRUPT, f"not COBS: {error}") from None
    if len(decoded) < CRC_BYTES:
        raise LinkError(Refusal.CORRUPT, "shorter than its CRC")
    frame, check = decoded[:-CRC_BYTES], decoded[-CRC_BYTES:]
    if crc32(frame) != check:
        raise LinkError(Refusal.CORRUPT, "its CRC does not match")
    return frame


@dataclass
class Deframer:
    """Cuts a serial byte stream into frames at each zero byte. Holds at most
    MAX_ENCODED_BYTES: past that, bytes are dropped until the next zero (one refusal)."""

    buffer: bytearray = field(default_factory=bytearray)
    overflowed: bool = False

    @property
    def receiving(self) -> bool:
        """Whether a frame is under way: bytes since the last zero."""
        return bool(self.buffer) or self.overflowed

    def feed(self, data: bytes) -> list[bytes | LinkError]:
        """The frames (and the refusals) that ``data`` completes, in order."""
        found: list[bytes | LinkError] = []
        start = 0
        while True:
            end = data.find(b"\0", start)
            piece = data[start:] if end < 0 else data[start:end]
            if not self.overflowed:
                self.buffer += piece
                if len(self.buffer) > MAX_ENCODED_BYTES:
                    self.overflowed = True
                    self.buffer.clear()
            if end < 0:
                return found
            if self.overflowed:
                found.append(LinkError(Refusal.OVERSIZE, "a frame longer than the limit"))
            elif self.buffer:  # consecutive zeros are idle fill
                try:
                    found.append(serial_decode(bytes(self.buffer)))
                except LinkError as error:
                    found.append(error)
            self.buffer.clear()
            self.overflowed = False
            start = end + 1


# --- addresses -----------------------------------------------------------------------------

DEFAULT_BAUD = 115200
Transport = Literal["udp", "serial"]


@dataclass(frozen=True)
class LinkAddress:
    """Where a link goes: ``udp://HOST:PORT`` or ``serial:PATH[@BAUD]``."""

    transport: Transport
    host: str = ""
    port: int = 0
    path: str = ""
    baud: int = DEFAULT_BAUD

    def __str__(self) -> str:
        if self.transport == "udp":
            host = f"[{self.host}]" if ":" in self.host else self.host
            return f"udp://{host}:{self.port}"
        return f"serial:{self.path}@{self.baud}"


def parse_address(text: str) -> LinkAddress:
    """The link address ``text`` names; ValueError saying what is wrong otherwise."""
    if text.startswith("udp://"):
        rest = text[len("udp://") :]
        host, colon, port = rest.rpartition(":")
        host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        if not colon or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
            raise ValueError(f"{text!r}: a UDP link is udp://HOST:PORT")
        return LinkAddress("udp", host=host, port=int(port))
    if text.startswith("serial:"):
        path, at, baud = text[len("serial:") :].rpartition("@")
        if not at:
            path, baud = baud, str(DEFAULT_BAUD)
        if not path or not baud.isdigit() or not 50 <= int(baud) <= 10_000_000:
            raise ValueError(f"{text!r}: a serial link is serial:PATH[@BAUD]")
        return LinkAddress("serial", path=path, baud=int(baud))
    raise ValueError(f"{text!r}: a link is udp://HOST:PORT or serial:PATH[@BAUD]")
