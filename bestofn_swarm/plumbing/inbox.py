"""The queue between Zenoh's callbacks and a process's one owning thread, with a memory cap.

Callbacks only copy bytes in; the owning thread checks and acts. Without a cap, anyone on
the router could grow a process without bound by sending faster than it checks. Past the
cap a message is dropped on arrival and counted by its source. Messages that come once
and are not sent again (liveliness: a robot that joins or leaves) may use a reserve of an
eighth of the cap beyond it, so that a flood of messages that are sent every tick does
not make a process miss one; the process's own control events (a stop) always go in.

The cap is on what a queued message really costs, not only on its bytes: every item is
charged ``ITEM_OVERHEAD_BYTES`` on top of the bytes it holds (payload, attachment, key),
empty ones included. Measured with tracemalloc (benchmarks/flood_memory.py prints it), a
queued message's objects (the inbox's tuple, the event or sample, its key string and the
headers of its bytes objects) take 160 to 370 bytes beyond its bytes in every process's
inbox; the charge rounds that up for the allocator's own slack.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Hashable
from typing import Final, Generic, Literal, TypeVar

Item = TypeVar("Item")

# What a process's inbox carries beside the samples of the key table: its stop signal.
Stop = Literal["stop"]
STOP: Final[Stop] = "stop"

DEFAULT_MAX_BYTES = 64 * 2**20
ITEM_OVERHEAD_BYTES = 512
RESERVE_FRACTION = 8  # the reserve for messages that come once: 1/8 of the cap


def message_bytes(payload: bytes, attachment: bytes | None = None, key: str = "") -> int:
    """The bytes a copied message holds: what ``BoundedInbox.put`` charges beyond its
    fixed overhead."""
    return len(payload) + len(attachment or b"") + len(key)


class BoundedInbox(Generic[Item]):
    """A SimpleQueue that holds at most ``max_bytes`` of messages at a time (and the
    reserve for messages that come once), each charged its bytes and
    ``ITEM_OVERHEAD_BYTES``."""

    def __init__(
        self, max_bytes: int = DEFAULT_MAX_BYTES, max_item_bytes: int | None = None
    ) -> None:
        self.max_bytes = max_bytes
        self.max_item_bytes = max_item_bytes  # a bigger message is never a valid one
        self.queued_bytes = 0
        self.peak_bytes = 0  # the most it held at once (benchmarks, tests)
        self.dropped: dict[Hashable, int] = {}
        self._queue: queue.SimpleQueue[tuple[int, Item]] = queue.SimpleQueue()
        self._lock = threading.Lock()

    @property
    def limit_bytes(self) -> int:
        """The most the inbox holds at once: its cap and the reserve (control items aside)."""
        return self.max_bytes + self.max_bytes // RESERVE_FRACTION

    def put(
        self,
        item: Item,
        size: int = 0,
        source: Hashable = None,
        *,
        once: bool = False,
        control: bool = False,
    ) -> bool:
        """Queue ``item``, which holds ``size`` bytes (``message_bytes``); False (dropped,
        counted under ``source``) if too big to be valid or over the cap. An item that
        comes ``once`` may use the reserve; a ``control`` item (the process's own stop)
        goes in whatever the inbox holds."""
        cost = ITEM_OVERHEAD_BYTES + size
        with self._lock:
            if not control:
                too_big = self.max_item_bytes is not None and size > self.max_item_bytes
                cap = self.limit_bytes if once else self.max_bytes
                if too_big or self.queued_bytes + cost > cap:
                    self.dropped[source] = self.dropped.get(source, 0) + 1
                    return False
            self.queued_bytes += cost
            self.peak_bytes = max(self.peak_bytes, self.queued_bytes)
        self._queue.put((cost, item))
        return True

    def get(self, timeout: float | None = None) -> Item:
        """The next item; ``queue.Empty`` after ``timeout`` seconds (None: wait for ever)."""
        cost, item = self._queue.get(timeout=timeout)
        with self._lock:
            self.queued_bytes -= cost
        return item

    def take_dropped(self, source: Hashable) -> int:
        """How many of ``source``'s messages were dropped since the last call."""
        with self._lock:
            return self.dropped.pop(source, 0)
