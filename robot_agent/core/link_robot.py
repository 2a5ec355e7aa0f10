"""The robot outside the emulator, without its I/O (pure): the link session, the question for
the map and, once it is answered, the robot's endpoint fed what the link brings.

It says hello until the bridge welcomes it (``session.LinkClient``), asks the world for its
map (``world/info``, relayed), builds its controller (its generator from the run's seed and
its id, as every robot's), sends its first status, and from then on steps once a tick's
inputs are in: sense, radio, camera frame as the world sealed them for it; act, radio and
status sealed with its own run key. The bridge relays them and can change none of them. A
world token the bridge reports is followed only once that world has answered for itself
(``world/info`` asked with the token's instance, as every robot does: docs/protocol.md).
``robot_agent/link/program.py`` is its loop and command line (``robot-agent --link``).
"""

from __future__ import annotations

import logging
import math
import secrets
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.core.session import LinkClient, LinkData, Lost, Welcomed
from bestofn_swarm.wire import auth, keyspace, names, protocol, settings
from bestofn_swarm.wire.keyspace import Part, Party
from robot_agent.core import builder
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.endpoint import Outgoing, RobotEndpoint
from robot_agent.core.plugin import PluginError
from robot_agent.core.plugins import Plugins

log = logging.getLogger("link.robot")

ASK_EVERY = 1.0  # seconds between questions for the map until one is answered
# Seconds between two sendings of the robot's latest status. The robot process publishes a
# status when it changes, over Zenoh, which does not lose it; a link may lose frames, and
# a status lost (a decision) would be lost for good. A repeat changes nothing anywhere.
STATUS_EVERY = 2.0
# A world token the bridge reports is followed once that world answers world/info asked
# with the token's instance (and so for it alone): asked up to PROVE_TRIES times,
# PROVE_EVERY seconds apart, as the robot process does (bestofn_swarm/plumbing/world_info.py); a
# token no world answers for is counted as a rejection.
PROVE_TRIES = 5
PROVE_EVERY = 2.0
# A question asked again does not void the ones before it: an answer to any of the last
# RECENT_QUESTIONS counts, so a relay slower than ASK_EVERY or PROVE_EVERY (a link with a
# long delay) still brings the map and the proofs.
RECENT_QUESTIONS = 8
# The link carries the robot's inputs and what it sends under their kinds' frame codes
# (the key table's). Inputs that come before the robot can step (none, normally: the bridge
# makes it present only once it has sent its first status) are dropped and counted.
INPUTS = frozenset(keyspace.link(kind) for kind in keyspace.heard_by(Party.ROBOT))


@dataclass
class Asking:
    """A question on world/info under way: the nonces of its last RECENT_QUESTIONS askings
    (newest last), and when to ask again. For the map ``instance`` is empty (any world
    answers); to prove a world token it is the token's instance, and ``tries`` counts the
    questions asked."""

    nonces: tuple[bytes, ...]
    again_at: float
    instance: str = ""
    tries: int = 1

    def again(self, nonce: bytes, again_at: float, tries: int) -> Asking:
        nonces = (*self.nonces, nonce)[-RECENT_QUESTIONS:]
        return Asking(nonces, again_at, self.instance, tries)


