"""The Section 5 trip as one table: every phase, the events that leave it, where they go.

``TRANSITIONS[phase][event]`` is the phase a robot enters when ``event`` happens while it
is in ``phase``. A ``PhaseMachine`` holds one robot's phase and changes it only through
this table: an event the table does not list for the current phase raises
``IllegalTransitionError`` (as h11's state machine does), so a change to the controller that
would take a path the protocol does not have fails at once instead of running on. What a
robot does in each phase and on entering it is the controller's
(``robot_agent/core/controller.py``); the phases themselves are the wire's ``protocol.Phase``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final, Literal

from bestofn_swarm.wire.protocol import Phase

Event = Literal[
    "start",
    "reached_viewpoint",
    "leg_timed_out",
    "sensed_first_site",
    "compared",
    "site_unseen",
    "heard_beacon",
    "reached_nest_centre",
    "pooled_undecided",
    "decided",
    "decided_to_linger",
    "lingered",
    "parked",
    "displaced",
]

INITIAL_PHASE: Final[Phase] = "to_site"

TRANSITIONS: Final[Mapping[Phase, Mapping[Event, Phase]]] = {
    # Drive to the viewpoint of the next site of the pair.
    "to_site": {
        "start": "to_site",  # the first step: the first pair is chosen from where it stands
        "reached_viewpoint": "sensing",  # there, or stalled near it (someone else is there)
        "leg_timed_out": "to_nest",  # the site is out of reach: no update this trip
    },
    # Face the site and take frames until one shows its quality.
    "sensing": {
        "sensed_first_site": "to_site",  # on to the other site of the pair
        "compared": "to_nest",  # both sites seen: negative update (Definition 1)
        "site_unseen": "to_nest",  # capture_attempts frames failed: give up the pair
    },
    # Drive home until the nest beacon is heard.
    "to_nest": {
        "heard_beacon": "at_nest",
        "reached_nest_centre": "waiting",  # at the centre and still deaf: wait there
    },
    "waiting": {"heard_beacon": "at_nest"},
    # Stand still broadcasting the opinion and listening for `dwell` seconds, then pool
    # (MProdOp) with every neighbour heard; trips += 1; the decision test.
    "at_nest": {
        "pooled_undecided": "to_site",  # the next pair
        "decided": "to_decision",
        "decided_to_linger": "lingering",  # linger > 0: broadcast a while longer first
    },
    "lingering": {"lingered": "to_decision"},
    # Park in the robot's own slot; kept from it, back off and try again (no phase change).
    "to_decision": {"parked": "stopped"},
    # Parked. Pushed more than a body width out of its slot (a crowd passing by), it drives
    # back: left there it could stand in a site's corridor, between the viewpoint and the
    # panel, and robots that still need that site could never see it.
    "stopped": {"displaced": "to_decision"},
}


class IllegalTransitionError(RuntimeError):
    """An event the phase table has no transition for in the current phase."""


class PhaseMachine:
    """One robot's phase; it changes only by ``fire``, through ``TRANSITIONS``."""

    def __init__(self, phase: Phase = INITIAL_PHASE) -> None:
        if phase not in TRANSITIONS:
            raise ValueError(f"unknown phase {phase!r}; the phases are {', '.join(TRANSITIONS)}")
        self._phase: Phase = phase

    @property
    def phase(self) -> Phase:
        return self._phase

    def fire(self, event: Event) -> Phase:
        """Move to the phase the table gives for ``event`` here, and return it."""
        leaving = TRANSITIONS[self._phase]
        if event not in leaving:
            allowed = ", ".join(leaving) or "none, it is final"
            raise IllegalTransitionError(
                f"{event!r} cannot happen in phase {self._phase!r} (its events: {allowed})"
            )
        self._phase = leaving[event]
        return self._phase


__all__ = ["INITIAL_PHASE", "TRANSITIONS", "Event", "IllegalTransitionError", "PhaseMachine"]
