"""The nest beacon's behaviour, without I/O: when to transmit, and what.

It transmits every ``period`` seconds of sim time. Outage windows (sim-time intervals)
silence it, and ``flaky`` makes each due transmission fail with a seeded probability,
so users can test robots against a beacon that comes and goes.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass, field

from robot_agent import protocol


@dataclass(frozen=True)
class BeaconConfig:
    name: str = "nest"
    period: float = 0.5  # seconds of sim time between transmissions
    outages: tuple[tuple[float, float], ...] = ()  # [start, end) sim-time windows
    flaky: float = 0.0  # probability that a due transmission is skipped

    def __post_init__(self) -> None:
        protocol.check_name(self.name, "beacon name")
        if self.name.isdigit():  # robots' radio names are their ids
            raise ValueError(f"beacon name {self.name!r} must not be all digits")
        if not self.period > 0:
            raise ValueError(f"beacon period must be positive, got {self.period}")
        if not 0.0 <= self.flaky <= 1.0:
            raise ValueError(f"flaky must be in [0, 1], got {self.flaky}")
        for start, end in self.outages:
            if not 0 <= start < end:
                raise ValueError(f"outage window [{start}, {end}) is empty or negative")


@dataclass
class Beacon:
    config: BeaconConfig
    rng: random.Random
    seq: int = 0
    next_due: float = 0.0
    skipped: int = field(default=0)

    def on_tick(self, t: float) -> list[protocol.BeaconPayload]:
        """The payloads to transmit in the tick that starts at sim time ``t``."""
        if t + 1e-9 < self.next_due:
            return []
        self.next_due = t + self.config.period
        if self.silenced(t) or (self.config.flaky and self.rng.random() < self.config.flaky):
            self.skipped += 1
            return []
        self.seq += 1
        return [protocol.BeaconPayload(v=protocol.VERSION, id=self.config.name, seq=self.seq)]

    def follow_new_world(self) -> None:
        """A restarted world counts sim time from zero again: transmit on its next tick."""
        self.next_due = 0.0

    def silenced(self, t: float) -> bool:
        return any(start <= t < end for start, end in self.config.outages)


def parse_outages(windows: Sequence[str]) -> tuple[tuple[float, float], ...]:
    """Parse ``START:END`` sim-second windows; ValueError says which one is wrong."""
    parsed = []
    for window in windows:
        start, sep, end = window.partition(":")
        try:
            if not sep:
                raise ValueError
            parsed.append((float(start), float(end)))
        except ValueError:
            raise ValueError(f"outage {window!r} is not START:END in sim seconds") from None
    return tuple(parsed)
