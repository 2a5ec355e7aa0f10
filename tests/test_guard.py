"""What each receiver checks before it believes a message (bestofn_swarm/wire/guard.py and its
users), without processes: tick windows, one world at a time, a robot's memory budget, the
world's handling of replays, foreign ids and senders that leave."""

from __future__ import annotations

import pytest

from bestofn_swarm.wire import auth, guard, keyspace, protocol
from bestofn_swarm.wire.names import Role
from bestofn_swarm.wire.rng import Stream
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.endpoint import RobotEndpoint
from robot_agent.core.tick_assembly import PENDING_BYTES
from world_server.core.coordinator import Coordinator
from world_server.core.events import Event as WorldEvent
from world_server.core.world import Transmission, World, WorldConfig

SECRET = bytes(range(32))


def test_a_tick_window_takes_any_first_tick_then_only_a_bounded_step() -> None:
    window = guard.TickWindow(window=10)
    assert window.refuses(2**53) is None  # nothing known yet
    window.last = 50
    assert window.refuses(60) is None and window.refuses(61) is not None
    assert window.ahead(51) and not window.ahead(50)


def test_sim_time_must_be_the_ticks() -> None:
    assert guard.time_refused(42, 42 * 0.1, 0.1) is None
    assert guard.time_refused(42, 1e9, 0.1) is not None


def test_in_real_time_a_message_must_come_after_its_senders_last_and_not_from_the_future() -> None:
    assert guard.realtime_refused((10, 1), None, 10) is None
    assert guard.realtime_refused((10, 2), (10, 1), 10) is None
    assert guard.realtime_refused((11, 0), (10, 5), 12) is None
    replay = guard.realtime_refused((10, 1), (10, 1), 12)
    older = guard.realtime_refused((9, 7), (10, 1), 12)
    future = guard.realtime_refused((13, 1), (10, 1), 12)
    assert replay is not None and not replay[1] and older is not None and not older[1]
    assert future is not None and not future[1]
    lagging = guard.realtime_refused((10, 2), (10, 1), 10 + guard.TICK_WINDOW + 1)
    assert lagging is not None and lagging[1]  # authentic, new, but far behind: late


def test_a_second_world_token_is_no_restart_while_the_followed_world_lives() -> None:
    follower = guard.WorldFollower()
    assert not follower.appeared("real")  # the first one is followed
    assert not follower.appeared("fake")  # a forged token beside it: ignored
    assert follower.followed == "real" and follower.impostors == ["fake"]
    assert not follower.vanished("fake")
    assert follower.vanished("real")  # the world died
    assert follower.appeared("new") == "new"  # and a new one is a restart
    assert follower.followed == "new"


def test_the_followed_world_coming_back_is_told_apart_from_a_restart() -> None:
    follower = guard.WorldFollower()
    assert follower.appeared("real") is None
    assert follower.appeared("real") is None  # the same token again: nothing new
    assert follower.vanished("real")  # its link went (a process frozen beyond the lease)
    assert follower.appeared("real") == "back"  # the same world: resume at its tick
    assert follower.appeared("real") is None  # once
    assert follower.followed == "real" and not follower.lost


def test_a_receiver_that_rejoins_takes_a_far_tick_once_and_never_an_old_one() -> None:
    ticks = guard.TickWindow()
    ticks.acted(900)
    assert ticks.refuses(1500) is not None  # too far ahead: a forged future tick
    ticks.rejoin()  # the followed world came back after ticking on without us
    assert ticks.refuses(1500) is None
    assert not ticks.ahead(900) and not ticks.ahead(850)  # a replay: already acted on
    ticks.acted(1500)
    assert ticks.refuses(2100) is not None  # bounded again from there


# --- a robot's budget -------------------------------------------------------------------


def _robot(keyring: auth.Keyring | None) -> RobotEndpoint:
    info = World(WorldConfig(num_sites=4, num_robots=2)).info
    controller = Controller(1, info, ControllerConfig(), Stream(1))
    return RobotEndpoint(
        1, keys=keyspace.Keys("guard"), controller=controller, world=info, keyring=keyring
    )


def _rx(
    robot: RobotEndpoint, tick: int, size: int, keyring: auth.Keyring | None
) -> tuple[bytes, bytes | None]:
    payload = b'{"kind":"opinion"' + b" " * (size - 17)
    meta = protocol.encode(
        protocol.RadioRxMeta(v=1, tick=tick, sender="0", seq=tick, sent_tick=tick - 1)
    )
    key = robot.keys.of(keyspace.RADIO_RX, 1)
    return payload, auth.seal(keyring, "robot/1", key, payload, meta)


