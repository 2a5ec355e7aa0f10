"""An opt-in timeline of a process's ticks, as JSON lines (``--trace PATH``).

Times are ``time.monotonic()`` seconds: on Linux one clock for every process of the
machine, so the world's and the robot hosts' lines can be laid side by side
(``benchmarks/tick_timeline.py`` does). Off by default: a run without ``--trace`` pays one
``None`` check per tick. The file is its owner's only (bestofn_swarm/plumbing/private_files.py).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import IO, Any

from bestofn_swarm.plumbing.private_files import open_private

now = time.monotonic


class TraceWriter:
    """Appends one JSON object per line to a file; flushed when closed."""

    def __init__(self, path: str | Path) -> None:
        self._file: IO[str] | None = open_private(path, "w", 1 << 20)

    def write(self, **fields: Any) -> None:
        if self._file is not None:
            self._file.write(json.dumps(fields, separators=(",", ":")) + "\n")

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def open_trace(path: str | None) -> TraceWriter | None:
    """A writer for ``--trace PATH``, or None when tracing is off."""
    return TraceWriter(path) if path else None
