"""``swarm run``: a whole swarm on this machine, to a stated ending.

Starts the world server (the Zenoh router of the run, on a Unix socket in a private
directory; TLS on loopback with ``--secure``; a client of the router ``--connect`` names),
the recorder, the nest beacon and the robot processes (``supervisor.py``; with ``--dask``
the robot processes on a Dask cluster's workers, ``dask_placement.py``); follows what
they publish (``follower.py``) and shows progress (``console.py``); kills and restarts
robots when their ``--kill`` and ``--restart`` sim time comes (the faults' plug-ins,
robot_agent/core/faults.py, given the launcher as their ``Engine``); stops when the world
ends the run (``world/ending``: world_server/observer/referee.py decides) or when what
only the launcher sees ends it first, in the order of
``bestofn_swarm.wire.endings.stop_reason``; stops every process it started, by pid,
however the run ends; prints a summary that says how it ended (the world's, with what the
launcher adds), hands it to the recorder (``recording.py``) and exits with that ending's
code (``swarm run --help``). ``--engine inprocess`` runs the same computation in this
process instead (``inprocess.py``).

The main thread owns the run. It waits on one inbox, into which Zenoh's callbacks queue
what the processes publish and the stop signals' relay queues the signals
(``signals.py``), until the next look is due; it takes what came, applies the faults
that fell due, and every ``LOOK_EVERY`` (at once on a signal) it looks: takes the world's
ending if it came, else marks the robots whose process died, updates the display, and
asks the ending rule.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import queue
import signal
import sys
import time
from collections.abc import Callable
from typing import Any

from rich.console import Console

from bestofn_swarm.plumbing.cliargs import UsageError
from bestofn_swarm.plumbing.ending import MAX_ENDING_SAMPLE_BYTES
from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.plumbing.lifecycle import die_with_launcher
from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.endings import Ending, Halt, Look, Stop, stop_reason
from deploy.launcher.console import decided_progress, describe_ending, print_summary, say
from deploy.launcher.follower import Follower, Heard
from deploy.launcher.inprocess import run_inprocess
from deploy.launcher.options import add_arguments
from deploy.launcher.plan import RunPlan, plan_from_args
from deploy.launcher.processes import Child
from deploy.launcher.recording import RecorderProgress, finish_recording
from deploy.launcher.signals import Signalled, StopSignals
from deploy.launcher.supervisor import OBSERVERS, StartError, Supervisor
from robot_agent.core import faults
from world_server.core.layout import make_layout

__all__ = ["add_arguments", "run"]

log = logging.getLogger("swarm.run")

# Wall seconds between two looks at the run. Looks are paced rather than made on every
# message: what they check costs a system call per robot process, and a process's death
# comes as no message at all.
LOOK_EVERY = 0.1
# What the launcher takes in (status, clock, state, acks, the ending), at most: junk cannot
# grow it.
EVENTS_BYTES, MAX_EVENT_BYTES = 64 * 2**20, MAX_ENDING_SAMPLE_BYTES
# Wall seconds the launcher waits for the run's ending once a process of the run exited on
# its own: robots and the beacon exit when they hear the ending, maybe before it does.
ENDING_GRACE = 2.0


class Swarm:
    """One local run as the main loop holds it: its processes (``supervisor``), what is
    known of it (``follower``), the faults to come, and the inbox between them."""

    def __init__(
        self,
        plan: RunPlan,
        echo: Callable[[str, str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.plan = plan
        self.clock = clock
        self.launched_at = clock()
        self.inbox: BoundedInbox[Heard | Signalled] = BoundedInbox(EVENTS_BYTES, MAX_EVENT_BYTES)
        self.supervisor = Supervisor(plan, self.inbox, echo)
        self.follower = Follower(plan, clock)
        self.faults = faults.Schedule(plan.faults)
        self.crash: Child | None = None  # the process whose death ended the run
        self.plugin_failure: str | None = None  # a robot's plug-in failed: its one line
        self.ended_at: float | None = None
        self.departures = 0  # the world's count before the swarm was stopped (stopping adds)
        self.world_ended = False  # the run ended by the world's ending (world/ending)
        self.lost_workers: list[Any] = []  # --dask: workers that left before any ending
        self._exits_seen: set[int] = set()  # processes seen to exit on their own

    def signalled(self, signum: int) -> None:
        """A stop signal, from the signals' relay: an event like any other."""
        self.inbox.put(Signalled(signum), control=True)

    @property
    def wall_deadline(self) -> float:
        """When ``--wall-timeout`` falls due (the time the live page held or paused the run
        is not counted)."""
        if self.plan.wall_timeout is None or self.follower.paused:
            return math.inf
        return self.launched_at + self.follower.paused_for() + self.plan.wall_timeout

    def take_events(self, until: float) -> bool:
        """Take in what came, waiting for it until the wall time ``until``; whether a stop
        signal came."""
        try:
            item = self.inbox.get(timeout=max(0.0, until - self.clock()))
        except queue.Empty:
            return False
        signalled = False
        while True:
            if isinstance(item, Signalled):
                signalled = True
            else:
                self.follower.take(item, self.supervisor.keyring)
            try:
                item = self.inbox.get(timeout=0)
            except queue.Empty:
                break
        self.follower.run.rejected += self.inbox.take_dropped(None)
        return signalled

    def inject_due_faults(self) -> None:
        """Apply the faults whose sim time has come (this is a tick boundary: the world
        said its new sim time)."""
        for applied in self.faults.apply_due(self, self.follower.run.sim_time):
            log.info(
                "%s robot %d at sim time %.1f", applied.action, applied.robot, applied.applied_at_s
            )

    # --- faults.Engine: what a fault may do to this run -------------------------------

    def kill(self, robot: int) -> bool:
        """SIGKILL the robot's process; whether it was running."""
        was_running = self.supervisor.kill_robot(robot)
        self.follower.run.killed(robot)
        return was_running

    def restart(self, robot: int) -> None:
        """A fresh process for the robot (killed first)."""
        self.follower.run.restarted(robot)
        self.supervisor.restart_robot(robot)

    def look(self, signalled: bool) -> Halt | None:
        """Whether the run stops now, and why (``bestofn_swarm.wire.endings.stop_reason``):
        the world's ending, once heard, for what the world decides (every running robot
        decided, the sim time limit, the stall watchdog, a lost beacon or robot); a process
        that died, a stop signal, a world that stopped ticking and the wall time limit are
        the launcher's to see."""
        supervisor, follower, run = self.supervisor, self.follower, self.follower.run
        placement = supervisor.placement
        lost = placement.lost() if placement is not None else []
        if follower.ending is None and (self._exited() or len(lost) > len(self.lost_workers)):
            signalled = self._await_ending() or signalled
        ending = follower.ending
        if ending is None:  # a process that exits after the ending did so because of it
            for robot in supervisor.crashed_robots():
                run.crashed(robot)
            self.crash = supervisor.infrastructure_crash()
            if self.crash is None and follower.paused:  # held for a page gone for good
                self.crash = supervisor.crashed_observer("viewer")
            if self.plugin_failure is None:
                self.plugin_failure = supervisor.plugin_failure()
            self.lost_workers = list(lost)
        world = Halt(ending.stop, ending.timeout_kind) if ending is not None else None
        halt = stop_reason(
            Look(
                sim_time=run.sim_time,
                sim_limit=math.inf,  # the world's to judge (world.ended)
                all_decided=False,
                last_decision=0.0,
                stalled=False,
                wall_time=self.clock() - self.launched_at - follower.paused_for(),
                wall_limit=self.plan.wall_timeout,
                crashed=self.crash is not None
                or self.plugin_failure is not None
                or bool(self.lost_workers),
                signalled=signalled,
                world_stopped=follower.world_stopped(self.plan.world_stop_window),
                ended=world,
            )
        )
        self.world_ended = halt is not None and halt is world
        return halt

    def _exited(self) -> bool:
        """A process of the run (not an observer) exited on its own since the last look."""
        exited = {
            child.pid for child in self.supervisor.group.crashed() if child.name not in OBSERVERS
        }
        new = bool(exited - self._exits_seen)
        self._exits_seen |= exited
        return new

    def _await_ending(self) -> bool:
        """Take in what comes for ENDING_GRACE, or until the world's ending came; whether a
        stop signal came meanwhile."""
        deadline = self.clock() + ENDING_GRACE
        signalled = False
        while self.follower.ending is None and self.clock() < deadline:
            signalled = self.take_events(until=deadline) or signalled
        return signalled

    def stop(self) -> protocol.WorldState | None:
        """Stop the robots and the beacon, and read the world's final counters (its last
        state if it does not answer; none needed once the world ended the run: its ending
        holds them)."""
        supervisor, follower, run = self.supervisor, self.follower, self.follower.run
        self.ended_at = self.clock()
        if self.world_ended:
            supervisor.stop_swarm()  # most exited on the ending already
            self.take_events(until=self.clock())
            return None
        # A world whose clock stopped (frozen, or stuck) cannot answer: its last state is
        # all there is, without waiting out a question it will not hear.
        answering = not follower.world_stopped(self.plan.world_stop_window)
        if answering and supervisor.world is not None and supervisor.world.alive():
            before = supervisor.query_world_stats() or run.last_state
            self.departures = before.departures if before else 0
        elif not answering and run.last_state is not None:
            self.departures = run.last_state.departures
        supervisor.stop_swarm()
        self.take_events(until=self.clock())  # what they said last
        stats = supervisor.world_stats() if answering and supervisor.world_running() else None
        return stats or run.last_state


