"""``swarm run --engine inprocess``: the whole lockstep run in this one process, for sweeps.

The same World, controllers and beacon as ``swarm run`` (``deploy/inmemory.py``), tick by
tick in the same order, so a seed gives the same per-robot results as over Zenoh; no
processes, no network. The summary (``--json``), the endings and their exit codes, the
progress display and the recording (``--record``, an MCAP file that ``swarm report``
reads) are those of ``swarm run``. What needs processes or a network, or a clock other
than lockstep, is refused with a usage error (``refuse_unsupported``).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from rich.console import Console

from deploy import inmemory
from deploy.run_progress import decided_progress
from deploy.wire_tap import WireTap
from plumbing.cliargs import UsageError
from plumbing.lifecycle import die_with_launcher
from wire import protocol
from wire.endings import Ending
from world_server.core.world import World, WorldConfig
from world_server.recording.writer import McapRecorder, RunDescription, Sample

if TYPE_CHECKING:
    from deploy.launcher import RunPlan

ENGINES = ("zenoh", "inprocess")
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def add_engine_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="zenoh",
        help="zenoh: every robot, the world and the beacon a process of their own, over "
        "Zenoh; inprocess: the same lockstep computation in one process, with the same "
        "summary and per-robot results, for sweeps (no network, no real-time clock, no "
        "robot faults, no live view) (default: zenoh)",
    )


def refuse_unsupported(args: argparse.Namespace) -> None:
    """ValueError naming the first option of ``args`` the in-process engine cannot honour."""
    refused = [
        (args.clock == "realtime", "--clock realtime", "it runs in lockstep only"),
        (bool(args.kill), "--kill", "it acts on a robot's process, and there is none"),
        (bool(args.restart), "--restart", "it acts on a robot's process, and there is none"),
        (args.robots_per_process is not None, "--robots-per-process", "there are no processes"),
        (args.no_batch, "--no-batch", "there are no processes"),
        (args.spawn != "fork", "--spawn", "there are no processes to start"),
        (args.connect is not None, "--connect", "it uses no network"),
        (args.secure, "--secure", "it uses no network"),
        (args.view is not None, "--view", "the live page follows a run over Zenoh"),
        (args.foxglove is not None, "--foxglove", "Foxglove live follows a run over Zenoh"),
        (args.trace is not None, "--trace", "the timeline is of the processes' messages"),
    ]
    for refuse, option, reason in refused:
        if refuse:
            raise ValueError(f"--engine inprocess cannot honour {option}: {reason}")


class _Signals:
    """A stop signal ends the run after the current tick, as interrupted (like Ctrl-C in
    ``swarm run``): the summary and the recording are still written."""

    def __init__(self) -> None:
        self.received: int | None = None

    @contextmanager
    def installed(self) -> Iterator[_Signals]:
        previous = {signum: signal.signal(signum, self._on_signal) for signum in STOP_SIGNALS}
        try:
            yield self
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)

    def _on_signal(self, signum: int, frame: object) -> None:
        if self.received is None:
            self.received = signum


def run_inprocess(args: argparse.Namespace) -> int:
    """``swarm run --engine inprocess``; the exit code of the run's ending."""
    from deploy import launcher  # it imports this module for its options

    launched = time.monotonic()
    try:
        plan = launcher.plan_from_args(args)  # calls refuse_unsupported
    except ValueError as error:
        raise UsageError(str(error)) from None
    die_with_launcher()  # started by `swarm experiment`: end in order if it dies
    switches = plan.switches
    config = switches.world.world
    state_every = switches.world.state_every
    recording = _Recording.open(plan.record, config, plan) if plan.record is not None else None
    signals = _Signals()
    console = Console(stderr=True)
    progress = decided_progress(console, args.quiet)
    task = progress.add_task("decided", total=plan.robots, info="starting")
    started = time.monotonic()

    def show(now: inmemory.Progress) -> None:
        elapsed = time.monotonic() - started
        factor = now.sim_time / elapsed if elapsed > 0 else 0.0
        progress.update(
            task,
            completed=now.decided,
            info=f"{now.decided}/{plan.robots} decided, {now.trips} trips, "
            f"sim {now.sim_time:.0f}s, {factor:.0f}x real time (in-process)",
        )

    hooks = inmemory.EngineHooks(
        stop_signal=lambda: signals.received is not None,
        since_launch=lambda: time.monotonic() - launched,
        wall_timeout=plan.wall_timeout,
        progress=None if args.quiet else show,
        wire=recording.tap(protocol.Keys(plan.run_id), state_every) if recording else None,
        wall_clock=time.monotonic,
        config=plan.config,
        poses_every=state_every,
    )
    try:
        with signals.installed(), progress:
            summary = inmemory.run_in_memory(
                config,
                switches.controller,
                switches.beacon,
                timeout=plan.timeout,
                stall_window=plan.stall_window,
                byzantine_robots=plan.byzantine_robots,
                hooks=hooks,
            )
    except BaseException:
        if recording is not None:
            recording.close(None)
        raise
    ended = Ending(summary["ended"])
    signum = signals.received if ended is Ending.INTERRUPTED else None
    if signum is not None:
        summary["signal"] = signal.Signals(signum).name
    summary["faults"] = []
    summary["recording"] = str(plan.record) if plan.record is not None else None
    if not args.quiet:
        print(f"swarm run: {launcher.describe_ending(summary)}", file=sys.stderr)
    if recording is not None:
        recording.close(summary)
    if args.json:
        print(json.dumps(summary))
    else:
        launcher.print_summary(summary, Console())
    return ended.exit_code(signum)


class _Recording:
    """The MCAP file of an in-process run, written by the recorder's own encoder."""

    def __init__(self, stream: IO[bytes], recorder: McapRecorder) -> None:
        self.stream = stream
        self.recorder = recorder

    @classmethod
    def open(cls, path: Path, config: WorldConfig, plan: RunPlan) -> _Recording:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            stream = path.open("wb")
        except OSError as error:
            raise UsageError(f"--record {path}: {error.strerror}") from None
        run = RunDescription(plan.run_id, plan.seed, plan.robots, plan.sites, plan.config)
        info = World(config).info  # what world/info would answer: dt, robot size, sites
        return cls(stream, McapRecorder(stream, protocol.Keys(plan.run_id), run, info))

    def tap(self, keys: protocol.Keys, state_every: int) -> WireTap:
        record = self.recorder.record

        def put(key: str, payload: bytes, attachment: bytes | None) -> None:
            record(Sample(key, payload, attachment, time.time_ns()))

        return WireTap(keys, put, state_every)

    def close(self, summary: dict[str, Any] | None) -> None:
        """Write the run's metadata record (with the summary, if the run ended) and close."""
        if summary is not None:
            self.recorder.finish(summary, finished_by="swarm run --engine inprocess")
        else:
            self.recorder.finish(finished_by="error")
        self.stream.close()
