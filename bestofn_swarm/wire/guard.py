"""What a receiver checks before it believes a message that decoded (no I/O).

A tag says who sent a message; these checks say whether it fits what the receiver
already knows: ticks move forward by a bounded step, sim time is the tick's, and only
one world server is followed at a time. They hold with or without run keys, so an
unauthenticated run is not frozen by one absurd but well-formed message either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

TICK_WINDOW = 100  # how far ahead of the last tick a message may be (10 s at dt = 0.1)


@dataclass
class TickWindow:
    """Ticks a receiver accepts: any to begin with, then only a bounded step ahead."""

    window: int = TICK_WINDOW
    last: int = -1  # the last tick acted on; -1 before the first
    rejoined: bool = False  # the next tick may be any distance ahead (see rejoin)

    def refuses(self, tick: int) -> str | None:
        """Why ``tick`` is not believable now, or None."""
        if self.last >= 0 and not self.rejoined and tick > self.last + self.window:
            return f"tick {tick} is more than {self.window} ahead of tick {self.last}"
        return None

    def acted(self, tick: int) -> None:
        self.last, self.rejoined = tick, False

    def rejoin(self) -> None:
        """The sender went on while this receiver was cut off from it: take its next tick
        however far ahead, but still none already acted on (a replay stays refused)."""
        self.rejoined = True

    def ahead(self, tick: int) -> bool:
        """Whether ``tick`` is still to come (not acted on yet)."""
        return tick > self.last


def realtime_refused(
    sent: tuple[int, int], last: tuple[int, int] | None, tick: int, window: int = TICK_WINDOW
) -> tuple[str, bool] | None:
    """Why a sender's message stamped ``sent`` = (its tick, its number in that tick's
    order) is not fresh in a real-time world at ``tick`` whose last message from that
    sender was ``last``, and whether it is only late (an honest sender that lags); None
    if it is fresh. A sender's messages come in order, so one not after its last is a
    replay; one for a tick the world has not reached cannot be; one more than ``window``
    ticks behind the world is late."""
    if sent[0] > tick:
        return f"tick {sent[0]} is ahead of the world's tick {tick}", False
    if last is not None and sent <= last:
        return f"stamped {sent}, not after the last taken {last}: a replay", False
    if sent[0] < tick - window:
        return f"tick {sent[0]} is more than {window} behind the world's tick {tick}", True
    return None


def time_refused(tick: int, t: float, dt: float) -> str | None:
    """Why sim time ``t`` cannot be that of ``tick`` in a world of step ``dt``, or None."""
    expected = tick * dt
    if not math.isclose(t, expected, rel_tol=1e-9, abs_tol=1e-6):
        return f"sim time {t!r} is not tick {tick} x {dt}"
    return None


@dataclass
class WorldFollower:
    """Which world server to follow, from the liveliness tokens ``alive/world/<instance>``.

    A run has one world server. A second instance that appears while the followed one is
    still alive is someone else's token, not a restart: it is ignored. Only once the
    followed instance is gone does a new one count as the world restarted.
    """

    followed: str | None = None
    present: set[str] = field(default_factory=set)

    def appeared(self, instance: str) -> Literal["new", "back"] | None:
        """Note a token: "new" when it is a new world to follow after the old one left;
        "back" when it is the followed world's again after it went (the same world, whose
        link was down longer than Zenoh's lease: a frozen process; it ticked on meanwhile)."""
        back = instance == self.followed and self.lost
        self.present.add(instance)
        if self.followed is None:
            self.followed = instance
            return None
        if instance == self.followed:
            return "back" if back else None
        if self.followed in self.present:
            return None
        self.followed = instance
        return "new"

    def vanished(self, instance: str) -> bool:
        """Note a token gone; True when it was the followed world."""
        self.present.discard(instance)
        return instance == self.followed

    @property
    def lost(self) -> bool:
        """Whether the followed world's token went and has not come back."""
        return self.followed is not None and self.followed not in self.present

    @property
    def impostors(self) -> list[str]:
        """Instances with a token that are not the followed world."""
        return sorted(self.present - {self.followed} if self.followed else self.present)
