"""The world ends its run (world_server/observer/referee.py): fed what a run publishes, its
referee ends it as swarm run's rules say, with the same summary; the ending it publishes
is tagged for every process, and a forged one is refused; a Dask cluster gets the robots
split by its workers' cores, each worker only its own robots' keys."""

from __future__ import annotations

import os
from typing import Any

import pytest

from bestofn_swarm.plumbing.ending import open_ending
from bestofn_swarm.plumbing.run_keys import from_text
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.endings import Ending, Halt, Stop, TimeLimit
from deploy.cli import build_parser
from deploy.inprocess.engine import EngineHooks, run_in_process
from deploy.launcher.dask_placement import DaskPlacement, WorkerSlot, split_robots
from deploy.launcher.plan import plan_from_args
from nest_beacon.core.beacon import BeaconConfig
from robot_agent.core.controller import ControllerConfig
from world_server.core.world import World, WorldConfig
from world_server.observer.referee import (
    LOST_AFTER,
    EndingRules,
    LostRobot,
    OutsideRobot,
    PlannedDeparture,
    Referee,
    RunShape,
)

RUN = "ending"
WATCHED = frozenset({keyspace.STATUS, keyspace.STATE, keyspace.CLOCK})


def _world(robots: int = 4, sites: int = 5, seed: int = 3) -> WorldConfig:
    return WorldConfig(run=RUN, seed=seed, num_sites=sites, num_robots=robots)


def _referee(config: WorldConfig, rules: EndingRules | None = None) -> Referee:
    world = World(config)
    shape = RunShape(
        run_id=config.run,
        seed=config.seed,
        num_robots=config.num_robots,
        num_sites=config.num_sites,
        best_site=world.layout.best_site,
        info=world.info,
    )
    return Referee(shape, rules or EndingRules())


