"""``run``: one swarm run, as ``swarm run`` makes it, from Python."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from bestofn_swarm.api import frames
from bestofn_swarm.api.options import plan, tokens
from bestofn_swarm.plumbing.lifecycle import PARENT_ENV
from deploy.inprocess.engine import EngineHooks, Progress
from deploy.launcher.inprocess import run_plan

ENGINES = ("inprocess", "zenoh")


@dataclass(frozen=True)
class RunResult:
    """A run's summary (the ``swarm run --json`` object) and what was seen of it as it went
    (``samples``: the swarm every ``--state-every`` ticks, in one process)."""

    summary: dict[str, Any]
    samples: tuple[Progress, ...] = field(default=(), repr=False)

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

    def frame(self) -> Any:
        """The run's time series as a pandas DataFrame (``frames.time_series``)."""
        return frames.time_series(self.samples)


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
        return RunResult(_over_zenoh(tokens(chosen)))
    chosen.setdefault("no_record", True)
    made = plan(["--engine", "inprocess", "--quiet", *tokens(chosen)])
    samples: list[Progress] = []
    hooks = EngineHooks(
        config=made.config,
        poses_every=made.switches.world.state_every,
        progress=samples.append,
        wall_clock=time.monotonic,
    )
    summary = run_plan(made, hooks)
    return RunResult(summary, (*samples, *_last_sample(summary, samples)))


def _last_sample(summary: dict[str, Any], samples: list[Progress]) -> tuple[Progress, ...]:
    """The swarm as the run ended, when that came after its last sample."""
    robots = summary["per_robot"]
    decided = sum(robot["decided_site"] is not None for robot in robots)
    end = Progress(summary["sim_time_s"], decided, sum(robot["trips"] for robot in robots))
    if samples and (samples[-1].sim_time >= end.sim_time or samples[-1] == end):
        return ()
    return (end,)


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
