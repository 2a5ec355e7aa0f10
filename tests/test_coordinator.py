"""The world's coordinator without Zenoh (world_server/core/coordinator.py): fed events and
a fake clock, it opens and closes ticks, takes joins and departures, learns and forgets
batch routes, refuses what it must, and answers queries; all it does comes out as data."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import pytest

from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from bestofn_swarm.wire.names import Role
from world_server.core.coordinator import NO_ID_LEFT, UNAUTHENTICATED, Coordinator
from world_server.core.events import (
    Answered,
    Event,
    Happening,
    Mark,
    Moment,
    Opened,
    Output,
    Publish,
    Reply,
    ReplyError,
)
from world_server.core.roster import MAX_BEACONS, SUSPEND_AFTER, Host
from world_server.core.world import World, WorldConfig
from world_server.server.timeline import TickTimeline

KEYS = keyspace.Keys("coord")
KEYRING = auth.Keyring(secret=bytes(range(32)))
STALL = 5.0
START = 60.0
NONCE = bytes(range(16))


@dataclass
class Harness:
    coordinator: Coordinator
    outputs: list[Output] = field(default_factory=list)

    @property
    def world(self) -> World:
        return self.coordinator.world

    def published(self, key: str) -> list[Publish]:
        return [out for out in self.outputs if isinstance(out, Publish) and out.key == key]

    def clocks(self) -> list[int]:
        """The ticks the world's clock announced, in order."""
        return [
            protocol.decode(out.payload, protocol.Clock).tick
            for out in self.published(KEYS.of(keyspace.CLOCK))
        ]


def harness(
    robots: int = 2,
    *,
    clock: Literal["lockstep", "realtime"] = "lockstep",
    expect_robots: int | None = None,
    expect_beacons: int = 1,
    traced: bool = False,
) -> Harness:
    world = World(WorldConfig(run="coord", num_sites=4, num_robots=robots, clock=clock))
    outputs: list[Output] = []
    coordinator = Coordinator(
        world,
        KEYS,
        outputs.append,
        stall_timeout=STALL,
        start_timeout=START,
        state_every=10,
        expect_robots=robots if expect_robots is None else expect_robots,
        expect_beacons=expect_beacons,
        keyring=KEYRING,
        traced=traced,
    )
    # Every robot and the nest beacon prove themselves present first, as their processes do
    # (they ask world/info before they declare their tokens): their tokens then join.
    for identity in [*(names.robot_identity(robot) for robot in range(robots)), "beacon/nest"]:
        coordinator.take(query(keyspace.INFO, KEYS.of(keyspace.INFO), identity), 0.0)
    return Harness(coordinator, outputs)


def started(robots: int = 2, *, now: float = 0.0, **options: Any) -> Harness:
    """A run that started at ``now`` with robots 0..robots-1 and the nest beacon."""
    h = harness(robots, **options)
    h.coordinator.begin(now)
    for robot in range(robots):
        h.coordinator.handle(alive(Role.ROBOT, str(robot)), now)
    h.coordinator.handle(alive(Role.BEACON, "nest"), now)
    assert h.coordinator.phase == "running" and h.world.tick == 0
    return h


# --- events, as the robots and the beacon send them ---------------------------------------


def act(
    robot: int,
    tick: int,
    *,
    radio_tx: int = 0,
    capture: bool = False,
    wheels: float = 0.1,
    keyring: auth.Keyring | None = KEYRING,
) -> Event:
    key = KEYS.of(keyspace.ACT, robot)
    payload = protocol.encode(
        protocol.Act(v=1, tick=tick, left=wheels, right=wheels, capture=capture, radio_tx=radio_tx)
    )
    attachment = keyring.seal(names.robot_identity(robot), key, payload) if keyring else None
    return Event(keyspace.ACT, key, payload, attachment)


def batch_of(
    first: int,
    last: int,
    *answers: tuple[int, int],
    keyring: auth.Keyring | None = KEYRING,
    identity: str | None = None,
) -> Event:
    """A batch of acts (robot, tick) from the process hosting robots ``first`` to ``last``,
    sealed with its host identity's key (or ``identity``'s)."""
    acts = [
        (robot, protocol.Act(v=1, tick=tick, left=0.1, right=0.1, capture=False, radio_tx=0))
        for robot, tick in answers
    ]
    key = KEYS.of(keyspace.HOST_ACT, first)
    payload = batch.encode_acts(last, acts)
    identity = identity or names.host_identity(first, last)
    attachment = keyring.seal(identity, key, payload) if keyring else None
    return Event(keyspace.HOST_ACT, key, payload, attachment)


