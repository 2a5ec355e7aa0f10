"""The Section 5 protocol is one table (robot_agent/core/phases.py), and the controller's phase
changes only through it."""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from typing import Any, get_args

import numpy as np
import pytest
from fakes import FakeBody, FakeSwarm, make_swarm

from bestofn_swarm.wire import protocol
from robot_agent.core import ports
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.phases import (
    INITIAL_PHASE,
    TRANSITIONS,
    Event,
    IllegalTransitionError,
    PhaseMachine,
)

EDGES = {(phase, event) for phase, leaving in TRANSITIONS.items() for event in leaving}


def test_the_table_has_every_phase_of_the_protocol_and_only_those() -> None:
    phases = set(get_args(protocol.Phase))
    assert set(TRANSITIONS) == phases
    assert {target for leaving in TRANSITIONS.values() for target in leaving.values()} <= phases
    assert {event for _, event in EDGES} == set(get_args(Event))  # no event left unused


def test_every_phase_is_reachable_and_a_decided_robot_only_parks() -> None:
    reached, frontier = {INITIAL_PHASE}, [INITIAL_PHASE]
    while frontier:
        for target in TRANSITIONS[frontier.pop()].values():
            if target not in reached:
                reached.add(target)
                frontier.append(target)
    assert reached == set(TRANSITIONS)
    # Once decided, a robot never goes back to the trip: it parks, and parks again when
    # pushed out of its slot.
    decided: set[protocol.Phase] = {"lingering", "to_decision", "stopped"}
    for phase in decided:
        assert set(TRANSITIONS[phase].values()) <= decided
    assert TRANSITIONS["stopped"] == {"displaced": "to_decision"}


@pytest.mark.parametrize(
    ("phase", "event"), sorted(itertools.product(TRANSITIONS, get_args(Event)))
)
def test_an_event_moves_as_the_table_says_or_raises(phase: protocol.Phase, event: Event) -> None:
    machine = PhaseMachine(phase)
    if (phase, event) in EDGES:
        assert machine.fire(event) == TRANSITIONS[phase][event] == machine.phase
    else:
        message = f"'{event}' cannot happen in phase '{phase}'"
        with pytest.raises(IllegalTransitionError, match=message):
            machine.fire(event)
        assert machine.phase == phase  # an illegal event changes nothing


def test_a_machine_starts_only_in_a_phase_of_the_table() -> None:
    assert PhaseMachine().phase == INITIAL_PHASE == "to_site"
    with pytest.raises(ValueError, match="unknown phase 'parked'"):
        PhaseMachine("parked")  # type: ignore[arg-type]


# --- the controller ----------------------------------------------------------------------


def observe_transitions(
    swarm: FakeSwarm, monkeypatch: pytest.MonkeyPatch
) -> set[tuple[protocol.Phase, Event]]:
    """Watch every controller step of ``swarm``: each change of ``controller.phase`` within
    a step must be the chain of table transitions fired in it. Returns the (phase, event)
    pairs fired, filled in as the swarm runs."""
    fired: list[tuple[protocol.Phase, Event, protocol.Phase]] = []
    seen: set[tuple[protocol.Phase, Event]] = set()
    fire = PhaseMachine.fire

    def recording_fire(machine: PhaseMachine, event: Event) -> protocol.Phase:
        leaving = machine.phase
        entering = fire(machine, event)
        fired.append((leaving, event, entering))
        return entering

    monkeypatch.setattr(PhaseMachine, "fire", recording_fire)

    class Checked:
        """A controller whose every step is checked (the swarm steps this instead)."""

        def __init__(self, controller: Controller) -> None:
            self.controller = controller

        def __getattr__(self, name: str) -> Any:
            return getattr(self.controller, name)

        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            controller = self.controller
            phase = controller.phase
            fired.clear()
            command = controller.step(reading, received)
            for leaving, event, entering in fired:
                assert leaving == phase, f"{phase} changed to {leaving} outside the table"
                phase = entering
                seen.add((leaving, event))
            assert controller.phase == phase, "the phase changed outside the table"
            return command

    swarm.controllers[:] = [Checked(controller) for controller in swarm.controllers]  # type: ignore[misc]
    return seen


def test_every_phase_change_of_a_ten_robot_run_is_a_transition_of_the_table(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    swarm = make_swarm(10, 6, seed=5)
    seen = observe_transitions(swarm, monkeypatch)
    swarm.run(1500)
    assert all(controller.phase == "stopped" for controller in swarm.controllers)
    assert seen == EDGES - {
        ("to_site", "leg_timed_out"),
        ("to_nest", "reached_nest_centre"),
        ("waiting", "heard_beacon"),
        ("at_nest", "decided_to_linger"),
        ("lingering", "lingered"),
        ("stopped", "displaced"),
    }


def test_a_hard_trip_takes_the_rest_of_the_table(monkeypatch: pytest.MonkeyPatch) -> None:
    """One robot that is stuck at first (its leg times out), finds the nest silent (it
    waits at the centre), sees nothing for a while (gives sites up) and lingers once
    decided, and once parked is pushed out of its slot: together with the run above,
    every transition of the table is taken."""
    swarm = make_swarm(1, 4, 2, ControllerConfig(linger=2.0))
    world, body = swarm.world, swarm.bodies[0]
    stuck_until, deaf_until, blind_until = 125.0, 160.0, 190.0
    drive, camera = body.drive, world.default_camera

    def stuck_at_first(left: float, right: float) -> None:
        drive(*((0.0, 0.0) if world.t < stuck_until else (left, right)))

    def blind_at_first(seen: FakeBody) -> np.ndarray | None:
        return None if world.t < blind_until else camera(seen)

    body.drive = stuck_at_first  # type: ignore[method-assign]
    world.camera = blind_at_first
    seen = observe_transitions(swarm, monkeypatch)
    for _ in _ticks(swarm, 900):
        world.beacon_on = world.t >= deaf_until
    assert swarm.controllers[0].phase == "stopped"
    x, y, theta = body.pose
    body.pose = (0.8 * x, 0.8 * y, theta)  # pushed towards the nest, out of its slot
    for _ in _ticks(swarm, 300):
        pass
    assert swarm.controllers[0].phase == "stopped"
    assert seen == EDGES - {("at_nest", "decided")}  # it lingered instead


def _ticks(swarm: FakeSwarm, seconds: float) -> Iterator[None]:
    for _ in range(round(seconds / swarm.world.info.dt)):
        yield
        swarm.step()
        if all(controller.phase == "stopped" for controller in swarm.controllers):
            return


def test_a_transition_missing_from_the_table_stops_the_controller(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delitem(TRANSITIONS["sensing"], "compared")
    swarm = make_swarm(1, 4, seed=2)
    with pytest.raises(IllegalTransitionError, match="'compared' cannot happen in phase 'sensing'"):
        swarm.run(300)
