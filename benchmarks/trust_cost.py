"""What trusting a run costs: run keys, secure mode and the private Unix socket.

Runs the same seeds of `swarm run` (lockstep, not recorded) three ways, interleaved so
that a busy machine slows each way alike, and reports real-time factors and their
ratios to the unkeyed run:

* ``--no-keys``: no tags, every message believed (as before run keys);
* the default: every message tagged and checked with run keys (bestofn_swarm/wire/auth.py),
  the router on a Unix socket in a private directory;
* ``--secure``: run keys, and TLS on loopback with a certificate per process and the
  access control (deploy/security/credentials.py).

It checks that the three give the same per-robot results (lockstep is deterministic;
keys must not change a decision). Then the transport: the same seeds (keyed) through a
router process on loopback TCP and one on a Unix socket (``--connect``, so only the
transport differs), the bare lockstep exchange (benchmarks/swarm_speed.py's floor) over
each, and what one tag costs in this process.

    .venv/bin/python benchmarks/trust_cost.py                      # 10 and 100 robots
    .venv/bin/python benchmarks/trust_cost.py --robots 10 --seeds 0 1 2 --repeat 2
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.swarm_speed import messaging_floor  # noqa: E402
from bestofn_swarm.plumbing.tcp import free_port  # noqa: E402
from bestofn_swarm.wire import auth, protocol  # noqa: E402

MODES = {"unkeyed": ["--no-keys"], "keyed": [], "secure": ["--secure"]}


def swarm_run(robots: int, seed: int, sites: int, options: list[str]) -> dict[str, Any]:
    command = [
        *(sys.executable, "-m", "deploy.cli", "run"),
        *("--robots", str(robots), "--sites", str(sites), "--seed", str(seed)),
        *("--json", "--quiet", "--no-record", *options),
    ]
    done = subprocess.run(command, capture_output=True, cwd=REPO, timeout=7200)
    if done.returncode != 0:
        raise RuntimeError(f"swarm run {options} failed: {done.stderr.decode()[-2000:]}")
    return json.loads(done.stdout)


def decisions(summary: dict[str, Any]) -> list[tuple[object, ...]]:
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


def runs(args: argparse.Namespace) -> None:
    print("Real-time factor (sim s / wall s, lockstep, not recorded), same seeds:")
    print(f"{'robots':>6} {'mode':>8} {'RTF':>8} {'/unkeyed':>9} {'runs':>5}  same results")
    for robots in args.robots:
        factors: dict[str, list[float]] = {mode: [] for mode in MODES}
        ratios: dict[str, list[float]] = {mode: [] for mode in MODES}
        same = True
        timeout = ["--timeout", str(args.sim_timeout)] if robots > 50 else []
        for seed in args.seeds:
            for _ in range(args.repeat):
                results = {
                    mode: swarm_run(robots, seed, args.sites, [*extra, *timeout])
                    for mode, extra in MODES.items()
                }
                base = float(results["unkeyed"]["real_time_factor"])
                for mode, summary in results.items():
                    factor = float(summary["real_time_factor"])
                    factors[mode].append(factor)
                    ratios[mode].append(factor / base)
                    same &= decisions(summary) == decisions(results["unkeyed"])
        for mode in MODES:
            print(
                f"{robots:>6} {mode:>8} {statistics.fmean(factors[mode]):>7.1f}x "
                f"{statistics.fmean(ratios[mode]):>9.2f} {len(factors[mode]):>5}  "
                f"{'yes' if same else 'NO'}",
                flush=True,
            )


def transport(args: argparse.Namespace) -> None:
    folder = Path(tempfile.mkdtemp(prefix="bestofn-"))
    endpoints = {
        "tcp": f"tcp/127.0.0.1:{free_port()}",
        "unix": f"unixsock-stream/{folder / 'router.sock'}",
    }
    routers = [
        subprocess.Popen(
            [sys.executable, "-m", "deploy.launcher.router", "--listen", endpoint], cwd=REPO
        )
        for endpoint in endpoints.values()
    ]
    try:
        time.sleep(3.0)
        print("\nThe same runs through a router process on each transport (--connect):")
        for robots in args.robots:
            timeout = ["--timeout", str(args.sim_timeout)] if robots > 50 else []
            factors: dict[str, list[float]] = {name: [] for name in endpoints}
            for seed in args.seeds:
                for _ in range(args.repeat):
                    for name, endpoint in endpoints.items():
                        summary = swarm_run(
                            robots, seed, args.sites, ["--connect", endpoint, *timeout]
                        )
                        factors[name].append(float(summary["real_time_factor"]))
            tcp, unix = statistics.fmean(factors["tcp"]), statistics.fmean(factors["unix"])
            print(
                f"{robots:>6} robots: tcp loopback {tcp:>6.1f}x, unix socket {unix:>6.1f}x "
                f"({unix / tcp:.2f} of tcp)",
                flush=True,
            )
    finally:
        for router in routers:
            router.terminate()
            router.wait(timeout=10)
    print("\nBare lockstep exchange (no tags), ticks per second through the router:")
    try:
        for robots in args.robots:
            tcp_rates: list[float] = []
            unix_rates: list[float] = []
            for _ in range(args.repeat):
                tcp_rates.append(messaging_floor(robots, args.floor_ticks))
                unix_rates.append(
                    messaging_floor(
                        robots, args.floor_ticks, f"unixsock-stream/{folder / 'floor.sock'}"
                    )
                )
            over_tcp, over_unix = statistics.fmean(tcp_rates), statistics.fmean(unix_rates)
            print(
                f"{robots:>6} robots: tcp loopback {over_tcp:>7.0f}/s, unix socket "
                f"{over_unix:>7.0f}/s ({over_unix / over_tcp:.2f} of tcp)",
                flush=True,
            )
            time.sleep(0.5)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def one_tag() -> None:
    keyring = auth.Keyring(secret=bytes(32))
    robot = keyring.only(["robot/3"])
    key = "bestofn/run/robot/3/sense"
    sense = protocol.encode(
        protocol.Sense(
            v=1, tick=42, t=4.2, x=0.31, y=-0.12, theta=1.5708, prox=[0.0] * 8, rx=0, camera=False
        )
    )
    attachment = keyring.seal("robot/3", key, sense)
    number = 20000
    seal = timeit.timeit(lambda: keyring.seal("robot/3", key, sense), number=number) / number
    check = timeit.timeit(lambda: robot.open("robot/3", key, sense, attachment), number=number)
    print(
        f"\nOne tag of a {len(sense)}-byte Sense in this process: {seal * 1e6:.1f} us to make, "
        f"{check / number * 1e6:.1f} us to check"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--repeat", type=int, default=1, help="rounds of the three modes per seed")
    parser.add_argument(
        "--sim-timeout",
        type=float,
        default=120.0,
        help="sim seconds per run beyond 50 robots (their runs to consensus are long)",
    )
    parser.add_argument("--floor-ticks", type=int, default=300)
    parser.add_argument("--no-transport", action="store_true", help="skip the bare exchange")
    args = parser.parse_args()
    runs(args)
    if not args.no_transport:
        transport(args)
    one_tag()


if __name__ == "__main__":
    main()
