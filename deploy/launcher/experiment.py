"""``swarm experiment``: the paper's Section 5 protocol in one command.

For every swarm size N and number of sites n, ``--runs`` runs with seeds ``--seed``,
``--seed + 1``, ...: each is a ``swarm run`` subprocess with its own run id, recorded to
``DIR/<run-id>.mcap``, and all of them share one Zenoh router (``deploy/launcher/router.py``) on a
Unix socket in a private directory, ``--parallel`` at a time. With ``--secure`` each run
is its own TLS router with its own certificates and access control instead (a shared
router would have to trust every run's certificate authority). A progress bar follows
the runs; at the end ``swarm report`` turns the recordings into the figures and the
summary table in DIR. With ``--engine inprocess`` each run is ``swarm run --engine
inprocess`` (one process, no router), handed to an executor (``deploy/reports/sweep.py``):
``--parallel`` local worker processes, or ``--dask [ADDRESS]``; each worker starts the run
as a child process of its own (its signals and output are its own) and sends back its
summary and log, which are written into DIR here. It records into DIR itself when it
can see DIR (a worker on this machine); a worker elsewhere records to a file of its own
and sends the recording back too. Each run's stderr
and JSON summary are kept in ``DIR/logs/``.

Every run ends in a stated way (its summary's ``ended``): each gets ``--wall-timeout``
(the experiment's ``--run-timeout``) and its own stall watchdog, and the report counts
the endings per group. A run that outlives its wall limit by BACKSTOP seconds anyway is
stopped from here. The runs die with the experiment (bestofn_swarm/plumbing/lifecycle.py): each then
stops in order, as on Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, NoReturn

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.cliargs import UsageError
from bestofn_swarm.plumbing.lifecycle import PARENT_ENV
from bestofn_swarm.plumbing.private_files import make_private_folder, open_private, write_private
from bestofn_swarm.wire import shape
from bestofn_swarm.wire.endings import Ending
from deploy.launcher.options import add_engine_option
from deploy.launcher.switches import add_swarm_switches, switches_argv
from deploy.reports import sweep

STOP_GRACE = 30.0  # wall seconds a run has to stop after SIGINT before SIGKILL
RUN_WALL_TIMEOUT = 1800.0  # wall seconds a run of a sweep may take, by default
BACKSTOP = 60.0  # wall seconds past --run-timeout before a run is stopped from here


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.usage = "%(prog)s --out DIR [options] [-- SWARM-RUN-OPTIONS]  (see --help)"
    parser.add_argument(
        "--robots",
        type=cliargs.robots,
        nargs="+",
        default=[shape.DEFAULT_ROBOTS],
        metavar="N",
        help=f"swarm sizes N (default: {shape.DEFAULT_ROBOTS})",
    )
    parser.add_argument(
        "--sites",
        type=cliargs.sites,
        nargs="+",
        default=[5, 8, 10],
        metavar="n",
        help="numbers of sites n (default: 5 8 10, as in the paper)",
    )
    parser.add_argument(
        "--runs",
        type=cliargs.positive_int,
        default=10,
        help="runs per (N, n) (default: 10, as in the paper)",
    )
    parser.add_argument(
        "--seed",
        type=cliargs.seed,
        default=shape.DEFAULT_SEED,
        help=f"seed of the first run; run i uses seed + i - 1 (default: {shape.DEFAULT_SEED})",
    )
    sweep.add_executor_options(parser)
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="directory for recordings, logs and the report",
    )
    parser.add_argument(
        "--name",
        type=cliargs.name,
        default="exp",
        help="run id prefix: <name>-N<robots>-n<sites>-r<run> (default: exp)",
    )
    parser.add_argument(
        "--timeout",
        type=cliargs.positive_float,
        default=None,
        metavar="SIM_SECONDS",
        help="per-run sim time limit, forwarded",
    )
    parser.add_argument(
        "--stall-window",
        type=cliargs.positive_float,
        default=None,
        metavar="SIM_SECONDS",
        help="per-run stall window, forwarded (default: swarm run's)",
    )
    parser.add_argument(
        "--run-timeout",
        "--wall-timeout",
        type=cliargs.positive_float,
        default=RUN_WALL_TIMEOUT,
        metavar="WALL_SECONDS",
        help="each run's wall time limit, forwarded as swarm run --wall-timeout: a run "
        f"that reaches it ends as timeout (wall); one that still runs {BACKSTOP:g} s later "
        f"is stopped from here (default: {RUN_WALL_TIMEOUT:g})",
    )
    add_engine_option(parser)
    parser.add_argument(
        "--secure",
        action="store_true",
        help="every run with swarm run --secure: TLS, certificates and access control "
        "made for it, on its own router (docs/security.md)",
    )
    parser.add_argument("--no-report", action="store_true", help="only record the runs")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print the report (runs, groups, failures) as JSON on stdout",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    # Every switch of `swarm run` (decision, radio faults, camera noise, beacon, robot
    # faults) is a switch here too, passed on to every run.
    add_swarm_switches(parser)
    parser.add_argument(
        "run_options",
        nargs=argparse.REMAINDER,
        help="after --: further swarm run options for every run, e.g. -- --robots-per-process 5",
    )


@dataclass(frozen=True)
class RunSpec:
    run_id: str
    robots: int
    sites: int
    seed: int
    argv: list[str]
    recording: Path


@dataclass
class RunResult:
    spec: RunSpec
    returncode: int | None = None
    summary: dict[str, Any] | None = None
    wall_s: float = 0.0
    note: str = ""

    @property
    def ended(self) -> Ending | None:
        """How the run ended, from its summary (None: it printed none)."""
        return Ending.named(self.summary.get("ended")) if self.summary else None

    @property
    def ok(self) -> bool:
        """The run ended in a stated way that is a result (consensus, split, stalled,
        timeout) and was recorded; crashed, interrupted or silent runs failed."""
        return self.ended is not None and self.ended.is_result and self.spec.recording.is_file()


@dataclass
class _Running:
    spec: RunSpec
    process: subprocess.Popen[bytes]
    started: float
    streams: list[IO[bytes]] = field(default_factory=list)


def plan_runs(args: argparse.Namespace, endpoint: str | None) -> list[RunSpec]:
    """Every run of the experiment, in order: by N, then n, then run number; each on the
    shared router at ``endpoint``, or (None) on its own."""
    extra = _run_options(args)
    network = ["--connect", endpoint] if endpoint is not None else []
    if getattr(args, "secure", False):
        network.append("--secure")
    if getattr(args, "engine", "zenoh") != "zenoh":
        network += ["--engine", args.engine]
    specs = []
    for robots in args.robots:
        for sites in args.sites:
            for number in range(1, args.runs + 1):
                seed = args.seed + number - 1
                run_id = f"{args.name}-N{robots}-n{sites}-r{number:02d}"
                recording = args.out / f"{run_id}.mcap"
                argv = [
                    "--robots",
                    str(robots),
                    "--sites",
                    str(sites),
                    "--seed",
                    str(seed),
                    "--run-id",
                    run_id,
                    *network,
                    "--record",
                    str(recording),
                    "--json",
                    "--quiet",
                    *extra,
                ]
                specs.append(RunSpec(run_id, robots, sites, seed, argv, recording))
    return specs


def _run_options(args: argparse.Namespace) -> list[str]:
    extra = switches_argv(args)
    if args.timeout is not None:
        extra += ["--timeout", str(args.timeout)]
    if args.stall_window is not None:
        extra += ["--stall-window", str(args.stall_window)]
    extra += ["--wall-timeout", str(args.run_timeout)]
    options = list(args.run_options)
    if options and options[0] == "--":
        options = options[1:]
    return extra + options


def validate_run_options(spec: RunSpec) -> None:
    """Parse one run's command line as ``swarm run`` would, so mistakes show up now."""
    from deploy.launcher.options import add_arguments
    from deploy.launcher.plan import plan_from_args

    class Probe(argparse.ArgumentParser):
        def error(self, message: str) -> NoReturn:
            raise UsageError(f"swarm run option: {message}")

    probe = Probe(prog="swarm run")
    add_arguments(probe)
    namespace = probe.parse_args(spec.argv)
    try:
        plan_from_args(namespace)
    except ValueError as error:
        raise UsageError(f"swarm run option: {error}") from None


