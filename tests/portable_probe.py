"""Runs a few swarms in process and prints what they decided, robot by robot, as one JSON
object; tests/test_portable_runs.py runs it twice, once with the machine's CPU dispatch as
it is and once with every dispatched SIMD path of numpy, OpenCV and glibc masked, and
requires the two outputs to be equal.

The runs cover every part of the numeric kernel and the generator that shapes a run:
physics and navigation (every run), camera pixel noise and lighting, radio loss (the
radio's streams), range loss (a power), the log-linear pool (logarithms and exponentials)
and a rival strategy's exponential draws. The Section 4 model (simulated, opinion by
opinion, and its exact chain) and a digest of the kernel's functions on a grid of inputs
come with them: a difference there names its source even when no swarm happens to show it.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.rng import Stream
from deploy import cli
from robot_agent.wellstirred import model as wellstirred
from robot_agent.wellstirred import voting

# Each a list of `swarm run` options; all in process, lockstep, no recording.
RUNS: list[list[str]] = [
    ["--seed", "0"],
    ["--seed", "1", "--robots", "8", "--sites", "6", "--drop", "0.2", "--camera-noise", "8",
     "--lighting", "0.3", "--range-loss", "0.5:2", "--timeout", "400"],
    ["--seed", "2", "--robots", "8", "--sites", "6", "--alpha", "0.1", "--pooling",
     "loglinear", "--timeout", "400"],
    ["--seed", "3", "--robots", "8", "--sites", "6", "--strategy", "dmvd", "--timeout", "400"],
    ["--seed", "4", "--robots", "6", "--sites", "5", "--linger", "10", "--timeout", "400"],
    ["--seed", "5", "--robots", "40", "--timeout", "60"],
]  # fmt: skip

# What a run's result is, robot by robot (the fields the run digest covers, and more).
ROBOT_FIELDS = ("id", "decided_site", "decision_time_s", "steps", "trips", "pool_sizes")


def run_results(options: list[str]) -> dict[str, Any]:
    """One in-process run's ending, sim time, radio counts and per-robot results."""
    out = io.StringIO()
    argv = ["run", "--engine", "inprocess", "--no-record", "--json", "--quiet", *options]
    with contextlib.redirect_stdout(out):
        code = cli.main(argv)
    summary = json.loads(out.getvalue())
    return {
        "options": options,
        "exit_code": code,
        "ended": summary["ended"],
        "sim_time_s": summary["sim_time_s"],
        "radio": summary["radio"],
        "per_robot": [
            {field: robot[field] for field in ROBOT_FIELDS} for robot in summary["per_robot"]
        ],
    }


def section4_results() -> dict[str, Any]:
    """The Section 4 model: survivors and opinion paths, a voting rival, the exact chain."""
    results: dict[str, Any] = {}
    for name, model in (
        ("survivors", wellstirred.Model(options=10, pool=3)),
        ("opinions", wellstirred.Model(options=10, pool=3, population=12, alpha=0.1,
                                       threshold=0.9)),
    ):  # fmt: skip
        outcome = wellstirred.simulate(model, 200, wellstirred.cell_rng(0, model))
        results[name] = outcome.times.tolist()
    vote = voting.VoteModel(strategy="dmmd", options=5, pool=3, population=10)
    results["dmmd"] = voting.simulate_votes(vote, 50, np.random.default_rng(0)).times.tolist()
    exact = wellstirred.exact_consensus_time(wellstirred.Model(options=20, pool=3))
    results["exact"] = exact.mean.hex()
    return results


def kernel_digest() -> str:
    """SHA-256 of the kernel's outputs, scalar and array, on a fixed grid of inputs."""
    digest = hashlib.sha256()
    stream = Stream(12345)
    angles = stream.random_array(4096) * 200.0 - 100.0
    exponents = (stream.random_array(4096) * 60.0 - 30.0).astype(np.int64)
    positive = np.ldexp(1.0 + stream.random_array(4096), exponents)  # exact scaling
    for array in (*numeric.sincos_array(angles), numeric.log_array(positive),
                  numeric.exp_array(angles), numeric.wrap_angle_array(angles),
                  stream.normal_array(4096)):  # fmt: skip
        digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
    for x, y in zip(angles.tolist(), positive.tolist(), strict=True):
        values = (*numeric.sincos(x), numeric.atan2(x, y - 1.0), numeric.atan(x),
                  numeric.exp(x), numeric.log(y), numeric.power(y, 0.37))  # fmt: skip
        digest.update(struct.pack("<7d", *values))
    return digest.hexdigest()


def python_from(
    root: Path, arguments: list[str], environment: dict[str, str], timeout: float = 250.0
) -> subprocess.CompletedProcess[str]:
    """``python ARGUMENTS`` in a fresh interpreter from the checkout ``root`` (its packages
    first on the path) with ``environment``; its output captured."""
    return subprocess.run(
        [sys.executable, *arguments],
        cwd=root,
        env=dict(environment, PYTHONPATH=str(root)),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def run(root: Path, environment: dict[str, str], timeout: float = 250.0) -> dict[str, Any]:
    """This probe's results, run in a fresh interpreter from the checkout ``root`` (its
    packages first on the path) with ``environment``."""
    done = python_from(root, [str(root / "tests" / "portable_probe.py")], environment, timeout)
    if done.returncode != 0:
        raise AssertionError(done.stderr[-2000:])
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def main() -> int:
    from robot_agent.core import controller

    json.dump(
        {
            "compiled": not controller.__file__.endswith(".py"),
            "kernel": kernel_digest(),
            "section4": section4_results(),
            "runs": [run_results(options) for options in RUNS],
        },
        sys.stdout,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
