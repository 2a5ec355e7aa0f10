"""How much memory does recording a large swarm take, with chunks that grow with the swarm
against the fixed 256 KiB chunks of before?

The MCAP writer keeps every chunk's index, an offset per channel in the chunk, until the
file is closed; a recording has channels per robot, so with small chunks a large swarm's
recorder grows with the run (``world_server/recording/writer.py``, ``chunk_bytes``).
This runs the same recorded in-process run twice in fresh children, once as it is and once
with the chunk size of before (256 KiB at any size), and reads each child's peak resident
memory from ``os.wait4`` (what ``/usr/bin/time -v`` calls "Maximum resident set
size"); and a third time without recording, for what the run
itself takes. Memory does not depend on the load; the wall times do.

    .venv/bin/python benchmarks/recorder_memory.py                      # 1000 robots, 200 sim s
    .venv/bin/python benchmarks/recorder_memory.py --robots 500 --sim-seconds 300

Prints one JSON line per run and, last, the recording's extra memory with grown chunks
as a share of that with fixed ones.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
CHILD = """
import sys
from world_server.recording import writer
if sys.argv[1] == "fixed":
    writer.chunk_bytes = lambda robots: writer.CHUNK_BYTES
from deploy.cli import main
sys.exit(main(sys.argv[2:]))
"""


def measure(mode: str, robots: int, sim_seconds: float, seed: int) -> dict[str, object]:
    """One recorded (or, for ``mode`` "none", unrecorded) run in a fresh child process."""
    with tempfile.TemporaryDirectory() as folder:
        recording = Path(folder) / "run.mcap"
        command = [
            sys.executable,
            *("-c", CHILD, mode),
            *("run", "--engine", "inprocess", "--quiet", "--json"),
            *("--robots", str(robots), "--sites", "10", "--seed", str(seed)),
            *("--timeout", str(sim_seconds)),
            *(("--record", str(recording)) if mode != "none" else ("--no-record",)),
        ]
        started = time.perf_counter()
        with open(Path(folder) / "out", "wb") as out, open(Path(folder) / "err", "wb") as err:
            child = subprocess.Popen(command, stdout=out, stderr=err, cwd=REPO)
            _, status, usage = os.wait4(child.pid, 0)  # this child's own peak
            child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - started
        size = recording.stat().st_size if recording.is_file() else 0
        if child.returncode not in (0, 5):  # 5: timed out before consensus, as intended
            errors = (Path(folder) / "err").read_text()[-2000:]
            raise SystemExit(f"swarm run failed ({child.returncode}):\n{errors}")
    return {
        "chunks": mode,
        "robots": robots,
        "sim_s": sim_seconds,
        "recording_mb": round(size / 1e6, 1),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "wall_s": round(wall, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000, help="swarm size (1000)")
    parser.add_argument("--sim-seconds", type=float, default=200.0, help="sim time (200)")
    parser.add_argument("--seed", type=int, default=0, help="seed (0)")
    args = parser.parse_args()
    with open("/proc/loadavg") as loadavg:
        print("load before:", loadavg.read().split()[0], file=sys.stderr)
    results = {
        mode: measure(mode, args.robots, args.sim_seconds, args.seed)
        for mode in ("none", "grown", "fixed")
    }
    for result in results.values():
        print(json.dumps(result), flush=True)
    base = float(str(results["none"]["peak_rss_mb"]))
    grown = float(str(results["grown"]["peak_rss_mb"])) - base
    fixed = float(str(results["fixed"]["peak_rss_mb"])) - base
    with open("/proc/loadavg") as loadavg:
        print("load after:", loadavg.read().split()[0], file=sys.stderr)
    print(
        f"recording's extra memory: {grown:.1f} MB with chunks grown with the swarm, "
        f"{fixed:.1f} MB with fixed 256 KiB chunks: {grown / fixed:.2f} of it"
    )


if __name__ == "__main__":
    main()
