"""Controllers that watch a run without changing it, for the studies that need more than
a run's summary: every site comparison (robustness), and every pooling and decision
(why the last robot lags, ``lag.py``).

Each is a subclass of the robot's ``Controller`` that reads what it needs after or around
the controller's own work and changes nothing it decides; ``run_in_process`` builds the
robots with it (``controller_factory``), so an observed run is the same run as an
unobserved one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from robot_agent.core import ports
from robot_agent.core.beliefs import Beliefs
from robot_agent.core.controller import Controller


def comparing_controller(log: list[tuple[int, Any]]) -> type[Controller]:
    """A Controller that puts every new ``comparison`` (read through the public property
    after each ``step``; a new comparison is a new object) into ``log``."""

    class Comparing(Controller):
        _last_seen: object = None

        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            command = super().step(reading, received)
            comparison = self.comparison
            if comparison is not None and comparison is not self._last_seen:
                self._last_seen = comparison
                log.append((self.robot_id, comparison))
            return command

    return Comparing


def judge_comparisons(
    log: Sequence[tuple[int, Any]], qualities: dict[int, float], best: int
) -> dict[str, int]:
    """How many comparisons, how many eliminated the better site of the pair (against the
    true qualities), and how many of those eliminated the best site."""
    wrong = best_eliminated = 0
    for _, comparison in log:
        eliminated = comparison.eliminated
        kept = comparison.site_b if eliminated == comparison.site_a else comparison.site_a
        if qualities[eliminated] > qualities[kept]:
            wrong += 1
            best_eliminated += eliminated == best
    return {"comparisons": len(log), "wrong_comparisons": wrong, "best_eliminated": best_eliminated}


def support_mask(opinion: Sequence[float]) -> int:
    """The sites still held possible (probability > 0), as a bit mask."""
    return sum(1 << index for index, value in enumerate(opinion) if value > 0.0)


def pooling_controller(registry: dict[str, Any]) -> type[Controller]:
    """A Controller that logs into ``registry`` every pooling (who, when, which trip, the
    pool's members and the sites each still held possible) and, at each decision, where
    every robot was and what it still held possible. ``registry`` holds the lists
    ``controllers``, ``poolings`` and ``decisions``."""

    class Pooling(Controller):
        last_xy: tuple[float, float] = (0.0, 0.0)

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            registry["controllers"].append(self)

        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            self.last_xy = (reading.x, reading.y)
            return super().step(reading, received)

        def _pool_and_decide(self, reading: ports.BodyReading) -> None:
            since = self._nest_arrival - 1e-9
            if not isinstance(self._beliefs, Beliefs):
                raise TypeError("pooling is observed for the paper's strategy only")
            heard = self._beliefs.heard
            partners = sorted(robot for robot, (when, _) in heard.items() if when >= since)
            partner_masks = [support_mask(heard[robot][1]) for robot in partners]
            before = support_mask(self.opinion)
            super()._pool_and_decide(reading)
            registry["poolings"].append(
                [
                    self.robot_id,
                    round(self._t, 2),
                    self.trips,
                    len(partners) + 1,
                    partners,
                    before,
                    partner_masks,
                    support_mask(self.opinion),
                    round(self._nest_arrival, 2),
                ]
            )
            if self.decided_site is not None:
                snapshot = [
                    [
                        other.robot_id,
                        str(other.phase),
                        round(math.hypot(*other.last_xy), 3),
                        support_mask(other.opinion),
                        other.trips,
                    ]
                    for other in registry["controllers"]
                ]
                registry["decisions"].append(
                    [self.robot_id, round(self._t, 2), self.trips, snapshot]
                )

    return Pooling