def ack(name: str, tick: int, radio_tx: int = 0, next_tick: int | None = None) -> Event:
    key = KEYS.of(keyspace.ACK, name)
    payload = protocol.encode(protocol.Ack(v=1, tick=tick, radio_tx=radio_tx, next_tick=next_tick))
    return Event(
        keyspace.ACK, key, payload, KEYRING.seal(names.beacon_identity(name), key, payload)
    )


def tx(sender: str, tick: int, seq: int, keyring: auth.Keyring = KEYRING) -> Event:
    key = KEYS.of(keyspace.RADIO_TX, sender)
    payload = b'{"kind":"beacon","v":1,"id":"nest","seq":1}'
    meta = protocol.encode(protocol.RadioTxMeta(v=1, tick=tick, seq=seq))
    identity = names.sender_identity(sender)
    assert identity is not None
    return Event(keyspace.RADIO_TX, key, payload, keyring.seal(identity, key, payload, meta))


def alive(role: Role, ident: str) -> Event:
    return Event(keyspace.TOKEN_OF[role], KEYS.token(role, ident))


def gone(role: Role, ident: str) -> Event:
    return Event(keyspace.TOKEN_OF[role], KEYS.token(role, ident), gone=True)


def query(
    kind: keyspace.KeyKind, key: str, identity: str, keyring: auth.Keyring = KEYRING
) -> Event:
    attachment = auth.query_seal(keyring, identity, key, b"", NONCE)
    return Event(kind, key, b"", attachment, query=object())


def answer_all(h: Harness, tick: int, now: float = 0.0, robots: tuple[int, ...] = (0, 1)) -> None:
    for robot in robots:
        h.coordinator.handle(act(robot, tick), now)
    h.coordinator.handle(ack("nest", tick), now)


# --- the start ------------------------------------------------------------------------


def test_the_run_starts_when_the_expected_robots_and_beacons_are_live() -> None:
    h = harness()
    h.coordinator.begin(0.0)
    h.coordinator.handle(alive(Role.ROBOT, "0"), 1.0)
    h.coordinator.handle(alive(Role.ROBOT, "1"), 1.0)
    assert h.coordinator.phase == "waiting" and h.outputs == []  # the beacon is expected
    assert h.coordinator.deadline == START
    h.coordinator.handle(alive(Role.BEACON, "nest"), 2.0)
    assert h.coordinator.phase == "running"
    assert h.clocks() == [0]
    assert [len(h.published(KEYS.of(keyspace.SENSE, robot))) for robot in (0, 1)] == [1, 1]
    assert len(h.published(KEYS.of(keyspace.STATE))) == 1  # tick 0: every state_every ticks
    assert h.coordinator.deadline == 2.0 + STALL


def test_the_start_timeout_starts_with_the_robots_there_are_but_not_with_none() -> None:
    h = harness()
    h.coordinator.begin(0.0)
    h.coordinator.wake(START)
    assert h.coordinator.phase == "waiting"  # no robot: nothing to run
    assert h.coordinator.deadline is None  # only a token can start it now
    h.coordinator.handle(alive(Role.ROBOT, "1"), START + 3.0)
    assert h.coordinator.phase == "running" and h.world.live_robots() == [1]
    assert h.clocks() == [0]


def test_a_stop_publishes_the_last_state_of_a_running_world_only() -> None:
    waiting = harness()
    waiting.coordinator.begin(0.0)
    waiting.coordinator.handle(Event(Happening.STOP), 1.0)
    assert waiting.coordinator.stopped and waiting.outputs == []
    h = started()
    h.outputs.clear()
    h.coordinator.handle(Event(Happening.STOP), 1.0)
    assert h.coordinator.stopped and len(h.published(KEYS.of(keyspace.STATE))) == 1
    h.coordinator.handle(alive(Role.ROBOT, "0"), 2.0)  # nothing is taken after a stop
    assert h.coordinator.deadline is None and h.coordinator.roster.pending == []


# --- lockstep -------------------------------------------------------------------------


@pytest.mark.parametrize("radio_first", [False, True])
def test_a_tick_closes_only_with_every_answer_and_every_announced_radio_message(
    radio_first: bool,
) -> None:
    h = started()
    if radio_first:  # a radio message may overtake its sender's act
        h.coordinator.handle(tx("0", 0, seq=1), 0.1)
    h.coordinator.handle(act(0, 0, radio_tx=1), 0.1)
    h.coordinator.handle(act(1, 0), 0.1)
    assert h.world.tick == 0  # the beacon has not answered
    h.coordinator.handle(ack("nest", 0), 0.1)
    if not radio_first:
        assert h.world.tick == 0  # robot 0's announced message has not arrived
        h.coordinator.handle(tx("0", 0, seq=1), 0.1)
    assert h.world.tick == 1 and h.clocks() == [0, 1]
    assert h.world.radio.counters.sent == 1
    assert h.coordinator.deadline == 0.1 + STALL


