"""What ``swarm`` prints, read as a person would: a short usage line before the one-line
error of a bad option, plain progress lines when stderr is not a terminal, and the kills
and restarts of a run in its per-robot table."""

from __future__ import annotations

import os
import subprocess

import pytest
from swarm_helpers import REPO, kill_leftovers, swarm_command, unique_run_id

pytestmark = pytest.mark.timeout(180)


def _swarm(*arguments: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    # Wide enough that a table's row is one line.
    return subprocess.run(
        swarm_command(*arguments),
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=timeout,
        env={**os.environ, "COLUMNS": "200"},
    )


@pytest.mark.parametrize(
    ("arguments", "usage", "error"),
    [
        (["run", "--robots", "-3"], "usage: swarm run [options] (", "argument --robots: -3"),
        (["report", "--out", "x"], "usage: swarm report [options] RUN.mcap", "required: RUN.mcap"),
        (["bogus"], "usage: swarm [options] COMMAND", "invalid choice: 'bogus'"),
    ],
)
def test_a_bad_option_is_a_short_usage_line_and_one_line_of_error(
    arguments: list[str], usage: str, error: str
) -> None:
    done = _swarm(*arguments)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 2, done.stderr
    assert lines[0].startswith(usage) and "--help lists the options" in lines[0]
    assert lines[1].startswith(f"swarm{'' if arguments[0] == 'bogus' else ' ' + arguments[0]}: ")
    assert error in lines[1]


def test_progress_is_plain_lines_when_stderr_is_not_a_terminal() -> None:
    done = _swarm("run", "--engine", "inprocess", "--robots", "10", "--sites", "5", "--no-record")
    assert done.returncode == 0, done.stderr
    progress = [line for line in done.stderr.splitlines() if line.startswith("decided: ")]
    assert progress and progress[0] == "decided: 0/10, starting"
    assert "\x1b[" not in done.stderr and "\r" not in done.stderr  # no live bar's control codes
    assert "swarm run: ended in consensus" in done.stderr


def test_kills_and_restarts_are_in_the_per_robot_table() -> None:
    run_id = unique_run_id("faults-table")
    try:
        done = _swarm(
            "run", "--run-id", run_id, "--robots", "5", "--sites", "3", "--seed", "2",
            "--kill", "3@20", "--restart", "3@40", "--kill", "1@25", "--no-record",
        )  # fmt: skip
    finally:
        kill_leftovers(run_id)
    # Robot 1 stays killed; robot 3's fresh process decides, and the run ends on it.
    assert done.returncode == 0, done.stderr[-2000:]
    assert "swarm run: ended in consensus" in done.stderr
    table = done.stdout
    assert "process" in table, table
    rows = {line.split("│")[1].strip(): line for line in table.splitlines() if line.count("│") > 3}
    assert "killed at 20 s, started again at 40 s" in rows["3"]
    assert "killed at 25" in rows["1"]
    assert "killed" not in rows["0"]
