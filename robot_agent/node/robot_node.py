"""Robots on Zenoh: the only Zenoh code of the robot, thin adapters around its endpoint.

Each robot has its own Zenoh session, keys, liveliness token and RNG; a process can host
one robot or many. What a robot does with what it receives (checks, tick assembly, the
control step, sealing what it sends) is ``robot_agent.core.endpoint.RobotEndpoint``;
``RobotNode`` subscribes to its inputs, hands them over and publishes what comes back.
A process hosting several robots answers for all of them in one batch of acts per input
that stepped them, on its first robot's session (``host/<first>/act``, bestofn_swarm/wire/batch.py;
``HostBatch`` around ``robot_agent.core.hosting.HostedRobots``); the world then sends
their senses in one batch too. A batch is sealed once, with the process's own key (the
host identity's); every robot keeps its own keys for radio, status, camera and liveliness.

Threads: a robot's inputs (sense, batch of senses, radio, camera) are handled in the Zenoh
callback that brings them, under one lock per process, so the robots of a process are
stepped by one thread at a time and a tick's step needs no wake-up of another thread (that
hand-off was a large part of a lockstep tick: docs/performance.md). Nothing queues for
them: an input waits in Zenoh until the robots are free. The process's own thread handles
what is rare (the world's liveliness, stop) from a bounded inbox, under the same lock (a
world token is followed only once its world answers for it: it is only a hint), and
the inbox still takes what is too big to be a valid input, to drop and count it.

In real time the world does not wait, so a robot must act on its newest reading, not work
through a backlog: there a sense (or a batch of senses) is not stepped in its callback but
left for the process's ``LatestSenses`` thread, which steps only the newest of each robot
(or host); a sense replaced before the thread came to it is skipped, its radio and frame
still taken with the next (robot_agent/core/tick_assembly.py). Ten robot processes at 10x
on two shared cores answered tick t's senses p90 21 ms after the world sent them stepping
every sense in its callback, 12 ms stepping the newest (a tick is 10 ms there:
docs/performance.md, "Real time").
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import zenoh

from bestofn_swarm.plumbing.inbox import STOP, BoundedInbox, Stop
from bestofn_swarm.plumbing.trace import TraceWriter, now
from bestofn_swarm.plumbing.world_info import world_proved
from bestofn_swarm.plumbing.zenoh_session import reliable_publisher
from bestofn_swarm.wire import auth, keyspace, protocol
from bestofn_swarm.wire.keyspace import Party
from bestofn_swarm.wire.names import Role
from robot_agent.core.endpoint import Outgoing, RobotEndpoint, Step
from robot_agent.core.hosting import HostedRobots
from robot_agent.core.plugin import PluginError

log = logging.getLogger("robot_agent")

# What may wait in a process's inbox for its one thread. It grows with the robots a
# process hosts; a tick's inputs are a few kilobytes per robot, so this leaves room for a
# long stall, not for a flood.
INBOX_BYTES, INBOX_BYTES_PER_ROBOT = 16 * 2**20, 2**20
MAX_MESSAGE_BYTES = protocol.MAX_CAMERA_FRAME_BYTES + 1024  # a frame and its attachment


# What a robot process hears on its own keys, the key table says: its inputs, and the
# batches of senses of the robots it hosts.
INPUTS = keyspace.heard_by(Party.ROBOT)
BATCHES = keyspace.heard_by(Party.HOST)


@dataclass(frozen=True)
class Event:
    """What reaches a robot process: a sample of one of the kinds it hears, a world
    server's liveliness token that appeared or went (``gone``), or its stop (``failure``:
    a plug-in failed in a robot's step, the one line that says so)."""

    robot: int
    kind: keyspace.KeyKind | Stop
    payload: bytes = b""
    attachment: bytes | None = None
    arrived: float = 0.0  # monotonic time the callback took it (only when tracing)
    gone: bool = False
    code: int = 0  # a stop: the process's exit code (the run's, when it ended)
    failure: str | None = None


