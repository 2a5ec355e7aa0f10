"""Files at a user's paths: written readable by their owner only
(bestofn_swarm/plumbing/private_files.py), read with a size limit
(bestofn_swarm/plumbing/bounded_read.py); key files and configurations that fail say so in one line
with exit code 2; the sweep of run directories whose launcher is gone (deploy/security/janitor.py).
The same against live processes: tests/test_private_runs.py."""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

import pytest

from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.plumbing.bounded_read import read_bounded, read_bounded_text
from bestofn_swarm.plumbing.private_files import make_private_folder, open_private, write_private
from bestofn_swarm.plumbing.trace import TraceWriter
from bestofn_swarm.wire import settings
from deploy.security import certificates
from deploy.security.janitor import MAKER_FILE, PREFIX, PrivateDirectory, maker_alive, sweep
from world_server.recording.description import json_object
from world_server.server import cli as world_cli


def mode_of(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


# --- written private ---------------------------------------------------------------------


def test_a_new_file_is_private_and_a_file_written_over_becomes_private(tmp_path: Path) -> None:
    fresh = tmp_path / "fresh.mcap"
    with open_private(fresh, "wb") as stream:
        stream.write(b"x")
    assert mode_of(fresh) == 0o600
    old = tmp_path / "old.mcap"
    old.write_bytes(b"world readable, as a file from before")
    old.chmod(0o644)
    write_private(old, b"new")
    assert mode_of(old) == 0o600 and old.read_bytes() == b"new"
    write_private(tmp_path / "text.json", "{}\n")
    assert mode_of(tmp_path / "text.json") == 0o600


def test_folders_made_are_private_and_folders_found_are_left_alone(tmp_path: Path) -> None:
    found = tmp_path / "runs"
    found.mkdir(mode=0o755)
    found.chmod(0o755)
    made = make_private_folder(found / "a" / "b")
    assert made == found / "a" / "b"
    assert mode_of(found) == 0o755
    assert mode_of(found / "a") == 0o700 and mode_of(found / "a" / "b") == 0o700
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError):
        make_private_folder(tmp_path / "file")


def test_a_trace_is_private(tmp_path: Path) -> None:
    trace = TraceWriter(tmp_path / "world.jsonl")
    trace.write(tick=1)
    trace.close()
    assert mode_of(tmp_path / "world.jsonl") == 0o600


def test_certificates_and_keys_are_private(tmp_path: Path) -> None:
    ca, ca_key = tmp_path / "ca" / "ca.pem", tmp_path / "ca" / "ca.key"
    certificates.create_ca(ca, ca_key, days=1)
    certificates.issue_all(["router"], ["robot-0"], ca, ca_key, tmp_path / "certs", days=1)
    assert mode_of(tmp_path / "ca") == 0o700 and mode_of(tmp_path / "certs") == 0o700
    written = [ca, ca_key, *(tmp_path / "certs").iterdir()]
    assert len(written) == 7  # ca.pem copied, and a key and a certificate for each
    assert {mode_of(path) for path in written} == {0o600}


# --- read bounded ------------------------------------------------------------------------


def test_a_read_stops_at_its_limit_whatever_the_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"key file /dev/zero is too big \(more than 100 bytes"):
        read_bounded("/dev/zero", 100, "key file")
    small = tmp_path / "small"
    small.write_bytes(b"x" * 100)
    assert read_bounded(small, 100) == b"x" * 100
    with pytest.raises(ValueError, match="too big"):
        read_bounded(small, 99)
    with pytest.raises(ValueError, match=r"cannot read file .*: No such file"):
        read_bounded(tmp_path / "missing", 100)
    small.write_bytes(b"\xff\xfe")
    with pytest.raises(ValueError, match="not UTF-8"):
        read_bounded_text(small, 100)


def test_a_key_file_that_never_ends_is_a_usage_error_of_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(ValueError, match="too big"):
        run_keys.load("demo", "/dev/zero", "test")
    # As each process reads it: exit code 2, one line, before any session opens.
    with pytest.raises(SystemExit) as exited:
        world_cli.main(["--run-id", "demo", "--key-file", "/dev/zero"])
    assert exited.value.code == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "key file /dev/zero is too big" in error


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        (None, "too big"),  # /dev/zero
        ("{mode: ", "Zenoh configuration"),
        ("\xff", "Zenoh configuration"),
    ],
)
def test_a_zenoh_configuration_is_read_bounded_and_checked_before_any_session(
    text: str | None, reason: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = "/dev/zero"
    if text is not None:
        path = str(tmp_path / "zenoh.json5")
        Path(path).write_text(text, encoding="latin-1")
    with pytest.raises(SystemExit) as exited:
        world_cli.main(["--run-id", "demo", "--zenoh-config", path])
    assert exited.value.code == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and reason in error


def test_a_configuration_text_has_a_size_limit_too() -> None:
    too_long = '{"x": "' + "a" * settings.MAX_TEXT_BYTES + '"}'
    with pytest.raises(ValueError, match="longer than"):
        settings.decode(too_long, dict)
    with pytest.raises(ValueError, match="longer than"):
        json_object(too_long)


def test_run_keys_out_an_existing_file_is_one_line_not_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    existing = tmp_path / "keys"
    existing.write_text("not a folder")
    assert run_keys.main(["--run-id", "demo", "--robots", "2", "--out", str(existing)]) == 2
    error = capsys.readouterr().err
    assert error == f"run_keys: error: cannot write {existing}: not a folder\n"


# --- run directories whose launcher is gone ------------------------------------------------


def _dead_pid() -> int:
    """A pid no process has now (the highest pid is rarely taken)."""
    highest = int(Path("/proc/sys/kernel/pid_max").read_text())
    for pid in range(highest - 1, highest - 1000, -1):
        if not Path(f"/proc/{pid}").exists():
            return pid
    raise AssertionError("no free pid found")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_next_run_sweeps_directories_whose_launcher_is_gone(tmp_path: Path) -> None:
    mine = PrivateDirectory.create(str(tmp_path), janitor=False)
    assert mode_of(mine.path) == 0o700 and maker_alive(mine.path)
    orphan = tmp_path / f"{PREFIX}orphan"
    (orphan / "certs").mkdir(parents=True)
    (orphan / "certs" / "robot-0.key").write_text("private")
    (orphan / MAKER_FILE).write_text(f"{_dead_pid()} 12345\n")
    reused = tmp_path / f"{PREFIX}reused"  # our pid, but another start time: another process
    reused.mkdir()
    (reused / MAKER_FILE).write_text(f"{os.getpid()} 1\n")
    unknown = tmp_path / f"{PREFIX}unknown"  # no maker file: not ours to judge
    unknown.mkdir()
    other = tmp_path / "other"
    other.mkdir()
    assert sorted(sweep(tmp_path)) == [orphan, reused]
    assert mine.path.exists() and unknown.exists() and other.exists()
    second = PrivateDirectory.create(str(tmp_path), janitor=False)  # sweeps too
    assert mine.path.exists()
    second.close()
    mine.close()
    assert not mine.path.exists() and not second.path.exists()
