"""The layers, read from the source: every folder is one layer, and what it may import is
said here once, per folder (docs/architecture.md draws the same map).

* **pure** folders (every ``core/``, the wire vocabulary ``bestofn_swarm/wire/``, the
  Section 4 model) import no network, no clock, no thread, no process and no adapter: what
  a port to a robot copies, and what tests drive without Zenoh. mypy checks exactly these
  folders strictly (``pyproject.toml``; plus ``bestofn_swarm/plumbing/``).
* **adapters** (a process on Zenoh, a hardware link, the recorder) import the pure layers
  and their own transport; the robot's hardware link (``robot_agent/link/``) imports no
  Zenoh, not even through what it imports.
* **deploy** (the ``swarm`` command) and the observers (``deploy/viewer/``) may use
  everything but are used by nothing below them.
* No two folders import each other, directly or round a cycle.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# The folders of the code, each one layer (a folder's own modules; its sub-folders are
# layers of their own).
PURE = [
    "bestofn_swarm/wire",
    "bestofn_swarm/link/core",
    "robot_agent/core",
    "robot_agent/wellstirred",
    "world_server/core",
    "world_server/observer",
    "world_server/bridge/core",
    "nest_beacon/core",
    "deploy/viewer/core",
    "deploy/analysis",
    "deploy/inprocess",
]
ADAPTERS = [
    "bestofn_swarm/plumbing",
    "bestofn_swarm/link/io",
    "robot_agent/plugins",
    "robot_agent/node",
    "robot_agent/link",
    "world_server/server",
    "world_server/recording",
    "world_server/recorder",
    "world_server/bridge",
    "nest_beacon/node",
]
# The rooms of the ``swarm`` command: the launcher (``swarm run`` and what starts runs),
# security (keys, certificates, access control), reports (what is made of runs), studies
# (the runs behind the published pages, ``swarm study``), conformance (a port checked against
# the controller, ``swarm conformance``), the observers (``swarm view``).
OUTER = [
    "deploy",
    "deploy/launcher",
    "deploy/security",
    "deploy/reports",
    "deploy/study",
    "deploy/conformance",
    "deploy/viewer",
    "bestofn_swarm/api",
]
# The package roots that hold only layers and a ``__main__`` that starts one.
ROOTS = ["bestofn_swarm", "bestofn_swarm/link", "robot_agent", "world_server", "nest_beacon"]
# The installed packages: a wheel installs exactly these (tests/test_wheel.py).
PACKAGES = ["bestofn_swarm", "robot_agent", "world_server", "nest_beacon", "deploy"]
FOLDERS = PURE + ADAPTERS + OUTER + ROOTS

# What a pure folder never imports: the network, clocks, threads, processes, signals,
# and the layers outside the pure ones.
NOT_PURE = {
    "zenoh",
    "socket",
    "ssl",
    "serial",
    "asyncio",
    "selectors",
    "time",
    "datetime",
    "threading",
    "queue",
    "concurrent",
    "multiprocessing",
    "subprocess",
    "signal",
    "os",
    "mcap",
}
# Folders each folder may import (beyond itself and third-party libraries), by layer.
ALLOWED: dict[str, set[str]] = {
    "bestofn_swarm/wire": set(),
    "bestofn_swarm/plumbing": {"bestofn_swarm/wire"},
    # The link's protocol (frames, sessions) and its loop and transports, for both ends.
    "bestofn_swarm/link/core": {"bestofn_swarm/wire"},
    "bestofn_swarm/link/io": {"bestofn_swarm/wire", "bestofn_swarm/link/core"},
    "robot_agent/core": {"bestofn_swarm/wire", "bestofn_swarm/link/core"},
    "world_server/core": {"bestofn_swarm/wire"},
    # Watching a run: records, the watchdog, the ending and the summary; the parking slots and
    # the liars' declarations are the robot's own.
    "world_server/observer": {"bestofn_swarm/wire", "world_server/core", "robot_agent/core"},
    "nest_beacon/core": {"bestofn_swarm/wire"},
    "deploy/viewer/core": {"bestofn_swarm/wire", "world_server/core", "world_server/observer"},
    "robot_agent/wellstirred": {"robot_agent/core", "bestofn_swarm/wire"},
    # Finding plug-ins by name: importing them, the installed entry points, their sources.
    "robot_agent/plugins": {"bestofn_swarm/wire", "robot_agent/core"},
    "robot_agent/node": {
        "bestofn_swarm/wire",
        "robot_agent/core",
        "robot_agent/plugins",
        "bestofn_swarm/plumbing",
    },
    # The robot's end of the link: its program, on the link's loop and transports.
    "robot_agent/link": {
        "bestofn_swarm/wire",
        "robot_agent/core",
        "robot_agent/plugins",
        "bestofn_swarm/link/core",
        "bestofn_swarm/link/io",
        "bestofn_swarm/plumbing",
    },
    "world_server/server": {
        "bestofn_swarm/wire",
        "world_server/core",
        "world_server/observer",
        "bestofn_swarm/plumbing",
    },
    "world_server/recording": {"bestofn_swarm/wire", "world_server/core", "world_server/observer"},
    "world_server/recorder": {
        "bestofn_swarm/wire",
        "world_server/core",
        "world_server/recording",
        "bestofn_swarm/plumbing",
    },
    # The bridge is the other end of the robots' links: their protocol and transports.
    "world_server/bridge/core": {"bestofn_swarm/wire", "bestofn_swarm/link/core"},
    "world_server/bridge": {
        "bestofn_swarm/wire",
        "bestofn_swarm/plumbing",
        "bestofn_swarm/link/core",
        "bestofn_swarm/link/io",
        "world_server/bridge/core",
    },
    "nest_beacon/node": {"bestofn_swarm/wire", "nest_beacon/core", "bestofn_swarm/plumbing"},
    # The package roots that hold compiled cores first see that no stale one runs
    # (bestofn_swarm/plumbing/cores_state.py); the shared root gives the public API lazily.
    "bestofn_swarm": {"bestofn_swarm/plumbing", "bestofn_swarm/api"},
    "bestofn_swarm/link": set(),
    "robot_agent": {"robot_agent/node", "bestofn_swarm/plumbing"},
    "world_server": {
        "world_server/server",
        "world_server/recorder",
        "world_server/bridge",
        "bestofn_swarm/plumbing",
    },
    "nest_beacon": {"nest_beacon/node"},
    "deploy/viewer": {
        "bestofn_swarm/wire",
        "bestofn_swarm/plumbing",
        "deploy/viewer/core",
        "world_server/core",
        "world_server/observer",
        "world_server/recording",
    },
    # What a run decided and when it ends (summary, digest, watchdog), and the tables of runs.
    "deploy/analysis": {"bestofn_swarm/wire"},
    # The in-process engine: the world's, the robots' and the beacon's cores on one bus.
    "deploy/inprocess": {
        "bestofn_swarm/wire",
        "robot_agent/core",
        "world_server/core",
        "world_server/observer",
        "nest_beacon/core",
    },
    "deploy/security": {"bestofn_swarm/wire", "bestofn_swarm/plumbing"},
    "deploy/reports": set(FOLDERS)
    - {"deploy", "deploy/reports", "deploy/launcher", "deploy/study", "bestofn_swarm"},
    "deploy/launcher": set(FOLDERS)
    - {"deploy", "deploy/launcher", "deploy/study", "bestofn_swarm"},
    "deploy/study": set(FOLDERS) - {"deploy", "deploy/study", "bestofn_swarm"},
    "deploy/conformance": set(FOLDERS)
    - {"deploy", "deploy/conformance", "deploy/study", "bestofn_swarm"},
    "deploy": set(FOLDERS) - {"deploy", "bestofn_swarm"},
    # The public Python API (``from bestofn_swarm import run, sweep``): runs and sweeps as
    # swarm run and the study runner make them; nothing imports it but the shared root.
    "bestofn_swarm/api": set(FOLDERS) - {"bestofn_swarm", "bestofn_swarm/api", "deploy"},
}
# What ``robot-agent --link`` may not import, directly or through any module of this
# repository it imports: it runs where there is no Zenoh.
LINK_PROGRAM = "robot_agent.link.program"
LINK_FORBIDDEN = {"zenoh"}


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, wherever in the file: ``import a.b`` gives ``a.b``,
    ``from a import b`` gives ``a`` and ``a.b`` (b may be a module or a name)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def folder_of(module: str) -> str | None:
    """The layer folder a module of this repository is in (the deepest that holds it)."""
    path = module.replace(".", "/")
    found = [folder for folder in FOLDERS if path == folder or path.startswith(folder + "/")]
    return max(found, key=len) if found else None


def modules_of(folder: str) -> list[Path]:
    """The folder's own modules (not those of the layer folders inside it)."""
    return sorted((REPO / folder).glob("*.py"))


