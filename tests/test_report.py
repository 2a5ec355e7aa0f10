"""``swarm report``: figures and tables from recordings, including cut-short ones.

The recordings here are written by the real recorder class from made-up samples whose
outcome is known exactly (robots' steps and pool sizes), so the table can be checked to
the number; tests/test_recording.py reports on a real run's recording.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO, swarm_command

from bestofn_swarm.wire import keyspace, protocol
from deploy.cli import main
from deploy.reports import collect, report
from world_server.core.layout import make_layout
from world_server.observer.summary import run_digest
from world_server.recording.description import RunDescription
from world_server.recording.writer import McapRecorder, Sample

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SITES, ROBOTS, SEED = 4, 3, 7
# Pool sizes of each robot's poolings; each robot decides at its last pooling.
POOLS = {0: [2, 3], 1: [1, 2, 3], 2: [2, 2]}


def _status(
    robot: int, tick: int, pools: list[int], decided: int | None, opinion: list[float]
) -> bytes:
    """A status after ``len(pools)`` trips, each ending in a pooling."""
    trips = len(pools)
    return protocol.encode(
        protocol.Status(
            v=1,
            id=robot,
            tick=tick,
            t=tick * 0.1,
            phase="to_decision" if decided is not None else "to_site",
            trips=trips,
            opinion=opinion,
            pool_size=pools[-1] if pools else 0,
            poolings=trips,
            decided_site=decided,
            decision_time=tick * 0.1 if decided is not None else None,
            decision_trips=trips if decided is not None else None,
            comparison=None,
        )
    )


def make_recording(
    path: Path,
    run_id: str,
    sites: int = SITES,
    *,
    finish: bool = True,
    summary: dict[str, Any] | None = None,
    lost: range = range(0),
) -> tuple[int, int]:
    """Write a recording of a made-up run, without the clock and senses of the ticks in
    ``lost``. Returns two file sizes: before the last status message, and before the
    records that finishing the file adds."""
    keys = keyspace.Keys(run_id)
    best = make_layout(sites, ROBOTS, SEED).best_site
    stream = io.BytesIO()
    mcap = McapRecorder(
        stream,
        keys,
        RunDescription(run_id, SEED, ROBOTS, sites, {"sites": sites}),
        chunk_size=1,  # every message in its own chunk: a cut loses only what is after it
    )
    uniform = [1.0 / sites] * sites
    certain = [1.0 if site == best else 0.0 for site in range(sites)]

    def put(key: str, payload: bytes) -> None:
        mcap.record(Sample(key, payload, None, time.time_ns()))

    for tick in range(400):
        if tick in lost:
            continue
        put(keys.of(keyspace.CLOCK), protocol.encode(protocol.Clock(v=1, tick=tick, t=tick * 0.1)))
        for robot in range(ROBOTS):
            sense = protocol.Sense(
                v=1,
                tick=tick,
                t=tick * 0.1,
                x=0.001 * tick,
                y=0.1 * robot,
                theta=0.0,
                prox=[0.0] * 8,
                rx=0,
                camera=False,
            )
            put(keys.of(keyspace.SENSE, robot), protocol.encode(sense))
    before_last = 0
    for robot, pools in POOLS.items():
        put(keys.of(keyspace.STATUS, robot), _status(robot, 0, [], None, uniform))
        for trip in range(1, len(pools) + 1):
            last = trip == len(pools)
            before_last = stream.tell()
            put(
                keys.of(keyspace.STATUS, robot),
                _status(
                    robot,
                    100 * trip + robot,
                    pools[:trip],
                    best if last else None,
                    certain if last else uniform,
                ),
            )
    unfinished = stream.tell()
    if finish:
        mcap.finish(summary)
    path.write_bytes(stream.getvalue())
    return before_last, unfinished


def run_report(capsys: pytest.CaptureFixture[str], *arguments: str) -> tuple[int, dict[str, Any]]:
    """``swarm report ... --json`` in this process: exit code and JSON output."""
    code = main(["report", *arguments, "--json"])
    output = capsys.readouterr().out
    return code, json.loads(output) if output.strip() else {}


def test_the_table_has_each_runs_steps_and_pool_sizes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make_recording(tmp_path / "a.mcap", "made-a")
    code, result = run_report(capsys, str(tmp_path / "a.mcap"), "--out", str(tmp_path / "out"))
    assert code == 0
    (row,) = result["runs"]
    assert row["run_id"] == "made-a" and (row["robots"], row["sites"]) == (ROBOTS, SITES)
    assert row["source"] == "status messages" and row["complete"] is True
    assert row["consensus"] and row["correct"]
    assert row["best_site"] == make_layout(SITES, ROBOTS, SEED).best_site
    assert (row["swarm_steps"], row["steps_min"], row["steps_max"]) == (3, 2, 3)
    assert row["steps_mean"] == pytest.approx(7 / 3, abs=1e-3)
    assert row["pool_mean"] == pytest.approx(15 / 7, abs=1e-3)
    assert (row["pool_min"], row["pool_max"], row["poolings"]) == (1, 3, 7)
    assert row["robots_within_half_n"] == 2 and row["within_half_n"] is False
    assert row["digest"] == run_digest(collect.rebuild_summary(collect.read_recording(
        tmp_path / "a.mcap"))["per_robot"])  # fmt: skip
    (group,) = result["groups"]
    assert group["runs"] == group["correct_runs"] == 1 and group["runs_within_half_n"] == 0
    with open(tmp_path / "out" / "summary.csv") as stream:
        (line,) = list(csv.DictReader(stream))
    assert line["run_id"] == "made-a" and line["swarm_steps"] == "3"
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["runs"] == [row]
    for name in report.FIGURES:
        assert (tmp_path / "out" / name).read_bytes().startswith(PNG_MAGIC)


def test_a_runs_digest_is_its_per_robot_results_and_nothing_else() -> None:
    robots = [
        {"id": 1, "decided_site": 2, "decision_time_s": 88.1, "steps": 3, "pool_sizes": [2, 1],
         "phase": "stopped", "trips": 3},
        {"id": 0, "decided_site": 2, "decision_time_s": 91.6, "steps": 4, "pool_sizes": [2],
         "phase": "stopped", "trips": 4},
    ]  # fmt: skip
    digest = run_digest(robots)
    assert len(digest) == 16 and int(digest, 16) >= 0
    assert run_digest(list(reversed(robots))) == digest  # by id, whatever the order
    # What the digest does not cover (where a robot is when the run stops) leaves it alone.
    assert run_digest([{**robots[0], "phase": "to_nest", "trips": 9}, robots[1]]) == digest
    for field, other in (("decided_site", 1), ("decision_time_s", 88.2), ("steps", 4),
                         ("pool_sizes", [2, 2])):  # fmt: skip
        assert run_digest([{**robots[0], field: other}, robots[1]]) != digest, field


def test_the_launchers_summary_is_used_when_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "made.mcap"
    make_recording(path, "made-b")
    rebuilt = collect.rebuild_summary(collect.read_recording(path))
    launcher_only = {"wall_time_s": 12.5}  # a field only the launcher knew
    rebuilt.update(launcher_only)
    make_recording(path, "made-b", summary=rebuilt)
    code, result = run_report(capsys, str(path), "--out", str(tmp_path / "out"))
    assert code == 0
    (row,) = result["runs"]
    assert row["source"] == "metadata"
    assert {key: row[key] for key in launcher_only} == launcher_only
    assert row["swarm_steps"] == 3


def test_a_cut_short_recording_is_reported_from_its_status_messages(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    whole = tmp_path / "whole.mcap"
    before_last, unfinished = make_recording(whole, "made-c", finish=False)
    data = whole.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[:unfinished])
    code, result = run_report(capsys, str(tmp_path / "cut.mcap"), "--out", str(tmp_path / "o"))
    assert code == 0
    (row,) = result["runs"]
    assert row["complete"] is False and row["source"] == "status messages"
    assert (row["swarm_steps"], row["poolings"]) == (3, 7)
    # Cut inside the last robot's last status: what was recorded before is still reported.
    (tmp_path / "cut2.mcap").write_bytes(data[: before_last + 20])
    code, result = run_report(capsys, str(tmp_path / "cut2.mcap"), "--out", str(tmp_path / "p"))
    assert code == 0
    (row,) = result["runs"]
    assert row["complete"] is False and row["consensus"] is False and row["decided"] == 2
    assert (tmp_path / "p" / "fig4.png").read_bytes().startswith(PNG_MAGIC)


def test_a_cut_short_recording_takes_the_launchers_printed_summary_when_given(
    tmp_path: Path,
) -> None:
    """What ``swarm experiment`` does when a recorder fell behind and left its file without
    the summary: the run's own (here: all decided) beats the truncated status messages."""
    whole = tmp_path / "whole.mcap"
    before_last, _ = make_recording(whole, "made-d", finish=False)
    full = collect.rebuild_summary(collect.read_recording(whole))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: before_last + 20])
    alone = report.write_report([cut], tmp_path / "alone")
    given = report.write_report([cut], tmp_path / "given", launcher_summaries={cut: full})
    (alone_row,) = alone.as_json()["runs"]
    (given_row,) = given.as_json()["runs"]
    assert (alone_row["source"], alone_row["decided"]) == ("status messages", 2)
    assert (given_row["source"], given_row["decided"]) == ("launcher", 3)
    assert given_row["complete"] is False and given_row["ended"] == "consensus"


