"""The stall watchdog on its own, and the endings of in-process runs that use it."""

from __future__ import annotations

import pytest

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.endings import ENDINGS, Stop, ending_of
from deploy.inprocess.engine import run_in_process
from nest_beacon.core.beacon import BeaconConfig
from robot_agent.core.controller import ControllerConfig
from world_server.core.world import WorldConfig
from world_server.observer.watchdog import Watchdog, default_stall_window

BODY = 0.074  # two e-puck radii
WINDOW = 100.0


def _status(
    robot: int,
    t: float,
    phase: protocol.Phase = "to_site",
    trips: int = 0,
    decided: int | None = None,
) -> protocol.Status:
    return protocol.Status(
        v=1,
        id=robot,
        tick=round(t * 10),
        t=t,
        phase=phase,
        trips=trips,
        opinion=[0.5, 0.5],
        pool_size=0,
        poolings=trips,
        decided_site=decided,
        decision_time=t if decided is not None else None,
        decision_trips=trips if decided is not None else None,
        comparison=None,
    )


def test_robots_that_never_progress_stall_exactly_at_the_window() -> None:
    watchdog = Watchdog(range(2), WINDOW, BODY)
    for robot in range(2):
        watchdog.status(_status(robot, 0.0))
    t = 0.0
    while t < WINDOW - 1.0:
        t += 1.0
        # Roaming far and wide, jostling at the nest: motion is not progress.
        watchdog.poses(t, [(0, 10 * BODY * (t % 2), 0.0), (1, 1.0, 3 * BODY * (t % 3))])
        assert not watchdog.stalled(t)
    assert not watchdog.stalled(WINDOW - 0.01)
    assert watchdog.stalled(WINDOW)


