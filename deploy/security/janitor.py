"""A run's private directory (its router's socket; in secure mode the certificates and
their private keys) goes however the process that made it ends, SIGKILL included.

``PrivateDirectory.create`` makes the directory and starts a janitor for it: a small
process (``python -m deploy.security.janitor DIR``) that waits on a pipe whose only write end the
maker holds. However the maker ends, the kernel closes that end, the janitor reads end of
file and removes the directory. It runs in a session of its own, so a signal to the
maker's process group (a terminal's Ctrl-C, timeout(1)) reaches it only through that
pipe. A maker that ends in order removes the directory itself first (``close``).

Should the janitor be killed as well (``kill -9`` of every process of the user), the next
directory made in the same place sweeps away those whose maker is gone (``sweep``): each
directory names its maker (pid and start time, so that a reused pid does not count as
alive) in its ``maker`` file.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

PREFIX = "bestofn-"
MAKER_FILE = "maker"


def process_start(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot), or None if it is gone
    (or this is not Linux)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # The command name (field 2) may hold spaces and parentheses: count after its end.
    fields = stat[stat.rindex(")") + 2 :].split()
    return fields[19] if len(fields) > 19 else None  # field 22 of proc(5)


def maker_alive(directory: Path) -> bool:
    """Whether the process named in the directory's maker file still runs (True when the
    file cannot be read: the directory is then not ours to judge)."""
    try:
        pid_text, _, start = (directory / MAKER_FILE).read_text().partition(" ")
        pid = int(pid_text)
    except (OSError, ValueError):
        return True
    return process_start(pid) == start.strip()


def sweep(base: Path) -> list[Path]:
    """Remove the run directories in ``base`` that belong to this user and whose maker is
    gone; the directories removed."""
    removed = []
    with contextlib.suppress(OSError):
        for directory in base.glob(f"{PREFIX}*"):
            try:
                if directory.lstat().st_uid != os.getuid() or not directory.is_dir():
                    continue
            except OSError:
                continue
            if not maker_alive(directory):
                shutil.rmtree(directory, ignore_errors=True)
                removed.append(directory)
    return removed


@dataclass
class PrivateDirectory:
    """A directory only this user can enter (mkdtemp makes it 0700), and its janitor."""

    path: Path
    janitor: subprocess.Popen[bytes] | None

    @classmethod
    def create(cls, base: str, *, janitor: bool = True) -> PrivateDirectory:
        """The directory in ``base``, after a sweep of those left there; without
        ``janitor`` (tests of the fast tier start no process) only the sweep covers it."""
        sweep(Path(base))
        path = Path(tempfile.mkdtemp(prefix=PREFIX, dir=base))
        start = process_start(os.getpid())
        if start is not None:
            (path / MAKER_FILE).write_text(f"{os.getpid()} {start}\n")
        if not janitor:
            return cls(path, None)
        watcher: subprocess.Popen[bytes] | None
        try:
            watcher = subprocess.Popen(
                [sys.executable, "-m", "deploy.security.janitor", str(path)],
                env=_janitor_environment(),
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        except OSError:  # no janitor: the next run's sweep removes what a crash leaves
            watcher = None
        return cls(path, watcher)

    def close(self) -> None:
        """Remove the directory, and let the janitor go."""
        shutil.rmtree(self.path, ignore_errors=True)
        janitor, self.janitor = self.janitor, None
        if janitor is not None and janitor.stdin is not None:
            janitor.stdin.close()
            with contextlib.suppress(subprocess.TimeoutExpired):
                janitor.wait(timeout=5.0)


def _janitor_environment() -> dict[str, str]:
    """The maker's environment, less the run's own variables (``BESTOFN_*``): the janitor
    runs no part of the run, and tests count a run's processes by its run id there."""
    return {name: value for name, value in os.environ.items() if not name.startswith("BESTOFN_")}


def main(argv: list[str]) -> int:
    """The janitor: wait for end of file on stdin, then remove the directory."""
    if len(argv) != 1:
        print("usage: python -m deploy.security.janitor DIRECTORY", file=sys.stderr)
        return 2
    while sys.stdin.buffer.read(4096):
        pass
    shutil.rmtree(argv[0], ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