def test_the_stall_deadline_closes_a_tick_without_a_silent_robot() -> None:
    h = started()
    h.coordinator.handle(act(0, 0), 1.0)
    h.coordinator.handle(ack("nest", 0), 1.0)
    assert h.coordinator.deadline == STALL
    h.coordinator.wake(STALL - 0.01)
    assert h.world.tick == 0 and h.coordinator.counters.stalls == 0
    h.coordinator.wake(STALL)
    assert h.world.tick == 1
    assert h.coordinator.counters.stalls == 1
    assert h.coordinator.counters.missed == {"robot/1": 1}
    assert h.coordinator.deadline == 2 * STALL


def test_a_robot_silent_for_suspend_after_ticks_is_not_waited_for_until_it_answers() -> None:
    h = started()
    now = 0.0
    for tick in range(SUSPEND_AFTER):
        answer_all(h, tick, now, robots=(0,))
        now = h.coordinator.deadline or 0.0
        h.coordinator.wake(now)
    assert h.world.tick == SUSPEND_AFTER
    assert h.coordinator.counters.stalls == SUSPEND_AFTER
    # Tick 3 closes as soon as the others answered: robot 1 is not waited for.
    answer_all(h, SUSPEND_AFTER, now, robots=(0,))
    assert h.world.tick == SUSPEND_AFTER + 1 and h.coordinator.counters.stalls == SUSPEND_AFTER
    # Its answer to a tick it was not waited for is late, but it is waited for again.
    h.coordinator.handle(act(1, SUSPEND_AFTER + 1), now)
    assert h.coordinator.counters.late == 1
    assert h.world.tick == SUSPEND_AFTER + 1
    answer_all(h, SUSPEND_AFTER + 1, now, robots=(0,))
    assert h.world.tick == SUSPEND_AFTER + 2
    assert "robot/1" in h.coordinator.intake.barrier.answers


def test_a_join_takes_effect_when_the_tick_under_way_closes() -> None:
    h = started()
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.0)
    answer_all(h, 0, robots=(0,))
    assert h.world.tick == 1 and h.world.live_robots() == [0]
    h.outputs.clear()
    h.coordinator.handle(alive(Role.ROBOT, "1"), 0.5)
    assert h.world.live_robots() == [0]  # not during tick 1
    assert "robot/1" not in h.coordinator.intake.barrier.answers
    h.coordinator.handle(act(1, 1), 0.5)  # a newcomer's answer to a tick it is not in
    assert h.coordinator.counters.late == 1
    answer_all(h, 1, 0.5, robots=(0,))
    assert h.world.tick == 2 and h.world.live_robots() == [0, 1]
    sense = protocol.decode(h.published(KEYS.of(keyspace.SENSE, 1))[0].payload, protocol.Sense)
    assert sense.tick == 2
    assert sorted(h.coordinator.intake.barrier.answers) == ["beacon/nest", "robot/0", "robot/1"]


def test_with_nobody_left_the_world_idles_and_the_next_token_closes_the_tick_at_once() -> None:
    h = started()
    for event in (gone(Role.ROBOT, "0"), gone(Role.ROBOT, "1"), gone(Role.BEACON, "nest")):
        h.coordinator.handle(event, 1.0)
    for now in (10.0, 100.0, 1000.0):
        h.coordinator.wake(now)
        assert h.coordinator.deadline == now + STALL  # nothing to wait for: no stall
    assert h.world.tick == 0 and h.coordinator.counters.stalls == 0
    h.coordinator.handle(alive(Role.ROBOT, "1"), 1001.0)
    assert h.world.tick == 1 and h.world.live_robots() == [1]
    sense = protocol.decode(h.published(KEYS.of(keyspace.SENSE, 1))[-1].payload, protocol.Sense)
    assert sense.tick == 1
    assert list(h.coordinator.intake.barrier.answers) == ["robot/1"]


def test_departures_are_counted_once_for_robots_and_beacons_taking_part() -> None:
    h = started(3)
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.0)
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.0)  # not live any more: not again
    h.coordinator.handle(gone(Role.BEACON, "nest"), 0.0)
    h.coordinator.handle(gone(Role.BEACON, "other"), 0.0)  # never took part
    h.coordinator.handle(gone(Role.WORLD, "abc"), 0.0)  # not a participant's token
    assert h.coordinator.counters.departures == 2
    assert h.coordinator.state().departures == 2
    # The tick under way stops waiting for them.
    h.coordinator.handle(act(0, 0), 0.0)
    h.coordinator.handle(act(2, 0), 0.0)
    assert h.world.tick == 1 and h.coordinator.counters.stalls == 0


