"""What a ``world-server`` process is configured with, as one object (``WorldServerConfig``):
the world (``WorldConfig``: layout, clock, radio medium and its faults, camera noise), how
the server paces and publishes it, and how it ends the run (``EndingRules``). ``swarm run``
hands it over as ``--config JSON``; by hand, its options are made from the settings' own
definitions."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Annotated, ClassVar

from msgspec import Meta

from bestofn_swarm.plumbing.settings_cli import Options
from bestofn_swarm.wire import settings
from bestofn_swarm.wire.settings import Flag
from world_server.core.world import WorldConfig
from world_server.observer.referee import EndingRules


@dataclass(frozen=True)
class WorldServerConfig:
    """The world, how the world server runs it, and how it ends the run."""

    FLAG_GROUP: ClassVar[str] = "clock"

    world: WorldConfig = field(default_factory=WorldConfig)
    rules: EndingRules = field(default_factory=EndingRules)
    speed: Annotated[
        float,
        Meta(
            ge=0.01,
            le=1000.0,
            description="real-time speed factor, realtime clock only; the world does not "
            "wait, so a robot answering later than a tick of wall time (dt / speed) drives on "
            "an old reading: many robot processes on few cores need a low factor "
            "(benchmarks/realtime_lag.py)",
        ),
        Flag(),
    ] = 1.0
    stall_timeout: Annotated[
        float,
        Meta(
            gt=0.0,
            description="lockstep: wall seconds to wait for a silent controller before "
            "closing the tick without it; after 3 such ticks it is not waited for until it "
            "answers again",
        ),
        Flag(),
    ] = 5.0
    state_every: Annotated[
        int, Meta(ge=1, description="publish world/state every N ticks"), Flag()
    ] = 10
    start_timeout: Annotated[
        float,
        Meta(gt=0.0, description="wall seconds to wait for the expected robots"),
        Flag(group="world"),
    ] = 60.0
    beacons: Annotated[
        int,
        Meta(ge=0, description="nest beacons to wait for before starting"),
        Flag(group="world"),
    ] = 1
    # swarm run --view holds a run for the first browser. It shapes no run, so it has no
    # option of its own (the launcher sets it in the configuration it hands over).
    hold: Annotated[
        bool,
        Meta(description="open tick 0 and wait there until the live page says play (viewer/pace)"),
    ] = False

    def __post_init__(self) -> None:
        settings.check(self)


WORLD_SERVER_OPTIONS = Options(WorldServerConfig)


def world_server_config(args: argparse.Namespace) -> WorldServerConfig:
    """The WorldServerConfig of ``world-server``'s options (its run id from ``--run-id``)."""
    config: WorldServerConfig = WORLD_SERVER_OPTIONS.build(args, {"world.run": args.run_id})
    return config
