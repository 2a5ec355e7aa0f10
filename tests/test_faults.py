"""Every chaos switch of `swarm run`, on the real processes; and a world server that dies."""

from __future__ import annotations

import base64
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from swarm_helpers import (
    REPO,
    kill_leftovers,
    loopback_router,
    run_swarm,
    stop_processes,
    unique_run_id,
)

from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.rng import Stream
from nest_beacon.core.beacon import Beacon, BeaconConfig
from world_server.core.camera import CameraNoise
from world_server.core.layout import make_layout
from world_server.core.radio import sender_order
from world_server.core.world import World, WorldConfig

pytestmark = pytest.mark.timeout(240)

SEED = 11
BASE = ["--robots", "4", "--sites", "5", "--seed", str(SEED), "--timeout", "1500"]


@dataclass
class Recording:
    """What a switch's effect shows in: the messages the world, the beacon and the robots
    published, as the recorder kept them (in the order they arrived)."""

    rx: list[tuple[str, protocol.RadioRxMeta]] = field(default_factory=list)  # receiver, meta
    beacon_tx: list[int] = field(default_factory=list)  # ticks the beacon transmitted in
    beacon_answered: set[int] = field(default_factory=set)  # ticks the beacon acknowledged
    clocks: list[protocol.Clock] = field(default_factory=list)
    acts: dict[int, list[int]] = field(default_factory=dict)  # robot -> ticks it answered
    statuses: dict[int, list[protocol.Status]] = field(default_factory=dict)
    frames: list[np.ndarray] = field(default_factory=list)  # camera frames, decoded

    @classmethod
    def read(cls, path: Path) -> Recording:
        recording = cls()
        with open(path, "rb") as stream:
            for schema, channel, message in make_reader(stream).iter_messages(log_time_order=False):
                recording._take(schema.name if schema else "", channel.topic, message.data)
        return recording

    def _take(self, schema: str, topic: str, data: bytes) -> None:
        name = topic.rsplit("/", 1)[-1]
        if schema == "bestofn.RadioRxRecord":
            meta = json.loads(data)["meta"]
            self.rx.append((name, protocol.decode(json.dumps(meta).encode(), protocol.RadioRxMeta)))
        elif schema == "bestofn.RadioTxRecord" and name == "nest":
            self.beacon_tx.append(json.loads(data)["meta"]["tick"])
        elif schema == "bestofn.Ack":
            self.beacon_answered.add(protocol.decode(data, protocol.Ack).tick)
        elif schema == "bestofn.Clock":
            self.clocks.append(protocol.decode(data, protocol.Clock))
        elif schema == "bestofn.Act":
            robot = int(topic.rsplit("/", 2)[-2])
            self.acts.setdefault(robot, []).append(protocol.decode(data, protocol.Act).tick)
        elif schema == "bestofn.Status":
            status = protocol.decode(data, protocol.Status)
            self.statuses.setdefault(status.id, []).append(status)
        elif schema == "foxglove.CompressedImage":
            png = np.frombuffer(base64.b64decode(json.loads(data)["data"]), np.uint8)
            frame = cv2.imdecode(png, cv2.IMREAD_COLOR)
            assert frame is not None, f"{topic}: not a PNG frame"
            self.frames.append(frame)


@dataclass
class Run:
    summary: dict[str, Any]
    recording: Recording | None


# --- what each switch must do, seen in what its process published -------------------


def _world_drops(run: Run) -> None:
    """The world's radio lost copies (a run without a loss switch loses none)."""
    assert run.summary["radio"]["dropped"] > 0, run.summary["radio"]


def _world_delays_by_3_to_6_ticks(run: Run) -> None:
    """--latency 3 --jitter 3: every copy arrives 1 + 3 + (0..3) ticks after it was sent
    (without them, 1), and each delay happens; jitter alone keeps each tick's order."""
    recording = _recorded(run)
    delays = Counter(meta.tick - meta.sent_tick for _, meta in recording.rx)
    assert set(delays) == {4, 5, 6, 7}, delays
    assert len(recording.rx) == run.summary["radio"]["delivered"]
    assert _out_of_order_ticks(recording) == 0


def _world_duplicates(run: Run) -> None:
    """--duplicate 0.5: some copies arrive twice (none more), the second 0 or 1 tick
    after the first; the world counts both as delivered."""
    recording = _recorded(run)
    copies = Counter((receiver, meta.sender, meta.seq) for receiver, meta in recording.rx)
    assert max(copies.values()) == 2
    twice = sum(count == 2 for count in copies.values())
    sent = sum(copies.values()) - twice
    assert 0.3 * sent < twice < 0.7 * sent, (twice, sent)
    assert {meta.tick - meta.sent_tick for _, meta in recording.rx} == {1, 2}
    assert len(recording.rx) == run.summary["radio"]["delivered"]


