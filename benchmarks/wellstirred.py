"""Time the full Figure 1 sweep of the well-stirred model, fast path against the reference.

The sweep: n in {10, 20, 50, 100}, k in {1, 2, 3, 4, 5, 6, 7, 8, 10, 15, 20, 30, 50},
1000 runs each, 100 steps, alpha = 0, population = pool (the paper's set-up).

* fast: ``sweep(..., method="auto")``, which takes the survivors path (exact in
  distribution for alpha = 0 and one pool: it tracks the number of surviving options).
* reference: ``sweep(..., method="opinions")``, the plain vectorised simulation of every
  agent's full opinion vector (the general path, used for alpha > 0 or population > pool).

Both run in this process with the same seed. The script prints each time, the speed-up,
and how well the two agree with each other and with the exact expected time.

    .venv/bin/python benchmarks/wellstirred.py [--repeat 3] [--runs 1000] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Sequence

import numpy as np

from bestofn_swarm.plumbing import cliargs
from robot_agent.wellstirred.model import (
    FIGURE1_OPTIONS,
    FIGURE1_POOLS,
    Cell,
    Method,
    Model,
    exact_consensus_time,
    sweep,
)


def timed_sweep(runs: int, seed: int, method: Method) -> tuple[float, list[Cell]]:
    start = time.perf_counter()
    cells = sweep(FIGURE1_OPTIONS, FIGURE1_POOLS, runs=runs, seed=seed, method=method)
    return time.perf_counter() - start, cells


def standard_error(cell: Cell) -> float:
    return math.sqrt(cell.outcome.times.var(ddof=1) / cell.outcome.runs)


def largest_z(first: Sequence[Cell], second: Sequence[Cell]) -> tuple[float, Cell]:
    """The largest |difference of means| / standard error over the cells, and where."""
    worst, where = 0.0, first[0]
    for a, b in zip(first, second, strict=True):
        variance = a.outcome.times.var(ddof=1) / a.outcome.runs
        variance += b.outcome.times.var(ddof=1) / b.outcome.runs
        difference = abs(a.summary.mean - b.summary.mean)
        # Cells with no spread (k = 1: always n - 1 steps) must agree exactly.
        z = difference / math.sqrt(variance) if variance > 0 else (math.inf if difference else 0)
        if z > worst:
            worst, where = z, a
    return worst, where


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--repeat",
        type=cliargs.positive_int,
        default=3,
        help="timed repetitions of the fast sweep (default: %(default)s)",
    )
    parser.add_argument("--runs", type=cliargs.positive_int, default=1000)
    parser.add_argument("--seed", type=cliargs.seed, default=0)
    args = parser.parse_args(argv)

    cells_count = len(FIGURE1_OPTIONS) * len(FIGURE1_POOLS)
    print(f"Figure 1 sweep: {cells_count} cells x {args.runs} runs, 100 steps, alpha = 0")
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}"
    )

    fast_times = []
    fast_cells: list[Cell] = []
    for _ in range(args.repeat):
        elapsed, fast_cells = timed_sweep(args.runs, args.seed, "auto")
        fast_times.append(elapsed)
    print(
        "fast (survivors path):   "
        + ", ".join(f"{t:.3f} s" for t in fast_times)
        + f"  (best {min(fast_times):.3f} s, median {statistics.median(fast_times):.3f} s)"
    )

    reference_time, reference_cells = timed_sweep(args.runs, args.seed, "opinions")
    print(f"reference (full opinions): {reference_time:.3f} s")
    print(
        f"speed-up: {reference_time / min(fast_times):.1f}x best, "
        f"{reference_time / statistics.median(fast_times):.1f}x median"
    )

    start = time.perf_counter()
    models = [cell.model for cell in fast_cells]
    exact = [exact_consensus_time(model).mean for model in models if isinstance(model, Model)]
    exact_time = time.perf_counter() - start
    print(f"exact chain for all {cells_count} cells: {exact_time:.3f} s")

    z, where = largest_z(fast_cells, reference_cells)
    print(
        f"fast vs reference: largest |mean difference| = {z:.2f} standard errors "
        f"(n={where.model.options}, k={where.model.pool})"
    )
    z_exact, where = max(
        (
            (abs(cell.summary.mean - mean) / standard_error(cell), cell)
            for cell, mean in zip(fast_cells, exact, strict=True)
            if standard_error(cell) > 0
        ),
        key=lambda pair: pair[0],
    )
    print(
        f"fast vs exact: largest |mean - exact mean| = {z_exact:.2f} standard errors "
        f"(n={where.model.options}, k={where.model.pool})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
