"""Which compiled cores there are, whether they are fresh, and their source in their place
when they are not (``use_source_if_stale``), imported first by every package that holds
cores. Building them is ``cores.py``'s (``python -m bestofn_swarm.plumbing.cores``)."""

from __future__ import annotations

import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

# Where the packages are (a checkout's root, or site-packages): the cores are built next to
# their sources. Nothing of the project is imported here before use_source_if_stale has
# run: a module imported now would be the compiled one, stale or not.
REPO = Path(__file__).resolve().parents[2]

# The modules compiled, by path from the repository's root: the numeric kernel, the
# robot's controller and its tick, and the world's tick. Every one is in a pure folder
# that mypy checks strictly (pyproject.toml). Not among them: the decision maths
# (robot_agent/core/decision.py), which a port copies and which answers any argument of
# the wrong type with its own error (compiled code raises TypeError first), and every
# module that holds a settings dataclass (compiled, a dataclass loses its Annotated
# metadata, which bestofn_swarm/wire/settings.py reads).
MODULES = (
    "bestofn_swarm/wire/numeric.py",
    "bestofn_swarm/wire/rng.py",
    "bestofn_swarm/wire/guard.py",
    "bestofn_swarm/wire/names.py",
    "bestofn_swarm/wire/batch.py",
    "robot_agent/core/navigation.py",
    "robot_agent/core/motion.py",
    "robot_agent/core/controller.py",
    "robot_agent/core/sensing.py",
    "robot_agent/core/parking.py",
    "robot_agent/core/beliefs.py",
    "robot_agent/core/strategies.py",
    "robot_agent/core/voting.py",
    "robot_agent/core/ports.py",
    "robot_agent/core/simulated.py",
    "robot_agent/core/tick_assembly.py",
    "robot_agent/core/endpoint.py",
    "robot_agent/core/hosting.py",
    "world_server/core/physics.py",
    "world_server/core/clock.py",
    "world_server/core/counters.py",
    "world_server/core/roster.py",
    "world_server/core/intake.py",
    "world_server/core/coordinator.py",
    "deploy/inprocess/engine.py",
)
# The library every compiled module shares (``bestofn_swarm/wire/cores__mypyc``): inside a package,
# so it is found wherever the packages are.
GROUP = "bestofn_swarm.wire.cores"

MANIFEST = REPO / "build" / "cores.json"


@dataclass(frozen=True)
class Status:
    """Whether the compiled cores are what runs."""

    state: str  # "compiled", "interpreted" or "stale"
    why: str

    @property
    def line(self) -> str:
        return f"compiled cores: {self.state} ({self.why})"


def extension_path(module: str) -> Path:
    """Where the compiled form of ``module`` (a path like bestofn_swarm/wire/numeric.py) is put."""
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return REPO / (module.removesuffix(".py") + suffix)


def shared_library() -> Path:
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return REPO / (GROUP.replace(".", "/") + "__mypyc" + suffix)


def importable(name: str, suffixes: Sequence[str]) -> bool:
    """Whether this interpreter's import system would load a file of this name as a module:
    a module name and one of its extension suffixes. Another machine's build in the same
    folder (``engine.cpython-311-x86_64-linux-gnu.so`` seen by an aarch64 Python) is not."""
    return any(
        name.endswith(suffix) and name.removesuffix(suffix).isidentifier() for suffix in suffixes
    )


def compiled_files() -> list[Path]:
    """Every compiled module this interpreter would import from the folders the cores come
    from, ours or not."""
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    folders = sorted({(REPO / module).parent for module in MODULES})
    return [
        path for folder in folders for path in folder.iterdir() if importable(path.name, suffixes)
    ]