def _start(spec: RunSpec, logs: Path) -> _Running:
    stdout = open_private(logs / f"{spec.run_id}.json", "wb")  # closed in _reap
    stderr = open_private(logs / f"{spec.run_id}.log", "wb")
    process = subprocess.Popen(
        [sys.executable, "-m", "deploy.cli", "run", *spec.argv],
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=stderr,
        env={**os.environ, PARENT_ENV: str(os.getpid())},  # the run dies with us
    )
    return _Running(spec, process, time.monotonic(), [stdout, stderr])


def _reap(running: _Running, logs: Path, note: str = "") -> RunResult:
    for stream in running.streams:
        stream.close()
    result = RunResult(
        running.spec,
        running.process.returncode,
        wall_s=time.monotonic() - running.started,
        note=note,
    )
    text = (logs / f"{running.spec.run_id}.json").read_text().strip()
    if text:
        try:
            result.summary = json.loads(text.splitlines()[-1])
        except ValueError:
            result.note = result.note or "no JSON summary"
    return result


def _stop(running: _Running) -> None:
    """Ask a run to stop (its launcher cleans up on SIGINT), then insist."""
    if running.process.poll() is None:
        running.process.send_signal(signal.SIGINT)
        try:
            running.process.wait(timeout=STOP_GRACE)
        except subprocess.TimeoutExpired:
            running.process.kill()
            running.process.wait()