def run(args: argparse.Namespace) -> int:
    if args.engine == "inprocess":
        return run_inprocess(args)
    try:
        plan = plan_from_args(args)
    except ValueError as error:
        raise UsageError(str(error)) from None
    console = Console(stderr=True)
    echo = (
        (lambda name, line: console.print(f"[dim]{name}:[/] {line}", highlight=False))
        if args.verbose
        else None
    )
    # Started by `swarm experiment`: end in order if it dies (a SIGTERM then: signals.py).
    die_with_launcher()
    swarm = Swarm(plan, echo)
    with StopSignals(notify=swarm.signalled) as signals:
        try:
            return _run_swarm(swarm, args, console, signals)
        finally:
            swarm.supervisor.close()


def _run_swarm(
    swarm: Swarm, args: argparse.Namespace, console: Console, signals: StopSignals
) -> int:
    try:
        started = swarm.supervisor.start(stopping=lambda: signals.received is not None)
        page = swarm.plan.page
        if started and page is not None and swarm.plan.hold and not args.quiet:
            print(
                f"swarm run: the swarm waits at tick 0 until a browser opens {page.url} "
                "(--no-wait starts it at once)",
                file=sys.stderr,
                flush=True,
            )
        halt = _watch(swarm, signals, console, args.quiet) if started else None
    except StartError as error:
        print(f"swarm run: could not start: {error}", file=sys.stderr)
        if error.child is not None and error.child.tail():
            print(error.child.tail(), file=sys.stderr)
        return Ending.CRASHED.code
    if halt is None:  # a stop signal came while the processes were starting
        halt = Halt(Stop.INTERRUPTED)
    signum = signals.received if halt.stop is Stop.INTERRUPTED else None
    code = _finish(swarm, args, halt, signum)
    if signum is None:
        _linger(swarm, signals, args.quiet)
    return code


