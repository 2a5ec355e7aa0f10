"""One port contract, and every transport runs it.

``ports.control_step`` is the loop docs/porting.md tells a port to implement. The Zenoh
robot (robot_agent/node/robot_node.py), the in-process engine (deploy/inprocess/engine.py)
and the UDP example (examples/udp_robot.py) are adapters of it. These tests replay the tick vectors
(tests/vectors/tick.json) through the adapter the node and the engine share, and through
the node itself, and check in each transport that its controller is stepped by
``control_step`` and by nothing else (the calling frame is the contract's code, however
the adapter imported it).
"""

from __future__ import annotations

import importlib.util
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from types import CodeType, ModuleType
from typing import Any

import pytest

from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.wire import keyspace, protocol
from deploy.inprocess.engine import run_in_process
from examples.udp_radio import UdpRadioStats
from robot_agent.core import ports
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.endpoint import RobotEndpoint
from robot_agent.core.simulated import SimulatedPorts
from robot_agent.node.robot_node import Event, RobotNode
from world_server.core.world import World, WorldConfig

REPO = Path(__file__).resolve().parent.parent
if not hasattr(ports.control_step, "__code__"):
    pytest.skip(
        "ports.control_step is compiled (bestofn_swarm/plumbing/cores.py) and leaves no frame "
        "to tell its caller by; tests/test_compiled_cores.py runs this module from the source",
        allow_module_level=True,
    )
CONTRACT = ports.control_step.__code__
TICKS: list[dict[str, Any]] = json.loads(
    (REPO / "tests" / "vectors" / "tick.json").read_text(encoding="utf-8")
)["ticks"]
ROBOT = 7  # the robot of the tick vectors


class Scripted:
    """A ``RobotController`` that commands what a tick vector says and keeps what it got."""

    def __init__(self, command: dict[str, Any]) -> None:
        self.command = ports.Command(
            left=command["left"],
            right=command["right"],
            capture=command["capture"],
            broadcasts=tuple(
                protocol.decode_radio(json.dumps(payload).encode())  # type: ignore[misc]
                for payload in command["broadcasts"]
            ),
        )
        self.steps: list[tuple[ports.BodyReading, Sequence[ports.Received]]] = []
        self.stepped_by: list[CodeType] = []

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        self.stepped_by.append(sys._getframe(1).f_code)
        self.steps.append((reading, received))
        return self.command

    def status(self, tick: int) -> protocol.Status:
        raise AssertionError("a tick's answer needs no status")

    def take_status_change(self) -> bool:
        return False

    @property
    def decided_site(self) -> int | None:
        return None


def check_what_the_controller_got(controller: Scripted, vector: dict[str, Any]) -> None:
    assert controller.stepped_by == [CONTRACT]
    [(reading, received)] = controller.steps
    expected = vector["reading"]
    assert (reading.t, reading.x, reading.y, reading.theta) == (
        expected["t"],
        expected["x"],
        expected["y"],
        expected["theta"],
    )
    assert reading.proximity == tuple(expected["proximity"])
    frame = expected["frame"]
    if frame is None:
        assert reading.frame is None
    else:
        assert reading.frame is not None
        assert reading.frame.shape == (frame["height"], frame["width"], 3)
        assert (reading.frame == frame["bgr"]).all()
    assert [(item.sender, json.loads(protocol.encode(item.payload))) for item in received] == [
        (item["sender"], item["message"]) for item in vector["received"]
    ]


def expected_transmissions(vector: dict[str, Any]) -> list[tuple[int, str, str]]:
    return [(sent["seq"], sent["hex"], sent["meta_hex"]) for sent in vector["out"]["radio_tx"]]


