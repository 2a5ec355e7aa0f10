"""``swarm run --engine inprocess`` and ``swarm experiment --engine inprocess``: the same
summary, endings, exit codes and recordings as ``swarm run``, without processes; the
options it cannot honour are usage errors. (Robot for robot against a real ``swarm run``:
tests/test_swarm.py.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO, kill_leftovers, swarm_command

from bestofn_swarm.wire import keyspace
from deploy import cli
from deploy.reports.collect import read_recording
from deploy.reports.rows import run_summary

pytestmark = pytest.mark.timeout(180)

FOUR = ["--engine", "inprocess", "--robots", "4", "--sites", "3", "--no-record", "--json"]


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict[str, Any]]:
    code = cli.main(["run", *argv, "--quiet"])
    return code, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(
    ("options", "ended", "code"),
    [
        (["--seed", "1", "--threshold", "0.5"], "consensus", 0),
        # Deciding at 0.5 with three sites: one comparison each, and the robots disagree.
        (["--seed", "2", "--threshold", "0.5"], "split", 3),
        (
            ["--seed", "0", "--robots", "1", "--beacon-outage", "0:1e6", "--stall-window", "20"],
            "stalled",
            4,
        ),
        (["--seed", "0", "--timeout", "5"], "timeout", 5),
    ],
)
def test_each_ending_has_swarm_runs_exit_code(
    capsys: pytest.CaptureFixture[str], options: list[str], ended: str, code: int
) -> None:
    exit_code, summary = _run(capsys, *FOUR, *options)
    assert (summary["ended"], exit_code) == (ended, code)
    assert summary["faults"] == [] and summary["recording"] is None
    assert summary["config"]["engine"] == "inprocess"
    if ended == "timeout":
        assert summary["timeout_kind"] == "sim"


def test_a_wall_time_limit_ends_the_run_as_a_wall_timeout(
    capsys: pytest.CaptureFixture[str],
) -> None:
    exit_code, summary = _run(capsys, *FOUR, "--seed", "0", "--wall-timeout", "0.05")
    assert (summary["ended"], summary["timeout_kind"], exit_code) == ("timeout", "wall", 5)
    # Stopped long before anyone could decide (the first decision takes tens of seconds of
    # sim time): every robot is still undecided, and listed.
    assert [robot["id"] for robot in summary["stuck"]] == [0, 1, 2, 3]


@pytest.mark.parametrize(
    "options",
    [
        ["--clock", "realtime"],
        ["--robots-per-process", "2"],
        ["--spawn", "exec"],
        ["--connect", "tcp/127.0.0.1:7447"],
        ["--secure"],
        ["--view", "0"],
        ["--foxglove", "0"],
        ["--trace", "somewhere"],
    ],
)
def test_what_it_cannot_honour_is_a_one_line_usage_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, options: list[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["run", "--engine", "inprocess", "--record", str(tmp_path / "r.mcap"), *options])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.startswith(f"swarm run: error: --engine inprocess cannot honour {options[0]}")
    assert error.count("\n") == 1
    assert list(tmp_path.iterdir()) == []  # nothing was started, nothing written


def test_its_recording_reads_like_a_swarm_run_recording(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "runs" / "inprocess.mcap"
    argv = [o for o in FOUR if o != "--no-record"]
    exit_code, summary = _run(capsys, *argv, "--seed", "0", "--record", str(path))
    assert exit_code == 0 and summary["recording"] == str(path)
    recording = read_recording(path)
    assert recording.complete and recording.problem is None
    reported = run_summary(recording)
    assert reported["source"] == "metadata"
    assert reported["missing_messages"] == 0
    assert {**reported, "source": None, "complete": None, "missing_messages": None} == {
        **summary,
        "source": None,
        "complete": None,
        "missing_messages": None,
    }
    ticks = recording.clock.count
    assert recording.clock.first == 0 and recording.clock.last == ticks - 1
    for robot in range(4):  # every tick's sense and act of every robot, none missing
        assert (recording.sense[robot].first, recording.sense[robot].count) == (0, ticks)
        assert (recording.act[robot].first, recording.act[robot].count) == (0, ticks)
    # The beacon answers the ticks with a transmission due (every 5), as over Zenoh.
    assert recording.ack.count == len(range(0, ticks, 5)) == recording.ack.expected
    messages = recording.messages
    # Every radio message, frame and delivery the messages declare is in the recording.
    assert messages[keyspace.RADIO_RX.name] == recording.declared.rx > 0
    assert messages[keyspace.RADIO_TX.name] == recording.declared.tx > 0
    assert messages[keyspace.CAMERA.name] == recording.declared.camera > 0
    assert recording.declared.status_gaps == 0
    assert messages[keyspace.STATE.name] == len(range(0, ticks, 10)) + 1  # and the last
    recorded = [keyspace.ACK, keyspace.ACT, keyspace.CLOCK, keyspace.RADIO_RX, keyspace.RADIO_TX]
    recorded += [keyspace.SENSE, keyspace.STATUS, keyspace.STATE, keyspace.CAMERA]
    assert set(messages) == {kind.name for kind in recorded} | {
        "foxglove.FrameTransforms",
        "foxglove.SceneUpdate",
        "bestofn.SwarmSample",  # the swarm's curves, one per world state
    }
    assert messages["bestofn.SwarmSample"] == messages[keyspace.STATE.name]


def test_a_stop_signal_ends_it_interrupted_with_its_summary_and_recording(
    tmp_path: Path,
) -> None:
    path = tmp_path / "interrupted.mcap"
    command = swarm_command(
        "run", "--engine", "inprocess", "--robots", "30", "--seed", "0", "--json", "--quiet"
    )
    process = subprocess.Popen([*command, "--record", str(path)], stdout=subprocess.PIPE, cwd=REPO)
    try:
        deadline = time.monotonic() + 60
        while not (path.exists() and path.stat().st_size > 0) and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(process.pid, signal.SIGTERM)
        out, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 128 + signal.SIGTERM
    summary = json.loads(out)
    assert (summary["ended"], summary["signal"]) == ("interrupted", "SIGTERM")
    recording = read_recording(path)
    assert recording.complete and run_summary(recording)["ended"] == "interrupted"


def test_an_experiment_runs_in_process_runs_in_parallel_and_reports_their_endings(
    tmp_path: Path,
) -> None:
    out = tmp_path / "exp"
    command = swarm_command(
        "experiment",
        *("--engine", "inprocess", "--robots", "3", "--sites", "3", "--runs", "3"),
        *("--parallel", "2", "--seed", "4", "--timeout", "60", "--out", str(out)),
        *("--name", "inproc", "--json", "--quiet"),
    )
    try:
        done = subprocess.run(command, capture_output=True, timeout=150, cwd=REPO)
    finally:
        kill_leftovers("inproc-N3")
    assert done.returncode == 0, done.stderr.decode()
    report = json.loads(done.stdout)
    # Seeds 4, 5 and 6 (deterministic): two consensus runs and one at the sim time limit.
    endings = {"inproc-N3-n3-r01": "consensus", "inproc-N3-n3-r02": "timeout"}
    endings["inproc-N3-n3-r03"] = "consensus"
    for run_id, ended in endings.items():
        printed = json.loads((out / "logs" / f"{run_id}.json").read_text())
        assert (printed["ended"], printed["config"]["engine"]) == (ended, "inprocess")
    assert {row["run_id"]: row["ended"] for row in report["runs"]} == endings
    (group,) = report["groups"]
    assert group["endings"] == {"consensus": 2, "timeout": 1}
    assert report["parallel"] == 2 and report["failed"] == []
