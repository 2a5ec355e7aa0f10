"""What the tests of a swarm over several hosts share (tests/test_hosts.py on loopback,
tests/test_multihost.py in network namespaces): the commands of the hand-started layout
of deploy/README.md, of a Dask cluster whose workers place the robots, a process that
publishes a forged ending, and how to wait for processes to end by themselves."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

PY = sys.executable


def router(listen: str, *connect: str) -> list[str]:
    return [PY, "-m", "deploy.launcher.router", "--listen", listen] + [
        arg for endpoint in connect for arg in ("--connect", endpoint)
    ]


@dataclass(frozen=True)
class HandRun:
    """The processes of one run started by hand (deploy/README.md), each a client of the
    router it is given, with the key file deploy/README.md hands it."""

    run_id: str
    seed: int
    robots: int
    sites: int
    keys: Path  # the folder of its key files (write_keys)

    @property
    def shape(self) -> list[str]:
        return ["--seed", str(self.seed), "--robots", str(self.robots), "--sites", str(self.sites)]

    def world(self, router_at: str) -> list[str]:
        return [*self._program("world_server.server", router_at, "secret.json"), *self.shape]

    def beacon(self, router_at: str) -> list[str]:
        return self._program("nest_beacon", router_at, "secret.json")

    def robot_host(self, first: int, last: int, router_at: str) -> list[str]:
        """A robot-agent process hosting robots ``first`` to ``last``, their keys only."""
        ids = [arg for robot in range(first, last + 1) for arg in ("--id", str(robot))]
        return [*self._program("robot_agent.node", router_at, f"host-{first}-{last}.json"), *ids]

    def recorder(self, router_at: str, out: Path) -> list[str]:
        program = self._program("world_server.recorder", router_at, "secret.json")
        return [*program, *self.shape, "--out", str(out)]

    def follow(self, router_at: str) -> list[str]:
        return [
            PY, "-m", "deploy.cli", "follow", "--connect", router_at, "--run-id", self.run_id,
            "--key-file", str(self.keys / "secret.json"), "--json", "--quiet",
        ]  # fmt: skip

    def forger(self, router_at: str) -> list[str]:
        """A process holding robot 1's key that forges a stalled ending once the world ticks."""
        key_file = str(self.keys / "robot-1.json")
        return [PY, "-c", FORGER, router_at, self.run_id, key_file, str(self.robots)]

    def write_keys(self, per_process: int) -> None:
        """The run's key files, as deploy/README.md writes them."""
        subprocess.run(
            [
                PY, "-m", "bestofn_swarm.plumbing.run_keys", "--run-id", self.run_id,
                "--robots", str(self.robots), "--robots-per-process", str(per_process),
                "--out", str(self.keys),
            ],
            check=True,
            capture_output=True,
            timeout=60,
        )  # fmt: skip

    def _program(self, module: str, router_at: str, key_file: str) -> list[str]:
        return [
            PY, "-m", module, "--run-id", self.run_id, "--mode", "client",
            "--connect", router_at, "--key-file", str(self.keys / key_file),
        ]  # fmt: skip


def scheduler(host: str, port: int) -> list[str]:
    return [
        PY,
        "-m",
        "distributed.cli.dask_scheduler",
        "--host",
        host,
        "--port",
        str(port),
        "--no-dashboard",
    ]


def worker(
    scheduler_at: str, host: str, threads: int, router_at: str | None = None, name: str = ""
) -> list[str]:
    """A Dask worker (no nanny: killing it kills the worker itself), given its host's
    router with ``--router`` (else it reads $BESTOFN_ROUTER)."""
    command = [
        PY,
        "-m",
        "distributed.cli.dask_worker",
        scheduler_at,
        "--host",
        host,
        "--nthreads",
        str(threads),
        "--no-nanny",
        "--no-dashboard",
        "--preload",
        "deploy.launcher.dask_worker",
    ]
    return (
        command
        + (["--router", router_at] if router_at else [])
        + (["--name", name] if name else [])
    )


def wait_for_workers(scheduler_at: str, count: int, timeout: float = 60.0) -> None:
    """Wait until the scheduler has ``count`` workers (asked from a process of its own)."""
    probe = (
        "import sys, time\n"
        "from distributed import Client\n"
        "with Client(sys.argv[1], timeout=30) as client:\n"
        "    client.wait_for_workers(int(sys.argv[2]), timeout=float(sys.argv[3]))\n"
    )
    subprocess.run(
        [PY, "-c", probe, scheduler_at, str(count), str(timeout)],
        check=True,
        capture_output=True,
        timeout=timeout + 30,
    )


# A process that holds only robot 1's key and publishes an ending of the run claiming it
# stalled, once the world ticks: argv: router, run id, key file, robots.
FORGER = """
import sys, time
from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.plumbing.zenoh_session import open_session
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.endings import Ending, Stop
router, run, key_file, robots = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
keyring = run_keys.load(run, key_file, "forger")
keys = keyspace.Keys(run)
ticks = []
session = open_session("client", [router])
session.declare_subscriber(keys.of(keyspace.CLOCK), lambda sample: ticks.append(1))
deadline = time.monotonic() + 60
while len(ticks) < 20 and time.monotonic() < deadline:
    time.sleep(0.01)
ending = protocol.RunEnding(
    v=1, run=run, ended=Ending.STALLED, code=4, stop=Stop.STALLED, timeout_kind=None,
    tick=1, t=0.1, signal=None, lost=[], summary={"ended": "stalled"})
key = keys.of(keyspace.ENDING)
payload = protocol.encode(ending)
mine = names.robot_identity(1)
tag = keyring.seal(mine, key, payload).hex()
seals = protocol.EndingSeals(v=1, robots=[tag] * robots, bridge=tag)
attachment = keyring.seal(mine, key, payload, protocol.encode(seals))
session.put(key, payload, attachment=attachment)
time.sleep(0.5)
print("forged" if ticks else "no tick", flush=True)
session.close()
"""


def wait_all(processes: Sequence[subprocess.Popen[bytes]], timeout: float) -> list[int | None]:
    """Wait up to ``timeout`` in all for every process to end by itself; their exit codes
    (None: still running)."""
    deadline = time.monotonic() + timeout
    for process in processes:
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=max(0.1, deadline - time.monotonic()))
    return [process.poll() for process in processes]
