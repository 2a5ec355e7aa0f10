"""The run's table of message kinds: every key of a run, puts, queries and liveliness tokens,
what it carries, who speaks on it and who hears it, its code on a robot's link and how a
recording keeps it. Everything else is derived from this table: the keys themselves
(``Keys``), the decoding of a sample (``open_sample``), what a robot, a beacon, the world,
the launcher, the recorder and the views take in and send, the link's frame codes, Zenoh's
access control (``deploy/security/zenoh_acl.py``), the C robot's header
(``c_robot/src/kinds.h``, ``python -m bestofn_swarm.wire.keyspace --c-header``) and the
key table of docs/protocol.md. A new kind of message is one row here.

A key is ``<root>/<run>/`` then the chunks of its pattern; a placeholder chunk names a
robot (``{robot}``: its id in decimal, one spelling per id), the lead robot of a hosting
process (``{lead}``), a beacon (``{beacon}``), a radio sender (``{sender}``: a robot or a
beacon), a process (``{process}``) or a world server's instance (``{instance}``).

The speaker is whose run key tags every sample on the key (``bestofn_swarm/wire/auth.py``):
the world server tags what it sends a robot with *that robot's* key, and what it
publishes for everyone with its own. So the speaker of ``robot/<id>/sense`` is robot
``<id>``'s key (sealed by the world), and the publisher is the world: both columns are
here.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Final

from bestofn_swarm.wire import auth, batch, names, protocol


class Party(StrEnum):
    """Who publishes on a key, whose key tags it, or who hears it."""

    WORLD = "world"  # the world server
    ROBOT = "robot"  # the robot the key names
    HOST = "host"  # the process hosting the robots lead..last (its host identity)
    BEACON = "beacon"  # the beacon the key names
    SENDER = "sender"  # the robot or beacon the key names, as a radio sender
    RECEIVER = "receiver"  # the robot a radio delivery is for (its key tags it)
    BRIDGE = "bridge"  # the bridge to robots outside the emulator
    LAUNCHER = "launcher"  # swarm run (or whoever follows a run: swarm follow)
    RECORDER = "recorder"  # the recorder (and what reads a recording: report, replay)
    VIEWER = "viewer"  # the live views: the page (--view) and Foxglove live
    ANY = "any"  # every process of the run


class How(StrEnum):
    """How a key is used."""

    PUT = "put"  # a publication
    QUERY = "query"  # a queryable: asked, and answered with a reply
    TOKEN = "token"  # a liveliness token: it appears, and goes


class Recorded(StrEnum):
    """How a recording keeps a kind's samples (world_server/recording/records.py)."""

    MESSAGE = "message"  # its JSON payload, schema bestofn.<message type>
    RADIO = "radio"  # {"meta": <attachment>, "payload": <payload>}, schema bestofn.<record>
    IMAGE = "image"  # a camera frame, as foxglove.CompressedImage
    CHECKED = "checked"  # its tag checked, not kept (the same message on another key)
    BATCH = "batch"  # unpacked into its robots' own messages


@dataclass(frozen=True, eq=False)
class KeyKind:
    """One key pattern of the protocol: one object per kind, compared and hashed by identity
    (a tick looks kinds up in dictionaries thousands of times)."""

    name: str  # the kind's name: "sense", "radio_rx", ...
    pattern: tuple[str, ...]  # the chunks after <root>/<run>/
    how: How
    message: Any  # the payload's type (a query: its reply's); None: not JSON (a PNG, a batch)
    metadata: Any  # the attachment's type after the tag; None: no metadata
    publisher: Party  # who puts on it, answers it (a query) or declares it (a token)
    speaker: Party | None  # whose key tags it; None: not tagged
    hearers: frozenset[Party]  # who subscribes to it, asks it (a query) or watches it
    about: str
    # Its frame codes on a robot's link (bestofn_swarm/link/core/codec.py): the message
    # (a query: the question), a query's reply and error answer, a token that went.
    link: int | None = None
    link_reply: int | None = None
    link_error: int | None = None
    link_gone: int | None = None
    recorded: Recorded | None = None  # None: a recording leaves it out
    record: Any = None  # Recorded.RADIO: the record type
    names_field: str | None = None  # the message's field that must equal the key's robot
    link_name: str = ""  # its name on the link (LinkCode.name), in upper case
    # Tagged for everyone: besides its speaker's tag, its metadata (protocol.EndingSeals)
    # holds a tag with each robot's key and with the bridge's, for the processes that hold
    # neither the speaker's key nor the run secret (``seal_for_everyone``).
    for_everyone: bool = False

    @property
    def placeholder(self) -> str | None:
        """The kind's one placeholder chunk (``{robot}`` ...), or None."""
        found = [chunk for chunk in self.pattern if chunk.startswith("{")]
        return found[0] if found else None

    @property
    def label(self) -> str:
        """Its keys for every robot, beacon or process, as a reader names them
        (``robot/*/sense``)."""
        return "/".join("*" if chunk.startswith("{") else chunk for chunk in self.pattern)

    @property
    def schema(self) -> str | None:
        """The MCAP schema name of its recorded samples; None if not recorded as a sample."""
        if self.recorded is Recorded.MESSAGE:
            return f"bestofn.{self.message.__name__}"
        if self.recorded is Recorded.RADIO:
            return f"bestofn.{self.record.__name__}"
        if self.recorded is Recorded.IMAGE:
            return "foxglove.CompressedImage"
        return None

    @property
    def record_type(self) -> Any:
        """The type a recorded sample decodes as (None for an image or what is not kept)."""
        if self.recorded is Recorded.MESSAGE:
            return self.message
        if self.recorded is Recorded.RADIO:
            return self.record
        return None


