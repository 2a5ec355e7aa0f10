"""A run's time series in one call: the in-process engine's collector, ``swarm frame`` on
the run's recording (CSV and Parquet) and ``frame_of_recording`` give the same rows for the
same run; a run over Zenoh gives them too, for the ticks both engines ran."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO, kill_leftovers, swarm_command, unique_run_id

from deploy.inprocess import engine
from deploy.launcher.plan import plan_from_args
from world_server.observer.frame import FrameCollector, text_cell
from world_server.recording.frame import frame_of_recording

pytestmark = pytest.mark.timeout(300)
pandas = pytest.importorskip("pandas")

ROBOTS, SITES, SEED = 10, 5, 3
SHAPE = ["--robots", str(ROBOTS), "--sites", str(SITES), "--seed", str(SEED)]


def _in_process(run_id: str) -> tuple[dict[str, Any], FrameCollector]:
    """The run ``swarm run --engine inprocess`` makes of SHAPE, with a collector."""
    from deploy.cli import build_parser

    arguments = ["run", "--engine", "inprocess", "--run-id", run_id, "--no-record", *SHAPE]
    plan = plan_from_args(build_parser(arguments).parse_args(arguments))
    collector = FrameCollector.of_run(SITES, ROBOTS, SEED)
    switches = plan.switches
    hooks = engine.EngineHooks(
        config=plan.config, poses_every=switches.world.state_every, frame=collector
    )
    summary = engine.run_in_process(
        switches.world.world,
        switches.controller,
        switches.beacon,
        timeout=plan.timeout,
        stall_window=plan.stall_window,
        hooks=hooks,
    )
    return summary, collector


def _swarm(*arguments: str, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        swarm_command(*arguments), capture_output=True, text=True, cwd=REPO, timeout=timeout
    )


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The in-process run of SHAPE, recorded by ``swarm run --engine inprocess``."""
    path = tmp_path_factory.mktemp("frame") / "run.mcap"
    done = _swarm(
        "run", "--engine", "inprocess", "--run-id", "frame", *SHAPE, "--record", str(path),
        "--json", "--quiet",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    return path, json.loads(done.stdout)


def test_swarm_frame_of_a_recording_equals_the_in_process_collector(
    recorded: tuple[Path, dict[str, Any]], tmp_path: Path
) -> None:
    path, summary = recorded
    own, collector = _in_process("frame")
    assert own["digest"] == summary["digest"]
    expected = collector.dataframe(run_id="frame")
    assert len(expected) >= ROBOTS * 10 and collector.late == 0
    pandas.testing.assert_frame_equal(frame_of_recording(path), expected)
    pandas.testing.assert_frame_equal(
        frame_of_recording(path, swarm=True), collector.dataframe(swarm=True, run_id="frame")
    )
    out = tmp_path / "frame.csv"
    done = _swarm("frame", str(path), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert f"wrote {len(expected):,} rows of run frame" in done.stdout
    with out.open() as stream:
        lines = list(csv.reader(stream))
    kinds = [kind for _, kind in collector.robot_columns]
    columns = list(zip(*(list(column) for column in collector.robots.values), strict=True))
    assert lines[0] == ["run_id", *(name for name, _ in collector.robot_columns)]
    assert lines[1:] == [
        ["frame", *(text_cell(kind, value) for kind, value in zip(kinds, row, strict=True))]
        for row in columns
    ]


def test_swarm_frame_writes_parquet_and_the_swarms_rows(
    recorded: tuple[Path, dict[str, Any]], tmp_path: Path
) -> None:
    pytest.importorskip("pyarrow")
    path, _ = recorded
    out = tmp_path / "frame.parquet"
    assert _swarm("frame", str(path), "--out", str(out), "--every", "2").returncode == 0
    thinned = pandas.read_parquet(out)
    whole = frame_of_recording(path, every=2)
    assert len(thinned) == len(whole) and thinned["tick"].tolist() == whole["tick"].tolist()
    assert thinned["decided_site"].isna().tolist() == whole["decided_site"].isna().tolist()
    assert (thinned["entropy"] - whole["entropy"]).abs().max() == 0.0
    swarm = tmp_path / "swarm.parquet"
    assert _swarm("frame", str(path), "--out", str(swarm), "--swarm").returncode == 0
    rows = pandas.read_parquet(swarm)
    assert rows["decided"].iloc[-1] == ROBOTS
    assert rows[[f"share_{site}" for site in range(SITES)]].sum(axis=1).round(6).eq(1.0).all()


def test_swarm_frame_refuses_what_it_cannot_write_with_one_line(tmp_path: Path) -> None:
    for arguments, said in (
        (["frame", str(tmp_path / "none.mcap"), "--out", "x.csv"], "no such recording"),
        (["frame", __file__, "--out", str(tmp_path / "x.txt")], "name a .csv or a .parquet"),
        (["frame", __file__, "--out", str(tmp_path / "x.csv"), "--every", "0"], "--every"),
    ):
        done = _swarm(*arguments)
        assert done.returncode == 2 and said in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) <= 2
    done = _swarm("frame", __file__, "--out", str(tmp_path / "x.csv"))
    assert done.returncode == 1 and "not a readable MCAP recording" in done.stderr


def test_a_run_over_zenoh_gives_the_rows_of_the_in_process_engine(tmp_path: Path) -> None:
    """The same seed over Zenoh: the same rows for every world state both engines made
    (the launcher stops its world a little after the last decision, the engine at once)."""
    run_id = unique_run_id("frame-zenoh")
    path = tmp_path / "zenoh.mcap"
    try:
        done = _swarm("run", "--run-id", run_id, *SHAPE, "--record", str(path), "--json", "--quiet")
    finally:
        kill_leftovers(run_id)
    assert done.returncode == 0, done.stderr[-2000:]
    own, collector = _in_process(run_id)
    assert json.loads(done.stdout)["digest"] == own["digest"]
    ours = collector.dataframe(run_id=run_id)
    theirs = frame_of_recording(path)
    last = ours["tick"].max()
    both = ours["tick"].lt(last)  # the engine's own last state is at its stop
    shared = theirs[theirs["tick"].isin(ours.loc[both, "tick"])].reset_index(drop=True)
    pandas.testing.assert_frame_equal(shared, ours[both].reset_index(drop=True))
