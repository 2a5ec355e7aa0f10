"""The swarm's curves as the page charts them (pure): robots decided, each site's share of
the swarm's opinion, the mean entropy and the mean pool size, one point per world state
(the swarm rows of ``world_server/observer/frame.py``).

A page is sent what it has not got: ``since(epoch, count)`` gives the points after the
first ``count``, or all of them when the page's copy is of an older ``epoch``. The points
are kept at most ``limit``: when full, every other point goes and the epoch changes, so
that a long run's chart costs the same memory and traffic as a short one's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

LIMIT = 1200  # points kept, at most


def point(row: Sequence[Any]) -> list[Any]:
    """A swarm row as the page's point: ``[t, decided, entropy_mean, pool_size_mean,
    share_0, share_1, ...]`` (null for a value not known)."""
    _, t, _, decided, entropy_mean, _, _, pool_mean, *shares = row

    def number(value: float, digits: int = 4) -> float | None:
        return None if math.isnan(value) else round(value, digits)

    return [
        round(t, 2),
        decided,
        number(entropy_mean),
        number(pool_mean, 2),
        *(number(share) for share in shares),
    ]


class Series:
    """A bounded list of chart points with an epoch (see the module's text)."""

    def __init__(self, limit: int = LIMIT) -> None:
        self.limit = max(4, limit)
        self.points: list[list[Any]] = []
        self.epoch = 0
        self._stride = 1
        self._seen = 0

    def extend(self, rows: Iterable[Sequence[Any]]) -> None:
        for row in rows:
            if self._seen % self._stride == 0:
                if len(self.points) >= self.limit:
                    del self.points[1::2]
                    self._stride *= 2
                    self.epoch += 1
                if self._seen % self._stride == 0:
                    self.points.append(point(row))
            self._seen += 1

    def since(self, epoch: int, count: int) -> dict[str, Any] | None:
        """The message a page holding ``count`` points of ``epoch`` needs (None: nothing)."""
        if epoch == self.epoch and count >= len(self.points):
            return None
        reset = epoch != self.epoch or count > len(self.points)
        return {
            "type": "series",
            "epoch": self.epoch,
            "reset": reset,
            "points": list(self.points) if reset else self.points[count:],
        }


def series_of(rows: Iterable[Sequence[Any]], limit: int = LIMIT) -> Series:
    series = Series(limit)
    series.extend(rows)
    return series