def _kind(name: str, pattern: str, how: How, message: Any, **rest: Any) -> KeyKind:
    rest.setdefault("link_name", name.upper())
    return KeyKind(name, tuple(pattern.split("/")), how, message, **rest)


_W, _R, _H, _B = Party.WORLD, Party.ROBOT, Party.HOST, Party.BEACON
_S, _RX, _BR, _L = Party.SENDER, Party.RECEIVER, Party.BRIDGE, Party.LAUNCHER
_REC, _V, _ANY = Party.RECORDER, Party.VIEWER, Party.ANY
_FOLLOWERS = frozenset({_L, _REC, _V})  # the launcher and the observers


# fmt: off
INFO: Final = _kind(
    "info", "world/info", How.QUERY, protocol.WorldInfo, metadata=None, publisher=_W,
    speaker=_W, hearers=frozenset({_R, _B, _BR, _L, _V}), link=19, link_reply=4, link_error=5,
    link_name="INFO",
    about="the map a robot is given; the query's payload: empty, or a world instance")
STATS: Final = _kind(
    "stats", "world/stats", How.QUERY, protocol.WorldState, metadata=None, publisher=_W,
    speaker=_W, hearers=frozenset({_L}), about="the world's counters now")
JOIN: Final = _kind(
    "join", "world/join", How.QUERY, protocol.JoinReply, metadata=None, publisher=_W,
    speaker=_W, hearers=frozenset({_R}), about="an id for a robot started with --id auto")
CLOCK: Final = _kind(
    "clock", "world/clock", How.PUT, protocol.Clock, metadata=None, publisher=_W, speaker=_W,
    hearers=_FOLLOWERS, recorded=Recorded.MESSAGE,
    about="the tick and sim time, each tick (while anyone subscribes)")
STATE: Final = _kind(
    "state", "world/state", How.PUT, protocol.WorldState, metadata=None, publisher=_W,
    speaker=_W, hearers=_FOLLOWERS, recorded=Recorded.MESSAGE,
    about="every pose and the world's counters, every --state-every ticks")
SENSE: Final = _kind(
    "sense", "robot/{robot}/sense", How.PUT, protocol.Sense, metadata=None, publisher=_W,
    speaker=_R, hearers=frozenset({_R, _REC}), link=1, recorded=Recorded.MESSAGE,
    about="one robot's senses of a tick")
CAMERA: Final = _kind(
    "camera", "robot/{robot}/camera", How.PUT, None, metadata=protocol.CameraMeta,
    publisher=_W, speaker=_R, hearers=frozenset({_R, _REC}), link=2, recorded=Recorded.IMAGE,
    about="one robot's camera frame (PNG) of a tick")
ACT: Final = _kind(
    "act", "robot/{robot}/act", How.PUT, protocol.Act, metadata=None, publisher=_R,
    speaker=_R, hearers=frozenset({_W, _REC}), link=16, recorded=Recorded.MESSAGE,
    about="one robot's answer to a tick")
