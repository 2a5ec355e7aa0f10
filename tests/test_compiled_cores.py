"""The compiled cores give the same runs as the source they are compiled from.

``plumbing/cores.py`` builds the pure modules of a tick with mypyc; the interpreted source
stays the reference. The probe of the portability test (a few swarms covering physics,
navigation, camera noise, radio and range loss, the log-linear pool, a rival strategy,
lingering and 40 robots; the Section 4 model; the numeric kernel on a grid) runs once with
the compiled cores and once from a copy of the source without them: every result must be
the same.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from plumbing import cores

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("wire", "robot_agent", "world_server", "nest_beacon", "deploy", "plumbing",
            "wellstirred", "viewer", "link")  # fmt: skip

pytestmark = pytest.mark.timeout(300)


def probe(root: Path) -> dict[str, Any]:
    """The probe's results with the packages of ``root``."""
    environment = dict(os.environ, PYTHONPATH=str(root))
    done = subprocess.run(
        [sys.executable, str(root / "tests" / "portable_probe.py")],
        cwd=root,
        env=environment,
        capture_output=True,
        text=True,
        timeout=250,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def source_only(destination: Path) -> Path:
    """A copy of the repository's packages and the probe without a compiled module."""
    skip = shutil.ignore_patterns("*.so", "__pycache__")
    for package in PACKAGES:
        shutil.copytree(REPO / package, destination / package, ignore=skip)
    (destination / "tests").mkdir()
    shutil.copy(REPO / "tests" / "portable_probe.py", destination / "tests")
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
