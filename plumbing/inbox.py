"""The queue between Zenoh's callbacks and a process's one owning thread, with a memory cap.

Callbacks only copy bytes in; the owning thread checks and acts. Without a cap, anyone on
the router could grow a process without bound by sending faster than it checks. Past the
cap a message is dropped on arrival and counted by its source; control events (stop,
liveliness) always go in.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Hashable
from typing import Generic, TypeVar

Item = TypeVar("Item")

DEFAULT_MAX_BYTES = 64 * 2**20


class BoundedInbox(Generic[Item]):
    """A SimpleQueue that holds at most ``max_bytes`` of payloads at a time."""

    def __init__(
        self, max_bytes: int = DEFAULT_MAX_BYTES, max_item_bytes: int | None = None
    ) -> None:
        self.max_bytes = max_bytes
        self.max_item_bytes = max_item_bytes  # a bigger message is never a valid one
        self.queued_bytes = 0
        self.dropped: dict[Hashable, int] = {}
        self._queue: queue.SimpleQueue[tuple[int, Item]] = queue.SimpleQueue()
        self._lock = threading.Lock()

    def put(self, item: Item, size: int = 0, source: Hashable = None) -> bool:
        """Queue ``item`` of ``size`` bytes; False (dropped, counted) if over the cap."""
        with self._lock:
            too_big = self.max_item_bytes is not None and size > self.max_item_bytes
            if too_big or (size and self.queued_bytes + size > self.max_bytes):
                self.dropped[source] = self.dropped.get(source, 0) + 1
                return False
            self.queued_bytes += size
        self._queue.put((size, item))
        return True

    def get(self, timeout: float | None = None) -> Item:
        """The next item; ``queue.Empty`` after ``timeout`` seconds (None: wait for ever)."""
        size, item = self._queue.get(timeout=timeout)
        if size:
            with self._lock:
                self.queued_bytes -= size
        return item

    def take_dropped(self, source: Hashable) -> int:
        """How many of ``source``'s messages were dropped since the last call."""
        with self._lock:
            return self.dropped.pop(source, 0)
