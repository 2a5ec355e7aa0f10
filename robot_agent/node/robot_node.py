"""``robot-agent``: robots on Zenoh. The only Zenoh code of the robot.

Each robot has its own Zenoh session, keys, liveliness token and RNG; a process can host
one robot or many. A process hosting several robots answers for all of them in one batch
of acts per input that stepped them, on its first robot's session (``host/<lead>/act``,
wire/batch.py); the world then sends their senses in one batch too. Each entry is
sealed with its own robot's key, and every robot keeps its own keys for radio, status,
camera and liveliness.

Threads: a robot's inputs (sense, batch of senses, radio, camera) are handled in the Zenoh
callback that brings them, under one lock per process, so the robots of a process are
stepped by one thread at a time and a tick's step needs no wake-up of another thread (that
hand-off was a large part of a lockstep tick: docs/performance.md). Nothing queues for
them: an input waits in Zenoh until the robots are free. The process's own thread handles
what is rare (the world's liveliness, stop) from a bounded inbox, under the same lock, and
the inbox still takes what is too big to be a valid input, to drop and count it.

Lockstep: the world's ``sense`` for tick t says how many radio messages and whether a
camera frame belong to tick t; the robot steps only when all of them are in, so the
order in which Zenoh delivers different keys cannot change a run.

Trust: in a keyed run a robot holds only its own run key; it believes an input only with
that key's tag (wire/auth.py), only for a tick within reach of its last one, and
holds at most PENDING_BYTES of inputs for ticks it has not reached (wire/guard.py).
"""

from __future__ import annotations

import argparse
import logging
import random
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import msgspec
import zenoh

from plumbing import cliargs, run_keys, settings_cli
from plumbing.inbox import BoundedInbox
from plumbing.lifecycle import die_with_launcher
from plumbing.trace import TraceWriter, now, open_trace
from plumbing.world_info import ask, fetch_world_info
from plumbing.zenoh_session import certificate_name, open_from_args, reliable_publisher
from robot_agent.core import byzantine
from robot_agent.core.ports import RejectCounter, RobotController
from robot_agent.core.simulated import SimulatedPorts
from robot_agent.node.options import AGENT_OPTIONS, RobotAgentConfig, hosted_byzantine
from wire import auth, batch, guard, names, protocol
from wire.names import Role

log = logging.getLogger("robot_agent")
Meta = TypeVar("Meta", protocol.RadioRxMeta, protocol.CameraMeta)

# What may wait for one robot: the inputs of ticks it has not reached (a lockstep robot
# needs one tick's; a camera frame and the radio of a crowded nest are well under this),
# and what may wait in a process's inbox for its one thread.
PENDING_BYTES = 4 * 2**20
PENDING_MESSAGES = 4000
# The inbox grows with the robots a process hosts; a tick's inputs are a few kilobytes
# per robot, so this leaves room for a long stall, not for a flood.
INBOX_BYTES, INBOX_BYTES_PER_ROBOT = 16 * 2**20, 2**20
MAX_MESSAGE_BYTES = protocol.MAX_FRAME_BYTES + 1024  # a frame and its attachment


@dataclass(frozen=True)
class Event:
    robot: int
    kind: str  # sense | batch | camera | rx | world | no-world | stop
    payload: bytes = b""
    attachment: bytes | None = None
    arrived: float = 0.0  # monotonic time the callback took it (only when tracing)


@dataclass
class _TickInputs:
    sense: protocol.Sense | None = None
    rx: list[tuple[str, bytes]] = field(default_factory=list)
    frame: bytes | None = None
    size: int = 0  # bytes held for this tick
    messages: int = 0
    arrived: float = 0.0  # when its last input reached the callback (only when tracing)


