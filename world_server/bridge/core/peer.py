"""The bridge's end of one robot's link (no I/O: bytes and the time in, bytes and events out).

``LinkPeer`` welcomes the robot program's hello, takes the session once the program's
first authentic frame in it arrives (a recorded hello replayed by someone else opens
nothing: they cannot make that frame), relays its messages, pings it to measure the
link's round trip and loss, and closes the session when the program says bye or goes
quiet. Every frame is checked before anything is done with it: size, form, the tag under
the robot's link key, the session, the sequence number (each taken once), the direction,
and a rate bound; a refusal is counted by reason and never raised. On a serial line the
robot is not silent while a frame of it is arriving (``hearing``), nor while a long frame
of the bridge's is still on its way to it (``sending``): it cannot answer a ping queued
behind a map of 1000 sites, which takes 5 s at 115200 baud.

A newer session of the same robot (the program restarted, or its link came back) replaces
the old one: ``SessionClosed`` then ``SessionOpened``, so that the run sees the robot leave
and join.
"""

from __future__ import annotations

import logging
import secrets
from collections import Counter, deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.core.pacing import TokenBucket, percentile
from bestofn_swarm.wire import keyspace, protocol

log = logging.getLogger("bridge")

# A robot's messages are small (an act, a status, an opinion of at most 1000 sites): what a
# robot sends is refused past this, before its tag is even checked.
MAX_FROM_ROBOT_BYTES = 32 * 1024
FRAME_RATE, FRAME_BURST = 5000.0, 2000.0  # authentic frames a robot may send, a second
PING_TIMEOUT = 2.0  # seconds after which an unanswered ping counts as lost
RTT_KEPT = 200  # round trips kept for the median and 95th percentile
LOGGED_REFUSALS = 10  # per robot; every one is counted


@dataclass(frozen=True)
class SessionOpened:
    robot: int


@dataclass(frozen=True)
class SessionClosed:
    robot: int
    reason: str


@dataclass(frozen=True)
class Message:
    robot: int
    kind: keyspace.LinkCode
    payload: bytes
    attachment: bytes | None


PeerEvent = SessionOpened | SessionClosed | Message


@dataclass
class Session:
    robot_nonce: bytes
    bridge_nonce: bytes
    cipher_key: bytes | None
    target: Hashable  # where its frames go (a UDP address; the port itself on serial)
    welcome: bytes = b""  # the welcome frame, sent again if the hello is repeated
    sent_seq: int = 0

    @property
    def nonces(self) -> tuple[bytes, bytes]:
        return self.robot_nonce, self.bridge_nonce


