"""The project installed from a wheel, as a user installs it: outside the checkout.

A wheel is built from a copy of the checkout and installed into a fresh venv in a
temporary folder. The venv takes its dependencies from this environment's site-packages
by a path line in a ``.pth`` file (nothing is downloaded): a path line adds the folder but
runs none of the ``.pth`` files in it, so the editable install of the checkout stays out.
Every command then runs from a folder outside the checkout with an empty HOME: what a user
of the wheel can do works (``swarm run`` in process and over Zenoh, ``swarm report``,
``swarm view``, ``swarm wellstirred``), and what needs the repository says so in one line
with exit code 2.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import subprocess
import sys
import sysconfig
import time
import urllib.error
import urllib.request
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import kill_leftovers, unique_run_id
from test_layering import PACKAGES

from bestofn_swarm.plumbing.tcp import free_port

REPO = Path(__file__).resolve().parent.parent
# What the copy the wheel is built from leaves out: environments, builds, caches, runs.
NOT_COPIED = shutil.ignore_patterns(
    ".git",
    ".venv",
    "build",
    "runs",
    "out",
    ".portable",
    "__pycache__",
    "*.egg-info",
    ".mypy_cache",
    ".ruff_cache",
    ".pytest_cache",
    ".hypothesis",
)
NOT_INSTALLED = ("portable", "benchmarks", "tests", "examples", "docs", "c_robot")
TIMEOUT = 120.0
# A small run: a few seconds over Zenoh.
RUN = ("--robots", "3", "--sites", "3", "--seed", "1", "--json", "--quiet")


@dataclass(frozen=True)
class Installed:
    """A venv outside the checkout with the wheel installed, and where to run it."""

    wheel: Path
    venv: Path
    work: Path  # the current folder of every command: outside the checkout
    env: dict[str, str]

    @property
    def site_packages(self) -> Path:
        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        return self.venv / "lib" / version / "site-packages"

    def run(self, *command: str, timeout: float = TIMEOUT) -> subprocess.CompletedProcess[str]:
        """``command``, its program taken from the venv's bin folder, in ``work``."""
        program = str(self.venv / "bin" / command[0])
        return subprocess.run(
            [program, *command[1:]],
            cwd=self.work,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    base = tmp_path_factory.mktemp("wheel")
    source = base / "source"
    shutil.copytree(REPO, source, ignore=NOT_COPIED, symlinks=True)
    wheels = base / "wheels"
    build = ["wheel", "--no-deps", "--no-build-isolation", "--wheel-dir", str(wheels)]
    subprocess.run(
        [sys.executable, "-m", "pip", *build, "--quiet", "--no-index", str(source)],
        check=True,
        capture_output=True,
        timeout=TIMEOUT,
    )
    (wheel,) = wheels.glob("bestofn_swarm-*.whl")
    venv = base / "venv"
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(venv)],
        check=True,
        capture_output=True,
        timeout=TIMEOUT,
    )
    home, work = base / "home", base / "work"
    home.mkdir()
    work.mkdir()
    env = {
        "PATH": f"{venv / 'bin'}:/usr/bin:/bin",
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "MPLBACKEND": "Agg",
    }
    found = Installed(wheel, venv, work, env)
    dependencies = sysconfig.get_paths()["purelib"]  # this environment's site-packages
    (found.site_packages / "dependencies.pth").write_text(dependencies + "\n")
    install = ["install", "--no-deps", "--ignore-installed", str(wheel)]
    subprocess.run(
        [str(venv / "bin" / "python"), "-m", "pip", *install, "--quiet", "--no-index"],
        check=True,
        cwd=work,
        env=env,
        capture_output=True,
        timeout=TIMEOUT,
    )
    return found


def _one_line_refusal(installed: Installed, done: subprocess.CompletedProcess[str]) -> str:
    """The refusal of a command that needs the checkout: exit code 2, and one line on
    stderr that says so and where this copy is, without an errno or a call to run make."""
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1, done.stderr
    assert done.stdout == ""
    line = lines[0]
    assert "needs a checkout of the repository" in line
    assert f"an installed copy ({installed.site_packages})" in line
    said = line.replace(str(installed.site_packages), "")
    assert "Errno" not in said and "make" not in said
    return line


def test_the_wheel_installs_exactly_the_five_packages(installed: Installed) -> None:
    with zipfile.ZipFile(installed.wheel) as wheel:
        names = wheel.namelist()
        tops = {name.split("/")[0] for name in names if not name.split("/")[0].endswith("-info")}
        (top_level,) = [name for name in names if name.endswith(".dist-info/top_level.txt")]
        declared = set(wheel.read(top_level).decode().split())
    assert tops == set(PACKAGES)
    assert declared == set(PACKAGES)
    assert not [name for name in names if name.split("/")[0] in NOT_INSTALLED]
    # Compiled cores built in the checkout stay there (the copy has them, if built).
    assert not [name for name in names if name.endswith(".so")]


def test_its_commands_import_the_wheel_not_the_checkout(installed: Installed) -> None:
    probe = (
        "import importlib, json, sys\n"
        "print(json.dumps({p: importlib.import_module(p).__file__ for p in sys.argv[1:]}))"
    )
    done = installed.run("python", "-c", probe, *PACKAGES)
    assert done.returncode == 0, done.stderr
    for package, where in json.loads(done.stdout).items():
        assert Path(where).is_relative_to(installed.site_packages), (package, where)
    scripts = ["swarm", "robot-agent", "world-server", "nest-beacon"]
    for script in scripts:
        first = (installed.venv / "bin" / script).read_text().splitlines()[0]
        assert first == f"#!{installed.venv / 'bin' / 'python'}"


