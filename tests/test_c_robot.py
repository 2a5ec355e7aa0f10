"""The robot in C (c_robot/, docs in c_robot/README.md) against live runs: robots outside the
emulator run as the C program instead of ``robot-agent --link``, over UDP and over a serial
line, and every robot's results (and the run's digest) equal those of the all-emulated run
of the same seed. Also: its unit tests (the conformance vectors) and its command line.

The binary is built with ``make -C c_robot`` when it is missing (skipped without gcc and
make); every process a test starts is killed by pid when it ends (outside_helpers)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from outside_helpers import OutsideRun, decisions, in_process, outside_run, pty_pair, udp_link
from swarm_helpers import REPO

pytestmark = pytest.mark.timeout(900)

C_ROBOT = REPO / "c_robot"
BINARY = C_ROBOT / "build" / "c-robot"
# A world that waits long for a robot a busy machine starved stays in lockstep.
PATIENT = ["--stall-timeout", "300"]
TEN = ["--robots", "10", "--timeout", "900", "--no-record", *PATIENT]


@pytest.fixture(scope="module")
def binary() -> Path:
    if not BINARY.exists():
        if shutil.which("make") is None or shutil.which("gcc") is None:
            pytest.skip("gcc or make is missing: the C robot cannot be built")
        subprocess.run(["make", "-C", str(C_ROBOT)], check=True, timeout=600, capture_output=True)
    return BINARY


def start_c(run: OutsideRun, binary: Path, link: str, robot: int) -> subprocess.Popen[bytes]:
    """The C program for ``robot``, as a porter starts it; killed with the run's programs."""
    command = [str(binary), "--link", link, "--id", str(robot)]
    started = subprocess.Popen(
        [*command, "--key-file", str(run.key_file(robot)), "--give-up", "60"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    run.programs.append(started)
    return started


def test_the_unit_tests_pass(binary: Path) -> None:
    """Every conformance vector a robot needs, bit for bit (make -C c_robot test)."""
    done = subprocess.run(
        ["make", "-C", str(C_ROBOT), "test"], capture_output=True, timeout=600, text=True
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert any(re.fullmatch(r"\d+ passed, 0 failed", line) for line in done.stdout.splitlines())


@pytest.mark.parametrize("seed", [0, 3])
def test_two_c_robots_over_udp_decide_exactly_as_all_emulated(
    tmp_path: Path, binary: Path, seed: int
) -> None:
    options = [*TEN, "--seed", str(seed)]
    reference = in_process(options)
    address = udp_link()
    with outside_run(tmp_path, *options, "--external", "8,9", "--link", address) as run:
        start_c(run, binary, address, 8)
        start_c(run, binary, address, 9)
        code, summary, stderr = run.finish(timeout=800)
        programs = run.program_summaries()
    assert code == 0, stderr
    assert summary is not None
    assert summary["world"]["departures"] == 0
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert [r["outside"] for r in summary["per_robot"]] == [None] * 8 + ["udp", "udp"]
    links = summary["links"]
    assert all(item["sessions"] == 1 and item["refused"] == 0 for item in links.values())
    # each program says how it ended: the bridge told it the run was over
    decided = [robot["decided_site"] for robot in summary["per_robot"][8:]]
    assert [each["decided_site"] for each in programs] == decided
    assert all(each["sessions"] == 1 and each["refused"] == {} for each in programs)


def test_a_c_robot_over_a_serial_line_decides_exactly_as_all_emulated(
    tmp_path: Path, binary: Path
) -> None:
    options = [*TEN, "--seed", "1"]
    reference = in_process(options)
    with pty_pair(tmp_path) as (bridge_end, robot_end):
        served = f"9=serial:{bridge_end}@921600"
        with outside_run(tmp_path, *options, "--external", "9", "--link", served) as run:
            start_c(run, binary, f"serial:{robot_end}@921600", 9)
            code, summary, stderr = run.finish(timeout=800)
    assert code == 0, stderr
    assert summary is not None
    assert summary["world"]["departures"] == 0
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert summary["links"]["9"]["transport"] == "serial"
    assert summary["links"]["9"]["refused"] == 0


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


def test_a_c_robot_on_an_encrypted_link_decides_exactly_as_all_emulated(
    tmp_path: Path, binary: Path
) -> None:
    """``--secure``: every frame of the session ChaCha20-Poly1305 under the session key."""
    options = ["--robots", "4", "--sites", "3", "--timeout", "600", "--no-record", *PATIENT]
    options += ["--seed", "1"]
    reference = in_process(options)
    address = udp_link()
    with outside_run(tmp_path, *options, "--secure", "--external", "2", "--link", address) as run:
        start_c(run, binary, address, 2)
        code, summary, stderr = run.finish(timeout=800)
        programs = run.program_summaries()
    assert code == 0, stderr
    assert summary is not None
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert summary["links"]["2"]["sessions"] == 1 and summary["links"]["2"]["refused"] == 0
    assert programs[0]["refused"] == {} and programs[0]["sessions"] == 1
