"""``swarm run --dask ADDRESS``: the robot processes of a run placed on a Dask cluster.

Dask places the processes, Zenoh carries the messages: the world server, the beacon and
the recorder run where the command runs (clients of this host's router); the robots go to
the cluster's workers, split by the workers' cores (``split_robots``): each worker gets a
contiguous block of robots in proportion to its threads, hosted in up to one process per
thread, and one task (``dask_worker.host_processes``) that starts those processes as
clients of its own host's router. Each process is handed only the run keys of its own
robots (and of its host identity, for its batches): a worker never holds another's keys,
nor the run secret.

The run ends as every run does, by the world's ending: the robots hear it and exit, and
so the tasks end. A worker that leaves the cluster mid-run (``lost``) takes its robots
with it; the world, told that a lost robot ends the run (``LostRobot.END``), ends it as
crashed, and the launcher names the worker and its host. Whatever the ending, ``stop``
sets the run's stop event, which every task watches, and waits for the tasks: no process
of the run is left on any host.

Dask is imported only here, and only for ``swarm run --dask``.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.wire import auth, names
from deploy.launcher.dask_worker import Hosted, Launch, Share, host_processes
from deploy.launcher.plan import RunPlan

log = logging.getLogger("swarm.run")

CONNECT_TIMEOUT = 10.0  # wall seconds to reach the scheduler
LOST_CHECK_EVERY = 1.0  # wall seconds between two questions to the scheduler: who is there?
TASK_WAIT = 15.0  # wall seconds to wait for the tasks once the run is over


class DaskError(Exception):
    """The cluster cannot take the run (no scheduler, no worker)."""


@dataclass(frozen=True)
class WorkerSlot:
    """A worker of the cluster, as the scheduler describes it."""

    address: str
    host: str
    threads: int
    name: str = ""


@dataclass(frozen=True)
class Placed:
    """A worker's share of the run: its robots, in processes."""

    worker: WorkerSlot
    processes: list[list[int]]

    @property
    def robots(self) -> list[int]:
        return [robot for process in self.processes for robot in process]


@dataclass(frozen=True)
class LostWorker:
    """A worker that left mid-run, and the robots it took with it."""

    worker: WorkerSlot
    robots: list[int]

    def describe(self) -> str:
        robots = ", ".join(map(str, self.robots))
        hosted = f"robots {robots}" if self.robots else "the world server"
        return f"worker {self.worker.address} on host {self.worker.host} ({hosted})"

    def as_dict(self) -> dict[str, Any]:
        return {"worker": self.worker.address, "host": self.worker.host, "robots": self.robots}


def split_robots(robots: Sequence[int], workers: Sequence[WorkerSlot]) -> list[Placed]:
    """``robots`` over ``workers``, in order: contiguous blocks in proportion to each
    worker's threads (largest remainders first), each block in up to one process per
    thread. A worker may get none (more workers than robots)."""
    if not workers:
        raise DaskError("the cluster has no worker")
    total = sum(worker.threads for worker in workers)
    exact = [len(robots) * worker.threads / total for worker in workers]
    counts = [math.floor(share) for share in exact]
    by_remainder = sorted(
        range(len(workers)), key=lambda index: (counts[index] - exact[index], index)
    )
    for index in by_remainder[: len(robots) - sum(counts)]:
        counts[index] += 1
    placed, start = [], 0
    for worker, count in zip(workers, counts, strict=True):
        block = list(robots[start : start + count])
        start += count
        if not block:
            continue
        parts = min(worker.threads, len(block))
        size, extra = divmod(len(block), parts)
        processes, at = [], 0
        for part in range(parts):
            width = size + (1 if part < extra else 0)
            processes.append(block[at : at + width])
            at += width
        placed.append(Placed(worker, processes))
    return placed


