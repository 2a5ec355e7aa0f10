"""A swarm's speed against another revision of this repository, in one run.

For each swarm size and seed it runs ``swarm run --engine inprocess`` (lockstep, no
recording; ``--engine zenoh``: ``swarm run`` with its processes over Zenoh, robots laid
out as ``swarm run`` does by default) with the working tree and with a baseline revision
checked out into a temporary worktree, alternating which goes first, ``--repeats`` times
each, and reports the wall time per tick of each (the run's own ``wall_time_s`` over its
ticks: start-up is left out; the fastest of the repeats, which is the least disturbed by
anything else), their ratio, the median over the seeds, and the real-time factors (sim
seconds per wall second) and their ratio. Per tick, because a change to the numeric
kernel changes how long a run lasts in sim time; ``--horizon`` caps every run at the same
sim time so both do similar work. The working tree runs with its compiled cores when they
are built (``make cores``); the baseline as it was.

    .venv/bin/python benchmarks/engine_speed.py --baseline 00d94b4 --robots 10 100 \
        --seeds 0 1 2 3 4 --horizon 200
    .venv/bin/python benchmarks/engine_speed.py --baseline 7630779 --engine zenoh \
        --robots 10 100 --seeds 0 1 --repeats 2 --horizon 200

Check ``cat /proc/loadavg`` before and after: on a busy machine the figures mean little.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent


def run_once(tree: Path, robots: int, seed: int, horizon: float, engine: str) -> dict[str, Any]:
    """One run from ``tree``'s code; its summary."""
    environment = dict(os.environ, PYTHONPATH=str(tree))
    command = [sys.executable, "-m", "deploy.cli", "run"]
    if engine == "inprocess":
        command += ["--engine", "inprocess"]
    command += ["--robots", str(robots), "--seed", str(seed), "--timeout", str(horizon)]
    command += ["--no-record", "--json", "--quiet"]
    done = subprocess.run(
        command, cwd=tree, env=environment, capture_output=True, text=True, check=False
    )
    if not done.stdout.strip():
        raise SystemExit(f"engine_speed: {' '.join(command)} in {tree} failed:\n{done.stderr}")
    summary: dict[str, Any] = json.loads(done.stdout)
    return summary


def per_tick_ms(summary: dict[str, Any]) -> float:
    ticks = max(1.0, summary["sim_time_s"] / summary["config"]["dt"])
    return 1000.0 * summary["wall_time_s"] / ticks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", required=True, help="git revision to compare with")
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--horizon", type=float, default=200.0, help="sim seconds at most")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each seed and tree")
    parser.add_argument(
        "--engine",
        choices=["inprocess", "zenoh"],
        default="inprocess",
        help="inprocess (default), or zenoh: swarm run's processes over Zenoh",
    )
    args = parser.parse_args(argv)
    print(f"load average before: {Path('/proc/loadavg').read_text().split()[:3]}")
    with tempfile.TemporaryDirectory(prefix="engine-speed-") as scratch:
        baseline = Path(scratch) / "baseline"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(baseline), args.baseline],
            check=True,
            capture_output=True,
        )
        try:
            print(f"engine: {args.engine}")
            print(
                "| robots | seeds | baseline ms/tick | working tree ms/tick | ratio "
                "| baseline RTF | working tree RTF | RTF ratio |"
            )
            print("|---:|---:|---:|---:|---:|---:|---:|---:|")
            for robots in args.robots:
                old: list[float] = []
                new: list[float] = []
                for seed in args.seeds:
                    fastest = {baseline: float("inf"), REPO: float("inf")}
                    for repeat in range(args.repeats):
                        order = [baseline, REPO] if repeat % 2 == 0 else [REPO, baseline]
                        for tree in order:
                            summary = run_once(tree, robots, seed, args.horizon, args.engine)
                            fastest[tree] = min(fastest[tree], per_tick_ms(summary))
                    old.append(fastest[baseline])
                    new.append(fastest[REPO])
                old_ms, new_ms = statistics.median(old), statistics.median(new)
                # Sim seconds per wall second: a tick is dt = 0.1 sim s.
                old_rtf, new_rtf = 100.0 / old_ms, 100.0 / new_ms
                print(
                    f"| {robots} | {len(args.seeds)} | {old_ms:.3f} | {new_ms:.3f} "
                    f"| {new_ms / old_ms:.3f} | {old_rtf:.1f} | {new_rtf:.1f} "
                    f"| {new_rtf / old_rtf:.2f} |",
                    flush=True,
                )
        finally:
            subprocess.run(
                ["git", "-C", str(REPO), "worktree", "remove", "--force", str(baseline)],
                check=False,
                capture_output=True,
            )
    print(f"load average after: {Path('/proc/loadavg').read_text().split()[:3]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
