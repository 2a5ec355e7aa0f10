"""Presence that cannot be forged, freshness in every clock mode: the attacks of issue 23
(cases 1 to 4) against a live ``swarm run``, by a client on the run's router that holds
no keys (``test_attacks.attacked_run``).

1. Fake beacon tokens declared before the real beacon joins must not crowd it out.
2. Fake world tokens coming and going must not make the robots follow a world that is
   not there, nor shift their clocks.
3. Old world states, authentic, replayed to the launcher must not hide a stall.
4. In real time, old acts and radio transmissions, authentic, replayed to the world are
   refused and counted.

Cases 1 and 2 run the issue's 10-robot run (seed 3) and compare it robot for robot with
the same run left alone: lockstep is deterministic, so an attack that changes nothing
leaves every robot's decision and its time as they were.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh
from swarm_helpers import processes_of, run_swarm, unique_run_id
from test_attacks import SMALL, Attacked, assert_right_consensus, attacked_run

from bestofn_swarm.wire import keyspace
from bestofn_swarm.wire.names import Role

pytestmark = pytest.mark.timeout(300)

BLOCK = zenoh.CongestionControl.BLOCK
ISSUE_RUN = ["--robots", "10", "--seed", "3", "--timeout", "400"]


def per_robot(summary: dict[str, Any]) -> list[tuple[int | None, float | None]]:
    return [(robot["decided_site"], robot["decision_time_s"]) for robot in summary["per_robot"]]


@pytest.fixture(scope="module")
def clean() -> dict[str, Any]:
    """The issue's run, left alone."""
    code, summary, stderr = run_swarm(
        [*ISSUE_RUN, "--no-record"], unique_run_id("clean"), timeout=240
    )
    assert code == 0 and summary is not None, stderr[-3000:]
    return summary


def assert_as_clean(
    code: int, summary: dict[str, Any] | None, stderr: str, clean: dict[str, Any]
) -> dict[str, Any]:
    assert code == 0, stderr[-3000:]
    assert summary is not None and summary["ended"] == "consensus"
    assert per_robot(summary) == per_robot(clean)
    assert summary["sim_time_s"] == clean["sim_time_s"]
    assert (summary["world"]["stalls"], summary["world"]["departures"]) == (0, 0)
    assert "Traceback" not in stderr
    return summary


# --- case 1 ----------------------------------------------------------------------------


def test_fake_beacon_tokens_before_the_real_beacon_neither_join_nor_crowd_it_out(
    clean: dict[str, Any],
) -> None:
    """Twenty ``alive/beacon/*`` tokens, declared as the run starts, before the real
    beacon joins: tokens are only hints, so none of them joins, fills MAX_BEACONS or holds
    a tick up; the real beacon, which proves itself with its key, joins as in a clean run."""
    with attacked_run(*ISSUE_RUN, "--no-record") as run:
        liveliness = run.session.liveliness()
        tokens = [
            liveliness.declare_token(run.keys.token(Role.BEACON, f"fake{index}"))
            for index in range(20)
        ]
        code, summary, stderr = run.finish(timeout=240)
        for token in tokens:
            token.undeclare()
    summary = assert_as_clean(code, summary, stderr, clean)
    assert summary["rejected"]["world"] == 0  # hints are not rejections: nothing was said
    assert "more than 16 beacons" not in stderr


# --- case 2 ----------------------------------------------------------------------------


def test_fake_world_tokens_coming_and_going_are_not_followed(clean: dict[str, Any]) -> None:
    """A fake world token declared before the robots start (so a robot may see it first),
    then replaced 30 times by another (each new one declared before the old one goes):
    unproved, a robot followed the fake and took each replacement for a restarted world,
    shifting its clock (decision times up to 266 s against 188 s clean). Now every robot
    and the beacon asks each token to prove itself (world/info for that instance, which
    only the world can answer with the run's key), none does, each is counted as refused,
    and the run ends as a clean one, robot for robot."""
    with attacked_run(*ISSUE_RUN, "--no-record") as run:
        liveliness = run.session.liveliness()
        token = liveliness.declare_token(run.keys.token(Role.WORLD, "fake0"))
        run.wait_for_tick(1, timeout=120)  # every robot started (tick 0 waits for them)
        for index in range(1, 31):
            replacement = liveliness.declare_token(run.keys.token(Role.WORLD, f"fake{index}"))
            time.sleep(0.05)
            token.undeclare()
            token = replacement
            time.sleep(0.05)
        code, summary, stderr = run.finish(timeout=240)
        token.undeclare()
    summary = assert_as_clean(code, summary, stderr, clean)
    # Each refusal is counted where it happened: 31 fake tokens, each seen by every robot
    # and the beacon. A robot reports its count in its next status change, the beacon in
    # every ack.
    assert summary["rejected"]["beacon"] == 31, summary["rejected"]
    assert 0 < summary["rejected"]["robots"] <= 31 * 10, summary["rejected"]


# --- case 3 ----------------------------------------------------------------------------


