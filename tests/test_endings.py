"""How a real ``swarm run`` ends: signals as a terminal or timeout(1) send them, SIGKILL,
the stall watchdog, time limits, and bad command lines; nothing may be left running.

The processes of a run are counted by its run id (tests/swarm_helpers.processes_of):
the launcher, the world, the recorder, the beacon, the robot processes and, when robots
are forked, the fork server and multiprocessing's resource tracker.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    processes_of,
    run_swarm,
    swarm_cli,
    swarm_command,
    unique_run_id,
)

from bestofn_swarm.plumbing.tcp import free_port
from deploy.reports import collect

pytestmark = pytest.mark.timeout(180)

# A run that does not end on its own: the beacon is silent all along, so nobody pools,
# and neither the watchdog nor the time limits come near.
ENDLESS = [
    *("--robots", "4", "--sites", "3", "--beacon-outage", "0:1000000"),
    *("--timeout", "1000000", "--stall-window", "1000000"),
]


def _expected_processes(robot_processes: int, *, fork: bool, record: bool) -> int:
    """launcher + world + beacon (+ recorder) (+ fork server + resource tracker) + robots."""
    return 3 + int(record) + 2 * int(fork) + robot_processes


def _start(run_id: str, *args: str) -> subprocess.Popen[bytes]:
    """``swarm run`` as a shell starts a job: in a process group of its own, which a
    terminal's Ctrl-C or hang-up and timeout(1) signal as a whole."""
    return subprocess.Popen(
        swarm_command("run", "--run-id", run_id, "--json", "--quiet", *args),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def _wait_for_count(run_id: str, count: int, timeout: float = 60.0) -> list[int]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pids = processes_of(run_id)
        if len(pids) >= count:
            time.sleep(1.0)  # let the run tick a little
            return processes_of(run_id)
        time.sleep(0.05)
    raise AssertionError(f"fewer than {count} processes of {run_id}: {processes_of(run_id)}")


def _finish(process: subprocess.Popen[bytes], run_id: str) -> tuple[int, Any, str]:
    try:
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    summary = json.loads(stdout) if stdout.strip() else None
    return process.returncode, summary, stderr.decode()


@dataclass(frozen=True)
class StopCase:
    signum: int
    code: int
    options: list[str]
    robot_processes: int
    fork: bool
    record: bool


STOP_CASES = {
    # timeout(1) sends SIGTERM to its whole process group: here, the job's.
    "sigterm-fork": StopCase(
        signal.SIGTERM,
        143,
        ["--record", "{tmp}/run.mcap", "--robots-per-process", "1"],
        4,
        True,
        True,
    ),
    # A closing terminal hangs up the job; two robots in each robot process.
    "sighup-fork-2-per-process": StopCase(
        signal.SIGHUP, 129, ["--no-record", "--robots-per-process", "2"], 2, True, False
    ),
    # Ctrl-C, with robots started as fresh interpreters.
    "sigint-exec": StopCase(
        signal.SIGINT,
        130,
        ["--no-record", "--spawn", "exec", "--robots-per-process", "1"],
        4,
        False,
        False,
    ),
}


@pytest.mark.parametrize("case", list(STOP_CASES))
def test_a_stop_signal_to_the_job_ends_the_run_in_order(tmp_path: Path, case: str) -> None:
    stop = STOP_CASES[case]
    run_id = unique_run_id("signal")
    argv = [*ENDLESS, *(option.replace("{tmp}", str(tmp_path)) for option in stop.options)]
    expected = _expected_processes(stop.robot_processes, fork=stop.fork, record=stop.record)
    process = _start(run_id, *argv)
    try:
        before = _wait_for_count(run_id, expected)
        assert len(before) == expected
        os.killpg(process.pid, stop.signum)
        returncode, summary, stderr = _finish(process, run_id)
        left = processes_of(run_id)
    finally:
        kill_leftovers(run_id)
    assert returncode == stop.code, stderr
    assert left == []  # the launcher stopped everything, fork server included, before exiting
    assert "Traceback" not in stderr
    assert summary["ended"] == "interrupted"
    assert summary["signal"] == signal.Signals(stop.signum).name
    assert not summary["consensus"] and not summary["timed_out"]
    assert [robot["id"] for robot in summary["stuck"]] == [0, 1, 2, 3]
    if stop.record:
        recording = collect.read_recording(tmp_path / "run.mcap")
        assert recording.complete and recording.summary is not None
        assert recording.summary["ended"] == "interrupted"
        assert recording.summary["stuck"] == summary["stuck"]


@pytest.mark.parametrize("per_process", [1, 2])
def test_nothing_of_the_run_outlives_a_sigkilled_launcher_by_10_seconds(
    tmp_path: Path, per_process: int
) -> None:
    run_id = unique_run_id("sigkill")
    process = _start(
        run_id,
        *ENDLESS,
        "--record",
        str(tmp_path / "run.mcap"),
        "--robots-per-process",
        str(per_process),
    )
    expected = _expected_processes(4 // per_process, fork=True, record=True)
    try:
        before = _wait_for_count(run_id, expected)
        assert len(before) == expected
        process.kill()  # SIGKILL to the launcher alone: no handler can run
        process.wait()
        deadline = time.monotonic() + 10.0
        while processes_of(run_id) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = processes_of(run_id)
    finally:
        kill_leftovers(run_id)
        process.communicate()
    assert left == []


def test_a_run_that_stalls_ends_stalled_and_the_report_says_so(tmp_path: Path) -> None:
    """The beacon is silent all run: the lone robot comes home and waits at the nest for
    good. The watchdog ends the run long before --timeout."""
    run_id = unique_run_id("stall")
    recording = tmp_path / "stalled.mcap"
    code, summary, stderr = run_swarm(
        [
            *("--robots", "1", "--sites", "3", "--beacon-outage", "0:1000000"),
            *("--stall-window", "20", "--timeout", "100000", "--record", str(recording)),
        ],
        run_id,
    )
    assert code == 4, stderr
    assert summary["ended"] == "stalled" and not summary["timed_out"]
    (stuck,) = summary["stuck"]
    assert stuck["id"] == 0 and stuck["phase"] == "waiting"
    assert summary["sim_time_s"] - stuck["last_progress_s"] >= 20.0
    assert summary["sim_time_s"] < 300.0
    assert summary["config"]["stall_window"] == 20.0
    assert processes_of(run_id) == []
    done = subprocess.run(
        swarm_command("report", str(recording), "--out", str(tmp_path / "report")),
        capture_output=True,
        timeout=120,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr.decode()
    assert "stalled, 1 stuck" in done.stdout.decode()
    assert "1 runs (1 stalled); 0/1 correct; none ended in consensus" in done.stdout.decode()
    rows = json.loads((tmp_path / "report" / "summary.json").read_text())
    (row,) = rows["runs"]
    assert row["ended"] == "stalled" and row["stuck"] == 1
    (group,) = rows["groups"]
    assert group["endings"] == {"stalled": 1} and group["aggregated_runs"] == 0


def test_a_swarm_that_can_never_pool_ends_stalled_within_its_window() -> None:
    """Issue 24's run: the beacon is silent to the time limit, so no robot ever pools.
    The robots reach their sites, look at them and come home, where they jostle at the
    nest centre, moving but completing nothing: the run ends stalled one stall window
    after the last step any robot completed (it used to run to --wall-timeout), the same
    as in one process, and says per robot the phase it is stuck in and since when."""
    from deploy.inprocess.engine import run_in_process
    from nest_beacon.core.beacon import BeaconConfig
    from robot_agent.core.controller import ControllerConfig
    from world_server.core.world import WorldConfig

    run_id = unique_run_id("never-pools")
    options = ["--robots", "6", "--sites", "6", "--seed", "1", "--timeout", "100000"]
    code, summary, stderr = run_swarm(
        [*options, "--beacon-outage", "0:100000", "--wall-timeout", "100", "--no-record"],
        run_id,
    )
    assert code == 4, stderr
    assert summary["ended"] == "stalled" and not summary["timed_out"]
    window = summary["config"]["stall_window"]
    assert window < 300.0  # the outage, lasting to the time limit, is not waited for
    stuck = summary["stuck"]
    assert [robot["id"] for robot in stuck] == list(range(6))
    assert {robot["phase"] for robot in stuck} <= {"to_nest", "waiting"}
    assert all(robot["trips"] == 0 for robot in stuck)
    # Each is stuck in the phase it entered with its last step, or later (deaf at the nest).
    assert all(robot["last_progress_s"] <= robot["phase_since_s"] for robot in stuck)
    last = max(robot["last_progress_s"] for robot in stuck)
    assert last + window <= summary["sim_time_s"] < last + window + 30.0
    assert processes_of(run_id) == []
    alone = run_in_process(
        WorldConfig(run="memory", seed=1, num_robots=6, num_sites=6),
        ControllerConfig(),
        BeaconConfig(outages=((0.0, 100000.0),)),
        timeout=100000.0,
    )
    assert alone["ended"] == "stalled"
    assert [robot["last_progress_s"] for robot in alone["stuck"]] == [
        robot["last_progress_s"] for robot in stuck
    ]


def test_a_world_that_stops_ticking_ends_the_run_as_world_stopped() -> None:
    """The world server frozen (SIGSTOP) for good: the sim clock stands still, so neither
    the watchdog nor --timeout can end the run; the world-stop window does."""
    from swarm_helpers import wait_for_processes

    run_id = unique_run_id("world-stops")
    process = subprocess.Popen(
        swarm_command(
            "run",
            *("--run-id", run_id, "--json", "--quiet", "--verbose", "--no-record"),
            *ENDLESS,
            *("--world-stop-window", "3"),
        ),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    world: list[int] = []
    try:
        assert process.stderr is not None
        for line in process.stderr:  # the world's log: tick 0 opens now
            if b"starting with 4 robot(s)" in line:
                break
        time.sleep(1.0)
        world = wait_for_processes(run_id, "world_server.server", 1, 10)
        os.kill(world[0], signal.SIGSTOP)
        stdout, _ = process.communicate(timeout=60)
    finally:
        for pid in world:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGCONT)
        if process.poll() is None:
            process.kill()
        kill_leftovers(run_id)
    summary = json.loads(stdout)
    assert process.returncode == 6
    assert summary["ended"] == "world_stopped" and not summary["timed_out"]
    assert summary["config"]["world_stop_window"] == 3.0
    assert len(summary["stuck"]) == 4
    assert processes_of(run_id) == []


@pytest.mark.parametrize(
    ("limit", "kind"),
    [(["--wall-timeout", "3"], "wall"), (["--timeout", "20"], "sim")],  # last wins
)
def test_a_time_limit_ends_the_run_as_a_timeout_of_its_kind(limit: list[str], kind: str) -> None:
    run_id = unique_run_id(f"limit-{kind}")
    code, summary, stderr = run_swarm([*ENDLESS, *limit, "--no-record"], run_id)
    assert code == 5, stderr
    assert summary["ended"] == "timeout" and summary["timeout_kind"] == kind
    assert summary["timed_out"] and len(summary["stuck"]) == 4
    assert processes_of(run_id) == []


def test_robots_that_decide_on_different_sites_end_split() -> None:
    """Deciding at probability 0.5 among three sites takes one comparison; with seed 2
    the robots disagree (the same run in one process: tests/test_watchdog.py)."""
    run_id = unique_run_id("split")
    code, summary, stderr = run_swarm(
        ["--robots", "4", "--sites", "3", "--seed", "2", "--threshold", "0.5", "--no-record"],
        run_id,
    )
    assert code == 3, stderr
    assert summary["ended"] == "split" and summary["stuck"] == []
    assert [robot["decided_site"] for robot in summary["per_robot"]] == [1, 1, 0, 1]


def test_an_unwritable_recording_path_is_refused_before_anything_starts(
    capsys: pytest.CaptureFixture[str],
) -> None:
    run_id = unique_run_id("badrecord")
    code, _, err = swarm_cli(["run", "--run-id", run_id, "--record", "/etc/passwd/x.mcap"], capsys)
    errors = err.strip().splitlines()
    assert code == 2
    assert errors == [
        "swarm run: error: --record /etc/passwd/x.mcap: /etc/passwd is not a directory"
    ]
    assert processes_of(run_id) == []


def test_a_router_that_is_not_there_is_one_line_saying_how_long_it_tried() -> None:
    run_id = unique_run_id("norouter")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    done = subprocess.run(
        swarm_command("run", "--run-id", run_id, "--no-record", "--connect", endpoint),
        capture_output=True,
        timeout=60,
        cwd=REPO,
    )
    took = time.monotonic() - started
    errors = done.stderr.decode().strip().splitlines()
    assert done.returncode == 1
    assert errors == [
        f"swarm run: could not start: no Zenoh router answers at {endpoint} (tried for 5 s)"
    ]
    assert took < 20.0
    assert processes_of(run_id) == []


def test_the_help_documents_each_endings_exit_code(capsys: pytest.CaptureFixture[str]) -> None:
    _, text, _ = swarm_cli(["run", "--help"], capsys)
    for line in ("0    consensus", "1    crashed", "3    split", "4    stalled", "5    timeout"):
        assert line in text
    assert "6    world_stopped" in text and "--world-stop-window" in text
    assert "130  interrupted" in text and "143 by SIGTERM" in text and "129 by SIGHUP" in text
    assert "--wall-timeout" in text and "--stall-window" in text
