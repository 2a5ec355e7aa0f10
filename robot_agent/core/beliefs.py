"""What one robot believes under the paper's strategy: its opinion over the sites and,
once it has one, its decision.

A comparison of the two sites of a pair updates the opinion by Definition 1 (negative
updating); at the nest it is pooled (MProdOp, Definition 2, or ``config.pooling``; with
``config.defence``, that defence's pool, ``defence.py``) with the latest opinion of every
neighbour heard since the robot arrived, and then tested for a decision. The arithmetic
is ``robot_agent/core/decision.py``'s; this is the state it acts on. It is the
controller's ``strategies.Strategy`` for ``--strategy paper`` (``paper`` makes it, the
strategy plug-in the project registers under that name).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.compiled import mypyc_attr
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import decision, defence

if TYPE_CHECKING:
    from robot_agent.core.controller_config import ControllerConfig


# A strategy plug-in may be a subclass (docs/extending.md); compiled, a class refuses
# interpreted subclasses unless it allows them.
@mypyc_attr(allow_interpreted_subclasses=True)
class Beliefs:
    """One robot's opinion, what it heard from neighbours, and its decision."""

    def __init__(
        self,
        num_sites: int,
        config: ControllerConfig,
        pooling: decision.PoolingOperator | None = None,
    ) -> None:
        """``pooling``: the operator (a plug-in's, resolved); None: the built-in that
        ``config.pooling`` names."""
        self._config = config
        self.opinion = decision.uniform_opinion(num_sites)
        self.trips = 0  # poolings so far: one per trip
        self.pool_sizes: list[int] = []  # robots in each pool, this one included
        self.comparison: protocol.Comparison | None = None  # the last one that told apart
        self.decided_site: int | None = None
        self.decision_time: float | None = None
        self.decision_trips: int | None = None
        # The latest opinion of each robot, with when it was heard; pooling takes those
        # heard since arriving at the nest.
        self.heard: dict[int, tuple[float, list[float]]] = {}
        operator = pooling if pooling is not None else config.pooling
        self._pooler = defence.make_pooler(config.defence, operator, config.trim)

    def hear(self, robot_id: int, t: float, opinion: list[float]) -> None:
        """Robot ``robot_id``'s opinion (validated over our sites), heard at sim time ``t``."""
        self.heard[robot_id] = (t, opinion)
        self._pooler.hear(robot_id, opinion)

    def hear_payload(self, robot_id: int, t: float, payload: object) -> bool:
        """A neighbour's broadcast; False (not taken) unless it is an opinion over our
        sites (wrong length, negative, NaN, or a vote)."""
        if not isinstance(payload, protocol.OpinionPayload):
            return False
        try:
            opinion = decision.validate_opinion(payload.opinion, len(self.opinion))
        except ValueError:
            return False
        self.hear(robot_id, t, opinion)
        return True

    def next_sites(self, rng: Stream) -> list[int]:
        """The pair of the next trip, drawn by weight from the opinion."""
        return list(decision.choose_pair(self.opinion, rng))

    def exploration(self, rng: Stream) -> float:
        """The paper's robot leaves a site as soon as it has seen it."""
        return 0.0

    def nest_visit(self, arrival: float, rng: Stream) -> tuple[float, float]:
        """``dwell`` seconds at the nest, pooling what was heard since arriving."""
        return arrival + self._config.dwell, arrival

    def broadcast(self, robot_id: int) -> protocol.OpinionPayload:
        return protocol.OpinionPayload(
            v=protocol.VERSION,
            id=robot_id,
            trip=self.trips,
            decided=self.decided_site is not None,
            opinion=protocol.wire_opinion(self.opinion),
        )

    def compare(self, qualities: dict[int, float]) -> bool:
        """Negative update from the two sites' qualities (in visiting order); whether the
        opinion changed. Equal qualities are no evidence either way: no update."""
        (site_a, quality_a), (site_b, quality_b) = qualities.items()
        if quality_a == quality_b:
            return False  # an update would be a coin toss
        worse = site_a if quality_a < quality_b else site_b
        self.comparison = protocol.Comparison(site_a, quality_a, site_b, quality_b, worse)
        updated = decision.negative_update(self.opinion, worse, self._config.alpha)
        if updated == self.opinion:
            return False
        self.opinion = updated
        return True

    def pool(self, since: float, t: float, rng: Stream | None = None) -> None:
        """Pool with every neighbour heard since ``since``, count the trip, and decide at
        sim time ``t`` if an option reaches the threshold (``decided_site``). Draws
        nothing from ``rng``."""
        neighbours = [
            opinion for _, (heard, opinion) in sorted(self.heard.items()) if heard >= since
        ]
        pool = [self.opinion, *neighbours]
        pooled = self._pooler.pool(pool)
        if pooled is not None:  # None: contradictory evidence, keep our own opinion
            self.opinion = pooled
        self.heard = {}
        self.pool_sizes.append(len(pool))
        self.trips += 1
        decided = decision.decided_option(self.opinion, self._config.threshold)
        if decided is not None:
            self.decided_site = decided
            self.decision_time = t
            self.decision_trips = self.trips


def paper(
    num_sites: int, config: ControllerConfig, robot_id: int, pooling: decision.PoolingOperator
) -> Beliefs:
    """The paper's strategy for one robot: the strategy plug-in ``paper``
    (``strategies.StrategyFactory``)."""
    return Beliefs(num_sites, config, pooling)


__all__ = ["Beliefs", "paper"]
