"""What a run leaves on disk is its user's only, and files a user names are read with a
bound (issue 23, parts 6 to 8), against live processes: recordings and traces another
user cannot read, key files and configurations that never end refused in one line, a
secure run's keys gone after a SIGKILL of its launcher, a crashed world server reported
as such. The units: tests/test_user_files.py."""

from __future__ import annotations

import json
import os
import pwd
import signal
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    private_directories,
    processes_of,
    swarm_command,
    unique_run_id,
)

from bestofn_swarm.wire.endings import Ending
from deploy.reports import collect
from deploy.security import credentials

pytestmark = pytest.mark.timeout(180)

SMALL = ["--robots", "3", "--sites", "4", "--seed", "1"]


def mode_of(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


@pytest.fixture
def shared_folder() -> Iterator[Path]:
    """A folder every user may enter (0755), as a project folder is: only what is written
    into it decides what another user can read."""
    folder = Path(tempfile.mkdtemp(prefix="private-runs-", dir="/tmp"))
    folder.chmod(0o755)
    try:
        yield folder
    finally:
        subprocess.run(["rm", "-rf", str(folder)], check=False)


def another_user_reads(path: Path) -> subprocess.CompletedProcess[bytes]:
    """``cat path`` as the user nobody."""
    return subprocess.run(
        ["cat", str(path)], user=pwd.getpwnam("nobody").pw_uid, capture_output=True, timeout=30
    )


def _wait_for(condition: Callable[[], object], timeout: float) -> object:
    deadline = time.monotonic() + timeout
    while not (found := condition()) and time.monotonic() < deadline:
        time.sleep(0.1)
    return found


# --- part 6: recordings, run directories and logs are their owner's ---------------------


@pytest.mark.parametrize("mode", [[], ["--secure"]], ids=["default", "secure"])
def test_a_recording_and_traces_are_private_in_a_folder_anyone_may_enter(
    mode: list[str], shared_folder: Path
) -> None:
    runs = shared_folder / "runs"
    runs.mkdir()
    runs.chmod(0o755)  # the runs/ folder: there already, 0755
    recording = runs / "new" / "run.mcap"  # and a folder the launcher makes
    traces = shared_folder / "traces"
    run_id = unique_run_id("private")
    command = swarm_command(
        "run", "--run-id", run_id, "--json", "--quiet", *SMALL, *mode,
        "--record", str(recording), "--trace", str(traces),
    )  # fmt: skip
    try:
        done = subprocess.run(command, cwd=REPO, capture_output=True, timeout=150)
    finally:
        kill_leftovers(run_id)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    assert mode_of(runs) == 0o755  # found: left alone
    assert mode_of(runs / "new") == 0o700 and mode_of(traces) == 0o700
    assert mode_of(recording) == 0o600
    written = list(traces.iterdir())
    assert written and {mode_of(path) for path in written} == {0o600}
    if os.geteuid() != 0:
        pytest.skip("reading as another user needs root (the modes are checked above)")
    refused = another_user_reads(recording)
    assert refused.returncode != 0 and b"Permission denied" in refused.stderr
    assert another_user_reads(written[0]).returncode != 0
    # The owner reads all of it.
    assert collect.read_recording(recording).summary is not None


def test_an_experiment_s_logs_and_report_are_private(shared_folder: Path) -> None:
    out = shared_folder / "experiment"
    command = swarm_command(
        "experiment", "--robots", "3", "--sites", "4", "--runs", "1", "--parallel", "1",
        "--out", str(out), "--json", "--quiet", "--engine", "inprocess",
    )  # fmt: skip
    done = subprocess.run(command, cwd=REPO, capture_output=True, timeout=170)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    folders = [out, *(path for path in out.rglob("*") if path.is_dir())]
    files = [path for path in out.rglob("*") if path.is_file()]
    assert {mode_of(folder) for folder in folders} == {0o700}
    assert {path.suffix for path in files} >= {".json", ".log", ".mcap", ".csv", ".png"}
    assert {mode_of(path) for path in files} == {0o600}


# --- part 7: files a user names, read with a bound ----------------------------------------


PROCESSES = {
    "world-server": ["world_server.server"],
    "robot-agent": ["robot_agent.node", "--id", "0"],
    "nest-beacon": ["nest_beacon"],
    "recorder": ["world_server.recorder", "--out", "never.mcap"],
    "viewer": ["deploy.viewer.live"],
    "foxglove-live": ["deploy.viewer.foxglove_live"],
}


@pytest.mark.parametrize("option", ["--key-file", "--zenoh-config"])
@pytest.mark.parametrize("process", sorted(PROCESSES))
def test_a_file_that_never_ends_is_refused_in_one_line(
    process: str, option: str, tmp_path: Path
) -> None:
    command = [sys.executable, "-m", *PROCESSES[process], "--run-id", "r", option, "/dev/zero"]
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, timeout=60)
    error = done.stderr.decode()
    assert done.returncode == 2, error[-2000:]
    assert error.count("\n") == 1 and "/dev/zero is too big" in error, error[-2000:]
    assert not (tmp_path / "never.mcap").exists()


