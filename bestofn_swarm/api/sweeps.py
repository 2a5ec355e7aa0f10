"""``sweep``: many runs over a grid of settings and seeds, one row each, on the study runner.

A sweep is a study declared on the fly (``deploy/study/``): its points are the grid's
combinations, its runs each point at each seed, made by the study runner on local processes
(``parallel``) or Dask, longest first, each kept in its results file as it finishes (so a
sweep given the same ``root`` again makes only what is missing), and read back as a pandas
DataFrame, one row per run (``deploy/study/dataframe.py``: its settings, seed, result,
wall time, commit and plug-ins).
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from rich.console import Console

from bestofn_swarm.api import frames
from bestofn_swarm.api.options import plan, tokens
from deploy.reports.sweep import ExecutorSpec
from deploy.study import grid, runner
from deploy.study.dataframe import flatten
from deploy.study.declare import Study
from deploy.study.state import state_of

DEFAULT_TIMEOUT = 1800.0  # sim seconds a run of a sweep is given by default


def sweep(
    grid_of: Mapping[str, Sequence[Any]],
    seeds: int | Iterable[int] = 10,
    parallel: int = 1,
    *,
    name: str = "sweep",
    root: str | Path | None = None,
    engine: str = "inprocess",
    timeout: float = DEFAULT_TIMEOUT,
    dask: str | None = None,
    quiet: bool = True,
    **options: Any,
) -> Any:
    """Every combination of ``grid_of`` (``swarm run`` options by name, each with its values:
    ``{"pooling": ["mprodop", "linear"], "robots": [10, 20]}``) at each seed (``seeds``: a
    number, 0 to N-1, or the seeds), with ``options`` the same for every run; run on
    ``parallel`` local processes (or the Dask scheduler ``dask``), in this process
    (``engine="inprocess"``) or over Zenoh. Its results file is ``NAME.jsonl`` under
    ``root`` (default: a temporary folder); given again, only missing runs are made. A
    pandas DataFrame, one row per run, in the grid's order. ValueError in one line for an
    option ``swarm run`` would refuse, before any run."""
    chosen = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    kind = {"inprocess": "inprocess", "zenoh": "zenoh"}.get(engine)
    if kind is None:
        raise ValueError(f"engine must be inprocess or zenoh, got {engine!r}")
    points = []
    for combination in grid.product(**{key: list(values) for key, values in grid_of.items()}):
        argv = tokens({**options, **combination})
        plan(["--engine", "inprocess", "--no-record", *argv])  # refused now, not in a worker
        points.append(grid.Point(combination, chosen, kind, options=argv, timeout=timeout))
    folder = Path(root) if root is not None else Path(tempfile.mkdtemp(prefix="bestofn-sweep-"))
    study = Study(
        name=name,
        title=f"the sweep {name}",
        points=lambda: points,
        source="bestofn_swarm.api.sweep",
        results_file=f"{name}.jsonl",
    )
    executor = ExecutorSpec(parallel=parallel, dask=dask)
    console = Console(stderr=True)
    failures = runner.run_missing(
        state_of(study, folder), folder, executor, folder / "recordings", console, quiet=quiet
    )
    if failures:
        lines = runner.failures_text(failures)
        raise RuntimeError(f"{len(failures)} runs of the sweep failed, e.g. {lines[0]}")
    records = state_of(study, folder).records()
    return frames.pandas_module().DataFrame([flatten(record) for record in records.runs])


__all__ = ["DEFAULT_TIMEOUT", "sweep"]
