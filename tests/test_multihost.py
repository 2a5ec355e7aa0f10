"""A swarm across three hosts: network namespaces joined by veth pairs on a bridge, each
host with its own Zenoh router (the routers of hosts 1 and 2 connected to host 0's), every
process a client of its own host's router, as on real machines.

* By hand, as deploy/README.md says: the world server and the beacon on host 0, a robot
  host process of two robots on each of hosts 1 and 2, a recorder on host 2. The run ends
  by itself: every process exits with the run's exit code, and the recording is complete
  (``swarm report`` reads it to the end).
* ``swarm run --dask`` from host 0, with the Dask scheduler on host 0 and a worker on each
  of hosts 1 (given its router with ``--router``) and 2 (reading ``$BESTOFN_ROUTER``): a
  worker killed mid-run ends the run crashed, naming its host, and leaves no process of the
  run on any host; a second run on the same cluster gives the digest of ``swarm run`` on one
  machine.
* Robots that run a plug-in (the example plug-in, examples/linear_pool, installed) on two
  hosts make the run the in-process engine makes with it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import hosts_helpers as hosts
import pytest
from netns import Lan, namespaces
from swarm_helpers import (
    REPO,
    kill_leftovers,
    processes_of,
    reference_run,
    run_swarm,
    stop_processes,
    swarm_command,
    unique_run_id,
)

from world_server.observer.summary import DIGEST_FIELDS

pytestmark = pytest.mark.timeout(240)

SUBNET = "10.78.0"  # only ever inside the namespaces this test creates
PORT, SCHEDULER_PORT = 7447, 8786
SEED, SITES, ROBOTS = 3, 5, 4
SHAPE = ["--seed", str(SEED), "--robots", str(ROBOTS), "--sites", str(SITES)]


class Hosts:
    """Three hosts, each with its own router; what runs on them, and its log."""

    def __init__(self, lan: Lan, log: Path) -> None:
        self.lan = lan
        self.log = log.open("wb")
        self.started: list[subprocess.Popen[bytes]] = []
        self.on(0, *hosts.router(self.endpoint(0))[1:])
        for host in (1, 2):
            self.on(host, *hosts.router(self.endpoint(host), self.endpoint(0))[1:])

    def endpoint(self, host: int) -> str:
        return f"tcp/{self.lan.address(host)}:{PORT}"

    def on(
        self, host: int, *command: str, stdout: int | None = None, env: dict[str, str] | None = None
    ) -> subprocess.Popen[bytes]:
        """``python COMMAND`` on ``host`` (logs to a file: a pipe nobody reads would block)."""
        process = subprocess.Popen(
            self.lan.run(host, sys.executable, *command),
            cwd=REPO,
            stdout=stdout or self.log,
            stderr=self.log,
            env=env,
        )
        self.started.append(process)
        return process

    def close(self) -> None:
        stop_processes(self.started)
        self.log.close()


@pytest.fixture(scope="module")
def lan(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hosts]:
    with namespaces("bmh", 3, SUBNET) as network:
        made = Hosts(network, tmp_path_factory.mktemp("hosts") / "processes.log")
        try:
            yield made
        finally:
            made.close()


def _tail(lan: Hosts) -> str:
    lan.log.flush()
    return Path(lan.log.name).read_text(errors="replace")[-3000:]


def test_the_hand_started_layout_ends_by_itself_with_a_complete_recording(
    lan: Hosts, tmp_path: Path
) -> None:
    run = hosts.HandRun(unique_run_id("hand"), SEED, ROBOTS, SITES, tmp_path / "keys")
    run.write_keys(per_process=2)
    recording = tmp_path / "run.mcap"

    def program(host: int, command: list[str]) -> subprocess.Popen[bytes]:
        return lan.on(host, *command[1:])  # command[0] is the interpreter

    recorder = program(2, run.recorder(lan.endpoint(2), recording))
    time.sleep(1.0)  # it subscribes before the robots can start the run
    swarm = [
        program(0, run.world(lan.endpoint(0))),
        program(0, run.beacon(lan.endpoint(0))),
        program(1, run.robot_host(0, 1, lan.endpoint(1))),
        program(2, run.robot_host(2, 3, lan.endpoint(2))),
        recorder,
    ]
    codes = hosts.wait_all(swarm, timeout=150)
    left = kill_leftovers(run.run_id)
    assert codes == [0] * len(swarm), f"{codes}\n{_tail(lan)}"
    assert left == []
    report = subprocess.run(
        swarm_command("report", str(recording), "--out", str(tmp_path / "report")),
        cwd=REPO,
        capture_output=True,
        timeout=120,
    )
    assert report.returncode == 0, report.stderr.decode()[-2000:]
    (row,) = json.loads((tmp_path / "report" / "summary.json").read_text())["runs"]
    assert row["ended"] == "consensus" and row["correct"]


class Cluster:
    """A Dask scheduler on host 0 and a worker on each of hosts 1 and 2."""

    def __init__(self, lan: Hosts) -> None:
        self.lan = lan
        self.scheduler = f"tcp://{lan.lan.address(0)}:{SCHEDULER_PORT}"
        lan.on(0, *hosts.scheduler(lan.lan.address(0), SCHEDULER_PORT)[1:])
        self.workers = {host: _worker(lan, self.scheduler, host) for host in (1, 2)}
        _wait_for_workers(lan, self.scheduler, 2)


@pytest.mark.skipif(
    importlib.util.find_spec("bestofn_linear_pool") is None,
    reason="the example plug-in is not installed: pip install -e examples/linear_pool",
)
def test_a_plugin_on_two_hosts_makes_the_run_it_makes_in_one_process(
    lan: Hosts, tmp_path: Path
) -> None:
    run = hosts.HandRun(unique_run_id("plugin"), SEED, ROBOTS, SITES, tmp_path / "keys")
    run.write_keys(per_process=2)
    plugin = ["--pooling", "linear"]
    following = lan.on(2, *run.follow(lan.endpoint(2))[1:], stdout=subprocess.PIPE)
    swarm = [
        lan.on(0, *run.world(lan.endpoint(0))[1:]),
        lan.on(0, *run.beacon(lan.endpoint(0))[1:]),
        lan.on(1, *run.robot_host(0, 1, lan.endpoint(1))[1:], *plugin),
        lan.on(2, *run.robot_host(2, 3, lan.endpoint(2))[1:], *plugin),
    ]
    codes = hosts.wait_all([*swarm, following], timeout=150)
    output = following.communicate(timeout=10)[0].decode()
    kill_leftovers(run.run_id)
    assert codes == [0] * 5, f"{codes}\n{_tail(lan)}"
    found = json.loads(output)
    alone = reference_run([*run.shape, *plugin])
    assert alone["ended"] == "consensus"

    def results(per_robot: list[dict[str, object]]) -> list[dict[str, object]]:
        return [{name: robot[name] for name in DIGEST_FIELDS} for robot in per_robot]

    assert results(found["per_robot"]) == results(alone["per_robot"]), _tail(lan)
    assert found["digest"] == alone["digest"]


@pytest.fixture(scope="module")
def cluster(lan: Hosts) -> Cluster:
    pytest.importorskip("distributed", reason="Dask is an optional extra: '.[dask]'")
    return Cluster(lan)


def _worker(lan: Hosts, scheduler: str, host: int) -> subprocess.Popen[bytes]:
    """Host 1's worker is told its router; host 2's reads it from its host's environment."""
    address = lan.lan.address(host)
    if host == 1:
        return lan.on(host, *hosts.worker(scheduler, address, 2, lan.endpoint(host))[1:])
    env = {**os.environ, "BESTOFN_ROUTER": lan.endpoint(host)}
    return lan.on(host, *hosts.worker(scheduler, address, 2)[1:], env=env)