@dataclass(frozen=True)
class Recorded:
    path: Path
    summary: dict[str, Any]


@pytest.fixture(scope="module")
def recorded(installed: Installed) -> Recorded:
    """A run over Zenoh, the default engine, made and recorded from the wheel."""
    run_id = unique_run_id("wheel")
    path = installed.work / "runs" / "recorded.mcap"
    try:
        done = installed.run("swarm", "run", *RUN, "--run-id", run_id, "--record", str(path))
    finally:
        kill_leftovers(run_id)
    assert done.returncode == 0, done.stderr
    return Recorded(path, json.loads(done.stdout))


def test_swarm_run_over_zenoh_and_in_process_give_the_same_run(
    installed: Installed, recorded: Recorded
) -> None:
    done = installed.run(
        "swarm", "run", *RUN, "--engine", "inprocess", "--record", "runs/inprocess.mcap"
    )
    assert done.returncode == 0, done.stderr
    inprocess = json.loads(done.stdout)
    assert recorded.summary["ended"] == inprocess["ended"] == "consensus"
    assert recorded.summary["digest"] == inprocess["digest"]
    assert recorded.path.stat().st_size > 0
    assert (installed.work / "runs" / "inprocess.mcap").stat().st_size > 0


def test_swarm_report_makes_the_figures_of_a_recording(
    installed: Installed, recorded: Recorded
) -> None:
    done = installed.run("swarm", "report", str(recorded.path), "--out", "report", "--json")
    assert done.returncode == 0, done.stderr
    (run,) = json.loads(done.stdout)["runs"]
    assert run["ended"] == "consensus" and run["digest"] == recorded.summary["digest"]
    for figure in ("fig4.png", "fig5.png", "fig2.png", "summary.csv"):
        assert (installed.work / "report" / figure).stat().st_size > 0


@contextlib.contextmanager
def _serving(installed: Installed, command: Sequence[str]) -> Iterator[subprocess.Popen[str]]:
    process = subprocess.Popen(
        [str(installed.venv / "bin" / command[0]), *command[1:]],
        cwd=installed.work,
        env=installed.env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        yield process
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def _page(url: str, process: subprocess.Popen[str], timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise AssertionError(f"it exited ({process.returncode}): {process.communicate()[1]}")
        with (
            contextlib.suppress(urllib.error.URLError, ConnectionError),
            urllib.request.urlopen(url, timeout=5) as answer,
        ):
            text: str = answer.read().decode()
            return text
        time.sleep(0.2)
    raise AssertionError(f"nothing answered on {url}")


def test_swarm_view_serves_the_page_of_a_recording(
    installed: Installed, recorded: Recorded
) -> None:
    port = free_port()
    command = ["swarm", "view", str(recorded.path), "--port", str(port)]
    with _serving(installed, command) as process:
        page = _page(f"http://127.0.0.1:{port}/", process)
        assert "<title>bestofn swarm view</title>" in page
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/viewer.js", timeout=5) as script:
            assert script.status == 200
    assert process.returncode == -15  # stopped by the SIGTERM sent, and by nothing else


def test_swarm_wellstirred(installed: Installed) -> None:
    done = installed.run(
        "swarm", "wellstirred", "--options", "10", "--pool", "2", "--runs", "20", "--json"
    )
    assert done.returncode == 0, done.stderr
    (record,) = json.loads(done.stdout)
    assert record["options"] == 10 and record["pool"] == 2 and record["success_rate"] == 1.0


CORES = "python -m bestofn_swarm.plumbing.cores"


@pytest.mark.parametrize(
    "command",
    [
        "swarm study --list",
        "swarm study scale --status",
        "swarm study scale --render",
        "swarm study scale --check",
        "swarm study --check",
        "swarm study scale",
        "swarm section5 --check",
        "swarm section5 --check --sample",
        "swarm section5 --write",
        "swarm section5 --render",
        f"{CORES} build",
    ],
)
def test_what_needs_the_repository_says_so_in_one_line(installed: Installed, command: str) -> None:
    line = _one_line_refusal(installed, installed.run(*command.split()))
    said_by = CORES if command.startswith(CORES) else " ".join(command.split()[:2])
    assert line.startswith(f"{said_by}: error: ")


def test_the_compiled_cores_are_interpreted_in_an_installed_copy_and_say_why(
    installed: Installed,
) -> None:
    done = installed.run("python", "-m", "bestofn_swarm.plumbing.cores", "status")
    assert done.returncode == 0, done.stderr
    why = "an installed copy: they are built in a checkout only"
    assert done.stdout == f"compiled cores: interpreted ({why})\n"


def test_a_checkout_given_by_root_is_used_from_the_wheel(installed: Installed) -> None:
    """What needs the repository works from the wheel on a checkout named by --root."""
    done = installed.run("swarm", "study", "--list", "--root", str(REPO))
    assert done.returncode == 0, done.stderr
    here = subprocess.run(
        [sys.executable, "-m", "deploy.cli", "study", "--list"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert here.returncode == 0, here.stderr
    assert done.stdout == here.stdout
