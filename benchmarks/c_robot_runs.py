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
import shutil
import signal
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

BINARY = REPO / "c_robot" / "build" / "c-robot"
IMPAIRED = ["--link-delay", "50", "--link-loss", "0.2"]
LOCKSTEP_STALL_TIMEOUT = 300.0  # wall seconds: a busy machine must not close ticks early


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


def outside_run(
    options: Sequence[str], outside: dict[int, tuple[str, str]], timeout: float = 7200
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """``swarm run`` with the robots of ``outside`` (robot -> (the run's --link, the
    program's --link)) run by the C program; the summary and each program's last line."""
    keys = Path(tempfile.mkdtemp(prefix="c-robot-keys-"))
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
            program = [str(BINARY), "--link", reach, "--id", str(robot)]
            program += ["--key-file", str(key_file), "--give-up", "120"]
            programs.append(
                subprocess.Popen(
                    program, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
                )
            )
        stdout, stderr = run.communicate(timeout=timeout)
        for started in programs:
            try:
                out, _ = started.communicate(timeout=30)
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
        self.directory = Path(tempfile.mkdtemp(prefix="c-robot-pty-"))
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
        summary, programs = outside_run(options, outside)
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
    summary, programs = outside_run(options, {8: (address, address), 9: (address, address)})
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


def seeds(text: str) -> list[int]:
    """``0-9``, ``1,3`` or ``0-4,7``; ``none`` for no seed."""
    if text == "none":
        return []
    chosen: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        chosen += range(int(first), int(last or first) + 1)
    return chosen


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
