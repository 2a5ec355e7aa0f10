"""The robot in C on a microcontroller (c_robot/platform/, docs/porting.md "On a
microcontroller"): a robot without a source of entropy refuses to start, on Linux and as
firmware; the firmware fits its flash and RAM and computes doubles in software; the key
record a host writes is the one the firmware reads; and ``make check-mcu`` skips, saying
why, where the ARM toolchain is missing.

The firmware's tests need arm-none-eabi-gcc and newlib, and qemu-system-arm to run it
(skipped without, as on most machines); its lockstep runs are ``make check-mcu``'s, which
takes minutes. The C unit tests (``make -C c_robot test``, tests/test_c_robot.py) hold its
pure parts: the motor guard, the key record's reading, a long frame on a serial line."""

from __future__ import annotations

import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest
from outside_helpers import C_ROBOT, c_robot_binary, make_c_robot
from swarm_helpers import REPO

from portable import mcu

pytestmark = pytest.mark.timeout(600)

KEY_FILE = {"v": 1, "run": "demo", "keys": {"robot/9": "ab" * 32}}


def test_a_key_record_is_the_layout_the_firmware_reads() -> None:
    """Magic, robot id and length (little-endian), the key file, then the CRC-32 of all
    before it (c_robot/platform/key_record.h; the C unit tests read one made by hand)."""
    text = json.dumps(KEY_FILE).encode()
    record = mcu.key_record(text, 9)
    assert record[:4] == b"BOKR"
    assert struct.unpack("<II", record[4:12]) == (9, len(text))
    assert record[12:-4] == text
    assert struct.unpack("<I", record[-4:])[0] == zlib.crc32(record[:-4])


def test_a_robot_built_without_entropy_refuses_to_start(tmp_path: Path) -> None:
    """c-robot built with no source of random bytes (ENTROPY_NONE): exit code 1 and one
    error line before it says anything on its link (never a made-up nonce)."""
    if c_robot_binary() is None:
        pytest.skip("the C compiler ($CC, or gcc) or make is missing: the C robot cannot be built")
    built = make_c_robot("no-entropy")
    assert built.returncode == 0, built.stderr[-2000:]
    key = tmp_path / "robot-9.key"
    key.write_text(json.dumps(KEY_FILE))
    key.chmod(0o600)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as bridge:
        bridge.bind(("127.0.0.1", 0))
        bridge.settimeout(0.5)
        port = bridge.getsockname()[1]
        program = C_ROBOT / "build" / "no-entropy" / "c-robot"
        link = ["--link", f"udp://127.0.0.1:{port}", "--id", "9"]
        done = subprocess.run(
            [str(program), *link, "--key-file", str(key), "--give-up", "2"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        with pytest.raises(TimeoutError):
            bridge.recv(70000)
    assert done.returncode == 1
    errors = [line for line in done.stderr.splitlines() if "ERROR" in line]
    assert len(errors) == 1 and "no source of random bytes" in errors[0], done.stderr
    assert done.stdout == ""


def test_check_mcu_skips_and_says_why_where_the_toolchain_is_missing() -> None:
    """Without the ARM compiler, qemu-system-arm and socat on the path: one line saying
    what is missing and how to install it, and exit code 0."""
    empty = {**os.environ, "PATH": str(Path(sys.executable).parent)}
    done = subprocess.run(
        [sys.executable, "-m", "portable.mcu"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=empty,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "check-mcu: skipped: arm-none-eabi-gcc, qemu-system-arm, socat missing (Debian: "
        "apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm socat); "
        "the firmware was not built or run"
    ]


def arm_toolchain() -> None:
    """Skip, saying why, without the ARM compiler or its newlib."""
    if shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("arm-none-eabi-gcc is missing (apt-get install gcc-arm-none-eabi)")
    if "newlib for arm-none-eabi" in mcu.missing_tools():
        pytest.skip("newlib for arm-none-eabi is missing (apt-get install libnewlib-arm-none-eabi)")


def test_the_firmware_fits_its_budgets_and_computes_doubles_in_software() -> None:
    """At most 256 KB of flash and 128 KB of RAM (data, bss, heap and stack, as the build
    reserves them; the linker script fails past them), and no double-precision FPU
    instruction or fused multiply-add: every double is libgcc's, bit for bit IEEE's."""
    arm_toolchain()
    built = mcu.make("firmware", "ENTROPY=semihost")
    assert built.returncode == 0, built.stderr[-2000:]
    elf = mcu.firmware_path("semihost")
    flash, ram = mcu.memory(elf)
    assert 0 < flash <= mcu.FLASH_BUDGET and 0 < ram <= mcu.RAM_BUDGET
    assert f"firmware: flash {flash} bytes, RAM {ram} bytes" in built.stdout
    assert mcu.double_instructions(elf) == []
    usage = (C_ROBOT / "build" / "m4" / "semihost").glob("*.su")
    assert any("controller_step" in path.read_text() for path in usage)  # -fstack-usage


def test_the_firmware_without_entropy_refuses_to_start_under_qemu(tmp_path: Path) -> None:
    """Built with ENTROPY=none, on netduinoplus2 with a key record in flash: exit code 1,
    the error line on its log, and not a byte on its link."""
    arm_toolchain()
    if shutil.which("qemu-system-arm") is None:
        pytest.skip("qemu-system-arm is missing (apt-get install qemu-system-arm)")
    built = mcu.make("firmware", "ENTROPY=none")
    assert built.returncode == 0, built.stderr[-2000:]
    ok, said = mcu.refuses_without_entropy(mcu.firmware_path("none"), tmp_path)
    assert ok, said