def robot_process(run_id: str, robot: int) -> int:
    """The pid of robot ``robot``'s own process (``--spawn exec``: a command line each)."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        for pid in processes_of(run_id):
            try:
                args = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            ours = b"robot_agent.node" in args and b"--id" in args
            if ours and args[args.index(b"--id") + 1] == str(robot).encode():
                return pid
        time.sleep(0.05)
    raise TimeoutError(f"no process of robot {robot}")


@pytest.fixture
def frozen() -> Iterator[list[int]]:
    """Pids the test froze (SIGSTOP): thawed at the end, whatever happened."""
    pids: list[int] = []
    yield pids
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)


Sample = tuple[str, bytes, bytes | None]  # key, payload, attachment (its tag included)


def replay_until_done(run: Attacked, samples: list[Sample], every: float) -> int:
    """Put ``samples`` again and again, one every ``every`` seconds (0: as fast as they
    go), until the run ends; how many were put."""
    put = 0
    while run.process.poll() is None:
        for key, payload, attachment in samples:
            run.session.put(
                key,
                payload,
                attachment=attachment,
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
            put += 1
            if every:
                time.sleep(every)
            if run.process.poll() is not None:
                break
    return put


def recorder(run: Attacked, key: str) -> tuple[list[Sample], Any]:
    """Every sample on ``key`` as it came (payload and attachment: tag included)."""
    heard: list[Sample] = []
    lock = threading.Lock()

    def on_sample(sample: zenoh.Sample) -> None:
        extra = sample.attachment.to_bytes() if sample.attachment is not None else None
        with lock:
            heard.append((str(sample.key_expr), sample.payload.to_bytes(), extra))

    return heard, run.session.declare_subscriber(key, on_sample)


FREEZE_TICK = 1200  # sim 120 s: half the robots of the issue's run have decided


def test_replayed_world_states_do_not_hide_a_stall(
    clean: dict[str, Any], frozen: list[int]
) -> None:
    """The robots still undecided at tick 1200 frozen (SIGSTOP) with a stall window of
    30 s: the others, decided, keep the world ticking, and the run ends stalled. Old world
    states, authentic, replayed to the launcher at 20 Hz show the frozen robots elsewhere:
    the launcher refuses each (older than the last it took) and counts it, and the run
    still ends stalled."""
    undecided = [
        robot
        for robot, (_, decided_at) in enumerate(per_robot(clean))
        if decided_at is None or decided_at > FREEZE_TICK * 0.1 + 1.0
    ]
    assert undecided
    options = ("--no-record", "--spawn", "exec", "--stall-window", "30")
    with attacked_run(*ISSUE_RUN, *options) as run:
        states, subscriber = recorder(run, run.keys.of(keyspace.STATE))
        pids = [robot_process(run.run_id, robot) for robot in undecided]
        run.wait_for_tick(FREEZE_TICK, timeout=180)
        frozen.extend(pids)
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        subscriber.undeclare()
        assert len(states) >= 2
        replayed = replay_until_done(run, list(states), every=0.05)
        code, summary, stderr = run.finish(timeout=240)
    assert summary is not None and summary["ended"] == "stalled", (code, stderr[-3000:])
    assert "Traceback" not in stderr
    assert 0 < summary["rejected"]["observer"] <= replayed, (summary["rejected"], replayed)


# --- case 4 ----------------------------------------------------------------------------

# 10x real time: each robot its own process must take 100 senses a wall second, which a
# loaded 2-core machine still does (at 25x a clean run there may already fall behind).
REALTIME = ["--clock", "realtime", "--speed", "10"]
# A replay, not a flood: floods are the inbox caps' business (issue 23, part 5), and at
# full rate on a shared 2-core machine they starve every process of the run.
REPLAY_EVERY = 0.001


@pytest.mark.parametrize("replayed", ["act", "radio"])
def test_in_real_time_replayed_acts_and_radio_are_refused_and_counted(replayed: str) -> None:
    """In real time, robot 0's acts (or every robot's and the beacon's radio messages)
    heard from tick 0 to 50, replayed (up to 1000 a second) from then on: each that
    reaches the world is refused (not after its sender's last) and counted, and the run
    reaches the right consensus; the radio takes no replayed message."""
    with attacked_run(*SMALL, "--no-record", *REALTIME) as run:
        key = (
            run.keys.of(keyspace.ACT, 0)
            if replayed == "act"
            else run.keys.of(keyspace.RADIO_TX, "*")
        )
        heard, subscriber = recorder(run, key)
        run.wait_for_tick(50)
        subscriber.undeclare()
        assert heard
        put = replay_until_done(run, list(heard), every=REPLAY_EVERY)
        code, summary, stderr = run.finish(timeout=240)
    assert_right_consensus(code, summary, stderr)
    assert summary is not None
    rejected = summary["rejected"]["world"]
    assert rejected > 0 and rejected <= put, (rejected, put)
    if replayed == "radio":
        radio = summary["radio"]
        assert radio["rejected"] == rejected, radio
        assert radio["sent"] < 1000, radio  # a clean run of these sends about 200
