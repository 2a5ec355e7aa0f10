"""A study's results file: one synced JSON line a run, a torn last line skipped with a
warning (and ended before the next line is written), the later of two lines of a key kept,
and what a run was made with (commit, run lock)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from deploy.study import results


def _run(key: str, value: float) -> dict[str, object]:
    return {"key": key, "params": {}, "seed": 0, "result": {"sim_time_s": value}}


def test_runs_are_appended_one_a_line_and_read_back_by_key(tmp_path: Path) -> None:
    path = tmp_path / "studies" / "s.jsonl"
    with results.Appender(path) as appender:
        appender.add(_run("a seed=0", 1.0))
        appender.add(_run("a seed=1", 2.0))
    assert path.read_text().count("\n") == 2
    loaded = results.load(path)
    assert list(loaded.runs) == ["a seed=0", "a seed=1"]
    assert loaded.skipped == []
    assert results.load(tmp_path / "none.jsonl").runs == {}


def test_a_torn_last_line_is_skipped_with_a_warning_and_ended_by_the_next_writer(
    tmp_path: Path,
) -> None:
    path = tmp_path / "s.jsonl"
    with results.Appender(path) as appender:
        appender.add(_run("a seed=0", 1.0))
    with path.open("a") as file:  # a runner killed while it wrote a line
        file.write('{"key": "a seed=1", "params": {}, "res')
    loaded = results.load(path)
    assert list(loaded.runs) == ["a seed=0"]
    (warning,) = loaded.skipped
    assert "its last line is not a whole run" in warning
    with results.Appender(path) as appender:
        appender.add(_run("a seed=1", 2.0))
    loaded = results.load(path)
    assert list(loaded.runs) == ["a seed=0", "a seed=1"]
    (warning,) = loaded.skipped
    assert "line 2 is not a whole run" in warning


def test_the_later_line_of_a_key_is_the_run(tmp_path: Path) -> None:
    path = tmp_path / "s.jsonl"
    with results.Appender(path) as appender:
        appender.add(_run("a seed=0", 1.0))
        appender.add(_run("a seed=0", 3.0))
    assert results.load(path).runs["a seed=0"]["result"] == {"sim_time_s": 3.0}


def test_the_lock_is_a_hash_of_the_run_lock(tmp_path: Path) -> None:
    (tmp_path / "requirements").mkdir()
    (tmp_path / "requirements" / "run.lock").write_text("numpy==2.4.6\n")
    assert results.lock_hash(tmp_path) == hashlib.sha256(b"numpy==2.4.6\n").hexdigest()[:12]
    assert results.lock_hash(tmp_path / "elsewhere") is None


def test_commits_and_locks_are_counted_with_uncommitted_changes_marked() -> None:
    records = [
        {"commit": "abc1234", "dirty": False, "lock": "l1"},
        {"commit": "abc1234", "dirty": True, "lock": "l1"},
        {"commit": "abc1234", "dirty": False},
    ]
    assert results.made_with(records) == {"abc1234": 2, "abc1234+": 1}
    assert results.locks(records) == {"l1": 2, "unknown": 1}
    assert json.dumps(results.made_with([])) == "{}"
