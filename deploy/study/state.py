"""Where a study stands: which of its declared runs its results file holds, which are
missing, and what the file holds that the study no longer declares."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from deploy.study import grid, results
from deploy.study.declare import Records, Study


@dataclass
class State:
    """``runs``: the declared runs (those ``--only`` selects); ``done`` and ``missing``
    split them; ``undeclared``: keys of the file that no declared run has."""

    study: Study
    runs: list[grid.Run]
    loaded: results.Loaded
    done: list[grid.Run]
    missing: list[grid.Run]
    undeclared: list[str]

    root: Path

    def records(self) -> Records:
        """The records of the runs done, in the declaration's order."""
        return Records([self.loaded.runs[run.key] for run in self.done], len(self.runs), self.root)

    def walls(self) -> dict[str, list[float]]:
        """The wall seconds of the runs made, by point (what ``grid.estimate`` reads)."""
        by_point: dict[str, list[float]] = {}
        for run in self.done:
            wall = self.loaded.runs[run.key].get("wall_s")
            if isinstance(wall, int | float):
                by_point.setdefault(run.point, []).append(float(wall))
        return by_point


def state_of(study: Study, root: Path, only: Mapping[str, set[str]] | None = None) -> State:
    """The study's state under ``root``; ValueError for an ``--only`` no run matches."""
    declared = study.runs()
    runs = grid.select(declared, only or {})
    loaded = results.load(root / study.results)
    done = [run for run in runs if run.key in loaded.runs]
    missing = [run for run in runs if run.key not in loaded.runs]
    keys = {run.key for run in declared}
    undeclared = [key for key in loaded.runs if key not in keys]
    return State(study, runs, loaded, done, missing, undeclared, root)


def record_of(
    run: grid.Run, made: Mapping[str, Any], provenance: Mapping[str, Any]
) -> dict[str, Any]:
    """The results file's line for a run: its key, parameters, seed, kind, the command that
    makes it again, what it gave and what it was made with."""
    return {
        "key": run.key,
        "params": dict(run.params),
        "seed": run.seed,
        "kind": run.kind,
        "command": run.command(),
        **dict(made),
        **dict(provenance),
    }
