"""The controller's plug-in point for a decision rule: what a strategy decides in the
Section 5 trip.

The controller (``controller.py``) drives, senses, keeps the nest's rhythm and talks on
the radio; a ``Strategy`` says which sites a trip visits, what a sensed quality does to
the robot's belief, how long it stays at a site and at the nest, what it broadcasts,
what it takes from what it hears, and when it has decided. A ``StrategyFactory`` makes one
robot's strategy; the built-ins, by name (``--strategy``; the project registers them as
plug-ins of the group ``bestofn_swarm.strategies`` under the same names):

* ``paper``: ``beliefs.Beliefs``, the paper's negative updating and pooling (with the
  pooling operator of ``--pooling``, or ``config.defence``'s pooler, ``defence.py``); two
  sites a trip, no extra time at a site, ``dwell`` seconds at the nest;
* ``dmvd``, ``dmmd``, ``dc``: ``voting.VoteBeliefs`` (Valentini et al.); one site a trip,
  sensed for an exponential time, an exponential dissemination at the nest.

A plug-in of one's own is any ``StrategyFactory`` (docs/extending.md); the robot's builder
(``builder.py``) makes it from the resolved plug-ins (``plugins.py``).

Pure, like everything in ``robot_agent/core``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import beliefs, decision, voting

if TYPE_CHECKING:
    from robot_agent.core.controller_config import ControllerConfig


class Strategy(Protocol):
    """One robot's belief and decision under a strategy (read by the status, driven by the
    controller's trip)."""

    @property
    def opinion(self) -> list[float]: ...

    @property
    def trips(self) -> int: ...

    @property
    def pool_sizes(self) -> list[int]: ...

    @property
    def comparison(self) -> protocol.Comparison | None: ...

    @property
    def decided_site(self) -> int | None: ...

    @property
    def decision_time(self) -> float | None: ...

    @property
    def decision_trips(self) -> int | None: ...

    def next_sites(self, rng: Stream) -> list[int]:
        """The sites the next trip visits (one or two), as drawn."""
        ...

    def compare(self, qualities: dict[int, float]) -> bool:
        """The trip's sensed qualities, in visiting order; whether the opinion changed."""
        ...

    def exploration(self, rng: Stream) -> float:
        """Sim seconds to stay sensing a site once there (0: until its quality is seen)."""
        ...

    def nest_visit(self, arrival: float, rng: Stream) -> tuple[float, float]:
        """For a robot at the nest since ``arrival``: when it pools, and from when what it
        heard counts."""
        ...

    def hear_payload(self, robot_id: int, t: float, payload: object) -> bool:
        """A neighbour's broadcast heard at ``t``; False if it is not one to take."""
        ...

    def broadcast(self, robot_id: int) -> protocol.RobotBroadcast:
        """What the robot broadcasts at the nest."""
        ...

    def pool(self, since: float, t: float, rng: Stream) -> None:
        """Combine with what was heard since ``since``, count the trip, decide at ``t``."""
        ...


class StrategyFactory(Protocol):
    """What makes one robot's strategy: a strategy plug-in. ``num_sites`` sites, the
    controller's settings, the robot's id, and the pooling operator of the run
    (``--pooling``) for a strategy that pools opinions. Draws nothing at random: a
    strategy draws from the ``rng`` its methods are given."""

    def __call__(
        self,
        num_sites: int,
        config: ControllerConfig,
        robot_id: int,
        pooling: decision.PoolingOperator,
    ) -> Strategy: ...


BUILTIN_STRATEGIES: dict[str, StrategyFactory] = {
    "paper": beliefs.paper,
    "dmvd": voting.dmvd,
    "dmmd": voting.dmmd,
    "dc": voting.dc,
}
"""The built-in strategies, by their plug-in names."""


def make_strategy(num_sites: int, config: ControllerConfig, robot_id: int) -> Strategy:
    """Robot ``robot_id``'s strategy for ``config.strategy`` and ``config.pooling``, both
    built-ins (a plug-in is made by the robot's builder from the resolved plug-ins:
    ValueError here)."""
    factory = BUILTIN_STRATEGIES.get(config.strategy)
    operator = decision.POOLING_OPERATORS.get(config.pooling)
    if factory is None or operator is None:
        unknown = config.strategy if factory is None else config.pooling
        raise ValueError(
            f"{unknown!r} is not built in: a plug-in is resolved first "
            "(robot_agent.plugins.registry) and built by robot_agent.core.builder"
        )
    return factory(num_sites, config, robot_id, operator)


__all__ = ["BUILTIN_STRATEGIES", "Strategy", "StrategyFactory", "make_strategy"]
