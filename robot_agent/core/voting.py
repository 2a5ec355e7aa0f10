"""The voting strategies the paper is compared with: DMVD, DMMD and DC (pure).

Each robot holds one site as its opinion (not a probability vector) and cycles through
two states, after Valentini et al.:

* **exploration**: it goes to the site it favours and senses it for a time drawn from an
  exponential with mean sigma (``config.exploration``); the camera gives its quality
  estimate rho-hat;
* **dissemination**: it goes to the nest and broadcasts its vote (site and rho-hat) for
  an exponential time with mean rho-hat * g (``config.dissemination``; the *direct
  modulation* of positive feedback), plus ``config.listen`` seconds in which it also
  listens; at the end it applies its decision rule to the votes of the last
  ``config.neighbours`` (G) robots heard in those seconds, and explores the site it then
  favours.

The rules (``update``):

* ``dmvd``, Direct Modulation of Voter-based Decisions (Valentini, Hamann and Dorigo,
  AAMAS 2014, "Self-organized collective decision making: the weighted voter model"):
  adopt the site of one neighbour drawn at random;
* ``dmmd``, Direct Modulation of Majority-based Decisions (Valentini, Hamann and Dorigo,
  AAMAS 2015, "Efficient decision-making in a self-organizing robot swarm: on the speed
  versus accuracy trade-off"; Valentini, Ferrante, Hamann and Dorigo, JAAMAS 30(3), 2016,
  "Collective decision with 100 Kilobots"): adopt the site most of itself and its G
  neighbours favour (a tie: one of the tied sites at random);
* ``dc``, Direct Comparison (Valentini, Brambilla, Hamann and Dorigo, ANTS 2016,
  "Collective perception of environmental features in a robot swarm"): compare its own
  estimate with that of one neighbour drawn at random and adopt the neighbour's site if
  the neighbour's estimate is higher. Its dissemination is not modulated: the mean is g
  whatever rho-hat is (docs/strategies.md says why).

What the papers leave to the arena of sites and the nest beacon, decided here (each
choice with its reason in docs/strategies.md): the swarm starts spread evenly over the
sites (robot r favours site r mod n); robots stand still at the nest while they
disseminate, as the paper's robots do while they pool; and, since this project's robots
each decide and then park, a robot *decides* once its update has left its site unchanged
``config.settle`` times in a row with no vote heard for another site.

Randomness: only from the controller's RNG (exploration and dissemination times, the
voter's and comparison's neighbour, a majority's tie).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.compiled import mypyc_attr
from bestofn_swarm.wire.rng import Stream
from robot_agent.core.controller_config import (
    NEVER_SETTLE,
    STRATEGIES,
    VOTING,
    ControllerConfig,
    StrategyName,
)


@dataclass(frozen=True)
class Vote:
    """A neighbour's vote as heard: who, when (sim time, and the order of hearing), for
    which site, with what quality estimate."""

    robot: int
    t: float
    order: int
    site: int
    quality: float


def initial_site(robot_id: int, num_sites: int) -> int:
    """The site robot ``robot_id`` favours at the start: the swarm spread evenly over the
    sites, as the papers start theirs (equal shares of each option)."""
    return robot_id % num_sites


def update(
    strategy: StrategyName,
    site: int,
    quality: float | None,
    votes: Sequence[Vote],
    rng: Stream,
) -> int:
    """The site a robot favours after its decision rule, from the site it favours, its
    estimate of that site's quality (None: none yet) and its neighbours' ``votes``. No
    votes: it keeps its site (and draws nothing)."""
    if not votes:
        return site
    if strategy == "dmvd":
        return votes[rng.randrange(len(votes))].site
    if strategy == "dmmd":
        return majority(site, [vote.site for vote in votes], rng)
    if strategy == "dc":
        neighbour = votes[rng.randrange(len(votes))]
        own = 0.0 if quality is None else quality
        return neighbour.site if neighbour.quality > own else site
    raise ValueError(f"{strategy!r} is not a voting strategy; use one of {', '.join(VOTING)}")


def majority(site: int, neighbours: Sequence[int], rng: Stream) -> int:
    """The site most of ``site`` and ``neighbours`` name; a tie: one of the tied at random
    (drawn only when there is a tie)."""
    counts: dict[int, int] = {}
    for named in (site, *neighbours):
        counts[named] = counts.get(named, 0) + 1
    top = max(counts.values())
    tied = sorted(named for named, count in counts.items() if count == top)
    return tied[0] if len(tied) == 1 else tied[rng.randrange(len(tied))]


@mypyc_attr(allow_interpreted_subclasses=True)  # a strategy plug-in may be a subclass
class VoteBeliefs:
    """One voting robot's site, quality estimate, the votes it heard, and its decision;
    the controller's strategy for ``dmvd``, ``dmmd`` and ``dc`` (``strategies.Strategy``)."""

    def __init__(
        self,
        num_sites: int,
        config: ControllerConfig,
        robot_id: int,
        rule: str | None = None,
    ) -> None:
        """``rule``: dmvd, dmmd or dc (None: ``config.strategy``'s)."""
        strategy = config.strategy if rule is None else rule
        if strategy not in VOTING:
            raise ValueError(f"{strategy!r} is not a voting strategy")
        self._config = config
        self._strategy: StrategyName = VOTING[VOTING.index(strategy)]
        self._num_sites = num_sites
        self.site = initial_site(robot_id, num_sites)
        self.quality: float | None = None  # the estimate of ``site``, once explored
        self.trips = 0  # updates so far: one per trip
        self.pool_sizes: list[int] = []  # votes used in each update, this robot's included
        self.comparison: protocol.Comparison | None = None  # voting robots compare no pair
        self.decided_site: int | None = None
        self.decision_time: float | None = None
        self.decision_trips: int | None = None
        self.settled = 0  # updates in a row that kept the site with no dissent heard
        self.heard: dict[int, Vote] = {}  # the latest vote of each robot
        self._order = 0

    @property
    def opinion(self) -> list[float]:
        """The site favoured, as an opinion: certain of it (the status reports this)."""
        return [1.0 if index == self.site else 0.0 for index in range(self._num_sites)]

    def next_sites(self, rng: Stream) -> list[int]:
        """Exploration visits the one site the robot favours."""
        return [self.site]

    def compare(self, qualities: dict[int, float]) -> bool:
        """The explored site's quality estimate; the site favoured does not change."""
        for site, quality in qualities.items():
            if site == self.site:
                self.quality = quality
        return False

    def exploration(self, rng: Stream) -> float:
        """Sim seconds to sense the site: exponential with mean sigma."""
        return self._config.exploration * rng.expovariate(1.0)

    def nest_visit(self, arrival: float, rng: Stream) -> tuple[float, float]:
        """When dissemination ends and when listening starts, for a robot at the nest
        since ``arrival``: exponential with mean rho-hat * g (DC: g), then ``listen``."""
        if self._strategy == "dc":
            mean = self._config.dissemination
        else:
            mean = self._config.dissemination * (self.quality or 0.0)
        listening = arrival + mean * rng.expovariate(1.0)
        return listening + self._config.listen, listening

    def hear_payload(self, robot_id: int, t: float, payload: object) -> bool:
        """A neighbour's vote; False (not taken) for anything but a vote for one of our
        sites."""
        if not isinstance(payload, protocol.VotePayload) or payload.site >= self._num_sites:
            return False
        self._order += 1
        self.heard[robot_id] = Vote(robot_id, t, self._order, payload.site, payload.quality)
        return True

    def broadcast(self, robot_id: int) -> protocol.VotePayload:
        return protocol.VotePayload(
            v=protocol.VERSION,
            id=robot_id,
            trip=self.trips,
            decided=self.decided_site is not None,
            site=self.site,
            quality=0.0 if self.quality is None else self.quality,
        )

    def pool(self, since: float, t: float, rng: Stream) -> None:
        """The decision rule on the last G votes heard since ``since``; count the trip, and
        decide at sim time ``t`` once the site has settled."""
        window = sorted(
            (vote for vote in self.heard.values() if vote.t >= since), key=lambda v: v.order
        )
        used = window[-self._config.neighbours :]
        before = self.site
        self.site = update(self._strategy, before, self.quality, used, rng)
        if self.site != before:
            self.quality = None  # the new site is yet to be explored
            self.settled = 0
        elif any(vote.site != self.site for vote in window):
            self.settled = 0
        else:
            self.settled += 1
        self.heard = {}
        self.pool_sizes.append(1 + len(used))
        self.trips += 1
        if self.settled >= self._config.settle:
            self.decided_site = self.site
            self.decision_time = t
            self.decision_trips = self.trips


