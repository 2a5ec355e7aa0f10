"""What a ``robot-agent`` process is configured with, as one object (``RobotAgentConfig``):
``swarm run`` hands it over as ``--config JSON``; by hand, its options are made from the
settings' own definitions (``ControllerConfig``'s flagged settings and the ones below)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated

from msgspec import Meta

from bestofn_swarm.plumbing.settings_cli import Options
from bestofn_swarm.wire import protocol, settings
from bestofn_swarm.wire.settings import Flag
from robot_agent.core import byzantine
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.faults import FaultSpec
from robot_agent.core.plugin import ControllerChoice


@dataclass(frozen=True)
class RobotAgentConfig:
    """The configuration of one robot process: the run's seed, the controller's settings,
    which of its robots misbehave (a fault experiment), and which controller they run
    (with the run's plug-ins' sources)."""

    seed: Annotated[
        protocol.Seed | None,
        Meta(
            description="run seed: must be the world's (each robot's generator derives from "
            "the world's seed and its id)"
        ),
        Flag(default_text="the world's"),
    ] = None
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    byzantine: Annotated[
        tuple[byzantine.ByzantineRobot, ...],
        Meta(
            description="hosted robot ROBOT misbehaves: liar=SITE, inverted or silent (a "
            "fault experiment; swarm run --byzantine chooses a liar's site itself)"
        ),
        Flag(metavar="ROBOT:MODE"),
    ] = ()
    plugins: ControllerChoice = field(default_factory=ControllerChoice)
    faults: Annotated[
        tuple[FaultSpec, ...],
        Meta(
            description="the faults of its robots that change what their controllers do (a "
            "motor failure), as swarm run declared them (robot_agent/core/faults.py)"
        ),
    ] = ()

    def __post_init__(self) -> None:
        settings.check(self)


AGENT_OPTIONS = Options(RobotAgentConfig)


def agent_config(args: argparse.Namespace) -> RobotAgentConfig:
    """The RobotAgentConfig of ``robot-agent``'s options; ValueError if they do not fit."""
    config: RobotAgentConfig = AGENT_OPTIONS.build(args)
    return config


def controller_config(args: argparse.Namespace) -> ControllerConfig:
    """The ControllerConfig of ``robot-agent``'s options; ValueError if they do not fit."""
    return agent_config(args).controller


def hosted_byzantine(
    switches: Sequence[byzantine.ByzantineRobot], hosted: Sequence[int]
) -> dict[int, byzantine.Behaviour]:
    """The ``--byzantine`` switches by robot; ValueError unless each names a robot hosted
    here (by a fixed --id) once, and each liar names its site."""
    chosen: dict[int, byzantine.Behaviour] = {}
    for switch in switches:
        if switch.robot not in hosted:
            raise ValueError(f"--byzantine {switch}: robot {switch.robot} is not hosted here")
        if switch.robot in chosen:
            raise ValueError(f"--byzantine names robot {switch.robot} twice")
        if switch.behaviour.mode == "liar" and switch.behaviour.site is None:
            raise ValueError(f"--byzantine {switch}: name the site it claims, e.g. liar=0")
        chosen[switch.robot] = switch.behaviour
    return chosen
