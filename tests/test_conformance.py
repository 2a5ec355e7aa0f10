"""``swarm conformance`` (deploy/conformance/, docs/porting.md): the C robot conforms over UDP
and over a serial line, the Python program does, and a C robot built with one constant
changed is reported at the tick and field where it first answers otherwise, in the vectors
and in a swarm, where the Python controller with the same constant changed first differs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from outside_helpers import C_ROBOT, c_robot_binary
from swarm_helpers import REPO, swarm_cli

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from deploy.conformance import swarm, vectors
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.navigation import NavParams

pytestmark = pytest.mark.timeout(900)

TRACKS = vectors.load(REPO / "tests" / "vectors" / "controller.json")
SMALL_SWARM = ["--robots", "4", "--sites", "3", "--seed", "1"]


@pytest.fixture(scope="module")
def binary() -> Path:
    built = c_robot_binary()
    if built is None:
        pytest.skip("the C compiler ($CC, or gcc) or make is missing: the C robot cannot be built")
    return built


def conformance(*arguments: str, timeout: float = 600) -> tuple[int, list[str]]:
    done = subprocess.run(
        [sys.executable, "-m", "deploy.cli", "conformance", *arguments],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return done.returncode, done.stdout.splitlines()


def broken_c_robot(folder: Path, source: str, old: str, new: str) -> Path:
    """The C robot built in ``folder`` from a copy of its source with ``old`` in ``source``
    changed to ``new`` (once)."""
    shutil.copytree(C_ROBOT / "src", folder / "src")
    shutil.copy(C_ROBOT / "Makefile", folder / "Makefile")
    path = folder / "src" / source
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} is not in {source} once"
    path.write_text(text.replace(old, new))
    built = subprocess.run(["make", "-C", str(folder)], capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    return folder / "build" / "c-robot"


def test_the_c_robot_conforms_over_udp(binary: Path) -> None:
    code, lines = conformance(str(binary))
    assert code == 0, "\n".join(lines)
    assert lines[-1].startswith("PASS: every tick of 5 tracks")
    assert "gives the all-emulated run" in lines[-1]


def test_the_c_robot_conforms_over_a_serial_line(binary: Path) -> None:
    if shutil.which("socat") is None:
        pytest.skip("socat is not installed (apt-get install socat): no serial line to test")
    code, lines = conformance("--serial", *SMALL_SWARM, str(binary))
    assert code == 0, "\n".join(lines)
    assert lines[-1].startswith("PASS:") and "over a serial line at 921600 baud" in lines[-1]


def test_the_python_program_conforms() -> None:
    code, lines = conformance("--no-swarm", sys.executable, "-m", "robot_agent.link")
    assert code == 0, "\n".join(lines)
    assert lines[-1] == "PASS: every tick of 5 tracks (1655 ticks) over UDP"


def test_a_robot_that_never_drives_back_to_its_slot_is_caught_where_it_was_pushed_out(
    tmp_path: Path, binary: Path
) -> None:
    """The displaced rule's constant, a body width, made one and a half: the robot is found
    out at the tick the track's robot was pushed out of its slot, by its act."""
    broken = broken_c_robot(
        tmp_path,
        "controller.c",
        "distance_to(r, c->slot_x, c->slot_y) > 2 * c->robot_radius",
        "distance_to(r, c->slot_x, c->slot_y) > 3 * c->robot_radius",
    )
    (displaced,) = [track for track in TRACKS if track.name == "displaced"]
    (tick,) = [at for at, _, event, _ in displaced.transitions if event == "displaced"]
    code, lines = conformance("--no-swarm", str(broken))
    assert code == 1, "\n".join(lines)
    expected = displaced.ticks[tick].out["left"]
    assert lines[-1] == (
        f"FAIL: track 'displaced', tick {tick}: act.left: expected {expected!r}, received 0.0 "
        f"(robot {displaced.robot}, seed {displaced.world.seed})"
    )
    assert f"  track displaced: differs at tick {tick}" in lines
    report = "\n".join(lines)
    assert (
        f"the last transition up to it: tick {tick}, stopped --displaced--> to_decision" in report
    )
    assert f"      tick {tick - 3}: t " in report  # the inputs that led there
    # The other tracks never park long enough to be pushed: they pass.
    assert "  track waiting: 142 ticks, every output as expected" in lines


def turning_faster(track: vectors.Track) -> Controller:
    """The Python controller of a track with the navigator's turn gain 4.5 rad/s per rad."""
    world = track.world
    params = NavParams(
        max_speed=world.max_wheel_speed,
        wheel_base=world.wheel_base,
        robot_radius=world.robot_radius,
        control_period=world.dt,
        turn_gain=4.5,
    )
    rng = Stream.named(world.seed, "robot", track.robot)
    return Controller(track.robot, world, track.controller, rng, nav_params=params)


def test_a_robot_that_turns_faster_is_caught_where_the_python_one_would_differ(
    tmp_path: Path, binary: Path
) -> None:
    """The turn gain changed in the C source, and in the Python controller: the tick and
    field swarm conformance reports, in the vectors and in a swarm, are where the Python
    controller with that gain first gives another output."""
    broken = broken_c_robot(tmp_path, "navigation.c", "turn_gain = 4.0;", "turn_gain = 4.5;")
    track = TRACKS[0]
    python = vectors.replay(track, turning_faster(track))
    assert python is not None
    code, lines = conformance("--no-swarm", "--track", track.name, str(broken))
    assert code == 1
    assert lines[-1].startswith(f"FAIL: {python.describe()} ")

    # In a swarm: where the run with robot 3 turning faster first leaves the emulated one.
    options = swarm.run_options(4, 3, 1)
    _, emulated = swarm.reference_run(options, 3)

    class Faster(Controller):
        def __init__(
            self,
            robot_id: int,
            world: protocol.WorldInfo,
            config: ControllerConfig,
            rng: Stream,
            **others: Any,
        ) -> None:
            if robot_id == 3:
                others["nav_params"] = NavParams(
                    max_speed=world.max_wheel_speed,
                    wheel_base=world.wheel_base,
                    robot_radius=world.robot_radius,
                    control_period=world.dt,
                    turn_gain=4.5,
                )
            super().__init__(robot_id, world, config, rng, **others)

    _, faster = swarm.reference_run(options, 3, Faster)
    expected = None
    for want, got in zip(emulated.ticks, faster.ticks, strict=False):
        observed = {**got.out, "status": got.out.get("status")}
        found = vectors.first_difference(want, observed, fields=())
        if found is not None:
            expected = (want.tick, found[0])
            break
    assert expected is not None
    result = swarm.check_swarm(
        [str(broken)], robots=4, sites=3, seed=1, robot=3, folder=tmp_path / "swarm"
    )
    assert not result.same and result.divergence is not None
    assert (result.divergence.tick, result.divergence.field) == expected


def test_bad_arguments_exit_with_code_2_and_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": 99}))
    for arguments, says in [
        (["no-such-program-here"], "no program"),
        (["--vectors", str(bad), sys.executable], "holds no controller vectors"),
        (["--track", "nowhere", sys.executable], "no track nowhere"),
        (["--robot", "10", sys.executable], "--robot 10"),
        (["--baud", "7", "--serial", sys.executable], ""),
        ([], "the following arguments are required: PROGRAM"),
    ]:
        code, _, err = swarm_cli(["conformance", *arguments], capsys)
        assert code == 2, (arguments, err)
        errors = [line for line in err.splitlines() if "error:" in line]
        assert len(errors) == 1 and says in errors[0], (arguments, err)