def present(h: Harness, identity: str) -> None:
    """``identity`` proves itself present: an authenticated world/info query."""
    h.coordinator.handle(query(keyspace.INFO, KEYS.of(keyspace.INFO), identity), 0.0)


def test_more_than_max_beacons_beacons_are_refused() -> None:
    h = harness(expect_beacons=MAX_BEACONS)
    h.coordinator.begin(0.0)
    for index in range(MAX_BEACONS + 1):
        present(h, f"beacon/b{index}")
        h.coordinator.handle(alive(Role.BEACON, f"b{index}"), 0.0)
    h.coordinator.handle(alive(Role.BEACON, "b0"), 0.0)  # one of them again: still in
    assert len(h.world.beacons()) == MAX_BEACONS and f"b{MAX_BEACONS}" not in h.world.beacons()
    assert h.coordinator.counters.rejected == 1


def test_tokens_without_proof_of_presence_never_join_nor_fill_the_beacons() -> None:
    """Twenty beacon tokens of an attacker with no key, then the real beacon: the fakes
    are hints that never join (nor count toward MAX_BEACONS, nor hold a tick up); the
    real one joins once it asks world/info with its key, in either order."""
    h = harness(expect_beacons=1)
    h.coordinator.begin(0.0)
    for index in range(20):
        h.coordinator.handle(alive(Role.BEACON, f"fake{index}"), 0.0)
    forged = query(keyspace.INFO, KEYS.of(keyspace.INFO), "beacon/fake0", keyring=OTHER_RUN)
    h.coordinator.handle(forged, 0.0)  # a proof without the key: refused, counted
    h.coordinator.handle(alive(Role.ROBOT, "0"), 0.0)
    h.coordinator.handle(alive(Role.ROBOT, "1"), 0.0)
    assert h.world.beacons() == [] and h.coordinator.phase == "waiting"
    h.coordinator.handle(alive(Role.BEACON, "real"), 0.0)
    assert h.world.beacons() == []  # a token alone: a hint
    present(h, "beacon/real")
    assert h.world.beacons() == ["real"] and h.coordinator.phase == "running"
    assert h.coordinator.counters.rejected == 1
    answers = [act(0, 0), act(1, 0), ack("real", 0)]
    for event in answers:
        h.coordinator.handle(event, 0.0)
    assert h.world.tick == 1 and h.coordinator.counters.stalls == 0


def test_a_robot_token_joins_only_once_its_robot_proved_present() -> None:
    h = harness(3, expect_robots=3)
    h.coordinator.roster.proven.discard("robot/2")  # the harness proved every robot
    h.coordinator.begin(0.0)
    for robot in range(3):
        h.coordinator.handle(alive(Role.ROBOT, str(robot)), 0.0)
    h.coordinator.handle(alive(Role.BEACON, "nest"), 0.0)
    assert h.world.live_robots() == [0, 1] and h.coordinator.phase == "waiting"
    present(h, "robot/2")
    assert h.world.live_robots() == [0, 1, 2] and h.coordinator.phase == "running"


# --- batch routes ---------------------------------------------------------------------


def test_a_batch_route_is_learnt_from_current_acts_and_forgotten_when_the_lead_goes() -> None:
    h = started()
    h.coordinator.handle(batch_of(0, 1, (0, 0), (1, 0)), 0.0)
    h.coordinator.handle(ack("nest", 0), 0.0)
    host = Host(0, 1)
    assert h.world.tick == 1 and h.coordinator.roster.hosts == {0: host, 1: host}
    batches = h.published(KEYS.of(keyspace.HOST_SENSE, 0))
    assert len(batches) == 1 and batches[0].steady
    # One tag for the batch, the host's; the senses are the robots' own (made at once).
    auth.unseal(
        KEYRING.only([host.identity]),
        host.identity,
        KEYS.of(keyspace.HOST_SENSE, 0),
        batches[0].payload,
        batches[0].attachment,
    )
    senses = batch.decode_senses(batches[0].payload)
    assert senses.last == 1 and senses.robots == [0, 1]
    assert [sense.tick for sense in senses.senses] == [1, 1]
    assert senses.senses == h.world.senses([0, 1], {}, ()).messages()
    assert len(h.published(KEYS.of(keyspace.SENSE, 1))) == 1  # tick 0's, on its own key
    h.coordinator.handle(gone(Role.ROBOT, "0"), 0.0)  # the first robot's process is gone
    assert h.coordinator.roster.hosts == {}
    h.coordinator.handle(act(1, 1), 0.0)
    h.coordinator.handle(ack("nest", 1), 0.0)
    assert h.world.tick == 2
    assert len(h.published(KEYS.of(keyspace.HOST_SENSE, 0))) == 1  # no batch for tick 2
    assert (
        protocol.decode(h.published(KEYS.of(keyspace.SENSE, 1))[-1].payload, protocol.Sense).tick
        == 2
    )


