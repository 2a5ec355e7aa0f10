"""Helpers for tests of robots outside the emulator: ``swarm run --external`` with the
outside programs started by the test (``python -m robot_agent.link``, or the C robot,
``c_robot/build/c-robot``), on loopback UDP or a pseudo-terminal pair made by ``socat``.
Every process is killed by pid at the end."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    reference_run,
    stop_processes,
    swarm_command,
    unique_run_id,
)

from deploy.launcher.outside import free_udp_port


def decisions(summary: dict[str, Any]) -> list[tuple[object, ...]]:
    """Per robot: decided site, steps, decision time, pool sizes (what must not change)."""
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


def in_process(options: Sequence[str]) -> dict[str, Any]:
    """The all-emulated run of the same options (the in-process engine gives the same
    per-robot results as swarm run: tests/test_swarm.py), run in this process once per
    set of options and kept (``reference_run``)."""
    return reference_run(options)


def program(link: str, robot: int, key_file: Path, *extra: str) -> subprocess.Popen[bytes]:
    """The outside robot's program, as a porter starts it."""
    command = [sys.executable, "-m", "robot_agent.link", "--link", link, "--id", str(robot)]
    return subprocess.Popen(
        [*command, "--key-file", str(key_file), "--give-up", "60", *extra],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


C_ROBOT = REPO / "c_robot"
C_BINARY = C_ROBOT / "build" / "c-robot"


def make_c_robot(*targets: str) -> subprocess.CompletedProcess[str]:
    """``make -C c_robot TARGETS``, one at a time across test workers (they share the
    build folder)."""
    C_BINARY.parent.mkdir(exist_ok=True)
    with (C_BINARY.parent / ".make-lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return subprocess.run(
            ["make", "-C", str(C_ROBOT), *targets], capture_output=True, timeout=600, text=True
        )


def c_robot_binary() -> Path | None:
    """The C robot, built when it is missing; None without make or the C compiler make
    would use (``$CC``, as the Makefile's test target asks, or gcc)."""
    compiler = os.environ.get("CC") or "gcc"
    if shutil.which("make") is None or shutil.which(compiler) is None:
        return None
    built = make_c_robot()
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    return C_BINARY


def wait_for(path: Path, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert path.exists(), f"{path} never appeared"


@dataclass
class OutsideRun:
    """A live ``swarm run --external`` and the programs the test started for it."""

    run_id: str
    keys: Path
    process: subprocess.Popen[bytes]
    programs: list[subprocess.Popen[bytes]] = field(default_factory=list)

    def key_file(self, robot: int) -> Path:
        path = self.keys / f"robot-{robot}.key"
        wait_for(path)
        return path

    def start(self, link: str, robot: int, *extra: str) -> subprocess.Popen[bytes]:
        started = program(link, robot, self.key_file(robot), *extra)
        self.programs.append(started)
        return started

    def start_c(self, binary: Path | None, link: str, robot: int) -> subprocess.Popen[bytes]:
        """The C robot for ``robot``, as a porter starts it; the Python program in its place
        (with a warning) when there is no C compiler to build it."""
        if binary is None:
            warnings.warn(f"no C compiler: robot {robot} runs as the Python program", stacklevel=2)
            return self.start(link, robot)
        command = [str(binary), "--link", link, "--id", str(robot)]
        started = subprocess.Popen(
            [*command, "--key-file", str(self.key_file(robot)), "--give-up", "60"],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        self.programs.append(started)
        return started

    def finish(self, timeout: float = 240.0) -> tuple[int, dict[str, Any] | None, str]:
        stdout, stderr = self.process.communicate(timeout=timeout)
        text = stdout.decode().strip()
        return self.process.returncode, json.loads(text) if text else None, stderr.decode()

    def program_summaries(self, timeout: float = 30.0) -> list[dict[str, Any]]:
        """Each program's last line (it prints one when the bridge says the run ended)."""
        found = []
        for started in self.programs:
            stdout, _ = started.communicate(timeout=timeout)
            lines = stdout.decode().strip().splitlines()
            found.append(json.loads(lines[-1]) if lines else {})
        return found


@contextlib.contextmanager
def outside_run(tmp_path: Path, *options: str, prefix: str = "outside") -> Iterator[OutsideRun]:
    run_id = unique_run_id(prefix)
    keys = tmp_path / "keys"
    command = swarm_command(
        "run", "--run-id", run_id, "--json", "--quiet", "--link-keys", str(keys), *options
    )
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    run = OutsideRun(run_id, keys, process)
    try:
        yield run
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        stop_processes(run.programs, grace=2.0)
        kill_leftovers(run_id)


def udp_link() -> str:
    return f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"


@contextlib.contextmanager
def pty_pair(tmp_path: Path) -> Iterator[tuple[Path, Path]]:
    """Two pseudo-terminals joined by ``socat``: the bridge's end and the robot's end of a
    serial line. Skips the test when socat is missing."""
    socat = shutil.which("socat")
    if socat is None:
        pytest.skip("socat is not installed (apt-get install socat): no serial line to test")
    bridge_end, robot_end = tmp_path / "bridge-tty", tmp_path / "robot-tty"
    process = subprocess.Popen(
        [socat, f"pty,raw,echo=0,link={bridge_end}", f"pty,raw,echo=0,link={robot_end}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(bridge_end, 10)
        wait_for(robot_end, 10)
        yield bridge_end, robot_end
    finally:
        stop_processes([process], grace=2.0)


class Relay(threading.Thread):
    """A UDP relay between a program and the bridge that keeps what the program sent, and
    can send frames to the bridge from the program's side (an attacker on the path)."""

    def __init__(self, bridge_port: int) -> None:
        super().__init__(daemon=True)
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.bind(("127.0.0.1", 0))
        self.port = self.socket.getsockname()[1]
        self.bridge = ("127.0.0.1", bridge_port)
        self.program: tuple[str, int] | None = None
        self.captured: list[bytes] = []
        self.stopping = threading.Event()

    def run(self) -> None:
        while not self.stopping.is_set():
            ready, _, _ = select.select([self.socket], [], [], 0.1)
            if not ready:
                continue
            data, source = self.socket.recvfrom(70000)
            if source == self.bridge:
                if self.program is not None:
                    self.socket.sendto(data, self.program)
            else:
                self.program = source
                self.captured.append(data)
                self.socket.sendto(data, self.bridge)

    def inject(self, data: bytes) -> None:
        self.socket.sendto(data, self.bridge)

    @property
    def address(self) -> str:
        """Where the program connects: the relay."""
        return f"udp://127.0.0.1:{self.port}"

    def wait_for(self, frames: int, timeout: float = 120.0) -> None:
        """Wait until the program has sent ``frames`` frames through the relay (the run's
        progress, whatever the machine's speed)."""
        deadline = time.monotonic() + timeout
        while len(self.captured) < frames and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(self.captured) >= frames, "the program never got that far"

    def stop(self) -> None:
        self.stopping.set()
        self.join(5)
        self.socket.close()

    @classmethod
    @contextlib.contextmanager
    def to(cls, bridge: str) -> Iterator[Relay]:
        """A relay to the bridge at ``bridge`` (udp://127.0.0.1:PORT), running."""
        relay = cls(int(bridge.rsplit(":", 1)[1]))
        relay.start()
        try:
            yield relay
        finally:
            relay.stop()