class RobotNode:
    """One robot: its session, its controller, and the lockstep bookkeeping."""

    def __init__(
        self,
        robot_id: int,
        *,
        session: zenoh.Session,
        keys: protocol.Keys,
        controller: RobotController,
        inbox: BoundedInbox[Event],
        world: protocol.WorldInfo,
        lock: threading.Lock | None = None,
        keyring: auth.Keyring | None = None,
        trace: TraceWriter | None = None,
    ) -> None:
        self.robot_id = robot_id
        self.identity = names.robot_identity(robot_id)
        self.session = session
        self.keys = keys
        self.controller = controller
        self.inbox = inbox
        # The process's (shared by the robots it hosts): one thread at a time steps them.
        self.lock = lock or threading.Lock()
        # Set under the lock when the process stops: a callback that comes after does
        # nothing, so none publishes on a session being closed.
        self.closed = False
        self.lockstep = world.clock == "lockstep"
        self.keyring = keyring  # None: an unauthenticated run
        self.dt = world.dt
        self.rejects = RejectCounter()
        self.ports = SimulatedPorts(self.rejects)  # the body and radio control_step drives
        self.pending: dict[int, _TickInputs] = {}
        self.pending_bytes = 0
        self.pending_messages = 0
        self.ticks = guard.TickWindow()
        self.time_offset = 0.0  # keeps the controller's clock monotonic across world restarts
        self.last_t = 0.0
        self.worlds = guard.WorldFollower()  # the world server's instance (its Zenoh id)
        self._declared: list[object] = []
        self.trace = trace  # --trace: one line per step (plumbing/trace.py)
        self._arrived = 0.0  # the arrival time of the event being handled
        self.host: HostBatch | None = None  # set when its acts go out in its process's batch

    @property
    def last_tick(self) -> int:
        return self.ticks.last

    def start(self) -> None:
        """Subscribe first, then announce liveliness, so no tick is missed."""
        keys, robot, session = self.keys, self.robot_id, self.session

        def forward(kind: str) -> Callable[[zenoh.Sample], None]:
            def callback(sample: zenoh.Sample) -> None:
                attachment = sample.attachment
                payload = sample.payload.to_bytes()
                extra = attachment.to_bytes() if attachment is not None else None
                size = len(payload) + len(extra or b"")
                arrived = now() if self.trace is not None else 0.0
                event = Event(robot, kind, payload, extra, arrived)
                if size > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                    self.inbox.put(event, size, robot)
                    return
                with self.lock:
                    if self.closed:
                        return
                    self.handle(event)
                    if self.host is not None:
                        self.host.flush()

            return callback

        self._declared = [
            session.declare_subscriber(keys.sense(robot), forward("sense")),
            session.declare_subscriber(keys.camera(robot), forward("camera")),
            session.declare_subscriber(keys.radio_rx(names.robot_name(robot)), forward("rx")),
            session.liveliness().declare_subscriber(
                keys.alive(Role.WORLD, "*"),
                lambda sample: self.inbox.put(
                    Event(
                        robot,
                        "world" if sample.kind == zenoh.SampleKind.PUT else "no-world",
                        keys.last_chunk(str(sample.key_expr)).encode(),
                    )
                ),
                history=True,
            ),
        ]
        self._act = reliable_publisher(session, keys.act(robot))
        self._status = reliable_publisher(session, keys.status(robot))
        self._tx = reliable_publisher(session, keys.radio_tx(names.robot_name(robot)))
        self._publish_status(0)
        self._token = session.liveliness().declare_token(keys.alive(Role.ROBOT, robot))

    def close(self) -> None:
        self._token.undeclare()
        for entity in self._declared:
            entity.undeclare()  # type: ignore[attr-defined]

    # --- inputs --------------------------------------------------------------------

    def handle(self, event: Event) -> None:
        if event.kind in ("world", "no-world"):
            self._world_presence(event.payload.decode(errors="replace"), event.kind == "world")
            return
        key = {"sense": "sense", "rx": "radio/rx", "camera": "camera"}.get(event.kind)
        if key is None:
            return
        self._arrived = event.arrived
        key_expr = {
            "sense": self.keys.sense,
            "rx": self.keys.radio_rx,
            "camera": self.keys.camera,
        }[event.kind](self.robot_id)
        try:
            metadata = auth.unseal(
                self.keyring, self.identity, key_expr, event.payload, event.attachment
            )
        except auth.AuthError as error:
            self._reject(key, error)
            return
        if event.kind == "sense":
            self._take_sense(event.payload)
        elif event.kind == "rx":
            meta = self._metadata(metadata, protocol.RadioRxMeta, key)
            if meta is not None and self._admit(meta.tick, key, len(event.payload)):
                self.pending[meta.tick].rx.append((meta.sender, event.payload))
                self._advance(meta.tick)
        else:
            camera = self._metadata(metadata, protocol.CameraMeta, key)
            if camera is not None and self._admit(camera.tick, key, len(event.payload)):
                self.pending[camera.tick].frame = event.payload
                self._advance(camera.tick)

    def _take_sense(self, payload: bytes) -> None:
        try:
            sense = protocol.decode(payload, protocol.Sense)
            refused = guard.time_refused(sense.tick, sense.t, self.dt)
            if refused:
                raise protocol.ProtocolError(refused)
        except protocol.ProtocolError as error:
            self._reject("sense", error)
            return
        if not self.ticks.ahead(sense.tick):
            return  # a repeat of a tick already answered
        if self._admit(sense.tick, "sense", 0):
            self.pending[sense.tick].sense = sense
            self._advance(sense.tick)

    def _admit(self, tick: int, key: str, size: int) -> bool:
        """Make room for one input of ``tick``, if it is believable and fits this robot's
        budget; a stale one is dropped quietly, anything else rejected (counted)."""
        if not self.ticks.ahead(tick):
            return False  # for a tick already answered: late, not wrong
        refused = self.ticks.refuses(tick)
        if refused is None and (
            self.pending_bytes + size > PENDING_BYTES or self.pending_messages >= PENDING_MESSAGES
        ):
            refused = f"more than {PENDING_BYTES} bytes or {PENDING_MESSAGES} messages waiting"
        if refused is not None:
            self._reject(key, protocol.ProtocolError(refused))
            return False
        inputs = self.pending.setdefault(tick, _TickInputs())
        inputs.arrived = max(inputs.arrived, self._arrived)
        inputs.size += size
        inputs.messages += 1
        self.pending_bytes += size
        self.pending_messages += 1
        return True

    def _metadata(self, metadata: bytes | None, kind: type[Meta], key: str) -> Meta | None:
        """The event's metadata (in its Zenoh attachment) as ``kind``, or None, rejected."""
        try:
            if metadata is None:
                raise protocol.ProtocolError("missing attachment")
            return protocol.decode(metadata, kind)
        except protocol.ProtocolError as error:
            self._reject(key, error)
            return None

    def _world_presence(self, instance: str, present: bool) -> None:
        """Wait while the world server is gone; when another one appears, follow its ticks.

        A new world counts ticks from zero again: forget the old tick numbers, and shift
        its time so that the controller's clock never runs backwards. A second world token
        while the followed world is still alive is not a restart: ignored.
        """
        if not present:
            if self.worlds.vanished(instance):
                log.warning("robot %d lost the world server; waiting", self.robot_id)
            return
        seen = self.worlds.appeared(instance)
        if seen == "new":
            log.warning("robot %d: a new world server appeared; resuming", self.robot_id)
            self._drop_pending(list(self.pending))
            self.ticks = guard.TickWindow()
            self.time_offset = self.last_t
        elif seen == "back":
            # Its ticks went on while this robot was cut off, perhaps by far more than
            # the tick window allows.
            log.warning("robot %d: the world server is back; resuming", self.robot_id)
            self._drop_pending(list(self.pending))
            self.ticks.rejoin()
        elif instance != self.worlds.followed:
            log.warning(
                "robot %d: ignoring a second world token %s while following %s",
                self.robot_id,
                instance,
                self.worlds.followed,
            )

    def _reject(self, key: str, error: Exception) -> None:
        self.rejects.reject(f"robot {self.robot_id} {key}", error)

    def _drop_pending(self, ticks: list[int]) -> None:
        for tick in ticks:
            inputs = self.pending.pop(tick)
            self.pending_bytes -= inputs.size
            self.pending_messages -= inputs.messages

    def _advance(self, tick: int) -> None:
        inputs = self.pending.get(tick)
        if inputs is None or inputs.sense is None:
            return
        sense = inputs.sense
        if self.lockstep:
            complete = len(inputs.rx) >= sense.rx and (inputs.frame is not None or not sense.camera)
            if not complete:
                return
            # Inputs of an earlier tick that never all arrived: one was dropped (counted in
            # this robot's rejects), and the world went on without this robot's answer
            # (counted in the world's stalls). Nothing more to report: forget them.
            self._drop_pending([old for old in self.pending if old < tick])
        else:
            # Real time: use whatever has arrived, including earlier ticks' radio.
            earlier = sorted(t for t in self.pending if t < tick)
            inputs.rx[:0] = [item for old in earlier for item in self.pending[old].rx]
            self._drop_pending(earlier)
        self._drop_pending([tick])
        self._step(sense, inputs)

    # --- one control step ----------------------------------------------------------

    def _step(self, sense: protocol.Sense, inputs: _TickInputs) -> None:
        handled = now() if self.trace is not None else 0.0
        if self.time_offset:
            sense = msgspec.structs.replace(sense, t=sense.t + self.time_offset)
        self.last_t = sense.t
        answer = self.ports.answer(self.controller, sense, inputs.rx, inputs.frame)
        for sent in answer.transmissions:
            attachment = self._seal(self._tx_key, sent.payload, sent.meta)
            self._tx.put(sent.payload, attachment=attachment)
        act = protocol.encode(answer.act)
        attachment = self._seal(self._act_key, act)
        self.ticks.acted(sense.tick)
        step: dict[str, float] | None = None
        if self.trace is not None:
            step = {
                "robot": self.robot_id,
                "tick": sense.tick,
                "arrived": round(inputs.arrived, 6),
                "handled": round(handled, 6),
            }
        if self.host is not None:
            self.host.add(batch.Entry(self.robot_id, act, attachment), step)
        else:
            self._act.put(act, attachment=attachment)
            if self.trace is not None and step is not None:
                self.trace.write(**step, answered=round(now(), 6))
        if self.controller.take_status_change():
            self._publish_status(sense.tick)

    def _publish_status(self, tick: int) -> None:
        dropped = self.inbox.take_dropped(self.robot_id)
        if dropped:  # dropped on arrival: too big, or the process's inbox was full
            for _ in range(dropped):
                self._reject("inbox", protocol.ProtocolError("dropped on arrival"))
        status = self.controller.status(tick)
        status = msgspec.structs.replace(status, rejected=status.rejected + self.rejects.count)
        payload = protocol.encode(status)
        self._status.put(payload, attachment=self._seal(self.keys.status(self.robot_id), payload))

    @property
    def _tx_key(self) -> str:
        return self.keys.radio_tx(names.robot_name(self.robot_id))

    @property
    def _act_key(self) -> str:
        return self.keys.act(self.robot_id)

    def _seal(self, key: str, payload: bytes, metadata: bytes = b"") -> bytes | None:
        return auth.seal(self.keyring, self.identity, key, payload, metadata)


