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
nonce and a sequence number (bestofn_swarm/link/core/codec.py), checked by the peer before anything
is forwarded. The bridge pings each program, and publishes each link's figures (round trip,
loss, frames, refusals: ``LinkStats`` on ``link/<id>/stats``, sealed as the bridge) every
second and whenever a link opens or closes. A link can be made worse on purpose
(``impairment.py``).

Threads: Zenoh's callbacks only queue what they bring (a bounded inbox) and wake the loop;
one thread owns the peers and the link transports (a ``bestofn_swarm.link.io.hub.Hub``, the loop
``robot-agent --link`` runs on too), and publishes.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import queue
import socket
import time
from collections import Counter
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, field
from typing import Any

import msgspec
import zenoh

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.io.hub import Hub
from bestofn_swarm.link.io.transport import SerialLine, UdpServer
from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.plumbing.zenoh_session import reliable_publisher
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.keyspace import Part
from bestofn_swarm.wire.names import Role
from world_server.bridge.core.impairment import ImpairedDirection, LinkImpairment
from world_server.bridge.core.peer import LinkPeer, Message, PeerEvent, SessionClosed, SessionOpened
from world_server.bridge.presence import Presence

log = logging.getLogger("bridge")

INBOX_BYTES = 64 * 2**20
MAX_INBOX_ITEM = protocol.MAX_CAMERA_FRAME_BYTES + 2048
STATS_EVERY = 1.0  # seconds between two LinkStats of a link
QUERY_TIMEOUT = 5.0  # seconds a relayed world/info question waits for answers
UDP = "udp"  # the hub's name for the one UDP server; serial lines go by their robot
WAKE = "wake"

# What the world sends a robot, by its key, and what the robot sends, to its key.
FROM_WORLD = (
    keyspace.link(keyspace.SENSE),
    keyspace.link(keyspace.CAMERA),
    keyspace.link(keyspace.RADIO_RX),
)


@dataclass(frozen=True)
class LinkedRobot:
    robot: int
    address: codec.LinkAddress