def _linger(swarm: Swarm, signals: StopSignals, quiet: bool) -> None:
    """Keep the live page up with the run's result, until a stop signal or the end of
    ``--view-linger`` (the robots are stopped; the world, the recorder and the page stay)."""
    page, linger = swarm.plan.page, swarm.plan.view_linger
    if page is None or linger == 0 or not swarm.supervisor.observer_alive("viewer"):
        return
    if not quiet:
        until = "Ctrl-C ends it" if linger is None else f"for {linger:g} s (--view-linger)"
        print(f"swarm run: the page stays up at {page.url}: {until}", file=sys.stderr, flush=True)
    deadline = math.inf if linger is None else swarm.clock() + linger
    while signals.received is None and swarm.clock() < deadline:
        if not swarm.supervisor.observer_alive("viewer"):
            return
        time.sleep(min(LOOK_EVERY, max(0.0, deadline - swarm.clock())))


def _watch(swarm: Swarm, signals: StopSignals, console: Console, quiet: bool) -> Halt:
    """Follow the run until the ending rule stops it."""
    plan, follower, run = swarm.plan, swarm.follower, swarm.follower.run
    progress = decided_progress(console, quiet)
    with progress:
        task = progress.add_task("decided", total=plan.robots, info="starting")
        next_look = swarm.clock() + LOOK_EVERY
        while True:
            # Until the next look or the wall limit; a fault falls due with a clock message.
            signalled = swarm.take_events(until=min(next_look, swarm.wall_deadline))
            swarm.inject_due_faults()
            now = swarm.clock()
            if not signalled and now < min(next_look, swarm.wall_deadline):
                continue
            next_look = now + LOOK_EVERY
            started_at = follower.started_at
            elapsed = now - started_at - follower.paused_for() if started_at is not None else 0.0
            factor = run.sim_time / elapsed if elapsed > 0 else 0.0
            if follower.held:
                info = "waiting at tick 0 for a browser on the live page"
            elif started_at is None:
                info = "waiting for the robots to join"
            else:
                info = (
                    f"{run.decided()}/{plan.robots} decided, {run.trips()} trips, "
                    f"sim {run.sim_time:.0f}s, "
                    + (
                        "paused from the live page"
                        if follower.paused
                        else f"{factor:.0f}x real time"
                    )
                )
            progress.update(task, completed=run.decided(), info=info)
            halt = swarm.look(signals.received is not None)
            if halt is not None:
                return halt


