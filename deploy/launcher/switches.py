"""The options that shape a run, by what they configure: the decision (every robot
process), the controller it runs (``--controller``, a plug-in point), the clock, radio
medium and camera (the world server), the nest beacon (as ``--beacon-*``) and the robot
faults (the launcher itself).

``swarm run`` and ``swarm experiment`` both take all of them. Each option is made from its
setting's one definition on the config dataclass (``bestofn_swarm/wire/settings.py``), and the
processes of a run are handed the configs these options make, each as one JSON object.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, NamedTuple

from msgspec import Meta

from bestofn_swarm.plumbing.settings_cli import Options
from bestofn_swarm.wire import settings
from bestofn_swarm.wire.settings import Flag
from nest_beacon.core.beacon import BeaconConfig
from robot_agent.core import byzantine, faults
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import ControllerChoice
from world_server.server.options import WorldServerConfig


class RobotAtTime(NamedTuple):
    """``ROBOT@SIMTIME``, e.g. ``3@60``: robot 3 at 60 s of sim time."""

    robot: int
    at: float  # sim seconds

    def __str__(self) -> str:  # the switch's own form, so that it can be passed on
        return f"{self.robot}@{settings.number_text(self.at)}"

    @classmethod
    def parse(cls, text: str) -> RobotAtTime:
        robot, sep, when = text.partition("@")
        try:
            if not sep or not (robot.isascii() and robot.isdigit()):
                raise ValueError
            at = float(when)
            if not 0.0 <= at < 1e9:
                raise ValueError
        except ValueError:
            raise ValueError(
                f"{text!r} is not ROBOT@SIMTIME, e.g. 3@60 (robot 3 at 60 sim seconds)"
            ) from None
        return cls(int(robot), at)


@dataclass(frozen=True)
class RobotFaults:
    """The faults of robots a run declares, one switch each (each a plug-in of both
    engines: robot_agent/core/faults.py), and its Byzantine robots."""

    FLAG_GROUP: ClassVar[str] = "robot faults"

    kill: Annotated[
        tuple[RobotAtTime, ...], Meta(description=faults.Kill.HELP), Flag(metavar="ROBOT@SIMTIME")
    ] = ()
    restart: Annotated[
        tuple[RobotAtTime, ...],
        Meta(description=faults.Restart.HELP),
        Flag(metavar="ROBOT@SIMTIME"),
    ] = ()
    motor_failure: Annotated[
        tuple[RobotAtTime, ...],
        Meta(description=faults.MotorFailure.HELP),
        Flag(metavar="ROBOT@SIMTIME"),
    ] = ()
    radio_failure: Annotated[
        tuple[RobotAtTime, ...],
        Meta(description=faults.RadioFailure.HELP),
        Flag(metavar="ROBOT@SIMTIME"),
    ] = ()
    byzantine: Annotated[
        tuple[byzantine.ByzantineRobot, ...],
        Meta(
            description="robot ROBOT misbehaves for the whole run: liar[=SITE] broadcasts "
            "certainty of SITE (default: a non-best site drawn from the seed), inverted "
            "eliminates the better site of each pair, silent never broadcasts; default "
            "mode liar. Consensus counts the honest robots (docs/byzantine.md)"
        ),
        Flag(metavar="ROBOT[:MODE]"),
    ] = ()

    def robot_faults(self) -> list[faults.RobotFault]:
        """Every fault of a robot declared, as the plug-in its switch names."""
        return [
            kind(robot, at)
            for kind in faults.FAULTS
            for robot, at in getattr(self, kind.SWITCH.replace("-", "_"))
        ]


CONTROLLER = Options(ControllerConfig)
PLUGINS = Options(ControllerChoice)
# The world's size, seed and run id are swarm run's own options; it starts one beacon. How
# the world ends the run, swarm run tells it from its own options and plan (plan.py).
WORLD = Options(
    WorldServerConfig,
    exclude={
        "--seed",
        "--sites",
        "--robots",
        "--start-timeout",
        "--beacons",
        "--timeout",
        "--stall-window",
        "--lost-robot",
        "--controller-settings",
        "--byzantine",
    },
)
BEACON = Options(BeaconConfig, prefix="beacon-", exclude={"--name"})
FAULTS = Options(RobotFaults)
SWITCHES = (CONTROLLER, PLUGINS, WORLD, BEACON, FAULTS)


def add_swarm_switches(parser: argparse.ArgumentParser) -> None:
    """Declare every run-shaping option (decision, clock, radio, camera, beacon, faults)."""
    for options in SWITCHES:
        options.add_to(parser)


def switches_argv(args: argparse.Namespace) -> list[str]:
    """The run-shaping options given, to pass on to ``swarm run``."""
    return [token for options in SWITCHES for token in options.argv(args)]


@dataclass(frozen=True)
class RunSwitches:
    """The configs a run's options make."""

    controller: ControllerConfig = field(default_factory=ControllerConfig)
    plugins: ControllerChoice = field(default_factory=ControllerChoice)
    world: WorldServerConfig = field(default_factory=WorldServerConfig)
    beacon: BeaconConfig = field(default_factory=BeaconConfig)
    faults: RobotFaults = field(default_factory=RobotFaults)

    def record(self) -> dict[str, Any]:
        """Every option's value, keyed like the option (``radio_range``), for the summary."""
        return {
            **CONTROLLER.record(self.controller),
            **PLUGINS.record(self.plugins),
            **WORLD.record(self.world),
            **BEACON.record(self.beacon),
            **FAULTS.record(self.faults),
        }


def run_switches(
    args: argparse.Namespace, *, run_id: str, seed: int, sites: int, robots: int
) -> RunSwitches:
    """The configs of the options in ``args`` for one run; ValueError if they do not fit."""
    world = {
        "world.run": run_id,
        "world.seed": seed,
        "world.num_sites": sites,
        "world.num_robots": robots,
    }
    return RunSwitches(
        controller=CONTROLLER.build(args),
        plugins=PLUGINS.build(args),
        world=WORLD.build(args, world),
        beacon=BEACON.build(args),
        faults=FAULTS.build(args),
    )
