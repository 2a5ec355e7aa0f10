"""The robot in C (c_robot/, docs in c_robot/README.md): its unit tests (every conformance
vector a robot needs) and its command line. Its live runs, over UDP, over a serial line and
on an encrypted link, are in tests/test_outside.py, beside the Python program's: each run
has one robot of each, and every robot's results (and the run's digest) equal those of the
all-emulated run of the same seed.

The binary is built with ``make -C c_robot`` (skipped without gcc and make)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from outside_helpers import c_robot_binary, make_c_robot

pytestmark = pytest.mark.timeout(900)


@pytest.fixture(scope="module")
def binary() -> Path:
    built = c_robot_binary()
    if built is None:
        pytest.skip("the C compiler ($CC, or gcc) or make is missing: the C robot cannot be built")
    return built


def test_the_unit_tests_pass(binary: Path) -> None:
    """Every conformance vector a robot needs, bit for bit (make -C c_robot test)."""
    done = make_c_robot("test")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert any(re.fullmatch(r"\d+ passed, 0 failed", line) for line in done.stdout.splitlines())


@pytest.mark.parametrize(
    ("arguments", "says"),
    [
        ([], "the following arguments are required: --link, --id, --key-file"),
        (["--link", "tcp://x:1", "--id", "3", "--key-file", "k"], "argument --link"),
        (["--link", "udp://127.0.0.1:1", "--id", "07", "--key-file", "k"], "argument --id"),
        (
            ["--link", "udp://127.0.0.1:1", "--id", "7", "--key-file", "k", "--give-up", "0"],
            "--give-up",
        ),
        (["--link", "udp://127.0.0.1:1", "--id", "7", "--key-file", "/nonexistent/k"], "key file"),
        (["--bogus"], "unrecognized arguments"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_code_2(
    binary: Path, arguments: list[str], says: str
) -> None:
    done = subprocess.run([str(binary), *arguments], capture_output=True, timeout=30, text=True)
    assert done.returncode == 2
    error_lines = [line for line in done.stderr.splitlines() if "error:" in line]
    assert len(error_lines) == 1 and says in error_lines[0], done.stderr


def test_a_key_file_of_another_robot_is_refused(tmp_path: Path, binary: Path) -> None:
    key = tmp_path / "robot-3.key"
    key.write_text('{"v":1,"run":"demo","keys":{"robot/3":"' + "ab" * 32 + '"}}')
    key.chmod(0o600)
    done = subprocess.run(
        [str(binary), "--link", "udp://127.0.0.1:9", "--id", "4", "--key-file", str(key)],
        capture_output=True,
        timeout=30,
        text=True,
    )
    assert done.returncode == 2
    assert "holds no key for robot 4" in done.stderr