def _finish(swarm: Swarm, args: argparse.Namespace, halt: Halt, signum: int | None) -> int:
    """Stop the swarm, build and print the summary, finish the recording; the exit code."""
    plan, supervisor, follower = swarm.plan, swarm.supervisor, swarm.follower
    if signum is not None:
        print(
            f"swarm run: {signal.Signals(signum).name}: stopping every process",
            file=sys.stderr,
        )
    if swarm.crash is not None:
        print(
            f"swarm run: the {swarm.crash.name} process crashed (exit code "
            f"{swarm.crash.process.returncode}):\n{swarm.crash.tail()}",
            file=sys.stderr,
        )
    ending = follower.ending
    if swarm.world_ended and ending is not None and not _crashes_unseen(swarm, ending):
        swarm.stop()
        summary = launcher_summary(swarm, ending)
        code = ending.code
    else:
        summary = _own_summary(swarm, halt, signum)
        code = Ending(summary["ended"]).exit_code(signum)
    robot_crashes = [robot["id"] for robot in summary["per_robot"] if robot["crashed"]]
    _name_lost_hosts(swarm, summary)
    supervisor.finish_observers(summary)
    if not args.quiet:
        print(f"swarm run: {describe_ending(summary)}", file=sys.stderr)
    problem = _finish_recording(swarm, summary, args.quiet)
    if problem is not None:
        print(f"swarm run: the recorder did not confirm {plan.record}: {problem}", file=sys.stderr)
        summary["recording"] = None
    if args.json:
        print(json.dumps(summary))
    else:
        print_summary(summary, Console())
    if robot_crashes and swarm.plugin_failure is None:
        print(f"swarm run: robot process(es) {robot_crashes} crashed", file=sys.stderr)
    return code


def _counters_of(ending: protocol.RunEnding) -> protocol.WorldState:
    """The world's counters as its ending's summary gives them."""
    summary = ending.summary
    return protocol.WorldState(
        v=protocol.VERSION,
        tick=ending.tick,
        t=ending.t,
        robots=[],
        radio=protocol.RadioCounters(**summary["radio"]),
        rejected=summary["world"]["rejected"],
        stalls=summary["world"]["stalls"],
        departures=summary["world"]["departures"],
    )


def _crashes_unseen(swarm: Swarm, ending: protocol.RunEnding) -> bool:
    """Whether a robot process died that the world's ending does not count as lost: the
    world saw only its token go (maybe a frozen process), the launcher saw it die. The
    launcher's own summary then says so, as before the world ended runs."""
    lost = {robot["id"] for robot in ending.summary.get("per_robot", []) if robot["crashed"]}
    died = {record.id for record in swarm.follower.run.records.values() if record.crashed}
    return bool(died - lost)


