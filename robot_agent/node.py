"""``robot-agent``: robots on Zenoh. The only Zenoh code of the robot.

Each robot has its own Zenoh session, keys, liveliness token and RNG; a process can host
one robot or many (they share one inbox and one thread, and are indistinguishable on the
wire from single-robot processes). Zenoh callbacks only copy bytes into the inbox.

Lockstep: the world's ``sense`` for tick t says how many radio messages and whether a
camera frame belong to tick t; the robot steps only when all of them are in, so the
order in which Zenoh delivers different keys cannot change a run.
"""

from __future__ import annotations

import argparse
import logging
import queue
import random
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import msgspec
import zenoh

from plumbing import cliargs
from plumbing.lifecycle import die_with_launcher
from plumbing.world_info import fetch_world_info
from plumbing.zenoh_session import open_from_args, reliable_publisher
from robot_agent import byzantine, protocol
from robot_agent.lockstep import answer_tick
from robot_agent.options import (
    add_byzantine_option,
    add_controller_options,
    controller_config,
    hosted_byzantine,
)
from robot_agent.ports import RejectCounter, RobotController

log = logging.getLogger("robot_agent")
Meta = TypeVar("Meta", protocol.RadioRxMeta, protocol.CameraMeta)


@dataclass(frozen=True)
class Event:
    robot: int
    kind: str  # sense | camera | rx | stop
    payload: bytes = b""
    attachment: bytes | None = None


@dataclass
class _TickInputs:
    sense: protocol.Sense | None = None
    rx: list[tuple[str, bytes]] = field(default_factory=list)
    frame: bytes | None = None


