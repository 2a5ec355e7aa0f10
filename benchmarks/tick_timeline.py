"""What a lockstep tick costs, hop by hop, from the timelines of ``swarm run --trace DIR``.

The world server writes one line per tick (when it began and finished publishing the
tick's inputs, when each answer reached its Zenoh callback and its thread, when it began
closing the tick and how long ``World.advance`` and the radio deliveries took); each robot
process writes one line per control step (when the step's last input reached its
callback, when the step began, when the answer was published: for robots answering in
one batch, when the batch was). A robot steps in the callback of its last input, after
the robots of its process that came before it in the batch, so "input to its step" is
the wait for those, not a thread hand-off. All times are one machine-wide monotonic
clock, so the hops line up:

    .venv/bin/swarm run --robots 10 --seed 4 --no-record --trace /tmp/trace10
    .venv/bin/python benchmarks/tick_timeline.py /tmp/trace10

Prints the median and mean of each hop in milliseconds, over the ticks after the first
``--skip`` (start-up).
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any


def read_lines(path: Path) -> list[dict[str, Any]]:
    lines = []
    with path.open() as file:
        for text in file:
            text = text.strip()
            if text:
                try:
                    lines.append(json.loads(text))
                except ValueError:
                    break  # a line cut short by a killed process: the rest is unusable
    return lines


def describe(name: str, values: Iterable[float]) -> str:
    data = [value * 1000 for value in values]
    if not data:
        return f"{name:<58} (no data)"
    return (
        f"{name:<58} median {statistics.median(data):7.3f} ms   mean "
        f"{statistics.fmean(data):7.3f} ms   n {len(data)}"
    )


def timeline(folder: Path, skip: int) -> list[str]:
    world = [line for line in read_lines(folder / "world.jsonl") if line.get("tick", 0) >= skip]
    by_tick = {line["tick"]: line for line in world}
    steps: dict[int, list[dict[str, Any]]] = defaultdict(list)
    hosts = sorted(path for path in folder.glob("*.jsonl") if path.name != "world.jsonl")
    for path in hosts:
        for line in read_lines(path):
            if line.get("tick", 0) >= skip and "robot" in line:
                steps[line["tick"]].append(line)
    # The world's own work between the last answer of tick t and the inputs of t + 1.
    advance: list[float] = []
    deliver: list[float] = []
    publish: list[float] = []
    wait: list[float] = []
    answer_trip: list[float] = []
    handoff: list[float] = []
    for tick, line in by_tick.items():
        following = by_tick.get(tick + 1)
        if following is None or "close_start" not in line:
            continue
        advance.append(line["advanced"] - line["close_start"])
        deliver.append(line["delivered"] - line["advanced"])
        publish.append(following["opened"] - following["open_start"])
        answers = line.get("answers", [])
        if answers:
            wait.append(max(handled for _, _, handled in answers) - line["opened"])
            answer_trip.extend(arrived - line["open_start"] for _, arrived, _ in answers)
            handoff.extend(handled - arrived for _, arrived, handled in answers)
    to_robot, robot_handoff, robot_step, to_world = [], [], [], []
    answered_at: dict[tuple[int, str], float] = {}
    for tick, lines in steps.items():
        opened = by_tick.get(tick)
        for step in lines:
            if opened is not None and step["arrived"]:
                to_robot.append(step["arrived"] - opened["open_start"])
            if step["arrived"]:
                robot_handoff.append(step["handled"] - step["arrived"])
            robot_step.append(step["answered"] - step["handled"])
            answered_at[(tick, f"robot/{step['robot']}")] = step["answered"]
    for tick, line in by_tick.items():
        for who, arrived, _ in line.get("answers", []):
            sent = answered_at.get((tick, who))
            if sent is not None and arrived:
                to_world.append(arrived - sent)
    ticks = [
        following["opened"] - line["opened"]
        for tick, line in by_tick.items()
        if (following := by_tick.get(tick + 1)) is not None
    ]
    robots = statistics.fmean(line.get("robots", 0) for line in world) if world else 0
    return [
        f"{folder}: {len(world)} ticks, {robots:.1f} robots in the barrier on average, "
        f"{len(hosts)} robot process(es)",
        describe("whole tick (inputs published to inputs published)", ticks),
        describe("world: publish a tick's inputs (sense, frames)", publish),
        describe("world -> robot: inputs published to the robot's callback", to_robot),
        describe("robot: input to its step (the process's robots before it)", robot_handoff),
        describe("robot: step to its answer published (and its batch's)", robot_step),
        describe("robot -> world: answer published to the world's callback", to_world),
        describe("world: callback to its thread", handoff),
        describe("world: inputs published to the last answer taken (barrier)", wait),
        describe("world: advance (radio, physics, camera)", advance),
        describe("world: publish radio deliveries", deliver),
        describe("round trip seen by the world (publish start to each answer)", answer_trip),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", type=Path, nargs="+", help="directories of swarm run --trace")
    parser.add_argument("--skip", type=int, default=10, help="start-up ticks to leave out")
    args = parser.parse_args()
    for folder in args.folders:
        print("\n".join(timeline(folder, args.skip)))


if __name__ == "__main__":
    main()