def test_a_host_speaks_only_for_the_robots_it_hosts() -> None:
    """Host 0-0's batch with robot 1's act in it: that entry is refused and counted, robot
    0's is taken, and robot 1 is still waited for (the host is no robot 1 process)."""
    h = started()
    h.coordinator.handle(batch_of(0, 0, (0, 0), (1, 0)), 0.0)
    assert h.coordinator.counters.rejected == 1
    assert h.coordinator.roster.hosts == {0: Host(0, 0)}
    h.coordinator.handle(ack("nest", 0), 0.0)
    assert h.world.tick == 0  # robot 1 has not answered
    h.coordinator.handle(act(1, 0), 0.0)
    assert h.world.tick == 1


def test_an_old_batch_replayed_teaches_no_route() -> None:
    h = started()
    stale = batch_of(0, 1, (0, 0), (1, 0))
    h.coordinator.handle(act(0, 0), 0.0)
    answer_all(h, 0, robots=(1,))
    assert h.world.tick == 1
    # Host 0-1's batch of tick 0, replayed after that tick closed: late, no route.
    h.coordinator.handle(stale, 0.0)
    assert h.coordinator.roster.hosts == {} and h.coordinator.counters.late == 2
    answer_all(h, 1)
    assert h.published(KEYS.of(keyspace.HOST_SENSE, 0)) == []
    assert (
        protocol.decode(h.published(KEYS.of(keyspace.SENSE, 0))[-1].payload, protocol.Sense).tick
        == 2
    )


# --- the beacon -----------------------------------------------------------------------


def beacon_clocks(h: Harness) -> list[int]:
    """The ticks the nest beacon was sent its clock for."""
    published = h.published(KEYS.of(keyspace.BEACON_CLOCK, "nest"))
    for message in published:
        KEYRING.open(names.WORLD, message.key, message.payload, message.attachment)
    return [protocol.decode(message.payload, protocol.Clock).tick for message in published]


def test_the_beacon_takes_part_in_the_ticks_it_answers_only() -> None:
    """Its ack names the next tick it answers: the world sends it no clock before then, and
    closes the ticks in between on the robots' answers alone."""
    h = started()
    h.coordinator.handle(act(0, 0), 0.0)
    h.coordinator.handle(act(1, 0), 0.0)
    assert h.world.tick == 0  # the beacon's first answer is waited for
    h.coordinator.handle(ack("nest", 0, next_tick=3), 0.0)
    for tick in (1, 2):
        assert h.world.tick == tick
        answer_robots = [act(robot, tick) for robot in (0, 1)]
        for event in answer_robots:
            h.coordinator.handle(event, 0.0)
    assert h.world.tick == 3
    answer_all(h, 3)  # its answer to tick 3 names none: every tick again
    answer_all(h, 4)
    assert h.world.tick == 5 and h.coordinator.counters.stalls == 0
    assert beacon_clocks(h) == [0, 3, 4, 5]
    assert h.clocks() == [0, 1, 2, 3, 4, 5]  # world/clock, for observers, every tick
    assert all(out.if_heard for out in h.published(KEYS.of(keyspace.CLOCK)))


def test_a_beacon_that_leaves_and_comes_back_is_sent_every_tick_until_it_answers() -> None:
    h = started()
    h.coordinator.handle(ack("nest", 0, next_tick=50), 0.0)
    answer_all(h, 0, robots=(0, 1))  # its second ack of tick 0 is late, and harmless
    assert h.world.tick == 1 and beacon_clocks(h) == [0]
    h.coordinator.handle(gone(Role.BEACON, "nest"), 0.0)
    h.coordinator.handle(alive(Role.BEACON, "nest"), 0.0)
    for robot in (0, 1):
        h.coordinator.handle(act(robot, 1), 0.0)
    assert h.world.tick == 2 and beacon_clocks(h) == [0, 2]
    assert "beacon/nest" in h.coordinator.intake.barrier.answers


# --- real time ------------------------------------------------------------------------


def test_real_time_closes_ticks_on_the_pacers_clock_holding_commands_capturing_once() -> None:
    h = started(1, now=100.0, clock="realtime")
    assert h.coordinator.deadline == pytest.approx(100.1)
    h.coordinator.handle(act(0, 0, capture=True, wheels=0.5), 100.05)
    h.coordinator.wake(100.09)
    assert h.world.tick == 0
    h.coordinator.wake(100.11)
    assert h.world.tick == 1 and h.coordinator.deadline == pytest.approx(100.2)
    assert len(h.published(KEYS.of(keyspace.CAMERA, 0))) == 1
    held = h.coordinator.intake.acts[0]
    assert (held.left, held.right, held.capture) == (0.5, 0.5, False)  # the command holds
    x1 = h.world.physics.pose(0)[:2]
    h.coordinator.wake(100.21)
    assert h.world.tick == 2
    assert len(h.published(KEYS.of(keyspace.CAMERA, 0))) == 1  # the capture happened once
    assert h.world.physics.pose(0)[:2] != x1  # still driving


