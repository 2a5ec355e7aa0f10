"""The stall watchdog: tells when no undecided robot has made progress for a while (pure).

A robot makes progress when it completes something (a phase change: a leg, a capture, a
pooling; a comparison; a decision) or moves more than two body lengths from where it
last made progress (a robot wriggling on one spot against its neighbours spans about
one). The launcher feeds it ``robot/*/status`` and ``world/state``; the in-process engine
feeds it the controllers' status and the world's poses. Both ask ``stalled(now)`` with
the sim time, so the same run stalls at the same sim time either way. Robots that
decided, and robots no longer running (killed or crashed), hold nothing up.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from wire import protocol

# Body lengths a robot must move to count as progress. One is not enough: robot 361 of a
# 500-robot run (seed 2), trapped among parked robots, wriggled over 8 cm, a little more
# than its 7.4 cm body, for thousands of seconds.
PROGRESS_DISTANCE = 2.0


def default_stall_window(
    arena_radius: float,
    max_speed: float,
    give_up_after: float,
    beacon_outages: Sequence[tuple[float, float]] = (),
) -> float:
    """Sim seconds without progress after which a run counts as stalled.

    The longest legitimate progress-free spell: a robot blocked on its way to a site gives
    up after ``give_up_after`` (a phase change; ``ControllerConfig.leg_allowance`` of the
    longest leg), so two of those, plus two crossings of the arena at full speed (legs,
    detours and queues grow with the arena), plus every configured beacon outage, during
    which robots at the nest legitimately wait without moving.
    """
    crossing = 2.0 * arena_radius / max_speed
    outage = sum(max(end - start, 0.0) for start, end in beacon_outages)
    return 2.0 * give_up_after + 2.0 * crossing + outage


@dataclass
class _Progress:
    """What the watchdog knows of one robot."""

    id: int
    phase: str | None = None
    trips: int = 0
    poolings: int = 0
    comparison: protocol.Comparison | None = None
    decided: bool = False
    running: bool = True
    position: tuple[float, float] | None = None
    anchor: tuple[float, float] | None = None  # where it stood at its last progress
    last_progress: float = 0.0


class Watchdog:
    """Follows the robots' progress in sim time; answers whether the run has stalled."""

    def __init__(
        self, robots: Iterable[int], window: float, body_length: float, start: float = 0.0
    ) -> None:
        if not window > 0.0:
            raise ValueError(f"the stall window must be positive, got {window}")
        self.window = window
        self.body_length = body_length
        self._robots = {robot: _Progress(robot, last_progress=start) for robot in robots}

    def status(self, status: protocol.Status) -> None:
        """A robot's status: progress if it completed anything since the last one."""
        robot = self._robots.get(status.id)
        if robot is None:
            return
        changed = (
            status.phase != robot.phase
            or status.trips != robot.trips
            or status.poolings != robot.poolings
            or status.comparison != robot.comparison
            or (status.decided_site is not None) != robot.decided
        )
        robot.phase, robot.trips, robot.poolings = status.phase, status.trips, status.poolings
        robot.comparison = status.comparison
        robot.decided = status.decided_site is not None
        if changed:
            self._progressed(robot, status.t)

    def poses(self, t: float, poses: Iterable[tuple[int, float, float]]) -> None:
        """Robot positions at sim time ``t``: progress for each that moved more than
        ``PROGRESS_DISTANCE`` body lengths from where it last made progress."""
        for robot_id, x, y in poses:
            robot = self._robots.get(robot_id)
            if robot is None:
                continue
            robot.position = (x, y)
            if robot.anchor is None:
                robot.anchor = (x, y)
            elif math.dist(robot.anchor, (x, y)) > PROGRESS_DISTANCE * self.body_length:
                self._progressed(robot, t)

    def restarted(self, robot_id: int, t: float) -> None:
        """A fresh controller runs this robot: it starts undecided, from now."""
        robot = self._robots.get(robot_id)
        if robot is not None:
            robot.phase, robot.trips, robot.poolings, robot.comparison = None, 0, 0, None
            robot.decided, robot.running = False, True
            self._progressed(robot, t)

    def retired(self, robot_id: int) -> None:
        """The robot's process is gone (killed or crashed): it holds nothing up."""
        robot = self._robots.get(robot_id)
        if robot is not None:
            robot.running = False

    def undecided(self) -> list[int]:
        """Running robots that have not decided, by id."""
        return [r.id for r in self._robots.values() if r.running and not r.decided]

    def last_progress(self) -> float | None:
        """The latest progress of any undecided running robot (None: there is none)."""
        times = [r.last_progress for r in self._robots.values() if r.running and not r.decided]
        return max(times) if times else None

    def stalled(self, now: float) -> bool:
        """Some robot is undecided and none of the undecided progressed for the window."""
        latest = self.last_progress()
        return latest is not None and now - latest >= self.window

    def stuck(self) -> list[dict[str, Any]]:
        """One entry per undecided running robot: where it is and since when it is stuck."""
        return [
            {
                "id": r.id,
                "phase": r.phase,
                "x": None if r.position is None else round(r.position[0], 3),
                "y": None if r.position is None else round(r.position[1], 3),
                "trips": r.trips,
                "last_progress_s": round(r.last_progress, 3),
            }
            for r in sorted(self._robots.values(), key=lambda r: r.id)
            if r.running and not r.decided
        ]

    def _progressed(self, robot: _Progress, t: float) -> None:
        robot.last_progress = max(robot.last_progress, t)
        if robot.position is not None:
            robot.anchor = robot.position
