"""The layering rules of DESIGN.md, read from the source: the pure core touches no Zenoh,
the robot needs nothing of the world, the beacon, the launcher or the Section 4 model."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# Modules that must run without a network, a clock of their own or I/O (rule 1).
PURE = [
    "robot_agent/decision.py",
    "robot_agent/controller.py",
    "robot_agent/controller_config.py",
    "robot_agent/settings.py",
    "robot_agent/phases.py",
    "robot_agent/beliefs.py",
    "robot_agent/motion.py",
    "robot_agent/sensing.py",
    "robot_agent/parking.py",
    "robot_agent/navigation.py",
    "robot_agent/vision.py",
    "robot_agent/protocol.py",
    "robot_agent/batch.py",
    "robot_agent/ports.py",
    "robot_agent/simulated.py",
    "robot_agent/auth.py",
    "robot_agent/guard.py",
    "robot_agent/byzantine.py",
    "nest_beacon/beacon.py",
    "world_server/world.py",
    "world_server/physics.py",
    "world_server/camera.py",
    "world_server/radio.py",
    "world_server/clock.py",
    "world_server/layout.py",
    "wellstirred/model.py",
    "wellstirred/equations.py",
    "viewer/model.py",
    "viewer/decode.py",
]
# What each package may never import (rule 2, and what a port to a robot can do without).
FORBIDDEN = {
    "robot_agent": {"world_server", "nest_beacon", "deploy", "wellstirred", "viewer"},
    "plumbing": {"world_server", "nest_beacon", "deploy", "wellstirred", "viewer"},
    "nest_beacon": {"world_server", "deploy", "wellstirred", "viewer"},
    "world_server": {"nest_beacon", "deploy", "wellstirred", "viewer"},
    "wellstirred": {"world_server", "nest_beacon", "deploy", "zenoh", "viewer"},
    # The view watches a run: it reads the protocol, the layout and the recorder's
    # records, and needs nothing of the launcher (which starts it as a process).
    "viewer": {"nest_beacon", "deploy", "wellstirred"},
}
NETWORK = {"zenoh", "plumbing", "socket", "deploy"}


def imported_packages(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports, wherever in the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_imported_packages_reads_every_import(tmp_path: Path) -> None:
    source = tmp_path / "sample.py"
    source.write_text(
        "import os.path\nfrom zenoh import Session\n\ndef f():\n    import deploy.cli\n"
    )
    assert imported_packages(source) == {"os", "zenoh", "deploy"}


@pytest.mark.parametrize("module", PURE)
def test_the_pure_core_has_no_network(module: str) -> None:
    assert not imported_packages(REPO / module) & NETWORK


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_packages_import_only_what_they_may(package: str) -> None:
    offenders = {
        str(path.relative_to(REPO)): sorted(imported_packages(path) & FORBIDDEN[package])
        for path in sorted((REPO / package).rglob("*.py"))
    }
    assert {path: names for path, names in offenders.items() if names} == {}
