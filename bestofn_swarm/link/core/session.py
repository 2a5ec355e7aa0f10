"""The robot's end of a link session (no I/O: bytes and the time in, bytes and events out).

``LinkClient`` says hello until the bridge welcomes it, then carries the robot's messages
in DATA frames, answers the bridge's pings and notices when the bridge goes quiet. A
session is the pair of nonces of one hello and its welcome; every frame after the welcome
carries them and a sequence number, each direction counting from 1, and its tag under the
robot's link key (bestofn_swarm/link/core/codec.py). A frame that is not authentic, not of this
session, or a sequence number already taken is refused and counted (``refused``), never raised.

When the bridge is silent for the welcome's ``silence`` seconds, or says bye, the session
is lost: the client says hello again (a fresh nonce) until a bridge answers, so a
restarted bridge is found again. On a serial line a frame under way (``hearing``) is not
silence: a long frame (a map of 1000 sites is 5 s at 115200 baud) keeps the session.
"""

from __future__ import annotations

import logging
import secrets
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from bestofn_swarm.link.core import codec
from bestofn_swarm.wire import keyspace

log = logging.getLogger("link.session")

HELLO_EVERY = 0.5  # seconds between hellos until one is answered


@dataclass(frozen=True)
class Welcomed:
    """A session opened: the run's settings for it."""

    welcome: codec.LinkWelcome


@dataclass(frozen=True)
class LinkData:
    """A message of the run for the robot."""

    kind: keyspace.LinkCode
    payload: bytes
    attachment: bytes | None


@dataclass(frozen=True)
class Lost:
    """The session ended (the bridge said bye, or went quiet); ``ended``: the run is over."""

    reason: str
    ended: bool = False


Event = Welcomed | LinkData | Lost