def strays() -> list[Path]:
    """Compiled modules there that no longer belong to the cores: each would shadow its
    source."""
    ours = {extension_path(module) for module in MODULES} | {shared_library()}
    return [path for path in compiled_files() if path not in ours]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def status() -> Status:
    """Whether the compiled cores are built, fresh, and what runs."""
    built = [module for module in MODULES if extension_path(module).exists()]
    leftover = strays()
    if leftover:
        return Status("stale", f"{leftover[0].relative_to(REPO)} is not one of the cores")
    if not built and not shared_library().exists():
        from bestofn_swarm.plumbing import checkout  # imports the project: not at the top

        if checkout.found() is None:
            return Status("interpreted", "an installed copy: they are built in a checkout only")
        return Status("interpreted", "not built; `make cores` builds them")
    try:
        manifest = json.loads(MANIFEST.read_text())
    except (OSError, ValueError):
        manifest = None
    if manifest is None:
        return Status("stale", f"{MANIFEST.relative_to(REPO)} is missing: a build was cut off")
    if len(built) != len(MODULES):
        missing = sorted(set(MODULES) - set(built))
        return Status("stale", f"{len(missing)} of {len(MODULES)} missing, {missing[0]} first")
    sources: dict[str, str] = manifest.get("sources", {})
    changed = [module for module in MODULES if sources.get(module) != digest(REPO / module)]
    if changed:
        return Status("stale", f"{', '.join(changed[:3])} changed since the build")
    if manifest.get("python") != sys.version:
        return Status("stale", "built by another Python")
    return Status("compiled", f"{len(MODULES)} modules, mypy {manifest.get('mypy')}")


# Set once a process has said that the cores are stale: the processes it starts say it no
# more (they load the source all the same).
STALE_ENV = "BESTOFN_CORES_STALE_SAID"


class SourceFirst(importlib.abc.MetaPathFinder):
    """Finds each core module (by module name) in its source file, ahead of the compiled
    one Python's own finder would take."""

    def __init__(self, sources: dict[str, Path]) -> None:
        self.sources = sources

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        source = self.sources.get(fullname)
        if source is None:
            return None
        return importlib.util.spec_from_file_location(fullname, source)


def module_name(module: str) -> str:
    """``robot_agent.core.controller`` of ``robot_agent/core/controller.py``."""
    return module.removesuffix(".py").replace("/", ".")


def _finder() -> SourceFirst | None:
    return next((found for found in sys.meta_path if isinstance(found, SourceFirst)), None)


def use_source_if_stale() -> Status:
    """When the compiled cores are stale, have every core module (and every stray compiled
    module of their folders that has a source) load from its source, and say so once, on
    standard error, with how to build them again. The status, as found. A core already
    imported compiled cannot be taken back: SystemExit then (it cannot happen when the
    package roots call this first, as they do)."""
    found = status()
    if found.state != "stale" or _finder() is not None:
        return found
    sources = {module_name(module): REPO / module for module in MODULES}
    for stray in strays():
        source = stray.with_name(stray.name.split(".")[0] + ".py")
        if source.is_file():
            sources[module_name(str(source.relative_to(REPO)))] = source
    loaded = [
        name
        for name in sources
        if not str(getattr(sys.modules.get(name), "__file__", "") or "").endswith(".py")
        and name in sys.modules
    ]
    if loaded:
        raise SystemExit(
            f"error: the compiled cores are stale ({found.why}) and {loaded[0]} was imported "
            "compiled before it could be loaded from its source: `make cores` builds them again"
        )
    sys.meta_path.insert(0, SourceFirst(sources))
    if not os.environ.get(STALE_ENV):
        os.environ[STALE_ENV] = "1"
        print(
            f"warning: the compiled cores are stale ({found.why}): running their source "
            "(slower); `make cores` builds them again",
            file=sys.stderr,
        )
    return found


__all__ = [
    "GROUP",
    "MANIFEST",
    "MODULES",
    "REPO",
    "STALE_ENV",
    "SourceFirst",
    "Status",
    "compiled_files",
    "digest",
    "extension_path",
    "importable",
    "module_name",
    "shared_library",
    "status",
    "strays",
    "use_source_if_stale",
]
