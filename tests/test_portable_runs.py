"""Same seed, same run, whatever the CPU: a few swarms give the same per-robot results with
the machine's SIMD dispatch as it is and with every dispatched path masked.

numpy, OpenCV and glibc's libm each pick code paths by CPU feature at run time (numpy's
float64 sin, cos, exp and log on AVX-512; glibc's FMA variants of sin, cos, atan, exp and
log). Masking the features this machine has beyond each library's baseline makes this
machine behave, for those libraries, as a CPU without them would. Nothing that shapes a
run may notice (docs/running.md, "Reproducibility"). On a CPU with no dispatched features
beyond the baselines the two runs are the same by construction; the test says so.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import portable_probe
import pytest

REPO = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.timeout(240)

# glibc's x86-64 features whose libm and string variants it picks at run time.
GLIBC_MASKED = ("AVX512F", "AVX512VL", "AVX512BW", "AVX512DQ", "AVX512CD", "AVX2", "FMA",
                "FMA4", "AVX")  # fmt: skip


def numpy_dispatched() -> list[str]:
    """The SIMD features numpy found on this CPU beyond its baseline."""
    umath = importlib.import_module("numpy._core._multiarray_umath")
    return [name for name in umath.__cpu_dispatch__ if umath.__cpu_features__.get(name)]


def opencv_dispatched() -> list[str]:
    """The SIMD features OpenCV dispatches to on this CPU (``*NAME`` in its features line,
    without the ``?`` of one that is not available)."""
    import cv2

    return [
        token[1:]
        for token in cv2.getCPUFeaturesLine().split()
        if token.startswith("*") and not token.endswith("?")
    ]


def masked_environment() -> dict[str, str]:
    environment = dict(os.environ)
    environment["NPY_DISABLE_CPU_FEATURES"] = " ".join(numpy_dispatched())
    environment["OPENCV_CPU_DISABLE"] = ",".join(opencv_dispatched())
    environment["GLIBC_TUNABLES"] = "glibc.cpu.hwcaps=" + ",".join(
        f"-{name}" for name in GLIBC_MASKED
    )
    # numpy's OpenBLAS picks its kernels by CPU too: the most generic x86-64 one.
    environment["OPENBLAS_CORETYPE"] = "Prescott"
    return environment


def probe(environment: dict[str, str]) -> dict[str, Any]:
    return portable_probe.run(REPO, environment, timeout=200)


def test_runs_are_the_same_with_every_dispatched_simd_path_masked() -> None:
    environment = masked_environment()
    masked_numpy = environment["NPY_DISABLE_CPU_FEATURES"]
    # The masking must take: numpy reports none of the masked features in the child.
    check = subprocess.run(
        [sys.executable, "-c", "import numpy, json; from numpy._core import _multiarray_umath "
         "as u; print(json.dumps([n for n in u.__cpu_dispatch__ if u.__cpu_features__[n]]))"],
        env=environment, capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    assert json.loads(check.stdout) == [], (masked_numpy, check.stdout)

    as_it_is = probe(dict(os.environ))
    masked = probe(environment)
    assert as_it_is["kernel"] == masked["kernel"], "the numeric kernel's outputs differ"
    assert as_it_is["section4"] == masked["section4"], "the Section 4 model's results differ"
    for plain, without_simd in zip(as_it_is["runs"], masked["runs"], strict=True):
        assert plain == without_simd, (
            f"swarm run {' '.join(plain['options'])}: the results differ with numpy's "
            f"{masked_numpy or 'nothing'}, OpenCV's {environment['OPENCV_CPU_DISABLE']} "
            f"and glibc's {','.join(GLIBC_MASKED)} masked"
        )