def _describe(result: RunResult) -> str:
    summary = result.summary
    if not result.ok or summary is None:
        reason = result.note or (result.ended or f"exit {result.returncode}")
        return f"{result.spec.run_id} FAILED ({reason})"
    steps = [robot["steps"] for robot in summary["per_robot"] if robot["steps"] is not None]
    verdict = (
        ("correct" if summary["correct"] else "wrong") if summary["consensus"] else "no consensus"
    )
    return (
        f"{result.spec.run_id}: {result.ended}, {verdict}, "
        f"steps {max(steps) if steps else '-'}, {result.wall_s:.1f}s"
    )


@dataclass(frozen=True)
class InprocessRun:
    """What a worker sends back for one ``--engine inprocess`` run."""

    returncode: int | None
    stdout: str
    stderr: str
    recording: bytes | None
    wall_s: float
    note: str = ""


def run_inprocess_spec(spec: RunSpec, run_timeout: float = RUN_WALL_TIMEOUT) -> InprocessRun:
    """One ``swarm run --engine inprocess`` in a child process of this worker: its output,
    and its recording if the worker cannot see the experiment's directory (it then records
    to a file of its own)."""
    with tempfile.TemporaryDirectory(prefix="swarm-experiment-") as directory:
        in_place = spec.recording.parent.is_dir()
        recording = spec.recording if in_place else Path(directory) / "run.mcap"
        argv = list(spec.argv)
        argv[argv.index("--record") + 1] = str(recording)
        started = time.monotonic()
        note = ""
        process = subprocess.Popen(
            [sys.executable, "-m", "deploy.cli", "run", *argv],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env={**os.environ, PARENT_ENV: str(os.getpid())},  # the run dies with its worker
        )
        try:
            stdout, stderr = process.communicate(timeout=run_timeout + BACKSTOP)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGINT)
            try:
                stdout, stderr = process.communicate(timeout=STOP_GRACE)
            except subprocess.TimeoutExpired:
                process.kill()
                stdout, stderr = process.communicate()
            note = f"stopped from outside after {run_timeout + BACKSTOP:g} wall seconds"
        return InprocessRun(
            process.returncode,
            stdout.decode(errors="replace"),
            stderr.decode(errors="replace"),
            None if in_place or not recording.is_file() else recording.read_bytes(),
            time.monotonic() - started,
            note,
        )


def _inprocess_task(task: tuple[RunSpec, float]) -> InprocessRun:
    return run_inprocess_spec(*task)


