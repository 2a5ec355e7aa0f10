"""How much memory does ``swarm report`` take on a large recording?

Runs ``swarm report RECORDING --out DIR`` in a child process, of this checkout or of
another one (``--checkout``: e.g. a ``git worktree`` of the commit before a change), and
reads the child's peak resident memory from ``resource.getrusage(RUSAGE_CHILDREN)``
(the same number as ``/usr/bin/time -v``'s "Maximum resident set size"). Makes the
recording first if it is not there: ``swarm run --engine inprocess --robots 200
--record ...`` (seed 0, a few minutes of one core).

    .venv/bin/python benchmarks/report_memory.py /tmp/run200.mcap
    .venv/bin/python benchmarks/report_memory.py /tmp/run200.mcap --checkout /tmp/before

Prints one JSON line per measurement: the checkout, the recording's size, the peak
resident memory (MB) and the wall time. docs/recording.md quotes the numbers.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
LIMIT_MB = 500.0  # a 200-robot recording's report stays under this


def make_recording(path: Path, robots: int, seed: int) -> None:
    command = [
        str(REPO / ".venv" / "bin" / "swarm"),
        *("run", "--engine", "inprocess", "--quiet", "--json"),
        *("--robots", str(robots), "--sites", "10", "--seed", str(seed)),
        *("--record", str(path)),
    ]
    print("making", path, "with", " ".join(command[1:]), file=sys.stderr, flush=True)
    subprocess.run(command, check=False, stdout=subprocess.DEVNULL, cwd=REPO)
    if not path.is_file():
        raise SystemExit(f"no recording at {path}")


def measure(checkout: Path, recording: Path) -> dict[str, object]:
    """One ``swarm report`` of ``recording`` by ``checkout``'s code, in a fresh child."""
    with tempfile.TemporaryDirectory() as out:
        command = [
            str(REPO / ".venv" / "bin" / "python"),
            "-c",
            "import sys; sys.path.insert(0, sys.argv[1]); from deploy.cli import main; "
            "sys.exit(main(sys.argv[2:]))",
            str(checkout),
            *("report", str(recording), "--out", out, "--json"),
        ]
        # The peak of the largest child so far: this script starts only this one.
        started = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - started
        peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if done.returncode != 0:
        raise SystemExit(f"swarm report failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return {
        "checkout": str(checkout),
        "recording": str(recording),
        "recording_mb": round(recording.stat().st_size / 1e6, 1),
        "peak_rss_mb": round(peak_kb / 1024, 1),
        "wall_s": round(wall, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording", type=Path, help="an MCAP recording (made if missing)")
    parser.add_argument("--checkout", type=Path, default=REPO, help="whose code reports")
    parser.add_argument("--robots", type=int, default=200, help="robots, to make one")
    parser.add_argument("--seed", type=int, default=0, help="seed, to make one")
    args = parser.parse_args()
    if not args.recording.is_file():
        make_recording(args.recording, args.robots, args.seed)
    result = measure(args.checkout.resolve(), args.recording)
    result["under_limit"] = float(str(result["peak_rss_mb"])) < LIMIT_MB
    print(json.dumps(result))


if __name__ == "__main__":
    main()