@dataclass
class LinkRobot:
    """The program without its I/O: the link session (``client``), the question for the
    map, and once it is answered the robot's endpoint, fed what the link brings."""

    robot: int
    run: str
    keyring: auth.Keyring
    client: LinkClient
    endpoint: RobotEndpoint | None = None
    worlds: set[str] = field(default_factory=set)  # world instances the bridge reports
    asking: Asking | None = None  # the question for the map
    proving: dict[str, Asking] = field(default_factory=dict)  # world tokens, by instance
    ended: bool = False
    failed: bool = False  # it ended because it cannot run (its settings, its map)
    last_status: Outgoing | None = None
    status_again_at: float = 0.0
    dropped: Counter[str] = field(default_factory=Counter)  # inputs it could not use
    # The run's controller settings as this program runs them, with their plug-ins
    # resolved (robot_agent/link/program.py: its own --controller, --strategy, --pooling);
    # None: the run's settings and the built-ins they name.
    prepare: Callable[[ControllerConfig], tuple[ControllerConfig, Plugins]] | None = None
    failure: str | None = None  # a plug-in failed or could not make the robot: its one line

    @classmethod
    def create(
        cls,
        robot: int,
        run: str,
        keyring: auth.Keyring,
        prepare: Callable[[ControllerConfig], tuple[ControllerConfig, Plugins]] | None = None,
    ) -> LinkRobot:
        key = keyring.key(names.robot_identity(robot))
        assert key is not None  # read_key_file checked it
        return cls(robot, run, keyring, LinkClient(robot, codec.link_key(key)), prepare=prepare)

    @property
    def identity(self) -> str:
        return names.robot_identity(self.robot)

    @property
    def deadline(self) -> float:
        asked = self.asking.again_at if self.asking is not None else math.inf
        proving = min((ask.again_at for ask in self.proving.values()), default=math.inf)
        status = self.status_again_at if self.last_status is not None else math.inf
        return min(self.client.deadline, asked, proving, status)

    # --- fed by the loop -----------------------------------------------------------

    def wake(self, now: float) -> None:
        for event in self.client.wake(now):
            self._take(event, now)
        if self.asking is not None and now >= self.asking.again_at and self.client.open:
            self._ask(now)
        for instance, ask in list(self.proving.items()):
            if now >= ask.again_at and self.client.open:
                self._prove(instance, now, ask.tries + 1)
        if self.last_status is not None and now >= self.status_again_at and self.client.open:
            self._send_status(self.last_status, now)

    def receive(self, data: bytes, now: float) -> None:
        for event in self.client.receive(data, now):
            self._take(event, now)

    def hearing(self, now: float) -> None:
        """A frame is arriving on a serial line: the session is alive, and no question is
        asked again while it comes (it may be the answer: a map of 1000 sites takes 5 s at
        115200 baud, and each question asked again would bring one more)."""
        self.client.hearing(now)
        if self.asking is not None:
            self.asking.again_at = max(self.asking.again_at, now + ASK_EVERY)
        for ask in self.proving.values():
            ask.again_at = max(ask.again_at, now + PROVE_EVERY)

    def stop(self) -> None:
        self.client.bye(codec.ByeReason.GOING_AWAY)

    # --- events of the link --------------------------------------------------------

    def _take(self, event: Welcomed | LinkData | Lost, now: float) -> None:
        if isinstance(event, Welcomed):
            self._welcomed(event.welcome, now)
        elif isinstance(event, Lost):
            self._lost(event)
        else:
            self._received(event, now)

    def _welcomed(self, welcome: codec.LinkWelcome, now: float) -> None:
        if welcome.run != self.run:
            log.error("the bridge serves run %s, the key file is of run %s", welcome.run, self.run)
            self.client.bye(codec.ByeReason.GOING_AWAY)
            self.ended = self.failed = True
            return
        log.info("robot %d: link session %d open", self.robot, self.client.sessions)
        if self.endpoint is None:
            self._ask(now)
        else:  # back after a lost link: say where it is, and so be present again
            self._send_status(self.endpoint.status(max(0, self.endpoint.last_tick)), now)

    def _lost(self, event: Lost) -> None:
        self.asking = None
        self.proving.clear()
        if self.endpoint is not None:
            for instance in sorted(self.worlds):  # the world is out of reach with the link
                self.endpoint.world_vanished(instance)
        self.worlds.clear()
        if event.ended:
            log.info("robot %d: the run has ended", self.robot)
            self.ended = True

    def _received(self, event: LinkData, now: float) -> None:
        kind = event.kind
        if kind is keyspace.link(keyspace.INFO, Part.REPLY):
            self._answered(event.payload, event.attachment, now)
        elif kind is keyspace.link(
            keyspace.INFO, Part.ERROR
        ):  # a token's question goes unanswered: a retry
            log.info("a world refused a question on world/info: %r", event.payload[:200])
        elif kind in (
            keyspace.link(keyspace.ALIVE_WORLD),
            keyspace.link(keyspace.ALIVE_WORLD, Part.GONE),
        ):
            self._world(kind, event.payload, now)
        elif kind in INPUTS:
            if self.endpoint is None:
                self.dropped[kind.name.lower()] += 1
                return
            try:
                step = self.endpoint.receive(kind.kind, event.payload, event.attachment)
            except PluginError as error:  # the robot's plug-in failed: it stops here
                self._fail(str(error))
                return
            if step is None:
                return
            for message in step.outgoing:  # its transmissions, its act, its status if new
                if message.kind is keyspace.STATUS:
                    self._send_status(message, now)
                else:
                    code = keyspace.link(message.kind)
                    self.client.send(code, message.payload, message.attachment)

    def _world(self, kind: keyspace.LinkCode, payload: bytes, now: float) -> None:
        """A world token the bridge reports, appeared or gone. The bridge is trusted with
        nothing the robot believes: an appeared token is followed only once that world
        answers for itself (``_prove``)."""
        instance = payload.decode(errors="replace")[: names.MAX_NAME_LENGTH]
        if kind is keyspace.link(keyspace.ALIVE_WORLD):
            self.worlds.add(instance)
            if self.endpoint is not None and instance not in self.proving:
                self._prove(instance, now, 1)
        else:
            self.worlds.discard(instance)
            self.proving.pop(instance, None)
            if self.endpoint is not None:
                self.endpoint.world_vanished(instance)

    # --- the map -------------------------------------------------------------------

    def _keys(self) -> keyspace.Keys:
        welcome = self.client.welcome
        assert welcome is not None
        return keyspace.Keys(welcome.run, welcome.root)

    def _question(self, instance: str) -> tuple[bytes, bytes | None]:
        """A question on ``world/info`` in the robot's name with a fresh nonce
        (auth.query_seal), sent: its payload names the world instance that must answer
        (empty: any). Its nonce and attachment."""
        nonce = secrets.token_bytes(auth.NONCE_BYTES)
        payload = instance.encode()
        key = self._keys().of(keyspace.INFO)
        attachment = auth.query_seal(self.keyring, self.identity, key, payload, nonce)
        self.client.send(keyspace.link(keyspace.INFO), payload, attachment)
        return nonce, attachment

    def _ask(self, now: float) -> None:
        """Ask any world for the map."""
        nonce, _ = self._question("")
        before = self.asking or Asking((), 0.0)
        self.asking = before.again(nonce, now + ASK_EVERY, 1)

    def _prove(self, instance: str, now: float, tries: int) -> None:
        """Ask world ``instance`` to answer for its token; after PROVE_TRIES questions
        without an answer that holds, the token is someone else's (counted)."""
        if tries > PROVE_TRIES:
            del self.proving[instance]
            assert self.endpoint is not None
            self.endpoint.world_unproven(instance)
            return
        nonce, _ = self._question(instance)
        before = self.proving.get(instance) or Asking((), 0.0, instance)
        self.proving[instance] = before.again(nonce, now + PROVE_EVERY, tries)

    def _holds(self, ask: Asking, payload: bytes, attachment: bytes | None) -> bool:
        """Whether an answer on world/info is the world's answer to ``ask`` (to any of its
        last RECENT_QUESTIONS askings)."""
        try:
            nonce = self.keyring.open(
                self.identity, self._keys().of(keyspace.INFO), payload, attachment
            )
        except auth.AuthError:
            return False
        return nonce in ask.nonces

    def _answered(self, payload: bytes, attachment: bytes | None, now: float) -> None:
        if self.asking is not None and self.endpoint is None:
            if not self._holds(self.asking, payload, attachment):
                log.warning("robot %d: an answer on world/info that does not hold", self.robot)
                return
            try:
                info = protocol.decode(payload, protocol.WorldInfo)
            except protocol.ProtocolError as error:
                log.warning("robot %d: a map that does not decode: %s", self.robot, error)
                return
            self.asking = None
            try:
                self.endpoint = self._build(self._keys(), info)
            except PluginError as error:  # a plug-in that cannot make the robot
                self._fail(str(error))
                return
            except ValueError as error:  # the run's settings or map, refused
                log.error("robot %d cannot run: %s", self.robot, error)
                self.client.bye(codec.ByeReason.GOING_AWAY)
                self.ended = self.failed = True
                return
            self._send_status(self.endpoint.status(0), now)
            for instance in sorted(self.worlds):  # reported before the map came
                self._prove(instance, now, 1)
            return
        for instance, ask in list(self.proving.items()):
            if self._holds(ask, payload, attachment):
                del self.proving[instance]
                if self.endpoint is not None and instance in self.worlds:
                    self.endpoint.world_appeared(instance)
                return

    def _build(self, keys: keyspace.Keys, info: protocol.WorldInfo) -> RobotEndpoint:
        """The robot as every robot of the run is built (robot_agent/core/builder.py): the
        run's controller settings, its generator from the world's seed and its id.
        ValueError if the settings or the map are refused."""
        welcome = self.client.welcome
        assert welcome is not None
        config = settings.decode(bytes(welcome.controller), ControllerConfig)
        plugins = None
        if self.prepare is not None:
            config, plugins = self.prepare(config)
        robot = builder.build_robot(
            self.robot, info, config, keys=keys, keyring=self.keyring, plugins=plugins
        )
        log.info(
            "robot %d: %d sites, clock %s, seed %d: running",
            self.robot,
            len(info.sites),
            info.clock,
            info.seed,
        )
        return robot

    def _fail(self, failure: str) -> None:
        """A plug-in failed: say goodbye and end (the program prints ``failure``)."""
        self.failure = failure
        self.client.bye(codec.ByeReason.GOING_AWAY)
        self.ended = self.failed = True

    def _send_status(self, status: Outgoing, now: float) -> None:
        """Send the robot's status, and again every STATUS_EVERY until it changes."""
        self.client.send(keyspace.link(keyspace.STATUS), status.payload, status.attachment)
        self.last_status = status
        self.status_again_at = now + STATUS_EVERY

    # --- what it did ---------------------------------------------------------------

    def summary(self) -> dict[str, object]:
        controller = self.endpoint.controller if self.endpoint is not None else None
        status = (
            controller.status(self.endpoint.last_tick) if controller and self.endpoint else None
        )
        return {
            "id": self.robot,
            "phase": status.phase if status else None,
            "decided_site": status.decided_site if status else None,
            "decision_time": status.decision_time if status else None,
            "trips": status.trips if status else 0,
            "last_tick": self.endpoint.last_tick if self.endpoint else None,
            "rejected": self.endpoint.rejects.count if self.endpoint else 0,
            "sessions": self.client.sessions,
            "refused": dict(self.client.refused),
            "dropped": dict(self.dropped),
        }
