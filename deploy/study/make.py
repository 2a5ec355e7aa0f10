"""Making one run of a study, in a worker: ``make(run)`` is the task every executor of
``deploy/reports/sweep.py`` is handed, and the record it returns is what the results file
keeps (``result``, the run's wall time).

By kind (``grid.KINDS``):

* ``inprocess``: ``swarm run --engine inprocess`` with the run's options: its options are
  parsed by ``swarm run``'s own parser and planned by its own planner, so the run is the
  one ``swarm run <options>`` makes, over Zenoh or in one process;
* ``comparisons`` and ``lag``: the same, observed (``observe.py``): every site comparison
  judged against the true qualities; every pooling and decision, measured by ``lag.py``;
* ``wellstirred``: a cell of the Section 4 model (100 runs of N agents);
* ``sensing``: no swarm: the camera and the robot's estimator on the best two sites;
* ``zenoh``: ``swarm run`` itself, real processes over Zenoh, in a child process (with
  ``--record`` when its point asks for a recording).

A swarm run's ``result`` is what its summary says about the decision (``digest``); what
depends on the machine (wall time, the recording's place) and what made it (``plugins``:
each plug-in's name, distribution, version and source hash) are kept beside it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from deploy.study.grid import Run

# Wall seconds a run over Zenoh may take beyond its own --wall-timeout before it is
# stopped from outside.
ZENOH_BACKSTOP = 120.0
# A run over Zenoh waits this long for a robot process a busy machine starves, so that the
# run stays in lockstep (and so the same as in one process).
ZENOH_STALL_TIMEOUT = 300.0
# Robots per robot process over Zenoh above this swarm size.
ZENOH_ROBOTS_PER_PROCESS = 50


class RunError(RuntimeError):
    """A run that gave no result: the reason, in one line."""


def make(run: Run) -> dict[str, Any]:
    """One run: ``{"result": ..., "wall_s": ...}`` (and ``recording`` for a recorded run)."""
    _die_with_runner()
    started = time.perf_counter()
    extra: dict[str, Any] = {}
    result = MAKERS[run.kind](run, extra)
    return {"result": result, "wall_s": round(time.perf_counter() - started, 2), **extra}


# The runner's pid, in the environment its worker processes inherit.
RUNNER_ENV = "BESTOFN_STUDY_RUNNER"
_PR_SET_PDEATHSIG = 1


def _die_with_runner() -> None:
    """In a worker process the runner started: be stopped (SIGTERM) when the runner dies,
    even by SIGKILL, so that a killed runner leaves no run going on. Nothing elsewhere (a
    Dask worker, the runner itself with ``--parallel 1``)."""
    import ctypes
    import signal

    runner = os.environ.get(RUNNER_ENV, "")
    if not runner.isdigit() or os.getppid() != int(runner):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if os.getppid() != int(runner):  # the runner died before the request
        os.kill(os.getpid(), signal.SIGTERM)


# --- what a swarm run gave -----------------------------------------------------------------


def verdict(summary: dict[str, Any]) -> str:
    """correct | wrong (the honest robots all on one other site) | split (all decided,
    not on one site) | undecided (some had not decided when the run ended)."""
    if summary["correct"]:
        return "correct"
    if summary["consensus"]:
        return "wrong"
    honest = [robot["decided_site"] for robot in summary["per_robot"] if not robot["byzantine"]]
    return "split" if all(site is not None for site in honest) else "undecided"


def digest(summary: dict[str, Any]) -> dict[str, Any]:
    """What a run's summary says about its decision: the fields a check compares. Not the
    radio's counts: over Zenoh the robots go on broadcasting for the few ticks the
    launcher takes to see that the run ended, so they are not the seed's alone."""
    robots = summary["per_robot"]
    honest = [robot for robot in robots if not robot["byzantine"]]
    steps = [robot["steps"] for robot in robots if robot["steps"] is not None]
    result: dict[str, Any] = {
        "ended": summary["ended"],
        "consensus": bool(summary["consensus"]),
        "correct": bool(summary["correct"]),
        "verdict": verdict(summary),
        "best_site": summary["best_site"],
        "chosen_site": summary["chosen_site"],
        "sim_time_s": float(summary["sim_time_s"]),
        "timed_out": bool(summary["timed_out"]),
        "undecided": sum(robot["decided_site"] is None for robot in honest),
        "slowest_steps": max(steps) if steps else None,
        "stalls": int(summary["world"]["stalls"]),
        "departures": int(summary["world"].get("departures", 0)),
        "digest": summary["digest"],
        "robots": {
            "steps": [robot["steps"] for robot in robots],
            "decided_site": [robot["decided_site"] for robot in robots],
            "decision_time_s": [robot["decision_time_s"] for robot in robots],
            "pools": [robot["pool_sizes"] for robot in robots],
            "byzantine": [robot["byzantine"] for robot in robots],
        },
    }
    liar_sites = {
        int(mode.partition("=")[2])
        for robot in robots
        if (mode := robot["byzantine"]) and mode.startswith("liar=")
    }
    if len(liar_sites) == 1:
        (site,) = liar_sites
        result["liar_site"] = site
        result["liar_won"] = result["verdict"] == "wrong" and summary["chosen_site"] == site
        result["liar_site_decided"] = sum(robot["decided_site"] == site for robot in honest)
    return result


