"""Time on a link (pure): when the bytes of a paced serial line have left, a rate bound,
and the quantiles of a link's round trips. Times are given, never read."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

# --- pacing a serial line ------------------------------------------------------------------


BITS_PER_BYTE = 10  # 8N1: a start bit, eight data bits, a stop bit


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