class RobotNode:
    """One robot: its session, its controller, and the lockstep bookkeeping."""

    def __init__(
        self,
        robot_id: int,
        *,
        session: zenoh.Session,
        keys: protocol.Keys,
        controller: RobotController,
        inbox: queue.SimpleQueue[Event],
        lockstep: bool,
    ) -> None:
        self.robot_id = robot_id
        self.session = session
        self.keys = keys
        self.controller = controller
        self.inbox = inbox
        self.lockstep = lockstep
        self.rejects = RejectCounter()
        self.pending: dict[int, _TickInputs] = {}
        self.seq = 0
        self.skipped_ticks = 0
        self.last_tick = -1
        self.time_offset = 0.0  # keeps the controller's clock monotonic across world restarts
        self.last_t = 0.0
        self.world: str | None = None  # the world server's instance id (its Zenoh id)
        self._declared: list[object] = []

    def start(self) -> None:
        """Subscribe first, then announce liveliness, so no tick is missed."""
        keys, robot, session = self.keys, self.robot_id, self.session

        def forward(kind: str) -> Callable[[zenoh.Sample], None]:
            def callback(sample: zenoh.Sample) -> None:
                attachment = sample.attachment
                self.inbox.put(
                    Event(
                        robot,
                        kind,
                        sample.payload.to_bytes(),
                        attachment.to_bytes() if attachment is not None else None,
                    )
                )

            return callback

        self._declared = [
            session.declare_subscriber(keys.sense(robot), forward("sense")),
            session.declare_subscriber(keys.camera(robot), forward("camera")),
            session.declare_subscriber(keys.radio_rx(protocol.radio_name(robot)), forward("rx")),
            session.liveliness().declare_subscriber(
                keys.alive("world", "*"),
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
        self._tx = reliable_publisher(session, keys.radio_tx(protocol.radio_name(robot)))
        self._publish_status(0)
        self._token = session.liveliness().declare_token(keys.alive("robot", robot))

    def close(self) -> None:
        self._token.undeclare()
        for entity in self._declared:
            entity.undeclare()  # type: ignore[attr-defined]

    # --- inputs --------------------------------------------------------------------

    def handle(self, event: Event) -> None:
        if event.kind in ("world", "no-world"):
            self._world_presence(event.payload.decode(errors="replace"), event.kind == "world")
        elif event.kind == "sense":
            try:
                sense = protocol.decode(event.payload, protocol.Sense)
            except protocol.ProtocolError as error:
                self._reject("sense", error)
                return
            if sense.tick <= self.last_tick:
                return  # a repeat of a tick already answered
            self.pending.setdefault(sense.tick, _TickInputs()).sense = sense
            self._advance(sense.tick)
        elif event.kind == "rx":
            meta = self._attachment(event, protocol.RadioRxMeta, "radio/rx")
            if meta is not None and meta.tick > self.last_tick:
                self.pending.setdefault(meta.tick, _TickInputs()).rx.append(
                    (meta.sender, event.payload)
                )
                self._advance(meta.tick)
        elif event.kind == "camera":
            meta = self._attachment(event, protocol.CameraMeta, "camera")
            if meta is not None and meta.tick > self.last_tick:
                inputs = self.pending.setdefault(meta.tick, _TickInputs())
                inputs.frame = event.payload
                self._advance(meta.tick)

    def _attachment(self, event: Event, kind: type[Meta], key: str) -> Meta | None:
        """The event's metadata (its Zenoh attachment) as ``kind``, or None, rejected."""
        try:
            if event.attachment is None:
                raise protocol.ProtocolError("missing attachment")
            return protocol.decode(event.attachment, kind)
        except protocol.ProtocolError as error:
            self._reject(key, error)
            return None

    def _world_presence(self, instance: str, present: bool) -> None:
        """Wait while the world server is gone; when another one appears, follow its ticks.

        A new world counts ticks from zero again: forget the old tick numbers, and shift
        its time so that the controller's clock never runs backwards.
        """
        if not present:
            if instance == self.world:
                log.warning("robot %d lost the world server; waiting", self.robot_id)
            return
        if self.world is not None and instance != self.world:
            log.warning("robot %d: a new world server appeared; resuming", self.robot_id)
            self.pending.clear()
            self.last_tick = -1
            self.time_offset = self.last_t
        self.world = instance

    def _reject(self, key: str, error: Exception) -> None:
        self.rejects.reject(f"robot {self.robot_id} {key}", error)

    def _advance(self, tick: int) -> None:
        inputs = self.pending.get(tick)
        if inputs is None or inputs.sense is None:
            return
        sense = inputs.sense
        if self.lockstep:
            complete = len(inputs.rx) >= sense.rx and (inputs.frame is not None or not sense.camera)
            if not complete:
                return
            stale = [old for old in self.pending if old < tick]
            self.skipped_ticks += len(stale)
            for old in stale:
                del self.pending[old]
        else:
            # Real time: use whatever has arrived, including earlier ticks' radio.
            for old in sorted(t for t in self.pending if t < tick):
                inputs.rx[:0] = self.pending.pop(old).rx
        del self.pending[tick]
        self._step(sense, inputs)

    # --- one control step ----------------------------------------------------------

    def _step(self, sense: protocol.Sense, inputs: _TickInputs) -> None:
        if self.time_offset:
            sense = msgspec.structs.replace(sense, t=sense.t + self.time_offset)
        self.last_t = sense.t
        answer = answer_tick(
            self.controller, sense, inputs.rx, inputs.frame, self.rejects, seq=self.seq
        )
        for seq, payload in answer.transmissions:
            meta = protocol.RadioTxMeta(v=protocol.VERSION, tick=sense.tick, seq=seq)
            self._tx.put(payload, attachment=protocol.encode(meta))
        self._act.put(protocol.encode(answer.act))
        self.seq = answer.next_seq
        self.last_tick = sense.tick
        if self.controller.take_status_change():
            self._publish_status(sense.tick)

    def _publish_status(self, tick: int) -> None:
        status = self.controller.status(tick)
        status = msgspec.structs.replace(status, rejected=status.rejected + self.rejects.count)
        self._status.put(protocol.encode(status))


def serve(nodes: Sequence[RobotNode], inbox: queue.SimpleQueue[Event]) -> None:
    """Feed every node its events until a stop event arrives."""
    by_id = {node.robot_id: node for node in nodes}
    while True:
        event = inbox.get()
        if event.kind == "stop":
            return
        by_id[event.robot].handle(event)


# --- command line ------------------------------------------------------------------------


def robot_id(text: str) -> int | None:
    """A robot id, or None for ``auto``."""
    if text == "auto":
        return None
    return cliargs.int_range(0, protocol.MAX_ROBOTS - 1)(text)


def ask_for_id(session: zenoh.Session, keys: protocol.Keys, timeout: float) -> int:
    """Ask the world server for a free robot id (``--id auto``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(keys.world_join, timeout=1.0):
            if reply.ok is not None:
                try:
                    return protocol.decode(reply.ok.payload.to_bytes(), protocol.JoinReply).id
                except protocol.ProtocolError as error:
                    raise TimeoutError(f"invalid answer on {keys.world_join}: {error}") from None
            if reply.err is not None:
                raise TimeoutError(f"the world server gave no id: {reply.err.payload.to_bytes()!r}")
        time.sleep(0.2)
    raise TimeoutError(f"no world server answered on {keys.world_join}")


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
        "--seed",
        type=cliargs.seed,
        default=0,
        help="run seed; each robot's RNG derives from it and its id (default: 0)",
    )
    parser.add_argument(
        "--info-timeout",
        type=cliargs.positive_float,
        default=60.0,
        help="wall seconds to wait for the world server (default: 60)",
    )
    add_controller_options(parser)
    add_byzantine_option(parser)
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
    try:
        config = controller_config(args)
        misbehaving = hosted_byzantine(args.byzantine, fixed)
    except ValueError as error:
        parser.exit(2, f"robot-agent: error: {error}\n")
    cliargs.configure_logging("robot-agent", args.log_level)
    keys = protocol.Keys(args.run_id, args.root)
    inbox: queue.SimpleQueue[Event] = queue.SimpleQueue()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: inbox.put(Event(-1, "stop")))
    sessions: list[zenoh.Session] = []
    nodes: list[RobotNode] = []
    try:
        for requested in args.ids:
            session = open_from_args(args, requested)
            sessions.append(session)
            info = fetch_world_info(session, keys, args.info_timeout)
            robot = (
                requested if requested is not None else ask_for_id(session, keys, args.info_timeout)
            )
            rng = random.Random(protocol.derive_seed(args.seed, "robot", robot))
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
                lockstep=info.clock == "lockstep",
            )
            node.start()
            nodes.append(node)
        log.info("robot(s) %s running", ", ".join(str(node.robot_id) for node in nodes))
        serve(nodes, inbox)
    except (zenoh.ZError, TimeoutError) as error:
        print(f"robot-agent: {error}", file=sys.stderr)
        return 1
    finally:
        for node in nodes:
            node.close()
        for session in sessions:
            session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
