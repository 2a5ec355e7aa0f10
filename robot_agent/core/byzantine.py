"""Byzantine robots: an honest Controller wrapped so that it lies, for fault experiments.

A Byzantine robot has valid credentials and speaks the protocol correctly; only what it
says is wrong. Each behaviour is built from the honest ``Controller`` through its public
interface alone (constructor arguments, ``step``'s command), so the robot drives, senses
and keeps the nest's rhythm exactly like an honest one:

* ``liar=SITE``: every opinion it broadcasts is one-hot on SITE, flagged as decided (what
  an honest robot certain of SITE would send); under a voting strategy every vote is for
  SITE with the highest quality, 1. It never settles, so it keeps coming back to lie: its
  controller is built with alpha = 0.5 (Definition 1's worthless evidence; a voting
  robot: a settle count out of reach) and hears no opinions, so it never decides and
  moves like a robot still undecided for the whole run.
* ``inverted``: its camera reads every site's quality q as 1 - q, so each comparison
  eliminates the better site of the pair. Otherwise honest: it pools, decides and
  broadcasts what its (wrong) evidence gives.
* ``silent``: a dead transmitter. Honest in everything but it never broadcasts.

Pure: no Zenoh, no clock, no randomness beyond the controller's own RNG.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, cast, get_args

import msgspec
import numpy as np

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import ports, vision, voting
from robot_agent.core.controller import Controller, ControllerConfig, QualityEstimator
from robot_agent.core.wrapped import WrappedController

Mode = Literal["liar", "inverted", "silent"]
MODES: tuple[str, ...] = get_args(Mode)
DEFAULT_MODE: Mode = "liar"
# A liar's own evidence is worthless to it (Definition 1 with alpha = 0.5), so it never
# decides; a threshold below 1 is what ControllerConfig requires with alpha > 0.
_LIAR_ALPHA, _LIAR_THRESHOLD = 0.5, 0.99


@dataclass(frozen=True)
class Behaviour:
    """How a Byzantine robot misbehaves; ``site`` is the liar's claim (None: not chosen)."""

    mode: Mode
    site: int | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"unknown Byzantine mode {self.mode!r}: use one of {', '.join(MODES)}")
        if self.site is not None and self.mode != "liar":
            raise ValueError(f"only a liar claims a site, not {self.mode!r}")

    def __str__(self) -> str:
        return self.mode if self.site is None else f"{self.mode}={self.site}"

    @classmethod
    def parse(cls, text: str) -> Behaviour:
        """``liar``, ``liar=SITE``, ``inverted`` or ``silent``; ValueError otherwise."""
        mode, sep, site = text.partition("=")
        if mode not in MODES:
            raise ValueError(f"unknown Byzantine mode {mode!r}: use one of {', '.join(MODES)}")
        if not sep:
            return cls(cast(Mode, mode))  # one of MODES: checked above
        if mode != "liar":
            raise ValueError(f"only a liar claims a site: {text!r}")
        if not site.isdigit():
            raise ValueError(f"{text!r}: the claimed site must be a site id, e.g. liar=3")
        return cls("liar", int(site))


@dataclass(frozen=True)
class ByzantineRobot:
    """One ``--byzantine ROBOT[:MODE]`` switch: which robot, and how it misbehaves."""

    robot: int
    behaviour: Behaviour

    def __str__(self) -> str:
        return f"{self.robot}:{self.behaviour}"

    @classmethod
    def parse(cls, text: str) -> ByzantineRobot:
        """``ROBOT``, ``ROBOT:MODE`` or ``ROBOT:liar=SITE``; the mode defaults to liar."""
        robot, sep, mode = text.partition(":")
        if not robot.isdigit():
            raise ValueError(f"{text!r} is not ROBOT[:MODE], e.g. 3:liar or 3:inverted")
        behaviour = Behaviour.parse(mode) if sep else Behaviour(DEFAULT_MODE)
        return cls(int(robot), behaviour)


def default_liar_site(num_sites: int, best_site: int, seed: int) -> int:
    """The site a liar claims when none is given: one of the sites other than the best,
    drawn from the run seed. Every liar of a run claims the same one (liars that claim
    different sites contradict each other and cancel out under MProdOp); whoever starts
    the run knows the best site, the robot does not."""
    others = [site for site in range(num_sites) if site != best_site]
    return Stream.named(seed, "byzantine", "liar-site").choice(others)


