"""What every script that writes a published page needs: the block between two markers
replaced, and the commit of the code that made it."""

from __future__ import annotations

import subprocess
from collections.abc import Iterable
from pathlib import Path

# Changes here cannot change a run, so they do not make the code that ran "uncommitted".
NOT_RUN = ("docs/", "benchmarks/", "tests/", "README.md")


def replace_between(text: str, begin: str, end: str, content: str) -> str:
    """``text`` with what lies between the lines ``begin`` and ``end`` replaced by
    ``content``; ValueError when a marker is missing or out of order."""
    start = text.find(begin)
    stop = text.find(end, start + len(begin)) if start >= 0 else -1
    if start < 0 or stop < 0:
        raise ValueError(f"no block between the lines\n{begin}\n{end}")
    return text[: start + len(begin)] + "\n" + content + "\n" + text[stop:]


def write_between(path: Path, begin: str, end: str, content: str) -> None:
    """Replace the block of ``path`` between ``begin`` and ``end``; a page without them
    stops the script with a message that says which lines to add."""
    try:
        path.write_text(replace_between(path.read_text(), begin, end, content))
    except ValueError as error:
        raise SystemExit(f"{path}: {error}") from None


def git_state(root: Path, ignore: Iterable[str] = ()) -> tuple[str | None, bool]:
    """HEAD's short hash (None outside a checkout) and whether tracked files other than
    ``ignore`` and ``NOT_RUN`` have changes."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True
        )
        status = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
        )
    except OSError:
        return None, False
    if head.returncode != 0:
        return None, False
    skipped = set(ignore)
    changed = [
        path
        for line in status.stdout.splitlines()
        if (path := line[3:]) not in skipped and not path.startswith(NOT_RUN)
    ]
    return head.stdout.strip(), bool(changed)


def made_at(root: Path) -> str:
    """ "commit abc1234" (with "with uncommitted changes" when the code that runs has
    any), for a page's "Made by" line."""
    commit, dirty = git_state(root)
    return f"commit {commit or 'unknown'}" + (" with uncommitted changes" if dirty else "")