def _name_lost_hosts(swarm: Swarm, summary: dict[str, Any]) -> None:
    """--dask: the workers (and their hosts) that left with robots of the run, said on
    stderr and kept in the summary's ``lost_hosts``."""
    placement = swarm.supervisor.placement
    if placement is None:
        return
    lost = swarm.lost_workers or placement.whose(
        [robot["id"] for robot in summary["per_robot"] if robot["crashed"]]
    )
    if not lost:
        return
    summary["lost_hosts"] = [worker.as_dict() for worker in lost]
    for worker in lost:
        print(f"swarm run: lost {worker.describe()}", file=sys.stderr)


def launcher_summary(swarm: Swarm, ending: protocol.RunEnding) -> dict[str, Any]:
    """The run's summary from the world's (``world/ending``), with what only the launcher
    knows: the run's configuration, its processes, the faults it applied, the recording,
    what it refused itself, and its wall time without what the live page held or paused."""
    plan, follower = swarm.plan, swarm.follower
    summary = dict(ending.summary)
    if follower.started_at is not None and swarm.ended_at is not None:
        wall = max(swarm.ended_at - follower.started_at - follower.paused_for(), 1e-9)
        summary["wall_time_s"] = round(wall, 3)
        summary["real_time_factor"] = round(ending.t / wall, 2)
    summary["config"] = plan.config
    summary["robot_processes"] = swarm.supervisor.robot_processes
    summary["rejected"] = {**summary.get("rejected", {}), "observer": swarm.follower.run.rejected}
    summary["faults"] = [applied.record() for applied in swarm.faults.applied]
    summary["recording"] = str(plan.record) if plan.record else None
    return summary


def _own_summary(swarm: Swarm, halt: Halt, signum: int | None) -> dict[str, Any]:
    """The run's summary from what the launcher followed, for an ending it decided itself
    (a process that died, a stop signal, a world that stopped ticking, the wall limit)."""
    plan, follower, run = swarm.plan, swarm.follower, swarm.follower.run
    run.departed(run.outside_present())  # before the bridge stops and every link goes
    stats = swarm.stop()
    ending = follower.ending
    if swarm.world_ended and ending is not None:  # the world's counters at its ending
        stats = _counters_of(ending)
        swarm.departures = stats.departures
    robot_crashes = [record.id for record in run.records.values() if record.crashed]
    stop = halt.stop
    if robot_crashes and stop is not Stop.INTERRUPTED:
        stop = Stop.CRASHED
    started_at = follower.started_at
    wall = (
        (swarm.ended_at or 0.0) - started_at - follower.paused_for()
        if started_at is not None
        else 0.0
    )
    summary = run.summary(
        run_id=plan.run_id,
        num_robots=plan.robots,
        num_sites=plan.sites,
        seed=plan.seed,
        best_site=make_layout(plan.sites, plan.robots, plan.seed).best_site,
        wall_time_s=wall,
        world=stats,
        departures=swarm.departures,
        config=plan.config,
        stop=stop,
        timeout_kind=halt.limit,
        byzantine={robot: str(how) for robot, how in plan.byzantine_robots.items()},
        robot_processes=swarm.supervisor.robot_processes,
    )
    if signum is not None:
        summary["signal"] = signal.Signals(signum).name
    if swarm.plugin_failure is not None:
        summary["error"] = swarm.plugin_failure
    summary["faults"] = [applied.record() for applied in swarm.faults.applied]
    summary["recording"] = str(plan.record) if plan.record else None
    return summary


def _finish_recording(swarm: Swarm, summary: dict[str, Any], quiet: bool) -> str | None:
    """Hand the summary to the recorder; None once it confirmed the file, else why not
    (also when the run records nothing)."""
    plan, supervisor = swarm.plan, swarm.supervisor
    if plan.record is None:
        return None
    recorder = supervisor.recorder
    if supervisor.session is None or recorder is None or not recorder.alive():
        return "it was not running"
    if plan.connect is None and not supervisor.world_running():
        # The world server was the run's router: nothing reaches the recorder any more.
        # Stopped, it closes the file without the summary.
        return "the world server, the run's router, is gone, so it cannot be reached"
    waiting = RecorderProgress(plan.record, recorder.alive, say(quiet))
    return finish_recording(
        supervisor.session, supervisor.keys, supervisor.keyring, waiting, summary
    )
