"""The compiled cores give the same runs as the source they are compiled from.

``bestofn_swarm/plumbing/cores.py`` builds the pure modules of a tick with mypyc; the interpreted
source stays the reference. The probe of the portability test (a few swarms covering physics,
navigation, camera noise, radio and range loss, the log-linear pool, a rival strategy,
lingering and 40 robots; the Section 4 model; the numeric kernel on a grid) runs once with
the compiled cores and once from a copy of the source without them: every result must be
the same.
"""

from __future__ import annotations

import importlib.machinery
import json
import os
import shutil
from pathlib import Path
from typing import Any

import portable_probe
import pytest

from bestofn_swarm.plumbing import cores, cores_state

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("bestofn_swarm", "robot_agent", "world_server", "nest_beacon", "deploy", "examples",
            "tests")  # fmt: skip
# Tests that recognise a function by its frame, which compiled code does not have: they
# skip with the compiled cores and run here from the source.
BY_FRAME = ("tests/test_ports_contract.py",)

pytestmark = pytest.mark.timeout(300)


def probe(root: Path) -> dict[str, Any]:
    """The probe's results with the packages of ``root``."""
    return portable_probe.run(root, dict(os.environ))


def source_only(destination: Path) -> Path:
    """A copy of the repository's packages and tests without a compiled module."""
    skip = shutil.ignore_patterns("*.so", "__pycache__", ".hypothesis")
    for package in PACKAGES:
        shutil.copytree(REPO / package, destination / package, ignore=skip)
    shutil.copy(REPO / "pyproject.toml", destination)
    return destination


def test_compiled_cores_give_the_runs_of_their_source(tmp_path: Path) -> None:
    found = cores.status()
    if found.state != "compiled":
        pytest.skip(f"{found.line}: nothing compiled to compare")
    compiled = probe(REPO)
    interpreted = probe(source_only(tmp_path))
    assert compiled.pop("compiled") is True and interpreted.pop("compiled") is False
    assert compiled["kernel"] == interpreted["kernel"], "the numeric kernel's outputs differ"
    assert compiled["section4"] == interpreted["section4"], "the Section 4 model differs"
    for fast, slow in zip(compiled["runs"], interpreted["runs"], strict=True):
        assert fast == slow, f"swarm run {' '.join(fast['options'])}: compiled and source differ"


def test_what_compiled_code_cannot_show_holds_in_the_source(tmp_path: Path) -> None:
    if cores.status().state != "compiled":
        pytest.skip("the compiled cores are not built: those tests run in the suite itself")
    root = source_only(tmp_path)
    pytest_args = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0", *BY_FRAME]
    done = portable_probe.python_from(root, pytest_args, dict(os.environ))
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-1000:]
    assert " skipped" not in done.stdout.splitlines()[-1], done.stdout[-500:]


def test_only_what_this_interpreter_would_import_can_shadow_a_source() -> None:
    aarch64 = (".cpython-311-aarch64-linux-gnu.so", ".abi3.so", ".so")
    assert cores.importable("engine.cpython-311-aarch64-linux-gnu.so", aarch64)
    assert cores.importable("engine.so", aarch64)
    assert cores.importable("cores__mypyc.abi3.so", aarch64)
    # A build of the same tree by an x86-64 Python: the aarch64 one never loads it.
    assert not cores.importable("engine.cpython-311-x86_64-linux-gnu.so", aarch64)
    assert not cores.importable("engine.py", aarch64)


