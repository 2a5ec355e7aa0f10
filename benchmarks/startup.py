"""How fast do robot processes start? Forked from a preloaded server vs fresh interpreters.

A robot is ready when its liveliness token is up: it has fetched world/info, built its
controller and subscribed to its keys. For each way of starting, the script starts a
world server, then N robot processes (one robot each), and times from the first spawn
until all N tokens are seen. Both ways run in the same process, so the ratio holds on
a noisy machine.

    .venv/bin/python benchmarks/startup.py              # 100 robots
    .venv/bin/python benchmarks/startup.py --robots 50 200
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from bestofn_swarm.wire.names import Role

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bestofn_swarm.plumbing.tcp import free_port, wait_for_port  # noqa: E402
from bestofn_swarm.plumbing.zenoh_session import open_session  # noqa: E402
from bestofn_swarm.wire import keyspace  # noqa: E402
from deploy.launcher.processes import ProcessGroup, python_module  # noqa: E402


def time_to_ready(robots: int, spawn: str) -> float:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    run = f"startup-{spawn}-{robots}"
    keys = keyspace.Keys(run)
    group = ProcessGroup()
    try:
        world = group.start(
            "world",
            python_module(
                "world_server.server",
                "--run-id",
                run,
                "--listen",
                endpoint,
                "--mode",
                "router",
                "--robots",
                str(robots),
                "--beacons",
                "0",
                "--start-timeout",
                "600",
            ),
        )
        if not wait_for_port(port, 30.0, world.alive):
            raise RuntimeError(f"the world server did not start:\n{world.tail()}")
        ready: set[str] = set()
        with open_session("client", [endpoint]) as session:
            session.liveliness().declare_subscriber(
                keys.token(Role.ROBOT, "*"),
                lambda sample: ready.add(str(sample.key_expr)),
                history=True,
            )
            argv = ["--run-id", run, "--connect", endpoint, "--mode", "client"]
            started = time.perf_counter()
            for robot in range(robots):
                robot_argv = ["--id", str(robot), *argv]
                if spawn == "fork":
                    group.fork(f"robot-{robot}", "robot_agent.node", robot_argv)
                else:
                    group.start(f"robot-{robot}", python_module("robot_agent.node", *robot_argv))
            deadline = started + 600
            while len(ready) < robots and time.perf_counter() < deadline:
                time.sleep(0.005)
            elapsed = time.perf_counter() - started
            if len(ready) < robots:
                raise RuntimeError(f"only {len(ready)} of {robots} robots became ready")
        return elapsed
    finally:
        group.stop_all()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[100])
    args = parser.parse_args()
    print(f"{'robots':>6} {'fork s':>8} {'exec s':>8} {'exec/fork':>9}")
    for robots in args.robots:
        fork = time_to_ready(robots, "fork")
        fresh = time_to_ready(robots, "exec")
        print(f"{robots:>6} {fork:>8.2f} {fresh:>8.2f} {fresh / fork:>9.1f}", flush=True)


if __name__ == "__main__":
    main()
