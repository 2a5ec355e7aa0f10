"""``swarm report``: the paper's Section 5 figures and a summary table, from recordings alone.

Reads MCAP recordings made by the recorder (``world_server/recording/writer.py``) one message
at a time with ``world_server/recording/reader.py``, so a file cut short by a crash is read
up to its last complete record.
The run summary comes from the recording's ``bestofn.run`` metadata record when there is
one, else it is rebuilt from the robots' status messages (the same code that
``swarm run`` uses); a recorded summary that lacks a field the report needs gets it from
the rebuilt one, with a warning. Each run is labelled with how it ended (``ended``: see
``world_server/observer/summary.py``); one whose recording says nothing of its end, and
whose robots did not all decide, is labelled ``aborted``. Aggregates over runs (steps, pool sizes)
take only the runs that ended in consensus; the others are counted by ending.
Writes, into ``--out``:

* ``fig4.png``: per run, a box plot of the robots' steps (trips) to decision, one panel
  per group, with the n/2 line (the paper's Figure 4); a group is the runs of one swarm
  size and sites and the same values of every setting that differs between the report's
  runs (``conditions.py``: a ``--drop 0.3`` run is never in a panel of default runs), and
  is labelled by them; each run is named by its id;
* ``fig5.png``: per run, a box plot of pool sizes (the paper's Figure 5);
* ``decided.png``: robots decided over sim time, and ``shares.png``: each site's share of
  the swarm's opinion over sim time; per group, the mean over its runs with a band from the
  lowest to the highest;
* ``fig2.png``: one robot's opinion of every site over sim time (cf. the paper's Fig. 2);
* ``trajectories.png``: the robots' paths in the arena of one run;
* ``summary.csv`` and ``summary.json``: one row per run, with a column for each setting
  that differs between the runs, and aggregates per group.

Its parts, one job each: ``collect.py`` reads a recording, ``rows.py`` makes the run's
summary and its table row and the aggregates, ``audit.py`` counts what a recording misses,
``figures.py`` draws; this module writes the report and is its command line.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing.private_files import make_private_folder, open_private, write_private
from deploy.reports import conditions
from deploy.reports.collect import Recording, read_recording
from deploy.reports.figures import (
    FIGURES,
    _natural,
    plot_boxes,
    plot_decided,
    plot_opinion,
    plot_shares,
    plot_trajectories,
)
from deploy.reports.rows import csv_columns, group_rows, groups_of, report_row, run_summary

# --- the report ----------------------------------------------------------------------------


@dataclass
class Report:
    runs: list[dict[str, Any]]
    groups: list[dict[str, Any]]
    unreadable: list[str]
    files: list[str]
    settings: list[str] = field(default_factory=list)  # those that differ between the runs

    def as_json(self) -> dict[str, Any]:
        return {
            "runs": self.runs,
            "groups": self.groups,
            "settings": self.settings,
            "unreadable": self.unreadable,
            "files": self.files,
        }


def write_report(
    paths: Iterable[Path],
    out: Path,
    *,
    example: str | None = None,
    robot: int | None = None,
    per_run: bool = False,
    warn: Any = None,
    launcher_summaries: Mapping[Path, dict[str, Any]] | None = None,
) -> Report:
    """Read every recording, write the figures and tables into ``out``; a recording
    without the launcher's summary takes it from ``launcher_summaries`` if there."""
    make_private_folder(out)
    recordings: list[Recording] = []
    unreadable: list[str] = []
    for path in paths:
        try:
            recording = read_recording(path, robot)
        except (ValueError, OSError) as error:
            unreadable.append(str(error))
            if warn is not None:
                warn(f"skipping {path}: {error}")
            continue
        if recording.problem and warn is not None:
            warn(f"{path}: {recording.problem}; reporting what was recorded")
        recordings.append(recording)
    launchers = launcher_summaries or {}
    summaries = [
        run_summary(recording, warn, launchers.get(recording.path)) for recording in recordings
    ]
    for recording, summary in zip(recordings, summaries, strict=True):
        if summary["missing_messages"] and warn is not None:
            warn(
                f"{recording.path}: {summary['missing_messages']:,} of the messages its "
                "publishers sent are not in it (a recorder that fell behind drops what it "
                "cannot hold); what is drawn from them has gaps"
            )
    settings = conditions.differing(summaries)
    by_id = sorted(range(len(recordings)), key=lambda i: _natural(summaries[i]["run_id"]))
    # Grouped by size and differing settings, each group's runs by run id.
    order = [
        by_id[i] for members in groups_of([summaries[i] for i in by_id], settings) for i in members
    ]
    recordings = [recordings[i] for i in order]
    summaries = [summaries[i] for i in order]
    runs = [
        report_row(summary, recording.path, settings)
        for summary, recording in zip(summaries, recordings, strict=True)
    ]
    groups = group_rows(runs, summaries, settings)
    members = groups_of(summaries, settings)
    files: list[str] = []
    if recordings:
        labelled = [
            (group["label"], [summaries[i] for i in indices])
            for group, indices in zip(groups, members, strict=True)
        ]
        plot_boxes(labelled, out / "fig4.png", pools=False)
        plot_boxes(labelled, out / "fig5.png", pools=True)
        curves = [
            (group["label"], [recordings[i] for i in indices])
            for group, indices in zip(groups, members, strict=True)
        ]
        plot_decided(curves, out / "decided.png")
        plot_shares(curves, out / "shares.png")
        chosen = _example(recordings, example)
        plot_opinion(chosen, _robot(chosen, robot), out / "fig2.png")
        plot_trajectories(chosen, out / "trajectories.png")
        files += [str(out / name) for name in FIGURES]
        if per_run:
            for recording in recordings:
                folder = out / "runs" / recording.run_id
                make_private_folder(folder)
                plot_opinion(recording, _robot(recording, robot), folder / "opinion.png")
                plot_trajectories(recording, folder / "trajectories.png")
                files += [str(folder / "opinion.png"), str(folder / "trajectories.png")]
    files += [str(out / "summary.csv"), str(out / "summary.json")]
    report = Report(runs, groups, unreadable, files, settings)
    with open_private(out / "summary.csv", "w", newline="") as stream:
        # A run's links (a mapping per outside robot) are for summary.json, not a CSV cell.
        writer = csv.DictWriter(stream, fieldnames=csv_columns(settings), extrasaction="ignore")
        writer.writeheader()
        writer.writerows(runs)
    write_private(out / "summary.json", json.dumps(report.as_json(), indent=2) + "\n")
    return report


