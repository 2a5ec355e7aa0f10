"""``run``: one swarm run, as ``swarm run`` makes it, from Python."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.api import frames
from bestofn_swarm.api.options import plan, tokens
from bestofn_swarm.plumbing.lifecycle import PARENT_ENV
from deploy.inprocess.engine import EngineHooks
from deploy.launcher.inprocess import run_plan
from world_server.observer.frame import FrameCollector

ENGINES = ("inprocess", "zenoh")


@dataclass(frozen=True)
class RunResult:
    """A run's summary (the ``swarm run --json`` object) and its time series: collected as
    it went (``collector``, a run in this process), or in its ``recording``."""

    summary: dict[str, Any]
    collector: FrameCollector | None = field(default=None, repr=False)
    recording: Path | None = None

    @property
    def ended(self) -> str:
        return str(self.summary["ended"])

    @property
    def digest(self) -> str:
        """The run's digest: equal for the same run on any engine or machine."""
        return str(self.summary["digest"])

    @property
    def plugins(self) -> dict[str, Any]:
        """What made it: each plug-in's name, distribution, version and source hash."""
        found: dict[str, Any] = self.summary["config"].get("plugins", {})
        return found

    def robots(self) -> Any:
        """The per-robot results as a pandas DataFrame, one row per robot."""
        return frames.pandas_module().DataFrame(self.summary["per_robot"])

    def frame(self, *, swarm: bool = False) -> Any:
        """The run's time series as a pandas DataFrame (``frames.time_series``): one row per
        robot per sample, or with ``swarm`` one row per sample."""
        run_id = str(self.summary.get("run_id", ""))
        return frames.time_series(run_id, self.collector, self.recording, swarm=swarm)


def run(
    robots: int = 10,
    sites: int = 5,
    seed: int = 0,
    *,
    strategy: str = "paper",
    pooling: str = "mprodop",
    controller: str = "paper",
    engine: str = "inprocess",
    timeout: float | None = None,
    **options: Any,
) -> RunResult:
    """The run ``swarm run --robots ROBOTS --sites SITES --seed SEED ...`` makes, its every
    other option given by name (``drop=0.2``, ``alpha=0.1``, ``threshold=0.99``): in this
    process (``engine="inprocess"``) or as real processes over Zenoh (``"zenoh"``, with
    ``record=PATH`` for a recording). ``strategy``, ``pooling`` and ``controller`` name the
    plug-ins (an installed one's name, or ``package.module:attribute``). ValueError in one
    line for what ``swarm run`` would refuse; a run that ends badly (a plug-in that fails
    ends it crashed, its ``summary["error"]`` saying why) is returned like any other."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    chosen = {
        "robots": robots,
        "sites": sites,
        "seed": seed,
        "strategy": strategy,
        "pooling": pooling,
        "controller": controller,
        "timeout": timeout,
        **options,
    }
    if engine == "zenoh":
        summary = _over_zenoh(tokens(chosen))
        recorded = summary.get("recording")
        return RunResult(summary, recording=Path(recorded) if recorded else None)
    chosen.setdefault("no_record", True)
    made = plan(["--engine", "inprocess", "--quiet", *tokens(chosen)])
    collector = FrameCollector.of_run(made.sites, made.robots, made.seed)
    hooks = EngineHooks(
        config=made.config,
        poses_every=made.switches.world.state_every,
        wall_clock=time.monotonic,
        frame=collector,
    )
    summary = run_plan(made, hooks)
    recorded = summary.get("recording")
    return RunResult(summary, collector, Path(recorded) if recorded else None)


def _over_zenoh(argv: list[str]) -> dict[str, Any]:
    """``swarm run ARGV --json`` in a process of its own: its summary."""
    if "--record" not in argv:
        argv = [*argv, "--no-record"]
    plan(["--engine", "zenoh", *argv])  # refuse here, in one line, what it would refuse
    command = [sys.executable, "-m", "deploy.cli", "run", *argv, "--json", "--quiet"]
    # It dies with this process (its processes with it), as with its launcher.
    environment = {**os.environ, PARENT_ENV: str(os.getpid())}
    done = subprocess.run(command, capture_output=True, text=True, env=environment, check=False)
    lines = done.stdout.strip().splitlines()
    if not lines:
        last = done.stderr.strip().splitlines()[-1:] or ["nothing on standard error"]
        raise RuntimeError(f"swarm run printed no summary (exit {done.returncode}): {last[0]}")
    summary: dict[str, Any] = json.loads(lines[-1])
    return summary


__all__ = ["ENGINES", "RunResult", "run"]
