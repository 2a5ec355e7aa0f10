"""The compiled cores: the pure modules a tick runs through, compiled by mypyc from their
own source.

The interpreted source is the reference. The compiled modules are that source, checked
by mypy and turned into C by mypyc, built without fused multiply-add
(``-ffp-contract=off``) and for the baseline of the machine's architecture (no
``-march``), so a run is the same, bit for bit, compiled or not, on any CPU
(``tests/test_compiled_cores.py`` runs both; docs/kernel.md). A machine without a C
compiler, or without mypyc, runs the source unchanged.

They are built in place, each next to its source
(``robot_agent/core/controller.cpython-311-x86_64-linux-gnu.so``, with the shared
``bestofn_swarm/wire/cores__mypyc...so``), where Python imports them in place of the source. So a
source edited after a build would be shadowed by its old compiled self: ``check`` tells,
every program of the swarm refuses to start with stale cores, and ``make`` builds them
again whenever a source changes.

    python -m bestofn_swarm.plumbing.cores build     # build them, or say why they are not built
    python -m bestofn_swarm.plumbing.cores status    # compiled, interpreted or stale, and why
    python -m bestofn_swarm.plumbing.cores clean     # remove them: the interpreted source runs
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import importlib.machinery
import importlib.util
import json
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from bestofn_swarm.plumbing import checkout
from bestofn_swarm.plumbing.cliargs import UsageError

REPO = checkout.ROOT  # where the packages are: the cores are built next to their sources

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
# Fixed, whatever CFLAGS says: no contraction into fused multiply-adds (the rounding of a
# * b + c would then depend on the CPU's instructions), and no -march.
COMPILE_FLAGS = ("-ffp-contract=off",)
# Flags of Python's own build that would change the arithmetic: refused.
UNSAFE_FLAGS = ("-ffast-math", "-Ofast", "-march", "-mfma", "-funsafe-math-optimizations")
MANIFEST = REPO / "build" / "cores.json"
LOG = REPO / "build" / "cores.log"


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


def _shared_library() -> Path:
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return REPO / (GROUP.replace(".", "/") + "__mypyc" + suffix)


def importable(name: str, suffixes: Sequence[str]) -> bool:
    """Whether this interpreter's import system would load a file of this name as a module:
    a module name and one of its extension suffixes. Another machine's build in the same
    folder (``engine.cpython-311-x86_64-linux-gnu.so`` seen by an aarch64 Python) is not."""
    return any(
        name.endswith(suffix) and name.removesuffix(suffix).isidentifier() for suffix in suffixes
    )


def _compiled_files() -> list[Path]:
    """Every compiled module this interpreter would import from the folders the cores come
    from, ours or not."""
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    folders = sorted({(REPO / module).parent for module in MODULES})
    return [
        path for folder in folders for path in folder.iterdir() if importable(path.name, suffixes)
    ]


def _strays() -> list[Path]:
    """Compiled modules there that no longer belong to the cores: each would shadow its
    source."""
    ours = {extension_path(module) for module in MODULES} | {_shared_library()}
    return [path for path in _compiled_files() if path not in ours]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fingerprint() -> dict[str, object]:
    """What a build depends on: the sources, and the Python and mypy that built them."""
    mypy_version: str | None
    try:
        from mypy.version import __version__ as mypy_version
    except ImportError:
        mypy_version = None
    return {
        "python": sys.version,
        "platform": sysconfig.get_platform(),
        "mypy": mypy_version,
        "flags": list(COMPILE_FLAGS),
        "sources": {module: _digest(REPO / module) for module in MODULES},
    }


def status() -> Status:
    """Whether the compiled cores are built, fresh, and what runs."""
    built = [module for module in MODULES if extension_path(module).exists()]
    strays = _strays()
    if strays:
        return Status("stale", f"{strays[0].relative_to(REPO)} is not one of the cores")
    if not built and not _shared_library().exists():
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
    changed = [module for module in MODULES if sources.get(module) != _digest(REPO / module)]
    if changed:
        return Status("stale", f"{', '.join(changed[:3])} changed since the build")
    if manifest.get("python") != sys.version:
        return Status("stale", "built by another Python")
    return Status("compiled", f"{len(MODULES)} modules, mypy {manifest.get('mypy')}")


def check() -> None:
    """Stop the program (exit 2, with what to do) if compiled cores are stale: they would
    run old code in place of the source."""
    found = status()
    if found.state == "stale":
        raise SystemExit(
            f"error: the compiled cores are stale ({found.why}): `make cores` builds them "
            "again, `python -m bestofn_swarm.plumbing.cores clean` removes them (the source "
            "then runs)"
        )


def clean() -> int:
    """Remove every compiled core; how many files went."""
    removed = 0
    for path in [*(extension_path(module) for module in MODULES), *_compiled_files(), MANIFEST]:
        if path.exists():
            path.unlink()
            removed += 1
    return removed


def _compiler() -> str | None:
    """The C compiler Python's build uses, if it is installed."""
    compiler = os.environ.get("CC") or str(sysconfig.get_config_var("CC") or "cc")
    program = shlex.split(compiler)[0] if compiler.strip() else "cc"
    return program if shutil.which(program) else None


