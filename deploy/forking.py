"""Start robot processes fast: a preloaded fork server instead of a fresh interpreter each.

A fresh ``python -m robot_agent.node`` spends most of its start-up importing numpy,
OpenCV and Zenoh; on two cores, a hundred of them starting at once take tens of
seconds. The fork server (``multiprocessing``'s, with the robot's modules preloaded)
imports them once and forks a child per robot, which then runs ``main(argv)`` exactly
as the command would. Its stderr goes to a pipe the launcher reads, like a subprocess.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import signal
import subprocess
import sys
from multiprocessing.connection import Connection
from typing import IO

from plumbing.lifecycle import PARENT_ENV, die_with_launcher

PRELOAD = ["robot_agent.node", "nest_beacon.__main__"]

# Single-threaded numerical libraries: no thread pools to copy into forks, and no
# spinning worker threads competing for the two cores with hundreds of processes.
QUIET_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _child_main(
    module: str, argv: list[str], log: Connection, env: dict[str, str] | None = None
) -> None:
    """Runs in the forked child: stderr to the launcher's pipe, then the module's main.

    ``env`` (a robot's run keys) comes through the fork call, not the fork server's own
    environment, so that no other child inherits it."""
    os.environ.update(env or {})
    os.dup2(log.fileno(), 2)
    log.close()
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.close(devnull)
    # The parent of a forked child is the fork server, which dies with the launcher.
    os.environ[PARENT_ENV] = str(os.getppid())
    die_with_launcher()
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(importlib.import_module(module).main(argv))


class ForkedProcess:
    """A forked child with the parts of ``subprocess.Popen`` the launcher uses."""

    def __init__(self, process: multiprocessing.process.BaseProcess, stderr: IO[bytes]) -> None:
        self._process = process
        self.stderr = stderr

    @property
    def pid(self) -> int:
        assert self._process.pid is not None
        return self._process.pid

    @property
    def returncode(self) -> int | None:
        return self._process.exitcode

    def poll(self) -> int | None:
        return None if self._process.is_alive() else self._process.exitcode

    def send_signal(self, signum: int) -> None:
        if self._process.is_alive():
            os.kill(self.pid, signum)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def wait(self, timeout: float | None = None) -> int:
        self._process.join(timeout)
        if self._process.is_alive():
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout or 0.0)
        return int(self._process.exitcode or 0)


class ForkServer:
    """Forks robot (and beacon) processes from one preloaded server process."""

    def __init__(self, preload: list[str] | None = None) -> None:
        os.environ.update(QUIET_THREADS)  # inherited by the server when it starts
        self._context = multiprocessing.get_context("forkserver")
        self._context.set_forkserver_preload(preload or PRELOAD)

    def start(
        self, module: str, argv: list[str], env: dict[str, str] | None = None
    ) -> ForkedProcess:
        reader, writer = self._context.Pipe(duplex=False)
        process = self._context.Process(
            target=_child_main, args=(module, list(argv), writer, env), daemon=False
        )
        process.start()
        writer.close()  # the child holds the only write end: EOF when it exits
        stderr = os.fdopen(os.dup(reader.fileno()), "rb")
        reader.close()
        return ForkedProcess(process, stderr)
