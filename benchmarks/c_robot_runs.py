"""Whole runs with the robot in C (c_robot/) outside the emulator: the full counts.

* lockstep over UDP: for each of ``--seeds``, 10 robots with robots 8 and 9 run by the C
  program (``c_robot/build/c-robot``), against the all-emulated run of the seed (the
  in-process engine): are the digest and every robot's decided site, steps, decision time
  and pool sizes the same?
* lockstep over a serial line: for each of ``--serial-seeds``, robot 9 alone in C over a
  pseudo-terminal pair made by ``socat``;
* real time: for each of ``--realtime-seeds``, 10 robots at ``--speed`` (1: the wall clock)
  with robots 8 and 9 in C on a link made worse on purpose (``--link-delay 50 --link-loss
  0.2``): how many reach the right consensus with the C robots taking part.

    make -C c_robot
    .venv/bin/python benchmarks/c_robot_runs.py                     # the full counts
    .venv/bin/python benchmarks/c_robot_runs.py --seeds 0-1 --serial-seeds 0 --realtime-seeds 0

It prints one JSON line per run as it ends, then a table with the command and
``cat /proc/loadavg`` before and after. Every process is stopped by pid when its run ends.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import shlex
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.link_runs import (  # noqa: E402
    IMPAIRED,
    LOCKSTEP_STALL_TIMEOUT,
    PtyPair,
    decisions,
    in_process,
    outside_run,
    seeds,
)
from deploy.launcher.outside import free_udp_port  # noqa: E402

BINARY = REPO / "c_robot" / "build" / "c-robot"


def lockstep(seed: int, serial: bool) -> dict[str, Any]:
    options = ["--robots", "10", "--seed", str(seed), "--timeout", "3000"]
    options += ["--stall-timeout", str(LOCKSTEP_STALL_TIMEOUT)]
    reference = in_process(options)
    pty = PtyPair() if serial else None
    try:
        if pty is not None:
            outside = {9: (f"9=serial:{pty.bridge}@921600", f"serial:{pty.robot}@921600")}
        else:
            address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
            outside = {8: (address, address), 9: (address, address)}
        summary, programs = outside_run(options, outside, program=[str(BINARY)])
    finally:
        if pty is not None:
            pty.close()
    return {
        "kind": "lockstep",
        "seed": seed,
        "transport": "serial" if serial else "udp",
        "outside": sorted(outside),
        "same": decisions(summary) == decisions(reference)
        and summary["digest"] == reference["digest"],
        "digest": summary["digest"],
        "reference_digest": reference["digest"],
        "ended": summary["ended"],
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "departures": summary["world"]["departures"],
        "stalls": summary["world"]["stalls"],
        "refused": [item["refused"] for item in summary.get("links", {}).values()],
        "programs": programs,
    }


def realtime(seed: int, speed: float) -> dict[str, Any]:
    options = ["--robots", "10", "--seed", str(seed), "--clock", "realtime"]
    options += ["--speed", str(speed), "--timeout", "1200", *IMPAIRED]
    address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
    served = {8: (address, address), 9: (address, address)}
    summary, programs = outside_run(options, served, program=[str(BINARY)])
    links = summary.get("links", {})
    outside = [r for r in summary["per_robot"] if r["outside"]]
    return {
        "kind": "realtime",
        "seed": seed,
        "speed": speed,
        "ended": summary["ended"],
        "correct": summary["correct"],
        "c_robots_decided": [r["decided_site"] for r in outside],
        "best_site": summary["best_site"],
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "rtt_ms": [item["rtt_ms"] for item in links.values()],
        "loss": [item["loss"] for item in links.values()],
        "sessions": [item["sessions"] for item in links.values()],
        "departures": summary["world"]["departures"],
        "programs": programs,
    }


def loadavg() -> str:
    try:
        return Path("/proc/loadavg").read_text().strip()
    except OSError:
        return "(no /proc/loadavg)"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=seeds, default=seeds("0-9"), help="lockstep, UDP")
    parser.add_argument("--serial-seeds", type=seeds, default=seeds("0-2"))
    parser.add_argument("--realtime-seeds", type=seeds, default=seeds("0-9"))
    parser.add_argument("--speed", type=float, default=1.0)
    parser.add_argument("--parallel", type=int, default=1, help="real-time runs at once")
    parser.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    if not BINARY.exists():
        subprocess.run(["make", "-C", str(REPO / "c_robot")], check=True)
    command = shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])
    before = loadavg()
    rows: list[dict[str, Any]] = []

    def keep(job: Any, *params: Any) -> None:
        try:
            row = job(*params)
        except (RuntimeError, subprocess.SubprocessError, json.JSONDecodeError) as error:
            row = {"kind": job.__name__, "params": params, "error": str(error)[-500:]}
        rows.append(row)
        print(json.dumps(row), flush=True)

    # lockstep runs one at a time: two at once on 2 cores slow both and change nothing
    for seed in args.seeds:
        keep(lockstep, seed, False)
    for seed in args.serial_seeds:
        keep(lockstep, seed, True)
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.parallel) as pool:
        list(pool.map(lambda seed: keep(realtime, seed, args.speed), args.realtime_seeds))
    after = loadavg()
    report(rows, command, before, after, args.speed)
    if args.out is not None:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


def report(rows: list[dict[str, Any]], command: str, before: str, after: str, speed: float) -> None:
    print()
    print(f"command: {command}")
    print(f"load average before: {before}")
    print(f"load average after:  {after}")
    print()
    print("| runs | C robots | seeds | result |")
    print("|---|---|---|---|")
    for transport, outside in (("udp", "8, 9 over UDP"), ("serial", "9 over a serial line")):
        chosen = sorted(
            (r for r in rows if r.get("kind") == "lockstep" and r.get("transport") == transport),
            key=lambda r: r["seed"],
        )
        if chosen:
            same = [r["seed"] for r in chosen if r["same"]]
            print(
                f"| lockstep, {len(chosen)} | {outside} | {[r['seed'] for r in chosen]} | "
                f"{len(same)} of {len(chosen)} the same run bit for bit as all emulated "
                f"(digest and per-robot results) |"
            )
    real = sorted((r for r in rows if r.get("kind") == "realtime"), key=lambda r: r["seed"])
    if real:
        correct = sum(1 for r in real if r["correct"])
        c_right = sum(
            1
            for r in real
            if r["correct"] and all(d == r["best_site"] for d in r["c_robots_decided"])
        )
        rtts = sorted(v for r in real for v in r["rtt_ms"] if v is not None)
        losses = sorted(v for r in real for v in r["loss"])
        rtt = rtts[len(rtts) // 2] if rtts else float("nan")
        loss = losses[len(losses) // 2] if losses else float("nan")
        print(
            f"| real time x{speed:g}, {len(real)} | 8, 9 over UDP, 50 ms + 20% loss each way | "
            f"{[r['seed'] for r in real]} | {correct} of {len(real)} right consensus "
            f"({c_right} with both C robots on the best site); rtt median {rtt:.1f} ms, "
            f"ping loss median {loss:.2f} |"
        )
    failed = [r for r in rows if "error" in r]
    if failed:
        print(f"\n{len(failed)} run(s) failed: " + "; ".join(r["error"][-200:] for r in failed))


if __name__ == "__main__":
    sys.exit(main())
