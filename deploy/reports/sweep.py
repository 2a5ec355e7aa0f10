"""Sweeps on an executor: many independent in-process runs, here, on local processes or
on Dask.

``swarm experiment --engine inprocess``, ``swarm section5`` and ``swarm study`` hand their
runs to ``run_sweep`` as tasks: a module-level function and one picklable argument per
run. Where they run is the executor's choice (``add_executor_options``):

* ``--parallel 1``: one after the other in this process;
* ``--parallel J`` (J > 1, the default 2): J local worker processes (spawned, so they
  share nothing with a caller that holds threads); no dependency beyond the project's;
* ``--dask``: a local Dask cluster of J single-threaded worker processes on loopback;
* ``--dask tcp://HOST:PORT``: an existing Dask scheduler, whose workers must have this
  project installed (``pip install -e '.[dask]'``).

Every run's result depends only on its task (a lockstep run is a function of its seed
and settings), so a sweep gives the same result per task whichever executor runs it,
in task order. Progress is reported as tasks finish. A worker that dies (killed, out of
memory, a crash in native code) costs only the runs it held: on local processes the
runs that had started when the pool broke are retried one at a time, each alone in a
fresh pool, so the one that kills its worker is found and the others finish; on Dask the
scheduler moves them to another worker. A run whose worker died more than ``--retries``
times, or whose function raised, is reported as failed (``Failure``), and the sweep goes
on with the rest.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import logging
import multiprocessing
import queue
import sys
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from bestofn_swarm.plumbing import cliargs

T = TypeVar("T")
R = TypeVar("R")

DEFAULT_RETRIES = 2
LOCAL_DASK = "local"  # --dask with no address: a LocalCluster here


@dataclass(frozen=True)
class ExecutorSpec:
    """Where a sweep runs: ``parallel`` workers; ``dask`` None (local processes, or this
    process if ``parallel`` is 1), ``"local"`` (a LocalCluster) or a scheduler address."""

    parallel: int = 2
    dask: str | None = None
    retries: int = DEFAULT_RETRIES

    def __post_init__(self) -> None:
        if self.parallel < 1:
            raise ValueError(f"parallel must be at least 1, got {self.parallel}")
        if self.retries < 0:
            raise ValueError(f"retries must be at least 0, got {self.retries}")

    def describe(self) -> str:
        if self.dask == LOCAL_DASK:
            return f"a local Dask cluster of {self.parallel} workers"
        if self.dask is not None:
            return f"the Dask scheduler at {self.dask}"
        if self.parallel == 1:
            return "this process"
        return f"{self.parallel} local processes"


@dataclass(frozen=True)
class Failure:
    """A task that gave no result: its index, why, and how often it was tried."""

    index: int
    error: str
    attempts: int


@dataclass
class SweepResult(Generic[R]):
    """Every task's result, in task order (None where it failed), and the failures."""

    results: list[R | None]
    failures: list[Failure] = field(default_factory=list)

    def completed(self) -> list[R]:
        """The results of the tasks that gave one, in task order."""
        return [result for result in self.results if result is not None]


# (finished so far, total, the task's index, its failure or None)
Progress = Callable[[int, int, int, Failure | None], None]
# (the task's index, its result): told as each result arrives, before the progress
OnResult = Callable[[int, Any], None]


def add_executor_options(parser: argparse.ArgumentParser, *, default_parallel: int = 2) -> None:
    """``--parallel``, ``--dask [ADDRESS]`` and ``--retries``."""
    group = parser.add_argument_group("where the runs go (deploy/reports/sweep.py)")
    group.add_argument(
        "--parallel",
        type=cliargs.int_range(1, 512),
        default=default_parallel,
        metavar="J",
        help=f"worker processes, or Dask workers of a local cluster (default: "
        f"{default_parallel}; 1: one run after another in this process)",
    )
    group.add_argument(
        "--dask",
        nargs="?",
        const=LOCAL_DASK,
        default=None,
        metavar="ADDRESS",
        help="run on Dask: alone, a local cluster of --parallel workers on loopback; with "
        "tcp://HOST:PORT, that scheduler's workers (pip install -e '.[dask]')",
    )
    group.add_argument(
        "--retries",
        type=cliargs.int_range(0, 100),
        default=DEFAULT_RETRIES,
        help="times a run is tried again after its worker died (default: %(default)s)",
    )