def test_imported_modules_reads_every_import(tmp_path: Path) -> None:
    source = tmp_path / "sample.py"
    source.write_text(
        "import os.path\nfrom zenoh import Session\n\ndef f():\n    import deploy.cli\n"
    )
    assert imported_modules(source) == {"os.path", "zenoh", "zenoh.Session", "deploy.cli"}


def test_every_package_folder_is_a_layer() -> None:
    """A new folder of code must be given its layer here before it can be imported."""
    packages = {
        str(init.parent.relative_to(REPO))
        for root in PACKAGES
        for init in (REPO / root).rglob("__init__.py")
        if ".venv" not in init.parts
    }
    assert packages - set(FOLDERS) == set()


@pytest.mark.parametrize("folder", PURE)
def test_pure_folders_import_no_network_clock_or_thread(folder: str) -> None:
    offenders = {
        path.name: sorted(
            module
            for module in imported_modules(path)
            if module.split(".")[0] in NOT_PURE
            or (folder_of(module) is not None and folder_of(module) not in PURE)
        )
        for path in modules_of(folder)
    }
    assert {name: found for name, found in offenders.items() if found} == {}


@pytest.mark.parametrize("folder", PURE)
def test_pure_folders_use_no_global_random_number_generator(folder: str) -> None:
    """Randomness comes in as a seeded ``random.Random`` or numpy Generator: a call of the
    ``random`` module's own functions would draw from the process's global state."""
    offenders = []
    for path in modules_of(folder):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id == "random"
                and node.attr != "Random"
            ):
                offenders.append(f"{path.name}:{node.lineno} random.{node.attr}")
    assert offenders == []


