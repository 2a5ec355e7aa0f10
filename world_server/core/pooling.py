"""Who pooled with whom, as anyone who follows a run sees it (pure): from the robots' status
messages (a pooling counted) and the radio deliveries (who each robot heard at the nest).

The live page, its replay and the recording's Foxglove scene all draw a pooling this way,
and for the same time: ``LINK_SECONDS`` of sim time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from bestofn_swarm.wire import names, protocol

LINK_SECONDS = 3.0  # sim seconds a pooling stays drawn: about a dwell at the nest
ARRIVAL_SLACK = 1e-6  # sim seconds: an opinion delivered in the tick of arrival counts


@dataclass(frozen=True)
class Pooling:
    """One pooling: ``robot`` pooled at sim time ``t`` the opinions of ``members``."""

    t: float
    robot: int
    size: int
    members: tuple[int, ...]


@dataclass
class PoolingTracker:
    """Finds poolings in status messages, and whom they joined from radio deliveries.

    A robot pools its own opinion with the latest opinion of every robot it heard since it
    arrived at the nest (``Controller._pool_and_decide``): here, the robot senders whose
    messages the medium delivered to it since its first ``at_nest`` status of the visit.
    """

    heard: dict[int, dict[int, float]] = field(default_factory=dict)  # robot -> sender -> t
    arrived: dict[int, float] = field(default_factory=dict)  # robot -> sim time at the nest
    poolings_seen: dict[int, int] = field(default_factory=dict)
    decided: set[int] = field(default_factory=set)

    def on_delivery(self, receiver: int, sender: str, t: float) -> None:
        robot = names.robot_of_name(sender)
        if robot is not None:  # a robot's opinion; the beacon has a name, not a number
            self.heard.setdefault(receiver, {})[robot] = t

    def on_status(self, status: protocol.Status) -> tuple[Pooling | None, bool]:
        """Take in one status: the pooling it reports (if any) and whether the robot just
        decided."""
        robot = status.id
        pooling = None
        if status.poolings > self.poolings_seen.get(robot, 0):
            since = self.arrived.pop(robot, -math.inf) - ARRIVAL_SLACK
            heard = self.heard.pop(robot, {})
            members = tuple(
                sorted(s for s, t in heard.items() if since <= t <= status.t and s != robot)
            )
            pooling = Pooling(status.t, robot, status.pool_size, members)
        elif status.phase == "at_nest":
            self.arrived.setdefault(robot, status.t)
        self.poolings_seen[robot] = status.poolings
        just_decided = status.decided_site is not None and robot not in self.decided
        if just_decided:
            self.decided.add(robot)
        return pooling, just_decided