def test_real_time_ignores_the_acts_of_robots_not_taking_part() -> None:
    h = started(2, now=0.0, clock="realtime")
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.0)
    h.coordinator.handle(act(1, 0), 0.01)
    assert h.coordinator.intake.acts == {}
    assert (h.coordinator.counters.rejected, h.coordinator.counters.late) == (0, 0)


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_a_radio_message_of_a_sender_that_leaves_before_its_tick_closes_is_late(
    clock: Literal["lockstep", "realtime"],
) -> None:
    """Taken, then its sender's token goes before the tick closes: nothing transmits it and
    it is no forgery, so it is late (as when the sender has left before it arrives), and
    the world and the radio refuse nothing (a stop-29 CI run saw the radio count it alone)."""
    h = started(2, now=0.0, clock=clock)
    h.coordinator.handle(tx("1", 0, 1), 0.01)
    h.coordinator.handle(tx("0", 0, 1), 0.01)
    assert len(h.coordinator.intake.transmissions) == 2
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.02)
    assert [t.sender for t in h.coordinator.intake.transmissions] == ["0"]
    if clock == "lockstep":
        h.coordinator.handle(act(0, 0, radio_tx=1), 0.03)
        h.coordinator.handle(ack("nest", 0), 0.03)
    else:
        h.coordinator.wake(0.11)
    assert h.world.tick == 1
    radio = h.world.radio.counters
    assert (radio.sent, radio.rejected) == (1, 0)
    assert (h.coordinator.counters.rejected, h.coordinator.counters.late) == (0, 1)
    assert h.coordinator.state().radio.rejected == h.coordinator.state().rejected == 0


def test_real_time_refuses_replayed_acts_and_radio_and_those_of_ticks_to_come() -> None:
    """Case 4 of issue 23: in real time an authentic act or radio message replayed (not
    after its sender's last) is refused and counted, as is one for a tick the world has
    not reached; one far behind the world is late."""
    h = started(1, now=0.0, clock="realtime")
    for now in (0.11, 0.21, 0.31):
        h.coordinator.wake(now)
    assert h.world.tick == 3
    h.coordinator.handle(act(0, 2, wheels=0.5), 0.32)
    h.coordinator.handle(tx("0", 2, 1), 0.32)
    h.coordinator.handle(tx("0", 3, 2), 0.32)
    assert h.coordinator.intake.acts[0].tick == 2
    taken = [(t.sender, t.seq) for t in h.coordinator.intake.transmissions]
    assert taken == [("0", 1), ("0", 2)] and h.coordinator.counters.rejected == 0
    for replay in (act(0, 2, wheels=-0.5), act(0, 1), tx("0", 2, 1), tx("0", 3, 2)):
        h.coordinator.handle(replay, 0.33)
    h.coordinator.handle(act(0, 4), 0.33)  # a tick to come
    h.coordinator.handle(tx("0", 4, 3), 0.33)
    assert h.coordinator.counters.rejected == 6 and h.world.radio.counters.rejected == 3
    assert h.coordinator.intake.acts[0].left == 0.5  # the replays did not steer it
    assert len(h.coordinator.intake.transmissions) == 2
    h.coordinator.handle(act(0, 3), 0.34)  # its next act: fresh
    assert h.coordinator.intake.acts[0].tick == 3 and h.coordinator.counters.rejected == 6
    h.coordinator.handle(ack("nest", 3, next_tick=8), 0.34)
    h.coordinator.handle(ack("nest", 0, next_tick=1), 0.34)  # an old ack: refused
    assert h.coordinator.roster.beacon_next == {"nest": 8}
    assert h.coordinator.counters.rejected == 7


# --- refusals -------------------------------------------------------------------------


OTHER_RUN = auth.Keyring(secret=bytes(32))
ACT_PAYLOAD = act(0, 0).payload


def sealed(kind: keyspace.KeyKind, key: str, payload: bytes, identity: str) -> Event:
    return Event(kind, key, payload, KEYRING.seal(identity, key, payload))


