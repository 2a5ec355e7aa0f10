"""What keeps a run to itself, on live runs: ``swarm run --secure`` end to end (TLS with
certificates made for the run, access control), the default's private Unix socket, and
keys that never show on a command line."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from swarm_helpers import (
    REPO,
    kill_leftovers,
    private_directories,
    processes_of,
    swarm_command,
    unique_run_id,
)

from bestofn_swarm.plumbing.run_keys import KEYS_ENV

pytestmark = pytest.mark.timeout(240)

SMALL = ["--robots", "3", "--sites", "4", "--seed", "1", "--timeout", "600"]
HEX_KEY = re.compile(rb"[0-9a-fA-F]{64}")


def run_in(tmp: Path, *options: str, timeout: float = 180) -> tuple[int, dict[str, Any], str]:
    """``swarm run`` with its temporary files (the run's private directory) under ``tmp``."""
    run_id = unique_run_id("secure")
    tmp.mkdir(exist_ok=True)
    command = swarm_command("run", "--run-id", run_id, "--json", "--quiet", *options)
    try:
        done = subprocess.run(
            command, capture_output=True, timeout=timeout, cwd=REPO, env=_env(tmp)
        )
    finally:
        left = kill_leftovers(run_id)
    assert left == []
    stdout = done.stdout.decode()
    return done.returncode, json.loads(stdout) if stdout.strip() else {}, done.stderr.decode()


def _env(tmp: Path) -> dict[str, str]:
    return {**os.environ, "TMPDIR": str(tmp)}


def _interruptible() -> None:
    """Ctrl-C as in a terminal: a test runner started in the background ignores SIGINT, and
    its children would inherit that."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_a_secure_swarm_reaches_consensus_and_records_it(short_tmp: Path, tmp_path: Path) -> None:
    recording = tmp_path / "run.mcap"
    code, summary, stderr = run_in(short_tmp, *SMALL, "--secure", "--record", str(recording))
    assert code == 0, stderr
    assert summary["correct"] and not summary["timed_out"], summary["per_robot"]
    assert summary["config"]["secure"] is True
    assert summary["rejected"] == {"world": 0, "robots": 0, "observer": 0, "beacon": 0}
    with recording.open("rb") as stream:
        reader = make_reader(stream)
        lines = [
            json.loads(message.data)["line"]
            for _, channel, message in reader.iter_messages()
            if channel.topic.endswith("/log/world")
        ]
        final = {record.name: record.metadata for record in reader.iter_metadata()}
    assert any("listening on tls/127.0.0.1:" in line for line in lines), lines
    assert json.loads(final["bestofn.run"]["summary"])["correct"] is True
    assert json.loads(final["bestofn.run"]["recorder"])["rejected"] == 0
    assert private_directories(short_tmp) == []  # certificates and keys are gone


def test_a_secure_swarm_survives_a_kill_and_a_restart(short_tmp: Path) -> None:
    code, summary, stderr = run_in(
        short_tmp,
        *["--robots", "4", "--sites", "5", "--seed", "11", "--timeout", "1500"],
        *["--secure", "--no-record", "--restart", "2@15", "--kill", "1@20"],
    )
    assert code == 0, stderr
    robots = summary["per_robot"]
    assert robots[1]["killed"] and robots[2]["restarts"] == 1
    assert summary["correct"], robots
    assert [robot["decided_site"] for robot in robots if not robot["killed"]] == [
        summary["best_site"]
    ] * 3
    assert private_directories(short_tmp) == []


def _wait_for(condition: Any, timeout: float) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    return None


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def _environ(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/environ").read_bytes()
    except OSError:
        return b""


def _tcp_listeners(pid: int) -> list[str]:
    """Local addresses of the TCP sockets ``pid`` listens on."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        target = os.readlink(fd) if fd.is_symlink() else ""
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = []
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # 0A: LISTEN
                found.append(fields[1])
    return found


def test_ctrl_c_on_a_secure_run_removes_its_certificates(short_tmp: Path, tmp_path: Path) -> None:
    tmp = short_tmp
    run_id = unique_run_id("secure-int")
    command = swarm_command("run", "--run-id", run_id, "--quiet", *SMALL, "--secure", "--no-record")
    command += ["--clock", "realtime", "--speed", "1"]  # long enough to interrupt
    # Output to a file, not a pipe: waiting for the launcher must not wait for whatever
    # else holds the pipe open.
    log = (tmp_path / "launcher.log").open("wb")
    process = subprocess.Popen(
        command,
        cwd=REPO,
        env=_env(tmp),
        stdout=log,
        stderr=log,
        preexec_fn=_interruptible,  # noqa: PLW1509 (before any thread of this test)
    )
    try:
        certificates = _wait_for(lambda: list(tmp.glob("bestofn-*/certs/robot-2.pem")), 60)
        assert certificates, "the run made no certificates"
        assert _wait_for(lambda: len(processes_of(run_id)) >= 5, 60)
        process.send_signal(signal.SIGINT)
        process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        log.close()
        # What an interrupted run leaves behind is the launcher's clean-up, tested apart.
        kill_leftovers(run_id)
    assert process.returncode == 130
    assert private_directories(tmp) == []


def test_keys_never_show_on_a_command_line_and_the_default_listens_on_no_port(
    short_tmp: Path,
    tmp_path: Path,
) -> None:
    """While a default run goes: no process of it has a key in its command line, the
    launcher and the fork server have none in their environment either (a forked robot
    gets its own through the fork call), and the world listens on a socket in a private
    directory, on no TCP port at all."""
    tmp = short_tmp
    run_id = unique_run_id("no-leak")
    command = swarm_command("run", "--run-id", run_id, "--quiet", *SMALL, "--no-record")
    command += ["--clock", "realtime", "--speed", "2", "--robots-per-process", "1"]
    # Output to a file, not a pipe: waiting for the launcher must not wait for whatever
    # else holds the pipe open.
    log = (tmp_path / "launcher.log").open("wb")
    process = subprocess.Popen(
        command,
        cwd=REPO,
        env=_env(tmp),
        stdout=log,
        stderr=log,
        preexec_fn=_interruptible,  # noqa: PLW1509 (before any thread of this test)
    )
    try:

        def forked_processes() -> list[int]:
            """The fork server, and the robots forked from it (they share its command line)."""
            return [pid for pid in processes_of(run_id) if b"forkserver" in _cmdline(pid)]

        assert _wait_for(lambda: len(forked_processes()) >= 4, 60), "the robots did not start"
        pids = [*processes_of(run_id), process.pid]
        world = next(pid for pid in pids if b"world_server.server" in _cmdline(pid))
        forked = forked_processes()
        for pid in pids:
            assert not HEX_KEY.search(_cmdline(pid)), _cmdline(pid)
            assert b"secret" not in _cmdline(pid)
        for pid in [process.pid, *forked]:
            assert KEYS_ENV.encode() not in _environ(pid)
        assert len(forked) == 4, forked  # the server and three robots
        listen = _cmdline(world).split(b"\0")
        endpoint = listen[listen.index(b"--listen") + 1].decode()
        assert endpoint.startswith("unixsock-stream/")
        directory = Path(endpoint.partition("/")[2]).parent
        assert directory.parent == tmp
        assert directory.stat().st_mode & 0o777 == 0o700
        assert _tcp_listeners(world) == []
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=60)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
            log.close()
            kill_leftovers(run_id)
    assert private_directories(tmp) == []