def _world_reorders(run: Run) -> None:
    """--reorder: some tick delivers a receiver's copies out of (sender, seq) order, which
    jitter alone never does (see the latency check)."""
    assert _out_of_order_ticks(_recorded(run)) > 0


def _out_of_order_ticks(recording: Recording) -> int:
    """(receiver, tick) pairs whose copies arrived out of (sender, sequence) order."""
    by_tick: dict[tuple[str, int], list[tuple[tuple[int, int, str], int]]] = {}
    for receiver, meta in recording.rx:
        by_tick.setdefault((receiver, meta.tick), []).append((sender_order(meta.sender), meta.seq))
    return sum(order != sorted(order) for order in by_tick.values())


def _world_camera_is_noisy_and_lit(run: Run) -> None:
    """--camera-noise 8: no frame is a clean render (one colour per surface, at most the
    palette's); --lighting 0.05: the robots' quality estimates follow each site's lit
    colour, not its clean one (the run's seed fixes the lighting)."""
    recording = _recorded(run)
    assert recording.frames
    palette = 4 + SITES  # background, floor, wall, robots, one per site
    for frame in recording.frames:
        assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10 * palette
    lit = _red_shares(CameraNoise(pixel_sigma=8, lighting=0.05))
    clean = _red_shares(CameraNoise())
    telling = {site for site in lit if abs(lit[site] - clean[site]) >= 0.01}
    estimates = [
        (site, quality)
        for statuses in recording.statuses.values()
        for status in statuses
        if status.comparison is not None
        for site, quality in (
            (status.comparison.site_a, status.comparison.quality_a),
            (status.comparison.site_b, status.comparison.quality_b),
        )
        if site in telling
    ]
    assert estimates, "no robot estimated a site whose lighting changes its colour"
    for site, quality in estimates:
        assert abs(quality - lit[site]) < abs(quality - clean[site]), (site, quality, lit, clean)


def _red_shares(noise: CameraNoise) -> dict[int, float]:
    """Each site's red share red / (red + blue) as the world of this run paints it."""
    world = World(WorldConfig(num_sites=SITES, num_robots=ROBOTS, seed=SEED, camera_noise=noise))
    shares = {}
    for site in range(SITES):
        blue, _, red = world.camera.panel_colour_bgr(site)
        shares[site] = red / (red + blue)
    return shares


def _beacon_ticks(recording: Recording, config: BeaconConfig) -> list[int]:
    """The ticks a beacon of ``config`` transmits in, given the clocks the recorded one
    answered (its seeded draws, replayed with nest_beacon's own logic)."""
    beacon = Beacon(config, Stream.named(SEED, "beacon", config.name))
    return [
        clock.tick
        for clock in recording.clocks
        if clock.tick in recording.beacon_answered and beacon.on_tick(clock.t)
    ]


def _beacon_silent_for_60_s(run: Run) -> None:
    """--beacon-outage 0:60: the beacon transmits exactly when a beacon with that outage
    would, first at 60 s; so nobody pools, and nobody decides, before then."""
    recording = _recorded(run)
    assert recording.beacon_tx == _beacon_ticks(recording, BeaconConfig(outages=((0, 60),)))
    assert recording.beacon_tx[0] == 600
    assert all(robot["decision_time_s"] > 60.0 for robot in run.summary["per_robot"])


def _beacon_skips_half(run: Run) -> None:
    """--beacon-flaky 0.5: the beacon transmits exactly when a beacon with that flakiness
    and the run's seed would, which is about half of the times it is due."""
    recording = _recorded(run)
    assert recording.beacon_tx == _beacon_ticks(recording, BeaconConfig(flaky=0.5))
    due = len(_beacon_ticks(recording, BeaconConfig()))
    assert 0.3 * due < len(recording.beacon_tx) < 0.7 * due, (len(recording.beacon_tx), due)


def _robot_1_stops(run: Run) -> None:
    """--kill 1@15: robot 1's process stops answering when it is killed, the others go on."""
    assert [(f["robot"], f["action"]) for f in run.summary["faults"]] == [(1, "kill")]
    fault = run.summary["faults"][0]
    robot = run.summary["per_robot"][1]
    assert robot["killed"] and not robot["crashed"]
    killed_at = round(fault["applied_at_s"] / DT)
    acts = _recorded(run).acts
    assert killed_at - 1 <= acts[1][-1] <= killed_at + 10, (acts[1][-1], killed_at)
    assert all(acts[other][-1] > killed_at + 100 for other in (0, 2, 3))


