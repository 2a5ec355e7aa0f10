"""One thread's loop over link transports: the I/O that ``robot-agent --link`` and the bridge
share.

A ``Hub`` holds named transports (``transport.py``) and anything else the loop must wake
for (the bridge's wake-up socket). It opens each transport, and opens it again every
``REOPEN_EVERY`` seconds after it failed or closed (a serial adapter unplugged and put
back, a UDP socket in error); waits until something is readable or the earliest deadline
comes (its owner's, a paced line's, a reopening's), never longer than ``MAX_WAIT`` so a
stop is seen at once; hands on what arrived; sends and flushes; and at the end drains the
paced lines for at most ``DRAIN_WAIT``. Its owner keeps all the protocol: the hub only
moves frames, and says which transports closed (``take_closed``) so the owner can end
their sessions.
"""

from __future__ import annotations

import logging
import math
import selectors
import time
from collections.abc import Callable, Hashable
from typing import Any

from bestofn_swarm.link.io.transport import LinkClosedError, SerialLine, Transport

log = logging.getLogger("link.hub")

MAX_WAIT = 0.2  # seconds the loop waits at most (a stop is seen within it)
REOPEN_EVERY = 1.0  # seconds between attempts to open a transport that failed or closed
DRAIN_WAIT = 2.0  # seconds to let paced serial lines send what they hold (a goodbye)


class Hub:
    """Named link transports, and the waiting, reading and writing of one loop over them."""

    def __init__(self) -> None:
        self._selector = selectors.DefaultSelector()
        self._openers: dict[Hashable, Callable[[], Transport]] = {}
        self.transports: dict[Hashable, Transport] = {}
        self.reopen_at: dict[Hashable, float] = {}
        self._closed: list[tuple[Hashable, str]] = []

    # --- transports ----------------------------------------------------------------

    def add(
        self, name: Hashable, opener: Callable[[], Transport], *, must_open: bool = False
    ) -> None:
        """Keep the transport ``opener`` opens under ``name``: opened now, or retried every
        ``REOPEN_EVERY`` (with ``must_open``, a first failure is the caller's OSError: an
        address that cannot be bound is a mistake to report, not to wait out)."""
        self._openers[name] = opener
        if must_open:
            transport = opener()
            self.transports[name] = transport
            self._selector.register(transport, selectors.EVENT_READ, name)
        else:
            self._open(name, time.monotonic())

    def watch(self, readable: Any, name: Hashable) -> None:
        """Wake the loop when ``readable`` (a socket, anything with ``fileno``) is readable;
        ``poll`` then returns ``name``."""
        self._selector.register(readable, selectors.EVENT_READ, name)

    def is_open(self, name: Hashable) -> bool:
        return name in self.transports

    def _open(self, name: Hashable, now: float) -> None:
        try:
            transport = self._openers[name]()
        except OSError as error:
            log.warning("cannot open %s: %s; trying again in %g s", name, error, REOPEN_EVERY)
            self.reopen_at[name] = now + REOPEN_EVERY
            return
        self.reopen_at.pop(name, None)
        self.transports[name] = transport
        self._selector.register(transport, selectors.EVENT_READ, name)

    def _close(self, name: Hashable, why: str, now: float) -> None:
        transport = self.transports.pop(name, None)
        if transport is None:
            return
        self._selector.unregister(transport)
        transport.close()
        log.warning("%s closed: %s; opening it again in %g s", name, why, REOPEN_EVERY)
        self.reopen_at[name] = now + REOPEN_EVERY
        self._closed.append((name, why))

    def take_closed(self) -> list[tuple[Hashable, str]]:
        """The transports that closed since the last call, and why."""
        closed, self._closed = self._closed, []
        return closed

    # --- one turn of the loop ------------------------------------------------------

    def poll(self, deadline: float = math.inf) -> list[Hashable]:
        """Wait until something is readable or ``deadline`` (the owner's next, on the
        monotonic clock) or a transport's own; the names of what is readable. Transports
        due to be opened again are opened first."""
        now = time.monotonic()
        for name, at in list(self.reopen_at.items()):
            if now >= at:
                self._open(name, now)
        deadlines = [deadline, *self.reopen_at.values()]
        deadlines += [t.deadline for t in self.transports.values() if t.deadline is not None]
        wait = min(max(0.0, min(deadlines) - now), MAX_WAIT)
        return [key.data for key, _ in self._selector.select(wait)]

    def receive(self, name: Hashable, now: float) -> list[tuple[bytes, Hashable]]:
        """What came on transport ``name``, each frame with where it came from; nothing if
        the transport closed (``take_closed`` says so)."""
        transport = self.transports.get(name)
        if transport is None:
            return []
        try:
            return transport.receive(now)
        except (LinkClosedError, OSError) as error:
            self._close(name, str(error), now)
            return []

    def receiving(self, name: Hashable) -> bool:
        """Whether a frame is under way on serial line ``name`` (bytes of it read, its end
        not yet)."""
        transport = self.transports.get(name)
        return isinstance(transport, SerialLine) and transport.receiving

    def busy_until(self, name: Hashable) -> float | None:
        """When what was written to serial line ``name`` has all arrived (None: no serial
        line of that name is open)."""
        transport = self.transports.get(name)
        return transport.busy_until if isinstance(transport, SerialLine) else None

    def discard_waiting(self, name: Hashable, now: float) -> int:
        """On serial line ``name``, drop the frames not begun yet; how many."""
        transport = self.transports.get(name)
        return transport.discard_waiting(now) if isinstance(transport, SerialLine) else 0

    def send(self, name: Hashable, frame: bytes, target: Hashable, now: float) -> None:
        """Send ``frame`` (to ``target``, for a UDP server) on transport ``name``; dropped
        while it is closed, as on a line that is down."""
        transport = self.transports.get(name)
        if transport is None:
            return
        try:
            transport.send(frame, target, now)
        except (LinkClosedError, OSError) as error:
            self._close(name, str(error), now)

    def flush(self, now: float) -> None:
        """Let paced lines write what is due."""
        for name, transport in list(self.transports.items()):
            try:
                transport.flush(now)
            except (LinkClosedError, OSError) as error:
                self._close(name, str(error), now)

    # --- the end -------------------------------------------------------------------

    def drain(self) -> None:
        """Let paced lines send what they hold, for at most ``DRAIN_WAIT``."""
        deadline = time.monotonic() + DRAIN_WAIT
        while time.monotonic() < deadline:
            waiting = [t.deadline for t in self.transports.values() if t.deadline is not None]
            if not waiting:
                break
            time.sleep(max(0.0, min(min(waiting) - time.monotonic(), 0.05)))
            self.flush(time.monotonic())
        self.flush(time.monotonic())

    def close(self) -> None:
        for transport in self.transports.values():
            transport.close()
        self.transports.clear()
        self._selector.close()


__all__ = ["DRAIN_WAIT", "MAX_WAIT", "REOPEN_EVERY", "Hub"]
