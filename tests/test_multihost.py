"""A swarm across three hosts: network namespaces joined by veth pairs on a bridge.

Host 0 runs a Zenoh router, the world server and the nest beacon; hosts 1 and 2 each
run a router (connected to host 0's) and a robot host process with two robots. Every
process is a client of its own host's router, as on real machines. Robots that run a
plug-in (the example plug-in, examples/linear_pool, installed) on both hosts make the run
the in-process engine makes with it.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from netns import Lan, namespaces
from swarm_helpers import REPO, reference_run, stop_processes

from world_server.core.layout import make_layout
from world_server.observer.summary import DIGEST_FIELDS

pytestmark = pytest.mark.timeout(180)

SUBNET = "10.78.0"  # only ever inside the namespaces this test creates
PORT = 7447
RUN, SEED, SITES, ROBOTS = "multihost", 3, 5, 4

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
    time.sleep(0.1)
print(json.dumps({robot: status.decided_site for robot, status in statuses.items()}), flush=True)
session.close()  # an open session can hold up the interpreter's exit
"""


@pytest.fixture(scope="module")
def hosts() -> Iterator[Lan]:
    with namespaces("bmh", 3, SUBNET) as network:
        yield network


def test_routers_per_host_carry_a_swarm_to_the_right_consensus(hosts: Lan, tmp_path: Path) -> None:
    started: list[subprocess.Popen[bytes]] = []
    logs = (tmp_path / "processes.log").open("wb")

    def on(host: int, *command: str) -> subprocess.Popen[bytes]:
        # Logs go to a file: a pipe nobody reads would block a chatty process.
        process = subprocess.Popen(
            hosts.run(host, sys.executable, *command), cwd=REPO, stdout=logs, stderr=logs
        )
        started.append(process)
        return process

    def endpoint(host: int) -> str:
        return f"tcp/{hosts.address(host)}:{PORT}"

    common = ["--run-id", RUN, "--seed", str(SEED), "--mode", "client"]
    try:
        on(0, "-m", "deploy.launcher.router", "--listen", endpoint(0))
        for host in (1, 2):
            on(
                host,
                "-m",
                "deploy.launcher.router",
                "--listen",
                endpoint(host),
                "--connect",
                endpoint(0),
            )
        on(
            0,
            "-m",
            "world_server.server",
            *common,
            "--connect",
            endpoint(0),
            "--robots",
            str(ROBOTS),
            "--sites",
            str(SITES),
        )
        on(0, "-m", "nest_beacon", *common, "--connect", endpoint(0))
        for host, robots in ((1, (0, 1)), (2, (2, 3))):
            ids = [arg for robot in robots for arg in ("--id", str(robot))]
            on(host, "-m", "robot_agent.node", *ids, *common, "--connect", endpoint(host))
        observer = subprocess.Popen(
            hosts.run(2, sys.executable, "-c", OBSERVER, endpoint(2), RUN, str(ROBOTS), "120"),
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=logs,
        )
        started.append(observer)
        output, _ = observer.communicate(timeout=170)
        crashed = [p.args for p in started if p is not observer and p.poll() is not None]
    finally:
        stop_processes(started)
        logs.close()
    log_text = (tmp_path / "processes.log").read_text(errors="replace")[-3000:]
    assert not crashed, f"processes exited early: {crashed}\n{log_text}"
    decisions = json.loads(output.decode().strip().splitlines()[-1])
    best = make_layout(SITES, ROBOTS, SEED).best_site
    assert decisions == {str(robot): best for robot in range(ROBOTS)}, log_text


# Each robot's results as swarm run's summary has them (its statuses, in order, since before
# the world's first tick), and their digest; printed once every robot has decided.
RESULTS = """
import json, sys, threading, time
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.plumbing.zenoh_session import open_session
from world_server.observer.summary import RobotRecord, robot_summary, run_digest
keys = keyspace.Keys(sys.argv[2])
robots = int(sys.argv[3])
records = {robot: RobotRecord(robot) for robot in range(robots)}
lock = threading.Lock()
def heard(sample):
    robot = keys.robot_of(keyspace.STATUS, str(sample.key_expr))
    with lock:
        records[robot].update(protocol.decode(sample.payload.to_bytes(), protocol.Status))
session = open_session("client", [sys.argv[1]])
session.declare_subscriber(keys.of(keyspace.STATUS, "*"), heard)
print("listening", flush=True)
deadline = time.monotonic() + float(sys.argv[4])
while time.monotonic() < deadline:
    with lock:
        if all(record.decided_site is not None for record in records.values()):
            break
    time.sleep(0.1)
time.sleep(0.5)
with lock:
    per_robot = [robot_summary(records[robot]) for robot in range(robots)]
print(json.dumps({"digest": run_digest(per_robot), "per_robot": per_robot}), flush=True)
session.close()
"""


@pytest.mark.skipif(
    importlib.util.find_spec("bestofn_linear_pool") is None,
    reason="the example plug-in is not installed: pip install -e examples/linear_pool",
)
def test_a_plugin_on_two_hosts_makes_the_run_it_makes_in_one_process(
    hosts: Lan, tmp_path: Path
) -> None:
    started: list[subprocess.Popen[bytes]] = []
    logs = (tmp_path / "processes.log").open("wb")
    run = "multihost-plugin"

    def on(host: int, *command: str) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(
            hosts.run(host, sys.executable, *command), cwd=REPO, stdout=logs, stderr=logs
        )
        started.append(process)
        return process

    def endpoint(host: int) -> str:
        return f"tcp/{hosts.address(host)}:{PORT}"

    common = ["--run-id", run, "--seed", str(SEED), "--mode", "client"]
    try:
        on(0, "-m", "deploy.launcher.router", "--listen", endpoint(0))
        for host in (1, 2):
            on(host, "-m", "deploy.launcher.router", "--listen", endpoint(host),
               "--connect", endpoint(0))  # fmt: skip
        observer = subprocess.Popen(
            hosts.run(2, sys.executable, "-c", RESULTS, endpoint(2), run, str(ROBOTS), "150"),
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=logs,
        )
        started.append(observer)
        assert observer.stdout is not None
        assert observer.stdout.readline().decode().strip() == "listening"
        on(0, "-m", "world_server.server", *common, "--connect", endpoint(0),
           "--robots", str(ROBOTS), "--sites", str(SITES))  # fmt: skip
        on(0, "-m", "nest_beacon", *common, "--connect", endpoint(0))
        for host, robots in ((1, (0, 1)), (2, (2, 3))):
            ids = [arg for robot in robots for arg in ("--id", str(robot))]
            on(host, "-m", "robot_agent.node", *ids, *common, "--connect", endpoint(host),
               "--pooling", "linear")  # fmt: skip
        output, _ = observer.communicate(timeout=170)
        crashed = [p.args for p in started if p is not observer and p.poll() is not None]
    finally:
        stop_processes(started)
        logs.close()
    log_text = (tmp_path / "processes.log").read_text(errors="replace")[-3000:]
    assert not crashed, f"processes exited early: {crashed}\n{log_text}"
    found = json.loads(output.decode().strip().splitlines()[-1])
    alone = reference_run(
        ["--robots", str(ROBOTS), "--sites", str(SITES), "--seed", str(SEED), "--pooling", "linear"]
    )
    assert alone["ended"] == "consensus"

    def results(per_robot: list[dict[str, object]]) -> list[dict[str, object]]:
        return [{name: robot[name] for name in DIGEST_FIELDS} for robot in per_robot]

    assert results(found["per_robot"]) == results(alone["per_robot"]), log_text
    assert found["digest"] == alone["digest"]