def test_robots_slowly_completing_steps_never_stall() -> None:
    """Each robot completes a step of its task just inside the window: slow, but
    progress, for ten windows of sim time."""
    watchdog = Watchdog(range(2), WINDOW, BODY)
    step = 0.9 * WINDOW
    t = 0.0
    # A trip's steps, each completed: reach a site, look at it, hear the beacon at the nest.
    phases: list[protocol.Phase] = ["to_site", "sensing", "to_nest", "at_nest"]
    moves = 0
    while t < 10 * WINDOW:
        t += step
        moves += 1
        watchdog.status(_status(0, t, phases[moves % len(phases)], trips=moves // 4))
        watchdog.status(_status(1, t, "to_site", trips=moves))  # a pooling, slowly
        for now in (t, t + step - 0.01):
            assert not watchdog.stalled(now), now
    # Only robot 1 keeps going from here; robot 0 falls silent, and the run still goes on.
    quiet_from = t
    for _ in range(5):
        t += step
        moves += 1
        watchdog.status(_status(1, t, "to_site", trips=moves))
        assert not watchdog.stalled(t)
    assert watchdog.last_progress() == t
    assert watchdog.stuck()[0]["last_progress_s"] == pytest.approx(quiet_from)


@pytest.mark.parametrize(
    ("before", "after", "progress"),
    [
        ("to_site", "sensing", True),  # reached a site
        ("sensing", "to_site", True),  # looked at the first site of the pair
        ("sensing", "to_nest", True),  # looked at the second (or gave it up)
        ("to_nest", "at_nest", True),  # at the nest, heard the beacon
        ("waiting", "at_nest", True),  # heard it at last
        ("to_site", "to_nest", False),  # gave up a leg
        ("to_nest", "waiting", False),  # at the nest centre, and the beacon is silent
    ],
)
def test_which_phase_changes_complete_a_step(
    before: protocol.Phase, after: protocol.Phase, progress: bool
) -> None:
    watchdog = Watchdog([0], WINDOW, BODY)
    watchdog.status(_status(0, 5.0, before))
    watchdog.status(_status(0, 50.0, after))
    assert watchdog.last_progress() == (50.0 if progress else 0.0)
    assert watchdog.stuck()[0]["phase"] == after
    assert watchdog.stuck()[0]["phase_since_s"] == 50.0


def test_the_same_status_again_is_no_progress() -> None:
    watchdog = Watchdog([0], WINDOW, BODY)
    watchdog.status(_status(0, 5.0, "to_nest", trips=1))
    watchdog.status(_status(0, 50.0, "to_nest", trips=1))  # e.g. only its reject count grew
    assert watchdog.last_progress() == 5.0
    assert watchdog.stalled(105.0)


def test_decided_and_departed_robots_hold_nothing_up() -> None:
    watchdog = Watchdog(range(3), WINDOW, BODY)
    watchdog.status(_status(0, 10.0, "to_decision", trips=2, decided=1))
    watchdog.status(_status(1, 20.0, "to_site", trips=1))
    watchdog.status(_status(2, 30.0, "to_site", trips=1))
    watchdog.retired(2)  # killed or crashed, last seen at 30 s
    assert watchdog.undecided() == [1]
    assert not watchdog.stalled(119.9) and watchdog.stalled(120.0)
    watchdog.status(_status(1, 125.0, "to_decision", trips=3, decided=1))
    assert watchdog.undecided() == [] and watchdog.last_progress() is None
    assert not watchdog.stalled(10_000.0)  # nobody left to wait for: not a stall
    assert watchdog.stuck() == []


def test_a_decided_robot_progresses_as_it_nears_its_slot_until_parked() -> None:
    """With the slots known, a robot still on its way to its slot keeps the run going
    while it gets closer; pushed to and fro, or parked, it does not."""
    slots = {(0, 1): (2.0, 0.0)}
    watchdog = Watchdog(range(2), WINDOW, BODY, slot_of=lambda robot, site: slots[robot, site])
    watchdog.status(_status(1, 1.0, "to_nest"))
    watchdog.status(_status(1, 5.0, "at_nest"))  # undecided, and its last step
    watchdog.status(_status(0, 10.0, "to_decision", trips=2, decided=1))
    assert watchdog.last_progress() == 10.0
    for t, x in [(20.0, 0.0), (60.0, 0.5), (100.0, 1.0)]:
        watchdog.poses(t, [(0, x, 0.0)])
    assert watchdog.last_progress() == 100.0
    # Backing off and coming back no closer: no progress.
    for t, x in [(120.0, 0.5), (150.0, 1.0 - 0.2 * BODY), (190.0, 0.3)]:
        watchdog.poses(t, [(0, x, 0.0)])
    assert watchdog.last_progress() == 100.0 and watchdog.stalled(200.0)
    watchdog.poses(210.0, [(0, 1.9, 0.0)])
    assert watchdog.last_progress() == 210.0
    # Parked: done, it holds the run up no more; robot 1 made no progress since 5 s.
    watchdog.status(_status(0, 220.0, "stopped", trips=2, decided=1))
    assert watchdog.last_progress() == 5.0 and watchdog.stalled(220.0)


def test_a_restarted_robot_starts_undecided_from_its_restart() -> None:
    watchdog = Watchdog([0], WINDOW, BODY)
    watchdog.status(_status(0, 10.0, "stopped", trips=3, decided=0))
    watchdog.retired(0)
    watchdog.restarted(0, 400.0)
    assert watchdog.undecided() == [0]
    assert not watchdog.stalled(499.0) and watchdog.stalled(500.0)


def test_each_stuck_robot_says_where_its_phase_and_since_when() -> None:
    watchdog = Watchdog(range(2), WINDOW, BODY)
    watchdog.status(_status(0, 1.0, "to_nest", trips=1))
    watchdog.status(_status(0, 3.0, "at_nest", trips=1))
    watchdog.status(_status(0, 5.0, "to_site", trips=2))
    watchdog.status(_status(0, 7.0, "to_nest", trips=2))  # a leg given up
    watchdog.status(_status(1, 4.0, "to_decision", trips=2, decided=0))
    watchdog.poses(10.0, [(0, 0.0123, -0.0456), (1, 1.0, 1.0)])
    assert watchdog.stuck() == [
        {
            "id": 0,
            "phase": "to_nest",
            "phase_since_s": 7.0,
            "x": 0.012,
            "y": -0.046,
            "trips": 2,
            "last_progress_s": 5.0,
        }
    ]


def test_the_default_window_grows_with_the_arena_and_the_beacons_outages() -> None:
    small = default_stall_window(0.75, 0.13, 120.0)
    assert small == pytest.approx(240.0 + 2 * 1.5 / 0.13)
    assert default_stall_window(3.3, 0.13, 120.0) > small
    assert default_stall_window(0.75, 0.13, 120.0, [(0.0, 60.0), (100.0, 400.0)]) == (
        pytest.approx(small + 360.0)
    )
    # An outage lasting to the time limit is not waited for: no pooling can come after it.
    outages = [(0.0, 60.0), (100.0, 1000.0)]
    assert default_stall_window(0.75, 0.13, 120.0, outages, time_limit=1000.0) == (
        pytest.approx(small + 60.0)
    )
    with pytest.raises(ValueError):
        Watchdog([0], 0.0, BODY)


def test_endings_from_why_the_run_stopped_and_what_the_robots_decided() -> None:
    assert ending_of(Stop.DECIDED, all_decided=True, consensus=True) == "consensus"
    assert ending_of(Stop.DECIDED, all_decided=True, consensus=False) == "split"
    assert ending_of(Stop.STALLED, all_decided=False, consensus=False) == "stalled"
    assert ending_of(None, all_decided=True, consensus=True) == "consensus"  # from a recording
    assert ending_of(None, all_decided=False, consensus=False) is None  # not known
    assert set(ENDINGS) == {
        "consensus",
        "split",
        "stalled",
        "timeout",
        "world_stopped",
        "interrupted",
        "crashed",
    }


# --- the in-process engine ------------------------------------------------------------


def _world(seed: int, robots: int, sites: int = 3) -> WorldConfig:
    return WorldConfig(run="memory", seed=seed, num_sites=sites, num_robots=robots)


@pytest.mark.timeout(120)
def test_an_in_process_run_that_stalls_ends_stalled_with_its_stuck_robot() -> None:
    """The beacon is silent all run: the lone robot comes home and waits at the nest."""
    silent = BeaconConfig(outages=((0.0, 1e6),))
    summary = run_in_process(
        _world(0, robots=1), ControllerConfig(), silent, timeout=1800, stall_window=20.0
    )
    assert summary["ended"] == "stalled" and not summary["timed_out"]
    assert not summary["consensus"]
    (stuck,) = summary["stuck"]
    assert stuck["id"] == 0 and stuck["phase"] == "waiting" and stuck["trips"] == 0
    assert summary["sim_time_s"] - stuck["last_progress_s"] == pytest.approx(20.0, abs=0.11)
    assert summary["sim_time_s"] < 200.0  # not ticking on to the timeout


@pytest.mark.timeout(120)
def test_in_process_endings_consensus_split_and_timeout() -> None:
    agreed = run_in_process(_world(1, robots=4), ControllerConfig(threshold=0.5), timeout=600)
    assert agreed["ended"] == "consensus" and "stuck" not in agreed
    # Deciding at 0.5 with three sites: one comparison each, and the robots disagree.
    split = run_in_process(_world(2, robots=4), ControllerConfig(threshold=0.5), timeout=600)
    assert split["ended"] == "split" and split["stuck"] == []
    assert not split["consensus"] and not split["timed_out"]
    assert len({robot["decided_site"] for robot in split["per_robot"]}) == 2
    short = run_in_process(_world(0, robots=4), ControllerConfig(), timeout=5.0)
    assert short["ended"] == "timeout" and short["timeout_kind"] == "sim"
    assert short["timed_out"] and [entry["id"] for entry in short["stuck"]] == [0, 1, 2, 3]
