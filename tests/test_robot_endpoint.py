"""A robot's end of the wire without Zenoh (robot_agent/core/endpoint.py, tick_assembly.py,
hosting.py): what it steps on, what it refuses and counts, and what it sends."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import msgspec
import numpy as np
import pytest
from fakes import make_world_info

from bestofn_swarm.wire import auth, batch, guard, keyspace, names, protocol
from robot_agent.core import ports
from robot_agent.core.endpoint import RobotEndpoint, Step
from robot_agent.core.hosting import HostedRobots
from robot_agent.core.tick_assembly import TickAssembly, TickRefused

SECRET = bytes(range(32))
ROBOT = 3
KEYS = keyspace.Keys("endpoint")
WORLD_KEYS = auth.Keyring(secret=SECRET)  # the world server holds the run secret
DT = make_world_info(3).dt
PNG = bytes(cv2.imencode(".png", np.zeros((8, 8, 3), np.uint8))[1])

Message = tuple[keyspace.KeyKind, bytes, bytes | None]


class Recording:
    """A ``RobotController`` that broadcasts ``broadcasts`` opinions a step, says its
    status changed when told, and keeps what it was given."""

    def __init__(self, robot: int = ROBOT, broadcasts: int = 0) -> None:
        self.robot = robot
        self.broadcasts = broadcasts
        self.steps: list[tuple[ports.BodyReading, list[ports.Received]]] = []
        self.changed = False

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        self.steps.append((reading, list(received)))
        opinion = protocol.OpinionPayload(
            v=1, id=self.robot, trip=len(self.steps), decided=False, opinion=[0.5, 0.5]
        )
        return ports.Command(left=0.01, right=-0.01, broadcasts=(opinion,) * self.broadcasts)

    def status(self, tick: int) -> protocol.Status:
        return protocol.Status(
            v=1,
            id=self.robot,
            tick=tick,
            t=tick * DT,
            phase="waiting",
            trips=0,
            opinion=[0.5, 0.5],
            pool_size=0,
            poolings=0,
            decided_site=None,
            decision_time=None,
            decision_trips=None,
            comparison=None,
            rejected=1,  # what the controller itself refused (radio): added to the endpoint's
        )

    def take_status_change(self) -> bool:
        changed, self.changed = self.changed, False
        return changed

    @property
    def decided_site(self) -> int | None:
        return None


@dataclass
class WorldSide:
    """Messages as the world server sends them to one robot: sealed with that robot's key
    in a keyed run (``keyring``: the run secret, or another run's), bare otherwise."""

    keyring: auth.Keyring | None
    robot: int = ROBOT

    def _seal(self, key: str, payload: bytes, meta: bytes = b"") -> bytes | None:
        return auth.seal(self.keyring, names.robot_identity(self.robot), key, payload, meta)

    def sense(self, tick: int, *, rx: int = 0, camera: bool = False) -> Message:
        return keyspace.SENSE, *self.sense_entry(tick, rx=rx, camera=camera)

    def sense_entry(
        self, tick: int, *, rx: int = 0, camera: bool = False, t: float | None = None
    ) -> tuple[bytes, bytes | None]:
        sense = protocol.Sense(
            v=1,
            tick=tick,
            t=tick * DT if t is None else t,
            x=0.1,
            y=0.2,
            theta=0.3,
            prox=[0.0] * 8,
            rx=rx,
            camera=camera,
        )
        payload = protocol.encode(sense)
        return payload, self._seal(KEYS.of(keyspace.SENSE, self.robot), payload)

    def rx(self, tick: int, seq: int, sender: str = "nest") -> Message:
        payload = protocol.encode(protocol.BeaconPayload(v=1, id="nest", seq=seq))
        meta = protocol.encode(
            protocol.RadioRxMeta(v=1, tick=tick, sender=sender, seq=seq, sent_tick=tick - 1)
        )
        return (
            keyspace.RADIO_RX,
            payload,
            self._seal(KEYS.of(keyspace.RADIO_RX, self.robot), payload, meta),
        )

    def frame(self, tick: int) -> Message:
        meta = protocol.encode(
            protocol.CameraMeta(v=1, tick=tick, width=8, height=8, encoding="png")
        )
        return keyspace.CAMERA, PNG, self._seal(KEYS.of(keyspace.CAMERA, self.robot), PNG, meta)


def robot_keys(robot: int = ROBOT) -> auth.Keyring:
    """What a robot process holds in a keyed run: its own key only."""
    return WORLD_KEYS.only([names.robot_identity(robot)])


def endpoint(
    keyed: bool = True, *, clock: str = "lockstep", robot: int = ROBOT, broadcasts: int = 0
) -> tuple[RobotEndpoint, Recording, WorldSide]:
    controller = Recording(robot, broadcasts)
    world = msgspec.structs.replace(make_world_info(3), clock=clock)
    robot_endpoint = RobotEndpoint(
        robot,
        keys=KEYS,
        controller=controller,
        world=world,
        keyring=robot_keys(robot) if keyed else None,
    )
    return robot_endpoint, controller, WorldSide(WORLD_KEYS if keyed else None, robot)


def feed(robot: RobotEndpoint, messages: Sequence[Message]) -> list[Step | None]:
    return [robot.receive(*message) for message in messages]


# --- tick assembly ------------------------------------------------------------------------


@pytest.mark.parametrize("keyed", [True, False], ids=["keyed", "no-keys"])
def test_a_tick_steps_once_all_its_inputs_are_in_whatever_their_order(keyed: bool) -> None:
    world = WorldSide(WORLD_KEYS if keyed else None)
    sense = world.sense(4, rx=2, camera=True)
    radio = {"nest": world.rx(4, seq=1), "7": world.rx(4, seq=2, sender="7")}
    acts = set()
    for order in itertools.permutations([sense, *radio.values(), world.frame(4)]):
        robot, controller, _ = endpoint(keyed)
        results = feed(robot, order)
        assert results[:-1] == [None, None, None]  # nothing steps before the last input
        step = results[-1]
        assert step is not None and step.tick == 4 and robot.last_tick == 4
        [(reading, received)] = controller.steps
        assert reading.t == pytest.approx(0.4) and reading.frame is not None
        in_order = [sender for message in order for sender in radio if radio[sender] is message]
        assert [item.sender for item in received] == in_order  # as they came
        assert robot.rejects.count == 0 and robot.assembly.pending == {}
        assert step.act is not None
        acts.add(step.act.payload)
    assert len(acts) == 1  # the same act whatever the order


def test_a_stale_or_repeated_tick_is_dropped_quietly() -> None:
    robot, controller, world = endpoint()
    assert robot.receive(*world.sense(1)) is not None
    assert feed(robot, [world.sense(1), world.rx(1, seq=1), world.sense(0)]) == [None] * 3
    # A sense repeated before its tick is complete is taken once.
    assert feed(robot, [world.sense(2, rx=1), world.sense(2, rx=1)]) == [None, None]
    step = robot.receive(*world.rx(2, seq=2))
    assert step is not None and step.tick == 2
    assert len(controller.steps) == 2 and robot.rejects.count == 0
    assert robot.assembly.pending == {} and robot.assembly.pending_messages == 0


def test_a_tick_beyond_the_window_is_refused_and_counted() -> None:
    robot, _, world = endpoint()
    assert robot.receive(*world.sense(5)) is not None
    assert robot.receive(*world.sense(5 + guard.TICK_WINDOW + 1)) is None
    assert robot.rejects.count == 1
    step = robot.receive(*world.sense(5 + guard.TICK_WINDOW))
    assert step is not None and step.tick == 5 + guard.TICK_WINDOW


def test_the_pending_inputs_are_held_within_their_budget() -> None:
    assembly = TickAssembly(lockstep=True, max_bytes=100, max_messages=4)
    sense = protocol.Sense(
        v=1, tick=6, t=0.6, x=0.0, y=0.0, theta=0.0, prox=[0.0] * 8, rx=1, camera=False
    )
    assert assembly.add_sense(sense)  # a message, of no bytes
    assert assembly.add_rx(5, "nest", b"x" * 60)
    with pytest.raises(TickRefused):
        assembly.add_rx(6, "nest", b"x" * 41)  # 101 bytes
    assert assembly.add_frame(8, b"")
    assert assembly.add_rx(6, "nest", b"x" * 40)
    with pytest.raises(TickRefused):
        assembly.add_rx(8, "nest", b"")  # a fifth message
    assert (assembly.pending_bytes, assembly.pending_messages) == (100, 4)
    ready = assembly.take_ready(6)
    assert ready is not None and ready.sense == sense and ready.rx == [("nest", b"x" * 40)]
    # Tick 5 never completed: forgotten with tick 6, which frees their share.
    assert (assembly.pending_bytes, assembly.pending_messages) == (0, 1)
    assert not assembly.add_rx(5, "nest", b"late")  # stale: quietly not held
    assert assembly.pending_messages == 1


def test_older_incomplete_ticks_are_forgotten_when_a_later_one_steps() -> None:
    robot, controller, world = endpoint()
    assert robot.receive(*world.sense(1, rx=1)) is None  # its radio message never comes
    step = robot.receive(*world.sense(2))
    assert step is not None and step.tick == 2
    assert robot.assembly.pending == {}
    assert robot.receive(*world.rx(1, seq=1)) is None  # too late: stale, not counted
    assert robot.rejects.count == 0 and len(controller.steps) == 1


def test_in_real_time_a_sense_steps_at_once_with_earlier_ticks_radio_first() -> None:
    robot, controller, world = endpoint(clock="realtime")
    assert feed(robot, [world.rx(1, seq=1), world.rx(2, seq=2, sender="7")]) == [None, None]
    step = robot.receive(*world.sense(2, rx=5, camera=True))  # waits for neither
    assert step is not None and step.tick == 2
    [(reading, received)] = controller.steps
    assert [item.sender for item in received] == ["nest", "7"] and reading.frame is None
    assert robot.assembly.pending == {} and robot.assembly.pending_bytes == 0


def test_in_real_time_a_frame_of_a_skipped_tick_reaches_the_next_step() -> None:
    """A robot that fell behind skips to its newest sense; the frame it asked for came
    with a sense it skipped, and must not be lost (it would cost a capture timeout)."""
    robot, controller, world = endpoint(clock="realtime")
    assert robot.receive(*world.frame(3)) is None  # its sense (tick 3) is skipped
    step = robot.receive(*world.sense(5))
    assert step is not None and step.tick == 5
    [(reading, _)] = controller.steps
    assert reading.frame is not None
    assert robot.assembly.pending == {} and robot.assembly.pending_bytes == 0


def test_in_lockstep_a_frame_of_an_older_tick_is_not_taken_for_this_one() -> None:
    robot, controller, world = endpoint()
    assert robot.receive(*world.frame(3)) is None
    step = robot.receive(*world.sense(5))
    assert step is not None and step.tick == 5
    [(reading, _)] = controller.steps
    assert reading.frame is None


def test_inputs_carry_their_latest_arrival_mark_to_the_step() -> None:
    robot, _, world = endpoint()
    assert robot.receive(*world.rx(1, seq=1), arrived=7.5) is None
    step = robot.receive(*world.sense(1, rx=1), arrived=5.0)
    assert step is not None and step.arrived == 7.5


# --- following the world ------------------------------------------------------------------


def test_a_new_world_restarts_the_ticks_and_time_goes_on() -> None:
    robot, controller, world = endpoint()
    robot.world_appeared("first")
    for tick in range(1, 4):
        assert robot.receive(*world.sense(tick)) is not None
    assert robot.receive(*world.sense(5, rx=1)) is None  # waits for its radio
    robot.world_appeared("impostor")  # a second token while the first lives: ignored
    assert robot.worlds.followed == "first" and 5 in robot.assembly.pending
    robot.world_vanished("first")
    robot.world_appeared("second")
    assert robot.assembly.pending == {} and robot.last_tick == -1
    for tick in range(2):  # the new world counts from zero ...
        assert robot.receive(*world.sense(tick)) is not None
    # ... and the controller's clock goes on from the last time it saw
    assert [reading.t for reading, _ in controller.steps] == pytest.approx(
        [0.1, 0.2, 0.3, 0.3, 0.4]
    )
    assert robot.rejects.count == 0


def test_world_tokens_no_world_answers_for_are_counted_and_shift_nothing() -> None:
    """Case 2 of issue 23: fake world tokens come and go; the node asks each to prove
    itself, none does, and the robot keeps following its world, its clock unshifted."""
    robot, controller, world = endpoint()
    robot.world_appeared("real")
    assert robot.receive(*world.sense(1)) is not None
    for index in range(30):
        robot.world_unproven(f"fake{index}")
        robot.world_vanished(f"fake{index}")
    assert robot.worlds.followed == "real" and not robot.worlds.lost
    assert robot.receive(*world.sense(2)) is not None
    assert [reading.t for reading, _ in controller.steps] == pytest.approx([0.1, 0.2])
    assert robot.rejects.count == 30


def test_the_same_world_back_is_rejoined_at_its_tick_and_a_replay_is_still_refused() -> None:
    robot, controller, world = endpoint()
    robot.world_appeared("world")
    assert robot.receive(*world.sense(10)) is not None
    assert robot.receive(*world.sense(11, rx=1)) is None
    robot.world_vanished("world")  # frozen beyond Zenoh's lease; it ticked on meanwhile
    robot.world_appeared("world")
    assert robot.assembly.pending == {}
    assert robot.receive(*world.sense(10)) is None  # a replay: already stepped
    far = 10 + 5 * guard.TICK_WINDOW
    step = robot.receive(*world.sense(far))  # however far ahead, once
    assert step is not None and step.tick == far
    assert controller.steps[-1][0].t == pytest.approx(far * DT)  # the same clock: no shift
    assert robot.receive(*world.sense(far + guard.TICK_WINDOW + 1)) is None
    assert robot.rejects.count == 1  # bounded again from there


# --- checks -------------------------------------------------------------------------------

OTHER_RUN = auth.Keyring(secret=bytes(32))


def _bad_inputs() -> dict[str, Message]:
    world = WorldSide(WORLD_KEYS)
    payload, _ = world.sense_entry(1)
    sense_at_wrong_time = world.sense_entry(1, t=5.0)
    garbage = b"not a sense"
    rx_kind, rx_payload, _ = world.rx(1, seq=1)
    rx_key = KEYS.of(keyspace.RADIO_RX, ROBOT)
    identity = names.robot_identity(ROBOT)
    camera_meta = protocol.encode(
        protocol.CameraMeta(v=1, tick=1, width=8, height=8, encoding="png")
    )
    return {
        "untagged": (keyspace.SENSE, payload, None),
        "another run's key": (
            keyspace.SENSE,
            payload,
            OTHER_RUN.seal(identity, KEYS.of(keyspace.SENSE, ROBOT), payload),
        ),
        "another robot's key": WorldSide(WORLD_KEYS, robot=4).sense(1),
        "tagged for another key": (
            keyspace.SENSE,
            payload,
            WORLD_KEYS.seal(identity, KEYS.of(keyspace.CAMERA, ROBOT), payload),
        ),
        "undecodable": (
            keyspace.SENSE,
            garbage,
            WORLD_KEYS.seal(identity, KEYS.of(keyspace.SENSE, ROBOT), garbage),
        ),
        "sim time not its tick's": (keyspace.SENSE, *sense_at_wrong_time),
        "radio without metadata": (
            rx_kind,
            rx_payload,
            WORLD_KEYS.seal(identity, rx_key, rx_payload),
        ),
        "radio with a camera's metadata": (
            rx_kind,
            rx_payload,
            WORLD_KEYS.seal(identity, rx_key, rx_payload, camera_meta),
        ),
        "a frame with no metadata": (
            keyspace.CAMERA,
            PNG,
            WORLD_KEYS.seal(identity, KEYS.of(keyspace.CAMERA, ROBOT), PNG),
        ),
    }


@pytest.mark.parametrize("name", list(_bad_inputs()))
def test_an_input_that_fails_a_check_is_refused_and_counted(name: str) -> None:
    robot, controller, world = endpoint()
    assert robot.receive(*_bad_inputs()[name]) is None
    assert robot.rejects.count == 1 and robot.assembly.pending == {}
    assert robot.receive(*world.sense(1)) is not None  # nothing stuck behind it
    assert len(controller.steps) == 1


def test_an_unkeyed_robot_still_refuses_what_does_not_decode() -> None:
    robot, _, world = endpoint(keyed=False)
    assert robot.receive(keyspace.SENSE, b"{", None) is None
    assert robot.receive(*world.sense(1, rx=1)) is None
    payload = protocol.encode(protocol.BeaconPayload(v=1, id="nest", seq=1))
    assert robot.receive(keyspace.RADIO_RX, payload, None) is None  # no metadata
    assert robot.rejects.count == 2


def test_inputs_dropped_by_the_transport_are_counted_in_the_status() -> None:
    robot, _, _ = endpoint()
    robot.receive(keyspace.SENSE, b"{", None)
    robot.count_dropped(3)
    status = protocol.decode(robot.status(0).payload, protocol.Status)
    assert status.rejected == 1 + 1 + 3  # the controller's, the endpoint's, the dropped


# --- what it sends ------------------------------------------------------------------------


def test_what_a_robot_sends_is_sealed_so_that_its_receivers_believe_it() -> None:
    robot, controller, world = endpoint(broadcasts=2)
    controller.changed = True
    step = robot.receive(*world.sense(6))
    assert step is not None
    assert [message.kind for message in step.outgoing] == [
        keyspace.RADIO_TX,
        keyspace.RADIO_TX,
        keyspace.ACT,
        keyspace.STATUS,
    ]
    identity = names.robot_identity(ROBOT)
    opened = [
        auth.unseal(WORLD_KEYS, identity, message.key, message.payload, message.attachment)
        for message in step.outgoing
    ]
    sent = [protocol.decode(meta or b"", protocol.RadioTxMeta) for meta in opened[:2]]
    assert [(meta.tick, meta.seq) for meta in sent] == [(6, 1), (6, 2)]
    assert {message.key for message in step.transmissions} == {
        KEYS.of(keyspace.RADIO_TX, names.robot_name(3))
    }
    assert step.act is not None
    act = protocol.decode(step.act.payload, protocol.Act)
    assert act == step.answer
    assert (act.tick, act.left, act.right, act.radio_tx) == (6, 0.01, -0.01, 2)
    assert step.act.key == KEYS.of(keyspace.ACT, ROBOT) and opened[2] == b""
    assert step.status is not None and step.status.key == KEYS.of(keyspace.STATUS, ROBOT)
    assert protocol.decode(step.status.payload, protocol.Status).tick == 6
    for message in step.outgoing:  # a forged or altered copy is not believed
        with pytest.raises(auth.AuthError):
            OTHER_RUN.open(identity, message.key, message.payload, message.attachment)
        with pytest.raises(auth.AuthError):
            auth.unseal(
                WORLD_KEYS, identity, message.key, message.payload + b" ", message.attachment
            )
    step = robot.receive(*world.sense(7))
    assert step is not None and step.status is None  # the status did not change


def test_an_unkeyed_robot_sends_bare_metadata() -> None:
    robot, _, world = endpoint(keyed=False, broadcasts=1)
    step = robot.receive(*world.sense(1))
    assert step is not None
    [sent] = step.transmissions
    meta = protocol.decode(sent.attachment or b"", protocol.RadioTxMeta)
    assert (meta.tick, meta.seq) == (1, 1)
    assert step.act is not None and step.act.attachment is None


# --- a process hosting several robots -----------------------------------------------------

HOST = names.host_identity(3, 4)


def hosted(keyed: bool = True) -> tuple[HostedRobots, RobotEndpoint, RobotEndpoint]:
    """Robots 3 and 4 in one process, which holds its host identity's key."""
    (lead, _, _), (other, _, _) = endpoint(keyed, robot=3), endpoint(keyed, robot=4)
    return HostedRobots([lead, other], WORLD_KEYS.only([HOST]) if keyed else None), lead, other


def sense_batch(
    robots: Sequence[int],
    tick: int,
    *,
    last: int = 4,
    rx: int = 0,
    keyring: auth.Keyring | None = WORLD_KEYS,
    identity: str = HOST,
) -> tuple[bytes, bytes | None]:
    """A batch of senses as the world sends it to host 3-4 (sealed with ``identity``)."""
    values = np.tile([0.1, 0.2, 0.3, *[0.0] * 8], (len(robots), 1))
    payload = batch.encode_senses(
        last,
        tick=tick,
        t=tick * DT,
        robots=list(robots),
        values=values,
        rx=[rx if robot == 4 else 0 for robot in robots],
        camera=[False] * len(robots),
    )
    return payload, auth.seal(keyring, identity, KEYS.of(keyspace.HOST_SENSE, 3), payload)


def step_all(host: HostedRobots, payload: bytes, attachment: bytes | None) -> None:
    for robot, sense in host.senses(payload, attachment):
        step = robot.receive_sense(sense)
        if step is not None:
            host.hold(step)


def test_a_batch_of_senses_reaches_each_hosted_robot_and_their_acts_leave_in_one_batch() -> None:
    host, lead, other = hosted()
    assert (host.sense_key, host.act_key) == (
        KEYS.of(keyspace.HOST_SENSE, 3),
        KEYS.of(keyspace.HOST_ACT, 3),
    )
    assert lead.batched and other.batched  # their acts leave in the batch, not on their keys
    step_all(host, *sense_batch([9, 3, 4], 2, rx=1))
    assert lead.rejects.count == 1  # the entry for a robot not hosted here
    acts = host.take_acts()
    assert (
        acts is not None
        and acts.kind is keyspace.HOST_ACT
        and acts.key == KEYS.of(keyspace.HOST_ACT, 3)
    )
    # One tag for the whole batch, the host's: no robot's key speaks for it.
    auth.unseal(WORLD_KEYS, HOST, KEYS.of(keyspace.HOST_ACT, 3), acts.payload, acts.attachment)
    with pytest.raises(auth.AuthError):
        auth.unseal(
            WORLD_KEYS, "robot/3", KEYS.of(keyspace.HOST_ACT, 3), acts.payload, acts.attachment
        )
    [(robot, act)] = batch.decode_acts(acts.payload).acts
    assert (robot, act.tick, act.left, act.right) == (3, 2, 0.01, -0.01)
    assert host.take_acts() is None  # nothing held since
    # Robot 4 steps on its radio message: its act leaves in a batch of its own.
    step = other.receive(*WorldSide(WORLD_KEYS, robot=4).rx(2, seq=1))
    assert step is not None and step.act is None
    host.hold(step)
    acts = host.take_acts()
    assert acts is not None and [robot for robot, _ in batch.decode_acts(acts.payload).acts] == [4]


def test_a_batched_robot_senses_what_it_would_have_sensed_alone() -> None:
    """The same sense, from a batch or on the robot's own key: the same reading, the same
    act (a robot's results cannot depend on how its process talks to the world)."""
    host, lead, _ = hosted()
    alone, controller_alone, world = endpoint()
    step_alone = alone.receive(*world.sense(5))
    step_all(host, *sense_batch([3], 5))
    acts = host.take_acts()
    assert acts is not None and step_alone is not None
    [(_, act)] = batch.decode_acts(acts.payload).acts
    assert act == step_alone.answer
    batched_controller = lead.controller
    assert isinstance(batched_controller, Recording)
    assert batched_controller.steps == controller_alone.steps


@pytest.mark.parametrize(
    "forged",
    [
        sense_batch([3, 4], 2, keyring=None),  # no tag
        sense_batch([3, 4], 2, keyring=OTHER_RUN),  # another run's key
        sense_batch([3, 4], 2, identity="robot/3"),  # a robot's key: not the host's
        sense_batch([3, 4], 2, identity=names.host_identity(3, 5)),  # another host's key
        sense_batch([3, 4], 2, last=5, identity=names.host_identity(3, 5)),  # another host's
        (b"BNS1\x04\x00\x00\x00 cut short", None),  # not a batch
    ],
)
def test_a_batch_without_this_host_s_tag_is_refused_whole_by_the_lead_robot(
    forged: tuple[bytes, bytes | None],
) -> None:
    host, lead, other = hosted()
    assert list(host.senses(*forged)) == []
    assert (lead.rejects.count, other.rejects.count) == (1, 0)


def test_an_unkeyed_host_exchanges_bare_batches() -> None:
    host, lead, _ = hosted(keyed=False)
    step_all(host, *sense_batch([3, 4], 1, keyring=None))
    acts = host.take_acts()
    assert acts is not None and acts.attachment is None
    assert [robot for robot, _ in batch.decode_acts(acts.payload).acts] == [3, 4]
    assert lead.rejects.count == 0


def test_only_robots_first_to_last_with_their_host_key_make_a_host() -> None:
    three, four, five = (endpoint(robot=robot)[0] for robot in (3, 4, 5))
    with pytest.raises(ValueError, match="first to last"):
        HostedRobots([three, five], None)
    with pytest.raises(ValueError, match="first to last"):
        HostedRobots([four, three], None)
    with pytest.raises(ValueError, match="no key"):
        HostedRobots([three, four], WORLD_KEYS.only(["robot/3", "robot/4"]))