def run_all_inprocess(
    specs: Sequence[RunSpec],
    executor: sweep.ExecutorSpec,
    logs: Path,
    run_timeout: float,
    quiet: bool,
) -> list[RunResult]:
    """Every ``--engine inprocess`` run on ``executor``; each run's log, summary and
    recording written here as it comes, a progress bar on stderr."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn

    from bestofn_swarm.plumbing.progress import progress as plain_or_live

    results: list[RunResult] = [RunResult(spec) for spec in specs]
    progress = plain_or_live(
        Console(stderr=True),
        TextColumn("[bold]runs"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        disable=quiet,
    )

    def keep(index: int, run: InprocessRun) -> None:
        spec = specs[index]
        stdout = run.stdout
        if run.recording is not None:  # recorded elsewhere: it is here now
            write_private(spec.recording, run.recording)
        result = RunResult(spec, run.returncode, wall_s=run.wall_s, note=run.note)
        text = stdout.strip()
        if text:
            try:
                result.summary = json.loads(text.splitlines()[-1])
            except ValueError:
                result.note = result.note or "no JSON summary"
        if result.summary is not None and run.recording is not None:
            result.summary["recording"] = str(spec.recording)
            stdout = json.dumps(result.summary) + "\n"
        write_private(logs / f"{spec.run_id}.json", stdout)
        write_private(logs / f"{spec.run_id}.log", run.stderr)
        results[index] = result

    with progress:
        bar = progress.add_task("runs", total=len(specs), info=f"on {executor.describe()}")

        def advance(done: int, total: int, index: int, failure: sweep.Failure | None) -> None:
            if failure is not None:
                results[index] = RunResult(
                    specs[index], note=f"{failure.error} ({failure.attempts} tries)"
                )
            progress.update(bar, completed=done, info=_describe(results[index]))

        tasks = [(spec, run_timeout) for spec in specs]
        sweep.run_sweep(_inprocess_task, tasks, executor, advance, on_result=keep)
    return results


def run_all(
    specs: Sequence[RunSpec], parallel: int, logs: Path, run_timeout: float, quiet: bool
) -> list[RunResult]:
    """Run every spec, ``parallel`` at a time, with a progress bar on stderr."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from bestofn_swarm.plumbing.progress import progress as plain_or_live

    pending = list(specs)
    running: list[_Running] = []
    results: list[RunResult] = []
    progress = plain_or_live(
        Console(stderr=True),
        TextColumn("[bold]runs"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        TextColumn("{task.fields[info]}"),
        disable=quiet,
    )
    try:
        with progress:
            task = progress.add_task("runs", total=len(specs), info="starting")
            while pending or running:
                while pending and len(running) < parallel:
                    running.append(_start(pending.pop(0), logs))
                time.sleep(0.1)
                for item in list(running):
                    # Each run stops itself at run_timeout (--wall-timeout); this is a backstop.
                    overdue = time.monotonic() - item.started > run_timeout + BACKSTOP
                    if item.process.poll() is None and not overdue:
                        continue
                    note = ""
                    if overdue and item.process.poll() is None:
                        _stop(item)
                        note = f"stopped from outside after {run_timeout + BACKSTOP:g} wall seconds"
                    running.remove(item)
                    result = _reap(item, logs, note)
                    results.append(result)
                    progress.update(task, advance=1, info=_describe(result))
    finally:
        for item in running:  # interrupted: stop what is still running, by pid
            _stop(item)
            _reap(item, logs, "interrupted")
    order = {spec.run_id: index for index, spec in enumerate(specs)}
    return sorted(results, key=lambda result: order[result.spec.run_id])


def run(args: argparse.Namespace) -> int:

    from deploy.launcher.processes import ProcessGroup, python_module
    from deploy.reports.report import print_report, report_console, write_report
    from deploy.security.credentials import (
        SOCKET_NAME,
        private_directory,
        socket_endpoint,
        wait_for_socket,
    )

    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} exists and is not a directory")
    executor = sweep.executor_from_args(args)
    on_executor = args.engine == "inprocess" and not args.secure
    if args.dask is not None and not on_executor:
        raise UsageError("--dask runs in-process runs: add --engine inprocess")
    # In-process runs need no network; a secure run is its own TLS router.
    shared_router = args.engine == "zenoh" and not args.secure
    # The shared router's socket does not exist yet: check the runs with a stand-in.
    planned = plan_runs(args, "unixsock-stream/router.sock" if shared_router else None)
    validate_run_options(planned[0])
    taken = sorted(str(spec.recording) for spec in planned if spec.recording.exists())
    if taken:
        raise UsageError(
            f"{len(taken)} recording(s) already in {args.out}, e.g. {taken[0]}: "
            "use another --out or --name"
        )
    logs = args.out / "logs"
    make_private_folder(logs)
    group = ProcessGroup()
    # The shared router listens on a socket only this user can reach.
    private = private_directory() if shared_router else None
    try:
        endpoint = socket_endpoint(private.path) if private is not None else None
        specs = plan_runs(args, endpoint)
        if private is not None and endpoint is not None:
            router = group.start(
                "router", python_module("deploy.launcher.router", "--listen", endpoint)
            )
            if not wait_for_socket(private.path / SOCKET_NAME, 30.0, router.alive):
                print(
                    f"swarm experiment: the router did not start:\n{router.tail()}",
                    file=sys.stderr,
                )
                return 1
        started = time.monotonic()
        if on_executor:
            results = run_all_inprocess(specs, executor, logs, args.run_timeout, args.quiet)
        else:
            results = run_all(specs, args.parallel, logs, args.run_timeout, args.quiet)
        elapsed = time.monotonic() - started
    finally:
        group.stop_all()
        if private is not None:
            private.close()
    failed = [result for result in results if not result.ok]
    for result in failed:
        print(
            f"swarm experiment: {_describe(result)}; see {logs / (result.spec.run_id + '.log')}",
            file=sys.stderr,
        )
    print(
        f"swarm experiment: {len(results) - len(failed)}/{len(specs)} runs recorded in "
        f"{elapsed:.0f}s wall (on {executor.describe()})",
        file=sys.stderr,
    )
    recordings = [result.spec.recording for result in results if result.spec.recording.is_file()]
    output: dict[str, Any] = {
        "wall_time_s": round(elapsed, 1),
        "parallel": args.parallel,
        "failed": [result.spec.run_id for result in failed],
    }
    if not args.no_report and recordings:
        report = write_report(
            recordings,
            args.out,
            warn=lambda text: print(f"swarm report: {text}", file=sys.stderr),
            # A recorder that fell behind leaves no summary in its file: the run's own.
            launcher_summaries={
                result.spec.recording: result.summary for result in results if result.summary
            },
        )
        output.update(report.as_json())
        if not args.json:
            print_report(report, report_console())
    if args.json:
        print(json.dumps(output))
    return 1 if failed else 0
