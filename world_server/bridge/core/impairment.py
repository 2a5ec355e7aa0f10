"""A link made worse on purpose (``--link-delay``, ``--link-jitter``, ``--link-loss``): to
rehearse a bad Wi-Fi or a slow radio modem on a good loopback link. No I/O, no clock.

Each direction of a robot's link is impaired on its own: a frame is lost with probability
``loss``, and otherwise held for ``delay`` plus a uniform draw in ±``jitter`` (never less
than nothing). Frames keep their order, as on a serial line or most Wi-Fi links: one held
longer holds back those behind it. Every draw comes from a generator seeded by the run's
seed, the robot and the direction, so the same run is impaired the same way.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Hashable
from dataclasses import dataclass, field

from bestofn_swarm.wire.rng import Stream

MAX_HELD = 10_000  # frames one direction holds at most (past that one is lost, counted)


@dataclass(frozen=True)
class LinkImpairment:
    delay: float = 0.0  # seconds
    jitter: float = 0.0  # seconds either side of the delay
    loss: float = 0.0  # probability that a frame is lost

    def __post_init__(self) -> None:
        if self.delay < 0 or self.jitter < 0 or not 0 <= self.loss <= 1:
            raise ValueError("delay and jitter are at least 0, loss is in [0, 1]")

    @property
    def none(self) -> bool:
        return self.delay == 0 and self.jitter == 0 and self.loss == 0


@dataclass
class ImpairedDirection:
    """One direction of one link: frames in, frames out when their time comes."""

    impairment: LinkImpairment
    rng: Stream
    held: list[tuple[float, int, bytes, Hashable]] = field(default_factory=list)
    last_release: float = 0.0
    dropped: int = 0
    _order: itertools.count[int] = field(default_factory=itertools.count)

    @classmethod
    def seeded(
        cls, impairment: LinkImpairment, seed: int, robot: int, direction: str
    ) -> ImpairedDirection:
        return cls(impairment, Stream.named(seed, "link", robot, direction))

    def put(self, frame: bytes, where: Hashable, now: float) -> bool:
        """Hold a frame; False if it is lost."""
        impairment = self.impairment
        if impairment.loss and self.rng.random() < impairment.loss:
            self.dropped += 1
            return False
        if len(self.held) >= MAX_HELD:
            self.dropped += 1
            return False
        spread = self.rng.uniform(-impairment.jitter, impairment.jitter) if impairment.jitter else 0
        release = max(now + max(0.0, impairment.delay + spread), self.last_release)
        self.last_release = release
        heapq.heappush(self.held, (release, next(self._order), frame, where))
        return True

    def due(self, now: float) -> list[tuple[bytes, Hashable]]:
        """The frames whose time has come, in order."""
        out = []
        while self.held and self.held[0][0] <= now:
            _, _, frame, where = heapq.heappop(self.held)
            out.append((frame, where))
        return out

    @property
    def deadline(self) -> float | None:
        return self.held[0][0] if self.held else None
