"""How late robots answer in real time: one process per robot against all robots in one.

In ``--clock realtime`` the world does not wait: it steps every ``dt / speed`` of wall
time and applies each robot's latest command, so a robot that answers late drives on an
old reading. This runs the same real-time swarm twice, recorded, once with every robot its
own process (the default up to 25 robots) and once with all of them hosted in one process
(``--robots-per-process N``), and reads from each recording how long after a robot's
Sense its Act arrived (both as the recorder received them, so the path through the router
is counted). It prints the percentiles of that delay in milliseconds and in ticks, the sim
time the run took to agree, and the CPU time the hypervisor took from this machine while it
ran (``steal`` in /proc/stat: on a shared VM it can be a third of both cores):

    .venv/bin/python benchmarks/realtime_lag.py
    .venv/bin/python benchmarks/realtime_lag.py --robots 10 --seed 2 --speed 10 --repeat 2

Runs are sequential, so the two layouts share the machine's state of the moment; real-time
runs are not reproducible, so compare the layouts within one invocation.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bestofn_swarm.link.core.pacing import percentile  # noqa: E402
from bestofn_swarm.wire import protocol  # noqa: E402
from world_server.recording.reader import RecordingReader  # noqa: E402

PERCENTILES = (50, 90, 99)


def answer_delays(recording: Path) -> list[float]:
    """Seconds from each robot's Sense to its Act for that tick, as the recorder got them."""
    sensed: dict[tuple[str, int], int] = {}
    delays: list[float] = []
    for message in RecordingReader(recording):
        if message.schema == "bestofn.Sense":
            robot = message.topic.split("/")[-2]
            sensed[(robot, protocol.decode(message.data, protocol.Sense).tick)] = (
                message.publish_time
            )
        elif message.schema == "bestofn.Act":
            robot = message.topic.split("/")[-2]
            sent = sensed.pop((robot, protocol.decode(message.data, protocol.Act).tick), None)
            if sent is not None:
                delays.append((message.publish_time - sent) / 1e9)
    return delays


def cpu_times() -> tuple[float, float]:
    """(all CPU time, stolen CPU time) of this machine so far, in clock ticks."""
    fields = [float(value) for value in Path("/proc/stat").read_text().split()[1:9]]
    return sum(fields), fields[7]


def run(options: list[str], recording: Path) -> tuple[dict[str, object], float]:
    """One recorded run: its summary and the share of CPU time stolen while it ran."""
    command = [sys.executable, "-m", "deploy.cli", "run", "--json", "--quiet", *options]
    command += ["--record", str(recording)]
    total_before, stolen_before = cpu_times()
    done = subprocess.run(command, capture_output=True, text=True, cwd=REPO, timeout=3600)
    total_after, stolen_after = cpu_times()
    if done.returncode != 0 and not done.stdout.strip():
        raise SystemExit(f"realtime_lag.py: swarm run failed: {done.stderr.strip()[-2000:]}")
    steal = (stolen_after - stolen_before) / max(total_after - total_before, 1.0)
    return dict(json.loads(done.stdout)), steal


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--sites", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--speed", type=float, default=10.0)
    parser.add_argument("--timeout", type=float, default=1800.0, help="sim seconds per run")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each layout")
    args = parser.parse_args()
    shape = ["--robots", str(args.robots), "--sites", str(args.sites), "--seed", str(args.seed)]
    shape += ["--clock", "realtime", "--speed", str(args.speed), "--timeout", str(args.timeout)]
    layouts = {
        "a process per robot": ["--robots-per-process", "1"],
        f"{args.robots} robots in one process": ["--robots-per-process", str(args.robots)],
    }
    tick_ms = 100.0 / args.speed  # dt = 0.1 s of sim time
    print(
        f"{args.robots} robots, {args.sites} sites, seed {args.seed}, real time at "
        f"{args.speed:g}x (a tick every {tick_ms:g} ms of wall time)"
    )
    header = "layout | run | sense->act ms p50 / p90 / p99 (ticks at p90) | sim s | ended | steal"
    print(header)
    print("-" * len(header))
    medians: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as folder:
        for attempt in range(args.repeat):
            for index, (name, layout) in enumerate(layouts.items()):
                recording = Path(folder) / f"{attempt}-{index}.mcap"
                started = time.monotonic()
                summary, steal = run([*shape, *layout], recording)
                delays = answer_delays(recording)
                recording.unlink()
                if not delays:
                    print(f"{name} | {attempt + 1} | no answers recorded", flush=True)
                    continue
                ms = [(percentile(delays, share / 100) or 0.0) * 1000 for share in PERCENTILES]
                medians.setdefault(name, []).append(ms[1])
                print(
                    f"{name} | {attempt + 1} | {ms[0]:.1f} / {ms[1]:.1f} / {ms[2]:.1f} "
                    f"({ms[1] / tick_ms:.1f}) | {summary['sim_time_s']} | {summary['ended']} | "
                    f"{steal:.0%} ({time.monotonic() - started:.0f} s wall)",
                    flush=True,
                )
    names = list(layouts)
    if all(medians.get(name) for name in names):
        one, hosted = (sum(medians[name]) / len(medians[name]) for name in names)
        print(f"p90 delay, a process per robot / hosted: {one / hosted:.1f}x")


if __name__ == "__main__":
    main()