STATUS: Final = _kind(
    "status", "robot/{robot}/status", How.PUT, protocol.Status, metadata=None, publisher=_R,
    speaker=_R, hearers=_FOLLOWERS | {_W}, link=18, recorded=Recorded.MESSAGE,
    names_field="id", about="one robot's state, when it changes (the world ends the run by it)")
HOST_SENSE: Final = _kind(
    "host_sense", "host/{lead}/sense", How.PUT, batch.SenseBatch, metadata=None, publisher=_W,
    speaker=_H, hearers=frozenset({_H, _REC}), recorded=Recorded.BATCH,
    about="the senses of every robot a process hosts, one batch a tick")
HOST_ACT: Final = _kind(
    "host_act", "host/{lead}/act", How.PUT, batch.ActBatch, metadata=None, publisher=_H,
    speaker=_H, hearers=frozenset({_W, _REC}), recorded=Recorded.BATCH,
    about="the acts of the robots a process hosts, one batch a tick")
BEACON_CLOCK: Final = _kind(
    "beacon_clock", "beacon/{beacon}/clock", How.PUT, protocol.Clock, metadata=None,
    publisher=_W, speaker=_W, hearers=frozenset({_B, _REC}), recorded=Recorded.CHECKED,
    about="the clock of the ticks a beacon answers, sent to it alone")
ACK: Final = _kind(
    "ack", "beacon/{beacon}/ack", How.PUT, protocol.Ack, metadata=None, publisher=_B,
    speaker=_B, hearers=frozenset({_W, _L, _REC}), recorded=Recorded.MESSAGE,
    about="a beacon's answer to a tick it answers")
RADIO_TX: Final = _kind(
    "radio_tx", "radio/tx/{sender}", How.PUT, protocol.RadioPayload,
    metadata=protocol.RadioTxMeta, publisher=_S, speaker=_S, hearers=frozenset({_W, _REC}),
    link=17, recorded=Recorded.RADIO, record=protocol.RadioTxRecord,
    about="a radio message for the medium")
RADIO_RX: Final = _kind(
    "radio_rx", "radio/rx/{robot}", How.PUT, protocol.RadioPayload,
    metadata=protocol.RadioRxMeta, publisher=_W, speaker=_RX,
    hearers=frozenset({_R, _REC, _V}), link=3, recorded=Recorded.RADIO,
    record=protocol.RadioRxRecord, about="a radio message the medium delivers to one robot")
LINK: Final = _kind(
    "link", "link/{robot}/stats", How.PUT, protocol.LinkStats, metadata=None, publisher=_BR,
    speaker=_BR, hearers=_FOLLOWERS | {_W}, recorded=Recorded.MESSAGE, names_field="robot",
    about="the link of a robot outside the emulator, each second and on change")
LOG: Final = _kind(
    "log", "log/{process}", How.PUT, protocol.LogLine, metadata=None, publisher=_L,
    speaker=_L, hearers=frozenset({_REC}), recorded=Recorded.MESSAGE,
    about="a process's log lines, relayed for the recording")
RECORDER_FINISH: Final = _kind(
    "recorder_finish", "recorder/finish", How.QUERY, None, metadata=None, publisher=_REC,
    speaker=None, hearers=frozenset({_L}),
    about="asked with the run summary (JSON); answered once the recording is on disk")
VIEWER_FINISH: Final = _kind(
    "viewer_finish", "viewer/finish", How.QUERY, None, metadata=None, publisher=_V,
    speaker=None, hearers=frozenset({_L}),
    about="asked with the run summary (JSON); answered once every page was told the ending")
ENDING: Final = _kind(
    "ending", "world/ending", How.PUT, protocol.RunEnding, metadata=protocol.EndingSeals,
    publisher=_W, speaker=_W, hearers=frozenset({_ANY}), recorded=Recorded.MESSAGE,
    for_everyone=True,
    about="how the run ended, once, with its summary: every process of the run exits on it")
PACE: Final = _kind(
    "pace", "viewer/pace", How.PUT, protocol.Pace, metadata=None, publisher=_V, speaker=_V,
    hearers=frozenset({_W, _L, _REC}), recorded=Recorded.MESSAGE,
    about="the live page's pause, play and speed; a run held for the page waits for play")
ALIVE_WORLD: Final = _kind(
    "alive_world", "alive/world/{instance}", How.TOKEN, None, metadata=None, publisher=_W,
    speaker=None, hearers=frozenset({_R, _B, _BR, _L}), link=6, link_gone=7, link_name="WORLD",
    about="a world server is up (its instance)")
