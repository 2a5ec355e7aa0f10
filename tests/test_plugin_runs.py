"""Plug-ins in every engine and on every host (docs/extending.md): the example plug-in
(examples/linear_pool, installed) makes the same run over Zenoh as in one process; a plug-in
that fails over Zenoh ends the run as it does in one process, with the same line, a
finished recording and no process left; a study declared in a file makes and checks runs
with it, each row saying what made it; and a whole controller plugged into ``robot-agent
--link`` is checked by ``swarm conformance`` as a port written in Python would be. Two hosts:
tests/test_multihost.py."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO, kill_leftovers, processes_of, reference_run, unique_run_id

from deploy.reports.collect import read_recording

pytestmark = pytest.mark.timeout(600)

TESTS = REPO / "tests"
SWARM = ["--robots", "6", "--sites", "4", "--seed", "3", "--timeout", "600"]
EXAMPLE = importlib.util.find_spec("bestofn_linear_pool") is not None
needs_example = pytest.mark.skipif(
    not EXAMPLE, reason="the example plug-in is not installed: pip install -e examples/linear_pool"
)


def environment() -> dict[str, str]:
    """This environment with tests/ on the module path (plugin_samples:NAME)."""
    path = os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path}


def swarm(*arguments: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "deploy.cli", *arguments],
        cwd=REPO,
        env=environment(),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def over_zenoh(run_id: str, *options: str) -> tuple[int, dict[str, Any], str]:
    """``swarm run OPTIONS`` over Zenoh: exit code, summary, standard error; every process of
    the run is gone after it (SIGKILLed if not, and the test fails)."""
    try:
        done = swarm("run", "--run-id", run_id, "--json", "--quiet", *options)
    finally:
        left = kill_leftovers(run_id)
    assert left == [], f"processes of the run left behind: {left}"
    return done.returncode, json.loads(done.stdout), done.stderr


def without_phase(robots: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{key: value for key, value in robot.items() if key != "phase"} for robot in robots]


@needs_example
def test_the_example_plugin_makes_the_same_run_over_zenoh_as_in_one_process() -> None:
    options = [*SWARM, "--pooling", "linear"]
    code, summary, _ = over_zenoh(unique_run_id("plug"), *options, "--no-record")
    alone = reference_run(options)
    assert code == 0 and summary["ended"] == "consensus"
    # Each robot's phase at the end may differ: the launcher notices the ending a few ticks
    # after the run in one process stops (docs/running.md); the rest may not.
    assert without_phase(summary["per_robot"]) == without_phase(alone["per_robot"])
    assert summary["digest"] == alone["digest"]
    assert summary["robot_processes"] == 6  # a process per robot, each finding the plug-in
    made = summary["config"]["plugins"]["pooling"]
    assert made["name"] == "linear" and made["distribution"] == "bestofn-linear-pool"
    assert made == alone["config"]["plugins"]["pooling"]
    assert alone["digest"] != reference_run(SWARM)["digest"]  # it is another rule


def test_a_plugin_that_fails_over_zenoh_ends_the_run_as_in_one_process(tmp_path: Path) -> None:
    run_id = unique_run_id("fail")
    record = tmp_path / "failed.mcap"
    pooling = ["--pooling", "plugin_samples:raising"]
    code, summary, error = over_zenoh(run_id, *SWARM, *pooling, "--record", str(record))
    sys.path.insert(0, str(TESTS))
    try:
        alone = reference_run([*SWARM, *pooling])
    finally:
        sys.path.remove(str(TESTS))
    assert code == 1 and summary["ended"] == "crashed" == alone["ended"]
    assert summary["error"] == alone["error"]
    assert summary["error"].startswith(
        "pooling plug-in 'plugin_samples:raising' raised ZeroDivisionError: a pool of more "
        "than one (robot "
    )
    assert "Traceback" not in error
    recording = read_recording(record)
    assert recording.complete and recording.problem is None
    assert recording.summary is not None and recording.summary["error"] == summary["error"]
    assert recording.config["plugins"]["pooling"]["name"] == "plugin_samples:raising"
    assert processes_of(run_id) == []


def test_a_plugin_that_cannot_make_a_robot_over_zenoh_says_so_in_one_line() -> None:
    code, summary, error = over_zenoh(
        unique_run_id("unmade"),
        *SWARM,
        "--strategy",
        "plugin_samples:unmade_strategy",
        "--no-record",
    )
    assert code == 1 and summary["ended"] == "crashed"
    assert summary["error"] == (
        "strategy plug-in 'plugin_samples:unmade_strategy' raised RuntimeError: no strategy for "
        "robot 2 making robot 2's strategy"
    )
    assert "Traceback" not in error


@needs_example
def test_a_declared_study_makes_and_checks_runs_with_the_plugin(tmp_path: Path) -> None:
    study = ["study", "linear-pool", "--declared", "examples/linear_pool/study.py"]
    where = ["--root", str(tmp_path), "--only", "seed=0", "--quiet"]
    made = swarm(*study, *where, "--new", "--parallel", "2", timeout=600)
    assert made.returncode == 0, made.stderr[-2000:]
    assert made.stdout.strip().splitlines()[-1] == "2 done, 0 missing"
    rows = [
        json.loads(line)
        for line in (tmp_path / "results" / "linear-pool.jsonl").read_text().splitlines()
    ]
    by_pooling = {row["params"]["pooling"]: row for row in rows}
    assert set(by_pooling) == {"mprodop", "linear"}
    linear = by_pooling["linear"]["plugins"]["pooling"]
    assert (linear["name"], linear["distribution"], linear["version"]) == (
        "linear",
        "bestofn-linear-pool",
        "0.1.0",
    )
    assert by_pooling["mprodop"]["plugins"]["pooling"]["distribution"] == "bestofn-swarm"
    assert by_pooling["linear"]["result"]["digest"] != by_pooling["mprodop"]["result"]["digest"]
    checked = swarm(*study, "--root", str(tmp_path), "--check", "--sample", "2", timeout=600)
    assert checked.returncode == 0, checked.stdout[-2000:] + checked.stderr[-2000:]
    assert "linear-pool: 2 of 2 runs as published" in checked.stderr


def test_a_whole_controller_on_a_link_is_checked_by_swarm_conformance() -> None:
    """A port written in Python, plugged into robot-agent --link as its controller: the
    paper's controller itself conforms; one whose wheels run away from 2 s on fails, with
    one line naming it, the robot and the tick."""
    link = [sys.executable, "-m", "robot_agent.link", "--controller"]
    same = swarm("conformance", "--no-swarm", *link, "plugin_samples:paper_controller", timeout=600)
    assert same.returncode == 0, same.stdout[-3000:]
    assert same.stdout.splitlines()[-1].startswith("PASS: every tick of 5 tracks")
    wrong = swarm(
        "conformance", "--no-swarm", *link, "plugin_samples:StallingController", timeout=600
    )
    assert wrong.returncode == 1, wrong.stdout[-3000:]
    assert wrong.stdout.splitlines()[-1].startswith("FAIL: track ")


def test_swarm_experiment_runs_the_plugin_in_each_of_its_runs(tmp_path: Path) -> None:
    done = swarm(
        "experiment", "--engine", "inprocess", "--robots", "6", "--sites", "4", "--runs", "2",
        "--pooling", "plugin_samples:product", "--out", str(tmp_path), timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    recordings = sorted(tmp_path.glob("*.mcap"))
    assert len(recordings) == 2
    for path in recordings:
        made = read_recording(path).config["plugins"]["pooling"]
        assert made["name"] == "plugin_samples:product" and made["source"] is not None
