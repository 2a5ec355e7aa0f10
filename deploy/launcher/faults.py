"""The faults a run injects (``--kill``, ``--restart``): which are due at a sim time, and
the record of those applied (the summary's ``faults``). The launcher applies them: its
supervisor kills and restarts the robot's process, its follower keeps the books."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from deploy.launcher.plan import Fault, FaultAction


class FaultSchedule:
    """The faults still to come, in sim-time order, and those applied."""

    def __init__(self, faults: Sequence[Fault]) -> None:
        self.pending = sorted(faults, key=lambda fault: fault.at)
        self.applied: list[dict[str, Any]] = []

    def due(self, sim_time: float) -> list[Fault]:
        """The faults whose time has come, taken off the schedule."""
        count = next(
            (index for index, fault in enumerate(self.pending) if fault.at > sim_time),
            len(self.pending),
        )
        due, self.pending = self.pending[:count], self.pending[count:]
        return due

    def restart_pending(self) -> bool:
        """A robot is still to be restarted: it will take part again."""
        return any(fault.action is FaultAction.RESTART for fault in self.pending)

    def note(self, fault: Fault, sim_time: float, was_running: bool) -> None:
        """Record an applied fault, as the summary lists it."""
        self.applied.append(
            {
                "robot": fault.robot,
                "action": fault.action.value,
                "at_s": fault.at,
                "applied_at_s": round(sim_time, 3),
                "was_running": was_running,
            }
        )