ALIVE_ROBOT: Final = _kind(
    "alive_robot", "alive/robot/{robot}", How.TOKEN, None, metadata=None, publisher=_R,
    speaker=None, hearers=frozenset({_W, _L}), about="a robot's controller is up")
ALIVE_BEACON: Final = _kind(
    "alive_beacon", "alive/beacon/{beacon}", How.TOKEN, None, metadata=None, publisher=_B,
    speaker=None, hearers=frozenset({_W, _L}), about="a beacon is up")
ALIVE_RECORDER: Final = _kind(
    "alive_recorder", "alive/recorder/{process}", How.TOKEN, None, metadata=None,
    publisher=_REC, speaker=None, hearers=frozenset({_L}), about="the recorder is up")
ALIVE_VIEWER: Final = _kind(
    "alive_viewer", "alive/viewer/{process}", How.TOKEN, None, metadata=None, publisher=_V,
    speaker=None, hearers=frozenset({_L}), about="the live page is up")
ALIVE_FOXGLOVE: Final = _kind(
    "alive_foxglove", "alive/foxglove/{process}", How.TOKEN, None, metadata=None,
    publisher=_V, speaker=None, hearers=frozenset({_L}), about="Foxglove live is up")
ALIVE_BRIDGE: Final = _kind(
    "alive_bridge", "alive/bridge/{process}", How.TOKEN, None, metadata=None, publisher=_BR,
    speaker=None, hearers=frozenset({_L}), about="the bridge to robots outside is up")
# fmt: on

KINDS: tuple[KeyKind, ...] = (
    INFO,
    STATS,
    JOIN,
    CLOCK,
    STATE,
    SENSE,
    CAMERA,
    ACT,
    STATUS,
    HOST_SENSE,
    HOST_ACT,
    BEACON_CLOCK,
    ACK,
    RADIO_TX,
    RADIO_RX,
    LINK,
    LOG,
    RECORDER_FINISH,
    VIEWER_FINISH,
    ENDING,
    PACE,
    ALIVE_WORLD,
    ALIVE_ROBOT,
    ALIVE_BEACON,
    ALIVE_RECORDER,
    ALIVE_VIEWER,
    ALIVE_FOXGLOVE,
    ALIVE_BRIDGE,
)
BY_NAME: dict[str, KeyKind] = {kind.name: kind for kind in KINDS}
# The liveliness token of each role a process plays (names.Role), by role.
TOKEN_OF: dict[names.Role, KeyKind] = {
    names.Role(kind.pattern[1]): kind for kind in KINDS if kind.how is How.TOKEN
}


# --- the link's frame codes ----------------------------------------------------------


class Part(StrEnum):
    """Which part of a kind a link frame carries."""

    MESSAGE = "message"  # a put (a query: the question; a token: it appeared)
    REPLY = "reply"  # a query's answer
    ERROR = "error"  # a query's error answer (its text)
    GONE = "gone"  # a token that went


@dataclass(frozen=True)
class LinkCode:
    """A frame code of a robot's link: the kind and part it carries, and its direction."""

    code: int
    kind: KeyKind
    part: Part

    @property
    def name(self) -> str:
        """Its name on the link: ``SENSE``, ``INFO_QUERY``, ``INFO_REPLY``, ``WORLD_UP``,
        ``WORLD_DOWN`` ... (docs/protocol.md; the C robot's ``K_`` names)."""
        kind = self.kind
        if self.part is Part.MESSAGE:
            if kind.how is How.QUERY:
                return f"{kind.link_name}_QUERY"
            return f"{kind.link_name}_UP" if kind.how is How.TOKEN else kind.link_name
        suffix = {Part.REPLY: "REPLY", Part.ERROR: "ERROR", Part.GONE: "DOWN"}[self.part]
        return f"{kind.link_name}_{suffix}"

    @property
    def to_robot(self) -> bool:
        """Whether the world's side sends it to the robot (else the robot sends it)."""
        if self.part is not Part.MESSAGE:
            return True
        return self.kind.publisher not in (Party.ROBOT, Party.SENDER) and self.kind.how is not (
            How.QUERY
        )


