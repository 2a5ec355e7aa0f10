"""How much memory does a run's time series take, from a recording and in process?

For each length of run (sim seconds), it records an in-process run of ``--robots`` robots
(``swarm run --engine inprocess --record``), then, each in a fresh child whose peak
resident memory is read from ``os.wait4`` (what ``/usr/bin/time -v`` calls "Maximum
resident set size"):

* ``swarm frame RUN.mcap --out F.csv``: the recording streamed to a file, a block of rows
  at a time;
* ``frame_of_recording(RUN.mcap)``: the recording read into a pandas DataFrame;
* the same run in process with a collector (``EngineHooks.frame``) and its DataFrame, and
  without one.

Streaming to a file should take the same memory whatever the length of the run; a
DataFrame takes what its rows take (about 100 bytes a row) on top. Memory does not depend
on the load; the wall times do.

    .venv/bin/python benchmarks/frame_memory.py            # 500 robots, 100 and 200 sim s
    .venv/bin/python benchmarks/frame_memory.py --robots 1000 --sim-seconds 100

Prints one JSON line per measurement.
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
MIB = 2**20

# In a child: read a recording into a DataFrame, and say its size.
FROM_RECORDING = """
import json, sys
from world_server.recording.frame import frame_of_recording
frame = frame_of_recording(sys.argv[1])
print(json.dumps({"rows": len(frame), "frame_mib": frame.memory_usage(deep=True).sum() / 2**20}))
"""

# In a child: the run in process, with a collector (sys.argv[1] == "frame") or without
# (pandas imported either way, so that the two differ by the rows alone).
IN_PROCESS = """
import json, sys
import pandas
from deploy.cli import build_parser
from deploy.inprocess import engine
from deploy.launcher.plan import plan_from_args
from world_server.observer.frame import FrameCollector
robots, sites, seed, timeout = (int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5])
arguments = ["run", "--engine", "inprocess", "--no-record", "--robots", str(robots),
             "--sites", str(sites), "--seed", str(seed), "--timeout", timeout]
plan = plan_from_args(build_parser(arguments).parse_args(arguments))
collector = FrameCollector.of_run(sites, robots, seed) if sys.argv[1] == "frame" else None
switches = plan.switches
hooks = engine.EngineHooks(config=plan.config, poses_every=switches.world.state_every,
                           frame=collector)
summary = engine.run_in_process(switches.world.world, switches.controller, switches.beacon,
                                timeout=plan.timeout, stall_window=plan.stall_window,
                                hooks=hooks)
found = {"digest": summary["digest"]}
if collector is not None:
    frame = collector.dataframe()
    found |= {"rows": len(frame), "frame_mib": frame.memory_usage(deep=True).sum() / 2**20}
print(json.dumps(found))
"""


def child(
    command: list[str], folder: Path, *, any_ending: bool = False
) -> tuple[float, float, str]:
    """Run a command in a fresh child: its peak resident memory (MiB), wall time, stdout.
    ``any_ending``: a run that ends at its time limit exits with that ending's code."""
    started = time.perf_counter()
    with open(folder / "out", "wb") as out, open(folder / "err", "wb") as err:
        process = subprocess.Popen(command, stdout=out, stderr=err, cwd=REPO)
        _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    if os.waitstatus_to_exitcode(status) != 0 and not any_ending:
        raise RuntimeError(f"{command[:4]}: {(folder / 'err').read_text()[-2000:]}")
    return usage.ru_maxrss / 1024, wall, (folder / "out").read_text()


def measure(robots: int, sites: int, seed: int, sim_seconds: float) -> list[dict[str, object]]:
    swarm = [sys.executable, "-m", "deploy.cli"]
    shape = ["--robots", str(robots), "--sites", str(sites), "--seed", str(seed)]
    found: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        recording = folder / "run.mcap"
        run = [*swarm, "run", "--engine", "inprocess", *shape, "--timeout", str(sim_seconds)]
        peak, wall, _ = child(
            [*run, "--record", str(recording), "--quiet", "--json"], folder, any_ending=True
        )
        common = {"robots": robots, "sim_seconds": sim_seconds}
        size = recording.stat().st_size / MIB
        found.append({**common, "what": "recorded run", "peak_mib": peak, "wall_s": wall,
                      "recording_mib": size})  # fmt: skip
        table = folder / "frame.csv"
        peak, wall, _ = child([*swarm, "frame", str(recording), "--out", str(table)], folder)
        found.append({**common, "what": "swarm frame to CSV", "peak_mib": peak, "wall_s": wall,
                      "recording_mib": size, "csv_mib": table.stat().st_size / MIB})  # fmt: skip
        peak, wall, out = child([sys.executable, "-c", FROM_RECORDING, str(recording)], folder)
        found.append({**common, "what": "frame_of_recording", "peak_mib": peak, "wall_s": wall,
                      **json.loads(out)})  # fmt: skip
        for mode in ("frame", "none"):
            arguments = [mode, str(robots), str(sites), str(seed), str(sim_seconds)]
            peak, wall, out = child([sys.executable, "-c", IN_PROCESS, *arguments], folder)
            what = "in process, collected" if mode == "frame" else "in process, bare"
            found.append({**common, "what": what, "peak_mib": peak, "wall_s": wall,
                          **json.loads(out)})  # fmt: skip
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=500)
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sim-seconds", type=float, nargs="+", default=[100.0, 200.0])
    args = parser.parse_args(argv)
    for sim_seconds in args.sim_seconds:
        for line in measure(args.robots, args.sites, args.seed, sim_seconds):
            print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
