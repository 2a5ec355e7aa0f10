"""What a ``nest-beacon`` process is configured with, as one object (``NestBeaconConfig``):
``swarm run`` hands it over as ``--config JSON``; by hand, its options are made from the
settings' own definitions (``BeaconConfig``'s flagged settings and the seed)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from msgspec import Meta

from bestofn_swarm.plumbing.settings_cli import Options
from bestofn_swarm.wire import protocol, settings
from bestofn_swarm.wire.settings import Flag
from nest_beacon.core.beacon import BeaconConfig


@dataclass(frozen=True)
class NestBeaconConfig:
    """The beacon and the run seed its flakiness draws from."""

    seed: Annotated[
        protocol.Seed | None,
        Meta(description="run seed: must be the world's (the beacon's flakiness draws from it)"),
        Flag(default_text="the world's"),
    ] = None
    beacon: BeaconConfig = field(default_factory=BeaconConfig)

    def __post_init__(self) -> None:
        settings.check(self)


NEST_BEACON_OPTIONS = Options(NestBeaconConfig)
