"""A run's time series as a pandas DataFrame: what ``RunResult.frame()`` gives.

The rows are the time-series collector's (``world_server/observer/frame.py``), the same
``swarm frame`` writes: one row per robot per sample (every ``--state-every`` ticks: its
pose, phase, trips, decided site, leading site, the probability it gives the best site,
its opinion's entropy, its pool size), or one row per sample for the swarm (robots
decided, each site's share of the swarm's opinion, mean entropy, poolings). A run in this
process fills a collector as it goes; a run over Zenoh has them in its recording.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

from world_server.observer.frame import FrameCollector

INSTALL = "pip install -e '.[analysis]'"


def pandas_module() -> ModuleType:
    """pandas, or ImportError saying how to install it (an optional extra)."""
    try:
        import pandas
    except ImportError:
        raise ImportError(f"DataFrames need pandas: {INSTALL}") from None
    return pandas


def time_series(
    run_id: str,
    collector: FrameCollector | None,
    recording: Path | None,
    *,
    swarm: bool = False,
) -> Any:
    """A run's time series: from its ``collector`` (a run in this process), else from its
    ``recording``; ``swarm``: one row per sample instead of one per robot per sample.
    ValueError for a run that kept neither (one over Zenoh without ``record=PATH``)."""
    pandas_module()
    if collector is not None:
        return collector.dataframe(swarm=swarm, run_id=run_id)
    if recording is not None:
        from world_server.recording.frame import frame_of_recording

        return frame_of_recording(recording, swarm=swarm)
    raise ValueError(
        "this run kept no time series: a run in this process does (engine='inprocess'); "
        "one over Zenoh keeps it in its recording (record=PATH)"
    )


__all__ = ["INSTALL", "pandas_module", "time_series"]