class LatestSenses:
    """Real time: the newest sense of each robot (or host), stepped by one thread.

    ``offer`` replaces what waits for the same source, so a robot that fell behind steps its
    newest sense next and skips the ones in between; ``skipped`` counts them. The thread is
    the process's: ``start`` it once, ``stop`` joins it.
    """

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._waiting: dict[object, Callable[[], None]] = {}
        self._stopped = False
        self.skipped = 0
        self._thread = threading.Thread(target=self._run, name="latest-senses", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def offer(self, source: object, step: Callable[[], None]) -> None:
        """Have ``step`` run next for ``source``, instead of what still waits for it."""
        with self._ready:
            if source in self._waiting:
                self.skipped += 1
            self._waiting[source] = step
            self._ready.notify()

    def stop(self) -> None:
        with self._ready:
            self._stopped = True
            self._ready.notify()
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)

    def _run(self) -> None:
        while True:
            with self._ready:
                while not self._waiting and not self._stopped:
                    self._ready.wait()
                if self._stopped:
                    return
                steps = list(self._waiting.values())
                self._waiting.clear()
            for step in steps:
                try:
                    step()
                except Exception:  # one bad step must not stop every robot of the process
                    log.exception("a robot's step failed")


class RobotNode:
    """One robot on Zenoh: its session, subscribers and publishers around its endpoint."""

    def __init__(
        self,
        endpoint: RobotEndpoint,
        *,
        session: zenoh.Session,
        inbox: BoundedInbox[Event],
        lock: threading.Lock | None = None,
        trace: TraceWriter | None = None,
        latest: LatestSenses | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.robot_id = endpoint.robot_id
        self.keys = endpoint.keys
        self.session = session
        self.inbox = inbox
        # The process's (shared by the robots it hosts): one thread at a time steps them.
        self.lock = lock or threading.Lock()
        # Set under the lock when the process stops: a callback that comes after does
        # nothing, so none publishes on a session being closed.
        self.closed = False
        self._declared: list[object] = []
        self.trace = trace  # --trace: one line per step (bestofn_swarm/plumbing/trace.py)
        self.host: HostBatch | None = None  # set when its acts go out in its process's batch
        # Real time: where its senses wait to be stepped, newest only (None: in the callback).
        self.latest = latest

    def start(self) -> None:
        """Declare what it publishes on, then subscribe, then announce liveliness: no
        input finds the robot unable to answer, and no tick is missed."""
        keys, robot, session = self.keys, self.robot_id, self.session
        input_keys = self.endpoint.input_keys
        output_keys = self.endpoint.output_keys
        self._act = reliable_publisher(session, output_keys[keyspace.ACT])
        self._status = reliable_publisher(session, output_keys[keyspace.STATUS])
        self._tx = reliable_publisher(session, output_keys[keyspace.RADIO_TX])

        def forward(kind: keyspace.KeyKind) -> Callable[[zenoh.Sample], None]:
            def callback(sample: zenoh.Sample) -> None:
                attachment = sample.attachment
                payload = sample.payload.to_bytes()
                extra = attachment.to_bytes() if attachment is not None else None
                size = len(payload) + len(extra or b"")
                arrived = now() if self.trace is not None else 0.0
                if size > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                    self.inbox.put(Event(robot, kind, payload, extra, arrived), size, robot)
                    return

                def deliver() -> None:
                    with self.lock:
                        if self.closed:
                            return
                        try:
                            self.take(kind, payload, extra, arrived)
                        except PluginError as error:
                            self.fail(error)
                            return
                        if self.host is not None:
                            self.host.flush()

                if kind is keyspace.SENSE and self.latest is not None:
                    self.latest.offer(robot, deliver)
                else:
                    deliver()

            return callback

        self._declared = [
            *(session.declare_subscriber(input_keys[kind], forward(kind)) for kind in INPUTS),
            session.liveliness().declare_subscriber(
                keys.every(keyspace.ALIVE_WORLD), self._on_world, history=True
            ),
        ]
        self._fold_dropped()
        self._publish(self.endpoint.status(0))
        self._token = session.liveliness().declare_token(keys.token(Role.ROBOT, robot))

    def fail(self, error: PluginError) -> None:
        """A plug-in failed in this robot's step (under the process's lock): the process
        answers no more and its thread ends it, saying why (robot_agent/node/cli.py)."""
        self.closed = True
        if self.host is not None:
            for node in self.host.by_id.values():
                node.closed = True
        self.inbox.put(Event(self.robot_id, STOP, failure=str(error)), control=True)

    def _on_world(self, sample: zenoh.Sample) -> None:
        """A world server's token came or went: for the process's thread, charged."""
        gone = sample.kind != zenoh.SampleKind.PUT
        instance = (self.keys.ident_of(keyspace.ALIVE_WORLD, str(sample.key_expr)) or "").encode()
        event = Event(self.robot_id, keyspace.ALIVE_WORLD, instance, gone=gone)
        self.inbox.put(event, len(instance), self.robot_id, once=True)

    def world_proved(self, instance: bytes) -> bool:
        """Whether the world token ``instance`` is a world's: it answers for it, asked as
        this robot (which also proves the robot present to it). Asked outside the lock."""
        endpoint = self.endpoint
        return world_proved(
            self.session,
            self.keys,
            endpoint.keyring,
            endpoint.identity,
            instance.decode(errors="replace"),
        )

    def close(self) -> None:
        self._token.undeclare()
        for entity in self._declared:
            entity.undeclare()  # type: ignore[attr-defined]

    # --- inputs (under the process's lock) -----------------------------------------

    def handle(self, event: Event) -> None:
        """One event of this robot from the process's thread (or a test)."""
        kind = event.kind
        if kind is keyspace.ALIVE_WORLD:
            instance = event.payload.decode(errors="replace")
            if event.gone:
                self.endpoint.world_vanished(instance)
            else:
                self.endpoint.world_appeared(instance)
        elif kind in INPUTS:
            assert isinstance(kind, keyspace.KeyKind)
            self.take(kind, event.payload, event.attachment, event.arrived)

    def take(
        self, kind: keyspace.KeyKind, payload: bytes, attachment: bytes | None, arrived: float
    ) -> None:
        """Hand one input to the endpoint, and send what the step it completes answers."""
        self._fold_dropped()
        handled = now() if self.trace is not None else 0.0
        step = self.endpoint.receive(kind, payload, attachment, arrived)
        if step is not None:
            self._send(step, handled)

    def take_sense(self, sense: protocol.Sense, arrived: float) -> None:
        """Hand the endpoint its sense from its process's batch (checked there), and send
        what the step it completes answers."""
        self._fold_dropped()
        handled = now() if self.trace is not None else 0.0
        step = self.endpoint.receive_sense(sense, arrived)
        if step is not None:
            self._send(step, handled)

    def _fold_dropped(self) -> None:
        """Count in the robot's rejections what the inbox dropped on arrival (too big, or
        the inbox full); looked at without its lock, taken with it."""
        if self.inbox.dropped:
            self.endpoint.count_dropped(self.inbox.take_dropped(self.robot_id))

    # --- outputs -------------------------------------------------------------------

    def _send(self, step: Step, handled: float) -> None:
        for sent in step.transmissions:
            self._tx.put(sent.payload, attachment=sent.attachment)
        line: dict[str, float] | None = None
        if self.trace is not None:
            line = {
                "robot": step.robot,
                "tick": step.tick,
                "arrived": round(step.arrived, 6),
                "handled": round(handled, 6),
            }
        if step.act is None:
            assert self.host is not None  # a batched robot's act leaves in its host's batch
            self.host.hold(step, line)
        else:
            self._act.put(step.act.payload, attachment=step.act.attachment)
            if self.trace is not None and line is not None:
                self.trace.write(**line, answered=round(now(), 6))
        if step.status is not None:
            self._publish(step.status)

    def _publish(self, status: Outgoing) -> None:
        self._status.put(status.payload, attachment=status.attachment)


class HostBatch:
    """The batched path of a process hosting several robots: the senses of all of them
    arrive as one batch on ``host/<first>/sense``, and the acts of the robots stepped on one
    event leave as one batch on ``host/<first>/act``, both on the first robot's session and
    sealed with the process's key.

    The world learns the path from the first batch of acts, and until then (and after
    it restarts) sends each robot's sense on its own key, which every robot still
    subscribes to; a tick's sense is taken once whichever way it came.

    Like every input, a batch is handled in its Zenoh callback under the process's lock;
    a robot steps only once all of a tick's inputs are in, whatever order they came in.
    """

    def __init__(
        self,
        nodes: Sequence[RobotNode],
        inbox: BoundedInbox[Event],
        keyring: auth.Keyring | None,
    ) -> None:
        """``keyring``: the host identity's key (None: an unauthenticated run); ValueError
        unless ``nodes`` are robots first to last in order and the key is there."""
        self.lead = nodes[0]
        self.by_id = {node.robot_id: node for node in nodes}
        self.inbox = inbox
        self.robots = HostedRobots([node.endpoint for node in nodes], keyring)
        self.steps: list[dict[str, float]] = []  # --trace lines of the batched acts
        self.lock = self.lead.lock
        with self.lock:
            for node in nodes:
                node.host = self

    def start(self) -> None:
        lead = self.lead

        def callback(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            attachment = sample.attachment
            extra = attachment.to_bytes() if attachment is not None else None
            arrived = now() if lead.trace is not None else 0.0
            if len(payload) > MAX_MESSAGE_BYTES:  # never valid: the inbox drops and counts it
                event = Event(lead.robot_id, keyspace.HOST_SENSE, payload, extra, arrived)
                self.inbox.put(event, len(payload), lead.robot_id)
                return

            def deliver() -> None:
                with self.lock:
                    if self.lead.closed:
                        return
                    try:
                        self.deliver(payload, extra, arrived)
                    except PluginError as error:
                        self.lead.fail(error)
                        return
                    self.flush()

            if lead.latest is not None:
                lead.latest.offer("host", deliver)  # a process has one host
            else:
                deliver()

        # The publisher first: a batch of senses may come as soon as the subscriber is up.
        self._publisher = reliable_publisher(lead.session, self.robots.act_key)
        self._subscriber = lead.session.declare_subscriber(self.robots.sense_key, callback)

    def close(self) -> None:
        self._subscriber.undeclare()

    def deliver(self, payload: bytes, attachment: bytes | None, arrived: float = 0.0) -> None:
        """Hand each sense of a batch of senses to its robot."""
        for endpoint, sense in self.robots.senses(payload, attachment):
            self.by_id[endpoint.robot_id].take_sense(sense, arrived)

    def hold(self, step: Step, line: dict[str, float] | None) -> None:
        self.robots.hold(step)
        if line is not None:
            self.steps.append(line)

    def flush(self) -> None:
        """Publish the acts gathered since the last flush, as one batch."""
        acts = self.robots.take_acts()
        if acts is None:
            return
        self._publisher.put(acts.payload, attachment=acts.attachment)
        trace = self.lead.trace
        if trace is not None:
            answered = round(now(), 6)
            for line in self.steps:
                trace.write(**line, answered=answered)
            self.steps.clear()


def serve(nodes: Sequence[RobotNode], inbox: BoundedInbox[Event]) -> Event:
    """Feed the nodes the events of their inbox (the world's liveliness) until a stop event
    arrives (a stop signal, the run's ending, or a plug-in's failure); their inputs they
    handle in Zenoh's callbacks. The stop event: its exit code (the run's, when it ended)
    and what a plug-in's failure said, if one stopped them."""
    by_id = {node.robot_id: node for node in nodes}
    while True:
        event = inbox.get()
        if event.kind == STOP:
            return event
        node = by_id[event.robot]
        if (
            event.kind is keyspace.ALIVE_WORLD
            and not event.gone
            and not node.world_proved(event.payload)
        ):
            with node.lock:
                node.endpoint.world_unproven(event.payload.decode(errors="replace"))
            continue
        with node.lock:
            node.handle(event)
