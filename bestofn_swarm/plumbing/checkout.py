"""Where the checkout of the repository is, if the code runs from one.

Most commands need only the installed packages. A few need the repository itself: the
published pages and the studies' results files (``docs/``), and the sources the compiled
cores are built from, in place. Installed from a wheel, those commands refuse in one line
with exit code 2 (``needed``), and say what to do instead.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from bestofn_swarm.plumbing.cliargs import UsageError

DISTRIBUTION = "bestofn-swarm"
# The folder that holds the packages: a checkout's root, or an installed copy's
# site-packages.
ROOT = Path(__file__).resolve().parents[2]


def found() -> Path | None:
    """The checkout this code runs from (its pyproject names this project, and its docs
    are there), or None: an installed copy."""
    try:
        with (ROOT / "pyproject.toml").open("rb") as file:
            project = tomllib.load(file).get("project", {})
    except (OSError, tomllib.TOMLDecodeError):
        return None
    if project.get("name") != DISTRIBUTION or not (ROOT / "docs").is_dir():
        return None
    return ROOT


def needed(what: str, otherwise: str = "") -> Path:
    """The checkout, or a ``UsageError`` (one line, exit code 2) saying that ``what``
    needs one; ``otherwise`` names another way, e.g. ``"give --root CHECKOUT"``."""
    root = found()
    if root is None:
        instead = f", or {otherwise}" if otherwise else ""
        raise UsageError(
            f"{what} needs a checkout of the repository, and this is an installed copy "
            f"({ROOT}): run it in a clone of {DISTRIBUTION}{instead}"
        )
    return root
