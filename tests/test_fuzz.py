"""Every decoder, fuzzed: any bytes give a decoded message or a counted rejection, never
an exception escaping a process, never a corrupted opinion."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import astuple, dataclass
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.wire import auth, keyspace, protocol
from bestofn_swarm.wire.rng import Stream
from deploy.launcher.follower import Follower, Heard
from deploy.launcher.plan import plan_from_args
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.endpoint import RobotEndpoint
from robot_agent.node.robot_node import Event, RobotNode
from world_server.core.coordinator import Coordinator
from world_server.core.events import Event as WorldEvent
from world_server.core.events import Output, Reply, ReplyError
from world_server.core.world import World, WorldConfig

MESSAGE_TYPES = [
    value
    for value in vars(protocol).values()
    if isinstance(value, type)
    and issubclass(value, protocol.Message)
    and value is not protocol.Message
]

# Bytes that are often almost valid: real messages with a few bytes changed.
VALID = [
    b'{"v":1,"tick":3,"t":0.3,"x":0.1,"y":0.2,"theta":0.0,'
    b'"prox":[0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0],"rx":0,"camera":false}',
    b'{"v":1,"tick":3,"left":0.1,"right":0.1,"capture":false,"radio_tx":0}',
    b'{"kind":"opinion","v":1,"id":1,"trip":1,"decided":false,"opinion":[0.5,0.5,0,0,0]}',
    b'{"kind":"beacon","v":1,"id":"nest","seq":1}',
    b'{"v":1,"tick":3,"sender":"1","seq":1,"sent_tick":2}',
    b'{"v":1,"tick":3,"width":64,"height":48,"encoding":"png"}',
    b'{"v":1,"tick":3,"seq":1}',
    b'{"v":1,"tick":3,"t":0.3}',
]


@st.composite
def payloads(draw: st.DrawFn) -> bytes:
    if draw(st.booleans()):
        return draw(st.binary(max_size=400))
    data = bytearray(draw(st.sampled_from(VALID)))
    for _ in range(draw(st.integers(0, 4))):
        if not data:
            break
        position = draw(st.integers(0, len(data) - 1))
        data[position] = draw(st.integers(0, 255))
    return bytes(data)


FUZZ = settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(data=payloads(), kind=st.sampled_from([*MESSAGE_TYPES, protocol.RadioPayload]))
def test_decode_gives_a_message_or_a_protocol_error(data: bytes, kind: Any) -> None:
    try:
        message = protocol.decode(data, kind)
    except protocol.ProtocolError:
        return
    assert protocol.decode(protocol.encode(message), kind) == message


@FUZZ
@given(data=payloads())
def test_radio_decode_gives_a_payload_or_a_protocol_error(data: bytes) -> None:
    try:
        message = protocol.decode_radio(data)
    except protocol.ProtocolError:
        return
    if isinstance(message, protocol.OpinionPayload):
        assert all(0.0 <= value <= 1.0 for value in message.opinion)
        assert math.isclose(sum(message.opinion), 1.0, abs_tol=1e-6)


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[tuple[bytes, bytes | None]] = []

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        self.sent.append((payload, attachment))


def _world_info() -> protocol.WorldInfo:
    return World(WorldConfig(num_sites=5, num_robots=2)).info


def _node() -> tuple[RobotNode, Controller, _Publisher]:
    """A robot node with recorders in place of its Zenoh publishers: handling an input
    publishes through those, never through the session."""
    info = _world_info()
    controller = Controller(1, info, ControllerConfig(), Stream(1))
    endpoint = RobotEndpoint(1, keys=keyspace.Keys("fuzz"), controller=controller, world=info)
    # The session is never used: see the publishers below.
    node = RobotNode(endpoint, session=None, inbox=BoundedInbox())  # type: ignore[arg-type]
    act = _Publisher()
    node._act, node._status, node._tx = act, _Publisher(), _Publisher()  # type: ignore[assignment]  # recorders
    return node, controller, act


@FUZZ
@given(
    events=st.lists(
        st.tuples(
            st.sampled_from(
                [
                    keyspace.SENSE,
                    keyspace.RADIO_RX,
                    keyspace.CAMERA,
                    "world",
                    "no-world",
                ]
            ),
            payloads(),
            st.one_of(st.none(), payloads()),
        ),
        max_size=12,
    )
)
def test_a_robot_survives_any_sequence_of_inputs(
    events: list[tuple[keyspace.KeyKind | str, bytes, bytes | None]],
) -> None:
    node, controller, act = _node()
    for kind, payload, attachment in events:
        if isinstance(kind, keyspace.KeyKind):
            node.handle(Event(1, kind, payload, attachment))
        else:  # a world server's token that appeared, or went
            node.handle(Event(1, keyspace.ALIVE_WORLD, payload, gone=kind == "no-world"))
    opinion = controller.opinion
    assert all(value >= 0.0 and math.isfinite(value) for value in opinion)
    assert math.isclose(sum(opinion), 1.0, rel_tol=1e-9)
    for payload, _ in act.sent:
        protocol.decode(payload, protocol.Act)


def _world_server(outputs: list[Output]) -> Coordinator:
    world = World(WorldConfig(run="fuzz", num_sites=5, num_robots=2))
    server = Coordinator(
        world,
        keyspace.Keys("fuzz"),
        outputs.append,
        stall_timeout=5.0,
        start_timeout=60.0,
        state_every=10,
    )
    world.join_robot(0)
    world.join_robot(1)
    world.join_beacon("nest")
    server.intake.barrier.open(3, ["robot/0", "robot/1", "beacon/nest"])
    return server


# What an ``alive`` token does in a swarm of robots 0 and 1: join (a robot of the swarm
# or a beacon name), rejected (a robot or beacon no member of the run can be), or
# nothing (a role the barrier does not involve, or no token key at all).
TOKEN_KEYS = {
    "bestofn/fuzz/alive/robot/0": "join",
    "bestofn/fuzz/alive/robot/1": "join",
    "bestofn/fuzz/alive/robot/2": "rejected",  # outside a swarm of two
    "bestofn/fuzz/alive/robot/99999": "rejected",
    "bestofn/fuzz/alive/robot/01": "rejected",
    "bestofn/fuzz/alive/robot/-1": "rejected",
    "bestofn/fuzz/alive/beacon/nest": "join",
    "bestofn/fuzz/alive/beacon/7": "rejected",
    "bestofn/fuzz/alive/beacon/other": "join",
    "bestofn/fuzz/alive/world/abc": "nothing",
    "bestofn/fuzz/alive/robot": "nothing",
    "bogus": "nothing",
}


@dataclass(frozen=True)
class _WorldCounts:
    """What the world server did with one input, as far as it shows."""

    rejected: int
    radio_rejected: int
    late: int
    acts: int
    transmissions: int
    answers: int  # answers the barrier took (acts and beacon acks)
    joins: int

    @classmethod
    def of(cls, server: Coordinator) -> _WorldCounts:
        intake = server.intake
        return cls(
            rejected=server.counters.rejected,
            radio_rejected=server.world.radio.rejected,
            late=server.counters.late,
            acts=len(intake.acts),
            transmissions=len(intake.transmissions),
            answers=sum(entry.radio_tx is not None for entry in intake.barrier.answers.values()),
            joins=len(server.roster.pending),
        )

    def __sub__(self, other: _WorldCounts) -> _WorldCounts:
        return _WorldCounts(*(a - b for a, b in zip(astuple(self), astuple(other), strict=True)))


def _decodes(payload: bytes | None, kind: Any) -> bool:
    try:
        protocol.decode(payload or b"", kind)
    except protocol.ProtocolError:
        return False
    return True


def _check_message(kind: str, key: str, event: WorldEvent, change: _WorldCounts) -> None:
    """An act, beacon ack or radio message is taken, late or rejected: exactly one."""
    taken = {"act": change.acts, "ack": change.answers, "tx": change.transmissions}[kind]
    assert change.rejected + change.late + taken == 1, (kind, key, change)
    assert change.joins == 0
    # The radio counts the world's rejections of radio messages, and only those.
    assert change.radio_rejected == (change.rejected if kind == "tx" else 0)
    if kind == "act" and taken:
        assert key == "bestofn/fuzz/robot/0/act" and _decodes(event.payload, protocol.Act)
        assert change.answers == 1
    if kind == "ack" and taken:
        assert key == "bestofn/fuzz/beacon/nest/ack" and _decodes(event.payload, protocol.Ack)
    if kind == "tx" and taken:
        assert key in ("bestofn/fuzz/radio/tx/1", "bestofn/fuzz/radio/tx/nest"), key
        assert _decodes(event.attachment, protocol.RadioTxMeta)


# What the world server's transport hands its coordinator for each fuzzed input (a token's
# key says whose it is: the roster reads it).
WORLD_KINDS = {
    "act": keyspace.ACT,
    "ack": keyspace.ACK,
    "tx": keyspace.RADIO_TX,
    "alive": keyspace.ALIVE_ROBOT,
    "gone": keyspace.ALIVE_ROBOT,
    "join": keyspace.JOIN,
    "stats": keyspace.STATS,
}


@FUZZ
@given(
    events=st.lists(
        st.one_of(
            st.tuples(
                st.sampled_from(["act", "ack", "tx"]),
                st.sampled_from(
                    [
                        "bestofn/fuzz/robot/0/act",
                        "bestofn/fuzz/robot/7/act",
                        "bestofn/fuzz/x",
                        "bestofn/fuzz/beacon/nest/ack",
                        "bestofn/fuzz/radio/tx/1",
                        "bestofn/fuzz/radio/tx/nest",
                        "bestofn/fuzz/radio/tx/99",
                        "bogus",
                    ]
                ),
                payloads(),
                st.one_of(st.none(), payloads()),
            ),
            st.tuples(
                st.sampled_from(["alive", "gone"]),
                st.sampled_from(list(TOKEN_KEYS)),
                st.just(b""),
                st.none(),
            ),
            st.tuples(st.sampled_from(["join", "stats"]), st.just(""), st.just(b""), payloads()),
            st.tuples(st.just("close"), st.just(""), st.just(b""), st.none()),
        ),
        max_size=16,
    )
)
@example(events=[("act", "bestofn/fuzz/robot/0/act", VALID[1], None)])  # taken
@example(events=[("act", "bestofn/fuzz/robot/0/act", VALID[1], None)] * 2)  # then late
@example(events=[("tx", "bestofn/fuzz/radio/tx/1", VALID[2], VALID[6])])  # taken
@example(events=[("ack", "bestofn/fuzz/beacon/nest/ack", b'{"v":1,"tick":3,"radio_tx":0}', None)])
def test_the_world_server_survives_any_sequence_of_inputs(
    events: list[tuple[str, str, bytes, bytes | None]],
) -> None:
    """Any messages, liveliness changes, id requests and tick closes, in any order: the
    world never fails, takes only its swarm's members, answers every query, and accounts
    for every message exactly once (taken, late or rejected)."""
    outputs: list[Output] = []
    server = _world_server(outputs)
    for kind, key, payload, attachment in events:
        before = _WorldCounts.of(server)
        if kind == "close":
            server.roster.apply_joins()
            server.close_tick()
            change = _WorldCounts.of(server) - before
            assert (change.rejected, change.late, change.radio_rejected) == (0, 0, 0)
            continue
        query = object() if kind in ("join", "stats") else None
        outputs.clear()
        event = WorldEvent(
            WORLD_KINDS[kind], key, payload, attachment, query=query, gone=kind == "gone"
        )
        server.take(event, 0.0)
        change = _WorldCounts.of(server) - before
        if kind in ("act", "ack", "tx"):
            _check_message(kind, key, event, change)
        elif kind == "alive":
            outcome = TOKEN_KEYS[key]
            assert change.joins == (outcome == "join"), (key, change)
            assert change.rejected == (outcome == "rejected"), (key, change)
            assert change.late == 0
        else:  # gone, join, stats: no message to count in an unkeyed run
            assert (change.rejected, change.late) == (0, 0), (kind, change)
        if query is not None:
            replies = [out for out in outputs if isinstance(out, Reply | ReplyError)]
            assert [reply.query for reply in replies] == [query]
        server.roster.apply_joins()
    for transmission in server.intake.transmissions:
        assert server.world.is_sender(transmission.sender)
    assert set(server.world.live_robots()) <= {0, 1}
    assert set(server.world.beacons()) <= {"nest", "other"}
    assert server.roster.assigned <= {0, 1}


@dataclass
class Launcher:
    """What the launcher takes samples with: its follower and the run's keys (or none)."""

    follower: Follower
    keyring: auth.Keyring | None


