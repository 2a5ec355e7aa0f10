"""The progress display of one run, shared by both engines so they look the same."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn


def decided_progress(console: Console, quiet: bool) -> Progress:
    """A bar of robots decided, with a free-text ``info`` field and the elapsed time;
    it disappears when the run ends (the summary follows)."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=quiet,
    )
