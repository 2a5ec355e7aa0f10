"""The controller vectors (tests/vectors/controller.json, docs/controller.md): the Python
controller gives every track's outputs, the tracks hold every transition of the phase table,
and the file is what tests/make_vectors.py makes from its runs. The C robot runs the same
tracks in its unit tests (c_robot/tests/controller.c); ``swarm conformance`` drives any
program with them over the link (tests/test_conformance.py)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import make_vectors
import pytest

from bestofn_swarm.wire.rng import Stream
from deploy.conformance import vectors
from robot_agent.core import phases
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.navigation import NavParams

FILE = Path(__file__).resolve().parent / "vectors" / "controller.json"
TRACKS = vectors.load(FILE)


@pytest.mark.parametrize("track", TRACKS, ids=[track.name for track in TRACKS])
def test_the_python_controller_gives_every_output_of_every_track(track: vectors.Track) -> None:
    assert vectors.replay(track) is None


def test_every_transition_of_the_phase_table_is_in_some_track() -> None:
    table = {
        (phase, event, entered)
        for phase, leaving in phases.TRANSITIONS.items()
        for event, entered in leaving.items()
    }
    covered = {
        (phase, event, entered)
        for track in TRACKS
        for _, phase, event, entered in track.transitions
    }
    assert not table - covered, f"no track takes {sorted(table - covered)}"
    assert covered <= table
    assert set(phases.TRANSITIONS) == {
        phase for track in TRACKS for tick in track.ticks for phase in [tick.out["phase"]]
    }, "every phase is some tick's"


@pytest.mark.parametrize("track", TRACKS, ids=[track.name for track in TRACKS])
def test_a_tracks_transitions_are_its_ticks_events(track: vectors.Track) -> None:
    """The list a reader starts from says what the ticks say: each event at its tick, and
    the phase after it."""
    from_ticks = [
        (tick.tick, phase, event, phases.TRANSITIONS[phase][event])
        for tick in track.ticks
        for phase, event in tick.out.get("events", [])
    ]
    assert [tuple(each) for each in track.transitions] == from_ticks
    for tick in track.ticks:
        events = tick.out.get("events", [])
        if events:  # the phase after a step is where its last event led
            phase, event = events[-1]
            assert tick.out["phase"] == phases.TRANSITIONS[phase][event]
    assert [tick.tick for tick in track.ticks] == list(range(len(track.ticks)))


def test_a_changed_output_or_constant_is_found_at_its_tick() -> None:
    """The replay can fail: an expected wheel speed nudged by one ulp, and a controller
    whose navigator turns a little faster, are each caught where they first show."""
    track = TRACKS[0]
    ticks = list(track.ticks)
    nudged = dict(ticks[500].out)
    nudged["right"] = math.nextafter(nudged["right"], math.inf)
    ticks[500] = vectors.Tick(ticks[500].tick, ticks[500].inputs, nudged)
    found = vectors.replay(dataclasses.replace(track, ticks=ticks))
    assert found is not None and (found.tick, found.field) == (500, "act.right")

    world = track.world
    faster = NavParams(
        max_speed=world.max_wheel_speed,
        wheel_base=world.wheel_base,
        robot_radius=world.robot_radius,
        control_period=world.dt,
        turn_gain=4.5,
    )
    controller = Controller(
        track.robot,
        world,
        track.controller,
        Stream.named(world.seed, "robot", track.robot),
        nav_params=faster,
    )
    found = vectors.replay(track, controller)
    assert found is not None and found.field in ("act.left", "act.right")


def test_the_runs_settings_are_the_defaults_but_what_each_track_names() -> None:
    for spec, track in zip(make_vectors.CONTROLLER_TRACKS, TRACKS, strict=True):
        assert track.controller == ControllerConfig(**spec.settings)
        assert track.robot == spec.robot and track.world.seed == spec.seed


def test_the_file_is_what_the_generator_makes_from_its_runs() -> None:
    assert FILE.read_text(encoding="utf-8") == make_vectors.controller_vectors(), (
        "run: python tests/make_vectors.py"
    )
