"""A study, declared as data: its grid (``grid.Point``s), where its results file is, and
what it publishes (the blocks of its pages, its figures, its data files), each rendered
from the results file alone.

A study module (``strategies.py``, ``scale.py``, ...) builds one ``Study``;
``catalogue.py`` names them all. Render functions get the study's runs as the results
file holds them (``Records``: every record of a declared run, and how many are declared),
never run anything, and must give the same text for the same records.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from deploy.analysis.prose import Claim
from deploy.study.grid import Point, Run, expand

RESULTS_FOLDER = "docs/studies"


@dataclass(frozen=True)
class Records:
    """The made runs of a study (the results file's records of its declared runs, in the
    declaration's order) and how many runs it declares."""

    runs: Sequence[dict[str, Any]]
    declared: int
    root: Path = Path()  # the repository the pages are rendered into

    @property
    def missing(self) -> int:
        return self.declared - len(self.runs)

    def where(self, **params: Any) -> list[dict[str, Any]]:
        """The runs whose parameters have these values."""
        return [
            record
            for record in self.runs
            if all(record["params"].get(name) == value for name, value in params.items())
        ]


Blocks = Callable[[Records], dict[str, str]]
Claims = Callable[[Records], Sequence[Claim]]


@dataclass(frozen=True)
class Page:
    """A Markdown page the study writes blocks into (between markers that name
    ``swarm study NAME --render``); ``made`` says whether it also gets the study's
    "Made by" block (``made``): every page but README. ``claims``: the numbers its prose
    reads from the runs (``deploy/study/prose.py``), checked, not written."""

    path: str
    blocks: Blocks
    made: bool = True
    claims: Claims | None = None


@dataclass(frozen=True)
class Output:
    """A file rendered whole from the runs: a figure (PNG) or the data behind one."""

    path: str
    write: Callable[[Records, Path], None]


@dataclass(frozen=True)
class Study:
    """A study: ``points`` its grid, ``pages`` and ``outputs`` what it publishes.
    ``source``: the module that declares it (the markers name it as the place to edit)."""

    name: str
    title: str
    points: Callable[[], Sequence[Point]]
    source: str
    pages: Sequence[Page] = ()
    outputs: Sequence[Output] = ()
    about: str = ""  # one line on what it measures, for --list
    results_file: str | None = None
    # The kinds of run it has, by name (``swarm study --check`` makes one of each):
    # without it, how a run is made and its swarm's size (``check.default_kind``).
    kinds: Callable[[Run], str] | None = None

    @property
    def results(self) -> str:
        """The results file, relative to the repository root."""
        return self.results_file or f"{RESULTS_FOLDER}/{self.name}.jsonl"

    def runs(self) -> list[Run]:
        return expand(self.name, self.points())
