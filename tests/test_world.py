"""The world and the swarm in one process (no Zenoh): correctness and determinism."""

from __future__ import annotations

from typing import Any

import pytest

from deploy.inprocess.engine import run_in_process
from robot_agent.core.controller import ControllerConfig
from world_server.core.radio import RadioConfig
from world_server.core.world import World, WorldConfig

pytestmark = pytest.mark.timeout(120)


def _config(seed: int, robots: int = 6, sites: int = 8, **radio: Any) -> WorldConfig:
    return WorldConfig(
        run="memory",
        seed=seed,
        num_sites=sites,
        num_robots=robots,
        radio=RadioConfig(**radio),
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_robot_decides_on_the_best_site(seed: int) -> None:
    summary = run_in_process(_config(seed), ControllerConfig(), timeout=1200)
    assert not summary["timed_out"]
    assert summary["correct"], summary["per_robot"]
    for robot in summary["per_robot"]:
        assert robot["decided_site"] == summary["best_site"]
        assert robot["steps"] == len(robot["pool_sizes"])


def test_the_same_seed_gives_the_same_run_and_another_seed_another() -> None:
    first = run_in_process(_config(4), ControllerConfig(), timeout=1200)
    again = run_in_process(_config(4), ControllerConfig(), timeout=1200)
    other = run_in_process(_config(5), ControllerConfig(), timeout=1200)
    assert first == again
    assert first["per_robot"] != other["per_robot"]


def test_a_lossy_radio_slows_nothing_down_into_a_wrong_decision() -> None:
    summary = run_in_process(_config(3, drop=0.3), ControllerConfig(), timeout=1800)
    assert summary["correct"]
    assert summary["radio"]["dropped"] > 0


def test_a_robot_whose_controller_left_stops_and_stays_an_obstacle() -> None:
    world = World(_config(0, robots=2))
    world.join_robot(0)
    world.join_robot(1)
    world.leave_robot(1)
    before = world.physics.pose(1)
    from bestofn_swarm.wire import protocol

    act = protocol.Act(v=1, tick=0, left=0.13, right=0.13, capture=False, radio_tx=0)
    for _ in range(20):
        world.advance({0: act, 1: act}, [])
    assert world.physics.pose(1) == pytest.approx(before, abs=1e-6)
    assert world.live_robots() == [0]
    assert [pose.id for pose in world.state().robots] == [0, 1]
    assert not world.is_sender("1") and world.is_sender("0")