@pytest.mark.parametrize("vector", TICKS, ids=[vector["name"] for vector in TICKS])
def test_tick_vectors_through_the_adapter_of_the_node_and_the_engine(
    vector: dict[str, Any],
) -> None:
    inputs = vector["in"]
    rejects = ports.RejectCounter()
    adapter = SimulatedPorts(rejects)
    adapter.radio.seq = vector["sent_before"]
    controller = Scripted(vector["command"])
    answer = adapter.answer(
        controller,
        protocol.decode(bytes.fromhex(inputs["sense"]["hex"]), protocol.Sense),
        [(item["sender"], bytes.fromhex(item["hex"])) for item in inputs["radio_rx"]],
        bytes.fromhex(inputs["camera"]["hex"]) if inputs["camera"] else None,
    )
    check_what_the_controller_got(controller, vector)
    assert rejects.count == vector["rejected"]
    assert [
        (sent.seq, sent.payload.hex(), protocol.encode(sent.meta).hex())
        for sent in answer.transmissions
    ] == expected_transmissions(vector)
    assert protocol.encode(answer.act).hex() == vector["out"]["act"]["hex"]


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[tuple[bytes, bytes | None]] = []

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        self.sent.append((payload, attachment))


@pytest.mark.parametrize("vector", TICKS, ids=[vector["name"] for vector in TICKS])
def test_tick_vectors_through_the_zenoh_robot(vector: dict[str, Any]) -> None:
    """The node's handling of what a Zenoh subscriber hands it (sense first: it must wait
    for the tick's radio and frame), and exactly what it publishes (an unkeyed run)."""
    controller = Scripted(vector["command"])
    endpoint = RobotEndpoint(
        ROBOT,
        keys=keyspace.Keys("ticks"),
        controller=controller,
        world=World(WorldConfig(num_sites=5, num_robots=8)).info,
    )
    node = RobotNode(endpoint, session=None, inbox=BoundedInbox())  # type: ignore[arg-type]
    tx, act = _Publisher(), _Publisher()
    node._tx, node._act, node._status = tx, act, _Publisher()  # type: ignore[assignment]
    endpoint.ports.radio.seq = vector["sent_before"]
    inputs = vector["in"]
    node.handle(Event(ROBOT, keyspace.SENSE, bytes.fromhex(inputs["sense"]["hex"])))
    for item in inputs["radio_rx"]:
        rx = Event(
            ROBOT, keyspace.RADIO_RX, bytes.fromhex(item["hex"]), bytes.fromhex(item["meta_hex"])
        )
        node.handle(rx)
    if inputs["camera"]:
        camera = inputs["camera"]
        node.handle(
            Event(
                ROBOT,
                keyspace.CAMERA,
                bytes.fromhex(camera["hex"]),
                bytes.fromhex(camera["meta_hex"]),
            )
        )
    check_what_the_controller_got(controller, vector)
    assert endpoint.rejects.count == vector["rejected"]
    assert [(payload.hex(), (meta or b"").hex()) for payload, meta in tx.sent] == [
        (payload, meta) for _, payload, meta in expected_transmissions(vector)
    ]
    assert act.sent == [(bytes.fromhex(vector["out"]["act"]["hex"]), None)]


class _Bytes:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, payload: bytes, attachment: bytes | None) -> None:
        self.payload = _Bytes(payload)
        self.attachment = _Bytes(attachment) if attachment is not None else None


class _Declared:
    def undeclare(self) -> None:
        pass


class _EagerSession:
    """A session on which what is waiting for a key arrives the moment a subscriber for
    it is declared (as a tick the world already sent does on a busy machine), and which
    notes the order of the declarations."""

    def __init__(self, waiting: dict[str, list[_Sample]]) -> None:
        self.waiting = waiting
        self.order: list[str] = []
        self.publishers: dict[str, _Publisher] = {}

    def declare_publisher(self, key: str, **_: object) -> _Publisher:
        self.order.append(f"publisher {key}")
        return self.publishers.setdefault(key, _Publisher())

    def declare_subscriber(self, key: str, callback: Any, **_: object) -> _Declared:
        self.order.append(f"subscriber {key}")
        for sample in self.waiting.pop(key, []):
            callback(sample)
        return _Declared()

    def declare_token(self, key: str) -> _Declared:
        self.order.append(f"token {key}")
        return _Declared()

    def liveliness(self) -> _EagerSession:
        return self


class _Announcing(Scripted):
    """The scripted controller, with the status a robot publishes as it starts."""

    def status(self, tick: int) -> protocol.Status:
        return protocol.Status(
            id=ROBOT,
            tick=tick,
            t=0.0,
            v=protocol.VERSION,
            phase="waiting",
            trips=0,
            opinion=[0.2] * 5,
            pool_size=0,
            poolings=0,
            decided_site=None,
            decision_time=None,
            decision_trips=None,
            comparison=None,
        )