def why_not() -> str | None:
    """Why the cores cannot be built here (None: they can)."""
    if _compiler() is None:
        return "no C compiler"
    if importlib.util.find_spec("mypyc") is None or importlib.util.find_spec("setuptools") is None:
        return "mypyc is not installed (pip install 'bestofn-swarm[cores]')"
    python_flags = str(sysconfig.get_config_var("CFLAGS") or "")
    unsafe = [flag for flag in UNSAFE_FLAGS if flag in python_flags]
    if unsafe:
        return f"this Python was built with {unsafe[0]}, which would change the arithmetic"
    return None


def build(*, force: bool = False) -> Status:
    """Build the cores in place unless they are fresh (or ``force``); the status after.
    A build that fails leaves none behind: the source runs."""
    if not force and status().state == "compiled":
        return status()
    reason = why_not()
    if reason is not None:
        clean()
        return Status("interpreted", reason)
    clean()
    LOG.parent.mkdir(exist_ok=True)
    environment = {key: value for key, value in os.environ.items() if key != "CFLAGS"}
    command = [sys.executable, "-m", "bestofn_swarm.plumbing.cores", "_compile"]
    started = time.monotonic()
    with LOG.open("w") as log:
        done = subprocess.run(
            command, cwd=REPO, env=environment, stdout=log, stderr=subprocess.STDOUT, check=False
        )
    if done.returncode != 0 or not all(extension_path(m).exists() for m in MODULES):
        clean()
        return Status("interpreted", f"the build failed, see {LOG.relative_to(REPO)}")
    MANIFEST.write_text(json.dumps(_fingerprint(), indent=1) + "\n")
    found = status()
    return Status(found.state, f"{found.why}, built in {time.monotonic() - started:.0f} s")


def _compile() -> None:
    """The build itself, in a process of its own (``build`` runs it): mypyc, then the C
    compiler with COMPILE_FLAGS, each module put next to its source."""
    from mypyc.build import mypycify

    setup = importlib.import_module("setuptools").setup  # it ships no type information
    extensions = mypycify(list(MODULES), opt_level="3", group_name=GROUP)
    for extension in extensions:
        extension.extra_compile_args = [*extension.extra_compile_args, *COMPILE_FLAGS]
    setup(
        name="bestofn-cores",
        ext_modules=extensions,
        script_args=["build_ext", "--inplace", "--build-temp", "build/cores-temp"],
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bestofn_swarm.plumbing.cores", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("action", choices=["build", "status", "clean", "_compile"])
    parser.add_argument("--force", action="store_true", help="build even if fresh")
    args = parser.parse_args(argv)
    if args.action == "_compile":
        _compile()
        return 0
    if args.action == "clean":
        print(f"compiled cores: removed {clean()} files; the source runs")
        return 0
    if args.action == "build":
        try:  # built in place, next to their sources: in a checkout
            checkout.needed("building the compiled cores", "let the source run (the reference)")
        except UsageError as error:
            parser.exit(2, f"{parser.prog}: error: {error}\n")
    found = build(force=args.force) if args.action == "build" else status()
    print(found.line)
    return 1 if found.state == "stale" else 0


if __name__ == "__main__":
    sys.exit(main())
