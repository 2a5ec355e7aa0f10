"""Defences against liars that need no ledger: how a robot pools what its neighbours say.

``none`` (the default) is the paper's pooling: the robot's opinion and those of the
neighbours it heard at the nest, combined by ``config.pooling`` (MProdOp, Definition 2).

``trimmed`` is trimmed pooling in the manner of W-MSR (LeBlanc, Zhang, Koutsoukos and
Sundaram, "Resilient asymptotic consensus in robust networks", IEEE JSAC 31(4), 2013):
of the inputs that would pull the robot's value one way, the F most extreme are dropped.
With alpha = 0 an opinion is uniform over the sites its holder has not ruled out
(Equation 4), so pooling by MProdOp is the intersection of those sets, and the only input
that moves the result is a zero: a neighbour's report that a site is not the best. The
trimmed pool drops, per site, the F lowest reports below the robot's own value: a site
the robot itself still holds possible is ruled out only when more than F peers report
it ruled out. The robot's own comparisons are never trimmed (W-MSR keeps a node's own
value), and the reports are those of every peer it has heard, the latest of each (a
peer counts once, however often it is heard; pools at the nest hold two or three robots,
too few to find F + 1 reports of anything in one pool).

Why that is a defence: without noise an honest robot never rules out the best site, so
only a Byzantine robot can report it ruled out, and an honest robot repeats such a report
only after more than F peers made it. So while at most F robots lie, no honest robot
ever rules out the best site, and every honest decision (one site left) is the best
site, whatever the liars say and however they collude. A liar's certainty of one site
is a report that every other site is ruled out; with F or fewer liars it is dropped,
site by site. The cost: a site another robot ruled out is ruled out here only once F + 1
peers have said so (or the robot's own comparison), so evidence spreads more slowly.
Defined for alpha = 0 (``ControllerConfig`` refuses it otherwise). Pure.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Literal, Protocol

from robot_agent.core import decision

DefenceName = Literal["none", "trimmed"]
DEFENCES: tuple[DefenceName, ...] = ("none", "trimmed")


class Pooler(Protocol):
    """How a robot combines its opinion with what it heard."""

    def hear(self, robot_id: int, opinion: list[float]) -> None:
        """Robot ``robot_id``'s opinion (validated over the robot's sites) was heard."""

    def pool(self, pool: Sequence[Sequence[float]]) -> list[float] | None:
        """The pooled opinion of ``pool`` (the robot's own opinion first, then those of the
        neighbours heard at this visit to the nest); None keeps the robot's own."""


class PaperPooling:
    """The paper's pooling (no defence): the pooling operator (``--pooling``: a built-in of
    ``decision.POOLING_OPERATORS`` by name, or a plug-in's) of the pool."""

    def __init__(self, operator: str | decision.PoolingOperator) -> None:
        self._operator = (
            decision.POOLING_OPERATORS[operator] if isinstance(operator, str) else operator
        )

    def hear(self, robot_id: int, opinion: list[float]) -> None:
        """Nothing to remember: the pool is what was heard at this visit."""

    def pool(self, pool: Sequence[Sequence[float]]) -> list[float] | None:
        return self._operator(pool)


class TrimmedPooling:
    """W-MSR-style trimmed pooling over the latest opinion of every peer heard (above)."""

    def __init__(self, trim: int) -> None:
        self.trim = decision.as_count(trim, "trim")
        self.peers: dict[int, list[float]] = {}

    def hear(self, robot_id: int, opinion: list[float]) -> None:
        self.peers[robot_id] = opinion

    def pool(self, pool: Sequence[Sequence[float]]) -> list[float] | None:
        return trimmed_support(pool[0], self.peers.values(), self.trim)


def trimmed_support(
    own: Sequence[float], peers: Iterable[Sequence[float]], trim: int
) -> list[float] | None:
    """The opinion uniform over the sites ``own`` holds possible that at most ``trim`` of
    ``peers`` rule out (give probability zero); None if that leaves no site."""
    reports = [0] * len(own)
    for opinion in peers:
        for index, value in enumerate(opinion):
            if value == 0.0:
                reports[index] += 1
    alive = {index for index, value in enumerate(own) if value > 0.0 and reports[index] <= trim}
    if not alive:
        return None
    return [1.0 / len(alive) if index in alive else 0.0 for index in range(len(own))]


def make_pooler(defence: DefenceName, pooling: str | decision.PoolingOperator, trim: int) -> Pooler:
    """The pooler of a robot's settings (``--defence``, ``--pooling``: a built-in's name or
    the operator itself, ``--trim``)."""
    if defence == "trimmed":
        return TrimmedPooling(trim)
    return PaperPooling(pooling)


__all__ = [
    "DEFENCES",
    "DefenceName",
    "PaperPooling",
    "Pooler",
    "TrimmedPooling",
    "make_pooler",
    "trimmed_support",
]