@pytest.mark.parametrize(
    "event",
    [
        act(0, 0, keyring=OTHER_RUN),  # forged: another run's key
        act(0, 0, keyring=None),  # no tag in a keyed run
        sealed(
            keyspace.ACT, KEYS.of(keyspace.ACT, 0), ACT_PAYLOAD, "robot/1"
        ),  # robot 1 speaking for 0
        sealed(keyspace.ACT, KEYS.of(keyspace.ACT, 7), ACT_PAYLOAD, "robot/7"),  # outside the swarm
        sealed(keyspace.ACT, KEYS.of(keyspace.ACT, 0), b"{not json", "robot/0"),
        act(0, 5),  # a tick that has not begun
        batch_of(7, 7, (0, 0)),  # a first robot outside the swarm
        batch_of(0, 7, (0, 0)),  # a last robot outside the swarm
        batch_of(0, 1, (0, 0), keyring=None),  # no tag
        batch_of(0, 1, (0, 0), keyring=OTHER_RUN),  # another run's key
        batch_of(0, 1, (0, 0), identity="robot/0"),  # a robot's key, not its host's
        batch_of(0, 0, (0, 0), identity=names.host_identity(0, 1)),  # another host's key
        batch_of(0, 0, (1, 0)),  # host 0-0 speaking for robot 1
        Event(keyspace.HOST_ACT, KEYS.of(keyspace.HOST_ACT, 0), b"BNA1 cut short"),
        ack("nest", 0, next_tick=0),  # the next tick it answers is not after this one
        Event(keyspace.ACK, KEYS.of(keyspace.ACK, "7"), ack("nest", 0).payload),  # no beacon name
        Event(keyspace.ACK, KEYS.of(keyspace.ACK, "nest"), ack("nest", 0).payload),  # untagged
        tx("99", 0, 1),  # no robot of the swarm
        tx("0", 0, 1, keyring=OTHER_RUN),
        tx("0", 3, 1),  # radio for a tick that has not begun
        alive(Role.ROBOT, "2"),  # a token outside a swarm of two
        alive(Role.BEACON, "07"),  # all digits: a robot's name, not a beacon's
        Event(Happening.REFUSED, KEYS.of(keyspace.INFO), b"no authentication tag"),
    ],
)
def test_forged_and_foreign_inputs_are_refused_and_counted(event: Event) -> None:
    h = started()
    h.coordinator.handle(event, 0.1)
    assert h.coordinator.counters.rejected == 1
    assert h.coordinator.counters.late == 0
    assert h.coordinator.intake.acts == {} and h.coordinator.intake.transmissions == []
    assert h.world.live_robots() == [0, 1] and h.world.beacons() == ["nest"]
    if event.kind == keyspace.RADIO_TX:  # the radio counts the medium's refusals too
        assert h.world.radio.counters.rejected == 1
    answer_all(h, 0, 0.1)  # the tick closes as ever: nothing was taken
    assert h.world.tick == 1 and h.coordinator.counters.stalls == 0


def test_a_radio_message_is_taken_once_and_at_most_max_tx_per_tick() -> None:
    h = started()
    h.coordinator.handle(tx("0", 0, 1), 0.0)
    h.coordinator.handle(tx("0", 0, 1), 0.0)  # a replay
    assert [(t.sender, t.seq) for t in h.coordinator.intake.transmissions] == [("0", 1)]
    assert h.coordinator.counters.rejected == 1 and h.world.radio.counters.rejected == 1


def test_the_inputs_dropped_by_the_transport_are_counted() -> None:
    h = started()
    h.coordinator.dropped(3)
    h.coordinator.dropped(0)
    assert h.coordinator.counters.rejected == 3 and h.coordinator.state().rejected == 3


# --- queries --------------------------------------------------------------------------


def _reply(h: Harness, event: Event) -> Reply | ReplyError:
    h.outputs.clear()
    h.coordinator.handle(event, 0.0)
    replies = [out for out in h.outputs if isinstance(out, Reply | ReplyError)]
    assert len(replies) == 1 and replies[0].query is event.query
    return replies[0]


def _join(h: Harness, identity: str = "robot/0") -> int | bytes:
    reply = _reply(h, query(keyspace.JOIN, KEYS.of(keyspace.JOIN), identity))
    if isinstance(reply, ReplyError):
        return reply.reason
    auth.reply_open(
        KEYRING.only([identity]), identity, reply.key, reply.payload, reply.attachment, nonce=NONCE
    )
    return protocol.decode(reply.payload, protocol.JoinReply).id


def test_join_hands_out_the_smallest_id_never_given_then_one_whose_robot_left() -> None:
    h = harness()
    h.coordinator.begin(0.0)
    h.coordinator.handle(alive(Role.ROBOT, "1"), 0.0)  # robot 1 runs: its id is taken
    assert _join(h) == 0
    h.coordinator.handle(alive(Role.ROBOT, "0"), 0.0)
    assert _join(h) == NO_ID_LEFT  # both robots run
    h.coordinator.handle(gone(Role.ROBOT, "1"), 0.0)
    assert _join(h) == 1  # a replacement for the robot that left
    assert h.coordinator.counters.rejected == 0