class Tap:
    """A referee watching an in-process run as the world server's adapter feeds it: the
    statuses and states it publishes, and a look at each tick the world opens."""

    def __init__(self, referee: Referee, robots: int) -> None:
        self.referee = referee
        self.keys = keyspace.Keys(RUN)
        self.robots = range(robots)
        self.halt: Halt | None = None

    def __call__(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        if self.halt is not None:
            return
        opened = keyspace.open_sample(
            self.keys, key, payload, attachment, keyring=None, kinds=WATCHED
        )
        if opened is None:
            return
        if opened.kind is keyspace.STATUS:
            self.referee.take(opened)
        elif opened.kind is keyspace.STATE:
            self.referee.state(opened.message)
        elif opened.kind is keyspace.CLOCK:
            clock = opened.message
            self.referee.now(clock.tick, clock.t, self.robots, [names.DEFAULT_BEACON])
            self.halt = self.referee.look()


@pytest.mark.parametrize(
    ("seed", "timeout", "ended"),
    [(3, 1800.0, Ending.CONSENSUS), (1, 40.0, Ending.TIMEOUT)],
)
def test_the_world_ends_a_run_as_the_engine_does_with_the_same_summary(
    seed: int, timeout: float, ended: Ending
) -> None:
    config = _world(seed=seed)
    referee = _referee(config, EndingRules(timeout=timeout))
    tap = Tap(referee, config.num_robots)
    summary = run_in_process(
        config, ControllerConfig(), BeaconConfig(), timeout=timeout, hooks=EngineHooks(tap=tap)
    )
    if tap.halt is None:  # the last status came in the engine's last tick: a wake-up's look
        tap.halt = referee.look()
    assert tap.halt is not None and summary["ended"] == ended
    ending = referee.ending(tap.halt, None, wall_time=1.0)
    assert ending.ended is ended and ending.code == ended.code and ending.run == RUN
    assert ending.summary["digest"] == summary["digest"]
    assert ending.summary["per_robot"] == summary["per_robot"]
    if ended is Ending.TIMEOUT:
        assert ending.timeout_kind is TimeLimit.SIM and ending.summary["timeout_kind"] == "sim"


def _started(referee: Referee, robots: range, beacons: list[str] | None = None) -> None:
    referee.now(0, 0.0, robots, beacons if beacons is not None else ["nest"], wall=0.0)


def test_a_beacon_away_for_longer_than_the_grace_ends_the_run_crashed() -> None:
    referee = _referee(_world())
    _started(referee, range(4))
    referee.now(10, 1.0, range(4), [], wall=1.0)
    assert referee.look() is None  # away: maybe its host is only suspended
    referee.now(20, 2.0, range(4), [], wall=1.0 + LOST_AFTER)
    assert referee.look() == Halt(Stop.CRASHED)
    assert referee.ending(Halt(Stop.CRASHED), None, 1.0).lost == ["nest"]


def test_a_spare_beacon_that_goes_is_not_missed() -> None:
    referee = _referee(_world())
    _started(referee, range(4), ["nest", "spare"])
    referee.now(10, 1.0, range(4), ["nest"], wall=1.0)
    referee.now(20, 2.0, range(4), ["nest"], wall=1.0 + LOST_AFTER)
    assert referee.look() is None and referee.lost == []


def test_what_comes_back_within_the_grace_never_went() -> None:
    """A world or robots suspended for longer than Zenoh's lease: every token goes, and
    comes back once they wake."""
    referee = _referee(_world())
    _started(referee, range(4))
    referee.now(10, 1.0, [], [], wall=1.0)
    assert referee.running() == [0, 1, 2, 3] and referee.look() is None
    referee.now(11, 1.1, range(4), ["nest"], wall=14.0)
    assert referee.lost == [] and not referee.beacon_lost
    referee.now(12, 1.2, [0, 1, 2], ["nest"], wall=15.0)  # robot 3 goes, and the run ends
    ending = referee.ending(Halt(Stop.STALLED), None, 15.0)
    assert ending.lost == [] and ending.ended is Ending.STALLED  # away, maybe only frozen


def test_with_every_robot_gone_the_world_waits_rather_than_decide() -> None:
    referee = _referee(_world(), EndingRules(lost_robot=LostRobot.CONTINUE))
    _started(referee, range(4))
    referee.now(10, 1.0, [], ["nest"], wall=1.0)
    referee.now(11, 1.1, [], ["nest"], wall=1.0 + LOST_AFTER)
    assert referee.running() == [] and referee.lost == ["0", "1", "2", "3"]
    assert referee.look() is None


@pytest.mark.parametrize("lost_robot", list(LostRobot))
def test_a_lost_robot_holds_nothing_up_and_the_run_ends_crashed(lost_robot: LostRobot) -> None:
    referee = _referee(_world(), EndingRules(lost_robot=lost_robot))
    _started(referee, range(4))
    referee.now(10, 1.0, [0, 1, 3], ["nest"], wall=1.0)
    halt = referee.look()
    if lost_robot is LostRobot.END:
        assert halt == Halt(Stop.CRASHED)  # at once: a lost host takes its robots along
    else:
        assert halt is None and referee.running() == [0, 1, 2, 3]  # away, held up for now
        referee.now(20, 2.0, [0, 1, 3], ["nest"], wall=1.0 + LOST_AFTER)
        assert referee.look() is None and referee.running() == [0, 1, 3]  # the rest go on
        halt = Halt(Stop.TIMEOUT, TimeLimit.SIM)
    ending = referee.ending(halt, None, 1.0)
    assert ending.ended is Ending.CRASHED and ending.code == 1 and ending.lost == ["2"]
    robot = ending.summary["per_robot"][2]
    assert robot["crashed"] and not robot["killed"]


def test_a_lost_robot_back_runs_again_and_a_fresh_process_is_a_restart() -> None:
    referee = _referee(_world(), EndingRules(lost_robot=LostRobot.END))
    _started(referee, range(4))
    keys = keyspace.Keys(RUN)
    referee.take(_status(keys, 1, tick=50))
    referee.now(60, 6.0, [0, 2, 3], ["nest"], wall=1.0)
    assert referee.lost == ["1"]
    referee.now(70, 7.0, range(4), ["nest"], wall=2.0)
    assert referee.lost == [] and referee.running() == [0, 1, 2, 3]
    referee.take(_status(keys, 1, tick=3))  # its first status: tick 3 of a fresh process
    record = referee.observer.records[1]
    assert record.restarts == 1 and not record.crashed


def _status(keys: keyspace.Keys, robot: int, tick: int) -> keyspace.Opened:
    status = protocol.Status(
        v=1,
        id=robot,
        tick=tick,
        t=tick * 0.1,
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
    opened = keyspace.open_sample(
        keys, keys.of(keyspace.STATUS, robot), protocol.encode(status), None, keyring=None
    )
    assert opened is not None
    return opened


def test_the_plan_s_faults_are_a_kill_and_a_restart_not_a_loss() -> None:
    rules = EndingRules(
        departures=(PlannedDeparture(1, 10.0), PlannedDeparture(2, 20.0, returns=True))
    )
    referee = _referee(_world(), rules)
    _started(referee, range(4))
    referee.now(5, 10.5, [0, 2, 3], ["nest"], wall=1.0)  # killed as planned
    referee.now(6, 20.5, [0, 3], ["nest"], wall=2.0 + LOST_AFTER)  # restarting: waited for
    assert referee.running() == [0, 2, 3] and referee.look() is None
    referee.now(7, 21.0, [0, 2, 3], ["nest"], wall=3.0 + LOST_AFTER)  # back
    assert referee.lost == []
    ending = referee.ending(Halt(Stop.TIMEOUT, TimeLimit.SIM), None, 1.0)
    assert ending.ended is Ending.TIMEOUT and ending.lost == []
    rows = ending.summary["per_robot"]
    assert rows[1]["killed"] and not rows[1]["crashed"] and rows[2]["restarts"] == 1


def test_a_robot_killed_then_restarted_by_the_plan_is_waited_for_and_counted_again() -> None:
    """``--kill 2@10 --restart 2@20``: killed at 10 s, the run waits for the restart to
    come, and the fresh process counts from the moment it joins (it once stayed killed,
    and the run waited for a restart that had already happened until its time limit)."""
    rules = EndingRules(
        departures=(PlannedDeparture(2, 10.0), PlannedDeparture(2, 20.0, returns=True))
    )
    referee = _referee(_world(), rules)
    _started(referee, range(4))
    referee.now(5, 10.5, [0, 1, 3], ["nest"], wall=1.0)  # killed as planned
    assert referee.running() == [0, 1, 3] and referee.look() is None  # a restart to come
    referee.now(8, 20.5, [0, 1, 2, 3], ["nest"], wall=2.0)  # started again
    assert referee.running() == [0, 1, 2, 3] and referee.lost == []
    ending = referee.ending(Halt(Stop.TIMEOUT, TimeLimit.SIM), None, 1.0)
    row = ending.summary["per_robot"][2]
    assert row["restarts"] == 1 and not row["killed"] and not row["crashed"]


def test_a_robot_that_leaves_before_its_planned_kill_is_lost() -> None:
    referee = _referee(_world(), EndingRules(departures=(PlannedDeparture(1, 10.0),)))
    _started(referee, range(4))
    referee.now(5, 9.0, [0, 2, 3], ["nest"], wall=1.0)
    referee.now(6, 9.1, [0, 2, 3], ["nest"], wall=1.0 + LOST_AFTER)
    assert referee.lost == ["1"]


def test_an_outside_robot_whose_link_went_departed() -> None:
    rules = EndingRules(outside=(OutsideRobot(3, "udp"),))
    referee = _referee(_world(), rules)
    _started(referee, range(4))
    referee.now(5, 1.0, [0, 1, 2], ["nest"], wall=1.0 + LOST_AFTER)
    assert referee.lost == [] and referee.running() == [0, 1, 2]
    ending = referee.ending(Halt(Stop.STALLED), None, 1.0)
    rows = ending.summary["per_robot"]
    assert rows[3]["departed"] and rows[3]["outside"] == "udp" and not rows[3]["crashed"]


def test_a_signal_before_the_start_or_after_ends_the_run_interrupted() -> None:
    referee = _referee(_world())
    assert referee.look() is None
    assert referee.look(signalled=True) == Halt(Stop.INTERRUPTED)
    ending = referee.ending(Halt(Stop.INTERRUPTED), None, 0.0, signum=15, signal_name="SIGTERM")
    assert ending.ended is Ending.INTERRUPTED and ending.code == 143
    assert ending.signal == "SIGTERM" and ending.summary["signal"] == "SIGTERM"


def test_byzantine_robots_are_not_waited_for() -> None:
    rules = EndingRules(byzantine=(byzantine_robot("1:silent"),))
    referee = _referee(_world(), rules)
    assert referee.behaviours == {1: referee.behaviours[1]}
    assert referee.observer.honest() == [0, 2, 3]


def byzantine_robot(text: str) -> Any:
    from robot_agent.core.byzantine import ByzantineRobot

    return ByzantineRobot.parse(text)


# --- the ending on the wire ---------------------------------------------------------------


def _sealed(keyring: auth.Keyring | None, robots: int = 4) -> tuple[str, bytes, bytes]:
    referee = _referee(_world(robots))
    ending = referee.ending(Halt(Stop.STALLED), None, 1.0)
    key = keyspace.Keys(RUN).of(keyspace.ENDING)
    payload = protocol.encode(ending)
    return key, payload, keyspace.seal_for_everyone(keyring, key, payload, robots, names.WORLD)


def test_every_process_checks_the_ending_with_a_key_it_holds() -> None:
    secret = auth.Keyring(os.urandom(auth.SECRET_BYTES))
    key, payload, attachment = _sealed(secret)
    keys = keyspace.Keys(RUN)
    holders = [
        secret,  # world, launcher, recorder, views
        secret.only([names.robot_identity(3)]),  # a robot process
        secret.only([names.robot_identity(0), names.robot_identity(1), names.host_identity(0, 1)]),
        secret.only([names.BRIDGE]),
        secret.only([names.beacon_identity("nest"), names.WORLD]),  # a beacon by hand
    ]
    for holder in holders:
        assert open_ending(keys, key, payload, attachment, holder).ended is Ending.STALLED


def test_a_forged_or_foreign_ending_is_refused() -> None:
    secret = auth.Keyring(os.urandom(auth.SECRET_BYTES))
    keys = keyspace.Keys(RUN)
    key, payload, attachment = _sealed(secret)
    robot = secret.only([names.robot_identity(2)])
    forgeries = [
        # robot 2's process, sealing an ending for everyone with the only key it holds
        (payload, robot.seal(names.robot_identity(2), key, payload)),
        # another run's world
        (payload, _sealed(auth.Keyring(os.urandom(auth.SECRET_BYTES)))[2]),
        # the real tags on another ending
        (payload.replace(b'"stalled"', b'"consensus"', 1), attachment),
        (payload, None),
    ]
    for forged, tags in forgeries:
        for holder in (secret, secret.only([names.robot_identity(3)]), robot):
            if holder is robot and tags is forgeries[0][1]:
                continue  # its own key's tag: only robot 2 itself could be fooled by it
            with pytest.raises(keyspace.SampleError):
                open_ending(keys, key, forged, tags, holder)
    other = keyspace.Keys("another-run")
    with pytest.raises(keyspace.SampleError):
        open_ending(other, other.of(keyspace.ENDING), payload, attachment, None)
    with pytest.raises(keyspace.SampleError, match="too large"):
        open_ending(keys, key, b" " * (2 * protocol.MAX_ENDING_BYTES + 1), None, None)


def test_an_unkeyed_ending_needs_no_tag() -> None:
    key, payload, attachment = _sealed(None)
    ending = open_ending(keyspace.Keys(RUN), key, payload, attachment, None)
    assert ending.summary["num_robots"] == 4


# --- Dask: where the robots go, and with which keys --------------------------------------


def test_robots_are_split_by_the_workers_cores_in_contiguous_processes() -> None:
    workers = [
        WorkerSlot("tcp://a:1", "a", 1),
        WorkerSlot("tcp://b:1", "b", 2),
        WorkerSlot("tcp://c:1", "c", 1),
    ]
    placed = split_robots(list(range(10)), workers)
    # 2.5, 5 and 2.5 robots: the first of the equal remainders takes the one left over.
    assert [share.robots for share in placed] == [[0, 1, 2], [3, 4, 5, 6, 7], [8, 9]]
    assert [share.processes for share in placed] == [[[0, 1, 2]], [[3, 4, 5], [6, 7]], [[8, 9]]]
    assert [share.robots for share in split_robots([0, 1], workers)] == [[0], [1]]
    with pytest.raises(Exception, match="no worker"):
        split_robots([0], [])


def test_each_worker_receives_only_its_own_robots_keys() -> None:
    args = build_parser(["run"]).parse_args(
        ["run", "--robots", "6", "--no-record", "--dask", "tcp://127.0.0.1:8786", "--secure"]
    )
    plan = plan_from_args(args)
    assert plan.lost_robot is LostRobot.END and plan.config["dask"] == "tcp://127.0.0.1:8786"
    secret = auth.Keyring(os.urandom(auth.SECRET_BYTES))
    placement = DaskPlacement(plan)
    launch = placement._launch([2, 3, 4], secret)
    assert launch.keys is not None and "secret" not in launch.keys
    keyring = from_text(launch.keys, plan.run_id)  # a key file of this run
    assert keyring.secret is None and keyring.identities == sorted(
        [*(names.robot_identity(robot) for robot in (2, 3, 4)), names.host_identity(2, 4)]
    )
    assert launch.argv.count("--id") == 3


@pytest.mark.parametrize(
    ("options", "refused"),
    [
        (["--kill", "1@10"], "--kill"),
        (["--robots-per-process", "2"], "--robots-per-process"),
        (["--engine", "inprocess"], "--dask"),
        (["--secure", "--no-keys"], "--no-keys"),
    ],
)
def test_what_cannot_go_with_dask_is_a_usage_error(options: list[str], refused: str) -> None:
    args = build_parser(["run"]).parse_args(
        ["run", "--no-record", "--dask", "tcp://127.0.0.1:8786", *options]
    )
    with pytest.raises(ValueError, match=refused):
        plan_from_args(args)
