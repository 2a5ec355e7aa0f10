"""Faults of robots as plug-ins of both engines (robot_agent/core/faults.py): kills and
restarts in one process, at a tick, the same run every time; a motor failure, declared by
one switch, the same run in one process and over Zenoh."""

from __future__ import annotations

import pytest
from swarm_helpers import run_swarm, unique_run_id

from robot_agent.core import builder, faults, ports
from robot_agent.core.controller import ControllerConfig
from world_server.core.world import World, WorldConfig

pytestmark = pytest.mark.timeout(240)

MOTOR = ["--robots", "4", "--sites", "4", "--seed", "5", "--timeout", "150"]


def _reading(t: float) -> ports.BodyReading:
    return ports.BodyReading(t=t, x=0.0, y=0.0, theta=0.0, proximity=(0.0,) * 8, frame=None)


def test_a_motor_failure_stops_the_wheels_from_its_time_and_leaves_the_rest() -> None:
    world = World(WorldConfig(run="m", seed=1, num_sites=3, num_robots=2))
    failing = builder.build_controller(
        0, world.info, ControllerConfig(), robot_faults=[faults.MotorFailure(0, 0.3)]
    )
    honest = builder.build_controller(0, world.info, ControllerConfig())  # the same draws
    assert isinstance(failing, faults.StoppedMotors)
    for tick in range(8):
        t = tick * 0.1
        made, meant = failing.step(_reading(t), []), honest.step(_reading(t), [])
        if t < 0.3:
            assert made == meant
        else:
            assert (made.left, made.right) == (0.0, 0.0)
            assert (made.capture, made.broadcasts) == (meant.capture, meant.broadcasts)
    # Another robot's fault leaves this one alone.
    other = builder.build_controller(
        1, world.info, ControllerConfig(), robot_faults=[faults.MotorFailure(0, 0.3)]
    )
    assert not isinstance(other, faults.StoppedMotors)


def test_kill_and_restart_in_one_process_make_the_same_run_every_time() -> None:
    options = ["--engine", "inprocess", "--kill", "3@60", "--restart", "3@120", "--seed", "2"]
    runs = [run_swarm(options, unique_run_id("faults")) for _ in range(2)]
    for code, _, stderr in runs:
        assert code == 0, stderr
    (_, first, _), (_, second, _) = runs
    assert first["digest"] == second["digest"]
    robot = first["per_robot"][3]
    assert (robot["restarts"], robot["killed"], robot["decided_site"]) == (
        1,
        False,
        first["best_site"],
    )
    assert [(fault["action"], fault["applied_at_s"]) for fault in first["faults"]] == [
        ("kill", 60.0),
        ("restart", 120.0),
    ]
    assert first["world"]["departures"] == 1  # the world saw robot 3 go, once


def test_a_motor_failure_is_the_same_run_in_one_process_and_over_zenoh() -> None:
    summaries = []
    for engine in ("inprocess", "zenoh"):
        code, summary, stderr = run_swarm(
            [*MOTOR, "--engine", engine, "--motor-failure", "1@20"], unique_run_id("motor")
        )
        assert summary is not None and code == 5, stderr  # it runs out of time
        summaries.append(summary)
    inprocess, zenoh = summaries
    assert inprocess["digest"] == zenoh["digest"]
    assert inprocess["faults"] == zenoh["faults"] == [
        {"robot": 1, "action": "motor-failure", "at_s": 20.0, "applied_at_s": 20.0,
         "was_running": True},
    ]  # fmt: skip
    # Robot 1 cannot reach a site after its wheels stopped; the others go on.
    assert inprocess["per_robot"][1]["decided_site"] is None
    assert inprocess["ended"] != "consensus"


def test_a_radio_failure_is_one_plug_in_and_one_switch_the_same_in_both_engines() -> None:
    """A fault added as architecture.md says (robot_agent/core/faults.py, its switch in
    deploy/launcher/switches.py): both engines apply it, the same run."""
    summaries = []
    for engine in ("inprocess", "zenoh"):
        _, summary, stderr = run_swarm(
            [*MOTOR, "--engine", engine, "--radio-failure", "2@5"], unique_run_id("radio")
        )
        assert summary is not None, stderr
        summaries.append(summary)
    inprocess, zenoh = summaries
    assert inprocess["digest"] == zenoh["digest"]
    assert [fault["action"] for fault in inprocess["faults"]] == ["radio-failure"]
    # It changed the run: without it the same seed makes another one.
    _, clean, stderr = run_swarm([*MOTOR, "--engine", "inprocess"], unique_run_id("clean"))
    assert clean is not None, stderr
    assert clean["digest"] != inprocess["digest"]