@pytest.mark.parametrize("folder", sorted(ALLOWED))
def test_folders_import_only_the_layers_they_may(folder: str) -> None:
    offenders = {}
    for path in modules_of(folder):
        bad = {
            target
            for module in imported_modules(path)
            if (target := folder_of(module)) is not None
            and target != folder
            and target not in ALLOWED[folder]
        }
        if bad:
            offenders[path.name] = sorted(bad)
    assert offenders == {}


def module_file(module: str) -> Path | None:
    """The source file of a module of this repository (a package's ``__init__.py``)."""
    base = REPO / module.replace(".", "/")
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def lazy_imports(path: Path) -> set[str]:
    """What a module imports only in its module-level ``__getattr__`` (PEP 562): made when a
    name it does not hold is asked of it (``from bestofn_swarm import run`` imports the
    public API, bestofn_swarm/api/), never by importing it or a module inside it."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
            for inner in ast.walk(node):
                if isinstance(inner, ast.ImportFrom) and inner.module and inner.level == 0:
                    names.add(inner.module)
                    names.update(f"{inner.module}.{alias.name}" for alias in inner.names)
                elif isinstance(inner, ast.Import):
                    names.update(alias.name for alias in inner.names)
    return names


def test_the_public_api_is_imported_only_when_asked_for() -> None:
    """The shared root gives ``run`` and ``sweep`` lazily: importing the shared layers (as
    every process does) imports no part of the API, and so nothing of ``deploy``."""
    root = REPO / "bestofn_swarm" / "__init__.py"
    assert lazy_imports(root) == {"bestofn_swarm", "bestofn_swarm.api"}
    reached = reached_imports("bestofn_swarm.wire.protocol")
    assert not [module for module in reached if module.startswith(("deploy", "bestofn_swarm.api"))]


def reached_imports(module: str) -> dict[str, str]:
    """Every module ``module`` imports, directly or through modules of this repository,
    each with the repository module that imports it first."""
    reached: dict[str, str] = {}
    waiting = [module]
    seen = {module}
    while waiting:
        current = waiting.pop()
        path = module_file(current)
        if path is None:
            continue
        imports = set(imported_modules(path)) - lazy_imports(path)
        parts = current.split(".")  # a module's packages run their __init__ first
        imports.update(".".join(parts[:n]) for n in range(1, len(parts)))
        for imported in sorted(imports):
            reached.setdefault(imported, current)
            if imported not in seen:
                seen.add(imported)
                waiting.append(imported)
    return reached


def test_reached_imports_follows_the_repository() -> None:
    reached = reached_imports("bestofn_swarm.link.io.hub")
    assert reached["bestofn_swarm.link.io.transport"] == "bestofn_swarm.link.io.hub"
    assert reached["serial"] == "bestofn_swarm.link.io.transport"  # one step further
    assert reached["cobs"] == "bestofn_swarm.link.core.codec"  # two steps further
    assert reached_imports("world_server.bridge.cli")["zenoh"] == "world_server.bridge.cli"


def test_the_robot_link_runs_without_zenoh() -> None:
    offenders = {
        module: by
        for module, by in reached_imports(LINK_PROGRAM).items()
        if module.split(".")[0] in LINK_FORBIDDEN
    }
    assert offenders == {}


def import_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {folder: set() for folder in FOLDERS}
    for folder in FOLDERS:
        for path in modules_of(folder):
            for module in imported_modules(path):
                target = folder_of(module)
                if target is not None and target != folder:
                    graph[folder].add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of the graph (its nodes in order, the first repeated at the end), or None."""
    state: dict[str, str] = {}  # "open" while on the path, "done" once explored
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = "open"
        path.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == "open":
                return [*path[path.index(target) :], target]
            if target not in state and (cycle := visit(target)) is not None:
                return cycle
        path.pop()
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)) is not None:
            return cycle
    return None


