"""The study runner end to end, on the tiny study of tests/study_tiny.py: made on two
worker processes, killed (SIGKILL) after its first run, its workers gone with it, resumed
(only what is missing is made), rendered, checked, and a run over Zenoh with real
processes and a recording, the same run as in one process."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from swarm_helpers import REPO, swarm_command

from deploy.study import lock, make, results
from deploy.study.catalogue import study_named

TINY = REPO / "tests" / "study_tiny.py"
IN_PROCESS = 6  # the tiny study's runs in one process


def _command(root: Path, *arguments: str) -> list[str]:
    return swarm_command(
        "study", "tiny", "--declared", str(TINY), "--root", str(root), "--quiet", *arguments
    )


def _workers_of(runner: int) -> list[int]:
    """Live processes that the runner ``runner`` started as its workers."""
    marker = f"{make.RUNNER_ENV}={runner}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        try:
            state = (entry / "stat").read_text().split()[2]
            if state != "Z" and marker in (entry / "environ").read_bytes().split(b"\0"):
                found.append(int(entry.name))
        except (OSError, IndexError):
            continue
    return found


@pytest.fixture
def root(tmp_path: Path) -> Iterator[Path]:
    import study_tiny

    (tmp_path / study_tiny.PAGE).write_text(study_tiny.page_text())
    yield tmp_path


def _lines(path: Path) -> list[bytes]:
    return path.read_bytes().split(b"\n") if path.exists() else []


@pytest.mark.timeout(400)
def test_a_killed_runner_loses_only_its_runs_in_flight_and_resumes(
    root: Path, short_tmp: Path
) -> None:
    results_file = root / "docs" / "studies" / "tiny.jsonl"
    environment = {**os.environ, "TMPDIR": str(short_tmp)}
    runner = subprocess.Popen(
        _command(root, "--only", "engine=inprocess", "--parallel", "2"),
        cwd=REPO,
        env=environment,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 180
        while not any(line.strip() for line in _lines(results_file)) and runner.poll() is None:
            assert time.monotonic() < deadline, "no run finished"
            time.sleep(0.02)
        workers = _workers_of(runner.pid)
        runner.send_signal(signal.SIGKILL)
        runner.wait(timeout=30)
        deadline = time.monotonic() + 60
        while _workers_of(runner.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert workers, "the runner had no worker processes"
        assert _workers_of(runner.pid) == []  # they die with it
    finally:
        if runner.poll() is None:
            os.killpg(runner.pid, signal.SIGKILL)
            runner.wait(timeout=30)
    kept = results.load(results_file)
    assert kept.skipped == []  # every line the kill left is whole
    assert 1 <= len(kept.runs) < IN_PROCESS, "the kill came after every run was made"
    with results_file.open("ab") as file:  # as if the kill had come in mid-line
        file.write(b'{"key": "drop=0.2 engine=inprocess seed=2", "para')

    status = subprocess.run(
        _command(root, "--status", "--only", "engine=inprocess"),
        cwd=REPO, capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    missing = IN_PROCESS - len(kept.runs)
    assert status.stdout.strip().splitlines()[-1] == f"{len(kept.runs)} done, {missing} missing"
    assert "its last line is not a whole run" in status.stderr

    resumed = subprocess.run(
        _command(root, "--only", "engine=inprocess", "--parallel", "2"),
        cwd=REPO, env=environment, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert resumed.stdout.strip().splitlines()[-1] == f"{IN_PROCESS} done, 0 missing"
    lines = [line for line in _lines(results_file) if line.strip()]
    keys = [json.loads(line)["key"] for line in lines[: -0 or None] if line.startswith(b'{"key":"')]
    assert len(keys) == len(set(keys)) == IN_PROCESS  # made once each: none twice, none lost
    after = results.load(results_file)
    assert len(after.skipped) == 1 and "line" in after.skipped[0]  # the torn line, now ended

    # Every run is the run `swarm run` makes: one of them made again here.
    study = study_named("tiny", [TINY])
    run = next(run for run in study.runs() if run.key == "drop=0.2 engine=inprocess seed=1")
    assert make.make(run)["result"] == after.runs[run.key]["result"]
    # Made with this checkout's code and run lock, wherever its results file is.
    assert after.runs[run.key]["lock"] == results.lock_hash(REPO)
    assert after.runs[run.key]["commit"] == results.provenance()["commit"] is not None
    assert after.runs[run.key]["command"] == (
        "swarm run --robots 10 --sites 5 --drop 0.2 --seed 1 --timeout 120"
    )

    rendered = subprocess.run(
        _command(root, "--render"), cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert rendered.returncode == 0, rendered.stderr
    page = (root / "tiny.md").read_text()
    assert f"{IN_PROCESS} of the 7 runs the study declares" in page
    assert "**1 run is missing**" in page
    assert "1 of the 7 runs of tiny are missing" in " ".join(rendered.stderr.split())

    checked = subprocess.run(
        _command(root, "--check", "--sample", "2", "--parallel", "1"),
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert checked.returncode == 0, checked.stdout + checked.stderr
    # A published result that the code no longer gives: the check names its key and field.
    changed = dict(after.runs[run.key])
    changed["result"] = {**changed["result"], "sim_time_s": 1.5}
    with results.Appender(results_file) as appender:
        appender.add(changed)
    checked = subprocess.run(
        _command(root, "--check", "--sample", str(IN_PROCESS), "--parallel", "1"),
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert checked.returncode == 1
    expected = (
        f"tiny run {run.key}: sim_time_s: 1.5 -> {after.runs[run.key]['result']['sim_time_s']!r}"
    )
    assert expected in checked.stdout.splitlines()


@pytest.mark.timeout(400)
def test_a_point_over_zenoh_is_made_by_real_processes_and_recorded(
    root: Path, short_tmp: Path
) -> None:
    recordings = root / "recordings"
    made = subprocess.run(
        _command(
            root, "--only", "engine=zenoh", "--parallel", "1", "--recordings", str(recordings)
        ),
        cwd=REPO,
        env={**os.environ, "TMPDIR": str(short_tmp)},
        capture_output=True,
        text=True,
        timeout=360,
    )
    assert made.returncode == 0, made.stderr[-3000:]
    (record,) = results.load(root / "docs" / "studies" / "tiny.jsonl").runs.values()
    assert record["kind"] == "zenoh"
    recording = root / record["recording"]["path"]  # kept relative to the root
    assert recording.parent == recordings / "tiny"
    assert recording.stat().st_size == record["recording"]["bytes"] > 0
    assert recording.read_bytes()[:8] == b"\x89MCAP0\r\n"
    # Lockstep over Zenoh is the run in one process, to the bit.
    (run,) = [run for run in study_named("tiny", [TINY]).runs() if run.kind == "zenoh"]
    in_process = make.make(dataclasses.replace(run, kind="inprocess", record=False))["result"]
    assert record["result"]["ended"] == "consensus"
    assert record["result"] == in_process


@pytest.mark.timeout(400)
def test_two_runners_on_one_results_file_make_each_run_once(root: Path, short_tmp: Path) -> None:
    """The second runner is refused and names the first; with --wait it waits for it and
    then finds nothing missing."""
    results_file = root / "docs" / "studies" / "tiny.jsonl"
    environment = {**os.environ, "TMPDIR": str(short_tmp)}
    only = ("--only", "engine=inprocess", "--parallel", "1")
    first = subprocess.Popen(
        _command(root, *only), cwd=REPO, env=environment, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        held = lock.lock_path(results_file)
        deadline = time.monotonic() + 120
        while f"pid {first.pid} " not in (held.read_text() if held.exists() else ""):
            assert first.poll() is None, "the first runner ended before it took the lock"
            assert time.monotonic() < deadline, "the first runner took no lock"
            time.sleep(0.02)
        # The first runner stands still, holding the lock, until the waiting one waits
        # (else it may finish its few runs first on a busy machine: nothing to wait for).
        os.killpg(first.pid, signal.SIGSTOP)
        second = subprocess.run(
            _command(root, *only), cwd=REPO, env=environment, capture_output=True, text=True,
            timeout=120,
        )  # fmt: skip
        assert second.returncode == 2
        assert f"is being made by pid {first.pid} on " in second.stderr
        waiting = subprocess.Popen(
            _command(root, *only, "--wait"), cwd=REPO, env=environment, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            assert waiting.stderr is not None
            said = ""
            deadline = time.monotonic() + 120
            while "waiting for it to end" not in " ".join(said.split()):
                assert time.monotonic() < deadline, said[-2000:]
                line = waiting.stderr.readline()
                assert line, f"the waiting runner ended: {said[-2000:]}"
                said += line
            os.killpg(first.pid, signal.SIGCONT)
            stdout, rest = waiting.communicate(timeout=300)
        finally:
            if waiting.poll() is None:
                waiting.kill()
                waiting.communicate()
        assert waiting.returncode == 0, (said + rest)[-2000:]
        assert stdout.strip().splitlines()[-1] == f"{IN_PROCESS} done, 0 missing"
        assert first.wait(timeout=300) == 0
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGCONT)
            os.killpg(first.pid, signal.SIGKILL)
        first.communicate(timeout=30)
    keys = [json.loads(line)["key"] for line in _lines(results_file) if line.strip()]
    assert len(keys) == len(set(keys)) == IN_PROCESS  # each run made once
