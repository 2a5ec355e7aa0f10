"""How fast does a lockstep swarm run? Real-time factor and wall time, to consensus.

For each swarm size it runs `swarm run --json` to consensus and reports the real-time
factor (sim seconds per wall second while ticking), the wall time of the run, and the
time to start. As a baseline measured in the same run, it times the bare lockstep
exchange of the same number of processes over Zenoh (sense out, act back, no physics,
no controller): the floor our own code sits on, so the ratio says what the swarm's
logic costs on top of the messaging.

    .venv/bin/python benchmarks/swarm_speed.py                 # 10, 50 and 100 robots
    .venv/bin/python benchmarks/swarm_speed.py --robots 10 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.processes import free_port  # noqa: E402
from robot_agent.zenoh_session import open_session, reliable_publisher  # noqa: E402

TARGETS = {10: 50.0, 50: 10.0, 100: 2.0, 200: 3.0, 500: 1.0}

ECHO_ROBOT = """
import sys, time
from robot_agent.zenoh_session import open_session, reliable_publisher
robot, endpoint = sys.argv[1], sys.argv[2]
session = open_session("client", [endpoint])
act = reliable_publisher(session, f"floor/robot/{robot}/act")
session.declare_subscriber(f"floor/robot/{robot}/sense", lambda s: act.put(s.payload.to_bytes()))
session.liveliness().declare_token(f"floor/alive/{robot}")
while True:
    time.sleep(3600)
"""


def messaging_floor(robots: int, ticks: int) -> float:
    """Ticks per second of a bare lockstep exchange with ``robots`` processes."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session("router", listen=[endpoint])
    answered: dict[int, int] = {}
    done = threading.Condition()

    def on_act(sample: object) -> None:
        tick = int(sample.payload.to_bytes())  # type: ignore[attr-defined]
        with done:
            answered[tick] = answered.get(tick, 0) + 1
            if answered[tick] == robots:
                done.notify()

    session.declare_subscriber("floor/robot/*/act", on_act)
    alive: set[str] = set()
    session.liveliness().declare_subscriber(
        "floor/alive/*", lambda sample: alive.add(str(sample.key_expr)), history=True
    )
    senders = [reliable_publisher(session, f"floor/robot/{r}/sense") for r in range(robots)]
    children = [
        subprocess.Popen([sys.executable, "-c", ECHO_ROBOT, str(r), endpoint], cwd=REPO)
        for r in range(robots)
    ]
    try:
        deadline = time.monotonic() + 120
        while len(alive) < robots and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        start = time.perf_counter()
        for tick in range(ticks):
            payload = str(tick).encode() + b" " * 100  # about the size of a Sense
            for sender in senders:
                sender.put(payload)
            with done:
                done.wait_for(lambda t=tick: answered.get(t, 0) >= robots, timeout=5)
        return ticks / (time.perf_counter() - start)
    finally:
        for child in children:
            child.kill()
            child.wait()
        session.close()


def swarm_run(robots: int, seed: int, sites: int, extra: list[str]) -> dict[str, float]:
    command = [
        sys.executable, "-m", "deploy.cli", "run", "--robots", str(robots), "--sites",
        str(sites), "--seed", str(seed), "--json", "--quiet", "--no-record", *extra,
    ]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, cwd=REPO, timeout=7200)
    total = time.perf_counter() - started
    if done.returncode != 0:
        raise RuntimeError(f"swarm run failed: {done.stderr.decode()[-2000:]}")
    summary = json.loads(done.stdout)
    return {
        "rtf": summary["real_time_factor"],
        "wall": summary["wall_time_s"],
        "sim": summary["sim_time_s"],
        "overhead": total - summary["wall_time_s"],
        "correct": float(summary["correct"]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 50, 100])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--floor-ticks", type=int, default=300)
    parser.add_argument("--no-floor", action="store_true", help="skip the messaging baseline")
    parser.add_argument("swarm_args", nargs=argparse.REMAINDER,
                        help="extra `swarm run` options after --")
    args = parser.parse_args()
    extra = [a for a in args.swarm_args if a != "--"]
    print(f"{'robots':>6} {'RTF':>7} {'target':>7} {'wall s':>8} {'sim s':>8} "
          f"{'start+stop s':>12} {'correct':>7} {'floor RTF':>9} {'RTF/floor':>9}")
    for robots in args.robots:
        runs = [swarm_run(robots, seed, args.sites, extra) for seed in args.seeds]
        rtf = statistics.fmean(run["rtf"] for run in runs)
        floor = 0.0 if args.no_floor else messaging_floor(robots, args.floor_ticks) * 0.1
        print(
            f"{robots:>6} {rtf:>6.1f}x {TARGETS.get(robots, 0):>6.0f}x "
            f"{statistics.fmean(r['wall'] for r in runs):>8.1f} "
            f"{statistics.fmean(r['sim'] for r in runs):>8.1f} "
            f"{statistics.fmean(r['overhead'] for r in runs):>12.1f} "
            f"{sum(r['correct'] for r in runs):>4.0f}/{len(runs):<2} "
            f"{floor:>8.0f}x {rtf / floor if floor else float('nan'):>9.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