def test_runs_are_grouped_by_swarm_size_and_sites(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paths = []
    for index, sites in enumerate((4, 6, 4)):
        paths.append(tmp_path / f"r{index}.mcap")
        make_recording(paths[-1], f"made-n{sites}-r{index}", sites)
    code, result = run_report(
        capsys,
        *map(str, paths),
        "--out",
        str(tmp_path / "out"),
        "--example",
        "made-n6-r1",
        "--per-run",
    )
    assert code == 0
    assert [(group["sites"], group["runs"]) for group in result["groups"]] == [(4, 2), (6, 1)]
    assert result["groups"][1]["runs_within_half_n"] == 1  # 3 steps <= 6 / 2
    for index, sites in enumerate((4, 6, 4)):
        folder = tmp_path / "out" / "runs" / f"made-n{sites}-r{index}"
        assert (folder / "opinion.png").read_bytes().startswith(PNG_MAGIC)


def test_an_unreadable_file_is_skipped_and_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    make_recording(tmp_path / "good.mcap", "made-d")
    code = main(
        [
            "report",
            str(tmp_path / "junk.mcap"),
            str(tmp_path / "good.mcap"),
            "--out",
            str(tmp_path / "out"),
            "--json",
        ]
    )
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert code == 0 and len(result["runs"]) == 1
    assert "junk.mcap" in result["unreadable"][0]
    assert "skipping" in captured.err and "junk.mcap" in captured.err
    code, result = run_report(capsys, str(tmp_path / "junk.mcap"), "--out", str(tmp_path / "x"))
    assert code == 1 and result["runs"] == []


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["missing.mcap", "--out", "out"], "no such recording"),
        (["{good}", "--out", "{good}"], "not a directory"),
        (["{good}", "--out", "out", "--robot", "-1"], "--robot"),
        (["{good}"], "--out"),
    ],
)
def test_bad_arguments_exit_with_code_2_and_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], arguments: list[str], message: str
) -> None:
    good = tmp_path / "good.mcap"
    make_recording(good, "made-e")
    argv = [argument.replace("{good}", str(good)) for argument in arguments]
    argv = [str(tmp_path / a) if a in ("missing.mcap", "out") else a for a in argv]
    with pytest.raises(SystemExit) as exit_info:
        main(["report", *argv])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert message in error[-1] and len([line for line in error if "error" in line]) == 1


