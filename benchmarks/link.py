"""What a link to a robot outside the emulator costs: its round trip, and the highest
control rate a robot sustains over it.

For each transport (UDP on loopback; a serial line at 115200 and at 921600 baud, a
pseudo-terminal pair made by ``socat``, paced at the baud rate as a UART would be) and each
swarm size, one lockstep run with the last robot outside, for ``--sim-seconds`` of sim
time, beside the all-emulated run of the same seed. In lockstep the world closes a tick
only when every robot has answered it, so the ticks per wall second of the run are the
control rate the slowest robot sustains: the outside one's, if its link is the bottleneck.
The bridge's pings give the link's round trip meanwhile (median and 95th percentile).

    .venv/bin/python benchmarks/link.py                          # 10 and 100 robots
    .venv/bin/python benchmarks/link.py --robots 10 --sim-seconds 30

The figures depend on the machine and its load; docs/performance.md gives those measured.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.link_runs import PtyPair, outside_run  # noqa: E402
from deploy.launcher.outside import free_udp_port  # noqa: E402

TRANSPORTS = ("none", "udp", "serial@115200", "serial@921600")
DT = 0.1  # sim seconds a tick


def emulated(options: Sequence[str]) -> dict[str, Any]:
    command = [sys.executable, "-m", "deploy.cli", "run", "--json", "--quiet", "--no-record"]
    done = subprocess.run([*command, *options], capture_output=True, cwd=REPO, timeout=7200)
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def measure(
    transport: str, robots: int, sites: int, seed: int, sim_seconds: float
) -> dict[str, Any]:
    options = ["--robots", str(robots), "--sites", str(sites), "--seed", str(seed)]
    options += ["--timeout", str(sim_seconds)]
    outside = robots - 1
    pty: PtyPair | None = None
    try:
        if transport == "none":
            summary = emulated(options)
        elif transport == "udp":
            address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
            summary, _ = outside_run(options, {outside: (address, address)})
        else:
            baud = int(transport.partition("@")[2])
            pty = PtyPair()
            served = f"{outside}=serial:{pty.bridge}@{baud}"
            summary, _ = outside_run(options, {outside: (served, f"serial:{pty.robot}@{baud}")})
    finally:
        if pty is not None:
            pty.close()
    link = summary.get("links", {}).get(str(outside), {})
    return {
        "transport": transport,
        "robots": robots,
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "ticks_per_second": round(summary["real_time_factor"] / DT, 1),
        "rtt_ms": link.get("rtt_ms"),
        "rtt_p95_ms": link.get("rtt_p95_ms"),
        "loss": link.get("loss"),
        "stalls": summary["world"]["stalls"],
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sim-seconds", type=float, default=60.0)
    parser.add_argument("--transports", nargs="+", default=list(TRANSPORTS), choices=TRANSPORTS)
    args = parser.parse_args(argv)
    rows = []
    for robots in args.robots:
        for transport in args.transports:
            row = measure(transport, robots, args.sites, args.seed, args.sim_seconds)
            rows.append(row)
            print(json.dumps(row), flush=True)
    print()
    print("| robots | the outside robot's link | ticks per wall second | rtt median / p95 (ms) |")
    print("|---:|---|---:|---|")
    for row in rows:
        link = "none (all emulated)" if row["transport"] == "none" else row["transport"]
        rtt = "-" if row["rtt_ms"] is None else f"{row['rtt_ms']:.2f} / {row['rtt_p95_ms']:.2f}"
        print(f"| {row['robots']} | {link} | {row['ticks_per_second']:.0f} | {rtt} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
