"""What the world's coordinator is fed and what it gives back, as data (no I/O).

A transport (the Zenoh adapter in ``world_server/server``, a test) turns what arrives into
``Event``s and hands the coordinator each one with the time it is handled at; the
coordinator answers with ``Output``s, which the transport publishes, replies with, or (the
timeline of ``--trace``) stamps with its clock.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from bestofn_swarm.wire import auth, keyspace
from bestofn_swarm.wire.parcel import Encoder, Parcel


class Happening(StrEnum):
    """What reaches the coordinator that is no sample of the key table."""

    REFUSED = "refused"  # something the transport refused on its own side: counted here
    STOP = "stop"  # the process is told to stop


@dataclass(frozen=True, slots=True)
class Event:
    """What arrived: a sample of a kind the world hears (``keyspace.heard_by(Party.WORLD)``:
    an act, a host's batch of acts, a beacon's ack, a radio message), a query it answers
    (world/info, answered by the transport: its asker is present; world/stats; world/join),
    a liveliness token that appeared or went (``gone``), or a happening."""

    kind: keyspace.KeyKind | Happening
    key: str = ""  # the key expression it came on (or was asked on)
    payload: bytes = b""  # REFUSED: why, in UTF-8
    attachment: bytes | None = None
    query: object = None  # the transport's handle of a query, handed back with its reply
    arrived: float = 0.0  # when the transport took it (only when tracing)
    # The message itself, handed over by a core in the same process (the in-process
    # engine): an Act, an ActBatch, an Ack, or a radio message's RadioTxMeta (its payload
    # stays in ``payload``). It is taken without decoding or a tag, as the process's own;
    # every other check still applies. A transport never sets it: what arrives as bytes
    # is decoded and its tag checked.
    message: object = None
    gone: bool = False  # a liveliness token that went (else it appeared)


# --- outputs ----------------------------------------------------------------------------


class Publish(Parcel):
    """A message to publish, reliably (blocking rather than dropping under congestion):
    ``message`` for a core in the same process, ``payload`` and ``attachment`` (encoded
    and sealed on demand) for a transport (``bestofn_swarm.wire.parcel``)."""

    def __init__(
        self,
        key: str,
        message: Any,
        encode: Encoder,
        *,
        identity: str,
        keyring: auth.Keyring | None,
        meta: Any = None,
        meta_encode: Encoder = None,
        steady: bool = False,
        if_heard: bool = False,
    ) -> None:
        super().__init__(
            key,
            message,
            encode,
            identity=identity,
            keyring=keyring,
            meta=meta,
            meta_encode=meta_encode,
        )
        # Sent tick after tick on this key (senses, batches, the clock, the state): worth a
        # publisher kept for the key; else one put (camera frames, radio deliveries).
        self.steady = steady
        # Only for observers (world/clock): need not go out while nobody subscribes to it.
        self.if_heard = if_heard


@dataclass(frozen=True, slots=True)
class Reply:
    """The answer to a query (``Event.query``)."""

    query: object
    key: str
    payload: bytes
    attachment: bytes | None


@dataclass(frozen=True, slots=True)
class ReplyError:
    """A query refused: ``reason`` goes back to the asker."""

    query: object
    reason: bytes


class Moment(StrEnum):
    """Points in the work of a tick that ``--trace`` times (bestofn_swarm/plumbing/trace.py)."""

    OPEN_START = "open_start"  # the tick's inputs start going out
    OPENED = "opened"  # they are all out
    CLOSE_START = "close_start"  # the tick is closing
    ADVANCED = "advanced"  # the world advanced
    DELIVERED = "delivered"  # the radio deliveries are out


@dataclass(frozen=True, slots=True)
class Mark:
    """A moment of the tick's work; the transport notes when it came out (tracing only)."""

    moment: Moment


@dataclass(frozen=True, slots=True)
class Opened:
    """What the tick just opened holds (tracing only; comes just before Mark(OPENED))."""

    tick: int
    robots: int
    frames: int
    rx: int  # radio deliveries
    batched: int  # senses sent in batches


@dataclass(frozen=True, slots=True)
class Answered:
    """An answer the tick under way took: who, when it arrived, when it was handled."""

    who: str
    arrived: float
    handled: float


Output = Publish | Reply | ReplyError | Mark | Opened | Answered
# Where the coordinator puts what it gives back, one output at a time, as soon as it is
# made: a process's batch of senses leaves before the next process's is made.
Outbox = Callable[[Output], None]