@pytest.fixture(scope="module", params=[False, True], ids=["unkeyed", "keyed"])
def observer(request: pytest.FixtureRequest) -> Launcher:
    from deploy.cli import build_parser

    args = build_parser(["run"]).parse_args(["run", "--robots", "2", "--no-record"])
    keyring = auth.Keyring(secret=bytes(range(32))) if request.param else None
    return Launcher(Follower(plan_from_args(args), clock=lambda: 0.0), keyring)


def _launcher_took(follower: Follower, kind: str, leaf: str, payload: bytes) -> Callable[[], bool]:
    """Whether the launcher believed one status, clock, state or ack: what it keeps of
    that kind changed to the message (the launcher keeps nothing of a rejected one)."""
    if kind == "status":
        robot = follower.keys.robot_of(keyspace.STATUS, f"{follower.keys.prefix}/{leaf}")
        record = follower.run.records.get(robot) if robot is not None else None
        old = record.status if record is not None else None
        return lambda: record is not None and record.status is not old
    if kind == "clock":
        follower.run.sim_time = -1.0  # no clock has this time
        return lambda: follower.run.sim_time != -1.0
    if kind == "state":
        old_state = follower.run.last_state
        return lambda: follower.run.last_state is not old_state
    follower.run.beacon_rejected.clear()
    return lambda: bool(follower.run.beacon_rejected)


