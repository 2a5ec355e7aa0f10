"""One runner per results file: an exclusive lock, taken before a runner decides which
runs are missing and held until it ends.

Two runners of one study on one results file would each make every missing run (and
write each twice). The lock is ``flock`` on a file beside the results file
(``NAME.jsonl.lock``), so it goes with its holder, however that ends (SIGKILL included);
the file says who holds it (pid, host, since when), for the runner that is refused.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path


class BusyError(Exception):
    """Another runner holds the lock: the message says who."""


def lock_path(results: Path) -> Path:
    return results.with_name(results.name + ".lock")


def holder(path: Path) -> str:
    """Who holds the lock at ``path``, as its holder wrote it."""
    try:
        said = path.read_text().strip()
    except OSError:
        said = ""
    return said or "another runner (it has not said who yet)"


@contextlib.contextmanager
def holding(
    results: Path, *, wait: bool = False, waiting: Callable[[str], None] | None = None
) -> Iterator[None]:
    """Hold the lock of the results file ``results`` for the block. Busy when another
    runner holds it, unless ``wait``: then ``waiting(holder)`` is called once and the lock
    is waited for."""
    path = lock_path(results)
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                raise BusyError(
                    f"{results} is being made by {holder(path)}: wait for it to end, or give --wait"
                ) from None
            if waiting is not None:
                waiting(holder(path))
            fcntl.flock(descriptor, fcntl.LOCK_EX)
        stamp = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime())
        os.ftruncate(descriptor, 0)
        os.pwrite(
            descriptor, f"pid {os.getpid()} on {socket.gethostname()} since {stamp}\n".encode(), 0
        )
        yield
    finally:
        os.close(descriptor)  # and with it the lock
