"""A run's time series as a pandas DataFrame: what ``RunResult.frame()`` gives.

For now the swarm as the in-process engine shows it at each sample (every
``--state-every`` ticks, its progress hook): sim time, robots decided, trips made by all.
The full time series of a run (each robot at each sample: phase, position, decided site,
opinion) is the time-series collector's (``world_server/observer/frame.py``, ``swarm
frame``); ``time_series`` is the one function to point at it.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType
from typing import Any

from deploy.inprocess.engine import Progress

INSTALL = "pip install -e '.[analysis]'"
COLUMNS = ("t", "decided", "trips")


def pandas_module() -> ModuleType:
    """pandas, or ImportError saying how to install it (an optional extra)."""
    try:
        import pandas
    except ImportError:
        raise ImportError(f"DataFrames need pandas: {INSTALL}") from None
    return pandas


def time_series(samples: Sequence[Progress]) -> Any:
    """One row per sample of a run (``RunResult.samples``): ``t`` (sim seconds), ``decided``
    (robots decided), ``trips`` (trips made by all robots). ValueError for a run that kept
    none (one over Zenoh: its recording holds them)."""
    if not samples:
        raise ValueError(
            "this run kept no time series: a run in this process does (engine='inprocess'); "
            "one over Zenoh keeps it in its recording (record=PATH)"
        )
    rows = [(sample.sim_time, sample.decided, sample.trips) for sample in samples]
    return pandas_module().DataFrame(rows, columns=list(COLUMNS))


__all__ = ["COLUMNS", "INSTALL", "pandas_module", "time_series"]
