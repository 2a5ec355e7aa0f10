"""The stall watchdog: tells when no robot at work has made progress for a while (pure).

Progress is task progress, not motion: a robot jostling in a crowd at a silent
nest moves all the time and gets nowhere. An undecided robot progresses when it completes
a step of its task: it reaches a site's viewpoint, finishes looking at the site, reaches
the nest and hears the beacon, pools, decides (``TASK_STEPS``, read from the phase changes
in its status). Giving up a leg, or reaching the nest centre without hearing the beacon,
completes nothing. A decided robot progresses when it gets closer to its parking slot than
it ever was (by ``PARK_PROGRESS`` body lengths) and when it parks; once parked it is done.
The run has stalled when some robot is undecided and no robot still at work (undecided,
or decided and not yet parked) progressed for the stall window.

The launcher feeds it ``robot/*/status`` and ``world/state``; the in-process engine feeds
it the controllers' status and the world's poses. Both ask ``stalled(now)`` with the sim
time, so the same run stalls at the same sim time either way. Robots no longer running
(killed or crashed) hold nothing up.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from bestofn_swarm.wire import protocol

# A decided robot's progress towards its slot: a new closest approach by at least this
# many body lengths (a robot pushed back and forth by its neighbours gets no closer).
PARK_PROGRESS = 0.5

# The phase changes that complete a step of the task. Out of ``sensing`` in any direction:
# the robot looked at the site (and saw its quality, or gave it up after its captures).
# Into ``at_nest``: it is at the nest and heard the beacon. Leaving ``at_nest`` is a pooling
# (its count grows too), into ``lingering`` or ``to_decision`` a decision, into ``stopped``
# a parked robot. Not progress: ``to_site -> to_nest`` (a leg given up) and
# ``to_nest -> waiting`` (at the nest centre, deaf).
TASK_STEPS: frozenset[tuple[protocol.Phase, protocol.Phase]] = frozenset(
    {
        ("to_site", "sensing"),
        ("sensing", "to_site"),
        ("sensing", "to_nest"),
        ("to_nest", "at_nest"),
        ("waiting", "at_nest"),
        ("at_nest", "to_site"),
        ("at_nest", "lingering"),
        ("at_nest", "to_decision"),
        ("lingering", "to_decision"),
        ("to_decision", "stopped"),
    }
)

# Where a decided robot parks: (robot id, site) -> (x, y).
SlotOf = Callable[[int, int], tuple[float, float]]


def default_stall_window(
    arena_radius: float,
    max_speed: float,
    give_up_after: float,
    beacon_outages: Sequence[tuple[float, float]] = (),
    time_limit: float = math.inf,
) -> float:
    """Sim seconds without progress after which a run counts as stalled.

    The longest legitimate progress-free spell: a robot blocked on its way to a site gives
    up after ``give_up_after`` (``ControllerConfig.leg_allowance`` of the longest leg) and
    heads home, where it completes its next step; two of those, plus two crossings of the
    arena at full speed (legs, detours and queues grow with the arena), plus every beacon
    outage that ends before the run's ``time_limit``, during which robots at the nest
    legitimately wait. An outage that lasts to the limit is not waited for: no robot can
    pool again before the run ends, so a swarm that needs one more pooling cannot finish.
    """
    crossing = 2.0 * arena_radius / max_speed
    outage = sum(max(end - start, 0.0) for start, end in beacon_outages if end < time_limit)
    return 2.0 * give_up_after + 2.0 * crossing + outage


# A world over Zenoh closes each lockstep tick within its --stall-timeout (then it goes on
# without a silent robot), so a live world's clock advances at least that often. Beyond
# that, one minute for what a live world can still go through: a machine suspended for
# longer than Zenoh's 10 s lease (every link drops and comes back: tests/test_faults.py
# freezes the world for 13 s and the run goes on to consensus), or starved by other work.
WORLD_STOP_GRACE = 60.0


def default_world_stop_window(world_stall_timeout: float) -> float:
    """Wall seconds without a new tick after which the launcher ends a run as
    ``world_stopped``: two of the world's longest ticks (it may wait out a silent robot
    twice in a row) plus ``WORLD_STOP_GRACE``."""
    return 2.0 * world_stall_timeout + WORLD_STOP_GRACE


@dataclass
class _Progress:
    """What the watchdog knows of one robot."""

    id: int
    phase: protocol.Phase | None = None
    phase_since: float = 0.0  # when it entered its phase (its first status: when heard)
    trips: int = 0
    poolings: int = 0
    decided: bool = False
    running: bool = True
    position: tuple[float, float] | None = None
    slot: tuple[float, float] | None = None  # decided, with its slot known
    closest: float = math.inf  # its closest approach to its slot so far
    last_progress: float = 0.0

    @property
    def at_work(self) -> bool:
        """Running and not done: undecided, or decided and not yet parked (when the
        watchdog knows its slot; without it, a decided robot holds nothing up)."""
        if not self.running:
            return False
        return not self.decided or (self.slot is not None and self.phase != "stopped")


class Watchdog:
    """Follows the robots' progress in sim time; answers whether the run has stalled."""

    def __init__(
        self,
        robots: Iterable[int],
        window: float,
        body_length: float,
        start: float = 0.0,
        slot_of: SlotOf | None = None,
    ) -> None:
        if not window > 0.0:
            raise ValueError(f"the stall window must be positive, got {window}")
        self.window = window
        self.body_length = body_length
        self._slot_of = slot_of
        self._robots = {
            robot: _Progress(robot, phase_since=start, last_progress=start) for robot in robots
        }

    def join(self, robot_id: int, start: float = 0.0) -> None:
        """Follow one more robot (one heard that was not known at the start)."""
        if robot_id not in self._robots:
            self._robots[robot_id] = _Progress(robot_id, phase_since=start, last_progress=start)

    def status(self, status: protocol.Status) -> None:
        """A robot's status: progress if it completed a step of its task since the last."""
        robot = self._robots.get(status.id)
        if robot is None:
            return
        decided = status.decided_site is not None
        completed = (
            (robot.phase, status.phase) in TASK_STEPS
            or status.poolings > robot.poolings
            or status.trips > robot.trips
            or (decided and not robot.decided)
        )
        if status.phase != robot.phase:
            robot.phase, robot.phase_since = status.phase, status.t
        robot.trips, robot.poolings = status.trips, status.poolings
        if decided and not robot.decided and self._slot_of is not None:
            assert status.decided_site is not None
            robot.slot = self._slot_of(robot.id, status.decided_site)
        robot.decided = decided
        if completed:
            robot.last_progress = max(robot.last_progress, status.t)

    def poses(self, t: float, poses: Iterable[tuple[int, float, float]]) -> None:
        """Robot positions at sim time ``t``: progress for each decided robot that came
        closer to its slot than it ever was, by ``PARK_PROGRESS`` body lengths."""
        for robot_id, x, y in poses:
            robot = self._robots.get(robot_id)
            if robot is None:
                continue
            robot.position = (x, y)
            if robot.slot is None or not robot.at_work:
                continue
            away = math.dist(robot.slot, (x, y))
            if away < robot.closest - PARK_PROGRESS * self.body_length:
                robot.closest = away
                robot.last_progress = max(robot.last_progress, t)

    def restarted(self, robot_id: int, t: float) -> None:
        """A fresh controller runs this robot: it starts undecided, from now."""
        robot = self._robots.get(robot_id)
        if robot is not None:
            robot.phase, robot.phase_since, robot.trips, robot.poolings = None, t, 0, 0
            robot.decided, robot.running, robot.slot, robot.closest = False, True, None, math.inf
            robot.last_progress = max(robot.last_progress, t)

    def retired(self, robot_id: int) -> None:
        """The robot's process is gone (killed or crashed): it holds nothing up."""
        robot = self._robots.get(robot_id)
        if robot is not None:
            robot.running = False

    def resumed(self, robot_id: int) -> None:
        """A robot given up as gone runs again (its process was only cut off): its
        progress goes on from where it was."""
        robot = self._robots.get(robot_id)
        if robot is not None:
            robot.running = True

    def undecided(self) -> list[int]:
        """Running robots that have not decided, by id."""
        return [r.id for r in self._robots.values() if r.running and not r.decided]

    def last_progress(self) -> float | None:
        """The latest progress of any robot at work, if some robot is undecided (None:
        every running robot decided, and nothing holds the run up)."""
        if not self.undecided():
            return None
        return max(r.last_progress for r in self._robots.values() if r.at_work)

    def stalled(self, now: float) -> bool:
        """Some robot is undecided and no robot at work progressed for the window."""
        latest = self.last_progress()
        return latest is not None and now - latest >= self.window

    def stuck(self) -> list[dict[str, Any]]:
        """One entry per undecided running robot: where it is, the phase it is stuck in
        and since when, and when it last completed a step."""
        return [
            {
                "id": r.id,
                "phase": r.phase,
                "phase_since_s": round(r.phase_since, 3),
                "x": None if r.position is None else round(r.position[0], 3),
                "y": None if r.position is None else round(r.position[1], 3),
                "trips": r.trips,
                "last_progress_s": round(r.last_progress, 3),
            }
            for r in sorted(self._robots.values(), key=lambda r: r.id)
            if r.running and not r.decided
        ]
