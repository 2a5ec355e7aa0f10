"""One robot builder, seeded from the world (robot_agent/core/builder.py): a robot started by
hand without ``--seed`` draws from its world's seed, so it makes the run ``swarm run`` makes;
a ``--seed`` that is not the world's is refused, robot and beacon alike."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from swarm_helpers import REPO, run_swarm, stop_processes, unique_run_id

from bestofn_swarm.plumbing.tcp import free_port
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import builder
from robot_agent.core.controller import Controller, ControllerConfig
from world_server.core.world import World, WorldConfig

pytestmark = pytest.mark.timeout(180)

SEED, SITES, ROBOTS = 7, 3, 3

# Follows the run's statuses until every robot decided; prints each robot's result.
OBSERVER = """
import json, sys, time
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.plumbing.zenoh_session import open_session
keys = keyspace.Keys(sys.argv[2])
statuses = {}
session = open_session("client", [sys.argv[1]])
session.declare_subscriber(
    keys.of(keyspace.STATUS, "*"),
    lambda s: statuses.__setitem__(
        keys.robot_of(keyspace.STATUS, str(s.key_expr)),
        protocol.decode(s.payload.to_bytes(), protocol.Status),
    ),
)
deadline = time.monotonic() + float(sys.argv[4])
while time.monotonic() < deadline:
    if len(statuses) == int(sys.argv[3]) and all(
        status.decided_site is not None for status in statuses.values()
    ):
        break
    time.sleep(0.05)
print(json.dumps({
    robot: [status.decided_site, status.decision_time, status.decision_trips]
    for robot, status in statuses.items()
}), flush=True)
session.close()
"""


def test_a_robot_draws_from_its_worlds_seed() -> None:
    world = World(WorldConfig(run="b", seed=SEED, num_sites=SITES, num_robots=ROBOTS))
    made = builder.build_controller(1, world.info, ControllerConfig())
    assert isinstance(made, Controller)
    # It draws from the world's seed's stream for robot 1: as one built on that stream.
    reference = Controller(1, world.info, ControllerConfig(), Stream.named(SEED, "robot", 1))
    assert [made._rng.next_u64() for _ in range(3)] == [reference._rng.next_u64() for _ in range(3)]
    assert builder.run_seed(world.info) == builder.run_seed(world.info, SEED) == SEED
    with pytest.raises(builder.SeedMismatchError, match="--seed 8 is not the seed"):
        builder.run_seed(world.info, 8)


def test_robot_agent_without_seed_makes_the_run_swarm_run_makes(tmp_path: Path) -> None:
    run_id = unique_run_id("builder")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    logs = (tmp_path / "processes.log").open("wb")
    started: list[subprocess.Popen[bytes]] = []

    def start(*command: str, stdout: int | None = None) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(
            [sys.executable, *command], cwd=REPO, stdout=stdout or logs, stderr=logs
        )
        started.append(process)
        return process

    try:
        # The world alone is told the seed; the beacon and the robots take it from its map.
        start(
            "-m", "world_server.server", "--run-id", run_id, "--seed", str(SEED),
            "--robots", str(ROBOTS), "--sites", str(SITES), "--listen", endpoint,
        )  # fmt: skip
        common = ["--run-id", run_id, "--connect", endpoint, "--mode", "client"]
        start("-m", "nest_beacon", *common)
        ids = [arg for robot in range(ROBOTS) for arg in ("--id", str(robot))]
        start("-m", "robot_agent.node", *ids, *common)
        observer = start(
            "-c", OBSERVER, endpoint, run_id, str(ROBOTS), "150", stdout=subprocess.PIPE
        )
        output, _ = observer.communicate(timeout=170)
    finally:
        stop_processes(started)
        logs.close()
    by_hand = {
        robot: [site, round(t, 3), trips]  # the summary gives times to the millisecond
        for robot, (site, t, trips) in json.loads(output.decode().strip().splitlines()[-1]).items()
    }
    code, summary, stderr = run_swarm(
        ["--seed", str(SEED), "--robots", str(ROBOTS), "--sites", str(SITES)],
        unique_run_id("builder-ref"),
    )
    assert code == 0, stderr
    expected = {
        str(robot["id"]): [robot["decided_site"], robot["decision_time_s"], robot["steps"]]
        for robot in summary["per_robot"]
    }
    log_text = (tmp_path / "processes.log").read_text(errors="replace")[-2000:]
    assert by_hand == expected, log_text


@pytest.mark.parametrize("program", ["robot_agent.node", "nest_beacon"])
def test_a_seed_that_is_not_the_worlds_is_refused(program: str) -> None:
    run_id = unique_run_id("builder-seed")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    world = subprocess.Popen(
        [sys.executable, "-m", "world_server.server", "--run-id", run_id, "--seed", str(SEED),
         "--robots", "1", "--sites", str(SITES), "--listen", endpoint],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        ids = ["--id", "0"] if program == "robot_agent.node" else []
        deadline = time.monotonic() + 60
        refused = subprocess.run(
            [sys.executable, "-m", program, *ids, "--run-id", run_id, "--seed", str(SEED + 1),
             "--connect", endpoint, "--mode", "client"],
            cwd=REPO, capture_output=True, text=True, timeout=deadline - time.monotonic(),
        )  # fmt: skip
    finally:
        stop_processes([world])
    assert refused.returncode == 2, refused.stderr
    assert f"--seed {SEED + 1} is not the seed of the world" in refused.stderr
    errors = [line for line in refused.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1 and "Traceback" not in refused.stderr, refused.stderr
