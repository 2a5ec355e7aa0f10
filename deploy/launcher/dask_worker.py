"""What ``swarm run --dask`` runs on a Dask worker: the processes of its share of the run.

A worker is started with this module preloaded, which gives ``dask worker`` the option
``--router ENDPOINT``, the Zenoh router of the worker's host::

    dask worker tcp://SCHEDULER:8786 --preload deploy.launcher.dask_worker \\
        --router tcp/127.0.0.1:7447

Without it (or without the preload) the router is read from the worker's host: the
variable ``BESTOFN_ROUTER``, else ``tcp/127.0.0.1:7447`` (a router of that host on Zenoh's
port, as deploy/README.md starts one).

``host_processes`` is the task: it starts the processes of its ``Share`` (robot-agent
processes, or the world and the beacon), each a client of the worker's router, with only
the run keys that process needs; then waits until they all exit (on the run's ending they
exit by themselves, with the run's exit code), or until the launcher asks them to stop
(the run's stop event), or until the scheduler can no longer be reached: then it stops
them (SIGTERM, then SIGKILL) rather than leave them behind. Each process also dies with
the worker (it asks Linux for a SIGTERM when its parent goes:
bestofn_swarm/plumbing/lifecycle.py), so a worker that is killed takes its processes with
it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from bestofn_swarm.plumbing.cliargs import LOCAL_ENDPOINT
from bestofn_swarm.plumbing.lifecycle import PARENT_ENV
from bestofn_swarm.plumbing.run_keys import KEYS_ENV

ROUTER_ENV = "BESTOFN_ROUTER"  # the router of a worker's host, when not given --router
RUN_ID_ENV = "BESTOFN_RUN_ID"  # as swarm run's own processes carry it (supervisor.py)
POLL = 0.2  # wall seconds between two looks at the processes
ASK_EVERY = 1.0  # wall seconds between two questions to the scheduler: stop?
LOST_AFTER = 10.0  # wall seconds without an answer from the scheduler: stop the processes
STOP_GRACE = 5.0  # wall seconds between SIGTERM and SIGKILL

_router: list[str] = []  # the worker's --router, set by dask_setup


def _setup(worker: Any, router: str | None = None) -> None:
    if router:
        _router[:] = [router]


try:  # ``dask worker --router``: a preload may add options as a Click command
    import click

    @click.command()
    @click.option(
        "--router",
        default=None,
        help="the Zenoh router of this worker's host, for swarm run --dask's processes",
    )
    def dask_setup(worker: Any, router: str | None) -> None:
        _setup(worker, router)

except ImportError:  # pragma: no cover - Click comes with Dask

    def dask_setup(worker: Any, router: str | None = None) -> None:  # type: ignore[misc]
        _setup(worker, router)


def router_of_host() -> str:
    """The Zenoh router this worker's processes connect to."""
    if _router:
        return _router[0]
    return os.environ.get(ROUTER_ENV) or LOCAL_ENDPOINT


@dataclass(frozen=True)
class Launch:
    """One process of a share: its name, ``python -m`` module and arguments (without its
    network options), and the run keys it holds (a key file's text; None: none)."""

    name: str
    module: str
    argv: list[str]
    keys: str | None = None


@dataclass(frozen=True)
class Share:
    """What one worker runs of a run."""

    run_id: str
    launches: list[Launch]
    stop_event: str  # the name of the Dask event the launcher sets to stop the run here
    robots: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class Hosted:
    """What became of a share: where it ran and how each process exited."""

    host: str
    worker: str
    codes: dict[str, int]
    stopped: bool  # asked to stop (or cut off from the scheduler), not ended by the run
    tails: dict[str, str] = field(default_factory=dict)  # the last lines each one wrote


def host_processes(share: Share) -> Hosted:
    """The task: run the share's processes until they exit (see the module's docstring)."""
    worker = _worker_address()
    _leave_the_pool()
    router = router_of_host()
    processes: dict[str, subprocess.Popen[bytes]] = {}
    with tempfile.TemporaryDirectory(prefix="bestofn-") as folder:
        logs = {launch.name: Path(folder) / f"{launch.name}.log" for launch in share.launches}
        try:
            for launch in share.launches:
                with logs[launch.name].open("wb") as log:
                    processes[launch.name] = _start(share.run_id, launch, router, log)
            stopped = _wait(processes, _stop_asked(share.stop_event))
        finally:
            _stop(processes)
        tails = {name: _tail(path) for name, path in logs.items() if path.exists()}
    codes = {name: process.returncode for name, process in processes.items()}
    return Hosted(socket.gethostname(), worker, codes, stopped, tails)


def _tail(path: Path, lines: int = 20) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


def _start(run_id: str, launch: Launch, router: str, log: IO[bytes]) -> subprocess.Popen[bytes]:
    env = {**os.environ, RUN_ID_ENV: run_id, PARENT_ENV: str(os.getpid())}
    env.pop(KEYS_ENV, None)
    if launch.keys is not None:
        env[KEYS_ENV] = launch.keys
    argv = [sys.executable, "-m", launch.module, *launch.argv]
    argv += ["--mode", "client", "--connect", router]
    return subprocess.Popen(
        argv,
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=log,
        stderr=log,
        start_new_session=True,  # a terminal's Ctrl-C on the worker reaches the worker only
    )


def _wait(
    processes: dict[str, subprocess.Popen[bytes]], stop_asked: Callable[[], bool | None]
) -> bool:
    """Until every process exited (False), or a stop was asked or the scheduler is lost
    (True)."""
    asked_at = answered_at = time.monotonic()
    while any(process.poll() is None for process in processes.values()):
        time.sleep(POLL)
        now = time.monotonic()
        if now - asked_at < ASK_EVERY:
            continue
        asked_at = now
        answer = stop_asked()
        if answer:
            return True
        if answer is not None:
            answered_at = now
        elif now - answered_at > LOST_AFTER:
            return True
    return False


def _stop_asked(name: str) -> Callable[[], bool | None]:
    """Whether the launcher set the run's stop event (None: the scheduler did not answer)."""
    from distributed import Event

    event = Event(name)

    def asked() -> bool | None:
        try:
            return bool(event.is_set())
        except Exception:  # the scheduler is gone or unreachable: no answer
            return None

    return asked


def _stop(processes: dict[str, subprocess.Popen[bytes]]) -> None:
    """SIGTERM what still runs, then SIGKILL what outlives the grace."""
    running = [process for process in processes.values() if process.poll() is None]
    for process in running:
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + STOP_GRACE
    for process in running:
        try:
            process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                process.kill()
            process.wait()


def _leave_the_pool() -> None:
    """The task only waits on processes: it gives its thread slot back to the worker, so
    that the worker's other share of the run (the world's, beside its robots) starts too."""
    try:
        from distributed import secede

        secede()
    except (ImportError, ValueError):  # not on a Dask worker (a test calls it directly)
        pass


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return ""


__all__ = ["Hosted", "Launch", "Share", "dask_setup", "host_processes", "router_of_host"]
