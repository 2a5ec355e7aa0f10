"""A swarm over several hosts, on loopback: the hand-started layout of deploy/README.md ends
by itself (every process exits with the run's code, the recording is complete, swarm follow
prints the summary), a forged ending changes nothing, and ``swarm run --dask`` on a local
Dask cluster of two workers reaches the digest of ``swarm run``, twice, leaves nothing
behind, and ends crashed, naming the host, when a worker is killed mid-run.
tests/test_multihost.py does the same across network namespaces."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import hosts_helpers as hosts
import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    processes_of,
    reference_run,
    stop_processes,
    swarm_command,
    unique_run_id,
)

from bestofn_swarm.plumbing.tcp import free_port

pytestmark = pytest.mark.timeout(240)

SEED, ROBOTS, SITES = 3, 4, 5  # about 110 s of sim time: a second or two of wall time
SHAPE = ["--seed", str(SEED), "--robots", str(ROBOTS), "--sites", str(SITES)]


def test_a_hand_started_run_ends_by_itself_with_a_complete_recording(tmp_path: Path) -> None:
    run = hosts.HandRun(unique_run_id("byhand"), SEED, ROBOTS, SITES, tmp_path / "keys")
    run.write_keys(per_process=2)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    recording = tmp_path / "run.mcap"
    log = (tmp_path / "processes.log").open("wb")
    started: list[subprocess.Popen[bytes]] = []

    def start(command: list[str], stdout: int | None = None) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(command, cwd=REPO, stdout=stdout or log, stderr=log)
        started.append(process)
        return process

    try:
        start(hosts.router(endpoint))
        world = start(run.world(endpoint))
        recorder = start(run.recorder(endpoint, recording))
        following = start(run.follow(endpoint), stdout=subprocess.PIPE)
        time.sleep(1.0)  # the recorder subscribes before the robots can start the run
        forger = start(run.forger(endpoint), stdout=subprocess.PIPE)
        swarm = [
            world,
            recorder,
            start(run.beacon(endpoint)),
            start(run.robot_host(0, 1, endpoint)),
            start(run.robot_host(2, 3, endpoint)),
        ]
        codes = hosts.wait_all([*swarm, following], timeout=120)
        output = following.communicate(timeout=10)[0].decode()
        forged = forger.communicate(timeout=30)[0].decode()
    finally:
        stop_processes(started)
        log.close()
        left = kill_leftovers(run.run_id)
    text = (tmp_path / "processes.log").read_text(errors="replace")
    # Every process ended by itself with the run's code: none believed the forged ending
    # (code 4, stalled), sent once the world ticked.
    assert "forged" in forged, text[-3000:]
    assert codes == [0] * 6, f"{codes}\n{text[-3000:]}"
    assert left == [], text[-3000:]
    assert "refused an ending" in text
    summary = json.loads(output)
    assert summary["ended"] == "consensus"
    assert summary["digest"] == reference_run(SHAPE)["digest"]
    # The recording is complete and closed: swarm report reads it to the end.
    report = subprocess.run(
        swarm_command("report", str(recording), "--out", str(tmp_path / "report")),
        cwd=REPO,
        capture_output=True,
        timeout=120,
    )
    assert report.returncode == 0, report.stderr.decode()[-2000:]
    (row,) = json.loads((tmp_path / "report" / "summary.json").read_text())["runs"]
    assert row["digest"] == summary["digest"] and row["ended"] == "consensus"


# --- swarm run --dask on a local cluster --------------------------------------------------


class Cluster:
    """A Dask scheduler with two workers and a Zenoh router, all on loopback."""

    def __init__(self, log: Path) -> None:
        pytest.importorskip(
            "distributed", reason="Dask is an optional extra: pip install '.[dask]'"
        )
        self.router = f"tcp/127.0.0.1:{free_port()}"
        self.scheduler = f"tcp://127.0.0.1:{free_port()}"
        self.log = log.open("wb")
        self.processes: list[subprocess.Popen[bytes]] = []
        port = int(self.scheduler.rsplit(":", 1)[1])
        self.start(hosts.router(self.router))
        self.start(hosts.scheduler("127.0.0.1", port))
        self.start(hosts.worker(self.scheduler, "127.0.0.1", 1, self.router, name="w1"))
        # The other worker reads its host's router from the environment.
        self.start(
            hosts.worker(self.scheduler, "127.0.0.1", 1, name="w2"),
            env={**os.environ, "BESTOFN_ROUTER": self.router},
        )
        hosts.wait_for_workers(self.scheduler, 2)

    def start(
        self, command: list[str], env: dict[str, str] | None = None
    ) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(command, cwd=REPO, stdout=self.log, stderr=self.log, env=env)
        self.processes.append(process)
        return process

    def run(self, run_id: str, *options: str, timeout: float = 150) -> subprocess.Popen[bytes]:
        command = swarm_command(
            "run", "--run-id", run_id, "--json", "--quiet", "--no-record", "--dask",
            self.scheduler, "--connect", self.router, *options,
        )  # fmt: skip
        return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def close(self) -> None:
        stop_processes(self.processes)
        self.log.close()


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    made = Cluster(tmp_path_factory.mktemp("dask") / "cluster.log")
    try:
        yield made
    finally:
        made.close()


def test_swarm_run_on_dask_reaches_the_digest_of_swarm_run_twice(cluster: Cluster) -> None:
    expected = reference_run(SHAPE)["digest"]
    # A second run on the same cluster works as the first, with the world on a worker.
    for attempt, world in enumerate([[], ["--dask-world", "w2"]]):
        run_id = unique_run_id(f"dask{attempt}")
        launcher = cluster.run(run_id, *SHAPE, *world)
        try:
            stdout, stderr = launcher.communicate(timeout=150)
        finally:
            if launcher.poll() is None:
                launcher.kill()
            time.sleep(0.5)
            left = kill_leftovers(run_id)
        assert launcher.returncode == 0, stderr.decode()[-3000:]
        summary = json.loads(stdout)
        assert summary["digest"] == expected and summary["ended"] == "consensus"
        assert summary["robot_processes"] == 2 and summary["config"]["dask"] == cluster.scheduler
        assert "on worker tcp://127.0.0.1:" in stderr.decode()
        if world:
            assert "the world server and the beacon on worker" in stderr.decode()
            assert summary["config"]["dask_world"] == "w2"
        assert left == [], f"left behind: {left}"


def test_a_worker_killed_mid_run_ends_it_crashed_naming_its_host(cluster: Cluster) -> None:
    # A third worker for this test alone, and a run slow enough to be caught mid-run.
    extra = cluster.start(hosts.worker(cluster.scheduler, "127.0.0.1", 2, cluster.router))
    hosts.wait_for_workers(cluster.scheduler, 3)
    run_id = unique_run_id("dasklost")
    launcher = cluster.run(run_id, *SHAPE, "--robots", "6", "--clock", "realtime", "--speed", "2")
    try:
        deadline = time.monotonic() + 90
        victims: list[int] = []
        while time.monotonic() < deadline and not victims:
            victims = [pid for pid in processes_of(run_id) if _parent(pid) == extra.pid]
            time.sleep(0.2)
        assert victims, "the third worker hosted no robot process"
        time.sleep(2.0)  # the run is under way
        extra.send_signal(signal.SIGKILL)
        stdout, stderr = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
        time.sleep(0.5)
        left = kill_leftovers(run_id)
    said = stderr.decode()
    assert launcher.returncode == 1, said[-3000:]
    summary = json.loads(stdout)
    assert summary["ended"] == "crashed"
    (lost,) = summary["lost_hosts"]
    assert lost["host"] == "127.0.0.1" and lost["robots"]
    assert f"lost worker {lost['worker']} on host 127.0.0.1" in said
    assert left == [], f"left behind: {left}"


def _parent(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        return -1
