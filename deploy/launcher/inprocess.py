"""``swarm run --engine inprocess``: the whole lockstep run in this one process, for sweeps.

The world, the robots and the beacon of ``swarm run`` on an in-memory bus
(``deploy/inprocess/engine.py``), so a seed gives the same per-robot results as over Zenoh;
no processes, no network. The summary (``--json``), the endings and their exit codes, the
progress display and the recording (``--record``, an MCAP file that ``swarm report``
reads) are those of ``swarm run``. What needs processes or a network, or a clock other
than lockstep, is refused with a usage error (``refuse_unsupported`` in deploy/launcher/plan.py).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path
from typing import IO, Any

from rich.console import Console

from bestofn_swarm.plumbing.cliargs import UsageError
from bestofn_swarm.plumbing.lifecycle import die_with_launcher
from bestofn_swarm.plumbing.private_files import make_private_folder, open_private
from bestofn_swarm.wire import keyspace
from bestofn_swarm.wire.endings import Ending
from deploy.inprocess import engine
from deploy.launcher.console import decided_progress, describe_ending, print_summary
from deploy.launcher.plan import RunPlan, plan_from_args
from deploy.launcher.signals import StopSignals
from world_server.core.world import World, WorldConfig
from world_server.recording.description import RunDescription
from world_server.recording.writer import McapRecorder, Sample


def run_inprocess(args: argparse.Namespace) -> int:
    """``swarm run --engine inprocess``; the exit code of the run's ending."""
    launched = time.monotonic()
    try:
        plan = plan_from_args(args)  # calls refuse_unsupported
    except ValueError as error:
        raise UsageError(str(error)) from None
    die_with_launcher()  # started by `swarm experiment`: end in order if it dies
    switches = plan.switches
    config = switches.world.world
    state_every = switches.world.state_every
    recording = _Recording.open(plan.record, config, plan) if plan.record is not None else None
    # A stop signal ends the run after the current tick, as interrupted (like Ctrl-C in
    # ``swarm run``): the summary and the recording are still written.
    signals = StopSignals()
    console = Console(stderr=True)
    progress = decided_progress(console, args.quiet)
    task = progress.add_task("decided", total=plan.robots, info="starting")
    started = time.monotonic()

    def show(now: engine.Progress) -> None:
        elapsed = time.monotonic() - started
        factor = now.sim_time / elapsed if elapsed > 0 else 0.0
        progress.update(
            task,
            completed=now.decided,
            info=f"{now.decided}/{plan.robots} decided, {now.trips} trips, "
            f"sim {now.sim_time:.0f}s, {factor:.0f}x real time (in-process)",
        )

    hooks = engine.EngineHooks(
        stop_signal=lambda: signals.received is not None,
        since_launch=lambda: time.monotonic() - launched,
        wall_timeout=plan.wall_timeout,
        progress=None if args.quiet else show,
        tap=recording.tap if recording else None,
        wall_clock=time.monotonic,
        config=plan.config,
        poses_every=state_every,
    )
    try:
        with signals, progress:
            summary = run_plan(plan, hooks)
    except BaseException:
        if recording is not None:
            recording.close(None)
        raise
    ended = Ending(summary["ended"])
    signum = signals.received if ended is Ending.INTERRUPTED else None
    if signum is not None:
        summary["signal"] = signal.Signals(signum).name
    summary["recording"] = str(plan.record) if plan.record is not None else None
    if not args.quiet:
        print(f"swarm run: {describe_ending(summary)}", file=sys.stderr)
    if recording is not None:
        recording.close(summary)
    if args.json:
        print(json.dumps(summary))
    else:
        print_summary(summary, Console())
    return ended.exit_code(signum)


def run_plan(plan: RunPlan, hooks: engine.EngineHooks | None = None) -> dict[str, Any]:
    """The run a plan of ``swarm run --engine inprocess`` describes, in this process and
    thread; its summary (the ``--json`` object but for what the command adds: ``faults``,
    ``recording``, ``signal``). ``hooks``: progress, a stop, a recording, wall time."""
    switches = plan.switches
    bare = engine.EngineHooks(config=plan.config, poses_every=switches.world.state_every)
    return engine.run_in_process(
        switches.world.world,
        switches.controller,
        switches.beacon,
        timeout=plan.timeout,
        stall_window=plan.stall_window,
        byzantine_robots=plan.byzantine_robots,
        robot_faults=plan.faults,
        hooks=hooks or bare,
        plugins=plan.plugins,
    )


class _Recording:
    """The MCAP file of an in-process run, written by the recorder's own encoder."""

    def __init__(self, stream: IO[bytes], recorder: McapRecorder) -> None:
        self.stream = stream
        self.recorder = recorder

    @classmethod
    def open(cls, path: Path, config: WorldConfig, plan: RunPlan) -> _Recording:
        try:
            make_private_folder(path.parent)
            stream = open_private(path, "wb")
        except OSError as error:
            raise UsageError(f"--record {path}: {error.strerror}") from None
        run = RunDescription(plan.run_id, plan.seed, plan.robots, plan.sites, plan.config)
        info = World(config).info  # what world/info would answer: dt, robot size, sites
        return cls(stream, McapRecorder(stream, keyspace.Keys(plan.run_id), run, info))

    def tap(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        """Record one message of the run, as the recorder process would take it."""
        self.recorder.record(Sample(key, payload, attachment, time.time_ns()))

    def close(self, summary: dict[str, Any] | None) -> None:
        """Write the run's metadata record (with the summary, if the run ended) and close."""
        if summary is not None:
            self.recorder.finish(summary, finished_by="swarm run --engine inprocess")
        else:
            self.recorder.finish(finished_by="error")
        self.stream.close()
