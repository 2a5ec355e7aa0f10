"""Every chaos switch of `swarm run`, on the real processes; and a world server that dies."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    loopback_router,
    run_swarm,
    stop_processes,
    unique_run_id,
)

from robot_agent import protocol
from world_server.layout import make_layout

pytestmark = pytest.mark.timeout(240)

BASE = ["--robots", "4", "--sites", "5", "--seed", "11", "--timeout", "1500", "--no-record"]


def _dropped(summary: dict[str, Any]) -> bool:
    return summary["radio"]["dropped"] > 0


def _nobody_pools_during_the_outage(summary: dict[str, Any]) -> bool:
    return all(robot["decision_time_s"] > 60.0 for robot in summary["per_robot"])


def _robot_1_was_killed(summary: dict[str, Any]) -> bool:
    robot = summary["per_robot"][1]
    return robot["killed"] and not robot["crashed"] and summary["faults"][0]["action"] == "kill"


def _robot_2_restarted(summary: dict[str, Any]) -> bool:
    robot = summary["per_robot"][2]
    return robot["restarts"] == 1 and robot["decided_site"] == summary["best_site"]


def _always(summary: dict[str, Any]) -> bool:
    return True


SWITCHES: dict[str, tuple[list[str], Callable[[dict[str, Any]], bool]]] = {
    "iid-loss": (["--drop", "0.3"], _dropped),
    "burst-loss": (["--burst-loss", "0.1:0.3"], _dropped),
    "range-loss": (["--range-loss", "0.3:1"], _dropped),
    "latency-jitter": (["--latency", "3", "--jitter", "3"], _always),
    "duplication": (["--duplicate", "0.5"], _always),
    "reordering": (["--reorder", "--jitter", "2"], _always),
    "camera-noise": (["--camera-noise", "8", "--lighting", "0.05"], _always),
    "beacon-outage": (["--beacon-outage", "0:60"], _nobody_pools_during_the_outage),
    "beacon-flaky": (["--beacon-flaky", "0.5"], _always),
    "kill": (["--kill", "1@15"], _robot_1_was_killed),
    "restart": (["--restart", "2@15"], _robot_2_restarted),
}


@pytest.mark.parametrize("switch", list(SWITCHES))
def test_the_swarm_still_decides_right_with(switch: str) -> None:
    options, check = SWITCHES[switch]
    code, summary, stderr = run_swarm([*BASE, *options], unique_run_id(switch))
    assert code == 0, stderr
    assert summary["correct"], summary["per_robot"]
    assert check(summary), summary
    # The switch is on record in the summary's configuration.
    flag = options[0].removeprefix("--").replace("-", "_")
    assert summary["config"][flag] not in (None, 0, 0.0, False, [])


def test_robots_wait_for_a_lost_world_server_and_resume_with_a_new_one() -> None:
    run_id = unique_run_id("world-loss")
    keys = protocol.Keys(run_id)
    common = ["--run-id", run_id, "--seed", "4", "--mode", "client"]
    world_command = [
        sys.executable,
        "-m",
        "world_server.server",
        *common,
        "--robots",
        "3",
        "--sites",
        "4",
    ]
    best = make_layout(4, 3, 4).best_site
    statuses: dict[int, protocol.Status] = {}
    with loopback_router() as (session, endpoint):
        connect = ["--connect", endpoint]
        session.declare_subscriber(
            keys.status("*"),
            lambda sample: statuses.__setitem__(
                int(keys.robot_of(str(sample.key_expr)) or 0),
                protocol.decode(sample.payload.to_bytes(), protocol.Status),
            ),
        )
        started: list[subprocess.Popen[bytes]] = []

        def start(command: list[str]) -> subprocess.Popen[bytes]:
            process = subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE)
            started.append(process)
            return process

        try:
            world = start([*world_command, *connect])
            start([sys.executable, "-m", "nest_beacon", *common, *connect])
            robots = [
                start(
                    [
                        sys.executable,
                        "-m",
                        "robot_agent.node",
                        "--id",
                        str(robot),
                        *common,
                        *connect,
                    ]
                )
                for robot in range(3)
            ]
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not any(
                status.trips >= 1 for status in statuses.values()
            ):
                time.sleep(0.05)
            assert statuses, "the robots never reported"
            os.kill(world.pid, signal.SIGKILL)
            world.wait()
            time.sleep(2.0)
            assert all(robot.poll() is None for robot in robots), "a robot exited"
            start([*world_command, *connect])
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not (
                len(statuses) == 3
                and all(status.decided_site is not None for status in statuses.values())
            ):
                time.sleep(0.1)
            assert all(robot.poll() is None for robot in robots)
        finally:
            stop_processes(started)
            kill_leftovers(run_id)
        errors = b"".join(process.stderr.read() for process in started if process.stderr)
    assert {status.decided_site for status in statuses.values()} == {best}
    assert b"Traceback" not in errors, errors.decode()[-3000:]
    assert b"new world server appeared" in errors
