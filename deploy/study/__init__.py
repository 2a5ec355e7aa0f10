"""The studies behind the published pages (``swarm study``, docs/studies.md): each
declared as data (its grid, its seeds, what it publishes), made by one resumable runner
into a results file, rendered from that file alone, checked by making a sample again.

``deploy.study.frame(NAME)`` loads a study's runs into a pandas DataFrame (the optional
``analysis`` extra).
"""

from __future__ import annotations

import os
from typing import Any


def frame(name: str, root: str | os.PathLike[str] | None = None) -> Any:
    """The runs of study ``name`` under ``root`` (a path or its string; default: this
    checkout) as a pandas DataFrame (``deploy/study/dataframe.py``)."""
    from deploy.study.dataframe import frame as load

    return load(name, root)


__all__ = ["frame"]