def test_find_cycle_finds_one() -> None:
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle_between_folders() -> None:
    assert find_cycle(import_graph()) is None


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_graph() -> dict[str, set[str]]:
    """Every module of the repository and the modules of the repository it imports,
    wherever in the file (``TYPE_CHECKING`` blocks and functions too); ``from package
    import module`` is an import of the module, not of its package."""
    paths = {
        module_name(path): path
        for root in PACKAGES
        for path in (REPO / root).rglob("*.py")
        if ".venv" not in path.parts
    }
    graph: dict[str, set[str]] = {}
    for module, path in paths.items():
        imported = imported_modules(path)
        graph[module] = {
            target
            for target in imported
            if target in paths
            and target != module
            # ``from a import b`` gives both a and a.b: a.b alone when b is a module
            and not any(other.startswith(target + ".") and other in paths for other in imported)
        }
    return graph


def test_no_import_cycle_between_modules() -> None:
    """Two modules that import each other, even only for their types, are one module in
    two files: their order of import, their layering and their tests are tangled."""
    assert find_cycle(module_graph()) is None


def test_no_import_cycle_between_packages() -> None:
    """No arrow runs back up: a package never imports one that imports it, through any of
    their folders (the robot's link imports the robot's core, so the robot's package does
    not import the link: ``robot-agent`` chooses between them from ``deploy/``)."""
    graph: dict[str, set[str]] = {}
    for module, targets in module_graph().items():
        package = package_of(module)
        graph.setdefault(package, set()).update(
            package_of(target) for target in targets if package_of(target) != package
        )
    assert find_cycle(graph) is None


def package_of(module: str) -> str:
    """The package a module belongs to: an installed package, or one of the shared layers
    under ``bestofn_swarm`` (each a package of its own)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "bestofn_swarm" and len(parts) > 1 else parts[0]


def test_the_cycle_checks_find_cycles() -> None:
    assert find_cycle({"a.x": {"b.y"}, "b.y": {"a.x"}}) == ["a.x", "b.y", "a.x"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_mypy_checks_exactly_the_pure_folders_strictly() -> None:
    config = tomllib.loads((REPO / "pyproject.toml").read_text())
    strict = next(
        override["module"]
        for override in config["tool"]["mypy"]["overrides"]
        if override.get("disallow_untyped_defs")
    )
    pure = {folder.replace("/", ".") + ".*" for folder in PURE}
    assert set(strict) - {"bestofn_swarm.plumbing.*"} == pure
