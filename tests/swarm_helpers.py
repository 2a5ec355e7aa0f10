"""Helpers for tests that start real swarm processes: run them, find them, clean up.

Every process a test starts is found by the unique run id in its command line, so a
test can check that nothing is left behind and kill stragglers by pid.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
import zenoh

from bestofn_swarm.plumbing.tcp import free_port
from bestofn_swarm.plumbing.zenoh_session import open_session
from deploy.launcher.supervisor import RUN_ID_ENV

REPO = Path(__file__).resolve().parent.parent


def unique_run_id(prefix: str = "t") -> str:
    return f"{prefix}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def swarm_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "deploy.cli", *args]


def processes_of(run_id: str) -> list[int]:
    """Pids of live processes of the run: ``run_id`` in their command line, or in their
    environment (forked robots have no command line of their own)."""
    found = []
    marker = f"{RUN_ID_ENV}={run_id}".encode()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().split(b"\0")
            environ = (entry / "environ").read_bytes().split(b"\0")
            state = (entry / "stat").read_text().split()[2]
        except OSError:
            continue
        if state != "Z" and (run_id.encode() in cmdline or marker in environ):
            found.append(int(entry.name))
    return found


def wait_for_processes(run_id: str, needle: str, count: int, timeout: float) -> list[int]:
    """Wait until ``count`` processes of the run have ``needle`` in their command line."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pids = [pid for pid in processes_of(run_id) if needle in _cmdline(pid)]
        if len(pids) >= count:
            return pids
        time.sleep(0.05)
    raise TimeoutError(f"fewer than {count} '{needle}' processes of {run_id} appeared")


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def private_directories(tmp: Path) -> list[str]:
    """The runs' private directories (sockets, keys, certificates) left in ``tmp``."""
    return sorted(path.name for path in tmp.iterdir() if path.name.startswith("bestofn-"))


def kill_leftovers(run_id: str) -> list[int]:
    """SIGKILL anything of the run still alive; return the pids that were left."""
    left = processes_of(run_id)
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    return left


def stop_processes(processes: Sequence[subprocess.Popen[bytes]], grace: float = 5.0) -> None:
    """SIGTERM every process still running, then SIGKILL those that outlive ``grace``."""
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@functools.cache
def _reference_json(options: tuple[str, ...]) -> str:
    from deploy.cli import build_parser
    from deploy.launcher.inprocess import run_plan
    from deploy.launcher.plan import plan_from_args

    argv = ["run", "--engine", "inprocess", "--no-record", *options]
    return json.dumps(run_plan(plan_from_args(build_parser(["run"]).parse_args(argv))))


def reference_run(options: Sequence[str]) -> dict[str, Any]:
    """The summary ``swarm run --engine inprocess --no-record OPTIONS`` gives (but for what
    the command adds to it: ``faults``, ``recording``), run in this process once per set of
    options and kept for the tests that compare a live run with it."""
    summary: dict[str, Any] = json.loads(_reference_json(tuple(options)))
    return summary


def call_main(
    main: Callable[[list[str]], int], argv: Sequence[str], capsys: pytest.CaptureFixture[str]
) -> tuple[int, str, str]:
    """A command's ``main(argv)`` called in this process, as its command line would be:
    (exit code, standard output, standard error). For what ends before anything starts
    (help, usage errors); what starts processes or sessions runs in a process of its own."""
    try:
        code = main(list(argv))
    except SystemExit as leaving:
        code = leaving.code if isinstance(leaving.code, int) else (0 if leaving.code is None else 1)
    out, err = capsys.readouterr()
    return code, out, err


def swarm_cli(argv: Sequence[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``swarm ARGV`` in this process (``call_main``)."""
    from deploy.cli import main

    return call_main(main, argv, capsys)


def run_swarm(args: Sequence[str], run_id: str, timeout: float = 120.0) -> tuple[int, Any, str]:
    """Run ``swarm run ... --json`` to the end; return (exit code, summary, stderr)."""
    command = swarm_command("run", "--run-id", run_id, "--json", "--quiet", *args)
    try:
        done = subprocess.run(command, capture_output=True, timeout=timeout, cwd=REPO)
    finally:
        kill_leftovers(run_id)
    stdout = done.stdout.decode()
    summary = json.loads(stdout) if stdout.strip() else None
    return done.returncode, summary, done.stderr.decode()


@contextlib.contextmanager
def loopback_router() -> Iterator[tuple[zenoh.Session, str]]:
    """A Zenoh router in the test process on a free loopback port."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session("router", listen=[endpoint])
    try:
        yield session, endpoint
    finally:
        session.close()
