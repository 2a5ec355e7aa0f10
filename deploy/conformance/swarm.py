"""A program in a lockstep swarm beside emulated robots (``swarm conformance``'s second
part).

The swarm runs twice. First all emulated, in this process (``deploy.inprocess.engine``,
the same per-robot results as ``swarm run``), with the robot the program will be watched
step by step (``capture.py``). Then with ``swarm run --external ROBOT`` over Zenoh, recorded,
and the program started as a porter starts it, on UDP or a serial line. In lockstep the two
must be the same run: the same digest and, for every robot, the same decided site, steps,
decision time and pool sizes. When they are not, the recording says where the program
first answered otherwise: its act, transmissions and status of each tick are compared with
the emulated robot's, in the order ``vectors.first_difference`` compares a track's, and the
world's inputs to it with the emulated robot's readings (if those differ first, the run
left lockstep before the program did anything wrong).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.wire import keyspace
from deploy.conformance import capture, vectors
from deploy.conformance.link_driver import pty_pair, stop
from deploy.inprocess import engine
from deploy.launcher import options as launcher_options
from deploy.launcher.outside import free_udp_port
from deploy.launcher.plan import plan_from_args
from robot_agent.core.controller import Controller
from world_server.core.world import World
from world_server.recording.reader import RecordingReader

RUN_TIMEOUT = 900.0  # wall seconds for the swarm with the program in it
KEY_WAIT = 120.0  # wall seconds for swarm run to write the program's key file


@dataclass
class SwarmResult:
    """How the swarm with the program went, against the all-emulated one."""

    same: bool
    summary: dict[str, Any] | None  # swarm run's, None if it gave none
    reference: dict[str, Any]  # the all-emulated run's
    divergence: vectors.Divergence | None = None
    reference_track: vectors.Track | None = None
    notes: list[str] = field(default_factory=list)
    compared: int = 0  # the program's ticks compared with the emulated robot's


def results(summary: dict[str, Any]) -> list[tuple[Any, ...]]:
    """Per robot: decided site, steps, decision time, pool sizes (what must not change)."""
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


def run_options(robots: int, sites: int, seed: int) -> list[str]:
    return ["--robots", str(robots), "--sites", str(sites), "--seed", str(seed)]


def reference_run(
    options: Sequence[str], robot: int, controller: type[Controller] = Controller
) -> tuple[dict[str, Any], vectors.Track]:
    """The all-emulated run of ``swarm run OPTIONS`` (in this process), and ``robot``'s
    steps in it as a track (``controller``: the robots' controller, a subclass to run
    another)."""
    parser = argparse.ArgumentParser()
    launcher_options.add_arguments(parser)
    args = parser.parse_args(["--engine", "inprocess", "--run-id", "conformance", *options])
    plan = plan_from_args(args)
    switches = plan.switches
    caught = capture.capture_run(
        switches.world.world,
        switches.controller,
        [robot],
        controller=controller,
        beacon_config=switches.beacon,
        timeout=plan.timeout,
        stall_window=plan.stall_window,
        hooks=engine.EngineHooks(config=plan.config, poses_every=switches.world.state_every),
    )
    track = vectors.track_of(
        vectors.track_from_steps(
            name="swarm",
            about="the robot in the all-emulated run",
            run={},
            robot=robot,
            world=World(switches.world.world).info,
            controller=switches.controller,
            steps=caught.steps[robot],
        )
    )
    return caught.summary, track


def check_swarm(
    command: Sequence[str],
    *,
    robots: int,
    sites: int,
    seed: int,
    robot: int,
    folder: Path,
    serial_baud: int | None = None,
) -> SwarmResult:
    """The swarm with ``robot`` the program, against the all-emulated swarm."""
    options = run_options(robots, sites, seed)
    reference, track = reference_run(options, robot)
    folder.mkdir(parents=True, exist_ok=True)
    keys, recording = folder / "keys", folder / "run.mcap"
    run_id = f"conformance-{seed}-{int(time.time() * 1000) % 10**9}"
    with contextlib.ExitStack() as stack:
        if serial_baud is None:
            address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
            served, program_link = address, address
        else:
            ours, theirs = stack.enter_context(pty_pair(folder / "line"))
            served = f"{robot}=serial:{ours}@{serial_baud}"
            program_link = f"serial:{theirs}@{serial_baud}"
        swarm_log = (folder / "swarm-run.log").open("wb")
        stack.callback(swarm_log.close)
        launched = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "deploy.cli",
                "run",
                *options,
                "--run-id",
                run_id,
                "--external",
                str(robot),
                "--link",
                served,
                "--link-keys",
                str(keys),
                "--stall-timeout",
                "300",
                "--record",
                str(recording),
                "--json",
                "--quiet",
            ],
            stdout=subprocess.PIPE,
            stderr=swarm_log,
        )
        stack.callback(stop, launched)
        key_file = keys / f"robot-{robot}.key"
        deadline = time.monotonic() + KEY_WAIT
        while not key_file.exists() and launched.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if not key_file.exists():
            return SwarmResult(False, None, reference, notes=["swarm run wrote no key file"])
        program_log = (folder / "program.log").open("wb")
        stack.callback(program_log.close)
        program = subprocess.Popen(
            [*command, "--link", program_link, "--id", str(robot), "--key-file", str(key_file)],
            stdin=subprocess.DEVNULL,
            stdout=program_log,
            stderr=subprocess.STDOUT,
        )
        stack.callback(stop, program)
        try:
            output, _ = launched.communicate(timeout=RUN_TIMEOUT)
        except subprocess.TimeoutExpired:
            return SwarmResult(
                False, None, reference, notes=[f"the swarm ran longer than {RUN_TIMEOUT:g} s"]
            )
        with contextlib.suppress(subprocess.TimeoutExpired):
            program.wait(10.0)  # it exits when the bridge says the run ended
    try:
        summary = json.loads(output.decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        return SwarmResult(False, None, reference, notes=["swarm run printed no summary"])
    # The program's every answer, not only the run's results: a robot can answer otherwise
    # and the swarm still end alike.
    divergence, compared = first_divergence(recording, summary, track)
    same = (
        divergence is None
        and compared == len(track.ticks)
        and results(summary) == results(reference)
        and summary["digest"] == reference["digest"]
    )
    result = SwarmResult(same, summary, reference, divergence, reference_track=track)
    result.compared = compared
    if not same and divergence is None and compared < len(track.ticks):
        result.notes.append(
            f"the recording holds robot {robot}'s inputs of {compared} of the "
            f"{len(track.ticks)} ticks it stepped all emulated"
        )
    elif not same and result.divergence is None:
        result.notes.append(
            f"robot {robot}'s answers were the emulated robot's at every tick recorded; "
            "the runs differ elsewhere (a tick closed without a robot: see stalls and "
            "departures in the summary's world)"
        )
    return result


def first_divergence(
    recording: Path, summary: dict[str, Any], track: vectors.Track
) -> tuple[vectors.Divergence | None, int]:
    """Where the recorded run's program first answered otherwise than the emulated robot,
    or first was given other inputs (None if it never did in what was recorded); and how
    many ticks were compared."""
    robot = track.robot
    keys = keyspace.Keys(summary["run_id"])
    topics = {
        keys.of(kind, robot): kind
        for kind in (keyspace.ACT, keyspace.RADIO_TX, keyspace.STATUS, keyspace.SENSE)
    }
    acts: dict[int, dict[str, Any]] = {}
    sent: dict[int, list[dict[str, Any]]] = {}
    statuses: dict[int, dict[str, Any]] = {}
    senses: dict[int, dict[str, Any]] = {}
    with contextlib.suppress(OSError, ValueError):
        for message in RecordingReader(recording):
            kind = topics.get(message.topic)
            if kind is None:
                continue
            value = json.loads(message.data)
            if kind is keyspace.ACT:
                acts[value["tick"]] = value
            elif kind is keyspace.RADIO_TX:
                sent.setdefault(value["meta"]["tick"], []).append(value["payload"])
            elif kind is keyspace.STATUS:
                statuses.setdefault(value["tick"], value)  # the first of a tick; repeats follow
            else:
                senses[value["tick"]] = value
    compared = 0
    for tick in track.ticks:
        sense = senses.get(tick.tick)
        if sense is None:
            break
        for name in ("t", "x", "y", "theta", "prox"):
            if not vectors.same(tick.inputs[name], sense[name]):
                found_input = vectors.Divergence(
                    "swarm", tick.tick, f"in.{name}", tick.inputs[name], sense[name]
                )
                return found_input, compared
        act = acts.get(tick.tick)
        if act is None:
            return vectors.Divergence("swarm", tick.tick, "act", "an act", "none"), compared
        observed = {
            "left": act["left"],
            "right": act["right"],
            "capture": act["capture"],
            "broadcasts": sent.get(tick.tick, []),
            "status": statuses.get(tick.tick),
        }
        found = vectors.first_difference(tick, observed, fields=())
        if found is not None:
            return vectors.Divergence("swarm", tick.tick, *found), compared
        compared += 1
    return None, compared


__all__ = ["SwarmResult", "check_swarm", "first_divergence", "reference_run", "results"]