def _robot_2_starts_afresh(run: Run) -> None:
    """--restart 2@15: a new process takes over robot 2 (its controller starts from tick 0
    again, once) and decides with the others."""
    assert [(f["robot"], f["action"]) for f in run.summary["faults"]] == [(2, "restart")]
    fault = run.summary["faults"][0]
    robot = run.summary["per_robot"][2]
    assert robot["restarts"] == 1 and robot["decided_site"] == run.summary["best_site"]
    statuses = _recorded(run).statuses
    for robot_id, history in statuses.items():
        fresh = sum(later.tick < earlier.tick for earlier, later in pairwise(history))
        assert fresh == (1 if robot_id == 2 else 0), (robot_id, fresh)
    restarted_at = round(fault["applied_at_s"] / DT)
    acts = _recorded(run).acts[2]
    assert any(tick > restarted_at for tick in acts) and acts[-1] == max(acts)


def _recorded(run: Run) -> Recording:
    assert run.recording is not None, "this switch's check reads the recording"
    return run.recording


ROBOTS, SITES, DT = 4, 5, 0.1

# Each switch: its options, the process it is for, what it must do, and whether that
# shows only in the recording (a recorded run takes a little longer).
SWITCHES: dict[str, tuple[list[str], str, Callable[[Run], None], bool]] = {
    "iid-loss": (["--drop", "0.3"], "world", _world_drops, False),
    "burst-loss": (["--burst-loss", "0.1:0.3"], "world", _world_drops, False),
    "range-loss": (["--range-loss", "0.3:1"], "world", _world_drops, False),
    "latency-jitter": (
        ["--latency", "3", "--jitter", "3"],
        "world",
        _world_delays_by_3_to_6_ticks,
        True,
    ),
    "duplication": (["--duplicate", "0.5"], "world", _world_duplicates, True),
    "reordering": (["--reorder", "--jitter", "2"], "world", _world_reorders, True),
    "camera-noise": (
        ["--camera-noise", "8", "--lighting", "0.05"],
        "world",
        _world_camera_is_noisy_and_lit,
        True,
    ),
    "beacon-outage": (["--beacon-outage", "0:60"], "beacon", _beacon_silent_for_60_s, True),
    "beacon-flaky": (["--beacon-flaky", "0.5"], "beacon", _beacon_skips_half, True),
    "kill": (["--kill", "1@15"], "robots", _robot_1_stops, True),
    "restart": (["--restart", "2@15"], "robots", _robot_2_starts_afresh, True),
}


# The switches run over Zenoh, one for each process a switch is for: a world switch and a
# beacon switch travel in the world's and the beacon's settings (one JSON object each, the
# same for every switch of that process), and the robots' switches act on their processes.
# The others run on the in-process engine, which runs the same world and beacon: what
# each does is checked there, in its recording, as over Zenoh.
LIVE = {"latency-jitter", "beacon-outage", "kill", "restart"}


@pytest.mark.parametrize("switch", list(SWITCHES))
def test_the_swarm_still_decides_right_with(switch: str, tmp_path: Path) -> None:
    """Each switch reaches the process it is for (the world, the beacon, the robots) and
    does there what it says, seen in what that process published; the swarm still
    decides right."""
    options, process, check, recorded = SWITCHES[switch]
    path = tmp_path / "run.mcap"
    output = ["--record", str(path)] if recorded else ["--no-record"]
    engine = [] if switch in LIVE else ["--engine", "inprocess"]
    run_id = unique_run_id(switch)
    code, summary, stderr = run_swarm([*BASE, *engine, *output, *options], run_id)
    assert code == 0, stderr
    assert summary["correct"], summary["per_robot"]
    try:
        check(Run(summary, Recording.read(path) if recorded else None))
    except AssertionError as error:
        raise AssertionError(f"--{switch}: no effect seen in the {process}: {error}") from None
    if switch not in ("iid-loss", "burst-loss", "range-loss"):
        assert summary["radio"]["dropped"] == 0  # the loss checks' baseline
    # Only a robot that is killed or restarted leaves mid-run, and the world says so.
    assert summary["world"]["departures"] == (1 if switch in ("kill", "restart") else 0)


