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
source edited after a build would be shadowed by its old compiled self. It never is: the
first import of a package that holds cores (``bestofn_swarm``, ``robot_agent``,
``world_server``, ``deploy``) calls ``use_source_if_stale``, which, when the cores are stale,
has every core module load from its source (all of them: compiled modules call each other
directly, so one stale module cannot be swapped alone), says so in one warning line with
how to build them again, and lets the program run; ``make`` builds them again whenever a
source changes. Plug-ins are never compiled: they always run from their source.

    python -m bestofn_swarm.plumbing.cores build     # build them, or say why they are not built
    python -m bestofn_swarm.plumbing.cores status    # compiled, interpreted or stale, and why
    python -m bestofn_swarm.plumbing.cores clean     # remove them: the interpreted source runs
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import time

from bestofn_swarm.plumbing import checkout
from bestofn_swarm.plumbing.cliargs import UsageError
from bestofn_swarm.plumbing.cores_state import (
    GROUP,
    MANIFEST,
    MODULES,
    REPO,
    Status,
    compiled_files,
    digest,
    extension_path,
    importable,
    status,
    use_source_if_stale,
)

# Fixed, whatever CFLAGS says: no contraction into fused multiply-adds (the rounding of a
# * b + c would then depend on the CPU's instructions), and no -march.
COMPILE_FLAGS = ("-ffp-contract=off",)
# Flags of Python's own build that would change the arithmetic: refused.
UNSAFE_FLAGS = ("-ffast-math", "-Ofast", "-march", "-mfma", "-funsafe-math-optimizations")
LOG = REPO / "build" / "cores.log"


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
        "sources": {module: digest(REPO / module) for module in MODULES},
    }


def check() -> None:
    """Make sure no stale compiled core runs (``use_source_if_stale``): what every program
    calls first. It never stops the program."""
    use_source_if_stale()


def clean() -> int:
    """Remove every compiled core; how many files went."""
    removed = 0
    for path in [*(extension_path(module) for module in MODULES), *compiled_files(), MANIFEST]:
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


# The state of the cores is cores_state.py's; what tests and tools ask of it, here too.
__all__ = [
    "COMPILE_FLAGS",
    "GROUP",
    "MODULES",
    "REPO",
    "Status",
    "build",
    "check",
    "clean",
    "extension_path",
    "importable",
    "main",
    "status",
    "why_not",
]


if __name__ == "__main__":
    sys.exit(main())
