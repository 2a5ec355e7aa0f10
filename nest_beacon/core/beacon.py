"""The nest beacon's behaviour, without I/O: when to transmit, and what.

It transmits every ``period`` seconds of sim time. Outage windows (sim-time intervals)
silence it, and ``flaky`` makes each due transmission fail with a seeded probability,
so users can test robots against a beacon that comes and goes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, ClassVar

from msgspec import Meta

from bestofn_swarm.wire import names, protocol, settings
from bestofn_swarm.wire.rng import Stream
from bestofn_swarm.wire.settings import Flag

SimTime = Annotated[float, Meta(ge=0.0)]


Outage = tuple[SimTime, SimTime]  # [start, end) in sim seconds


@dataclass(frozen=True)
class BeaconConfig:
    """The beacon's settings; its flagged ones are options of nest-beacon and (as
    --beacon-*) of swarm run."""

    FLAG_GROUP: ClassVar[str] = "nest beacon"

    name: Annotated[
        names.Name,
        Meta(description="beacon id on the radio; not all digits"),
        Flag(parse=names.check_beacon_name),
    ] = names.DEFAULT_BEACON
    period: Annotated[
        float,
        Meta(gt=0.0, description="sim seconds between beacon transmissions"),
        Flag(),
    ] = 0.5
    outages: Annotated[
        tuple[Outage, ...],
        Meta(description="the beacon is silent from START to END sim seconds"),
        Flag(name="outage", metavar="START:END"),
    ] = ()
    flaky: Annotated[
        float,
        Meta(
            ge=0.0,
            le=1.0,
            description="probability that a due beacon transmission is skipped",
        ),
        Flag(),
    ] = 0.0

    def __post_init__(self) -> None:
        settings.check(self)
        names.check_beacon_name(self.name)
        for start, end in self.outages:
            if not start < end:
                raise ValueError(f"outage {start:g}:{end:g} must have START < END")


@dataclass
class Beacon:
    config: BeaconConfig
    rng: Stream
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

    def next_tick(self, tick: int, dt: float) -> int:
        """The first tick after ``tick`` whose sim time (``tick * dt``, as the world counts
        it) has a transmission due: ``on_tick`` does nothing on the ticks in between, so a
        world in lockstep need not wait for the beacon on them."""
        # A start below the answer (by a tick's margin for rounding), then step to it.
        after = max(tick + 1, int((self.next_due - 1e-9) / dt) - 1)
        while after * dt + 1e-9 < self.next_due:
            after += 1
        return after

    def follow_new_world(self) -> None:
        """A restarted world counts sim time from zero again: transmit on its next tick."""
        self.next_due = 0.0

    def silenced(self, t: float) -> bool:
        return any(start <= t < end for start, end in self.config.outages)