def _report_command(tmp_path: Path, *paths: Path) -> tuple[subprocess.CompletedProcess[bytes], Any]:
    """The real ``swarm report ... --json``: the process, and its JSON output."""
    done = subprocess.run(
        swarm_command("report", *map(str, paths), "--out", str(tmp_path / "out"), "--json"),
        capture_output=True,
        timeout=120,
        cwd=REPO,
    )
    return done, json.loads(done.stdout) if done.stdout.strip() else None


def test_a_recorded_summary_that_lacks_fields_is_reported_from_the_status_messages(
    tmp_path: Path,
) -> None:
    path = tmp_path / "lacking.mcap"
    make_recording(path, "made-f")
    summary = collect.rebuild_summary(collect.read_recording(path))
    del summary["per_robot"], summary["num_sites"]
    summary["wall_time_s"] = "soon"  # a field of the wrong type
    make_recording(path, "made-f", summary=summary)
    done, result = _report_command(tmp_path, path)
    errors = done.stderr.decode()
    assert done.returncode == 0, errors
    assert "Traceback" not in errors
    (warning,) = errors.strip().splitlines()
    assert warning == (
        f"swarm report: {path}: the recorded summary lacks a usable num_sites, wall_time_s, "
        "per_robot; taken from the status messages instead"
    )
    (row,) = result["runs"]
    assert row["source"] == "metadata" and row["sites"] == SITES
    assert (row["swarm_steps"], row["poolings"]) == (3, 7)
    assert row["ended"] == "consensus"


