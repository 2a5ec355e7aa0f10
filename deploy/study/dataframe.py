"""A study's runs as a pandas DataFrame: ``deploy.study.frame("strategies")``.

One row per run of the results file that the study declares, in the declaration's
order: its key and seed, one column per parameter (``robots``, ``sites``, ...), one per
field of what it gave (``verdict``, ``sim_time_s``, ...; nested fields dotted:
``robots.steps``, whose values are lists, one item per robot), its wall
time (``wall_s``) and what it was made with (``commit``, ``dirty``, ``lock``, and for a
swarm each plug-in's record: ``plugins.pooling.name``, ``plugins.pooling.version``,
``plugins.pooling.source``...). A result field with the name of a parameter is called
``result.NAME``.

pandas is an optional extra: ``pip install -e '.[analysis]'``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from deploy.study.results import CODE_ROOT

INSTALL = "pip install -e '.[analysis]'"


def flatten(record: Mapping[str, Any]) -> dict[str, Any]:
    """One results line as one row: parameters and result fields as columns."""
    params = dict(record.get("params", {}))
    row: dict[str, Any] = {"key": record["key"], **params, "seed": record.get("seed")}

    def add(prefix: str, value: Any) -> None:
        if isinstance(value, Mapping):
            for name, inner in value.items():
                add(f"{prefix}.{name}" if prefix else str(name), inner)
        else:
            row[prefix if prefix not in row else f"result.{prefix}"] = value

    add("", record.get("result") or {})
    for name in ("kind", "command", "wall_s", "commit", "dirty", "lock"):
        row[name] = record.get(name)
    for kind, plugin in (record.get("plugins") or {}).items():
        for name, value in plugin.items():  # plugins.pooling.name, .version, .source...
            row[f"plugins.{kind}.{name}"] = value
    return row


def frame(name: str, root: str | os.PathLike[str] | None = None) -> Any:
    """The runs of study ``name`` (``swarm study --list`` names them) in its results file
    under ``root`` (a path or its string; default: this checkout) as a pandas DataFrame,
    one row per run."""
    try:
        import pandas
    except ImportError:
        raise ImportError(f"deploy.study.frame needs pandas: {INSTALL}") from None
    from deploy.study.catalogue import study_named
    from deploy.study.state import state_of

    state = state_of(study_named(name), CODE_ROOT if root is None else Path(root))
    return pandas.DataFrame([flatten(record) for record in state.records().runs])
