"""Progress on stderr that reads well wherever it goes: rich's live bar on a terminal, and
plain lines elsewhere (a log file, a pipe, CI), where a live bar prints nothing for
minutes and then one garbled line.

``progress(console, *columns, ...)`` returns either, with the part of rich's ``Progress``
the commands use: ``add_task``, ``update`` and use as a context manager. The plain one
writes a line when a task starts, at most every ``every`` wall seconds while it goes, at
once when its count changes if it is small, and when it completes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rich.console import Console
from rich.progress import Progress, ProgressColumn, TaskID

PLAIN_EVERY = 10.0  # wall seconds between two plain lines while nothing is completed
PLAIN_COUNT_EVERY = 1.0  # at most this often when something is


class PlainProgress:
    """Progress as plain lines: ``<name>: <done>/<total> <info>``."""

    def __init__(
        self,
        console: Console,
        *,
        disable: bool = False,
        every: float = PLAIN_EVERY,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.console = console
        self.disable = disable
        self.every = every
        self.clock = clock
        self.tasks: dict[TaskID, dict[str, Any]] = {}

    def __enter__(self) -> PlainProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        for task in self.tasks.values():
            if task["shown"] != (task["completed"], task["fields"].get("info")):
                self._line(task)

    def add_task(self, description: str, total: float | None = None, **fields: Any) -> TaskID:
        ident = TaskID(len(self.tasks))
        self.tasks[ident] = {
            "description": description,
            "total": total,
            "completed": 0.0,
            "fields": dict(fields),
            "at": -float("inf"),
            "shown": None,
        }
        self._line(self.tasks[ident])
        return ident

    def update(
        self,
        task_id: TaskID,
        *,
        completed: float | None = None,
        advance: float | None = None,
        **fields: Any,
    ) -> None:
        task = self.tasks[task_id]
        before = task["completed"]
        if completed is not None:
            task["completed"] = completed
        if advance is not None:
            task["completed"] += advance
        task["fields"].update(fields)
        now = self.clock()
        done = task["total"] is not None and task["completed"] >= task["total"]
        moved = task["completed"] != before and now - task["at"] >= PLAIN_COUNT_EVERY
        if done or moved or now - task["at"] >= self.every:
            self._line(task)

    def _line(self, task: dict[str, Any]) -> None:
        task["at"] = self.clock()
        info = task["fields"].get("info")
        task["shown"] = (task["completed"], info)
        if self.disable:
            return
        total = task["total"]
        count = f"{task['completed']:g}" + (f"/{total:g}" if total is not None else "")
        text = f"{task['description']}: {count}" + (f", {info}" if info else "")
        self.console.print(text, highlight=False, markup=False, soft_wrap=True)


def progress(
    console: Console,
    *columns: str | ProgressColumn,
    transient: bool = False,
    disable: bool = False,
) -> Progress | PlainProgress:
    """A live bar on a terminal, plain lines elsewhere."""
    if console.is_terminal:
        return Progress(*columns, console=console, transient=transient, disable=disable)
    return PlainProgress(console, disable=disable)