def test_robots_wait_for_a_lost_world_server_and_resume_with_a_new_one() -> None:
    run_id = unique_run_id("world-loss")
    keys = keyspace.Keys(run_id)
    common = ["--run-id", run_id, "--seed", "4", "--mode", "client"]
    world_command = [
        sys.executable,
        "-m",
        "world_server.server",
        *common,
        "--robots",
        "3",
        "--sites",
        "4",
    ]
    best = make_layout(4, 3, 4).best_site
    statuses: dict[int, protocol.Status] = {}
    with loopback_router() as (session, endpoint):
        connect = ["--connect", endpoint]
        session.declare_subscriber(
            keys.of(keyspace.STATUS, "*"),
            lambda sample: statuses.__setitem__(
                int(keys.robot_of(keyspace.STATUS, str(sample.key_expr)) or 0),
                protocol.decode(sample.payload.to_bytes(), protocol.Status),
            ),
        )
        started: list[subprocess.Popen[bytes]] = []

        def start(command: list[str]) -> subprocess.Popen[bytes]:
            process = subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE)
            started.append(process)
            return process

        try:
            world = start([*world_command, *connect])
            start([sys.executable, "-m", "nest_beacon", *common, *connect])
            robots = [
                start(
                    [
                        sys.executable,
                        "-m",
                        "robot_agent.node",
                        "--id",
                        str(robot),
                        *common,
                        *connect,
                    ]
                )
                for robot in range(3)
            ]
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not any(
                status.trips >= 1 for status in statuses.values()
            ):
                time.sleep(0.05)
            assert statuses, "the robots never reported"
            os.kill(world.pid, signal.SIGKILL)
            world.wait()
            time.sleep(2.0)
            assert all(robot.poll() is None for robot in robots), "a robot exited"
            start([*world_command, *connect])
            # The new world ends the run on consensus, and the robots with it.
            codes = [robot.wait(timeout=120) for robot in robots]
            assert codes == [0, 0, 0], codes
        finally:
            stop_processes(started)
            kill_leftovers(run_id)
        errors = b"".join(process.stderr.read() for process in started if process.stderr)
    assert {status.decided_site for status in statuses.values()} == {best}
    assert b"Traceback" not in errors, errors.decode()[-3000:]
    assert b"new world server appeared" in errors


# --- a process frozen for longer than Zenoh's lease --------------------------------------

FROZEN_SECONDS = 13.0  # longer than Zenoh's 10 s lease: every link of the process goes


def _parent(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


@pytest.mark.parametrize("frozen", ["world", "robots"])
def test_a_swarm_frozen_longer_than_the_lease_resumes_and_decides(frozen: str) -> None:
    """SIGSTOP, as a suspended laptop or a swapping machine does: the world, or the robots'
    process, stops answering for longer than Zenoh's lease, so every token of
    the frozen side goes. Once thawed, the tokens come back and the run goes on to the
    right consensus (it used to hang with the world frozen, and stall with the robots)."""
    from swarm_helpers import processes_of, swarm_command, wait_for_processes

    run_id = unique_run_id(f"frozen-{frozen}")
    robots, sites, seed = 10, 10, 0  # 153 s of sim time: long enough to freeze it midway
    command = swarm_command(
        "run",
        *("--run-id", run_id, "--json", "--quiet", "--no-record", "--verbose"),
        *("--robots", str(robots), "--sites", str(sites), "--seed", str(seed)),
        # Frozen robots are departed robots: the world ticks on without them, as fast as
        # the beacon answers, and the stall window in sim time may pass before they come
        # back (then the run ends stalled, saying so). Here only the wall clock limits.
        *("--wall-timeout", "100", "--stall-window", "100000", "--timeout", "100000"),
        # The ten robots in one process, so that one SIGSTOP freezes the robot side whole.
        *("--robots-per-process", str(robots)),
    )
    launcher = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    lines: list[bytes] = []
    started = threading.Event()

    def read_stderr() -> None:
        assert launcher.stderr is not None
        for line in launcher.stderr:
            lines.append(line)
            if b"starting with 10 robot(s)" in line:  # the world's log: tick 0 opens now
                started.set()

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    try:
        assert started.wait(60), b"".join(lines).decode()[-2000:]
        time.sleep(1.0)  # well into the run: a quiet machine takes 3 s or more
        if frozen == "world":
            pids = wait_for_processes(run_id, "world_server.server", 1, 10)
        else:  # the fork server's child: the process of the ten robots
            forked = wait_for_processes(run_id, "multiprocessing.forkserver", 2, 10)
            pids = [pid for pid in forked if _parent(pid) in forked]
            assert len(pids) == 1, pids
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        time.sleep(FROZEN_SECONDS)
        for pid in pids:
            os.kill(pid, signal.SIGCONT)
        assert launcher.stdout is not None
        stdout = launcher.stdout.read()
        launcher.wait(timeout=110)
        reader.join(timeout=10)
    finally:
        if launcher.poll() is None:
            launcher.kill()
        kill_leftovers(run_id)
    summary = json.loads(stdout)
    assert summary["ended"] == "consensus", (summary["ended"], b"".join(lines).decode()[-2000:])
    assert launcher.returncode == 0
    assert summary["chosen_site"] == make_layout(sites, robots, seed).best_site
    # Every token of the frozen side went once (the world saw its links die, or they saw
    # its link die): every robot's, and with the world frozen the beacon's too.
    assert summary["world"]["departures"] == robots + (1 if frozen == "world" else 0)
    assert processes_of(run_id) == []
