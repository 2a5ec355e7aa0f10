"""Stop signals as events: SIGINT, SIGTERM and SIGHUP end a run in order, like Ctrl-C
always did, instead of killing ``swarm run`` where it stands.

A signal handler runs in the main thread between any two bytecodes of whatever it is
doing, so it does as little as can be done safely there: it notes the first signal and
puts it in a queue whose ``put`` is reentrant (``queue.SimpleQueue``); a thread of its
own passes it on (to the launcher's event inbox, which takes locks). Nothing is raised
into the interrupted code: the main loop sees the signal at its next look and ends the
run in order. Later signals change nothing: the ending is bounded in time (processes get
a grace period, then SIGKILL), and cutting it short would lose the summary and the
recording's end. SIGKILL needs no handler: every child dies with the launcher
(plumbing/lifecycle.py).
"""

from __future__ import annotations

import queue
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass
from types import FrameType
from typing import Any

from wire.endings import StopSignal

# The handled signals, in the order wire.endings lists them (SIGINT, SIGTERM, SIGHUP).
STOP_SIGNALS = tuple(signal.Signals(stop) for stop in StopSignal)


@dataclass(frozen=True)
class Signalled:
    """A stop signal, as an event in the launcher's inbox."""

    signum: int


class StopSignals:
    """While entered, the stop signals are noted instead of ending the process: the first
    one's number is ``received``, and ``notify`` (if given) hears it from this object's
    relay thread. Leaving restores the previous handlers and joins the relay."""

    def __init__(self, notify: Callable[[int], None] | None = None) -> None:
        self.received: int | None = None
        self._notify = notify
        self._rung: queue.SimpleQueue[int | None] = queue.SimpleQueue()
        self._relay: threading.Thread | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
        if self._notify is not None:
            self._relay = threading.Thread(
                target=self._pass_on, args=(self._notify,), name="stop-signals"
            )
            self._relay.start()
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._on_signal)
        return self

    def __exit__(self, *exc_info: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
        if self._relay is not None:
            self._rung.put(None)  # the relay's last item: it returns
            self._relay.join()
            self._relay = None

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self.received is None:
            self.received = signum
            self._rung.put(signum)

    def _pass_on(self, notify: Callable[[int], None]) -> None:
        while (signum := self._rung.get()) is not None:
            notify(signum)