def _link_codes() -> dict[int, LinkCode]:
    codes: dict[int, LinkCode] = {}
    for kind in KINDS:
        for code, part in (
            (kind.link, Part.MESSAGE),
            (kind.link_reply, Part.REPLY),
            (kind.link_error, Part.ERROR),
            (kind.link_gone, Part.GONE),
        ):
            if code is not None:
                if code in codes:
                    raise ValueError(f"link code {code} is {codes[code].kind.name}'s already")
                codes[code] = LinkCode(code, kind, part)
    return codes


LINK_CODES: dict[int, LinkCode] = _link_codes()
_LINKS: dict[tuple[KeyKind, Part], LinkCode] = {(c.kind, c.part): c for c in LINK_CODES.values()}


def link(kind: KeyKind, part: Part = Part.MESSAGE) -> LinkCode:
    """The link frame code of ``kind``'s ``part``."""
    return _LINKS[(kind, part)]


TO_ROBOT: frozenset[int] = frozenset(code for code, found in LINK_CODES.items() if found.to_robot)
FROM_ROBOT: frozenset[int] = frozenset(LINK_CODES) - TO_ROBOT


# --- keys ----------------------------------------------------------------------------


class Keys:
    """The keys of one swarm: ``<root>/<run>/`` then a kind's pattern (docs/protocol.md)."""

    def __init__(self, run: str, root: str = protocol.DEFAULT_ROOT) -> None:
        names.check_name(root, "root")
        names.check_name(run, "run id")
        self.root = root
        self.run = run
        self.prefix = f"{root}/{run}"
        # Each kind's key as the text before and after its placeholder: a tick builds
        # thousands of keys, as fast as an f-string.
        self._parts: dict[str, tuple[str, str]] = {}
        for kind in KINDS:
            head, _, tail = "/".join(kind.pattern).partition(kind.placeholder or "\0")
            self._parts[kind.name] = (f"{self.prefix}/{head}", tail)

    def of(self, kind: KeyKind, ident: int | str | None = None) -> str:
        """The key of ``kind`` for the robot, beacon, sender or process ``ident`` (``*``:
        for every one)."""
        head, tail = self._parts[kind.name]
        if ident is None:
            if kind.placeholder is not None:
                raise ValueError(f"the key of {kind.name} names a {kind.placeholder}")
            return head
        return f"{head}{ident}{tail}"

    def every(self, kind: KeyKind) -> str:
        """The key expression of ``kind`` for every robot, beacon, sender or process."""
        return self.of(kind, "*") if kind.placeholder is not None else self.of(kind)

    def token(self, role: names.Role, ident: int | str) -> str:
        """The liveliness token of a process playing ``role``."""
        return self.of(TOKEN_OF[role], ident)

    def ident_of(self, kind: KeyKind, key: str) -> str | None:
        """The placeholder chunk ``key`` holds if it is a key of ``kind`` (a key without a
        placeholder gives ""), else None. It does not check that the chunk is a name."""
        head, tail = self._parts[kind.name]
        if kind.placeholder is None:
            return "" if key == head else None
        if not (key.startswith(head) and key.endswith(tail)) or len(key) <= len(head) + len(tail):
            return None
        chunk = key[len(head) : len(key) - len(tail)]
        return None if "/" in chunk else chunk

    def robot_of(self, kind: KeyKind, key: str) -> int | None:
        """The robot a key of ``kind`` names, or None if it is not such a key."""
        chunk = self.ident_of(kind, key)
        return None if chunk is None else names.robot_of_name(chunk)

    @property
    def all(self) -> str:
        """Every key of the run."""
        return f"{self.prefix}/**"

    @property
    def all_tokens(self) -> str:
        """Every liveliness token of the run."""
        return f"{self.prefix}/{ALIVE_WORLD.pattern[0]}/**"


@dataclass(frozen=True)
class Classified:
    """A key of the run, read: its kind and the name its placeholder held (or None)."""

    kind: KeyKind
    ident: str | None  # the robot id, lead, beacon name, sender or process it names

    @property
    def robot(self) -> int | None:
        """The robot the key names (a robot's key, a host's lead, a robot sender)."""
        return None if self.ident is None else names.robot_of_name(self.ident)

    @property
    def speaker(self) -> str | None:
        """The identity whose key tags the key (bestofn_swarm/wire/names.py); None for a
        host's batch, whose identity needs the last robot the batch gives, and for what is
        not tagged."""
        return speaker_of(self.kind, self.ident)