# The voting strategies as strategy plug-ins (``strategies.StrategyFactory``): the
# project registers them under their names. A voting robot pools no opinions: ``pooling``
# is not used.


def dmvd(num_sites: int, config: ControllerConfig, robot_id: int, pooling: object) -> VoteBeliefs:
    """The voter model (DMVD) for one robot: the strategy plug-in ``dmvd``."""
    return VoteBeliefs(num_sites, config, robot_id, "dmvd")


def dmmd(num_sites: int, config: ControllerConfig, robot_id: int, pooling: object) -> VoteBeliefs:
    """The majority rule (DMMD) for one robot: the strategy plug-in ``dmmd``."""
    return VoteBeliefs(num_sites, config, robot_id, "dmmd")


def dc(num_sites: int, config: ControllerConfig, robot_id: int, pooling: object) -> VoteBeliefs:
    """Direct comparison (DC) for one robot: the strategy plug-in ``dc``."""
    return VoteBeliefs(num_sites, config, robot_id, "dc")


def never_settles(config: ControllerConfig) -> ControllerConfig:
    """``config`` for a voting robot that must never decide (a liar)."""
    return dataclasses.replace(config, settle=NEVER_SETTLE)


__all__ = [
    "NEVER_SETTLE",
    "STRATEGIES",
    "VOTING",
    "StrategyName",
    "Vote",
    "VoteBeliefs",
    "dc",
    "dmmd",
    "dmvd",
    "initial_site",
    "majority",
    "never_settles",
    "update",
]
