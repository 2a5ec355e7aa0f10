"""What ``swarm run`` shows, the same for both engines: the progress display while the run
goes on, then one line on how it ended and the summary's table."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from bestofn_swarm.plumbing.progress import PlainProgress, progress
from bestofn_swarm.wire.endings import Ending, TimeLimit
from world_server.observer.summary import describe


def decided_progress(console: Console, quiet: bool) -> Progress | PlainProgress:
    """A bar of robots decided, with a free-text ``info`` field and the elapsed time;
    it disappears when the run ends (the summary follows). Plain lines when stderr is not
    a terminal (``bestofn_swarm/plumbing/progress.py``)."""
    return progress(
        console,
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        transient=True,
        disable=quiet,
    )


def say(quiet: bool) -> Callable[[str], None] | None:
    """A line on stderr from ``swarm run``, or nothing with ``--quiet``."""
    if quiet:
        return None
    return lambda line: print(f"swarm run: {line}", file=sys.stderr, flush=True)


def describe_ending(summary: dict[str, Any]) -> str:
    """One line: how the run ended, and what held it up."""
    ended = Ending.named(summary["ended"])
    at = f"at sim {summary['sim_time_s']:.0f} s"
    stuck = summary.get("stuck") or []
    undecided = f"; {len(stuck)} robot(s) undecided" if stuck else ""
    if ended is Ending.CONSENSUS:
        return f"ended in consensus on site {summary['chosen_site']} {at}"
    if ended is Ending.SPLIT:
        sites = sorted({r["decided_site"] for r in summary["per_robot"]} - {None})
        return f"ended split: the robots decided on different sites ({sites}) {at}"
    if ended is Ending.STALLED:
        window = summary["config"].get("stall_window")
        quiet = f" for {window:g} s of sim time" if window else ""
        return (
            f"ended stalled {at}: no robot at work completed a step of its task{quiet}{undecided}"
        )
    if ended is Ending.TIMEOUT:
        limit = "wall time limit (--wall-timeout)"
        if summary.get("timeout_kind") != TimeLimit.WALL:
            limit = "sim time limit (--timeout)"
        return f"ended at the {limit} {at}{undecided}"
    if ended is Ending.WORLD_STOPPED:
        window = summary["config"].get("world_stop_window")
        quiet = f" for {window:g} wall seconds" if window else ""
        return f"ended {at}: the world's clock did not advance{quiet}{undecided}"
    if ended is Ending.INTERRUPTED:
        return f"interrupted by {summary.get('signal', 'a signal')} {at}{undecided}"
    error = summary.get("error")
    if error:  # a plug-in failed: its one line says which, where and when
        return f"ended crashed {at}: {error}{undecided}"
    return f"ended crashed {at}: a process of the run died{undecided}"


def print_summary(summary: dict[str, Any], console: Console) -> None:
    robots = summary["per_robot"]
    table = Table(
        title=f"run {summary['run_id']}: {summary['num_robots']} robots, "
        f"{summary['num_sites']} sites, seed {summary['seed']}"
    )
    happened = process_events(summary)
    for column in ("robot", "decided site", "steps", "decision time (s)", "pool sizes"):
        table.add_column(column, justify="right")
    if happened:
        table.add_column("process", justify="left")
    for robot in robots:
        outside = robot.get("outside")
        row = [
            str(robot["id"]) + (f" (outside, {outside})" if outside else ""),
            "-" if robot["decided_site"] is None else str(robot["decided_site"]),
            "-" if robot["steps"] is None else str(robot["steps"]),
            "-" if robot["decision_time_s"] is None else f"{robot['decision_time_s']:.1f}",
            " ".join(map(str, robot["pool_sizes"])) or "-",
        ]
        if happened:
            row.append(happened.get(robot["id"], ""))
        table.add_row(*row)
    console.print(table)
    print_stuck(summary.get("stuck") or [], console)
    steps = [robot["steps"] for robot in robots if robot["steps"] is not None]
    pools = [size for robot in robots for size in robot["pool_sizes"]]
    verdict = (
        f"consensus on site {summary['chosen_site']}, the best"
        if summary["correct"]
        else f"consensus on site {summary['chosen_site']}, NOT the best ({summary['best_site']})"
        if summary["consensus"]
        else "no consensus"
    )
    console.print(
        f"ended: {summary['ended']}; {verdict}{' (timed out)' if summary['timed_out'] else ''}; "
        f"steps to decision {describe(steps)}; pool size {describe(pools)}; "
        f"sim {summary['sim_time_s']:.1f}s in {summary['wall_time_s']:.1f}s wall "
        f"({summary['real_time_factor']:.0f}x); radio sent {summary['radio']['sent']}, "
        f"delivered {summary['radio']['delivered']}, dropped {summary['radio']['dropped']}, "
        f"rejected {summary['radio']['rejected']}; digest {summary['digest']}"
    )
    departures = summary["world"].get("departures", 0)
    if departures:
        console.print(
            f"[yellow]{departures} robot(s) or beacon(s) left while the world ran (killed, "
            "crashed, or their connection lost): a lockstep run is then not the seed's "
            "deterministic one[/]"
        )
    for robot, link in (summary.get("links") or {}).items():
        rtt = "-" if link["rtt_ms"] is None else f"{link['rtt_ms']:.2f}/{link['rtt_p95_ms']:.2f} ms"
        console.print(
            f"robot {robot} outside over {link['transport']} ({link['address']}): round trip "
            f"{rtt} (median/p95), loss {100 * link['loss']:.0f}%, {link['sessions']} "
            f"session(s), {link['refused']} frame(s) refused",
            highlight=False,
        )
    if summary.get("recording"):
        console.print(f"recording: {summary['recording']} (swarm report, or open in Foxglove)")


def process_events(summary: dict[str, Any]) -> dict[int, str]:
    """What happened to each robot's process, in words, for the robots something happened
    to: its kills and restarts at their sim times (``--kill``, ``--restart``), a crash, a
    link that was down at the end (outside robots)."""
    said: dict[int, list[str]] = {}
    for fault in summary.get("faults") or []:
        at = fault.get("applied_at_s", fault.get("at_s"))
        when = f" at {at:.0f} s" if isinstance(at, int | float) else ""
        word = "restarted" if fault.get("action") == "restart" else "killed"
        if word == "killed" or fault.get("was_running", True):
            said.setdefault(int(fault["robot"]), []).append(f"{word}{when}")
        else:
            said.setdefault(int(fault["robot"]), []).append(f"started again{when}")
    for robot in summary["per_robot"]:
        notes = said.setdefault(robot["id"], [])
        if robot.get("killed") and not any(note.startswith("killed") for note in notes):
            notes.append("killed")
        restarts = robot.get("restarts") or 0
        if restarts > sum(1 for note in notes if not note.startswith("killed")):
            notes.append(f"restarted {restarts}x")
        if robot.get("crashed"):
            notes.append("crashed")
        if robot.get("departed"):
            notes.append("link down at the end")
    return {robot: ", ".join(notes) for robot, notes in said.items() if notes}


STUCK_ROWS_SHOWN = 20


def print_stuck(stuck: list[dict[str, Any]], console: Console) -> None:
    """The undecided robots: where each is, the phase it is in and since when, and when it
    last completed a step of its task."""
    if not stuck:
        return
    table = Table(title=f"undecided robots ({len(stuck)})")
    columns = ("robot", "phase", "in it since (sim s)", "position (m)", "trips")
    for column in (*columns, "last progress (sim s)"):
        table.add_column(column, justify="right")
    for robot in stuck[:STUCK_ROWS_SHOWN]:
        position = "-" if robot["x"] is None else f"({robot['x']:.2f}, {robot['y']:.2f})"
        since = robot.get("phase_since_s")  # absent from older summaries
        table.add_row(
            str(robot["id"]),
            robot["phase"] or "-",
            "-" if since is None else f"{since:.1f}",
            position,
            str(robot["trips"]),
            f"{robot['last_progress_s']:.1f}",
        )
    if len(stuck) > STUCK_ROWS_SHOWN:
        table.caption = f"and {len(stuck) - STUCK_ROWS_SHOWN} more (see --json)"
    console.print(table)
