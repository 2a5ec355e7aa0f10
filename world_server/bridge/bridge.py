"""The bridge: robots of a run served to programs outside the emulator, over their links.

``swarm run --external 8,9 --link udp://127.0.0.1:PORT`` starts the swarm without robots 8
and 9 and this process in their place. For each of them it holds a Zenoh session of its
own (in ``--secure`` runs with that robot's certificate, so it may say only what the robot
may say) and a link (``LinkPeer`` over UDP or a serial line):

* what the world sends the robot (its sense, camera frames, radio deliveries) goes down
  the link as it came, still sealed with the robot's run key by the world;
* what the robot program sends (its act, radio transmissions, status) is published on the
  robot's keys as it came, sealed by the program: the world and the program check each
  other's tags end to end, and the bridge, which holds only the robots' *link* keys, can
  neither make nor change any of it;
* the program's question for the map (``world/info``, tagged with its key and a nonce)
  goes to the world and the sealed answer comes back the same way;
* the world's liveliness goes down the link, so the program follows a restarted world as
  the robot process does; the robot's own token is presence (``presence.py``).

On top, every link frame carries its own tag under the robot's link key with a session
nonce and a sequence number (wire/link.py), checked by the peer before anything is
forwarded. The bridge pings each program, and publishes each link's figures (round trip,
loss, frames, refusals: ``LinkStats`` on ``link/<id>/stats``, sealed as the bridge) every
second and whenever a link opens or closes. A link can be made worse on purpose
(``impairment.py``).

Threads: Zenoh's callbacks only queue what they bring (a bounded inbox) and wake the loop;
one thread owns the peers, the sockets and serial lines, and publishes.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import selectors
import socket
import time
from collections import Counter
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, field
from typing import Any

import msgspec
import zenoh

from plumbing.inbox import BoundedInbox
from plumbing.zenoh_session import reliable_publisher
from robot_agent.link.transport import LinkClosedError, SerialLine
from wire import auth, link, names, protocol
from wire.names import Role
from world_server.bridge.impairment import ImpairedDirection, LinkImpairment
from world_server.bridge.peer import Closed, LinkPeer, Message, Opened, PeerEvent
from world_server.bridge.presence import Presence
from world_server.bridge.udp import UdpServer

log = logging.getLogger("bridge")

INBOX_BYTES = 64 * 2**20
MAX_INBOX_ITEM = protocol.MAX_FRAME_BYTES + 2048
STATS_EVERY = 1.0  # seconds between two LinkStats of a link
MAX_WAIT = 0.2  # seconds the loop waits at most
QUERY_TIMEOUT = 5.0  # seconds a relayed world/info question waits for answers
REOPEN_EVERY = 1.0  # seconds between attempts to reopen a serial line that closed
DRAIN_WAIT = 2.0  # seconds to let paced serial lines send their goodbyes
PING_EVERY = 0.5
SILENCE = 3.0

# What the world sends a robot, by its key, and what the robot sends, to its key.
FROM_WORLD = (link.DataKind.SENSE, link.DataKind.CAMERA, link.DataKind.RADIO_RX)


@dataclass(frozen=True)
class LinkedRobot:
    robot: int
    address: link.LinkAddress


@dataclass(frozen=True)
class BridgeConfig:
    run_id: str
    robots: tuple[LinkedRobot, ...]
    controller: str  # the run's ControllerConfig as JSON, for the programs' welcome
    root: str = protocol.DEFAULT_ROOT
    seed: int = 0  # for the impairment's draws
    encrypted: bool = False  # --secure: every session ChaCha20-Poly1305
    ping_every: float = PING_EVERY
    silence: float = SILENCE
    impairment: LinkImpairment = field(default_factory=LinkImpairment)

    def welcome(self) -> link.LinkWelcome:
        return link.LinkWelcome(
            v=1,
            run=self.run_id,
            root=self.root,
            cipher="chacha20-poly1305" if self.encrypted else "none",
            ping_every=self.ping_every,
            silence=self.silence,
            controller=msgspec.Raw(self.controller.encode()),  # passed on as it is
        )


@dataclass(frozen=True)
class FromWorld:
    robot: int
    kind: link.DataKind
    payload: bytes
    attachment: bytes | None


@dataclass(frozen=True)
class WorldToken:
    instance: str
    up: bool


@dataclass(frozen=True)
class StopBridge:
    reason: link.ByeReason


Event = FromWorld | WorldToken | StopBridge


class Bridge:
    """One run's outside robots: their Zenoh sessions, links and presence."""

    def __init__(
        self,
        config: BridgeConfig,
        *,
        session: zenoh.Session,
        robot_sessions: Mapping[int, zenoh.Session],
        link_keys: Mapping[int, bytes],
        keyring: auth.Keyring | None,
    ) -> None:
        self.config = config
        self.keys = protocol.Keys(config.run_id, config.root)
        self.session = session
        self.robot_sessions = robot_sessions
        self.keyring = keyring  # the bridge's own key: what it publishes as itself
        self.inbox: BoundedInbox[Event] = BoundedInbox(INBOX_BYTES, MAX_INBOX_ITEM)
        self._wake_read, self._wake_write = socket.socketpair()
        self._wake_read.setblocking(False)
        self._wake_write.setblocking(False)
        welcome = config.welcome()
        self.peers: dict[int, LinkPeer] = {}
        self.udp: UdpServer | None = None
        self.serial: dict[int, SerialLine | None] = {}
        self.reopen_at: dict[int, float] = {}
        self.up: dict[int, ImpairedDirection] = {}
        self.down: dict[int, ImpairedDirection] = {}
        for linked in config.robots:
            robot, address = linked.robot, linked.address
            self.peers[robot] = LinkPeer(
                robot,
                link_keys[robot],
                welcome,
                transport=address.transport,
                address=str(address),
            )
            if not config.impairment.none:
                seed, impairment = config.seed, config.impairment
                self.up[robot] = ImpairedDirection.seeded(impairment, seed, robot, "up")
                self.down[robot] = ImpairedDirection.seeded(impairment, seed, robot, "down")
        self.presence = Presence(robot_sessions, self.keys)
        self.worlds: set[str] = set()
        self.unattributed: Counter[str] = Counter()  # UDP frames of no robot served here
        self._publishers: dict[tuple[int, link.DataKind], zenoh.Publisher] = {}
        self._stats_publishers: dict[int, zenoh.Publisher] = {}
        self._declared: list[Any] = []
        self._token: Any = None
        self._selector = selectors.DefaultSelector()
        self._next_stats = 0.0

    # --- setting up --------------------------------------------------------------------

    def open_links(self) -> None:
        """Bind the UDP address and open the serial lines (OSError if one cannot be)."""
        udp = {linked.address for linked in self.config.robots if linked.address.transport == "udp"}
        if len(udp) > 1:
            raise ValueError(f"one UDP address serves every robot on UDP, not {len(udp)}")
        if udp:
            (address,) = udp
            self.udp = UdpServer(address.host, address.port)
            self._selector.register(self.udp, selectors.EVENT_READ, "udp")
        for linked in self.config.robots:
            if linked.address.transport == "serial":
                self._open_serial(linked)
        self._selector.register(self._wake_read, selectors.EVENT_READ, "wake")

    def _open_serial(self, linked: LinkedRobot) -> None:
        address = linked.address
        try:
            line = SerialLine(address.path, address.baud)
        except OSError as error:
            log.warning("robot %d: %s", linked.robot, error)
            self.serial[linked.robot] = None
            self.reopen_at[linked.robot] = time.monotonic() + REOPEN_EVERY
            return
        self.serial[linked.robot] = line
        self._selector.register(line, selectors.EVENT_READ, linked.robot)

    def declare(self) -> None:
        """Subscribe to each robot's inputs and the world's liveliness; say the bridge is up."""
        keys = self.keys
        for robot, session in self.robot_sessions.items():
            name = names.robot_name(robot)
            inputs = {
                link.DataKind.SENSE: keys.sense(robot),
                link.DataKind.CAMERA: keys.camera(robot),
                link.DataKind.RADIO_RX: keys.radio_rx(name),
            }
            for kind, key in inputs.items():
                self._declared.append(session.declare_subscriber(key, self._on_input(robot, kind)))
            outputs = {
                link.DataKind.ACT: keys.act(robot),
                link.DataKind.RADIO_TX: keys.radio_tx(name),
                link.DataKind.STATUS: keys.status(robot),
            }
            for kind, key in outputs.items():
                self._publishers[robot, kind] = reliable_publisher(session, key)
        for robot in self.peers:
            self._stats_publishers[robot] = reliable_publisher(self.session, keys.link_stats(robot))
        self._declared.append(
            self.session.liveliness().declare_subscriber(
                keys.alive(Role.WORLD, "*"), self._on_world, history=True
            )
        )
        self._token = self.session.liveliness().declare_token(keys.alive(Role.BRIDGE, 0))

    def close(self) -> None:
        self.presence.close()
        if self._token is not None:
            self._token.undeclare()
        for entity in self._declared:
            entity.undeclare()
        for line in self.serial.values():
            if line is not None:
                line.close()
        if self.udp is not None:
            self.udp.close()
        self._selector.close()
        self._wake_read.close()
        self._wake_write.close()

    # --- Zenoh side: callbacks queue and wake ------------------------------------------

    def put(self, event: Event, size: int = 0) -> None:
        self.inbox.put(event, size, "zenoh")
        with contextlib.suppress(OSError):  # a full wake-up pipe: the loop is awake anyway
            self._wake_write.send(b"\0")

    def stop(self, reason: link.ByeReason = link.ByeReason.RUN_ENDED) -> None:
        self.put(StopBridge(reason))

    def _on_input(self, robot: int, kind: link.DataKind) -> Callable[[zenoh.Sample], None]:
        def callback(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            self.put(FromWorld(robot, kind, payload, extra), len(payload) + len(extra or b""))

        return callback

    def _on_world(self, sample: zenoh.Sample) -> None:
        instance = self.keys.last_chunk(str(sample.key_expr))
        self.put(WorldToken(instance, sample.kind == zenoh.SampleKind.PUT))

    def _ask_world(self, robot: int, payload: bytes, attachment: bytes | None) -> None:
        """Relay the program's question for the map; each answer comes back on the link."""

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                data = reply.ok.payload.to_bytes()
                extra = reply.ok.attachment
                answer = FromWorld(
                    robot,
                    link.DataKind.INFO_REPLY,
                    data,
                    extra.to_bytes() if extra is not None else None,
                )
            else:
                said = reply.err.payload.to_bytes() if reply.err is not None else b"no answer"
                answer = FromWorld(robot, link.DataKind.INFO_ERROR, said[:1024], None)
            self.put(answer, len(answer.payload))

        self.robot_sessions[robot].get(
            self.keys.world_info,
            on_reply,
            payload=payload or None,
            attachment=attachment,
            timeout=QUERY_TIMEOUT,
        )

    # --- the loop ----------------------------------------------------------------------

    def run(self) -> None:
        """Serve the links until a stop event; then say bye and make the robots absent."""
        reason = self._serve()
        now = time.monotonic()
        for peer in self.peers.values():
            self._take_events(peer.close(reason), now)
            for frame, target in peer.take_outgoing():  # the goodbye is not impaired
                self._transmit(peer, frame, target, now)
        self._drain_serial()
        self._publish_stats(time.monotonic(), force=True)
        if sum(self.unattributed.values()):
            log.warning("refused UDP frames of no robot served here: %s", dict(self.unattributed))

    def _serve(self) -> link.ByeReason:
        while True:
            now = time.monotonic()
            for key, _ in self._selector.select(self._wait(now)):
                now = time.monotonic()
                if key.data == "wake":
                    self._drain_wake()
                elif key.data == "udp":
                    self._take_udp(now)
                else:
                    self._take_serial(int(key.data), now)
            now = time.monotonic()
            stop = self._take_inbox(now)
            if stop is not None:
                return stop.reason
            for peer in self.peers.values():
                self._take_events(peer.wake(now), now)
            self._release(now)
            for peer in self.peers.values():
                self._flush_peer(peer, now)
            self._flush_serial(now)
            self._publish_stats(now)

    def _wait(self, now: float) -> float:
        deadlines = [self._next_stats, *self.reopen_at.values()]
        deadlines += [peer.deadline for peer in self.peers.values() if peer.deadline is not None]
        for directions in (self.up, self.down):
            deadlines += [d.deadline for d in directions.values() if d.deadline is not None]
        for line in self.serial.values():
            if line is not None and line.deadline is not None:
                deadlines.append(line.deadline)
        return min(max(0.0, min(deadlines, default=math.inf) - now), MAX_WAIT)

    def _drain_wake(self) -> None:
        with contextlib.suppress(BlockingIOError):
            while self._wake_read.recv(4096):
                pass

    def _take_inbox(self, now: float) -> StopBridge | None:
        while True:
            try:
                event = self.inbox.get(timeout=0)
            except queue.Empty:
                return None
            if isinstance(event, StopBridge):
                return event
            if isinstance(event, WorldToken):
                self._world(event)
            else:
                peer = self.peers[event.robot]
                peer.send(event.kind, event.payload, event.attachment)
                self._flush_peer(peer, now)

    def _world(self, token: WorldToken) -> None:
        """Tell every program the world appeared or went (it follows one, as robots do)."""
        if token.up:
            self.worlds.add(token.instance)
        else:
            self.worlds.discard(token.instance)
        kind = link.DataKind.WORLD_UP if token.up else link.DataKind.WORLD_DOWN
        for peer in self.peers.values():
            peer.send(kind, token.instance.encode(), None)

    # --- links in ----------------------------------------------------------------------

    def _take_udp(self, now: float) -> None:
        assert self.udp is not None
        for data, source in self.udp.receive():
            try:
                header = link.read_header(data)
            except link.LinkError as error:
                self.unattributed[error.refusal] += 1
                continue
            peer = self.peers.get(header.robot)
            if peer is None or peer.transport != "udp":
                self.unattributed[link.Refusal.UNEXPECTED] += 1
                continue
            self._arrive(peer, data, source, now)

    def _take_serial(self, robot: int, now: float) -> None:
        line, peer = self.serial.get(robot), self.peers[robot]
        if line is None:
            return
        try:
            frames = line.receive(now)
        except LinkClosedError as error:
            self._serial_closed(robot, str(error), now)
            return
        for refusal, count in line.refused.items():
            for _ in range(count):
                peer.refuse(link.LinkError(link.Refusal(refusal), "serial framing"))
        line.refused.clear()
        for frame in frames:
            self._arrive(peer, frame, robot, now)

    def _serial_closed(self, robot: int, why: str, now: float) -> None:
        line = self.serial.get(robot)
        if line is not None:
            self._selector.unregister(line)
            line.close()
        self.serial[robot] = None
        self.reopen_at[robot] = now + REOPEN_EVERY
        log.warning("robot %d: %s", robot, why)
        peer = self.peers[robot]
        if peer.connected:
            self._take_events(peer.close(link.ByeReason.GOING_AWAY), now)
            peer.take_outgoing()  # nowhere to send the goodbye

    def _arrive(self, peer: LinkPeer, data: bytes, source: Hashable, now: float) -> None:
        up = self.up.get(peer.robot)
        if up is None:
            self._deliver(peer, data, source, now)
        elif not up.put(data, source, now):
            peer.impaired += 1

    def _deliver(self, peer: LinkPeer, data: bytes, source: Hashable, now: float) -> None:
        self._take_events(peer.receive(data, source, now), now)
        self._flush_peer(peer, now)

    def _release(self, now: float) -> None:
        """Frames the impairment held whose time has come, both ways."""
        for robot, up in self.up.items():
            for data, source in up.due(now):
                self._deliver(self.peers[robot], data, source, now)
        for robot, down in self.down.items():
            for frame, target in down.due(now):
                self._transmit(self.peers[robot], frame, target, now)
        for robot, at in list(self.reopen_at.items()):
            if now >= at:
                del self.reopen_at[robot]
                linked = next(item for item in self.config.robots if item.robot == robot)
                self._open_serial(linked)

    # --- what the peers say ------------------------------------------------------------

    def _take_events(self, events: list[PeerEvent], now: float) -> None:
        for event in events:
            if isinstance(event, Message):
                self._relay(event)
            elif isinstance(event, Opened):
                peer = self.peers[event.robot]
                for instance in sorted(self.worlds):
                    peer.send(link.DataKind.WORLD_UP, instance.encode(), None)
                self._publish_stats(now, force=True)
            elif isinstance(event, Closed):
                self.presence.gone(event.robot)
                self._publish_stats(now, force=True)

    def _relay(self, message: Message) -> None:
        """Publish what the program sent, as it sent it, on its robot's key."""
        if message.kind is link.DataKind.INFO_QUERY:
            self._ask_world(message.robot, message.payload, message.attachment)
            return
        publisher = self._publishers[message.robot, message.kind]
        publisher.put(message.payload, attachment=message.attachment)
        self.presence.spoke(message.robot, message.kind)

    # --- links out ---------------------------------------------------------------------

    def _flush_peer(self, peer: LinkPeer, now: float) -> None:
        down = self.down.get(peer.robot)
        for frame, target in peer.take_outgoing():
            if down is None:
                self._transmit(peer, frame, target, now)
            elif not down.put(frame, target, now):
                peer.impaired += 1

    def _transmit(self, peer: LinkPeer, frame: bytes, target: Hashable, now: float) -> None:
        if peer.transport == "udp":
            assert self.udp is not None
            self.udp.send(frame, target)
            return
        line = self.serial.get(peer.robot)
        if line is not None:
            line.send(frame, now)

    def _flush_serial(self, now: float) -> None:
        for robot, line in list(self.serial.items()):
            if line is None:
                continue
            try:
                line.flush(now)
            except LinkClosedError as error:
                self._serial_closed(robot, str(error), now)

    def _drain_serial(self) -> None:
        deadline = time.monotonic() + DRAIN_WAIT
        while time.monotonic() < deadline:
            waiting = [
                line.deadline
                for line in self.serial.values()
                if line is not None and line.deadline is not None
            ]
            if not waiting:
                break
            time.sleep(max(0.0, min(min(waiting) - time.monotonic(), 0.05)))
            self._flush_serial(time.monotonic())
        self._flush_serial(time.monotonic())

    # --- figures -----------------------------------------------------------------------

    def _publish_stats(self, now: float, force: bool = False) -> None:
        if not force and now < self._next_stats:
            return
        self._next_stats = now + STATS_EVERY
        for robot, peer in self.peers.items():
            key = self.keys.link_stats(robot)
            payload = protocol.encode(peer.stats())
            attachment = auth.seal(self.keyring, names.BRIDGE, key, payload)
            self._stats_publishers[robot].put(payload, attachment=attachment)
