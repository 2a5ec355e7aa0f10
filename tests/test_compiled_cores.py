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

from bestofn_swarm.plumbing import cores

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
    monkeypatch.setattr(cores, "REPO", tmp_path)
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
