"""The run's key table: every key pattern, what it carries, who speaks on it, who hears it.

One table, read by everything that decides who may publish what: the recorder (which
key is which kind of record, and whose tag each sample must carry), ``swarm report``, the
live view, the launcher's follower, and the generator of Zenoh's access control rules
(``deploy/security/zenoh_acl.py``). A key is ``<root>/<run>/`` then the chunks of its
pattern; a placeholder chunk names a robot (``{robot}``: its id in decimal, one spelling
per id), the lead robot of a hosting process (``{lead}``), a beacon (``{beacon}``), a
radio sender (``{sender}``: a robot or a beacon) or a process (``{process}``).

The speaker is whose run key tags every sample on the key (``bestofn_swarm/wire/auth.py``): the
world server tags what it sends a robot with *that robot's* key, and what it publishes for
everyone with its own. So the speaker of ``robot/<id>/sense`` is robot ``<id>``'s key
(sealed by the world), and the publisher is the world: both columns are here.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from bestofn_swarm.wire import batch, names, protocol


class Party(StrEnum):
    """Who publishes on a key, or whose key tags it."""

    WORLD = "world"  # the world server
    ROBOT = "robot"  # the robot the key names
    HOST = "host"  # the process hosting the robots lead..last (its host identity)
    BEACON = "beacon"  # the beacon the key names
    SENDER = "sender"  # the robot or beacon the key names, as a radio sender
    BRIDGE = "bridge"  # the bridge to robots outside the emulator
    LAUNCHER = "launcher"  # swarm run, which relays every process's log lines
    RECEIVER = "receiver"  # the robot a radio delivery is for (its key tags it)


@dataclass(frozen=True)
class KeyKind:
    """One key pattern of the protocol."""

    name: str  # the kind's name: "sense", "radio_rx", ...
    pattern: tuple[str, ...]  # the chunks after <root>/<run>/
    message: Any  # the payload's type in protocol.py; None: not JSON (a PNG, a batch)
    metadata: Any  # the attachment's type after the tag; None: no metadata
    publisher: Party  # the process that publishes on it
    speaker: Party  # whose key tags it
    about: str


KINDS: tuple[KeyKind, ...] = (
    KeyKind("clock", ("world", "clock"), protocol.Clock, None, Party.WORLD, Party.WORLD,
            "the tick and sim time, each tick (for observers)"),
    KeyKind("state", ("world", "state"), protocol.WorldState, None, Party.WORLD, Party.WORLD,
            "every pose and the world's counters, every --state-every ticks"),
    KeyKind("sense", ("robot", "{robot}", "sense"), protocol.Sense, None, Party.WORLD,
            Party.ROBOT, "one robot's senses of a tick"),
    KeyKind("camera", ("robot", "{robot}", "camera"), None, protocol.CameraMeta, Party.WORLD,
            Party.ROBOT, "one robot's camera frame (PNG) of a tick"),
    KeyKind("act", ("robot", "{robot}", "act"), protocol.Act, None, Party.ROBOT, Party.ROBOT,
            "one robot's answer to a tick"),
    KeyKind("status", ("robot", "{robot}", "status"), protocol.Status, None, Party.ROBOT,
            Party.ROBOT, "one robot's state, when it changes"),
    KeyKind("host_sense", ("host", "{lead}", "sense"), batch.SenseBatch, None, Party.WORLD,
            Party.HOST, "the senses of every robot a process hosts, one batch a tick"),
    KeyKind("host_act", ("host", "{lead}", "act"), batch.ActBatch, None, Party.HOST,
            Party.HOST, "the acts of the robots a process hosts, one batch a tick"),
    KeyKind("beacon_clock", ("beacon", "{beacon}", "clock"), protocol.Clock, None,
            Party.WORLD, Party.WORLD, "the clock of the ticks a beacon answers"),
    KeyKind("ack", ("beacon", "{beacon}", "ack"), protocol.Ack, None, Party.BEACON,
            Party.BEACON, "a beacon's answer to a tick it answers"),
    KeyKind("radio_tx", ("radio", "tx", "{sender}"), protocol.RadioPayload,
            protocol.RadioTxMeta, Party.SENDER, Party.SENDER,
            "a radio message for the medium"),
    KeyKind("radio_rx", ("radio", "rx", "{robot}"), protocol.RadioPayload,
            protocol.RadioRxMeta, Party.WORLD, Party.RECEIVER,
            "a radio message the medium delivers to one robot"),
    KeyKind("link", ("link", "{robot}", "stats"), protocol.LinkStats, None, Party.BRIDGE,
            Party.BRIDGE, "the link of a robot outside the emulator"),
    KeyKind("log", ("log", "{process}"), protocol.LogLine, None, Party.LAUNCHER,
            Party.LAUNCHER, "a process's log lines, relayed for the recording"),
)  # fmt: skip
BY_NAME: dict[str, KeyKind] = {kind.name: kind for kind in KINDS}


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
        """The identity whose key tags the key (bestofn_swarm/wire/names.py); None for a host's
        batch, whose identity needs the last robot the batch gives."""
        party = self.kind.speaker
        if party is Party.WORLD:
            return names.WORLD
        if party is Party.BRIDGE:
            return names.BRIDGE
        if party is Party.LAUNCHER:
            return names.LAUNCHER
        assert self.ident is not None
        if party in (Party.ROBOT, Party.RECEIVER):
            return names.robot_identity(int(self.ident))
        if party is Party.BEACON:
            return names.beacon_identity(self.ident)
        if party is Party.SENDER:
            return names.sender_identity(self.ident)
        return None  # a host's identity needs its last robot, which the batch gives


def classify(keys: protocol.Keys, key: str) -> Classified | None:
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


def _names_one(placeholder: str, chunk: str) -> bool:
    if placeholder in ("{robot}", "{lead}"):
        return names.robot_of_name(chunk) is not None
    if placeholder == "{beacon}":
        return names.is_beacon_name(chunk)
    if placeholder == "{sender}":
        return names.sender_identity(chunk) is not None
    return names.is_name(chunk)  # {process}


def key_of(keys: protocol.Keys, kind: str, ident: int | str | None = None) -> str:
    """The key of ``kind`` for the robot, beacon, sender or process ``ident``."""
    chunks = [str(ident) if chunk.startswith("{") else chunk for chunk in BY_NAME[kind].pattern]
    return "/".join([keys.prefix, *chunks])


def published_by(*parties: Party) -> tuple[KeyKind, ...]:
    """The kinds any of ``parties`` publishes."""
    return tuple(kind for kind in KINDS if kind.publisher in parties)


def inputs_of(*parties: Party) -> tuple[KeyKind, ...]:
    """What the world publishes for ``parties`` alone: the kinds it tags with their keys,
    or sends on keys that name them (a beacon's clock)."""
    return tuple(
        kind
        for kind in KINDS
        if kind.publisher is Party.WORLD
        and (kind.speaker in parties or (Party.BEACON in parties and "{beacon}" in kind.pattern))
    )


def keys_for(keys: protocol.Keys, kinds: tuple[KeyKind, ...], ident: int | str = "*") -> list[str]:
    """The keys of ``kinds`` for one robot, beacon or process (``*``: for every one)."""
    return [key_of(keys, kind.name, ident) for kind in kinds]


__all__ = ["BY_NAME", "KINDS", "Classified", "KeyKind", "Party", "classify", "key_of"]