def test_a_tick_that_arrives_as_the_robot_subscribes_is_answered() -> None:
    """A robot declares what it publishes on before it subscribes: a tick's inputs that
    arrive while it is still subscribing complete a step whose act goes out (not an
    error in a callback and a tick the world waits for), and its token comes last."""
    vector = TICKS[0]
    endpoint = RobotEndpoint(
        ROBOT,
        keys=keyspace.Keys("ticks"),
        controller=_Announcing(vector["command"]),
        world=World(WorldConfig(num_sites=5, num_robots=8)).info,
    )
    endpoint.ports.radio.seq = vector["sent_before"]
    inputs, keys = vector["in"], endpoint.input_keys
    waiting = {
        keys[keyspace.SENSE]: [_Sample(bytes.fromhex(inputs["sense"]["hex"]), None)],
        keys[keyspace.RADIO_RX]: [
            _Sample(bytes.fromhex(item["hex"]), bytes.fromhex(item["meta_hex"]))
            for item in inputs["radio_rx"]
        ],
    }
    if inputs["camera"]:
        camera = inputs["camera"]
        waiting[keys[keyspace.CAMERA]] = [
            _Sample(bytes.fromhex(camera["hex"]), bytes.fromhex(camera["meta_hex"]))
        ]
    session = _EagerSession(waiting)
    node = RobotNode(endpoint, session=session, inbox=BoundedInbox())  # type: ignore[arg-type]
    node.start()
    act = session.publishers[endpoint.output_keys[keyspace.ACT]]
    assert act.sent == [(bytes.fromhex(vector["out"]["act"]["hex"]), None)]
    kinds = [entry.split()[0] for entry in session.order]
    assert kinds.index("subscriber") > max(i for i, k in enumerate(kinds) if k == "publisher")
    assert kinds[-1] == "token"


def witness(stepped_by: list[CodeType]) -> type[Controller]:
    """The real controller, noting which function steps it."""

    class Witness(Controller):
        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            stepped_by.append(sys._getframe(1).f_code)
            return super().step(reading, received)

    return Witness


def test_the_in_process_engine_steps_every_robot_through_the_contract() -> None:
    stepped_by: list[CodeType] = []
    ticks: list[int] = []
    run_in_process(
        WorldConfig(num_sites=3, num_robots=2),
        ControllerConfig(),
        timeout=1.0,
        controller_factory=witness(stepped_by),
        on_tick=lambda world: ticks.append(world.tick),
    )
    assert len(ticks) == 11  # ticks 0 to 10: sim time 0 to 1 s
    assert stepped_by == [CONTRACT] * (2 * len(ticks))


def _udp_example() -> ModuleType:
    spec = importlib.util.spec_from_file_location("udp_robot", REPO / "examples" / "udp_robot.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _SteppedClock:
    """The example's clock, moved on only by its own sleeps: a fixed number of steps."""

    def __init__(self, speed: float = 1.0, start_at: float | None = None) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


class _QuietRadio:
    """The example's UdpRadio on no network: hears nothing, keeps what it sends."""

    def __init__(self, name: str, **options: object) -> None:
        self.stats = UdpRadioStats()
        self.sent: list[bytes] = []

    def __enter__(self) -> _QuietRadio:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def send(self, payload: bytes) -> None:
        self.sent.append(payload)

    def poll(self) -> list[tuple[str, bytes]]:
        return []


def test_the_udp_example_steps_its_robot_through_the_contract(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    example = _udp_example()
    stepped_by: list[CodeType] = []
    monkeypatch.setattr(example, "Controller", witness(stepped_by))
    monkeypatch.setattr(example, "ScaledClock", _SteppedClock)
    monkeypatch.setattr(example, "UdpRadio", _QuietRadio)
    args = example.build_parser().parse_args(
        ["--id", "0", "--qualities", "1,0.5,0", "--max-seconds", "0.95"]
    )
    summary = example.run(args)
    assert summary["phase"] != "stopped"
    assert stepped_by == [CONTRACT] * 10  # clock 0 to 0.9 s, a step every 0.1 s