@pytest.mark.parametrize("keyed", [False, True])
def test_radio_for_future_ticks_is_held_only_within_the_robots_budget(keyed: bool) -> None:
    """What the world would send (tagged with the robot's key when keyed) for the coming
    ticks is held, within a bound; the rest is rejected and counted."""
    keyring = auth.Keyring(secret=SECRET).only(["robot/1"]) if keyed else None
    robot = _robot(keyring)
    robot.assembly.ticks.last = 10
    size, count = 20_000, 400
    for index in range(count):
        robot.receive(keyspace.RADIO_RX, *_rx(robot, 11 + index % 100, size, keyring))
    held = PENDING_BYTES // size
    assert robot.assembly.pending_bytes == held * size <= PENDING_BYTES
    assert robot.rejects.count == count - held
    too_far = _rx(robot, 10 + guard.TICK_WINDOW + 1, 10, keyring)
    robot.receive(keyspace.RADIO_RX, *too_far)
    assert robot.rejects.count == count - held + 1


def test_a_keyed_robot_holds_nothing_without_its_key() -> None:
    robot = _robot(auth.Keyring(secret=SECRET).only(["robot/1"]))
    forged = auth.Keyring(secret=bytes(32)).only(["robot/1"])  # another run's key
    for tick in range(1, 50):
        robot.receive(keyspace.RADIO_RX, *_rx(robot, tick, 1000, None))
        robot.receive(keyspace.RADIO_RX, *_rx(robot, tick, 1000, forged))
    assert robot.assembly.pending == {} and robot.assembly.pending_bytes == 0
    assert robot.rejects.count == 98


# --- the world --------------------------------------------------------------------------


def _world_server(keyring: auth.Keyring | None = None) -> Coordinator:
    world = World(WorldConfig(run="guard", num_sites=4, num_robots=2))
    server = Coordinator(
        world,
        keyspace.Keys("guard"),
        lambda output: None,
        stall_timeout=5.0,
        start_timeout=60.0,
        state_every=10,
        keyring=keyring,
    )
    world.join_robot(0)
    world.join_robot(1)
    server.intake.barrier.open(0, ["robot/0", "robot/1"])
    return server


def _tx(server: Coordinator, sender: int, seq: int, keyring: auth.Keyring) -> WorldEvent:
    key = server.keys.of(keyspace.RADIO_TX, sender)
    payload = b'{"kind":"opinion"}'
    meta = protocol.encode(protocol.RadioTxMeta(v=1, tick=0, seq=seq))
    return WorldEvent(
        keyspace.RADIO_TX, key, payload, keyring.seal(f"robot/{sender}", key, payload, meta)
    )


def test_the_world_takes_a_robots_transmission_once_per_tick() -> None:
    keyring = auth.Keyring(secret=SECRET)
    server = _world_server(keyring)
    server.take(_tx(server, 0, 1, keyring), 0.0)
    server.take(_tx(server, 0, 1, keyring), 0.0)  # the same message again: a replay
    server.take(_tx(server, 0, 2, keyring), 0.0)
    assert [(t.sender, t.seq) for t in server.intake.transmissions] == [("0", 1), ("0", 2)]
    assert server.counters.rejected == 1 and server.world.radio.rejected == 1


@pytest.mark.parametrize("ident", ["2", "99999", "01", "-1", "x"])
def test_the_world_refuses_a_robot_token_outside_its_swarm(ident: str) -> None:
    server = _world_server()
    server.take(WorldEvent(keyspace.ALIVE_ROBOT, server.keys.token(Role.ROBOT, ident)), 0.0)
    server.roster.apply_joins()
    assert server.world.live_robots() == [0, 1]
    assert server.counters.rejected == 1


def test_a_transmission_whose_sender_left_is_dropped_when_the_tick_closes() -> None:
    world = World(WorldConfig(num_sites=4, num_robots=2))
    world.join_robot(0)
    world.join_robot(1)
    world.join_beacon("nest")
    queued = [Transmission("0", 1, b"{}"), Transmission("nest", 1, b"{}")]
    world.leave_robot(0)
    world.leave_beacon("nest")
    world.advance({}, queued)  # no KeyError: nobody transmits for a sender that is gone
    assert world.radio.rejected == 2 and world.radio.sent == 0


def test_a_robot_outside_the_swarm_has_no_body() -> None:
    world = World(WorldConfig(num_sites=4, num_robots=2))
    with pytest.raises(ValueError, match="not one of the 2"):
        world.join_robot(99999)