def speaker_of(kind: KeyKind, ident: str | None) -> str | None:
    """The identity whose key tags a key of ``kind`` naming ``ident``."""
    party = kind.speaker
    if party is Party.WORLD:
        return names.WORLD
    if party is Party.BRIDGE:
        return names.BRIDGE
    if party is Party.LAUNCHER:
        return names.LAUNCHER
    if party is Party.VIEWER:
        return names.VIEWER
    if party is None or ident is None:
        return None
    if party in (Party.ROBOT, Party.RECEIVER):
        return names.robot_identity(int(ident))
    if party is Party.BEACON:
        return names.beacon_identity(ident)
    if party is Party.SENDER:
        return names.sender_identity(ident)
    return None  # a host's identity needs its last robot, which the batch gives


def classify(keys: Keys, key: str) -> Classified | None:
    """The kind of ``key`` and the name it gives, or None for a key outside the table (or
    one whose name no robot, beacon or process of a run can have)."""
    if not key.startswith(keys.prefix + "/"):
        return None
    chunks = key[len(keys.prefix) + 1 :].split("/")
    for kind in KINDS:
        if len(chunks) != len(kind.pattern):
            continue
        ident = None
        for chunk, expected in zip(chunks, kind.pattern, strict=True):
            if expected.startswith("{"):
                if not _names_one(expected, chunk):
                    break
                ident = chunk
            elif chunk != expected:
                break
        else:
            return Classified(kind, ident)
    return None


def ident_in(kind: KeyKind, key: str) -> str | None:
    """The placeholder chunk of ``key`` read as a key of ``kind`` whatever its root and run
    (a recording's topic): "" for a kind without one, None if ``key`` is not such a key."""
    chunks = key.split("/")
    if len(chunks) < len(kind.pattern) + 2:
        return None
    ident = ""
    for chunk, expected in zip(chunks[-len(kind.pattern) :], kind.pattern, strict=True):
        if expected.startswith("{"):
            if not _names_one(expected, chunk):
                return None
            ident = chunk
        elif chunk != expected:
            return None
    return ident


def _names_one(placeholder: str, chunk: str) -> bool:
    if placeholder in ("{robot}", "{lead}"):
        return names.robot_of_name(chunk) is not None
    if placeholder == "{beacon}":
        return names.is_beacon_name(chunk)
    if placeholder == "{sender}":
        return names.sender_identity(chunk) is not None
    return names.is_name(chunk)  # {process}, {instance}


# --- the table, asked ----------------------------------------------------------------


def published_by(*parties: Party) -> tuple[KeyKind, ...]:
    """The kinds any of ``parties`` puts."""
    return tuple(kind for kind in KINDS if kind.how is How.PUT and kind.publisher in parties)


def heard_by(*parties: Party, how: How = How.PUT) -> tuple[KeyKind, ...]:
    """The kinds any of ``parties`` hears (subscribes to, asks, or watches: ``how``)."""
    return tuple(kind for kind in KINDS if kind.how is how and not kind.hearers.isdisjoint(parties))


def inputs_of(*parties: Party) -> tuple[KeyKind, ...]:
    """What the world puts for ``parties`` alone: the kinds it tags with their keys, or
    sends on keys that name them (a beacon's clock)."""
    return tuple(
        kind
        for kind in KINDS
        if kind.how is How.PUT
        and kind.publisher is Party.WORLD
        and (kind.speaker in parties or (Party.BEACON in parties and "{beacon}" in kind.pattern))
    )


def keys_for(keys: Keys, kinds: Iterable[KeyKind], ident: int | str = "*") -> list[str]:
    """The keys of ``kinds`` for one robot, beacon or process (``*``: for every one)."""
    return [keys.of(kind, ident) if kind.placeholder else keys.of(kind) for kind in kinds]


def recorded_kinds() -> tuple[KeyKind, ...]:
    """The kinds a recording keeps as samples of their own."""
    return tuple(kind for kind in KINDS if kind.schema is not None)


def by_schema() -> dict[str, KeyKind]:
    """The kind of each schema a recording holds (``bestofn.Sense`` -> SENSE ...)."""
    found: dict[str, KeyKind] = {}
    for kind in recorded_kinds():
        assert kind.schema is not None
        found.setdefault(kind.schema, kind)  # Clock: world/clock's (a beacon's is not kept)
    return found


# --- what a sample holds -------------------------------------------------------------


class SampleError(ValueError):
    """A sample that is not a valid message of its key (its tag, its decoding, or the robot
    it names)."""


