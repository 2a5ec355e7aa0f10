"""Making a study's missing runs: in parallel on an executor of
``deploy/reports/sweep.py`` (``--parallel J`` local processes, or Dask), longest first,
each appended to the results file the moment it finishes, with a progress bar and an
estimate of the time left (rich)."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from deploy.reports import sweep
from deploy.study import grid, make, results
from deploy.study.state import State, record_of


@dataclass
class Eta:
    """The time left: the expected wall seconds of the runs not yet done, scaled by how
    the finished runs compared with their estimates, over the workers."""

    remaining: float  # expected wall seconds of the runs not done
    workers: int
    expected_done: float = 0.0
    actual_done: float = 0.0

    def finished(self, expected: float, actual: float) -> None:
        self.remaining = max(0.0, self.remaining - expected)
        self.expected_done += expected
        self.actual_done += actual

    def dropped(self, expected: float) -> None:
        """A run that failed: no longer to do, and no measure of how fast runs go."""
        self.remaining = max(0.0, self.remaining - expected)

    def seconds_left(self) -> float:
        scale = self.actual_done / self.expected_done if self.expected_done > 0 else 1.0
        return self.remaining * scale / max(1, self.workers)


def describe_seconds(seconds: float) -> str:
    """``about 40 s``, ``about 12 min``, ``about 3.5 h``."""
    if seconds < 90:
        return f"about {seconds:.0f} s"
    if seconds < 90 * 60:
        return f"about {seconds / 60:.0f} min"
    return f"about {seconds / 3600:.1f} h"


def recording_path(run: grid.Run, folder: Path) -> str:
    """Where a recorded run over Zenoh writes its MCAP file."""
    name = run.key.replace(" ", "_").replace("=", "-").replace("/", "_")
    return str(folder / run.study / f"{name}.mcap")


@contextlib.contextmanager
def _runner_environment() -> Iterator[None]:
    """Worker processes started meanwhile know this process as their runner."""
    before = os.environ.get(make.RUNNER_ENV)
    os.environ[make.RUNNER_ENV] = str(os.getpid())
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(make.RUNNER_ENV, None)
        else:
            os.environ[make.RUNNER_ENV] = before


def run_missing(
    state: State,
    root: Path,
    executor: sweep.ExecutorSpec,
    recordings: Path,
    console: Console,
    *,
    quiet: bool = False,
) -> list[tuple[grid.Run, sweep.Failure]]:
    """Make the state's missing runs, longest first, appending each to the results file
    as it finishes; the runs that failed, with why."""
    walls = state.walls()
    todo = [
        replace(run, record_to=recording_path(run, recordings)) if run.record else run
        for run in grid.order(state.missing, walls)
    ]
    if not todo:
        return []
    expected = [grid.estimate(run, walls) for run in todo]
    eta = Eta(sum(expected), executor.parallel)
    failures: list[tuple[grid.Run, sweep.Failure]] = []
    started = time.monotonic()
    progress = Progress(
        TextColumn(f"[bold]{state.study.name}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[left]}"),
        TextColumn("{task.fields[info]}"),
        console=console,
        disable=quiet,
    )
    path = root / state.study.results
    appender = results.Appender(path)  # first: a file that cannot be written stops it all
    provenance = results.provenance()  # the code's, wherever the results go
    with appender, progress, _runner_environment():
        bar = progress.add_task(
            "runs",
            total=len(todo),
            left=f"{describe_seconds(eta.seconds_left())} left",
            info=f"on {executor.describe()}",
        )

        def keep(index: int, made: dict[str, object]) -> None:
            recording = made.get("recording")
            if isinstance(recording, dict):  # kept relative to the root where it can be
                made = {
                    **made,
                    "recording": {**recording, "path": _relative(recording["path"], root)},
                }
            appender.add(record_of(todo[index], made, provenance))
            wall = made.get("wall_s")
            eta.finished(expected[index], float(wall) if isinstance(wall, int | float) else 0.0)

        def advance(done: int, total: int, index: int, failure: sweep.Failure | None) -> None:
            if failure is not None:
                failures.append((todo[index], failure))
                eta.dropped(expected[index])
                console.print(f"{todo[index].key}: failed: {failure.error}")
            progress.update(
                bar,
                completed=done,
                left=f"{describe_seconds(eta.seconds_left())} left",
                info=todo[index].key,
            )

        sweep.run_sweep(make.make, todo, executor, advance, on_result=keep)
    if not quiet:
        console.print(
            f"{len(todo) - len(failures)} runs made in "
            f"{describe_seconds(time.monotonic() - started)[6:]}"
            f" on {executor.describe()}, into {path}"
        )
    return failures


def _relative(path: str, root: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(root.resolve()))
    except ValueError:
        return path


def failures_text(failures: Sequence[tuple[grid.Run, sweep.Failure]]) -> list[str]:
    return [f"{run.key}: {failure.error} ({failure.attempts} tries)" for run, failure in failures]
