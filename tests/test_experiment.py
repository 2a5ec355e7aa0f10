"""``swarm experiment``: a small real experiment end to end, and its argument errors."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import pytest
from swarm_helpers import (
    REPO,
    kill_leftovers,
    private_directories,
    processes_of,
    swarm_command,
    unique_run_id,
)

from deploy.cli import main
from deploy.reports import collect, report


@pytest.mark.timeout(300)
def test_a_small_experiment_records_every_run_and_reports(tmp_path: Path) -> None:
    name = unique_run_id("exp")
    out = tmp_path / "experiment"
    try:
        done = subprocess.run(
            swarm_command(
                "experiment",
                "--robots",
                "3",
                "--sites",
                "5",
                "--runs",
                "2",
                "--parallel",
                "2",
                "--seed",
                "4",
                "--name",
                name,
                "--out",
                str(out),
                "--json",
                "--quiet",
                "--",
                "--stall-timeout",
                "5",
            ),
            capture_output=True,
            timeout=280,
            cwd=REPO,
        )
    finally:
        left = kill_leftovers(name)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    assert left == [] and processes_of(name) == []
    result = json.loads(done.stdout)
    run_ids = [f"{name}-N3-n5-r01", f"{name}-N3-n5-r02"]
    assert result["failed"] == [] and result["parallel"] == 2
    assert [row["run_id"] for row in result["runs"]] == run_ids
    assert [row["seed"] for row in result["runs"]] == [4, 5]
    for row in result["runs"]:
        assert (row["robots"], row["sites"]) == (3, 5) and row["complete"]
        assert row["source"] == "metadata" and row["consensus"]
        assert row["ended"] == "consensus" and row["stuck"] == 0
        config = json.loads(collect.read_recording(Path(row["recording"])).description["config"])
        assert config["stall_timeout"] == 5.0
        assert config["wall_timeout"] == 1800.0  # --run-timeout, passed on to every run
    for run_id in run_ids:
        assert (out / f"{run_id}.mcap").is_file()
        summary = json.loads((out / "logs" / f"{run_id}.json").read_text())
        assert summary["run_id"] == run_id and summary["recording"] == str(out / f"{run_id}.mcap")
    for figure in report.FIGURES:
        assert (out / figure).stat().st_size > 0
    with open(out / "summary.csv") as stream:
        assert [line["run_id"] for line in csv.DictReader(stream)] == run_ids
    (group,) = result["groups"]
    assert group["runs"] == 2 and group["complete_runs"] == 2
    assert group["endings"] == {"consensus": 2} and group["aggregated_runs"] == 2


@pytest.mark.timeout(300)
def test_runs_that_stall_are_results_labelled_with_their_ending(tmp_path: Path) -> None:
    """A silent beacon: each lone robot waits at the nest until the watchdog ends its run."""
    name = unique_run_id("exp-stall")
    out = tmp_path / "experiment"
    try:
        done = subprocess.run(
            swarm_command(
                *("experiment", "--robots", "1", "--sites", "3", "--runs", "2"),
                *("--stall-window", "20", "--beacon-outage", "0:1000000"),
                *("--name", name, "--out", str(out), "--json", "--quiet"),
            ),
            capture_output=True,
            timeout=280,
            cwd=REPO,
        )
    finally:
        left = kill_leftovers(name)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    assert left == []
    result = json.loads(done.stdout)
    assert result["failed"] == []
    assert [(row["ended"], row["stuck"]) for row in result["runs"]] == [("stalled", 1)] * 2
    (group,) = result["groups"]
    assert group["endings"] == {"stalled": 2} and group["aggregated_runs"] == 0
    assert group["swarm_steps"]["mean"] is None  # no consensus time to aggregate
    for row in result["runs"]:
        config = json.loads(collect.read_recording(Path(row["recording"])).description["config"])
        assert config["stall_window"] == 20.0


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--runs", "0"], "--runs"),
        (["--sites", "1"], "--sites"),
        (["--", "--no-such-option", "3"], "swarm run option"),
        (["--", "--drop", "2"], "swarm run option"),
        (["--alpha", "0.2", "--threshold", "1"], "swarm run option"),
        (["--secure", "--", "--no-keys"], "swarm run option"),
    ],
)
def test_bad_arguments_exit_with_code_2_and_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], arguments: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["experiment", "--out", str(tmp_path / "out"), *arguments])
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert message in lines[-1] and sum("error" in line for line in lines) == 1
    assert not (tmp_path / "out").exists()  # nothing was started


@pytest.mark.timeout(300)
def test_a_secure_experiment_runs_each_swarm_on_its_own_tls_router(tmp_path: Path) -> None:
    name = unique_run_id("sexp")
    out, tmp = tmp_path / "experiment", tmp_path / "tmp"
    tmp.mkdir()
    try:
        done = subprocess.run(
            swarm_command(
                *("experiment", "--robots", "3", "--sites", "4", "--runs", "1"),
                *("--seed", "1", "--name", name, "--out", str(out), "--secure", "--json"),
                "--quiet",
            ),
            capture_output=True,
            timeout=240,
            cwd=REPO,
            env={**os.environ, "TMPDIR": str(tmp)},
        )
    finally:
        left = kill_leftovers(name)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    assert left == []
    (run_log,) = (out / "logs").glob("*.json")
    summary = json.loads(run_log.read_text())
    assert summary["correct"] and summary["config"]["secure"] is True
    assert summary["config"]["connect"] is None  # its own router, not a shared one
    assert private_directories(tmp) == []  # no certificates or sockets left behind