def test_aborted_and_interrupted_runs_are_labelled_and_kept_out_of_the_aggregates(
    tmp_path: Path,
) -> None:
    finished = tmp_path / "finished.mcap"
    make_recording(finished, "made-g1")
    interrupted = tmp_path / "interrupted.mcap"
    make_recording(interrupted, "made-g2")
    summary = collect.rebuild_summary(collect.read_recording(interrupted))
    summary.update(ended="interrupted", signal="SIGTERM", wall_time_s=1.0)
    make_recording(interrupted, "made-g2", summary=summary)
    # Cut short before its last robot decided, and never finished: nobody said how it ended.
    before_last, _ = make_recording(tmp_path / "whole.mcap", "made-g3", finish=False)
    aborted = tmp_path / "aborted.mcap"
    aborted.write_bytes((tmp_path / "whole.mcap").read_bytes()[:before_last])
    done, result = _report_command(tmp_path, finished, interrupted, aborted)
    assert done.returncode == 0, done.stderr.decode()
    assert [(row["run_id"], row["ended"]) for row in result["runs"]] == [
        ("made-g1", "consensus"),
        ("made-g2", "interrupted"),
        ("made-g3", "aborted"),
    ]
    (group,) = result["groups"]
    assert group["runs"] == 3 and group["aggregated_runs"] == 1
    assert group["endings"] == {"consensus": 1, "interrupted": 1, "aborted": 1}
    # Only the finished run's steps: 3 for the swarm, 2-3 per robot over its 3 robots.
    assert group["swarm_steps"] == {"mean": 3, "median": 3, "min": 3, "max": 3}
    assert (group["robot_steps"]["min"], group["robot_steps"]["max"]) == (2, 3)
    assert group["runs_within_half_n"] == 0


def test_messages_missing_from_a_recording_are_counted_and_warned_of(tmp_path: Path) -> None:
    """A recorder that fell behind by more than it may hold drops samples: the file is
    complete, but the report must not pass the gaps off as the whole run."""
    whole, gappy = tmp_path / "whole.mcap", tmp_path / "gappy.mcap"
    make_recording(whole, "made-w")
    make_recording(gappy, "made-g", lost=range(100, 150))
    warnings: list[str] = []
    result = report.write_report([whole, gappy], tmp_path / "out", warn=warnings.append)
    rows = {row["run_id"]: row for row in result.as_json()["runs"]}
    assert rows["made-w"]["missing_messages"] == 0
    # 50 ticks: a clock and a sense of each of the three robots each.
    assert rows["made-g"]["missing_messages"] == 50 * (1 + ROBOTS)
    assert rows["made-g"]["complete"] is True
    assert warnings == [
        f"{gappy}: 200 of the messages its publishers sent are not in it (a recorder that "
        "fell behind drops what it cannot hold); what is drawn from them has gaps"
    ]


# --- bounded memory (issue 24) ----------------------------------------------------------


def test_a_trail_keeps_at_most_its_limit_of_evenly_spaced_points_and_the_last() -> None:
    trail = collect.Trail(limit=8)
    for index in range(1000):
        trail.add(float(index), -float(index))
    xs, ys = trail.points()
    assert len(trail.xs) <= 8 and trail.seen == 1000
    assert xs[0] == 0.0 and xs[-1] == 999.0 and ys[-1] == -999.0  # start and end kept
    steps = {b - a for a, b in itertools.pairwise(xs[:-1])}
    assert steps == {float(trail.stride)}  # evenly spaced, in order
    short = collect.Trail(limit=8)
    for index in range(5):
        short.add(float(index), 0.0)
    assert short.points()[0] == [0.0, 1.0, 2.0, 3.0, 4.0]  # short trails whole


def test_a_recording_is_read_keeping_one_robots_statuses_and_a_trace_each(
    tmp_path: Path,
) -> None:
    """Every robot's summary record and progress are kept as they are read; all the
    statuses only of the robot the opinion figure shows (the lowest id, or --robot)."""
    make_recording(tmp_path / "a.mcap", "made-a")
    recording = collect.read_recording(tmp_path / "a.mcap")
    assert sorted(recording.robots_heard) == list(range(ROBOTS))
    assert recording.opinion_robot == 0
    assert [status.trips for status in recording.opinions] == list(range(len(POOLS[0]) + 1))
    for robot, trace in recording.robots_heard.items():
        assert recording.observer.records[robot].pool_sizes == POOLS[robot]
        assert trace.trail.seen == 400 and trace.trail.last == (0.399, 0.1 * robot)
    chosen = collect.read_recording(tmp_path / "a.mcap", opinion_robot=1)
    assert chosen.opinion_robot == 1 and len(chosen.opinions) == len(POOLS[1]) + 1


def test_acks_are_expected_at_the_ticks_the_beacon_named() -> None:
    """A beacon answers the ticks it names (Ack.next_tick), not every tick: only a gap
    after the tick named counts as missing acks, at the beacon's step."""
    acks = collect.AckTicks()
    for tick, next_tick in ((0, 5), (5, 10), (20, 25), (25, None), (26, None), (28, None)):
        acks.answered(tick, next_tick)
    # Missing: 10 and 15 (10 named, then every 5), and 27 (the next tick named).
    assert (acks.count, acks.expected) == (6, 9)