class LinkClient:
    """One robot's link sessions with the bridge, one after another."""

    def __init__(
        self,
        robot: int,
        key: bytes,
        *,
        nonce: Callable[[], bytes] = lambda: secrets.token_bytes(codec.NONCE_BYTES),
        hello_every: float = HELLO_EVERY,
    ) -> None:
        self.robot = robot
        self.key = key  # the link key (codec.link_key of the robot's run key)
        self.new_nonce = nonce
        self.hello_every = hello_every
        self.refused: Counter[str] = Counter()
        self.sessions = 0
        self.welcome: codec.LinkWelcome | None = None
        self.robot_nonce = nonce()
        self.bridge_nonce: bytes | None = None  # None: saying hello
        self.cipher_key: bytes | None = None
        self.sent_seq = 0
        self.window = codec.ReplayWindow()
        self.next_hello = 0.0
        self.last_heard = 0.0
        self.silence = codec.SILENCE  # until the welcome says
        self._outgoing: list[bytes] = []

    @property
    def open(self) -> bool:
        return self.bridge_nonce is not None

    def take_outgoing(self) -> list[bytes]:
        """The frames to send, in order, since the last call."""
        frames, self._outgoing = self._outgoing, []
        return frames

    @property
    def deadline(self) -> float:
        """When ``wake`` has something to do: the next hello, or when silence ends a session."""
        return self.last_heard + self.silence if self.open else self.next_hello

    # --- time ----------------------------------------------------------------------------

    def wake(self, now: float) -> list[Event]:
        """Say hello when due; end a session whose bridge has been silent too long."""
        if self.open:
            if now - self.last_heard < self.silence:
                return []
            return [self._lose(f"the bridge was silent for {self.silence:g} s", now)]
        if now >= self.next_hello:
            self._send_hello(now)
        return []

    def _send_hello(self, now: float) -> None:
        frame = codec.Frame(
            codec.FrameType.HELLO, False, self.robot, self.robot_nonce, codec.NO_NONCE, 0
        )
        self._outgoing.append(codec.seal(frame, self.key))
        self.next_hello = now + self.hello_every

    def _lose(self, reason: str, now: float, ended: bool = False) -> Lost:
        log.warning("robot %d: link session lost: %s", self.robot, reason)
        self.bridge_nonce = None
        self.cipher_key = None
        self.robot_nonce = self.new_nonce()  # a new session, a new nonce
        self.next_hello = now
        return Lost(reason, ended)

    def hearing(self, now: float) -> None:
        """Bytes of a frame are arriving on a serial line (its zero not yet): the bridge is
        there, so an open session's silence counts from now. On UDP a datagram is a whole
        frame, and only an authentic one counts."""
        if self.open:
            self.last_heard = max(self.last_heard, now)

    # --- sending -------------------------------------------------------------------------

    def send(self, kind: keyspace.LinkCode, payload: bytes, attachment: bytes | None) -> bool:
        """Queue one message of the robot; False if there is no session to carry it (or it
        is too big for a frame: counted as refused)."""
        if not self.open:
            return False
        try:
            self._send(codec.FrameType.DATA, codec.encode_data(kind, payload, attachment))
        except codec.LinkError as error:
            self.refused[error.refusal] += 1
            return False
        return True

    def bye(self, reason: codec.ByeReason) -> None:
        """Say goodbye: the session ends at this end (a second bye would be refused)."""
        if self.open:
            self._send(codec.FrameType.BYE, bytes((reason,)))
            self.bridge_nonce = None

    def _send(self, kind: codec.FrameType, body: bytes) -> None:
        assert self.bridge_nonce is not None
        self.sent_seq += 1
        frame = codec.Frame(
            kind,
            False,
            self.robot,
            self.robot_nonce,
            self.bridge_nonce,
            self.sent_seq,
            body,
            encrypted=self.cipher_key is not None,
        )
        self._outgoing.append(codec.seal(frame, self.key, self.cipher_key))

    # --- receiving -----------------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> list[Event]:
        """Take one frame from the link; the events it makes (refusals are counted)."""
        try:
            return self._receive(data, now)
        except codec.LinkError as error:
            self.refused[error.refusal] += 1
            if sum(self.refused.values()) <= 10:
                log.warning("robot %d: refused a link frame: %s", self.robot, error)
            return []

    def _receive(self, data: bytes, now: float) -> list[Event]:
        header = codec.read_header(data)
        if header.robot != self.robot or not header.from_bridge:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "not a frame for this robot")
        frame = codec.open_frame(data, self.key, self.cipher_key)
        codec.check_body(frame)
        if frame.robot_nonce != self.robot_nonce:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "a frame of another session")
        if frame.type is codec.FrameType.WELCOME:
            return self._welcomed(frame, now)
        if frame.bridge_nonce != self.bridge_nonce:
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "a frame of another session")
        self.window.admit(frame, encrypted=self.cipher_key is not None)
        self.last_heard = now
        if frame.type is codec.FrameType.PING:
            self._send(codec.FrameType.PONG, frame.body)
            return []
        if frame.type is codec.FrameType.BYE:
            reason = codec.ByeReason(frame.body[0])
            ended = reason is codec.ByeReason.RUN_ENDED
            return [self._lose(f"the bridge said bye ({reason.name.lower()})", now, ended)]
        if frame.type is codec.FrameType.DATA:
            kind, payload, attachment = codec.decode_data(frame.body)
            if not kind.to_robot:
                raise codec.LinkError(codec.Refusal.UNEXPECTED, f"{kind.name} is not for a robot")
            return [LinkData(kind, payload, attachment)]
        return []  # a pong: the bridge measures round trips, not this end

    def _welcomed(self, frame: codec.Frame, now: float) -> list[Event]:
        if self.open:
            if frame.bridge_nonce == self.bridge_nonce:
                return []  # the same welcome again: our hello was repeated
            raise codec.LinkError(codec.Refusal.UNEXPECTED, "a second welcome for one hello")
        welcome = codec.decode_welcome(frame.body)
        self.welcome = welcome
        self.bridge_nonce = frame.bridge_nonce
        self.cipher_key = (
            codec.session_key(self.key, self.robot_nonce, frame.bridge_nonce)
            if welcome.cipher != "none"
            else None
        )
        self.sent_seq = 0
        self.window = codec.ReplayWindow()
        self.silence = welcome.silence
        self.last_heard = now
        self.sessions += 1
        # An authenticated frame of the new session at once: the bridge takes the session
        # (and says the robot is present) only on the robot's first frame in it.
        self._send(codec.FrameType.PING, bytes(codec.PING_BODY_BYTES))
        return [Welcomed(welcome)]
