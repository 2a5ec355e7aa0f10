"""Start robot processes fast: a preloaded fork server instead of a fresh interpreter each.

A fresh ``python -m robot_agent.node`` spends most of its start-up importing numpy,
OpenCV and Zenoh; on two cores, a hundred of them starting at once take tens of
seconds. The fork server (``multiprocessing``'s, with the robot's modules preloaded)
imports them once and forks a child per robot, which then runs ``main(argv)`` exactly
as the command would. Its stderr goes to a pipe the launcher reads, like a subprocess.

Two things make the children die with the launcher, even on SIGKILL. The fork server
stops when its liveness pipe from the launcher reaches end of file, and each child asks
for a SIGTERM when the fork server dies (bestofn_swarm/plumbing/lifecycle.py). But multiprocessing
hands every forked child a copy of that pipe's write end (and of the resource tracker's),
so that children could start processes of their own; robots never do, and as long as
one of them held the pipe open, the fork server never saw the launcher die, and the
robots never saw the fork server die. So each child closes both first thing.
The fork server also leaves the launcher's process group (``deploy/fork_server_group``),
so that a terminal's or timeout(1)'s signal to that group reaches only the launcher.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import multiprocessing.process
import multiprocessing.util
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from multiprocessing import forkserver, resource_tracker
from multiprocessing.connection import Connection
from typing import IO, Any

from bestofn_swarm.plumbing.lifecycle import PARENT_ENV, die_with_launcher

PRELOAD = [
    "deploy.launcher.fork_server_group",
    "robot_agent.node.cli",
    "nest_beacon.node.cli",
]
FORK_SERVER_OF = "BESTOFN_FORK_SERVER_OF"  # the pid of the launcher that asks for the server

# Single-threaded numerical libraries: no thread pools to copy into forks, and no
# spinning worker threads competing for the two cores with hundreds of processes.
QUIET_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _drop_fork_server_handles() -> None:
    """Close the write ends of the fork server's liveness pipe and of the resource
    tracker's pipe that multiprocessing gave this child (see the module's docstring)."""
    # Private attributes of multiprocessing: where its _serve_one puts the two handles.
    # typeshed does not describe them, hence Any.
    server: Any = forkserver._forkserver
    if server._forkserver_alive_fd is not None:
        os.close(server._forkserver_alive_fd)
        server._forkserver_alive_fd = None
    tracker: Any = resource_tracker._resource_tracker
    if tracker._fd is not None:
        os.close(tracker._fd)
        tracker._fd = None


def _child_main(
    module: str, argv: list[str], log: Connection, env: dict[str, str] | None = None
) -> None:
    """Runs in the forked child: stderr to the launcher's pipe, then the module's main.

    ``env`` (a robot's run keys) comes through the fork call, not the fork server's own
    environment, so that no other child inherits it."""
    os.environ.update(env or {})
    _drop_fork_server_handles()
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
        # It may exit between the two calls (on the run's ending, robots exit by themselves).
        if self._process.is_alive():
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signum)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def wait(self, timeout: float | None = None) -> int:
        self._process.join(timeout)
        if self._process.is_alive():
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout or 0.0)
        return int(self._process.exitcode or 0)


# A Unix socket's path has at most 107 bytes. The fork server listens on one in a folder
# multiprocessing makes in the temp folder; below a temp folder longer than this, that
# socket's path would not fit ("AF_UNIX path too long"), so its folder goes under /tmp.
MAX_TEMP_FOLDER = 60


def _short_socket_folder() -> None:
    """Give multiprocessing a private folder of a path short enough for a socket, where the
    temp folder (TMPDIR) is too long for one."""
    if len(tempfile.gettempdir()) <= MAX_TEMP_FOLDER:
        return
    process: Any = multiprocessing.process.current_process()  # its config is private: Any
    config = process._config
    if config.get("tempdir") is None:
        folder = tempfile.mkdtemp(prefix="pymp-", dir="/tmp")  # mode 0700
        multiprocessing.util.Finalize(
            None, shutil.rmtree, args=(folder,), kwargs={"ignore_errors": True}, exitpriority=-100
        )
        config["tempdir"] = folder


class ForkServer:
    """Forks robot (and beacon) processes from one preloaded server process."""

    def __init__(self, preload: list[str] | None = None) -> None:
        _short_socket_folder()
        os.environ.update(QUIET_THREADS)  # inherited by the server when it starts
        os.environ[FORK_SERVER_OF] = str(os.getpid())
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

    def stop(self) -> None:
        """Stop the fork server and the resource tracker now, once every child is gone,
        rather than when the launcher exits: a run leaves nothing behind when it returns.
        (Each closes its pipe's write end and waits for the process: multiprocessing's own
        private way, which its tests use.)"""
        server: Any = forkserver._forkserver  # private, so not in typeshed: Any
        tracker: Any = resource_tracker._resource_tracker
        server._stop()
        tracker._stop()
