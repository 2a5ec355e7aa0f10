"""What the world counts of what went wrong, and the one place a rejection is logged."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

log = logging.getLogger("world_server")

MAX_LOGGED_KEYS = 1000  # keys whose first rejection is logged; then one line says so
ARRIVAL = "(arrival)"  # the key of what the transport dropped before it was checked


@dataclass
class Counters:
    rejected: int = 0  # messages refused: forged, foreign, malformed, out of bounds
    late: int = 0  # a sender's own messages that came after their tick (or after it left)
    stalls: int = 0  # lockstep ticks closed without every answer
    departures: int = 0  # robots and beacons whose liveliness token went while it ran
    missed: dict[str, int] = field(default_factory=dict)  # consecutive stalled ticks
    logged_keys: set[str] = field(default_factory=set)

    def reject(self, key: str, reason: object) -> None:
        """Count one refused message; log the first on each key (up to MAX_LOGGED_KEYS)."""
        self.rejected += 1
        logged = self.logged_keys
        if key in logged or len(logged) > MAX_LOGGED_KEYS:
            return
        logged.add(key)
        if len(logged) > MAX_LOGGED_KEYS:
            log.warning("rejected messages on more than %d keys: no longer logged", MAX_LOGGED_KEYS)
        else:
            log.warning(
                "rejected message on %s: %s (further ones on this key not logged)", key, reason
            )

    def dropped(self, count: int) -> None:
        """Count ``count`` messages the transport dropped on arrival (too big, or over its
        memory cap), with one log line."""
        if count:
            self.rejected += count - 1
            self.reject(ARRIVAL, f"{count} message(s) too big or over the inbox's cap")