def test_a_router_with_a_configuration_that_never_ends_is_refused_in_one_line() -> None:
    done = subprocess.run(
        swarm_command("router", "--zenoh-config", "/dev/zero"), capture_output=True, timeout=60
    )
    assert done.returncode == 2
    assert done.stderr.decode().splitlines()[-1].startswith("router: error: Zenoh configuration")
    assert b"Traceback" not in done.stderr


# --- part 8: smaller faults --------------------------------------------------------------


def test_run_keys_out_an_existing_file_is_one_line(tmp_path: Path) -> None:
    existing = tmp_path / "keys"
    existing.write_text("")
    command = [
        sys.executable,
        "-m",
        "bestofn_swarm.plumbing.run_keys",
        "--run-id",
        "r",
        "--robots",
        "2",
    ]
    done = subprocess.run(
        [*command, "--out", str(existing)], cwd=REPO, capture_output=True, timeout=60
    )
    assert done.returncode == 2
    assert done.stderr.decode() == f"run_keys: error: cannot write {existing}: not a folder\n"


def _secure_run(tmp: Path, run_id: str) -> subprocess.Popen[bytes]:
    command = swarm_command("run", "--run-id", run_id, "--quiet", *SMALL, "--secure")
    command += ["--no-record", "--clock", "realtime", "--speed", "1"]  # long enough to kill
    return subprocess.Popen(
        command,
        cwd=REPO,
        env={**os.environ, "TMPDIR": str(tmp)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _janitor_of(directory: Path) -> int | None:
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"deploy.security.janitor" in cmdline and str(directory).encode() in cmdline:
                return int(entry.name)
    return None


def test_a_sigkilled_secure_launcher_leaves_no_private_key_behind(short_tmp: Path) -> None:
    tmp = short_tmp
    run_id = unique_run_id("secure-kill")
    process = _secure_run(tmp, run_id)
    try:
        keys = _wait_for(lambda: list(tmp.glob("bestofn-*/certs/robot-2.key")), 60)
        assert keys, "the run made no keys"
        assert _wait_for(lambda: len(processes_of(run_id)) >= 5, 60)
        process.kill()  # SIGKILL: no handler of the launcher runs
        process.wait()
        assert _wait_for(lambda: private_directories(tmp) == [], 20), private_directories(tmp)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        kill_leftovers(run_id)


def test_the_next_run_sweeps_what_a_killed_launcher_and_janitor_left(
    short_tmp: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tmp = short_tmp
    run_id = unique_run_id("secure-kill")
    process = _secure_run(tmp, run_id)
    try:
        keys = _wait_for(lambda: list(tmp.glob("bestofn-*/certs/robot-2.key")), 60)
        assert isinstance(keys, list) and keys, "the run made no keys"
        directory = keys[0].parent.parent
        janitor = _janitor_of(directory)
        assert janitor is not None, "no janitor watches the run's directory"
        os.kill(janitor, signal.SIGKILL)  # everything killed: kill -9 of every process
        process.kill()
        process.wait()
        _wait_for(lambda: not processes_of(run_id), 20)
        assert private_directories(tmp) == [directory.name]  # left behind ...
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        kill_leftovers(run_id)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    network = credentials.RunNetwork.create("next", 2, janitor=False)  # ... until the next run
    try:
        assert private_directories(tmp) == [network.directory.name] if network.directory else []
    finally:
        network.close()
    assert private_directories(tmp) == []


def test_a_crashed_world_server_is_reported_as_the_router_gone(tmp_path: Path) -> None:
    """SIGKILL of the world, which is the run's router: the launcher said the recorder
    'did not grow for 60 s' 0.6 s after the crash."""
    run_id = unique_run_id("world-kill")
    recording = tmp_path / "run.mcap"
    command = swarm_command("run", "--run-id", run_id, "--json", "--quiet", *SMALL)
    command += ["--record", str(recording), "--clock", "realtime", "--speed", "1"]
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:

        def world() -> int | None:
            for pid in processes_of(run_id):
                try:
                    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
                except OSError:
                    continue
                if b"world_server.server" in cmdline:
                    return pid
            return None

        assert _wait_for(lambda: len(processes_of(run_id)) >= 6, 60)
        pid = world()
        assert pid is not None
        time.sleep(2.0)  # let it tick
        os.kill(pid, signal.SIGKILL)
        stdout, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        kill_leftovers(run_id)
    said = stderr.decode()
    assert process.returncode == Ending.CRASHED.code, said[-3000:]
    assert json.loads(stdout)["ended"] == "crashed"
    assert "did not grow" not in said
    assert "the world server, the run's router, is gone" in said
    assert "Traceback" not in said
    # Stopped, the recorder closed the file without the summary: whole and readable.
    assert collect.read_recording(recording).complete