def executor_from_args(args: argparse.Namespace) -> ExecutorSpec:
    """The executor of ``add_executor_options``' options; a usage error if Dask is asked
    for and not installed."""
    dask = getattr(args, "dask", None)
    if dask is not None:
        require_dask()
        if dask != LOCAL_DASK and not dask.startswith(("tcp://", "tls://", "ws://", "wss://")):
            raise cliargs.UsageError(f"--dask {dask}: give a scheduler address, tcp://HOST:PORT")
    return ExecutorSpec(args.parallel, dask, getattr(args, "retries", DEFAULT_RETRIES))


def require_dask() -> None:
    """A usage error saying how to install Dask, unless it is installed."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise cliargs.UsageError(
            "--dask needs Dask: pip install -e '.[dask]' (dask[distributed])"
        ) from None


def run_sweep(
    function: Callable[[T], R],
    tasks: Sequence[T],
    executor: ExecutorSpec,
    progress: Progress | None = None,
    on_result: OnResult | None = None,
) -> SweepResult[R]:
    """``function(task)`` for every task, on ``executor``; results in task order.

    ``function`` must be importable by the workers (a module-level function of an
    installed module); its result must be picklable and must not be None. ``on_result``
    sees each result as it arrives (to keep it before the sweep ends), ``progress`` each
    finished task.
    """
    if not tasks:
        return SweepResult([])
    tally: _Tally[R] = _Tally(len(tasks), progress, on_result)
    if executor.dask is not None:
        _on_dask(function, tasks, executor, tally)
    elif executor.parallel == 1:
        _here(function, tasks, tally)
    else:
        _on_local_processes(function, tasks, executor, tally)
    return tally.finish()


def _describe_error(error: BaseException) -> str:
    last = traceback.format_exception_only(type(error), error)[-1].strip()
    return last or type(error).__name__


class _Tally(Generic[R]):
    """The results as they come, and progress."""

    def __init__(self, total: int, progress: Progress | None, on_result: OnResult | None) -> None:
        self.results: list[R | None] = [None] * total
        self.failures: list[Failure] = []
        self.done = 0
        self._progress = progress
        self._on_result = on_result

    def result(self, index: int, value: R) -> None:
        self.results[index] = value
        if self._on_result is not None:
            self._on_result(index, value)
        self._advance(index, None)

    def failure(self, index: int, error: str, attempts: int) -> None:
        failure = Failure(index, error, attempts)
        self.failures.append(failure)
        self._advance(index, failure)

    def _advance(self, index: int, failure: Failure | None) -> None:
        self.done += 1
        if self._progress is not None:
            self._progress(self.done, len(self.results), index, failure)

    def finish(self) -> SweepResult[R]:
        return SweepResult(self.results, sorted(self.failures, key=lambda f: f.index))


# --- in this process -----------------------------------------------------------------------


def _here(function: Callable[[T], R], tasks: Sequence[T], tally: _Tally[R]) -> None:
    for index, task in enumerate(tasks):
        try:
            value = function(task)
        except Exception as error:  # a run's own error: reported, the sweep goes on
            tally.failure(index, _describe_error(error), 1)
        else:
            tally.result(index, value)


# --- local processes -----------------------------------------------------------------------

# In a worker process: where it says which task it starts (set by _worker_started).
_started: Any = None


def _set_started_queue(started: Any) -> None:
    global _started  # noqa: PLW0603 - one per worker process, set once by the pool
    _started = started


def _call(function: Callable[[T], R], index: int, task: T) -> R:
    """Run one task in a worker, first saying that it started (to find who killed a pool)."""
    if _started is not None:
        _started.put(index)
    return function(task)


def _on_local_processes(
    function: Callable[[T], R],
    tasks: Sequence[T],
    executor: ExecutorSpec,
    tally: _Tally[R],
) -> None:
    """A process pool; when a worker dies the pool breaks, and the tasks that had started
    are retried one at a time, each alone in a fresh pool (a task that kills its worker
    alone is tried ``retries`` more times, then reported)."""
    context = multiprocessing.get_context("spawn")
    deaths = [0] * len(tasks)
    waiting: deque[int] = deque(range(len(tasks)))
    suspects: deque[int] = deque()
    while waiting or suspects:
        if suspects:
            batch, workers = [suspects.popleft()], 1
        else:
            batch, workers = list(waiting), executor.parallel
            waiting.clear()
        started, unfinished = _run_pool(
            function, tasks, batch, workers=workers, context=context, tally=tally
        )
        if not unfinished:
            continue
        # The pool broke: the tasks that had started were in the dead worker or were lost
        # with the others; those that had not are simply run again.
        for index in unfinished:
            if index not in started:
                waiting.append(index)
            elif len(batch) > 1:
                suspects.append(index)
            else:
                deaths[index] += 1
                if deaths[index] > executor.retries:
                    tally.failure(index, "its worker process died", deaths[index])
                else:
                    suspects.append(index)


def _run_pool(
    function: Callable[[T], R],
    tasks: Sequence[T],
    batch: list[int],
    *,
    workers: int,
    context: Any,
    tally: _Tally[R],
) -> tuple[set[int], list[int]]:
    """Run ``batch`` on a fresh pool; (the tasks that started, those that gave neither a
    result nor an error because the pool broke)."""
    started_queue = context.SimpleQueue()
    unfinished: list[int] = []
    with concurrent.futures.ProcessPoolExecutor(
        max_workers=min(workers, len(batch)),
        mp_context=context,
        initializer=_set_started_queue,
        initargs=(started_queue,),
    ) as pool:
        futures = {pool.submit(_call, function, index, tasks[index]): index for index in batch}
        for future in concurrent.futures.as_completed(futures):
            index = futures[future]
            try:
                value = future.result()
            except BrokenProcessPool:
                unfinished.append(index)
            except Exception as error:  # the run's own error, raised in the worker
                tally.failure(index, _describe_error(error), 1)
            else:
                tally.result(index, value)
    started: set[int] = set()
    while not started_queue.empty():
        try:
            started.add(started_queue.get())
        except (EOFError, OSError, queue.Empty):  # a message cut short by a dying worker
            break
    return started, sorted(unfinished)


# --- Dask ----------------------------------------------------------------------------------


def _on_dask(
    function: Callable[[T], R],
    tasks: Sequence[T],
    executor: ExecutorSpec,
    tally: _Tally[R],
) -> None:
    """Every task a Dask future; a worker's death is the scheduler's to handle (it moves
    the worker's tasks elsewhere, and gives up on a task that has killed ``retries`` + 1
    workers: ``KilledWorker``, reported here)."""
    import dask
    from distributed import Client, LocalCluster, as_completed

    settings = {
        "distributed.scheduler.allowed-failures": executor.retries,
        # One task per worker thread at a time, none queued on a worker: a worker that dies
        # then charges its death to the task it ran alone, not to innocent ones queued there.
        "distributed.scheduler.worker-saturation": 1.0,
    }
    with dask.config.set(settings):
        cluster = None
        if executor.dask == LOCAL_DASK:
            # Our own cluster's chatter (a busy worker slow to exit at the end, ...) is
            # not the sweep's news: its errors are.
            logging.getLogger("distributed").setLevel(logging.ERROR)
            cluster = LocalCluster(
                n_workers=executor.parallel,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
            )
        address: Any = cluster if cluster is not None else executor.dask
        try:
            with Client(address) as client:
                futures = {
                    client.submit(_call, function, index, task, pure=False): index
                    for index, task in enumerate(tasks)
                }
                for future in as_completed(futures):
                    index = futures[future]
                    try:
                        value = future.result()
                    except Exception as error:  # KilledWorker, or the run's own error
                        killed = type(error).__name__ == "KilledWorker"
                        attempts = executor.retries + 1 if killed else 1
                        tally.failure(index, _describe_error(error), attempts)
                    else:
                        tally.result(index, value)
        finally:
            if cluster is not None:
                cluster.close()


def print_progress(label: str) -> Progress:
    """A progress report on stderr: ``label: done/total`` on one line, failures named."""

    def report(done: int, total: int, index: int, failure: Failure | None) -> None:
        if failure is not None:
            print(f"\n{label}: task {index} failed: {failure.error}", file=sys.stderr)
        end = "\n" if done == total else ""
        print(f"\r{label}: {done}/{total}", end=end, file=sys.stderr, flush=True)

    return report


__all__ = [
    "DEFAULT_RETRIES",
    "LOCAL_DASK",
    "ExecutorSpec",
    "Failure",
    "OnResult",
    "Progress",
    "SweepResult",
    "add_executor_options",
    "executor_from_args",
    "print_progress",
    "require_dask",
    "run_sweep",
]