def test_stats_answers_the_world_state_to_the_asker() -> None:
    h = started()
    h.coordinator.handle(act(0, 0, keyring=OTHER_RUN), 0.0)
    reply = _reply(h, query(keyspace.STATS, KEYS.of(keyspace.STATS), names.LAUNCHER))
    assert isinstance(reply, Reply)
    auth.reply_open(
        KEYRING, names.LAUNCHER, reply.key, reply.payload, reply.attachment, nonce=NONCE
    )
    state = protocol.decode(reply.payload, protocol.WorldState)
    assert (state.tick, state.rejected, len(state.robots)) == (0, 1, 2)


@pytest.mark.parametrize("kind", [keyspace.JOIN, keyspace.STATS])
def test_an_unauthenticated_query_is_refused_and_counted(kind: keyspace.KeyKind) -> None:
    h = started()
    key = KEYS.of(keyspace.JOIN) if kind == keyspace.JOIN else KEYS.of(keyspace.STATS)
    forged = query(kind, key, "robot/0", keyring=OTHER_RUN)
    assert _reply(h, forged) == ReplyError(forged.query, UNAUTHENTICATED)
    assert h.coordinator.counters.rejected == 1 and h.coordinator.roster.assigned == {0, 1}


# --- what goes out --------------------------------------------------------------------


def test_what_the_world_sends_a_robot_carries_that_robots_tag() -> None:
    h = started()
    h.coordinator.handle(act(0, 0, capture=True), 0.0)
    answer_all(h, 0, robots=(1,))
    robot_keyring = KEYRING.only(["robot/0"])
    for key, kind in (
        (KEYS.of(keyspace.SENSE, 0), protocol.Sense),
        (KEYS.of(keyspace.CAMERA, 0), None),
    ):
        message = h.published(key)[-1]
        metadata = auth.unseal(robot_keyring, "robot/0", key, message.payload, message.attachment)
        if kind is not None:
            assert protocol.decode(message.payload, kind).tick == 1
            assert message.steady
        else:
            assert protocol.decode(metadata or b"", protocol.CameraMeta).tick == 1
            assert not message.steady
    clock = h.published(KEYS.of(keyspace.CLOCK))[-1]
    auth.unseal(KEYRING, names.WORLD, KEYS.of(keyspace.CLOCK), clock.payload, clock.attachment)


def test_the_timeline_comes_out_in_the_order_of_the_ticks_work() -> None:
    h = started(traced=True)
    h.outputs.clear()
    answer_all(h, 0, now=0.25)
    timeline = [out for out in h.outputs if isinstance(out, Mark | Opened | Answered)]
    assert timeline == [
        Answered("robot/0", 0.0, 0.25),
        Answered("robot/1", 0.0, 0.25),
        Answered("beacon/nest", 0.0, 0.25),
        Mark(Moment.CLOSE_START),
        Mark(Moment.ADVANCED),
        Mark(Moment.DELIVERED),
        Mark(Moment.OPEN_START),
        Opened(tick=1, robots=2, frames=0, rx=0, batched=0),
        Mark(Moment.OPENED),
    ]
    untraced = started()
    answer_all(untraced, 0)
    assert not any(isinstance(out, Mark | Opened | Answered) for out in untraced.outputs)


class _Writer:
    def __init__(self) -> None:
        self.lines: list[dict[str, Any]] = []

    def write(self, **fields: Any) -> None:
        self.lines.append(fields)

    def close(self) -> None:
        pass


def test_the_trace_line_of_a_tick_holds_its_opening_answers_and_closing() -> None:
    h = started(traced=True)
    writer = _Writer()
    timeline = TickTimeline(writer)  # type: ignore[arg-type]
    for output in h.outputs:
        if isinstance(output, Mark | Opened | Answered):
            timeline.note(output)
    h.outputs.clear()
    answer_all(h, 0, now=0.25)
    for output in h.outputs:
        if isinstance(output, Mark | Opened | Answered):
            timeline.note(output)
    [line] = writer.lines
    assert list(line) == [
        "tick",
        "robots",
        "frames",
        "rx",
        "batched",
        "open_start",
        "opened",
        "answers",
        "close_start",
        "advanced",
        "delivered",
    ]
    assert (line["tick"], line["robots"]) == (0, 2)
    assert [who for who, _, _ in line["answers"]] == ["robot/0", "robot/1", "beacon/nest"]
    assert line["open_start"] <= line["opened"] <= line["close_start"]
    assert line["close_start"] <= line["advanced"] <= line["delivered"]