class DaskPlacement:
    """One run's robots on a Dask cluster: placed, watched, and stopped."""

    def __init__(self, plan: RunPlan) -> None:
        assert plan.dask is not None
        self.plan = plan
        self.address = plan.dask
        self.client: Any = None
        self.placed: list[Placed] = []
        self.futures: dict[str, Any] = {}  # worker address -> its task
        self.results: dict[str, Hosted] = {}
        self.stop_event = f"bestofn-stop-{plan.run_id}"
        self.workers: list[WorkerSlot] = []
        self.world: WorkerSlot | None = None  # --dask-world: where the world and beacon run
        self._lost: list[LostWorker] = []
        self._checked_at = -math.inf
        self._stopped = False

    def connect(self) -> list[WorkerSlot]:
        """Reach the scheduler (once); its workers, in address order. DaskError if it
        cannot, or has none."""
        from distributed import Client, Event

        if self.client is not None:
            return self.workers
        try:
            self.client = Client(self.address, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError) as error:
            raise DaskError(f"no Dask scheduler answers at {self.address}: {error}") from None
        info = self.client.scheduler_info()
        workers = [
            WorkerSlot(
                address,
                str(about.get("host", "")),
                int(about.get("nthreads", 1)),
                str(about.get("name", "")),
            )
            for address, about in sorted(info.get("workers", {}).items())
        ]
        if not workers:
            raise DaskError(f"the Dask scheduler at {self.address} has no worker")
        Event(self.stop_event, client=self.client).clear()
        self.workers = workers
        return workers

    def start_world(self, keyring: auth.Keyring | None) -> WorkerSlot:
        """--dask-world: the world server and the beacon on the named worker (its name,
        address or host), clients of its host's router; only that worker is handed the run
        secret (the world's) and the beacon's keys."""
        plan = self.plan
        named = plan.dask_world
        found = [w for w in self.connect() if named in (w.name, w.address, w.host)]
        if not found:
            raise DaskError(f"--dask-world {named}: no worker of {self.address} has that name")
        worker = self.world = found[0]
        beacon = names.beacon_identity(names.DEFAULT_BEACON)
        world_keys = beacon_keys = None
        if keyring is not None:
            world_keys = run_keys.to_text(keyring, plan.run_id)
            beacon_keys = run_keys.to_text(keyring.only([beacon, names.WORLD]), plan.run_id)
        share = Share(
            run_id=plan.run_id,
            launches=[
                Launch("world", "world_server.server", plan.world_argv(), world_keys),
                Launch("beacon", "nest_beacon", plan.beacon_argv(), beacon_keys),
            ],
            stop_event=self.stop_event,
        )
        self._submit(worker, share, "world")
        log.info("the world and the beacon on worker %s (host %s)", worker.address, worker.host)
        return worker

    def _submit(self, worker: WorkerSlot, share: Share, part: str) -> None:
        self.futures[f"{part}@{worker.address}"] = self.client.submit(
            host_processes,
            share,
            workers=[worker.address],
            allow_other_workers=False,
            pure=False,
            retries=0,
            key=f"bestofn-{self.plan.run_id}-{part}-{worker.address}",
        )

    def start(self, keyring: auth.Keyring | None) -> list[Placed]:
        """Place the run's robots and start their tasks; where each went."""
        plan = self.plan
        workers = self.connect()
        self.placed = split_robots(plan.emulated, workers)
        for placed in self.placed:
            share = Share(
                run_id=plan.run_id,
                launches=[self._launch(robots, keyring) for robots in placed.processes],
                stop_event=self.stop_event,
                robots=placed.robots,
            )
            self._submit(placed.worker, share, "robots")
            log.info(
                "robots %s on worker %s (host %s) in %d process(es)",
                _ranges(placed.robots),
                placed.worker.address,
                placed.worker.host,
                len(placed.processes),
            )
        return self.placed

    def _launch(self, robots: list[int], keyring: auth.Keyring | None) -> Launch:
        """One robot process: its robots, and only their keys (and its host identity's)."""
        plan = self.plan
        name = f"robot-{robots[0]}" + (f"-{robots[-1]}" if len(robots) > 1 else "")
        keys = None
        if keyring is not None:
            identities = [names.robot_identity(robot) for robot in robots]
            if len(robots) > 1 and plan.batch:
                identities.append(names.host_identity(robots[0], robots[-1]))
            keys = run_keys.to_text(keyring.only(identities), plan.run_id)
        return Launch(name, "robot_agent.node", plan.robot_argv(robots), keys)

    # --- during the run --------------------------------------------------------------

    def lost(self) -> list[LostWorker]:
        """The workers of the run that left the cluster, or whose task failed (asked of
        the scheduler at most every LOST_CHECK_EVERY seconds)."""
        now = time.monotonic()
        if self.client is None or now - self._checked_at < LOST_CHECK_EVERY:
            return self._lost
        self._checked_at = now
        try:
            present = set(self.client.nthreads())
        except Exception:  # the scheduler is gone: every worker is lost to the run
            present = set()
        known = {lost.worker.address for lost in self._lost}
        shares = [(placed.worker, placed.robots, "robots") for placed in self.placed]
        if self.world is not None:
            shares.append((self.world, [], "world"))
        for worker, robots, part in shares:
            future = self.futures.get(f"{part}@{worker.address}")
            # The world's task ends only when the world did: before the run's ending, lost.
            ended = ("error", "cancelled", "finished") if part == "world" else ("error",)
            failed = future is not None and future.status in (*ended, "cancelled")
            if worker.address not in known and (worker.address not in present or failed):
                self._lost.append(LostWorker(worker, robots))
                known.add(worker.address)
                log.warning("lost %s", self._lost[-1].describe())
        return self._lost

    def whose(self, robots: Sequence[int]) -> list[LostWorker]:
        """The workers that hosted any of ``robots`` (robots lost mid-run), each with all
        the robots it hosted: the world ends the run at the first of them it loses."""
        return [
            LostWorker(placed.worker, placed.robots)
            for placed in self.placed
            if any(robot in placed.robots for robot in robots)
        ]

    # --- the end ---------------------------------------------------------------------

    def stop(self, wait: float = TASK_WAIT) -> None:
        """Ask every task to stop its processes (those that did not end with the run) and
        wait for them; what each reported is in ``results``."""
        if self.client is None or self._stopped:
            return
        self._stopped = True
        from distributed import Event

        try:
            Event(self.stop_event, client=self.client).set()
        except Exception as error:  # the scheduler is gone: each task stops on its own
            log.info("could not ask the tasks to stop: %s", error)
        # A lost worker's task never finishes: it is not waited for.
        self._checked_at = -math.inf
        gone = {lost.worker.address for lost in self.lost()}
        waited = [f for part, f in self.futures.items() if part.partition("@")[2] not in gone]
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and not all(future.done() for future in waited):
            time.sleep(0.1)
        for part, future in self.futures.items():
            if future.status == "finished":
                self.results[part] = future.result()

    def close(self) -> None:
        """Forget the run's tasks and leave the cluster as it was."""
        if self.client is None:
            return
        with contextlib.suppress(Exception):  # the scheduler may be gone
            self.client.cancel(list(self.futures.values()), force=True)
        self.client.close()
        self.client = None


def _ranges(robots: Sequence[int]) -> str:
    return f"{robots[0]}-{robots[-1]}" if len(robots) > 1 else str(robots[0])


__all__ = ["DaskError", "DaskPlacement", "LostWorker", "Placed", "WorkerSlot", "split_robots"]