def test_another_machines_build_in_the_tree_is_not_stale(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A tree shared by two machines (the portability check runs an emulated aarch64 Python
    on the tree this one built) keeps both builds; each sees only its own."""
    monkeypatch.setattr(cores_state, "REPO", tmp_path)
    for module in cores.MODULES:
        (tmp_path / module).parent.mkdir(parents=True, exist_ok=True)
    folder = tmp_path / Path(cores.MODULES[0]).parent
    (folder / "engine.cpython-311-sparc64-linux-gnu.so").write_bytes(b"")
    assert cores.status().state == "interpreted"
    leftover = folder / ("leftover" + importlib.machinery.EXTENSION_SUFFIXES[0])
    leftover.write_bytes(b"")
    found = cores.status()
    assert found.state == "stale"
    assert leftover.name in found.why


OBSERVED = """
import json, sys
from deploy.study.grid import Run
from deploy.study.make import make_comparisons, make_lag
options = ("--robots", "10", "--sites", "5", "--seed", "3", "--timeout", "2400")
run = Run("observed", (("what", "observed"),), 3, options=options)
print(json.dumps({"comparisons": make_comparisons(run, {}), "lag": make_lag(run, {})}))
"""


def observed(root: Path) -> dict[str, Any]:
    """A run watched by the studies' interpreted subclasses of the controller
    (deploy/study/observe.py): every comparison, and every pooling and decision."""
    done = portable_probe.python_from(root, ["-c", OBSERVED], dict(os.environ))
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def test_studies_watch_a_compiled_controller_as_they_watch_its_source(tmp_path: Path) -> None:
    if cores.status().state != "compiled":
        pytest.skip("the compiled cores are not built")
    compiled = observed(REPO)
    assert compiled["comparisons"]["comparisons"] > 0
    assert compiled["lag"]["lag"] is not None
    assert compiled == observed(source_only(tmp_path))


STALE_PROBE = """
import json
from deploy.launcher.inprocess import run_plan
from deploy.launcher.plan import plan_from_args
from deploy.cli import build_parser
import robot_agent.core.controller as controller
argv = ["run", "--engine", "inprocess", "--no-record", "--robots", "6", "--sites", "4",
        "--seed", "3"]
summary = run_plan(plan_from_args(build_parser(["run"]).parse_args(argv)))
print(json.dumps({"file": controller.__file__, "digest": summary["digest"]}))
"""


def test_a_stale_core_runs_from_its_source_with_one_warning(tmp_path: Path) -> None:
    """Editing a compiled core module never traps: every core then loads from its source
    (the run is the same), one line says so and how to build them again, and a process
    started meanwhile says nothing more."""
    if cores.status().state != "compiled":
        pytest.skip("the compiled cores are not built")
    root = tmp_path / "tree"
    for package in PACKAGES:
        skip = shutil.ignore_patterns("__pycache__", ".hypothesis")
        shutil.copytree(REPO / package, root / package, ignore=skip)
    shutil.copytree(REPO / "build", root / "build", ignore=shutil.ignore_patterns("cores-temp"))
    fresh = portable_probe.python_from(root, ["-c", STALE_PROBE], dict(os.environ))
    assert fresh.returncode == 0, fresh.stderr[-2000:]
    compiled = json.loads(fresh.stdout)
    assert compiled["file"].endswith(importlib.machinery.EXTENSION_SUFFIXES[0])
    assert "warning" not in fresh.stderr
    edited = root / "robot_agent" / "core" / "motion.py"
    edited.write_text(edited.read_text() + "# an edit after the build\n")
    stale = portable_probe.python_from(root, ["-c", STALE_PROBE], dict(os.environ))
    assert stale.returncode == 0, stale.stderr[-2000:]
    source = json.loads(stale.stdout)
    assert source["file"] == str(root / "robot_agent" / "core" / "controller.py")
    assert source["digest"] == compiled["digest"]
    assert stale.stderr.splitlines() == [
        "warning: the compiled cores are stale (robot_agent/core/motion.py changed since the "
        "build): running their source (slower); `make cores` builds them again"
    ]
    said = dict(os.environ, **{cores_state.STALE_ENV: "1"})
    quiet = portable_probe.python_from(root, ["-c", STALE_PROBE], said)
    assert quiet.returncode == 0 and quiet.stderr == ""
