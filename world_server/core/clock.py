"""Time for the world: the lockstep barrier and the real-time pacer (pure, no I/O).

Lockstep closes tick t only when every participant that was live when the tick opened
has answered it and every radio message it announced for the tick has arrived; a
participant that leaves (liveliness lost) stops being waited for. Real time closes a
tick when the wall clock says so, with whatever has arrived.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field


class _Answer:
    """One participant's answer to the tick (a plain class: a tick makes one per robot,
    and a dataclass's generated __init__ runs interpreted in the compiled cores)."""

    def __init__(self) -> None:
        self.radio_tx: int | None = None  # announced count; None until the answer arrives
        self.received_tx = 0

    @property
    def done(self) -> bool:
        return self.radio_tx is not None and self.received_tx >= self.radio_tx


@dataclass
class Barrier:
    """Book-keeping of one lockstep tick."""

    tick: int = -1
    answers: dict[str, _Answer] = field(default_factory=dict)
    # Participants not done yet: counted as they finish, so that asking whether the tick is
    # complete after each of a hundred answers costs nothing per participant.
    waiting: int = 0

    def open(self, tick: int, participants: Iterable[str]) -> None:
        self.tick = tick
        self.answers = {name: _Answer() for name in participants}
        self.waiting = len(self.answers)

    def answer(self, tick: int, who: str, radio_tx: int) -> bool:
        """Record ``who``'s answer to ``tick``; False if it is stale, foreign or repeated."""
        entry = self.answers.get(who)
        if tick != self.tick or entry is None or entry.radio_tx is not None:
            return False
        entry.radio_tx = radio_tx
        if entry.done:
            self.waiting -= 1
        return True

    def transmitted(self, tick: int, who: str) -> bool:
        """Count a radio message ``who`` sent during ``tick``; False if it does not belong."""
        entry = self.answers.get(who)
        if tick != self.tick or entry is None:
            return False
        was_done = entry.done
        entry.received_tx += 1
        if entry.done and not was_done:
            self.waiting -= 1
        return True

    def leave(self, who: str) -> None:
        entry = self.answers.pop(who, None)
        if entry is not None and not entry.done:
            self.waiting -= 1

    @property
    def complete(self) -> bool:
        return self.waiting == 0

    def missing(self) -> list[str]:
        return sorted(who for who, entry in self.answers.items() if not entry.done)


@dataclass
class Pacer:
    """Real-time pacing: tick k closes at ``start + k * dt / speed`` wall seconds."""

    dt: float
    speed: float = 1.0
    start: float | None = None

    def __post_init__(self) -> None:
        if self.dt <= 0 or self.speed <= 0:
            raise ValueError(f"dt and speed must be positive, got dt={self.dt} speed={self.speed}")

    def deadline(self, tick: int, now: float) -> float:
        """Wall time at which ``tick`` should close (the first call starts the clock)."""
        if self.start is None:
            self.start = now - tick * self.dt / self.speed
        return self.start + (tick + 1) * self.dt / self.speed