class LinkPeer:
    """One robot outside the emulator, as the bridge serves it."""

    def __init__(
        self,
        robot: int,
        key: bytes,
        welcome: codec.LinkWelcome,
        *,
        transport: codec.Transport,
        address: str,
        nonce: Callable[[], bytes] = lambda: secrets.token_bytes(codec.NONCE_BYTES),
    ) -> None:
        self.robot = robot
        self.key = key  # the robot's link key, never its run key
        self.welcome = welcome
        self.welcome_body = codec.encode_welcome(welcome)
        self.transport: codec.Transport = transport
        self.address = address
        self.new_nonce = nonce
        self.session: Session | None = None
        self.pending: Session | None = None  # welcomed, not yet proven by the robot
        self.window = codec.ReplayWindow()
        self.hellos = codec.RecentNonces()
        self.bucket = TokenBucket(FRAME_RATE, FRAME_BURST)
        self.last_heard = 0.0
        self.line_busy_until = 0.0  # when what the bridge wrote has reached the robot
        self.next_ping = 0.0
        self.ping_id = 0
        self.outstanding: dict[int, float] = {}  # ping id -> when it was sent
        self.rtts: deque[float] = deque(maxlen=RTT_KEPT)
        self.answered = self.lost = 0
        self.sessions = 0
        self.frames_in = self.frames_out = self.bytes_in = self.bytes_out = 0
        self.impaired = 0  # counted by whoever impairs the link
        self.refused: Counter[str] = Counter()
        self._outgoing: list[tuple[bytes, Hashable]] = []

    @property
    def connected(self) -> bool:
        return self.session is not None

    def take_outgoing(self) -> list[tuple[bytes, Hashable]]:
        """(frame, where to) to send, in order, since the last call."""
        frames, self._outgoing = self._outgoing, []
        for frame, _ in frames:
            self.frames_out += 1
            self.bytes_out += len(frame)
        return frames

    @property
    def deadline(self) -> float | None:
        if self.session is None:
            return None
        oldest = min(self.outstanding.values(), default=None)
        times = [self.next_ping, self._quiet_since + self.welcome.silence]
        if oldest is not None:
            times.append(oldest + PING_TIMEOUT)
        return min(times)

    # --- time --------------------------------------------------------------------------

    def wake(self, now: float) -> list[PeerEvent]:
        """Ping when due; count unanswered pings as lost; close a silent session."""
        for ping, sent in list(self.outstanding.items()):
            if now - sent >= PING_TIMEOUT:
                del self.outstanding[ping]
                self.lost += 1
        if self.session is None:
            return []
        if now - self._quiet_since >= self.welcome.silence:
            return self._close(f"silent for {self.welcome.silence:g} s")
        if now >= self.next_ping:
            self.ping_id += 1
            self.outstanding[self.ping_id] = now
            self._send(codec.FrameType.PING, self.ping_id.to_bytes(codec.PING_BODY_BYTES, "big"))
            self.next_ping = now + self.welcome.ping_every
        return []

    @property
    def _quiet_since(self) -> float:
        """Silence counts from the robot's last sign of life, or from when the bridge's own
        frames have reached it (it cannot answer before), whichever is later."""
        return max(self.last_heard, self.line_busy_until)

    def hearing(self, now: float) -> None:
        """Bytes of a frame from the robot are arriving on a serial line (its end not yet):
        the robot is there. On UDP only an authentic frame counts."""
        if self.session is not None:
            self.last_heard = max(self.last_heard, now)

    def sending(self, until: float) -> None:
        """What the bridge has written to a serial line reaches the robot at ``until``."""
        self.line_busy_until = until

    # --- sending -----------------------------------------------------------------------

    def send(self, kind: keyspace.LinkCode, payload: bytes, attachment: bytes | None) -> bool:
        """Relay one message of the run to the robot; False if no session carries it (or it
        cannot go in a frame: a camera frame too big for the link, counted)."""
        if self.session is None:
            return False
        try:
            self._send(codec.FrameType.DATA, codec.encode_data(kind, payload, attachment))
        except codec.LinkError as error:
            self._refuse(error)
            return False
        return True

    def close(self, reason: codec.ByeReason) -> list[PeerEvent]:
        """End the session (the bridge stops): say bye to the program."""
        if self.session is None:
            return []
        self._send(codec.FrameType.BYE, bytes((reason,)))
        return self._close(f"the bridge said bye ({reason.name.lower()})")

    def _send(self, kind: codec.FrameType, body: bytes) -> None:
        session = self.session
        assert session is not None
        session.sent_seq += 1
        frame = codec.Frame(
            kind,
            True,
            self.robot,
            session.robot_nonce,
            session.bridge_nonce,
            session.sent_seq,
            body,
            encrypted=session.cipher_key is not None,
        )
        self._outgoing.append((codec.seal(frame, self.key, session.cipher_key), session.target))

    # --- receiving ---------------------------------------------------------------------

    def receive(self, data: bytes, source: Hashable, now: float) -> list[PeerEvent]:
        """Take one frame that came from ``source``; the events it makes."""
        try:
            return self._receive(data, source, now)
        except codec.LinkError as error:
            self._refuse(error)
            return []

    def refuse(self, error: codec.LinkError) -> None:
        """Count a frame refused before it reached this peer (by its transport)."""
        self._refuse(error)

    def _refuse(self, error: codec.LinkError) -> None:
        self.refused[error.refusal] += 1
        if sum(self.refused.values()) <= LOGGED_REFUSALS:
            log.warning("robot %d: refused a link frame: %s", self.robot, error)

    def _receive(self, data: bytes, source: Hashable, now: float) -> list[PeerEvent]:
        if len(data) > MAX_FROM_ROBOT_BYTES:
            raise codec.LinkError(codec.Refusal.OVERSIZE, f"{len(data)} bytes from a robot")
        header = codec.read_header(data)
        if header.robot != self.robot or header.from_bridge:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "not a frame of this robot")
        if header.type is codec.FrameType.HELLO:
            frame = codec.open_frame(data, self.key)
            codec.check_body(frame)
            self._hello(frame, source, now)
            return []
        nonces = (header.robot_nonce, header.bridge_nonce)
        events: list[PeerEvent] = []
        session = self.session
        if self.pending is not None and nonces == self.pending.nonces:
            frame = codec.open_frame(data, self.key, self.pending.cipher_key)
            codec.check_body(frame)
            if session is not None:
                events += self._close("a newer session replaced it")
            session = self.session = self.pending
            self.pending = None
            self.window = codec.ReplayWindow()
            self.sessions += 1
            self.next_ping = now
            events.append(SessionOpened(self.robot))
            log.info("robot %d: link session %d open (%s)", self.robot, self.sessions, source)
        elif session is not None and nonces == session.nonces:
            frame = codec.open_frame(data, self.key, session.cipher_key)
            codec.check_body(frame)
        else:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "a frame of no open session")
        self.window.admit(frame, encrypted=session.cipher_key is not None)
        if not self.bucket.take(now):
            raise codec.LinkError(codec.Refusal.RATE, f"more than {FRAME_RATE:g} frames a second")
        self.last_heard = now
        session.target = source  # a robot that roams (a new address) is followed once proven
        self.frames_in += 1
        self.bytes_in += len(data)
        return events + self._handle(frame, now)

    def _hello(self, frame: codec.Frame, source: Hashable, now: float) -> None:
        pending = self.pending
        if pending is not None and frame.robot_nonce == pending.robot_nonce:
            pending.target = source
            self._outgoing.append((pending.welcome, source))  # the hello again: same answer
            return
        if frame.robot_nonce in self.hellos:
            raise codec.LinkError(codec.Refusal.REPLAYED, "a hello already answered")
        self.hellos.add(frame.robot_nonce)
        bridge_nonce = self.new_nonce()
        cipher_key = (
            codec.session_key(self.key, frame.robot_nonce, bridge_nonce)
            if self.welcome.cipher != "none"
            else None
        )
        welcome = codec.Frame(
            codec.FrameType.WELCOME,
            True,
            self.robot,
            frame.robot_nonce,
            bridge_nonce,
            0,
            self.welcome_body,
        )
        sealed = codec.seal(welcome, self.key)
        self.pending = Session(frame.robot_nonce, bridge_nonce, cipher_key, source, sealed)
        self._outgoing.append((sealed, source))

    def _handle(self, frame: codec.Frame, now: float) -> list[PeerEvent]:
        if frame.type is codec.FrameType.PING:
            self._send(codec.FrameType.PONG, frame.body)
        elif frame.type is codec.FrameType.PONG:
            sent = self.outstanding.pop(int.from_bytes(frame.body, "big"), None)
            if sent is not None:
                self.rtts.append(now - sent)
                self.answered += 1
        elif frame.type is codec.FrameType.BYE:
            reason = codec.ByeReason(frame.body[0])
            return self._close(f"the program said bye ({reason.name.lower()})")
        elif frame.type is codec.FrameType.DATA:
            kind, payload, attachment = codec.decode_data(frame.body)
            if kind.to_robot:
                raise codec.LinkError(codec.Refusal.UNEXPECTED, f"{kind.name} is not a robot's")
            return [Message(self.robot, kind, payload, attachment)]
        else:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, f"a {frame.type.name} in a session")
        return []

    def _close(self, reason: str) -> list[PeerEvent]:
        log.warning("robot %d: link session %d closed: %s", self.robot, self.sessions, reason)
        self.session = None
        self.outstanding.clear()
        return [SessionClosed(self.robot, reason)]

    # --- figures -----------------------------------------------------------------------

    def stats(self) -> protocol.LinkStats:
        settled = self.answered + self.lost
        median = percentile(self.rtts, 0.5)
        p95 = percentile(self.rtts, 0.95)
        return protocol.LinkStats(
            v=protocol.VERSION,
            robot=self.robot,
            transport=self.transport,
            address=self.address[:256],
            connected=self.connected,
            sessions=self.sessions,
            rtt_ms=None if median is None else round(median * 1000, 3),
            rtt_p95_ms=None if p95 is None else round(p95 * 1000, 3),
            pings=settled,
            loss=round(self.lost / settled, 4) if settled else 0.0,
            frames_in=self.frames_in,
            frames_out=self.frames_out,
            bytes_in=self.bytes_in,
            bytes_out=self.bytes_out,
            impaired=self.impaired,
            refused=protocol.LinkRefusals(
                **{reason.value: self.refused[reason] for reason in codec.Refusal}
            ),
        )
