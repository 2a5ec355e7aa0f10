"""Whole runs with robots outside the emulator (hardware in the loop), as an experiment.

* ``--lockstep``: the same run bit for bit. For each seed, 10 robots with robots 8 and 9
  outside over UDP (and, with ``--serial-seeds``, robot 9 alone over a serial line: a
  pseudo-terminal pair made by ``socat``), against the all-emulated run of the seed (the
  in-process engine, which gives the same per-robot results as ``swarm run``). Reports,
  per seed, whether decided site, steps, decision time and pool sizes all agree.
* ``--realtime``: mixed real-time swarms, 8 emulated + 2 outside, at each ``--speeds``, on
  a clean link and on one made worse on purpose (``--link-delay 50 --link-loss 0.2``):
  how many of the seeds reach the right consensus, their sim and wall times, and the
  links' measured round trip and loss.

    .venv/bin/python benchmarks/link_runs.py --lockstep --seeds 0-9 --serial-seeds 0 1 2
    .venv/bin/python benchmarks/link_runs.py --realtime --seeds 0-9 --speeds 1 2 --parallel 3
    .venv/bin/python benchmarks/link_runs.py --realtime --seeds 1,3 --speeds 1 --links clean

Every process is stopped by pid when its run ends; runs are independent, so ``--parallel``
runs several at once (real-time runs mostly wait on their clock).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.launcher.outside import free_udp_port  # noqa: E402

IMPAIRED = ["--link-delay", "50", "--link-loss", "0.2"]
LOCKSTEP_STALL_TIMEOUT = 300.0  # wall seconds (docs/scale.md does the same on a busy machine)


def decisions(summary: dict[str, Any]) -> list[tuple[object, ...]]:
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


def in_process(options: Sequence[str]) -> dict[str, Any]:
    command = [sys.executable, "-m", "deploy.cli", "run", "--engine", "inprocess"]
    done = subprocess.run(
        [*command, "--json", "--quiet", "--no-record", *options],
        capture_output=True,
        cwd=REPO,
        timeout=3600,
    )
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def stop(processes: Sequence[subprocess.Popen[bytes]]) -> None:
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


# The link robot program: ``robot-agent --link``'s, or another that takes its options (the
# robot in C, benchmarks/c_robot_runs.py).
PYTHON_PROGRAM = (sys.executable, "-m", "robot_agent.link")


def outside_run(
    options: Sequence[str],
    outside: dict[int, tuple[str, str]],
    timeout: float = 7200,
    program: Sequence[str] = PYTHON_PROGRAM,
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """``swarm run`` with the robots of ``outside`` (robot -> (the run's --link, the
    program's --link)) run by ``program``, each started once its key file is written; the
    summary and each program's last line (``{}`` if it wrote none)."""
    keys = Path(tempfile.mkdtemp(prefix="link-keys-"))
    links = []
    shared = {served for served, _ in outside.values() if "=" not in served}
    for served in shared:
        links += ["--link", served]
    links += [arg for served, _ in outside.values() if "=" in served for arg in ("--link", served)]
    command = [
        *(sys.executable, "-m", "deploy.cli", "run", "--json", "--quiet", "--no-record"),
        *options,
        *("--external", ",".join(map(str, sorted(outside))), *links),
        *("--link-keys", str(keys)),
    ]
    run = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    programs: list[subprocess.Popen[bytes]] = []
    lines: list[dict[str, Any]] = []
    try:
        for robot, (_, reach) in sorted(outside.items()):
            key_file = keys / f"robot-{robot}.key"
            deadline = time.monotonic() + 120
            while not key_file.exists() and time.monotonic() < deadline:
                time.sleep(0.05)
            started = [*program, "--link", reach, "--id", str(robot)]
            started += ["--key-file", str(key_file), "--give-up", "120"]
            programs.append(
                subprocess.Popen(
                    started, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
                )
            )
        stdout, stderr = run.communicate(timeout=timeout)
        for finished in programs:
            try:
                out, _ = finished.communicate(timeout=30)
                text = out.decode().strip().splitlines()
                lines.append(json.loads(text[-1]) if text else {})
            except (subprocess.TimeoutExpired, json.JSONDecodeError):
                lines.append({})
    finally:
        stop([run, *programs])
        shutil.rmtree(keys, ignore_errors=True)
    if not stdout.strip():
        raise RuntimeError(f"swarm run {options} failed: {stderr.decode()[-2000:]}")
    summary: dict[str, Any] = json.loads(stdout)
    return summary, lines


class PtyPair:
    """Two pseudo-terminals joined by socat: the bridge's end and the robot's."""

    def __init__(self) -> None:
        socat = shutil.which("socat")
        if socat is None:
            raise SystemExit("socat is not installed (apt-get install socat)")
        self.directory = Path(tempfile.mkdtemp(prefix="link-pty-"))
        self.bridge, self.robot = self.directory / "bridge", self.directory / "robot"
        self.process = subprocess.Popen(
            [socat, f"pty,raw,echo=0,link={self.bridge}", f"pty,raw,echo=0,link={self.robot}"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + 10
        while not (self.bridge.exists() and self.robot.exists()) and time.monotonic() < deadline:
            time.sleep(0.05)

    def close(self) -> None:
        stop([self.process])
        shutil.rmtree(self.directory, ignore_errors=True)


def lockstep(seed: int, robots: int, sites: int, serial: bool) -> dict[str, Any]:
    options = ["--robots", str(robots), "--sites", str(sites), "--seed", str(seed)]
    # A world that waits long for a robot starved by a busy machine stays in lockstep (a
    # stall closes a tick without a robot: no longer the seed's run, whatever the link).
    options += ["--timeout", "3000", "--stall-timeout", str(LOCKSTEP_STALL_TIMEOUT)]
    reference = in_process(options)
    pty = PtyPair() if serial else None
    try:
        if pty is not None:
            outside = {robots - 1: (f"{robots - 1}=serial:{pty.bridge}@921600",
                                    f"serial:{pty.robot}@921600")}  # fmt: skip
        else:
            address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
            outside = {robots - 2: (address, address), robots - 1: (address, address)}
        summary, _ = outside_run(options, outside)
    finally:
        if pty is not None:
            pty.close()
    return {
        "seed": seed,
        "transport": "serial" if serial else "udp",
        "outside": sorted(outside),
        "same": decisions(summary) == decisions(reference),
        "sim_time_s": summary["sim_time_s"],
        "reference_sim_time_s": reference["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "departures": summary["world"]["departures"],
        "stalls": summary["world"]["stalls"],
        "links": summary.get("links", {}),
    }


def realtime(seed: int, robots: int, sites: int, speed: float, impaired: bool) -> dict[str, Any]:
    options = ["--robots", str(robots), "--sites", str(sites), "--seed", str(seed)]
    options += ["--clock", "realtime", "--speed", str(speed), "--timeout", "1200"]
    if impaired:
        options += IMPAIRED
    address = f"udp://127.0.0.1:{free_udp_port('127.0.0.1')}"
    outside = {robots - 2: (address, address), robots - 1: (address, address)}
    summary, _ = outside_run(options, outside)
    links = summary.get("links", {})
    return {
        "seed": seed,
        "speed": speed,
        "impaired": impaired,
        "ended": summary["ended"],
        "correct": summary["correct"],
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "rtt_ms": [item["rtt_ms"] for item in links.values()],
        "rtt_p95_ms": [item["rtt_p95_ms"] for item in links.values()],
        "loss": [item["loss"] for item in links.values()],
        "sessions": [item["sessions"] for item in links.values()],  # more than 1: reconnected
        "departures": summary["world"]["departures"],
        "stalls": summary["world"]["stalls"],
    }


def seeds(text: str) -> list[int]:
    """``0-9``, ``1,3`` or ``0-4,7``; ``none`` for no seed."""
    if text == "none":
        return []
    chosen: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        chosen += range(int(first), int(last or first) + 1)
    return chosen


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lockstep", action="store_true")
    parser.add_argument("--realtime", action="store_true")
    parser.add_argument("--seeds", type=seeds, default=[0])
    parser.add_argument("--serial-seeds", type=int, nargs="*", default=[])
    parser.add_argument("--speeds", type=float, nargs="+", default=[1.0, 2.0])
    parser.add_argument(
        "--links",
        nargs="+",
        choices=("clean", "impaired"),
        default=["clean", "impaired"],
        help="real time: on a clean link, on one made worse on purpose, or both",
    )
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--parallel", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    jobs: list[tuple[str, tuple[Any, ...]]] = []
    if args.lockstep:
        jobs += [("lockstep", (seed, args.robots, args.sites, False)) for seed in args.seeds]
        jobs += [("lockstep", (seed, args.robots, args.sites, True)) for seed in args.serial_seeds]
    if args.realtime:
        jobs += [
            ("realtime", (seed, args.robots, args.sites, speed, impaired))
            for impaired in (link == "impaired" for link in args.links)
            for speed in args.speeds
            for seed in args.seeds
        ]
    rows: list[dict[str, Any]] = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.parallel) as pool:
        futures = {
            pool.submit(lockstep if kind == "lockstep" else realtime, *params): kind
            for kind, params in jobs
        }
        for future in concurrent.futures.as_completed(futures):
            try:
                row = {"kind": futures[future], **future.result()}
            except (RuntimeError, subprocess.SubprocessError, json.JSONDecodeError) as error:
                # One run that failed is a row of its own: the others still count.
                row = {"kind": futures[future], "error": str(error)[-500:]}
            rows.append(row)
            print(json.dumps(row), flush=True)
    report(rows)
    if args.out is not None:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


def report(rows: list[dict[str, Any]]) -> None:
    failed = [row for row in rows if "error" in row]
    if failed:
        print(f"{len(failed)} run(s) failed: " + "; ".join(row["error"][-200:] for row in failed))
    rows = [row for row in rows if "error" not in row]
    lock = [row for row in rows if row["kind"] == "lockstep"]
    for transport in ("udp", "serial"):
        chosen = sorted((r for r in lock if r["transport"] == transport), key=lambda r: r["seed"])
        if chosen:
            same = [r["seed"] for r in chosen if r["same"]]
            stalled = [r["seed"] for r in chosen if r["stalls"]]
            print(
                f"lockstep over {transport}: {len(same)} of {len(chosen)} seeds the same run "
                f"bit for bit (seeds {[r['seed'] for r in chosen]}; with lockstep stalls: "
                f"{stalled})"
            )
    real = [row for row in rows if row["kind"] == "realtime"]
    groups = sorted({(row["speed"], row["impaired"]) for row in real})
    for speed, impaired in groups:
        chosen = [r for r in real if (r["speed"], r["impaired"]) == (speed, impaired)]
        rtts = [value for r in chosen for value in r["rtt_ms"] if value is not None]
        losses = [value for r in chosen for value in r["loss"]]
        link = "50 ms + 20% loss" if impaired else "clean link"
        print(
            f"real time x{speed:g}, {link}: {sum(r['correct'] for r in chosen)} of "
            f"{len(chosen)} right consensus; sim time median "
            f"{statistics.median(r['sim_time_s'] for r in chosen):.1f} s; rtt median "
            f"{statistics.median(rtts) if rtts else float('nan'):.1f} ms; loss median "
            f"{statistics.median(losses) if losses else float('nan'):.2f}"
        )


if __name__ == "__main__":
    sys.exit(main())
