"""Child processes of a local run: start them, keep their logs, stop every one of them.

Children die with the launcher (plumbing.lifecycle), their stderr is kept in a
ring buffer so a crash can be explained, and ``stop_all`` ends each by pid: SIGTERM, a
grace period, then SIGKILL. Each child's stderr is read by a thread of its own (its
pump), which the group joins once the child is gone: no pump outlives its ``stop``, so
nothing passes on a child's lines after that. Each child runs in a process group of its
own: a Ctrl-C in the terminal, a closing terminal or ``timeout(1)`` signal the launcher's
whole group, and only the launcher should get that signal, so that it stops the run in
order.
"""

from __future__ import annotations

import collections
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from bestofn_swarm.plumbing.lifecycle import PARENT_ENV
from deploy.launcher.forking import QUIET_THREADS, ForkedProcess, ForkServer

LOG_LINES_KEPT = 200
# Wall seconds the group waits for the pumps of stopped children to read their last lines
# (each ends at its pipe's end of file, as soon as the child is gone).
PUMP_JOIN_WAIT = 5.0


@dataclass
class Child:
    name: str
    argv: list[str]
    process: subprocess.Popen[bytes] | ForkedProcess
    log: collections.deque[str] = field(
        default_factory=lambda: collections.deque(maxlen=LOG_LINES_KEPT)
    )
    expected_exit: bool = False
    on_line: Callable[[str, str], None] | None = None
    pump: threading.Thread | None = None  # reads stderr into ``log``; the group joins it

    @property
    def pid(self) -> int:
        return self.process.pid

    def alive(self) -> bool:
        return self.process.poll() is None

    def tail(self, lines: int = 20) -> str:
        return "\n".join(list(self.log)[-lines:])


class ProcessGroup:
    """Every process a run started, so that each is stopped by pid, whatever happens."""

    def __init__(self, on_line: Callable[[str, str], None] | None = None) -> None:
        self.children: list[Child] = []
        self.on_line = on_line
        self._fork_server: ForkServer | None = None

    def start(self, name: str, argv: Sequence[str], env: dict[str, str] | None = None) -> Child:
        process = subprocess.Popen(
            list(argv),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env={**os.environ, **QUIET_THREADS, PARENT_ENV: str(os.getpid()), **(env or {})},
            process_group=0,
        )
        return self._adopt(Child(name, list(argv), process, on_line=self.on_line))

    def fork(
        self, name: str, module: str, argv: Sequence[str], env: dict[str, str] | None = None
    ) -> Child:
        """Like ``start(python -m module argv, env)``, but forked from a preloaded server."""
        if self._fork_server is None:
            self._fork_server = ForkServer()
        process = self._fork_server.start(module, list(argv), env)
        return self._adopt(Child(name, [module, *argv], process, on_line=self.on_line))

    def _adopt(self, child: Child) -> Child:
        self.children.append(child)
        # A daemon only as a last resort: a pipe held open elsewhere must not keep the
        # launcher from exiting (the group joins it, for at most PUMP_JOIN_WAIT).
        child.pump = threading.Thread(
            target=self._pump, args=(child,), name=f"pump-{child.name}", daemon=True
        )
        child.pump.start()
        return child

    def _pump(self, child: Child) -> None:
        assert child.process.stderr is not None
        for raw in child.process.stderr:
            line = raw.decode("utf-8", "replace").rstrip()
            child.log.append(line)
            if child.on_line is not None:
                child.on_line(child.name, line)

    def crashed(self) -> list[Child]:
        """Children that exited without being asked to."""
        return [child for child in self.children if not child.alive() and not child.expected_exit]

    def stop(self, children: Sequence[Child], grace: float = 3.0) -> None:
        for child in children:
            child.expected_exit = True
            if child.alive():
                child.process.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace
        for child in children:
            try:
                child.process.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                child.process.kill()
                child.process.wait()
        self._join_pumps(children)

    def kill(self, child: Child) -> None:
        """SIGKILL one child on purpose (fault injection), and say it was meant."""
        child.expected_exit = True
        if child.alive():
            child.process.kill()
            child.process.wait()
        self._join_pumps([child])

    def _join_pumps(self, children: Sequence[Child]) -> None:
        """Wait until the pumps of these (exited) children have read their last lines."""
        deadline = time.monotonic() + PUMP_JOIN_WAIT
        for child in children:
            if child.pump is not None:
                child.pump.join(max(0.0, deadline - time.monotonic()))

    def stop_all(self, grace: float = 3.0) -> None:
        self.stop(self.children, grace)
        if self._fork_server is not None:
            self._fork_server.stop()
            self._fork_server = None


def python_module(module: str, *args: str) -> list[str]:
    return [sys.executable, "-m", module, *args]
