"""The machines ``make check-portable`` runs on, and what each needs.

* ``native``: this machine, with the project's virtual environment.
* ``haswell``: x86-64 without AVX-512 (``qemu-x86_64 -cpu Haswell-v4``: AVX2 and FMA; numpy
  finds X86_V3, not X86_V4), the same interpreter and virtual environment.
* ``nehalem``: x86-64-v2, no AVX at all (``qemu-x86_64 -cpu Nehalem``: SSE4.2), the same.
* ``aarch64``: 64-bit ARM (``qemu-aarch64``, its default CPU, with SVE): Debian's arm64
  Python 3.11, taken from Debian's packages into a folder (nothing is installed on this
  machine), with requirements/run.lock installed into another from PyPI's manylinux
  aarch64 wheels; ``cortex-a72`` (not in the default check): the same on a Raspberry Pi
  4's CPU, where numpy finds nothing beyond its baseline.

qemu-user runs one program of another CPU in this machine's kernel. A program that one of
them starts is not emulated: the probes start none (portable/probe.py). Compiled modules
of this repository (mypyc builds, ``.so`` files beside the ``.py`` ones) are what the x86-64
interpreter loads, emulated or not; the aarch64 interpreter looks only for its own
extension suffix (``.cpython-311-aarch64-linux-gnu.so``) and runs the ``.py`` files.

What is downloaded is kept under the cache folder (``.portable/`` in the repository, which
git ignores): a second check finds it there and downloads nothing.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
import tarfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
RUN_LOCK = REPO / "requirements" / "run.lock"

# The Debian packages of the tools, installed on this machine when they are missing (as
# root; anyone else is told what to install). Not qemu-user-binfmt, which Debian
# recommends: registered with the kernel, it would run any aarch64 program through qemu,
# and the checks would no longer show that each program is started through the emulator.
TOOLS = {
    "qemu-x86_64": "qemu-user",
    "qemu-aarch64": "qemu-user",
    "aarch64-linux-gnu-gcc": "gcc-aarch64-linux-gnu libc6-dev-arm64-cross",
}

# Debian's arm64 packages of the interpreter: these and everything they depend on, less the
# tools among those dependencies that an interpreter never loads (a package manager, perl
# and the MIME tables' installers). libstdc++6: the C++ runtime of numpy's, OpenCV's and
# pymunk's wheels (manylinux wheels take it from the system).
ARM64_PACKAGES = ("python3.11-minimal", "libpython3.11-stdlib", "libstdc++6")
ARM64_NOT_NEEDED = re.compile(
    r"^(dpkg|tar|install-info|mailcap|mime-support|media-types|readline-common|perl.*|libperl.*)$"
)
# The manylinux wheels an arm64 Debian 12 (glibc 2.36) takes; pip takes only the tags it
# is given.
AARCH64_PLATFORMS = ["manylinux2014_aarch64"] + [
    f"manylinux_2_{minor}_aarch64" for minor in range(17, 37)
]
# Packages of the lock that publish no wheel, only a source archive, and what serves on
# aarch64 instead: cobs's C extension is optional, and its package falls back to its pure
# Python modules without it, so the package folder of the (hash-checked) archive is copied
# as it is, and nothing is compiled.
SOURCE_ONLY = {"cobs": "src/cobs/"}

# What makes numpy, OpenCV, glibc or OpenBLAS ignore CPU features: none of it may reach a
# probe, or a machine would not be the CPU it is said to be.
MASKS = (
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "OPENCV_CPU_DISABLE",
    "GLIBC_TUNABLES",
    "OPENBLAS_CORETYPE",
)
# qemu-x86_64's warnings that TCG leaves out a feature of a CPU model that no user program
# sees (invpcid, spec-ctrl): noise, dropped from the error output.
QEMU_NOISE = "TCG doesn't support requested feature"


class SetupError(Exception):
    """A tool or a package the check needs is missing or cannot be had (one line)."""


def run_quietly(command: Sequence[str], what: str, **kwargs: Any) -> str:
    """Run a command; its standard output, or SetupError with its last error line."""
    done = subprocess.run(list(command), capture_output=True, text=True, check=False, **kwargs)
    if done.returncode != 0:
        lines = [
            line
            for line in (done.stderr + done.stdout).splitlines()
            if line.strip() and "Location 'file:" not in line
        ]
        raise SetupError(f"{what} failed: {lines[-1] if lines else f'exit {done.returncode}'}")
    return done.stdout


def ensure_tools(names: Sequence[str], log: Callable[[str], None]) -> None:
    """Install the missing ones among ``names`` (TOOLS) with apt-get, as root; else
    SetupError saying what to install."""
    missing = [name for name in names if shutil.which(name) is None]
    if not missing:
        return
    packages = sorted({package for name in missing for package in TOOLS[name].split()})
    install = "apt-get install --no-install-recommends " + " ".join(packages)
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise SetupError(f"{', '.join(missing)} missing: install Debian's packages ({install})")
    log(f"setup: {', '.join(missing)} missing: {install}")
    environment = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    run_quietly(["apt-get", "update", "-qq"], "apt-get update", env=environment)
    run_quietly(
        ["apt-get", "install", "-y", "-qq", "--no-install-recommends", *packages],
        "apt-get install",
        env=environment,
    )
    still = [name for name in names if shutil.which(name) is None]
    if still:
        raise SetupError(f"{', '.join(still)} still missing after {install}")


def probe_environment(extra: dict[str, str] | None = None) -> dict[str, str]:
    environment = {name: value for name, value in os.environ.items() if name not in MASKS}
    environment.update(extra or {})
    return environment


@dataclass(frozen=True)
class Machine:
    """A machine a probe runs on: the command that starts an interpreter there, the
    environment, and what it must report (``expect``: the problems with what it said)."""

    name: str
    title: str
    prefix: tuple[str, ...]
    interpreter: tuple[str, ...]
    environment: tuple[tuple[str, str], ...] = ()

    def command(self, *arguments: str) -> list[str]:
        return [*self.prefix, *self.interpreter, *arguments]

    def env(self) -> dict[str, str]:
        return probe_environment(dict(self.environment))

    def expect(self, about: dict[str, Any]) -> list[str]:
        """What is wrong with the machine a probe reported, for this machine's name: an
        emulator that gave another CPU would make the check show nothing."""
        simd = set(about.get("numpy_simd", []))
        wanted: dict[str, tuple[str, set[str], set[str]]] = {
            "haswell": ("x86_64", {"X86_V3"}, {"X86_V4"}),
            "nehalem": ("x86_64", set(), {"X86_V3", "X86_V4"}),
            "aarch64": ("aarch64", set(), set()),
            "cortex-a72": ("aarch64", set(), {"ASIMDHP", "ASIMDDP", "ASIMDFHM", "SVE"}),
        }
        if self.name not in wanted:
            return []
        machine, present, absent = wanted[self.name]
        problems = []
        if about.get("machine") != machine:
            problems.append(f"the interpreter runs on {about.get('machine')}, not {machine}")
        if not present <= simd:
            problems.append(f"numpy finds {sorted(simd)}, without {sorted(present - simd)}")
        if absent & simd:
            problems.append(f"numpy finds {sorted(absent & simd)}, which this CPU lacks")
        return problems


def native() -> Machine:
    return Machine("native", "this machine", (), (sys.executable,))


def x86_64(name: str, cpu: str, title: str) -> Machine:
    return Machine(name, title, ("qemu-x86_64", "-cpu", cpu), (sys.executable,))


def haswell() -> Machine:
    return x86_64("haswell", "Haswell-v4", "x86-64 without AVX-512 (qemu-x86_64 -cpu Haswell-v4)")


def nehalem() -> Machine:
    return x86_64("nehalem", "Nehalem", "x86-64-v2 without AVX (qemu-x86_64 -cpu Nehalem)")


# --- aarch64: Debian's arm64 interpreter and the lock's aarch64 wheels ----------------------


def lock_blocks(text: str) -> list[tuple[str, str]]:
    """A hashed requirements file's entries: (name, the entry's lines), in order."""
    blocks: list[tuple[str, list[str]]] = []
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if line[0].isspace():
            if not blocks:
                raise ValueError(f"a continued line before any requirement: {line!r}")
            blocks[-1][1].append(line)
        else:
            name = re.split(r"[=<>!~;\s\[]", line, maxsplit=1)[0].lower().replace("_", "-")
            blocks.append((name, [line]))
    return [(name, "\n".join(lines)) for name, lines in blocks]


@dataclass(frozen=True)
class Aarch64Python:
    """Debian's arm64 Python 3.11 in ``root`` and run.lock's packages in ``site``."""

    cache: Path

    @property
    def root(self) -> Path:
        return self.cache / "root"

    @property
    def site(self) -> Path:
        return self.cache / "site"

    @property
    def python(self) -> Path:
        return self.root / "usr" / "bin" / "python3.11"

    def machine(self, cpu: str | None = None) -> Machine:
        """qemu's default aarch64 CPU (``max``: SVE, dot products, half floats), or the
        one named (``cortex-a72``, a Raspberry Pi 4's: none of those; numpy's baseline)."""
        paths = os.pathsep.join([str(REPO), str(self.site)])
        return Machine(
            cpu or "aarch64",
            f"aarch64 (qemu-aarch64{f' -cpu {cpu}' if cpu else ''}, Debian's arm64 Python 3.11, "
            "the lock's aarch64 wheels)",
            ("qemu-aarch64", *(("-cpu", cpu) if cpu else ()), "-L", str(self.root)),
            (str(self.python), "-s"),
            (("PYTHONPATH", paths), ("PYTHONNOUSERSITE", "1")),
        )

    def prepare(self, log: Callable[[str], None]) -> None:
        """Make ``root`` and ``site`` unless they are there for this lock already."""
        root_stamp = self.root / ".complete"
        if root_stamp.exists():
            log(f"setup: aarch64 Python: {root_stamp.read_text().strip()} (cached)")
        else:
            self._make_root(log)
        lock_text = RUN_LOCK.read_text()
        wanted = hashlib.sha256(lock_text.encode()).hexdigest()
        site_stamp = self.site / ".complete"
        if site_stamp.exists() and site_stamp.read_text().strip() == wanted:
            log("setup: aarch64 packages of requirements/run.lock (cached)")
        else:
            self._make_site(lock_text, log)
            site_stamp.write_text(wanted + "\n")

    def _apt(self) -> list[str]:
        """apt's options for arm64 on a state of its own under the cache: the machine's
        sources, nothing of the machine's own package state touched."""
        state = self.cache / "apt"
        for folder in (state / "lists" / "partial", state / "archives" / "partial"):
            folder.mkdir(parents=True, exist_ok=True)
        (state / "status").touch()
        options = {
            "APT::Architecture": "arm64",
            "APT::Architectures::": "arm64",
            "Dir::State::Lists": state / "lists",
            "Dir::State::status": state / "status",
            "Dir::Cache": state,
            "Dir::Cache::archives": state / "archives",
            "Debug::NoLocking": "1",
        }
        if os.geteuid() == 0:
            options["APT::Sandbox::User"] = "root"
        return [
            argument for name, value in options.items() for argument in ("-o", f"{name}={value}")
        ]

    def _make_root(self, log: Callable[[str], None]) -> None:
        for tool in ("apt-get", "apt-cache", "dpkg-deb"):
            if shutil.which(tool) is None:
                raise SetupError(f"{tool} missing: the aarch64 Python comes from Debian's packages")
        options = self._apt()
        log("setup: aarch64 Python: Debian's arm64 package lists (apt-get update)")
        run_quietly(["apt-get", *options, "update", "-qq"], "apt-get update (arm64)")
        listed = run_quietly(
            [
                "apt-cache",
                *options,
                "depends",
                "--recurse",
                "--no-recommends",
                "--no-suggests",
                "--no-conflicts",
                "--no-breaks",
                "--no-replaces",
                "--no-enhances",
                *ARM64_PACKAGES,
            ],
            "apt-cache depends (arm64)",
        )
        packages = sorted(
            {
                line.strip()
                for line in listed.splitlines()
                if line and not line[0].isspace() and not line.startswith("<")
            }
        )
        packages = [name for name in packages if not ARM64_NOT_NEEDED.match(name)]
        if "python3.11-minimal" not in packages:
            raise SetupError("apt's sources give no arm64 python3.11-minimal (Debian 12's do)")
        debs = self.cache / "debs"
        shutil.rmtree(debs, ignore_errors=True)
        debs.mkdir(parents=True)
        log(f"setup: aarch64 Python: apt-get download {len(packages)} arm64 packages")
        run_quietly(["apt-get", *options, "download", *packages], "apt-get download", cwd=debs)
        shutil.rmtree(self.root, ignore_errors=True)
        self.root.mkdir(parents=True)
        names = sorted(path.name for path in debs.glob("*.deb"))
        for name in names:
            run_quietly(["dpkg-deb", "-x", str(debs / name), str(self.root)], f"dpkg-deb -x {name}")
        version = run_quietly(
            [
                "qemu-aarch64",
                "-L",
                str(self.root),
                str(self.python),
                "-c",
                "import platform; print(platform.python_version(), platform.machine())",
            ],
            "the aarch64 Python",
        ).strip()
        python = next((name for name in names if name.startswith("python3.11-minimal_")), "")
        (self.root / ".complete").write_text(f"Python {version}, {python}\n")
        log(f"setup: aarch64 Python: Python {version}, from {len(names)} packages ({python})")

    def _make_site(self, lock_text: str, log: Callable[[str], None]) -> None:
        blocks = lock_blocks(lock_text)
        wheels = self.cache / "wheels"
        wheels.mkdir(parents=True, exist_ok=True)
        binary = self.cache / "binary.lock"
        source = self.cache / "source.lock"
        binary.write_text(
            "\n".join(text for name, text in blocks if name not in SOURCE_ONLY) + "\n"
        )
        source.write_text("\n".join(text for name, text in blocks if name in SOURCE_ONLY) + "\n")
        pip = [sys.executable, "-m", "pip", "--quiet", "--disable-pip-version-check"]
        platforms = [argument for tag in AARCH64_PLATFORMS for argument in ("--platform", tag)]
        target = [
            "--only-binary=:all:",
            *platforms,
            "--python-version",
            "3.11",
            "--implementation",
            "cp",
            "--abi",
            "cp311",
            "--no-deps",
            "--require-hashes",
        ]
        log(
            f"setup: aarch64 wheels of requirements/run.lock: pip download ({len(blocks)} packages)"
        )
        run_quietly(
            [*pip, "download", *target, "-d", str(wheels), "-r", str(binary)],
            "pip download of the lock's aarch64 wheels (a package without one?)",
        )
        if SOURCE_ONLY:
            run_quietly(
                [
                    *pip,
                    "download",
                    "--no-binary=:all:",
                    "--no-deps",
                    "--require-hashes",
                    "-d",
                    str(wheels),
                    "-r",
                    str(source),
                ],
                "pip download of the lock's source-only packages",
            )
        shutil.rmtree(self.site, ignore_errors=True)
        run_quietly(
            [
                *pip,
                "install",
                *target,
                "--no-index",
                "--find-links",
                str(wheels),
                "--target",
                str(self.site),
                "-r",
                str(binary),
            ],
            "pip install --target of the aarch64 wheels",
        )
        pinned = {name: text.split("==", 1)[1].split()[0] for name, text in blocks}
        for name, folder in SOURCE_ONLY.items():
            self._copy_pure_package(wheels / f"{name}-{pinned[name]}.tar.gz", folder, name)
        log(f"setup: aarch64 packages installed in {self.site}")

    def _copy_pure_package(self, archive: Path, folder: str, name: str) -> None:
        """The Python modules under ``folder`` of a source archive, into ``site/name``."""
        if not archive.exists():
            raise SetupError(f"{archive.name} was not downloaded")
        prefix = archive.name.removesuffix(".tar.gz") + "/" + folder
        with tarfile.open(archive) as tar:
            for member in tar.getmembers():
                if not (member.isfile() and member.name.startswith(prefix)):
                    continue
                if not member.name.endswith(".py"):
                    continue
                destination = self.site / name / member.name[len(prefix) :]
                destination.parent.mkdir(parents=True, exist_ok=True)
                extracted = tar.extractfile(member)
                if extracted is None:
                    raise SetupError(f"{archive.name}: {member.name} cannot be read")
                destination.write_bytes(extracted.read())