def _wait_for_workers(lan: Hosts, scheduler: str, count: int) -> None:
    probe = (
        "import sys\n"
        "from distributed import Client\n"
        "with Client(sys.argv[1], timeout=30) as client:\n"
        "    client.wait_for_workers(int(sys.argv[2]), timeout=60)\n"
    )
    assert lan.on(0, "-c", probe, scheduler, str(count)).wait(timeout=90) == 0, _tail(lan)


def _swarm_run_on(
    lan: Hosts, scheduler: str, run_id: str, *options: str
) -> subprocess.Popen[bytes]:
    """``swarm run --dask`` on host 0, the world a client of host 0's router."""
    return lan.on(
        0,
        *swarm_command("run", "--run-id", run_id, "--json", "--quiet", "--no-record")[1:],
        "--dask",
        scheduler,
        "--connect",
        lan.endpoint(0),
        *options,
        stdout=subprocess.PIPE,
    )


def test_a_killed_worker_ends_the_run_naming_its_host_then_the_cluster_runs_again(
    lan: Hosts, cluster: Cluster
) -> None:
    # The run on the real-time clock, slow enough to lose a worker while it goes.
    run_id = unique_run_id("lost")
    scheduler = cluster.scheduler
    launcher = _swarm_run_on(lan, scheduler, run_id, *SHAPE, "--clock", "realtime", "--speed", "2")
    host_2 = lan.lan.address(2)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and len(processes_of(run_id)) < 7:
            time.sleep(0.2)  # the launcher, the world, the beacon, four robot processes
        time.sleep(2.0)
        # Host 2's worker dies (``ip netns exec`` became the worker's interpreter).
        cluster.workers[2].send_signal(signal.SIGKILL)
        stdout, _ = launcher.communicate(timeout=150)
    finally:
        if launcher.poll() is None:
            launcher.kill()
        time.sleep(1.0)
        left = kill_leftovers(run_id)
    assert launcher.returncode == 1, _tail(lan)
    summary = json.loads(stdout)
    (lost,) = summary["lost_hosts"]
    assert summary["ended"] == "crashed" and lost["host"] == host_2
    assert f"on host {host_2}" in _tail(lan)
    assert left == [], f"processes of the run left behind: {left}"

    # The same cluster, with host 2's worker back, runs the swarm run of one machine.
    cluster.workers[2] = _worker(lan, scheduler, 2)
    _wait_for_workers(lan, scheduler, 2)
    run_id = unique_run_id("again")
    launcher = _swarm_run_on(lan, scheduler, run_id, *SHAPE)
    try:
        stdout, _ = launcher.communicate(timeout=150)
    finally:
        if launcher.poll() is None:
            launcher.kill()
        time.sleep(0.5)
        left = kill_leftovers(run_id)
    assert launcher.returncode == 0, _tail(lan)
    summary = json.loads(stdout)
    assert summary["robot_processes"] == 4 and "lost_hosts" not in summary
    code, here, stderr = run_swarm([*SHAPE, "--no-record"], unique_run_id("here"))
    assert code == 0, stderr
    assert summary["digest"] == here["digest"] and summary["ended"] == "consensus"
    assert left == [], f"processes of the run left behind: {left}"
