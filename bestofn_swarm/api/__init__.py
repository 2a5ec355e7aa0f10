"""The public Python API, for notebooks and scripts (docs/extending.md,
examples/notebooks/api.ipynb)::

    from bestofn_swarm import run, sweep

    result = run(robots=10, sites=5, seed=3, pooling="linear")
    result.summary["ended"], result.digest
    result.frame()                      # its time series, a pandas DataFrame

    table = sweep({"pooling": ["mprodop", "linear"]}, seeds=range(10), parallel=2)

``run`` is ``swarm run`` (in this process by default, or over Zenoh); ``sweep`` is a study
made on the fly by the study runner, one row per run. Options are ``swarm run``'s, by their
names (``drop=0.2``, ``camera_noise=5``); plug-ins are named as on the command line.
pandas is needed for DataFrames only: ``pip install -e '.[analysis]'``.
"""

from __future__ import annotations

from bestofn_swarm.api.runs import RunResult, run
from bestofn_swarm.api.sweeps import sweep

__all__ = ["RunResult", "run", "sweep"]
