"""Stop signals as calls from a thread of their own, for every process of a run.

A Python signal handler runs in the main thread between any two bytecodes of whatever it
is doing, even inside a ``with lock:`` or inside the very call it would make: a handler
that sets a ``threading.Event`` or puts in an inbox takes a lock the interrupted code may
hold, and the process hangs for good. (A world server did: SIGTERMs in quick succession
after its launcher was SIGKILLed, the second handler waiting in ``Event.set`` for the
lock the first held beneath it.) So the handler only notes the first signal and puts it
in a queue whose ``put`` is reentrant (``queue.SimpleQueue``); a relay thread makes the
call, where taking a lock is safe. Later signals change nothing: each process's stop is
bounded in time, and its launcher SIGKILLs what does not stop.
"""

from __future__ import annotations

import queue
import signal
import threading
from collections.abc import Callable, Iterable
from types import FrameType
from typing import Any, Self

PROCESS_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """While entered, ``signals`` are noted instead of ending the process: the first
    one's number is ``received``, and ``notify`` (if given) hears it from this object's
    relay thread. Leaving restores the previous handlers and joins the relay."""

    def __init__(
        self,
        notify: Callable[[int], object] | None = None,
        signals: Iterable[int] = PROCESS_STOP_SIGNALS,
    ) -> None:
        self.received: int | None = None
        self._notify = notify
        self._signals = tuple(signals)
        self._rung: queue.SimpleQueue[int | None] = queue.SimpleQueue()
        self._relay: threading.Thread | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> Self:
        if self._notify is not None:
            # A daemon: a process that ends without leaving (sys.exit from its main) is
            # not held up by it.
            self._relay = threading.Thread(
                target=self._pass_on, args=(self._notify,), name="stop-signals", daemon=True
            )
            self._relay.start()
        for signum in self._signals:
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

    def _pass_on(self, notify: Callable[[int], object]) -> None:
        while (signum := self._rung.get()) is not None:
            notify(signum)


def on_stop_signals(
    notify: Callable[[int], object], signals: Iterable[int] = PROCESS_STOP_SIGNALS
) -> StopSignals:
    """For the rest of the process's life, the first of ``signals`` calls ``notify`` (with
    its number) from a relay thread, never from inside the interrupted code."""
    return StopSignals(notify, signals).__enter__()
