"""``swarm run --trace DIR``: the world and each robot process write the timeline that
``benchmarks/tick_timeline.py`` reads (docs/performance.md)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from swarm_helpers import REPO, run_swarm, unique_run_id

pytestmark = pytest.mark.timeout(180)
LIMIT_TICKS = 600  # the run's --timeout in ticks of 0.1 s


def _tick_timeline() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "tick_timeline", REPO / "benchmarks" / "tick_timeline.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_trace_writes_every_tick_of_the_world_and_every_step_of_each_robot(
    tmp_path: Path,
) -> None:
    trace = tmp_path / "trace"
    code, summary, stderr = run_swarm(
        [
            *("--robots", "3", "--sites", "3", "--seed", "0", "--timeout", str(LIMIT_TICKS / 10)),
            *("--robots-per-process", "2", "--no-record", "--trace", str(trace)),
        ],
        unique_run_id("trace"),
    )
    assert code == 5, stderr  # this seed reaches the sim time limit, deterministically
    assert summary["timeout_kind"] == "sim"
    assert sorted(path.name for path in trace.iterdir()) == [
        "robot-0-1.jsonl",
        "robot-2.jsonl",
        "world.jsonl",
    ]
    world = _lines(trace / "world.jsonl")
    ticks = [line["tick"] for line in world]
    # One line per closed tick, from the first, none missing. Until the sim time limit
    # each closed only when every robot (and the beacon, on the ticks it names) answered
    # (no stall in a healthy run); while the launcher stops the processes, their leaving
    # closes the last ones.
    assert ticks == list(range(len(ticks)))
    running = [line for line in world if line["tick"] < LIMIT_TICKS]
    assert len(running) == LIMIT_TICKS
    beacon_answered = 0
    for line in running:
        assert line["robots"] == 3
        answers = sorted(who for who, _, _ in line["answers"])
        beacon_answered += answers[0] == "beacon/nest"
        robots_answered = [who for who in answers if who != "beacon/nest"]
        assert robots_answered == ["robot/0", "robot/1", "robot/2"]
        assert line["open_start"] <= line["opened"] <= line["close_start"]
        assert line["close_start"] <= line["advanced"] <= line["delivered"]
    # The beacon answers only the ticks it named in its last ack (Ack.next_tick), not every
    # tick: at its period of 0.5 s, every fifth.
    assert 0 < beacon_answered < LIMIT_TICKS
    steps = _lines(trace / "robot-0-1.jsonl") + _lines(trace / "robot-2.jsonl")
    for robot in range(3):
        stepped = [line["tick"] for line in steps if line["robot"] == robot]
        assert stepped[:LIMIT_TICKS] == list(range(LIMIT_TICKS))  # one line per step
    for line in steps:
        assert line["arrived"] <= line["handled"] <= line["answered"]
    report = _tick_timeline().timeline(trace, skip=10)
    assert report[0].startswith(f"{trace}: {len(ticks) - 10} ticks, 3.0 robots")
    assert "2 robot process(es)" in report[0]
    assert all("(no data)" not in line for line in report), report
