"""A study's results file: one JSON line per finished run, appended as it finishes.

Each line is one run: its key, parameters and seed, the ``swarm run`` command that makes
it again (swarm runs), what it gave (``result``, everything a check compares), its wall
time, and what it was made with: its plug-ins (``plugins``: each one's name, distribution,
version and source hash; swarm runs), the commit (``deploy/reports/pages.py`` ``git_state``,
and whether the code that runs had uncommitted changes) and a hash of the run lock
(``requirements/run.lock``, the exact versions of numpy, pymunk, OpenCV...).

A line is written whole, flushed and synced to disk before the runner counts the run as
done, so a runner killed at any moment (SIGKILL included) loses at most the runs in
flight. A line cut short by such a kill is skipped with a warning when the file is read,
and the next writer first ends it with a newline, so its own lines stay whole. When a key
is in the file twice, the later line is the run.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from deploy.reports import pages

RUN_LOCK = "requirements/run.lock"
# The checkout of the code that makes the runs, wherever its results files are written.
CODE_ROOT = Path(__file__).resolve().parent.parent.parent


@dataclass
class Loaded:
    """The runs of a results file by key, and the lines that could not be read."""

    runs: dict[str, dict[str, Any]] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)  # one warning per unreadable line

    def records(self) -> list[dict[str, Any]]:
        return list(self.runs.values())


def load(path: Path) -> Loaded:
    """Every run of ``path`` (none if it does not exist). A line that is not a whole JSON
    object with a key (a run cut short by a kill) is skipped and named in ``skipped``."""
    loaded = Loaded()
    if not path.exists():
        return loaded
    lines = path.read_bytes().split(b"\n")
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            key = record["key"]
        except (ValueError, TypeError, KeyError):
            where = "its last line" if number >= len(lines) - 1 else f"line {number}"
            loaded.skipped.append(
                f"{path}: {where} is not a whole run ({len(line)} bytes; a run cut short "
                "when its runner was killed?): ignored"
            )
            continue
        loaded.runs[str(key)] = record
    return loaded


class Appender:
    """Appends runs to a results file, each line synced to disk before ``add`` returns."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        new = not path.exists()
        self._file: IO[bytes] = path.open("ab")
        if new:
            _sync_folder(path.parent)
        elif _ends_unfinished(path):
            self._file.write(b"\n")  # end a torn last line, so the next one stays whole

    def add(self, record: Mapping[str, Any]) -> None:
        self._file.write(json.dumps(record, separators=(",", ":")).encode() + b"\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Appender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _ends_unfinished(path: Path) -> bool:
    with path.open("rb") as file:
        file.seek(0, os.SEEK_END)
        if file.tell() == 0:
            return False
        file.seek(-1, os.SEEK_END)
        return file.read(1) != b"\n"


def _sync_folder(folder: Path) -> None:
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


# --- what a run was made with --------------------------------------------------------------


def lock_hash(root: Path) -> str | None:
    """The first 12 hex digits of the SHA-256 of the run lock (None without one)."""
    try:
        return hashlib.sha256((root / RUN_LOCK).read_bytes()).hexdigest()[:12]
    except OSError:
        return None


def provenance(root: Path = CODE_ROOT, ignore: tuple[str, ...] = ()) -> dict[str, Any]:
    """The commit of the checkout ``root`` (by default the one whose code runs), whether
    the code that runs had uncommitted changes, and the run lock's hash."""
    commit, dirty = pages.git_state(root, ignore)
    return {"commit": commit, "dirty": dirty, "lock": lock_hash(root)}


def made_with(records: Iterator[Mapping[str, Any]] | list[dict[str, Any]]) -> dict[str, int]:
    """How many runs each commit made (``abc1234``, ``abc1234+`` with uncommitted changes,
    ``unknown``), most first."""
    counts: dict[str, int] = {}
    for record in records:
        name = str(record.get("commit") or "unknown") + ("+" if record.get("dirty") else "")
        counts[name] = counts.get(name, 0) + 1
    return dict(sorted(counts.items(), key=lambda item: (-item[1], item[0])))


def locks(records: list[dict[str, Any]]) -> dict[str, int]:
    """How many runs each run lock made (``unknown`` where a run does not say)."""
    counts: dict[str, int] = {}
    for record in records:
        name = str(record.get("lock") or "unknown")
        counts[name] = counts.get(name, 0) + 1
    return dict(sorted(counts.items(), key=lambda item: (-item[1], item[0])))