STATUS = protocol.encode(
    protocol.Status(
        v=protocol.VERSION,
        id=0,
        tick=3,
        t=0.3,
        phase="to_site",
        trips=0,
        opinion=[0.2] * 5,
        pool_size=0,
        poolings=0,
        decided_site=None,
        decision_time=None,
        decision_trips=None,
        comparison=None,
    )
)
STATE = protocol.encode(
    protocol.WorldState(
        v=protocol.VERSION,
        tick=3,
        t=0.3,
        robots=[protocol.Pose(0, 0.1, 0.2, 0.0)],
        radio=protocol.RadioCounters(),
        rejected=0,
        stalls=0,
    )
)
LAUNCHER_KINDS = {
    "status": protocol.Status,
    "clock": protocol.Clock,
    "state": protocol.WorldState,
    "ack": protocol.Ack,
}


@FUZZ
@given(
    events=st.lists(
        st.tuples(
            st.sampled_from(list(LAUNCHER_KINDS)),
            st.sampled_from(
                ["robot/0/status", "robot/5/status", "beacon/nest/ack", "beacon/a b/ack", "x"]
            ),
            payloads(),
            st.one_of(st.none(), payloads()),
        ),
        max_size=10,
    )
)
@example(events=[("clock", "x", VALID[7], None)])  # taken, unkeyed
@example(events=[("status", "robot/0/status", STATUS, None)])
@example(events=[("status", "robot/0/status", STATUS, None)] * 2)  # the same tick again: taken
@example(events=[("status", "robot/5/status", STATUS, None)])  # a status of robot 0 on 5's key
@example(events=[("state", "x", STATE, None)])
@example(events=[("ack", "beacon/nest/ack", b'{"v":1,"tick":3,"radio_tx":0}', None)])
@example(events=[("clock", "x", b"not json", None)])  # rejected
def test_the_launcher_survives_any_status_clock_or_state(
    observer: Launcher, events: list[tuple[str, str, bytes, bytes | None]]
) -> None:
    """Nothing it is sent breaks the launcher; each message is believed or counted as
    rejected, exactly one of the two; in a keyed run nothing untagged is believed."""
    follower = observer.follower
    for kind, leaf, payload, attachment in events:
        before = follower.run.rejected
        took = _launcher_took(follower, kind, leaf, payload)
        heard = Heard(keyspace.BY_NAME[kind], f"{follower.keys.prefix}/{leaf}", payload, attachment)
        believed = follower.take(heard, observer.keyring)
        assert believed == took()
        assert follower.run.rejected - before == (0 if believed else 1), (kind, leaf, payload)
        if believed:
            assert observer.keyring is None
            assert _decodes(payload, LAUNCHER_KINDS[kind])