@dataclass(frozen=True)
class Opened:
    """A sample of the run, believed: its kind, the name its key gives, the message its
    payload holds (None: not JSON) and its metadata (None: none)."""

    kind: KeyKind
    ident: str | None
    message: Any
    meta: Any = None

    @property
    def robot(self) -> int | None:
        return None if self.ident is None else names.robot_of_name(self.ident)


def open_message(
    kind: KeyKind, ident: str | None, payload: bytes, metadata: bytes | None
) -> Opened:
    """The one gate of a sample's contents, live or recorded: its payload decoded as its
    kind's message and its metadata as its kind's (both already freed of any tag), and the
    robot it names checked against the key's. Raises SampleError."""
    try:
        if kind.message is None:
            message: Any = None
        elif kind is RADIO_TX or kind is RADIO_RX:
            message = protocol.decode_radio(payload)
        else:
            message = protocol.decode(payload, kind.message)
        meta = None
        if kind.metadata is not None:
            if not metadata:
                raise SampleError(f"{kind.name} without metadata")
            meta = protocol.decode(metadata, kind.metadata)
    except protocol.ProtocolError as error:
        raise SampleError(f"{kind.name}: {error}") from None
    if kind.names_field is not None and ident is not None:
        named = getattr(message, kind.names_field)
        if str(named) != ident:
            raise SampleError(f"{kind.name} of robot {named} on the key of {ident}")
    return Opened(kind, ident, message, meta)


def open_sample(
    keys: Keys,
    key: str,
    payload: bytes,
    attachment: bytes | None,
    *,
    keyring: auth.Keyring | None,
    kinds: frozenset[KeyKind] | None = None,
) -> Opened | None:
    """The one gate of a live sample: its key read by the table (None: a key outside
    ``kinds``, or outside the table), its tag checked against its speaker's key (in a keyed
    run), then its contents (``open_message``). Raises SampleError."""
    found = classify(keys, key)
    if found is None or (kinds is not None and found.kind not in kinds):
        return None
    identity = found.speaker
    if identity is None:
        raise SampleError(f"{key}: not a key a single speaker tags")
    try:
        if found.kind.for_everyone and keyring is not None and not keyring.holds(identity):
            metadata: bytes | None = _open_own_tag(keyring, key, payload, attachment)
        else:
            metadata = auth.unseal(keyring, identity, key, payload, attachment)
    except auth.AuthError as error:
        raise SampleError(f"{key}: {identity}: {error}") from None
    return open_message(found.kind, found.ident, payload, metadata)


def seal_for_everyone(
    keyring: auth.Keyring | None, key: str, payload: bytes, robots: int, identity: str
) -> bytes:
    """The attachment of a sample of a kind tagged for everyone (``KeyKind.for_everyone``),
    sent as ``identity``: its tag, then its metadata (``protocol.EndingSeals``), which holds
    its tag with the key of each robot ``0`` to ``robots - 1`` and with the bridge's. In an
    unkeyed run, the metadata alone, with no tags."""
    if keyring is None:
        return protocol.encode(protocol.EndingSeals(v=protocol.VERSION, robots=[], bridge=None))
    seals = protocol.EndingSeals(
        v=protocol.VERSION,
        robots=[
            keyring.seal(names.robot_identity(robot), key, payload).hex() for robot in range(robots)
        ],
        bridge=keyring.seal(names.BRIDGE, key, payload).hex(),
    )
    return keyring.seal(identity, key, payload, protocol.encode(seals))


def _open_own_tag(
    keyring: auth.Keyring, key: str, payload: bytes, attachment: bytes | None
) -> bytes:
    """The metadata of a sample tagged for everyone, checked by a process without its
    speaker's key: with the tag of one of its own keys (a robot's, or the bridge's).
    Raises AuthError."""
    if attachment is None or len(attachment) < auth.TAG_BYTES:
        raise auth.AuthError("no authentication tag")
    metadata = attachment[auth.TAG_BYTES :]
    try:
        seals = protocol.decode(metadata, protocol.EndingSeals)
    except protocol.ProtocolError as error:
        raise auth.AuthError(f"no tags for everyone: {error}") from None
    for identity in keyring.identities:
        role, _, ident = identity.partition("/")
        robot = names.robot_of_name(ident) if role == names.Role.ROBOT else None
        if identity == names.BRIDGE:
            tag = seals.bridge
        elif robot is not None and robot < len(seals.robots):
            tag = seals.robots[robot]
        else:
            continue
        if tag is not None:
            keyring.open(identity, key, payload, bytes.fromhex(tag))
            return metadata
    raise auth.AuthError("no tag for any key this process holds")


