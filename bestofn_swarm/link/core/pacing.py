"""Time on a link (pure): when the bytes of a paced serial line have left, a rate bound,
and the quantiles of a link's round trips. Times are given, never read."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

# --- pacing a serial line ------------------------------------------------------------------


BITS_PER_BYTE = 10  # 8N1: a start bit, eight data bits, a stop bit
# A paced line hands bytes on as the line would carry them, in slices of this much line time
# (230 bytes at 115200 baud): the far end hears a long frame arriving, as on a real line,
# rather than nothing until its last byte.
SLICE_SECONDS = 0.02


@dataclass
class LinePacer:
    """When bytes written to a serial line at ``baud`` have all left: a frame is handed on
    once its last byte would have arrived, so a pseudo-terminal (which moves bytes at memory
    speed) behaves like the line it stands for."""

    baud: int
    free_at: float = 0.0

    def done_at(self, size: int, now: float) -> float:
        """Queue ``size`` bytes at ``now``: the time their last byte arrives."""
        self.free_at = max(now, self.free_at) + size * BITS_PER_BYTE / self.baud
        return self.free_at


@dataclass
class _Held:
    """One frame on a paced line: when its first and last bytes arrive, and how many of its
    bytes were handed on."""

    start: float
    done: float
    data: bytes
    handed: int = 0


class PacedLine:
    """Bytes written to a serial line at ``baud``, handed on when the line would have carried
    them (10 bits a byte, frame after frame): a frame's last byte at ``LinePacer.done_at``,
    the bytes before it in slices of ``SLICE_SECONDS`` on the way."""

    def __init__(self, baud: int) -> None:
        self.pacer = LinePacer(baud)
        self.slice = max(1, round(baud / BITS_PER_BYTE * SLICE_SECONDS))
        self.held: deque[_Held] = deque()
        self.held_bytes = 0

    def put(self, data: bytes, now: float) -> float:
        """Queue the bytes of one frame at ``now``: the time its last byte arrives."""
        start = max(now, self.pacer.free_at)
        done = self.pacer.done_at(len(data), now)
        self.held.append(_Held(start, done, data))
        self.held_bytes += len(data)
        return done

    def take(self, now: float) -> tuple[bytes, int]:
        """The bytes due by ``now`` that were not handed on yet, and how many frames they
        complete."""
        due: list[bytes] = []
        completed = 0
        while self.held:
            frame = self.held[0]
            if now >= frame.done:
                upto = len(frame.data)
            else:  # the bytes whose last bit is in by now (a millionth of a byte's slack)
                carried = (now - frame.start) * self.pacer.baud / BITS_PER_BYTE + 1e-6
                upto = min(len(frame.data), max(0, int(carried)))
            if upto > frame.handed:
                due.append(frame.data[frame.handed : upto])
                frame.handed = upto
            if frame.handed < len(frame.data):
                break
            self.held.popleft()
            self.held_bytes -= len(frame.data)
            completed += 1
        return b"".join(due), completed

    def discard_waiting(self, now: float) -> int:
        """Drop the frames not begun by ``now`` (the one under way goes on to its end, so
        the far end gets no broken frame); how many. The line is free again once the frame
        under way is done."""
        kept = 0
        while kept < len(self.held) and self.held[kept].start < now:
            kept += 1
        dropped = len(self.held) - kept
        for _ in range(dropped):
            self.held_bytes -= len(self.held.pop().data)
        self.pacer.free_at = self.held[-1].done if self.held else min(self.pacer.free_at, now)
        return dropped

    @property
    def deadline(self) -> float | None:
        """When ``take`` has the next slice of bytes (None: nothing held)."""
        if not self.held:
            return None
        frame = self.held[0]
        upto = frame.handed + self.slice
        if upto >= len(frame.data):
            return frame.done
        return frame.start + upto * BITS_PER_BYTE / self.pacer.baud

    @property
    def busy_until(self) -> float:
        """When the last byte queued so far arrives (in the past: the line is idle)."""
        return self.pacer.free_at


# --- rates ---------------------------------------------------------------------------------


@dataclass
class TokenBucket:
    """At most ``rate`` a second on average, ``burst`` at once."""

    rate: float
    burst: float
    tokens: float = -1.0
    at: float = 0.0

    def take(self, now: float, amount: float = 1.0) -> bool:
        if self.tokens < 0:
            self.tokens, self.at = self.burst, now
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        if self.tokens < amount:
            return False
        self.tokens -= amount
        return True


def percentile(values: Iterable[float], fraction: float) -> float | None:
    """The ``fraction`` quantile of ``values`` (nearest rank), or None if there are none."""
    ordered = sorted(values)
    if not ordered:
        return None
    rank = min(len(ordered) - 1, max(0, round(fraction * (len(ordered) - 1))))
    return ordered[rank]
