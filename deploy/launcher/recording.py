"""The launcher's handshake with the recorder at the end of a run: hand it the summary on
``recorder/finish`` and wait until it confirms the file is complete, as long as that is
worth waiting for (``RecorderProgress``)."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import zenoh

from bestofn_swarm.plumbing.world_info import ask
from bestofn_swarm.wire import auth, keyspace, names

# Waiting for the recorder after the run: given up once its file has not grown for
# RECORDER_PATIENCE wall seconds, and after RECORDER_LONGEST_WAIT in any case.
RECORDER_PATIENCE = 60.0
RECORDER_LONGEST_WAIT = 3600.0
RECORDER_REPORT_EVERY = 10.0


class RecorderProgress:
    """Whether waiting for the recorder still makes sense: it is alive and its file grew
    within ``patience`` wall seconds (of ``clock``). A recorder at low priority falls
    behind a large swarm (docs/recording.md) and catches up once the swarm stops; ``say``
    hears how far it got every ``RECORDER_REPORT_EVERY`` seconds."""

    def __init__(
        self,
        path: Path,
        alive: Callable[[], bool],
        say: Callable[[str], None] | None = None,
        patience: float = RECORDER_PATIENCE,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.path = path
        self.alive = alive
        self.say = say
        self.patience = patience
        self.clock = clock
        self.started = self.grew_at = self.reported_at = clock()
        self.size = self._size()
        self.died = False
        self.gave_up = False  # its file stopped growing for ``patience`` seconds

    def _size(self) -> int:
        try:
            return self.path.stat().st_size
        except OSError:
            return 0

    def __call__(self) -> bool:
        now = self.clock()
        if not self.alive():
            self.died = True
            return False
        size = self._size()
        if size > self.size:
            self.size, self.grew_at = size, now
        if self.say is not None and now - self.reported_at >= RECORDER_REPORT_EVERY:
            self.reported_at = now
            self.say(
                f"waiting for the recorder to write what it fell behind on: "
                f"{self.size / 2**20:.0f} MB written, {now - self.started:.0f} s so far"
            )
        self.gave_up = now - self.grew_at >= self.patience
        return not self.gave_up

    def why_not(self, refused: Sequence[str] = ()) -> str:
        """Why the recorder did not confirm, once its finish query came back without an
        answer (``refused``: what came back instead)."""
        if self.died:
            return "exited before it confirmed the file"
        if self.gave_up:
            return (
                f"did not confirm the file: it did not grow for {self.patience:g} s "
                f"({self.size / 2**20:.0f} MB written)"
            )
        waited = self.clock() - self.started
        said = f": {refused[0]}" if refused else ""
        return f"its finish query came back unanswered after {waited:.1f} s{said}"


def finish_recording(
    session: zenoh.Session,
    keys: keyspace.Keys,
    keyring: auth.Keyring | None,
    waiting: RecorderProgress,
    summary: dict[str, Any],
) -> str | None:
    """Hand the summary to the recorder and wait until the file is complete: as long as
    the recorder is alive and its file grows (it writes what it fell behind on first).
    None once it confirmed; else why not."""
    answers, refused = ask(
        session,
        keys.of(keyspace.RECORDER_FINISH),
        keyring,
        names.LAUNCHER,
        payload=json.dumps(summary).encode(),
        timeout=RECORDER_LONGEST_WAIT,
        worth_waiting=waiting,
    )
    return None if answers else waiting.why_not(refused)
