"""The robot in C (c_robot/) on aarch64: cross-built with ``aarch64-linux-gnu-gcc`` and run
under ``qemu-aarch64``.

* ``flags``: every compile of the cross build has ``-ffp-contract=off`` (no fused
  multiply-add, which aarch64 compilers otherwise emit) and no ``-march``/``-mcpu``/
  ``-ffast-math``;
* ``unit_tests``: ``make -C c_robot test`` with the cross compiler, every unit test run
  through the emulator (``C_ROBOT_EMULATOR``), the key-file cases included;
* ``lockstep``: a lockstep run over UDP with robots 8 and 9 run by the aarch64 program,
  against the all-emulated run of the same seed (benchmarks/link_runs.py): the same
  digest and per-robot results, bit for bit.
"""

from __future__ import annotations

import re
import shlex
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from portable.machines import REPO, SetupError, run_quietly

C_ROBOT = REPO / "c_robot"
CROSS = "aarch64-linux-gnu-gcc"
OUTSIDE = (8, 9)
# A compile flag that would let the compiler pick instructions or reorder arithmetic.
FORBIDDEN_FLAGS = re.compile(r"(^|\s)(-march=|-mcpu=|-mtune=native|-ffast-math|-Ofast|-mfma)")


@dataclass(frozen=True)
class Cross:
    """The cross build: its folder, and the emulator command that runs its programs."""

    target: str
    sysroot: Path

    @property
    def build(self) -> Path:
        return C_ROBOT / "build" / self.target

    @property
    def binary(self) -> Path:
        return self.build / "c-robot"

    def emulator(self) -> list[str]:
        return ["qemu-aarch64", "-L", str(self.sysroot)]


def cross() -> Cross:
    """The cross compiler's target and the folder of its C library (qemu's ``-L``)."""
    target = run_quietly([CROSS, "-dumpmachine"], f"{CROSS} -dumpmachine").strip()
    libc = Path(run_quietly([CROSS, "-print-file-name=libc.so.6"], CROSS).strip()).resolve()
    if not libc.is_file():
        raise SetupError(f"{CROSS} finds no libc.so.6 (install libc6-dev-arm64-cross)")
    return Cross(target, libc.parent.parent)  # .../aarch64-linux-gnu/lib/libc.so.6


def flags(build: Cross) -> list[str]:
    """What is wrong with the cross build's compile commands (``make -n``)."""
    programs = ["all", f"build/{build.target}/unit-tests"]
    planned = run_quietly(
        ["make", "-s", "-n", "-B", "-C", str(C_ROBOT), f"CC={CROSS}", *programs], "make -n"
    )
    return compile_problems(planned, CROSS)


def compile_problems(planned: str, compiler: str) -> list[str]:
    """What is wrong with the compile commands among ``planned`` (make's lines)."""
    compiles = [
        line for line in planned.splitlines() if line.startswith(compiler) and " -c " in line
    ]
    problems = [] if compiles else [f"make -n shows no compile with {compiler}"]
    for line in compiles:
        if "-ffp-contract=off" not in line.split():
            problems.append(f"no -ffp-contract=off: {line}")
        if FORBIDDEN_FLAGS.search(line):
            problems.append(f"a flag that changes arithmetic or picks a CPU: {line}")
    return problems


@dataclass(frozen=True)
class UnitTests:
    passed: int
    failed: int
    key_files: str  # the key-file cases' line
    output: str


def unit_tests(build: Cross) -> UnitTests:
    """``make -C c_robot test`` with the cross compiler, every program run under qemu."""
    emulator = shlex.join(build.emulator())
    done = subprocess.run(
        ["make", "-C", str(C_ROBOT), f"CC={CROSS}", f"C_ROBOT_EMULATOR={emulator}", "test"],
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    lines = done.stdout.splitlines()
    total = [m for line in lines if (m := re.fullmatch(r"(\d+) passed, (\d+) failed", line))]
    keys = next((line for line in lines if line.startswith("key files")), "no key-file line")
    if not total:
        tail = (done.stdout + done.stderr).strip().splitlines()[-3:]
        return UnitTests(0, 1, keys, " / ".join(tail))
    passed, failed = int(total[-1].group(1)), int(total[-1].group(2))
    if done.returncode != 0 and failed == 0:
        failed = 1
    return UnitTests(passed, failed, re.sub(r"\s+", " ", keys), done.stdout[-2000:])


def lockstep(build: Cross, seed: int) -> dict[str, Any]:
    """A lockstep run of 10 robots over UDP, robots 8 and 9 the aarch64 program, and the
    all-emulated run of the seed: whether they are the same run."""
    from benchmarks import link_runs
    from deploy.launcher.outside import free_udp_port

    options = ["--robots", "10", "--seed", str(seed), "--timeout", "3000"]
    options += ["--stall-timeout", str(link_runs.LOCKSTEP_STALL_TIMEOUT)]
    reference = link_runs.in_process(options)
    address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
    outside = {robot: (address, address) for robot in OUTSIDE}
    program = [*build.emulator(), str(build.binary)]
    summary, programs = link_runs.outside_run(options, outside, timeout=3600, program=program)
    same = link_runs.decisions(summary) == link_runs.decisions(reference)
    return {
        "seed": seed,
        "same": same and summary["digest"] == reference["digest"],
        "digest": summary["digest"],
        "reference_digest": reference["digest"],
        "sim_time_s": summary["sim_time_s"],
        "stalls": summary["world"]["stalls"],
        "departures": summary["world"]["departures"],
        "programs_ended": sum(1 for line in programs if line),
    }