# --- swarms in this process ----------------------------------------------------------------


class _Refusing(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise RunError(f"swarm run option: {message}")


def plan_of(run: Run) -> Any:
    """The ``swarm run --engine inprocess`` plan of the run's options (its RunPlan)."""
    from deploy.launcher.options import add_arguments
    from deploy.launcher.plan import plan_from_args

    parser = _Refusing(prog="swarm run")
    add_arguments(parser)
    args = parser.parse_args(
        [*run.options, "--engine", "inprocess", "--no-record", "--quiet", "--run-id", run.study]
    )
    try:
        return plan_from_args(args)
    except ValueError as error:
        raise RunError(f"swarm run option: {error}") from None


def configs_of(run: Run) -> tuple[Any, Any, Any]:
    """The world's, the controllers' and the beacon's configs of the run: those of its
    options, with its ``configs`` overrides (``spec.max_wheel_speed``, ``controller.dwell``)."""
    plan = plan_of(run)
    world = plan.switches.world.world
    controller = plan.switches.controller
    beacon = plan.switches.beacon
    for name, value in run.configs:
        part, _, field = name.partition(".")
        if part == "spec":
            world = dataclasses.replace(
                world, spec=dataclasses.replace(world.spec, **{field: value})
            )
        elif part == "world":
            world = dataclasses.replace(world, **{field: value})
        elif part == "controller":
            controller = dataclasses.replace(controller, **{field: value})
        elif part == "beacon":
            beacon = dataclasses.replace(beacon, **{field: value})
        else:
            raise RunError(f"config {name}: give spec., world., controller. or beacon.FIELD")
    return world, controller, beacon


def _engine_run(run: Run, **observe: Any) -> dict[str, Any]:
    """The run in this process (``run_in_process``), observed as ``observe`` says."""
    from deploy.inprocess.engine import EngineHooks, run_in_process

    plan = plan_of(run)
    world, controller, beacon = configs_of(run)
    hooks = EngineHooks(
        config=plan.config,
        poses_every=plan.switches.world.state_every,
        wall_timeout=run.wall_limit,
        since_launch=_since(time.monotonic()),
        wall_clock=time.monotonic,
    )
    summary = run_in_process(
        world,
        controller,
        beacon,
        timeout=plan.timeout,
        # With overridden configs the engine works out the watchdog's window from them.
        stall_window=None if run.configs else plan.stall_window,
        byzantine_robots=plan.byzantine_robots,
        hooks=hooks,
        plugins=plan.plugins,
        **observe,
    )
    _refuse_wall_timeout(run, summary)
    return summary


def _refuse_wall_timeout(run: Run, summary: dict[str, Any]) -> None:
    """A run given up at its wall limit says how fast the machine was, not what the run
    gives: it is no result."""
    if summary.get("timeout_kind") == "wall":
        raise RunError(f"given up after {run.wall_limit:g} wall seconds (its point's limit)")


def _since(start: float) -> Callable[[], float]:
    return lambda: time.monotonic() - start


def keep_plugins(summary: dict[str, Any], extra: dict[str, Any]) -> None:
    """What made the run (its plug-ins' names, versions and sources), for its row."""
    plugins = summary.get("config", {}).get("plugins")
    if plugins is not None:
        extra["plugins"] = plugins


def make_inprocess(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    summary = _engine_run(run)
    keep_plugins(summary, extra)
    return digest(summary)


def make_comparisons(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    from deploy.study.observe import comparing_controller, judge_comparisons

    qualities: dict[int, float] = {}

    def learn_qualities(world: Any) -> None:
        if not qualities:
            qualities.update({site.id: site.quality for site in world.layout.sites})

    log: list[tuple[int, Any]] = []
    summary = _engine_run(
        run, on_tick=learn_qualities, controller_factory=comparing_controller(log)
    )
    keep_plugins(summary, extra)
    return digest(summary) | judge_comparisons(log, qualities, summary["best_site"])


def make_lag(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    from deploy.study import lag
    from deploy.study.observe import pooling_controller

    registry: dict[str, Any] = {"controllers": [], "poolings": [], "decisions": []}
    summary = _engine_run(run, controller_factory=pooling_controller(registry))
    keep_plugins(summary, extra)
    result = digest(summary)
    result["lag"] = (
        lag.analyse(
            summary["num_sites"], summary["per_robot"], registry["poolings"], registry["decisions"]
        )
        if summary["ended"] == "consensus"
        else None
    )
    return result


# --- the Section 4 model, and the camera alone ---------------------------------------------

WELLSTIRRED_AGENTS = 100
WELLSTIRRED_GROUP = 3  # the paper's pool k, dmmd's group (itself and 2 neighbours)
WELLSTIRRED_RUNS = 100
WELLSTIRRED_STEPS = 2000


def make_wellstirred(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    """One cell of the Section 4 model: 100 runs of 100 agents, groups of 3, for the
    run's ``strategy`` and ``options``; each run's steps and success."""
    from robot_agent.wellstirred.model import Model, cell_rng, simulate
    from robot_agent.wellstirred.voting import VoteModel, simulate_votes, vote_cell_rng

    strategy, options = str(run.param("strategy")), int(run.param("options"))
    if strategy == "paper":
        model = Model(options, WELLSTIRRED_GROUP, WELLSTIRRED_AGENTS, steps=WELLSTIRRED_STEPS)
        outcome = simulate(model, WELLSTIRRED_RUNS, cell_rng(run.seed, model))
    else:
        vote = VoteModel(
            strategy,  # type: ignore[arg-type]  # checked by VoteModel
            options,
            WELLSTIRRED_GROUP,
            WELLSTIRRED_AGENTS,
            steps=WELLSTIRRED_STEPS,
        )
        outcome = simulate_votes(vote, WELLSTIRRED_RUNS, vote_cell_rng(run.seed, vote))
    return {
        "agents": WELLSTIRRED_AGENTS,
        "group": WELLSTIRRED_GROUP,
        "steps_limit": WELLSTIRRED_STEPS,
        "times": [int(t) for t in outcome.times],
        "success": [bool(s) for s in outcome.success],
    }


SENSING_FRAMES = 300


def make_sensing(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    """The best and second-best site of seed ``run.seed``'s layout (10 robots, 10 sites),
    seen from their viewpoints: 300 frames each, rendered and read as in a run (the world's
    camera, the robot's vision), at pixel noise ``sigma`` and lighting ``lighting``."""
    import math
    import statistics

    from bestofn_swarm.wire.rng import Stream, seed_of
    from robot_agent.core import vision
    from robot_agent.core.controller import ControllerConfig
    from world_server.core.camera import CameraNoise, CameraRenderer
    from world_server.core.layout import make_layout
    from world_server.core.world import DEFAULT_CAMERA

    sigma, lighting = float(run.param("sigma")), float(run.param("lighting"))
    layout = make_layout(10, 10, seed=run.seed)
    best, second = sorted(layout.sites, key=lambda site: site.rank)[:2]
    radius = layout.arena_radius - ControllerConfig().view_distance
    renderer = CameraRenderer(
        layout, DEFAULT_CAMERA, noise=CameraNoise(sigma, lighting), seed=seed_of(run.seed, "camera")
    )
    rng = Stream.named(run.seed, "frames")
    readings: list[list[float]] = []
    missed = 0
    for site in (best, second):
        x, y = radius * math.cos(site.angle), radius * math.sin(site.angle)
        values = []
        for _ in range(SENSING_FRAMES):
            quality = vision.estimate_quality(renderer.render(x, y, site.angle, rng=rng))
            if quality is None:
                missed += 1
            else:
                values.append(quality)
        readings.append(values)
    pairs = list(zip(*readings, strict=False))

    def spread(values: list[float]) -> dict[str, float | None]:
        if not values:
            return {"mean": None, "sd": None}
        return {"mean": statistics.fmean(values), "sd": statistics.pstdev(values)}

    return {
        "frames": SENSING_FRAMES,
        "best_quality": best.quality,
        "second_quality": second.quality,
        "best": spread(readings[0]),
        "second": spread(readings[1]),
        "missed": missed,
        "swapped": sum(a < b for a, b in pairs),
        "pairs": len(pairs),
    }


# --- real processes ------------------------------------------------------------------------


def zenoh_command(run: Run) -> list[str]:
    """``swarm run`` with the run's options, over Zenoh: the summary as JSON, no display;
    hosted robots above ``ZENOH_ROBOTS_PER_PROCESS``; a recording if the point asks."""
    command = [sys.executable, "-m", "deploy.cli", "run", *run.options, "--json", "--quiet"]
    if "--stall-timeout" not in run.options:
        command += ["--stall-timeout", f"{ZENOH_STALL_TIMEOUT:g}"]
    robots = int(run.param("robots")) if "robots" in dict(run.params) else 10
    if robots > ZENOH_ROBOTS_PER_PROCESS and "--robots-per-process" not in run.options:
        command += ["--robots-per-process", str(ZENOH_ROBOTS_PER_PROCESS)]
    if run.record and run.record_to is not None:
        command += ["--record", run.record_to]
    else:
        command += ["--no-record"]
    if run.wall_limit is not None:
        command += ["--wall-timeout", f"{run.wall_limit:g}"]
    return command


def make_zenoh(run: Run, extra: dict[str, Any]) -> dict[str, Any]:
    from bestofn_swarm.plumbing.lifecycle import PARENT_ENV

    command = zenoh_command(run)
    # swarm run dies with this worker (its processes with it), as it does with its launcher.
    environment = {**os.environ, PARENT_ENV: str(os.getpid())}
    limit = None if run.wall_limit is None else run.wall_limit + ZENOH_BACKSTOP
    try:
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=limit, env=environment, check=False
        )
    except subprocess.TimeoutExpired:
        raise RunError(f"swarm run still going after {limit:g} wall seconds: stopped") from None
    lines = done.stdout.strip().splitlines()
    if not lines:
        last = done.stderr.strip().splitlines()[-1:] or ["nothing on stderr"]
        raise RunError(f"swarm run printed no summary (exit {done.returncode}): {last[0]}")
    summary = json.loads(lines[-1])
    if summary["ended"] not in RESULT_ENDINGS:
        raise RunError(f"swarm run ended {summary['ended']} (exit {done.returncode})")
    _refuse_wall_timeout(run, summary)
    keep_plugins(summary, extra)
    if run.record_to is not None and Path(run.record_to).is_file():
        extra["recording"] = {"path": run.record_to, "bytes": Path(run.record_to).stat().st_size}
    return digest(summary)


RESULT_ENDINGS = ("consensus", "split", "stalled", "timeout")

MAKERS: dict[str, Callable[[Run, dict[str, Any]], dict[str, Any]]] = {
    "inprocess": make_inprocess,
    "comparisons": make_comparisons,
    "lag": make_lag,
    "wellstirred": make_wellstirred,
    "sensing": make_sensing,
    "zenoh": make_zenoh,
}