def resolve_liar_sites(
    behaviours: Mapping[int, Behaviour], num_sites: int, best_site: int, seed: int
) -> dict[int, Behaviour]:
    """``behaviours`` with every liar's site chosen (``default_liar_site`` where
    none was given); ValueError for a claimed site that is not a site of the run."""
    resolved = {}
    for robot, behaviour in behaviours.items():
        if behaviour.mode == "liar":
            site = behaviour.site
            if site is None:
                site = default_liar_site(num_sites, best_site, seed)
            elif site >= num_sites:
                raise ValueError(
                    f"robot {robot} would claim site {site}: there are {num_sites} sites "
                    f"(0..{num_sites - 1})"
                )
            behaviour = Behaviour("liar", site)
        resolved[robot] = behaviour
    return resolved


def one_hot(site: int, num_sites: int) -> list[float]:
    return [1.0 if option == site else 0.0 for option in range(num_sites)]


def inverted_estimate(estimate: QualityEstimator = vision.estimate_quality) -> QualityEstimator:
    """``estimate`` with every quality q read as 1 - q (None, no view, stays None)."""

    def inverted(frame: np.ndarray) -> float | None:
        quality = estimate(frame)
        return None if quality is None else 1.0 - quality

    return inverted


class Liar(WrappedController):
    """An honest controller whose radio claims one site with certainty (see above)."""

    def __init__(self, controller: ports.RobotController, site: int, num_sites: int) -> None:
        if not 0 <= site < num_sites:
            raise ValueError(f"a liar's site {site} is outside 0..{num_sites - 1}")
        super().__init__(controller)
        self._site = site
        self._claim = protocol.wire_opinion(one_hot(site, num_sites))

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        beacon_only = [m for m in received if isinstance(m.payload, protocol.BeaconPayload)]
        command = self._controller.step(reading, beacon_only)
        if not command.broadcasts:
            return command
        return command.with_broadcasts(tuple(self._lie(payload) for payload in command.broadcasts))

    def _lie(self, payload: protocol.RobotBroadcast) -> protocol.RobotBroadcast:
        if isinstance(payload, protocol.VotePayload):
            return msgspec.structs.replace(payload, decided=True, site=self._site, quality=1.0)
        return msgspec.structs.replace(payload, decided=True, opinion=self._claim)


class Silent(WrappedController):
    """An honest controller whose broadcasts never leave the robot."""

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        return self._controller.step(reading, received).with_broadcasts(())


def build_controller(
    robot_id: int,
    world: protocol.WorldInfo,
    config: ControllerConfig,
    rng: Stream,
    behaviour: Behaviour | None = None,
    *,
    factory: Callable[..., ports.RobotController] = Controller,
) -> ports.RobotController:
    """Robot ``robot_id``'s controller (``factory`` makes it: the Controller, a class
    watching it, or what makes the run's plug-ins' controller, ``plugins.controller_maker``):
    honest when ``behaviour`` is None, else Byzantine. Robots are built with
    ``robot_agent.core.builder``, which seeds ``rng`` from the world."""
    if behaviour is None:
        return factory(robot_id, world, config, rng)
    if behaviour.mode == "inverted":
        return factory(robot_id, world, config, rng, estimate_quality=inverted_estimate())
    if behaviour.mode == "silent":
        return Silent(factory(robot_id, world, config, rng))
    if behaviour.site is None:
        raise ValueError("a liar needs the site it claims (liar=SITE)")
    if config.strategy in voting.VOTING:
        liar_config = voting.never_settles(config)
    else:  # its own evidence worthless; no defence, which needs alpha = 0, for what it hears
        liar_config = dataclasses.replace(
            config, alpha=_LIAR_ALPHA, threshold=_LIAR_THRESHOLD, defence="none"
        )
    return Liar(factory(robot_id, world, liar_config, rng), behaviour.site, len(world.sites))


__all__ = [
    "DEFAULT_MODE",
    "MODES",
    "Behaviour",
    "ByzantineRobot",
    "Liar",
    "Mode",
    "Silent",
    "build_controller",
    "default_liar_site",
    "inverted_estimate",
    "one_hot",
    "resolve_liar_sites",
]