def _example(recordings: Sequence[Recording], run_id: str | None) -> Recording:
    if run_id is not None:
        for recording in recordings:
            if recording.run_id == run_id:
                return recording
    return recordings[0]


def _robot(recording: Recording, robot: int | None) -> int:
    if robot is not None:
        return robot
    return 0 if recording.opinion_robot is None else recording.opinion_robot


# --- command line --------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recordings",
        nargs="+",
        type=Path,
        metavar="RUN.mcap",
        help="MCAP recordings of swarm runs (cut-short ones too)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="directory for the figures and the summary table",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print the summary (runs and groups) as one JSON object on stdout",
    )
    parser.add_argument(
        "--example",
        metavar="RUN_ID",
        default=None,
        help="the run shown in fig2.png and trajectories.png (default: the first recording)",
    )
    parser.add_argument(
        "--robot",
        type=int,
        default=None,
        metavar="ID",
        help="the robot whose opinion fig2.png shows (default: the lowest id)",
    )
    parser.add_argument(
        "--per-run",
        action="store_true",
        help="also write an opinion and a trajectories plot for every run",
    )


def run(args: argparse.Namespace) -> int:

    from bestofn_swarm.plumbing.cliargs import UsageError

    missing = [str(path) for path in args.recordings if not path.is_file()]
    if missing:
        raise UsageError(f"no such recording: {', '.join(missing)}")
    if args.robot is not None and args.robot < 0:
        raise UsageError(f"--robot must be a robot id (>= 0), got {args.robot}")
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} exists and is not a directory")

    def warn(text: str) -> None:
        print(f"swarm report: {text}", file=sys.stderr)

    report = write_report(
        args.recordings,
        args.out,
        example=args.example,
        robot=args.robot,
        per_run=args.per_run,
        warn=warn,
    )
    if args.json:
        print(json.dumps(report.as_json()))
    else:
        print_report(report, report_console())
    return 0 if report.runs else 1


REPORT_WIDTH = 200  # characters, when stdout is not a terminal (a log file, a pipe)


def report_console() -> Any:
    """A console for the report: the terminal's width, or wide enough for whole run ids
    and every column when written to a file (rich would assume 80 columns and cut them)."""
    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=REPORT_WIDTH)


def print_report(report: Report, console: Any) -> None:
    from rich.table import Table

    table = Table(title="runs (steps and pool sizes: mean, min-max)")
    table.add_column("run", no_wrap=True)
    for column in ("N", "n", "ended", "consensus", "swarm steps", "robot steps", "pool size"):
        table.add_column(column, justify="right", no_wrap=True)
    table.add_column("digest", no_wrap=True)
    for row in report.runs:
        ended = row["ended"]
        if ended == "timeout" and row.get("timeout_kind"):
            ended += f" ({row['timeout_kind']})"
        if row.get("stuck"):
            ended += f", {row['stuck']} stuck"
        table.add_row(
            row["run_id"] + ("" if row["complete"] else " (cut short)"),
            str(row["robots"]),
            str(row["sites"]),
            ended,
            ("correct" if row["correct"] else "wrong") if row["consensus"] else "none",
            "-" if row["swarm_steps"] is None else str(row["swarm_steps"]),
            "-"
            if row["steps_mean"] is None
            else f"{row['steps_mean']:.1f} {row['steps_min']}-{row['steps_max']}",
            "-"
            if row["pool_mean"] is None
            else f"{row['pool_mean']:.1f} {row['pool_min']}-{row['pool_max']}",
            row["digest"],
        )
    console.print(table)
    for row in report.runs:
        for robot, link in (row.get("links") or {}).items():
            rtt = (
                "-"
                if link.get("rtt_ms") is None
                else f"{link['rtt_ms']:.2f} ms median, {link['rtt_p95_ms']:.2f} ms p95"
            )
            console.print(
                f"{row['run_id']}: robot {robot} outside over {link['transport']}: round trip "
                f"{rtt}, loss {100 * link['loss']:.0f}%, {link['sessions']} session(s), "
                f"{link['refused']} frame(s) refused",
                highlight=False,
            )
    for group in report.groups:
        endings = ", ".join(f"{count} {name}" for name, count in group["endings"].items())
        aggregated = group["aggregated_runs"]
        if aggregated == 0:
            times = "none ended in consensus: no steps or pool sizes to aggregate"
        else:
            apart = f"of the {aggregated} that ended in consensus: "
            times = (
                f"{apart if aggregated != group['runs'] else ''}"
                f"{group['runs_within_half_n']} within n/2 = {group['half_n']:g} steps, "
                f"mean pool size {group['pool_size']['mean']}"
            )
        console.print(
            f"{group['label']}: {group['runs']} runs ({endings}); "
            f"{group['correct_runs']}/{group['runs']} correct; {times}",
            highlight=False,
        )
    for path in report.files:
        console.print(f"wrote {path}", highlight=False)