class HostBatch:
    """The batched path of a process hosting several robots: the senses of all of them
    arrive as one batch on ``host/<lead>/sense``, and the acts of the robots stepped on one
    event leave as one batch on ``host/<lead>/act``, both on the lead robot's session.

    The world learns the path from the first batch of acts, and until then (and after
    it restarts) sends each robot's sense on its own key, which every robot still
    subscribes to; a tick's sense is taken once whichever way it came.

    Like every input, a batch is handled in its Zenoh callback under the process's lock;
    a robot steps only once all of a tick's inputs are in, whatever order they came in.
    """

    def __init__(self, nodes: Sequence[RobotNode], inbox: BoundedInbox[Event]) -> None:
        self.lead = nodes[0]
        self.by_id = {node.robot_id: node for node in nodes}
        self.inbox = inbox
        self.entries: list[batch.Entry] = []
        self.steps: list[dict[str, float]] = []  # --trace lines of the batched acts
        self.lock = self.lead.lock
        with self.lock:
            for node in nodes:
                node.host = self

    def start(self) -> None:
        lead, keys = self.lead, self.lead.keys

        def callback(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            arrived = now() if lead.trace is not None else 0.0
            event = Event(lead.robot_id, "batch", payload, None, arrived)
            if len(payload) > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                self.inbox.put(event, len(payload), lead.robot_id)
                return
            with self.lock:
                if self.lead.closed:
                    return
                self.deliver(event)
                self.flush()

        self._subscriber = lead.session.declare_subscriber(keys.host_sense(lead.robot_id), callback)
        self._publisher = reliable_publisher(lead.session, keys.host_act(lead.robot_id))

    def close(self) -> None:
        self._subscriber.undeclare()

    def deliver(self, event: Event) -> None:
        """Hand each entry of a batch of senses to its robot, as if it came on its key."""
        try:
            entries = batch.decode(event.payload)
        except batch.BatchError as error:
            self.lead._reject("host sense", error)
            return
        for robot, payload, attachment in entries:
            node = self.by_id.get(robot)
            if node is None:
                stranger = protocol.ProtocolError(f"robot {robot} is not hosted here")
                self.lead._reject("host sense", stranger)
                continue
            node.handle(Event(robot, "sense", payload, attachment, event.arrived))

    def add(self, entry: batch.Entry, step: dict[str, float] | None) -> None:
        self.entries.append(entry)
        if step is not None:
            self.steps.append(step)

    def flush(self) -> None:
        """Publish the acts gathered since the last flush, as one batch."""
        if not self.entries:
            return
        self._publisher.put(batch.encode(self.entries))
        self.entries.clear()
        trace = self.lead.trace
        if trace is not None:
            answered = round(now(), 6)
            for step in self.steps:
                trace.write(**step, answered=answered)
            self.steps.clear()


def serve(nodes: Sequence[RobotNode], inbox: BoundedInbox[Event]) -> None:
    """Feed the nodes the events of their inbox (the world's liveliness) until a stop event
    arrives; their inputs they handle in Zenoh's callbacks."""
    by_id = {node.robot_id: node for node in nodes}
    while True:
        event = inbox.get()
        if event.kind == "stop":
            return
        node = by_id[event.robot]
        with node.lock:
            node.handle(event)


# --- command line ------------------------------------------------------------------------


def robot_id(text: str) -> int | None:
    """A robot id, or None for ``auto``."""
    if text == "auto":
        return None
    return cliargs.int_range(0, names.MAX_ROBOTS - 1)(text)


class NoKeyError(Exception):
    """The world assigned an id whose key this process does not hold."""


def ask_for_id(
    session: zenoh.Session,
    keys: protocol.Keys,
    timeout: float,
    keyring: auth.Keyring | None = None,
) -> int:
    """Ask the world server for a free robot id (``--id auto``).

    In a keyed run the question is asked in the name of a robot whose key this process
    holds (robot 0 with the run secret), and the id is only taken if its key is held too.
    """
    asker = ""
    if keyring is not None:
        robots = [name for name in keyring.identities if name.startswith("robot/")]
        asker = robots[0] if robots else names.robot_identity(0)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        answers, refused = ask(session, keys.world_join, keyring, asker)
        for answer in answers:
            try:
                robot = protocol.decode(answer, protocol.JoinReply).id
            except protocol.ProtocolError as error:
                raise TimeoutError(f"invalid answer on {keys.world_join}: {error}") from None
            if keyring is not None and not keyring.holds(names.robot_identity(robot)):
                raise NoKeyError(f"the world server gave id {robot}, whose key this process lacks")
            return robot
        if refused and not answers:
            raise TimeoutError(f"the world server gave no id: {refused[-1]}")
        time.sleep(0.2)
    raise TimeoutError(f"no world server answered on {keys.world_join}")


def certificate_robot(config_file: str | None) -> int | None:
    """The robot a Zenoh configuration's client certificate names (``CN=robot-<id>``).

    Under the access control a robot may speak only as the robot of its certificate, so
    ``--id auto`` takes that id rather than ask the world for one it could not use."""
    if not config_file:
        return None
    return names.robot_of_certificate(certificate_name(config_file))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robot-agent",
        description="A robot of the swarm: the decision controller on Zenoh. Several --id "
        "options host several robots in this process, each with its own Zenoh session.",
    )
    parser.add_argument(
        "--id",
        dest="ids",
        type=robot_id,
        action="append",
        required=True,
        metavar="N|auto",
        help="robot id, or 'auto' to be given one by the world server "
        "(repeatable to host several robots)",
    )
    parser.add_argument(
        "--info-timeout",
        type=cliargs.positive_float,
        default=60.0,
        help="wall seconds to wait for the world server (default: 60)",
    )
    AGENT_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, RobotAgentConfig)
    parser.add_argument(
        "--no-batch",
        action="store_true",
        help="answer on each robot's own keys even when hosting several robots (by default "
        "a process hosting several robots exchanges one batch per step with the world)",
    )
    parser.add_argument(
        "--trace",
        metavar="PATH",
        default=None,
        help="write a timeline of every control step to PATH as JSON lines (docs/performance.md)",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    parser = build_parser()
    args = parser.parse_args(argv)
    fixed = [robot for robot in args.ids if robot is not None]
    if len(set(fixed)) != len(fixed):
        parser.exit(2, "robot-agent: error: the same --id is given twice\n")
    if None in args.ids and "{id}" in (args.zenoh_config or ""):
        parser.exit(2, "robot-agent: error: --id auto cannot fill '{id}' in --zenoh-config\n")
    agent: RobotAgentConfig = settings_cli.config_from(parser, args, AGENT_OPTIONS)
    config = agent.controller
    try:
        misbehaving = hosted_byzantine(agent.byzantine, fixed)
    except ValueError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    cliargs.configure_logging("robot-agent", args.log_level)
    keyring = run_keys.from_args(parser, args, "robot-agent")
    for robot in fixed:
        if keyring is not None and not keyring.holds(names.robot_identity(robot)):
            parser.exit(2, f"robot-agent: error: the run keys hold no key for robot {robot}\n")
    keys = protocol.Keys(args.run_id, args.root)
    inbox: BoundedInbox[Event] = BoundedInbox(
        INBOX_BYTES + INBOX_BYTES_PER_ROBOT * len(args.ids), MAX_MESSAGE_BYTES
    )
    lock = threading.Lock()  # the robots of this process: one thread at a time
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: inbox.put(Event(-1, "stop")))
    sessions: list[zenoh.Session] = []
    nodes: list[RobotNode] = []
    host: HostBatch | None = None
    trace = open_trace(args.trace)
    try:
        for requested in args.ids:
            session = open_from_args(args, requested)
            sessions.append(session)
            robot = requested
            if robot is None:
                robot = certificate_robot(args.zenoh_config)
            if robot is None:
                robot = ask_for_id(session, keys, args.info_timeout, keyring)
            identity = names.robot_identity(robot)
            info = fetch_world_info(session, keys, args.info_timeout, keyring, identity)
            rng = random.Random(protocol.derive_seed(agent.seed, "robot", robot))
            try:
                controller = byzantine.build_controller(
                    robot, info, config, rng, misbehaving.get(robot)
                )
            except ValueError as error:  # e.g. a liar's site the world does not have
                print(f"robot-agent: error: {error}", file=sys.stderr)
                return 2
            node = RobotNode(
                robot,
                session=session,
                keys=keys,
                controller=controller,
                inbox=inbox,
                lock=lock,
                world=info,
                keyring=keyring.only([identity]) if keyring is not None else None,
                trace=trace,
            )
            node.start()
            nodes.append(node)
        if len(nodes) > 1 and not args.no_batch:
            host = HostBatch(nodes, inbox)
            host.start()
        log.info("robot(s) %s running", ", ".join(str(node.robot_id) for node in nodes))
        serve(nodes, inbox)
    except (zenoh.ZError, TimeoutError, NoKeyError) as error:
        print(f"robot-agent: {error}", file=sys.stderr)
        return 1
    finally:
        with lock:  # once held, no callback is stepping a robot, and none will after
            for node in nodes:
                node.closed = True
        if host is not None:
            host.close()
        for node in nodes:
            node.close()
        for session in sessions:
            session.close()
        if trace is not None:
            trace.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