@dataclass(frozen=True)
class BridgeConfig:
    run_id: str
    robots: tuple[LinkedRobot, ...]
    controller: str  # the run's ControllerConfig as JSON, for the programs' welcome
    root: str = protocol.DEFAULT_ROOT
    seed: int = 0  # for the impairment's draws
    encrypted: bool = False  # --secure: every session ChaCha20-Poly1305
    ping_every: float = codec.PING_EVERY
    silence: float = codec.SILENCE
    impairment: LinkImpairment = field(default_factory=LinkImpairment)

    def welcome(self) -> codec.LinkWelcome:
        return codec.LinkWelcome(
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
    kind: keyspace.LinkCode
    payload: bytes
    attachment: bytes | None


@dataclass(frozen=True)
class WorldToken:
    instance: str
    up: bool


@dataclass(frozen=True)
class StopBridge:
    reason: codec.ByeReason


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
        self.keys = keyspace.Keys(config.run_id, config.root)
        self.session = session
        self.robot_sessions = robot_sessions
        self.keyring = keyring  # the bridge's own key: what it publishes as itself
        self.inbox: BoundedInbox[Event] = BoundedInbox(INBOX_BYTES, MAX_INBOX_ITEM)
        self._wake_read, self._wake_write = socket.socketpair()
        self._wake_read.setblocking(False)
        self._wake_write.setblocking(False)
        welcome = config.welcome()
        self.peers: dict[int, LinkPeer] = {}
        self.hub = Hub()
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
        self._publishers: dict[tuple[int, keyspace.LinkCode], zenoh.Publisher] = {}
        self._stats_publishers: dict[int, zenoh.Publisher] = {}
        self._declared: list[Any] = []
        self._token: Any = None
        self._next_stats = 0.0

    # --- setting up --------------------------------------------------------------------

    def open_links(self) -> None:
        """Bind the UDP address (OSError if it cannot be) and open the serial lines (one
        that cannot be opened yet is tried again every second: a cable not yet in)."""
        udp = {linked.address for linked in self.config.robots if linked.address.transport == "udp"}
        if len(udp) > 1:
            raise ValueError(f"one UDP address serves every robot on UDP, not {len(udp)}")
        if udp:
            (server,) = udp
            bind = functools.partial(UdpServer, server.host, server.port)
            self.hub.add(UDP, bind, must_open=True)
        for linked in self.config.robots:
            if linked.address.transport == "serial":
                line = functools.partial(SerialLine, linked.address.path, linked.address.baud)
                self.hub.add(linked.robot, line)
        self.hub.watch(self._wake_read, WAKE)

    def declare(self) -> None:
        """Subscribe to each robot's inputs and the world's liveliness; say the bridge is up."""
        keys = self.keys
        for robot, session in self.robot_sessions.items():
            name = names.robot_name(robot)
            inputs = {
                keyspace.link(keyspace.SENSE): keys.of(keyspace.SENSE, robot),
                keyspace.link(keyspace.CAMERA): keys.of(keyspace.CAMERA, robot),
                keyspace.link(keyspace.RADIO_RX): keys.of(keyspace.RADIO_RX, name),
            }
            for kind, key in inputs.items():
                self._declared.append(session.declare_subscriber(key, self._on_input(robot, kind)))
            outputs = {
                keyspace.link(keyspace.ACT): keys.of(keyspace.ACT, robot),
                keyspace.link(keyspace.RADIO_TX): keys.of(keyspace.RADIO_TX, name),
                keyspace.link(keyspace.STATUS): keys.of(keyspace.STATUS, robot),
            }
            for kind, key in outputs.items():
                self._publishers[robot, kind] = reliable_publisher(session, key)
        for robot in self.peers:
            self._stats_publishers[robot] = reliable_publisher(
                self.session, keys.of(keyspace.LINK, robot)
            )
        self._declared.append(
            self.session.liveliness().declare_subscriber(
                keys.token(Role.WORLD, "*"), self._on_world, history=True
            )
        )
        self._token = self.session.liveliness().declare_token(keys.token(Role.BRIDGE, 0))

    def close(self) -> None:
        self.presence.close()
        if self._token is not None:
            self._token.undeclare()
        for entity in self._declared:
            entity.undeclare()
        self.hub.close()
        self._wake_read.close()
        self._wake_write.close()

    # --- Zenoh side: callbacks queue and wake ------------------------------------------

    def put(self, event: Event, size: int = 0) -> None:
        self.inbox.put(event, size, "zenoh")
        with contextlib.suppress(OSError):  # a full wake-up pipe: the loop is awake anyway
            self._wake_write.send(b"\0")

    def stop(self, reason: codec.ByeReason = codec.ByeReason.RUN_ENDED) -> None:
        self.put(StopBridge(reason))

    def _on_input(self, robot: int, kind: keyspace.LinkCode) -> Callable[[zenoh.Sample], None]:
        def callback(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            extra = sample.attachment.to_bytes() if sample.attachment is not None else None
            self.put(FromWorld(robot, kind, payload, extra), len(payload) + len(extra or b""))

        return callback

    def _on_world(self, sample: zenoh.Sample) -> None:
        instance = self.keys.ident_of(keyspace.ALIVE_WORLD, str(sample.key_expr)) or ""
        self.put(WorldToken(instance, sample.kind == zenoh.SampleKind.PUT))

    def _ask_world(self, robot: int, payload: bytes, attachment: bytes | None) -> None:
        """Relay the program's question for the map; each answer comes back on the link."""

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                data = reply.ok.payload.to_bytes()
                extra = reply.ok.attachment
                answer = FromWorld(
                    robot,
                    keyspace.link(keyspace.INFO, Part.REPLY),
                    data,
                    extra.to_bytes() if extra is not None else None,
                )
            else:
                said = reply.err.payload.to_bytes() if reply.err is not None else b"no answer"
                answer = FromWorld(
                    robot, keyspace.link(keyspace.INFO, Part.ERROR), said[:1024], None
                )
            self.put(answer, len(answer.payload))

        self.robot_sessions[robot].get(
            self.keys.of(keyspace.INFO),
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
        self.hub.drain()
        self._publish_stats(time.monotonic(), force=True)
        if sum(self.unattributed.values()):
            log.warning("refused UDP frames of no robot served here: %s", dict(self.unattributed))

    def _serve(self) -> codec.ByeReason:
        while True:
            for name in self.hub.poll(self._deadline()):
                now = time.monotonic()
                if name == WAKE:
                    self._drain_wake()
                elif name == UDP:
                    self._take_udp(now)
                else:
                    self._take_serial(int(name), now)  # type: ignore[call-overload]
            now = time.monotonic()
            self._take_closed(now)
            stop = self._take_inbox(now)
            if stop is not None:
                return stop.reason
            for peer in self.peers.values():
                self._take_events(peer.wake(now), now)
            self._release(now)
            for peer in self.peers.values():
                self._flush_peer(peer, now)
            self.hub.flush(now)
            self._take_closed(now)
            for robot, peer in self.peers.items():
                busy_until = self.hub.busy_until(robot)
                if busy_until is not None:  # a serial line: the robot hears it all then
                    peer.sending(busy_until)
            self._publish_stats(now)

    def _deadline(self) -> float:
        """The loop's next own deadline (the hub adds its transports')."""
        deadlines = [self._next_stats]
        deadlines += [peer.deadline for peer in self.peers.values() if peer.deadline is not None]
        for directions in (self.up, self.down):
            deadlines += [d.deadline for d in directions.values() if d.deadline is not None]
        return min(deadlines, default=math.inf)

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
        kind = (
            keyspace.link(keyspace.ALIVE_WORLD)
            if token.up
            else keyspace.link(keyspace.ALIVE_WORLD, Part.GONE)
        )
        for peer in self.peers.values():
            peer.send(kind, token.instance.encode(), None)

    # --- links in ----------------------------------------------------------------------

    def _take_udp(self, now: float) -> None:
        for data, source in self.hub.receive(UDP, now):
            try:
                header = codec.read_header(data)
            except codec.LinkError as error:
                self.unattributed[error.refusal] += 1
                continue
            peer = self.peers.get(header.robot)
            if peer is None or peer.transport != "udp":
                self.unattributed[codec.Refusal.UNEXPECTED] += 1
                continue
            self._arrive(peer, data, source, now)

    def _take_serial(self, robot: int, now: float) -> None:
        peer = self.peers[robot]
        frames = self.hub.receive(robot, now)
        line = self.hub.transports.get(robot)
        if line is not None:
            for refusal, count in line.refused.items():
                for _ in range(count):
                    peer.refuse(codec.LinkError(codec.Refusal(refusal), "serial framing"))
            line.refused.clear()
        for frame, _ in frames:
            self._arrive(peer, frame, robot, now)
        if self.hub.receiving(robot):
            peer.hearing(now)  # a long frame from the robot under way is not silence

    def _take_closed(self, now: float) -> None:
        """End the session of each serial line that closed (the hub opens it again)."""
        for name, _ in self.hub.take_closed():
            peer = self.peers.get(name) if isinstance(name, int) else None
            if peer is not None and peer.connected:
                self._take_events(peer.close(codec.ByeReason.GOING_AWAY), now)
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

    # --- what the peers say ------------------------------------------------------------

    def _take_events(self, events: list[PeerEvent], now: float) -> None:
        for event in events:
            if isinstance(event, Message):
                self._relay(event)
            elif isinstance(event, SessionOpened):
                peer = self.peers[event.robot]
                for instance in sorted(self.worlds):
                    peer.send(keyspace.link(keyspace.ALIVE_WORLD), instance.encode(), None)
                self._publish_stats(now, force=True)
            elif isinstance(event, SessionClosed):
                self.presence.gone(event.robot)
                # What waits on a serial line for the session that ended would hold up the
                # next one's welcome behind it (a map of 1000 sites is 5 s at 115200 baud).
                self.hub.discard_waiting(event.robot, now)
                self._publish_stats(now, force=True)

    def _relay(self, message: Message) -> None:
        """Publish what the program sent, as it sent it, on its robot's key."""
        if message.kind is keyspace.link(keyspace.INFO):
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
        self.hub.send(UDP if peer.transport == "udp" else peer.robot, frame, target, now)

    # --- figures -----------------------------------------------------------------------

    def _publish_stats(self, now: float, force: bool = False) -> None:
        if not force and now < self._next_stats:
            return
        self._next_stats = now + STATS_EVERY
        for robot, peer in self.peers.items():
            key = self.keys.of(keyspace.LINK, robot)
            payload = protocol.encode(peer.stats())
            attachment = auth.seal(self.keyring, names.BRIDGE, key, payload)
            self._stats_publishers[robot].put(payload, attachment=attachment)
