"""The controller's settings (the Section 5 behaviour), each defined once: type, range,
default and help (``bestofn_swarm/wire/settings.py``). ``robot-agent`` and ``swarm run`` make
their decision options from the flagged ones. Pure."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal

from msgspec import Meta

from bestofn_swarm.wire import settings
from bestofn_swarm.wire.settings import Flag
from robot_agent.core import decision, defence

# The built-in decision strategies: the paper's, and the ones it is compared with, which
# vote. A strategy or pooling operator may also be a plug-in (robot_agent/core/plugins.py).
StrategyName = Literal["paper", "dmvd", "dmmd", "dc"]
STRATEGIES: tuple[StrategyName, ...] = ("paper", "dmvd", "dmmd", "dc")
VOTING: tuple[StrategyName, ...] = ("dmvd", "dmmd", "dc")
# A liar's settle count: it never decides, so it keeps coming back to lie.
NEVER_SETTLE = 1_000_000

# A plug-in's name: a built-in's or an installed entry point's (``linear``), or where it is
# (``package.module:attribute``).
PLUGIN_NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*(:[A-Za-z_][A-Za-z0-9_.]*)?$"
PluginName = Annotated[str, Meta(pattern=PLUGIN_NAME_PATTERN, min_length=1, max_length=200)]

Seconds = Annotated[float, Meta(gt=0.0)]
Metres = Annotated[float, Meta(gt=0.0)]
MetresOrZero = Annotated[float, Meta(ge=0.0)]


def default_threshold(given: Mapping[str, Any]) -> float:
    """1, or 0.99 when alpha > 0: with alpha > 0 no option ever reaches probability 1."""
    return 1.0 if given.get("alpha", 0.0) == 0 else 0.99


@dataclass(frozen=True)
class ControllerConfig:
    """Parameters of the Section 5 behaviour (seconds, metres, radians)."""

    FLAG_GROUP: ClassVar[str] = "decision"

    alpha: Annotated[
        float,
        Meta(
            ge=0.0,
            le=0.5,
            description="evidence reliability parameter of Definition 1, in [0, 0.5]",
        ),
        Flag(),
    ] = 0.0
    threshold: Annotated[
        float,
        Meta(gt=0.0, le=1.0, description="decide when an option reaches this probability"),
        Flag(default_text="1, or 0.99 when alpha > 0", default_from=default_threshold),
    ] = 1.0
    pooling: Annotated[
        PluginName,
        Meta(
            description="opinion pooling at the nest: mprodop (Definition 2, evidence "
            "preserving), loglinear (diluting: neighbours' opinions count with weight "
            f"{decision.LOGLINEAR_NEIGHBOUR_WEIGHT:g}; use with --alpha > 0), or a plug-in: "
            "an installed one's name or package.module:attribute (swarm plugins lists them; "
            "docs/extending.md)"
        ),
        Flag(metavar="NAME"),
    ] = "mprodop"
    dwell: Annotated[
        Seconds,
        Meta(description="sim seconds at the nest broadcasting and listening"),
        Flag(),
    ] = 3.0
    broadcast_period: Annotated[
        Seconds,
        Meta(description="sim seconds between opinion broadcasts at the nest"),
        Flag(),
    ] = 0.5
    linger: Annotated[
        float,
        Meta(
            ge=0.0,
            description="sim seconds broadcasting at the nest after "
            "deciding, the paper's fix for isolated robots",
        ),
        Flag(),
    ] = 0.0
    strategy: Annotated[
        PluginName,
        Meta(
            description="the decision strategy: paper (negative updating and pooling), one "
            "the paper is compared with (docs/strategies.md): dmvd (voter), dmmd (majority), "
            "dc (direct comparison), or a plug-in: an installed one's name or "
            "package.module:attribute (swarm plugins lists them; docs/extending.md)"
        ),
        Flag(metavar="NAME"),
    ] = "paper"
    exploration: Annotated[
        Seconds,
        Meta(description="dmvd, dmmd, dc: mean sim seconds sensing a site (sigma)"),
        Flag(),
    ] = 10.0
    dissemination: Annotated[
        Seconds,
        Meta(
            description="dmvd, dmmd, dc: mean sim seconds broadcasting at the nest per unit "
            "of quality (g; dc: the mean itself)"
        ),
        Flag(),
    ] = 10.0
    listen: Annotated[
        Seconds,
        Meta(description="dmvd, dmmd, dc: sim seconds of listening at the end of dissemination"),
        Flag(name="listen-window"),
    ] = 3.0
    neighbours: Annotated[
        int,
        Meta(ge=1, le=1000, description="dmvd, dmmd, dc: the last G votes heard are used"),
        Flag(),
    ] = 2
    settle: Annotated[
        int,
        Meta(
            ge=1,
            le=NEVER_SETTLE,
            description="dmvd, dmmd, dc: decide after this many updates in a row that kept "
            "the site with no vote heard for another",
        ),
        Flag(),
    ] = 3
    defence: Annotated[
        defence.DefenceName,
        Meta(
            description="a defence against liars (docs/byzantine.md): none, or trimmed (a "
            "site is ruled out by peers' reports only when more than --trim peers rule it "
            "out; paper strategy, alpha 0)"
        ),
        Flag(),
    ] = "none"
    trim: Annotated[
        int,
        Meta(ge=0, le=1000, description="--defence trimmed: the F of W-MSR, liars tolerated"),
        Flag(),
    ] = 1
    view_distance: Annotated[
        Metres, Meta(description="metres from the wall to the robot centre when sensing")
    ] = 0.15
    beacon_timeout: Annotated[
        Seconds, Meta(description="heard the beacon within this many seconds: at the nest")
    ] = 1.5
    capture_timeout: Annotated[
        Seconds, Meta(description="seconds to wait for a requested frame")
    ] = 1.0
    capture_attempts: Annotated[
        int,
        Meta(ge=1, description="frames tried at one site before giving up the pair"),
    ] = 3
    view_tolerance: Annotated[
        Metres, Meta(description="metres from the viewpoint that count as there")
    ] = 0.015
    heading_tolerance: Annotated[
        float,
        Meta(gt=0.0, description="radians off the site's direction when capturing"),
    ] = 0.05
    wiggle: Annotated[
        float,
        Meta(
            ge=0.0,
            le=math.pi / 2,
            description="radians: a retry aims up to this far either side of the site",
        ),
    ] = 0.12
    nest_tolerance: Annotated[
        Metres, Meta(description="metres from the nest centre where a deaf robot waits")
    ] = 0.05
    stall_timeout: Annotated[
        Seconds,
        Meta(description="seconds without progress near a goal: take it as reached"),
    ] = 4.0
    near_distance: Annotated[
        Metres, Meta(description="metres: how near a stalled robot must be to sense from there")
    ] = 0.2
    travel_timeout: Annotated[
        Seconds,
        Meta(description="seconds for a leg to a site (or parking) before giving up"),
    ] = 120.0
    travel_crawl: Annotated[
        float,
        Meta(
            gt=0.0, description="m/s: a longer leg gets the time to cover its length at this speed"
        ),
    ] = 1 / 30
    park_clearance: Annotated[
        MetresOrZero, Meta(description="metres from the wall to the centre of a parking slot")
    ] = 0.06
    park_spacing: Annotated[
        Metres, Meta(description="metres between parking slots along the wall")
    ] = 0.1
    park_corridor: Annotated[
        MetresOrZero, Meta(description="metres either side of each site kept free of parking")
    ] = 0.11
    park_lane: Annotated[
        Metres,
        Meta(description="metres kept free between parked robots beyond the wall row"),
    ] = 0.2

    def __post_init__(self) -> None:
        settings.check(self)
        if self.alpha > 0.0 and self.threshold >= 1.0:
            raise ValueError(
                f"with alpha = {self.alpha} > 0 no option ever reaches probability 1: "
                "set threshold below 1 (e.g. 0.99)"
            )
        if self.defence != "none" and (self.strategy != "paper" or self.alpha != 0.0):
            raise ValueError(
                f"defence {self.defence} works on the paper's strategy with alpha = 0 (its "
                "opinions are sets of sites still possible); got strategy "
                f"{self.strategy}, alpha {self.alpha}"
            )

    def leg_allowance(self, length: float) -> float:
        """Sim seconds a leg of ``length`` metres may take before the robot gives it up:
        ``travel_timeout``, or for a long leg (the arena grows with the swarm) the time to
        cover it at ``travel_crawl``, so a crowd on the way slows a robot without making
        it give up."""
        return max(self.travel_timeout, length / self.travel_crawl)