def open_recorded(kind: KeyKind, ident: str | None, data: bytes) -> Opened:
    """A recorded sample (``kind.recorded``: a message, or a radio record) through the same
    gate as a live one. Raises SampleError."""
    if kind.recorded is Recorded.RADIO:
        try:
            record = protocol.decode(data, kind.record)
        except protocol.ProtocolError as error:
            raise SampleError(f"{kind.name}: {error}") from None
        return Opened(kind, ident, record.payload, record.meta)
    return open_message(kind, ident, data, None)


# --- the C robot's header ------------------------------------------------------------


def c_header() -> str:
    """``c_robot/src/kinds.h``: the link's frame codes, from this table."""
    rows = [
        f"    K_{found.name} = {code}, /* {found.kind.name}: {found.part} */"
        for code, found in sorted(LINK_CODES.items())
    ]
    return "\n".join(
        [
            "/* Generated from the table of message kinds (bestofn_swarm/wire/keyspace.py) by",
            "   `python -m bestofn_swarm.wire.keyspace --c-header`: do not edit.",
            "   tests/test_keyspace.py fails when it is stale. */",
            "#ifndef KINDS_H",
            "#define KINDS_H",
            "",
            "/* What a DATA frame of the link carries (docs/protocol.md): codes below",
            "   K_FIRST_FROM_ROBOT go to the robot, the others come from it. */",
            "enum data_kind {",
            *rows,
            f"    K_FIRST_FROM_ROBOT = {min(FROM_ROBOT)}",
            "};",
            "",
            "/* Whether a DATA frame's kind is one of the link's. */",
            "static inline int kind_known(int kind) {",
            "    switch (kind) {",
            *(f"    case K_{found.name}:" for _, found in sorted(LINK_CODES.items())),
            "        return 1;",
            "    default:",
            "        return 0;",
            "    }",
            "}",
            "",
            "#endif",
            "",
        ]
    )


# --- docs/protocol.md's table of keys ------------------------------------------------

_PARTY_TEXT = {
    Party.WORLD: "world",
    Party.ROBOT: "robot",
    Party.HOST: "robot host",
    Party.BEACON: "beacon",
    Party.SENDER: "robot or beacon",
    Party.RECEIVER: "robot",
    Party.BRIDGE: "bridge",
    Party.LAUNCHER: "launcher",
    Party.RECORDER: "recorder",
    Party.VIEWER: "views",
    Party.ANY: "every process of the run",
}
_HOW_TEXT = {How.PUT: "put", How.QUERY: "query", How.TOKEN: "liveliness token"}


def _type_text(kind: KeyKind) -> str:
    message = kind.message
    if message is None:
        if kind is CAMERA:
            return "PNG image"
        return "run summary (JSON)" if kind.how is How.QUERY else ""
    if message is protocol.RadioPayload:
        return "radio payload"
    if message in (batch.SenseBatch, batch.ActBatch):
        return "batch (binary)"
    return f"`{message.__name__}`"


def markdown_table() -> str:
    """The table of keys of docs/protocol.md, from this table."""
    rows = [
        "| key | kind | from → to (a query: who answers → who asks) | payload (a query: its "
        "answer) | attachment | what |",
        "|---|---|---|---|---|---|",
    ]
    for kind in KINDS:
        key = "/".join(
            f"<{chunk[1:-1]}>" if chunk.startswith("{") else chunk for chunk in kind.pattern
        )
        hearers = ", ".join(sorted(_PARTY_TEXT[party] for party in kind.hearers))
        meta = f"`{kind.metadata.__name__}`" if kind.metadata is not None else ""
        rows.append(
            f"| `<root>/<run>/{key}` | {_HOW_TEXT[kind.how]} | {_PARTY_TEXT[kind.publisher]} → "
            f"{hearers} | {_type_text(kind)} | {meta} | {kind.about} |"
        )
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args == ["--c-header"]:
        sys.stdout.write(c_header())
        return 0
    if args == ["--markdown"]:
        sys.stdout.write(markdown_table())
        return 0
    print("usage: python -m bestofn_swarm.wire.keyspace --c-header | --markdown", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["BY_NAME", "KINDS", "Classified", "KeyKind", "Keys", "Party", "classify"]
