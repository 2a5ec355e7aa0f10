"""Tasks for tests/test_sweep.py, importable by worker processes (local and Dask)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


def small_run(task: tuple[str, int]) -> dict[str, Any]:
    """A whole lockstep run in memory: 3 robots, 3 sites, ``task`` = (strategy, seed)."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.core.controller_config import ControllerConfig
    from world_server.core.world import WorldConfig

    strategy, seed = task
    world = WorldConfig(run="sweep-test", seed=seed, num_sites=3, num_robots=3)
    summary = run_in_process(world, ControllerConfig(strategy=strategy), timeout=1200.0)
    return {
        "ended": summary["ended"],
        "sim_time_s": summary["sim_time_s"],
        "robots": [
            (robot["decided_site"], robot["steps"], robot["pool_sizes"])
            for robot in summary["per_robot"]
        ],
    }


def behave(task: tuple[str, str]) -> str:
    """``(what, marker)``: ``ok`` returns; ``die`` kills its worker; ``die-once`` kills its
    worker the first time (it leaves ``marker``), then returns; ``raise`` raises."""
    what, marker = task
    if what == "die" or (what == "die-once" and not Path(marker).exists()):
        Path(marker).touch()
        os._exit(3)
    if what == "raise":
        raise ValueError(f"the task says no ({marker})")
    return f"{what}:{Path(marker).name}"
