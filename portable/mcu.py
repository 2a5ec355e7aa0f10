"""``make check-mcu`` (``python -m portable.mcu``): the robot in C as Cortex-M4F firmware,
under qemu-system-arm.

1. The toolchain: arm-none-eabi-gcc with newlib, qemu-system-arm and socat (Debian's
   gcc-arm-none-eabi, libnewlib-arm-none-eabi, qemu-system-arm, socat). Without them the
   check says what is missing and exits 0 (``check-mcu: skipped: ...``).
2. The firmware (``make -C c_robot firmware``, the limits of c_robot/platform/profile_mcu.h):
   its flash and RAM (``arm-none-eabi-size``) within 256 KB and 128 KB (the linker script
   holds it to them too), and no double-precision FPU instruction and no fused multiply-add
   in its code (``arm-none-eabi-objdump``): every double is libgcc's software arithmetic.
3. The unit tests on qemu's mps2-an386 (``make -C c_robot test-m4``): every vector passes.
4. A firmware built without a source of entropy (``ENTROPY=none``) refuses to start.
5. Lockstep runs of 10 robots with robot 9 the firmware on qemu's netduinoplus2 (an
   STM32F405) on a serial line (a socat pseudo-terminal pair), its key in flash (a key
   record, c_robot/platform/key_record.h): seeds 0 and 3 as the paper's, at 115200 baud,
   and seeds 7 and 8 with the camera's noise (``--camera-noise 120 --alpha 0.1``: PNG
   frames of 5 to 9.4 KB, the largest the firmware holds) at 921600. Each run is the
   all-emulated run of its seed and options, digest and per-robot results; two run at a
   time (``--jobs``). ``--icount`` runs qemu with ``-icount shift=0`` and reports the
   instructions of the firmware's steps.

    python -m portable.mcu                                     # everything
    python -m portable.mcu --seeds 0 --noisy-seeds --icount    # one run, with instructions

It prints a line per result and one summary line; exit code 0 when everything passed or
the tools are missing (skipped), 1 when anything failed, 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import json
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
C_ROBOT = REPO / "c_robot"
TOOLS = {
    "arm-none-eabi-gcc": "gcc-arm-none-eabi libnewlib-arm-none-eabi",
    "qemu-system-arm": "qemu-system-arm",
    "socat": "socat",
}
SEEDS = (0, 3)
NOISY_SEEDS = (7, 8)  # the two shortest of seeds 0 to 9 with noise: 153 and 143 s of sim time
NOISY = ("--camera-noise", "120", "--alpha", "0.1")  # robustness.md's noisiest but one
ROBOTS = 10
OUTSIDE = 9
BAUD = 115200  # the paper's runs; the noisy ones at NOISY_BAUD, to keep the check short
NOISY_BAUD = 921600
FLASH_BUDGET = 256 * 1024
RAM_BUDGET = 128 * 1024
KEY_RECORD_ADDRESS = 0x080E0000  # the last flash sector (platform/stm32f4/board.c)
# A lockstep world that waits long for a robot slowed by a busy machine stays in lockstep.
STALL_TIMEOUT = 300
RUN_TIMEOUT = 1800.0  # wall seconds for one run
# What would be a double-precision FPU instruction or a fused multiply-add in the firmware's
# code (the Cortex-M4F's FPU is single precision: a .f64 instruction would not even run).
FPU_DOUBLE = re.compile(r"\bv\w+\.f64\b|\bvf[n]?m[as]\b")


@dataclass
class Tally:
    """What was checked, and what failed."""

    started: float = field(default_factory=time.monotonic)
    passed: int = 0
    failures: list[str] = field(default_factory=list)

    def result(self, ok: bool, line: str) -> None:
        if ok:
            self.passed += 1
        else:
            self.failures.append(line)
        print(f"{'ok  ' if ok else 'FAIL'} {line}", flush=True)


def missing_tools() -> list[str]:
    """The tools of TOOLS that are not installed, and newlib if the compiler lacks it."""
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if "arm-none-eabi-gcc" not in missing:
        found = subprocess.run(
            ["arm-none-eabi-gcc", "-print-file-name=libc_nano.a"],
            capture_output=True,
            text=True,
            check=False,
        )
        if not Path(found.stdout.strip()).is_file():
            missing.append("newlib for arm-none-eabi")
    return missing


def make(*arguments: str, timeout: float = 1800.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "-C", str(C_ROBOT), *arguments],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def firmware_path(entropy: str) -> Path:
    return C_ROBOT / "build" / "m4" / entropy / "c-robot.elf"


# --- the key record ------------------------------------------------------------------------


def key_record(key_file: bytes, robot: int) -> bytes:
    """The key record a firmware reads from flash (c_robot/platform/key_record.h): magic,
    robot id, length, the key file, CRC-32 of all before it; integers little-endian."""
    head = b"BOKR" + struct.pack("<II", robot, len(key_file)) + key_file
    return head + struct.pack("<I", zlib.crc32(head))


# --- the firmware's figures --------------------------------------------------------------


def sections(elf: Path) -> dict[str, int]:
    """The sizes of the firmware's sections (arm-none-eabi-size -A)."""
    listed = subprocess.run(
        ["arm-none-eabi-size", "-A", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    found = {}
    for line in listed.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            found[parts[0]] = int(parts[1])
    return found


def memory(elf: Path) -> tuple[int, int]:
    """Flash (vectors, code, constants, the data's initial values) and RAM (data, bss, the
    heap and the stack the linker script reserves), in bytes."""
    size = sections(elf)
    flash = sum(size.get(name, 0) for name in (".isr_vector", ".text", ".ARM.exidx", ".data"))
    ram = sum(size.get(name, 0) for name in (".data", ".bss", ".heap", ".stack"))
    return flash, ram


def double_instructions(elf: Path) -> list[str]:
    """The firmware's instructions that compute in double precision on the FPU or fuse a
    multiply and an add (none: every double operation is a libgcc call)."""
    listing = subprocess.run(
        ["arm-none-eabi-objdump", "-d", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    return [line.strip() for line in listing.splitlines() if FPU_DOUBLE.search(line)]


# --- the firmware on qemu ----------------------------------------------------------------


def qemu_command(elf: Path, record: Path, link: Path, log: Path, icount: bool) -> list[str]:
    """netduinoplus2 running the firmware: USART1 on the robot's end of the serial line,
    USART2 (the log) into a file, the key record in flash, semihosting for the host's
    entropy and the exit code."""
    command = ["qemu-system-arm", "-machine", "netduinoplus2", "-nographic", "-monitor", "none"]
    command += ["-semihosting-config", "enable=on,target=native"]
    command += ["-chardev", f"serial,id=link,path={link}", "-serial", "chardev:link"]
    command += ["-serial", f"file:{log}"]
    command += ["-device", f"loader,file={record},addr={KEY_RECORD_ADDRESS:#x},force-raw=on"]
    if icount:
        command += ["-icount", "shift=0"]  # the clock counts instructions: 1 ns each
    return [*command, "-kernel", str(elf)]


def log_lines(log: Path) -> tuple[list[str], dict[str, Any], dict[str, Any]]:
    """The firmware's log: its lines, the program's last line and its own figures."""
    lines = log.read_text(errors="replace").splitlines() if log.exists() else []
    summary: dict[str, Any] = {}
    figures: dict[str, Any] = {}
    for line in lines:
        if line.startswith("{"):
            found = json.loads(line)
            if "firmware" in found:
                figures = found["firmware"]
            else:
                summary = found
    return lines, summary, figures


@contextlib.contextmanager
def pty_pair(folder: Path) -> Iterator[tuple[Path, Path]]:
    """A serial line: two pseudo-terminals joined by socat, the bridge's end and the
    robot's."""
    bridge, robot = folder / "bridge-tty", folder / "robot-tty"
    process = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={bridge}", f"pty,raw,echo=0,link={robot}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 10
        while not (bridge.exists() and robot.exists()) and time.monotonic() < deadline:
            time.sleep(0.05)
        yield bridge, robot
    finally:
        stop([process])


def stop(processes: Sequence[subprocess.Popen[Any]]) -> None:
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def refuses_without_entropy(elf: Path, folder: Path) -> tuple[bool, str]:
    """The firmware built without a source of entropy, with a key record in flash: whether
    it stops at once with exit code 1, saying why, before sending a byte."""
    key_file = json.dumps({"v": 1, "run": "demo", "keys": {"robot/9": "ab" * 32}}).encode()
    record = folder / "record.bin"
    record.write_bytes(key_record(key_file, OUTSIDE))
    link, log = folder / "link.out", folder / "log.txt"
    command = qemu_command(elf, record, link, log, icount=False)
    command[command.index(f"serial,id=link,path={link}")] = f"file,id=link,path={link}"
    done = subprocess.run(command, capture_output=True, timeout=60, check=False)
    lines, _, _ = log_lines(log)
    said = next((line for line in lines if "ERROR" in line), "no error line")
    sent = link.read_bytes() if link.exists() else b""
    ok = done.returncode == 1 and "no source of random bytes" in said and sent == b""
    return ok, f"exit {done.returncode}, {len(sent)} bytes sent: {said}"


def lockstep(elf: Path, seed: int, extra: Sequence[str], baud: int, icount: bool) -> dict[str, Any]:
    """A lockstep run of ROBOTS robots, robot OUTSIDE the firmware on a serial line, and the
    all-emulated run of the seed and options: whether they are the same run, and the
    firmware's figures."""
    from benchmarks import link_runs

    options = ["--robots", str(ROBOTS), "--seed", str(seed), *extra, "--timeout", "3000"]
    options += ["--stall-timeout", str(STALL_TIMEOUT)]
    reference = link_runs.in_process(options)
    folder = Path(tempfile.mkdtemp(prefix="check-mcu-"))
    keys = folder / "keys"
    started = time.monotonic()
    try:
        with pty_pair(folder) as (bridge, robot):
            command = [
                *(sys.executable, "-m", "deploy.cli", "run", "--json", "--quiet"),
                *("--no-record", *options, "--external", str(OUTSIDE)),
                *("--link", f"{OUTSIDE}=serial:{bridge}@{baud}", "--link-keys", str(keys)),
            ]
            run = subprocess.Popen(
                command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE
            )
            qemu: subprocess.Popen[bytes] | None = None
            try:
                key_file = keys / f"robot-{OUTSIDE}.key"
                deadline = time.monotonic() + 120
                while not key_file.exists() and time.monotonic() < deadline:
                    time.sleep(0.05)
                record = folder / "record.bin"
                record.write_bytes(key_record(key_file.read_bytes(), OUTSIDE))
                log = folder / "firmware.log"
                qemu = subprocess.Popen(
                    qemu_command(elf, record, robot, log, icount),
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                )
                stdout, stderr = run.communicate(timeout=RUN_TIMEOUT)
                qemu.wait(timeout=60)  # the bridge's BYE 1 ends the firmware
            finally:
                stop([run, *([qemu] if qemu is not None else [])])
        lines, program, figures = log_lines(log)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    if not stdout.strip():
        raise RuntimeError(f"swarm run failed: {stderr.decode()[-1000:]}")
    summary = json.loads(stdout)
    same = link_runs.decisions(summary) == link_runs.decisions(reference)
    return {
        "seed": seed,
        "same": same and summary["digest"] == reference["digest"],
        "digest": summary["digest"],
        "reference_digest": reference["digest"],
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": round(time.monotonic() - started, 1),
        "stalls": summary["world"]["stalls"],
        "departures": summary["world"]["departures"],
        "firmware_exit": qemu.returncode if qemu is not None else None,
        "program": program,
        "firmware": figures,
        "log_tail": [line for line in lines if "WARNING" in line or "ERROR" in line][-4:],
    }


def instructions(figures: dict[str, Any]) -> str:
    """A run's step costs under -icount shift=0 (1 ns of the guest's clock an
    instruction), in instructions: the controller's step, and the whole step (the last
    input's tag, the PNG, the controller, the messages and their tags)."""
    per_tick = 1e9 / figures["clock_hz"]
    steps = figures["steps"] or 1
    said = []
    for name, what in (("controller", "controller_step"), ("step", "a whole step")):
        mean = figures[f"{name}_ticks_total"] / steps * per_tick
        worst = figures[f"{name}_ticks_worst"] * per_tick
        said.append(f"{what} {mean / 1000:.1f}k instructions on average, {worst / 1e6:.2f}M worst")
    return "; ".join(said)


# --- the check -----------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="check-mcu",
        description="The robot in C as Cortex-M4F firmware under qemu: its memory, its unit "
        "tests, and lockstep runs with it on a serial line.",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="*",
        default=list(SEEDS),
        metavar="SEED",
        help=f"the seeds of the paper's runs (default: {' '.join(map(str, SEEDS))})",
    )
    parser.add_argument(
        "--noisy-seeds",
        type=int,
        nargs="*",
        default=list(NOISY_SEEDS),
        metavar="SEED",
        help=f"the seeds of the runs with {' '.join(NOISY)} (default: "
        f"{' '.join(map(str, NOISY_SEEDS))})",
    )
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time (default: 2)")
    parser.add_argument(
        "--icount",
        action="store_true",
        help="run qemu with -icount shift=0 and report the steps' instructions",
    )
    parser.add_argument(
        "--no-unit-tests", action="store_true", help="leave out the unit tests on mps2-an386"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    missing = missing_tools()
    if missing:
        packages = sorted({p for tool in missing for p in TOOLS.get(tool, tool).split()})
        print(
            f"check-mcu: skipped: {', '.join(missing)} missing (Debian: apt-get install "
            f"{' '.join(packages)}); the firmware was not built or run",
            flush=True,
        )
        return 0
    tally = Tally()
    print(f"check-mcu: load {Path('/proc/loadavg').read_text().split()[0]}", flush=True)
    for entropy in ("semihost", "none"):
        built = make("firmware", f"ENTROPY={entropy}")
        if built.returncode != 0:
            tally.result(False, f"make firmware ENTROPY={entropy}: {built.stderr[-500:]}")
            return finish(tally)
    elf = firmware_path("semihost")
    flash, ram = memory(elf)
    tally.result(flash <= FLASH_BUDGET, f"firmware flash {flash} bytes (budget {FLASH_BUDGET})")
    tally.result(ram <= RAM_BUDGET, f"firmware RAM {ram} bytes (budget {RAM_BUDGET})")
    doubles = double_instructions(elf)
    tally.result(
        not doubles,
        "no double-precision FPU instruction, no fused multiply-add"
        + (f": {doubles[:3]}" if doubles else ""),
    )
    with tempfile.TemporaryDirectory(prefix="check-mcu-") as folder:
        ok, said = refuses_without_entropy(firmware_path("none"), Path(folder))
    tally.result(ok, f"a firmware without entropy refuses to start ({said})")
    if not args.no_unit_tests:
        done = make("test-m4", timeout=1800)
        total = re.findall(r"^(\d+) passed, (\d+) failed$", done.stdout, re.MULTILINE)
        ok = done.returncode == 0 and bool(total) and total[-1][1] == "0"
        line = f"{total[-1][0]} passed, {total[-1][1]} failed" if total else done.stdout[-300:]
        tally.result(ok, f"unit tests on mps2-an386: {line}")
    runs: list[tuple[int, tuple[str, ...], int]] = [(seed, (), BAUD) for seed in args.seeds]
    runs += [(seed, NOISY, NOISY_BAUD) for seed in args.noisy_seeds]
    with concurrent.futures.ThreadPoolExecutor(max(1, args.jobs)) as pool:
        started = {
            pool.submit(lockstep, elf, seed, extra, baud, args.icount): (seed, extra, baud)
            for seed, extra, baud in runs
        }
        for future in concurrent.futures.as_completed(started):
            seed, extra, baud = started[future]
            what = f"seed {seed}{' ' + ' '.join(extra) if extra else ''}"
            try:
                found = future.result()
            except (RuntimeError, OSError, subprocess.SubprocessError) as error:
                tally.result(False, f"{what}: {error}")
                continue
            clean = found["firmware"].get("overruns") == 0  # no byte lost by the ring
            tally.result(
                found["same"] and found["firmware_exit"] == 0 and clean,
                run_line(what, baud, found, args.icount),
            )
    return finish(tally)


def run_line(what: str, baud: int, found: dict[str, Any], icount: bool) -> str:
    line = (
        f"{what}: robot {OUTSIDE} on netduinoplus2 at {baud} baud, digest "
        f"{found['digest']} (all emulated {found['reference_digest']}), sim "
        f"{found['sim_time_s']} s in {found['wall_time_s']} s, stalls {found['stalls']}, "
        f"departures {found['departures']}, link sessions {found['program'].get('sessions')}"
    )
    figures = found["firmware"]
    if figures:
        line += (
            f"; firmware: {figures['steps']} steps, largest frame "
            f"{figures['largest_frame']} B, stack peak {figures['stack_peak']} B, heap peak "
            f"{figures['heap_peak']} B, bytes lost {figures['overruns']}, frames refused "
            f"{figures['framing_refused']}, exit {found['firmware_exit']}"
        )
        if icount:
            line += "; " + instructions(figures)
    if not found["same"]:
        line += "; the firmware's log ends: " + " | ".join(found["log_tail"])
    return line


def finish(tally: Tally) -> int:
    elapsed = time.monotonic() - tally.started
    if tally.failures:
        print(f"check-mcu: {len(tally.failures)} FAILED, {tally.passed} passed, {elapsed:.0f} s")
        return 1
    print(f"check-mcu: all {tally.passed} passed, {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
