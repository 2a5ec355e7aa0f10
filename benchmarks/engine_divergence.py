"""Where do a Zenoh run and an in-process run of the same seed part?

A lockstep run is meant to be deterministic: the same seed gives the same run in one
process (``--engine inprocess``) and over Zenoh (``swarm run``), tick for tick. This runs
both (or reads two recordings made before) with every tick's ``world/state`` recorded, and
prints the first tick at which any robot's pose differs, the robots that differ there,
and the first status (phase, trips, opinion, decision) each engine reported differently.

    .venv/bin/python benchmarks/engine_divergence.py --robots 200 --seed 8 --until 400 \
        --robots-per-process 50 --out /tmp/divergence
    .venv/bin/python benchmarks/engine_divergence.py --compare a.mcap b.mcap

Exit code 0 when the two runs agree over the ticks both recorded, 1 when they part.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bestofn_swarm.wire import protocol  # noqa: E402
from deploy.study.make import ZENOH_ROBOTS_PER_PROCESS as ROBOTS_PER_PROCESS  # noqa: E402
from deploy.study.make import ZENOH_STALL_TIMEOUT  # noqa: E402

TOLERANCE = 1e-9  # metres and radians: the runs must agree exactly, up to float printing


@dataclass(frozen=True)
class Recorded:
    """What one recording says: poses per tick, and each robot's statuses in order."""

    poses: dict[int, dict[int, tuple[float, float, float]]]
    statuses: dict[int, list[dict[str, object]]]


def read(path: Path) -> Recorded:
    poses: dict[int, dict[int, tuple[float, float, float]]] = {}
    statuses: dict[int, list[dict[str, object]]] = {}
    for topic, data in _messages(path):
        if topic.endswith("/world/state"):
            state = protocol.decode(data, protocol.WorldState)
            poses[state.tick] = {p.id: (p.x, p.y, p.theta) for p in state.robots}
        elif topic.endswith("/status") and "/robot/" in topic:
            status = json.loads(data)
            status.pop("t", None)
            history = statuses.setdefault(int(status["id"]), [])
            # A robot may repeat its status (a process also reports on start and stop):
            # only changes count, with the tick they happened at.
            if not history or _content(history[-1]) != _content(status):
                history.append(status)
    return Recorded(poses, statuses)


def _messages(path: Path) -> Iterator[tuple[str, bytes]]:
    """(topic, data) of every message in the file's order. Read as a stream, so that a
    recording that was never finished (no summary, cut in a chunk) still gives what it
    holds up to the cut."""
    topics: dict[int, str] = {}
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    yield topics[record.channel_id], record.data
        except McapError as error:
            print(f"{path.name}: read up to a cut ({type(error).__name__})", file=sys.stderr)


def _content(status: dict[str, object]) -> dict[str, object]:
    return {key: value for key, value in status.items() if key != "tick"}


def pose_differences(
    first: Recorded, second: Recorded
) -> Iterator[tuple[int, list[tuple[int, float]]]]:
    """(tick, [(robot, distance apart)]) for every tick both recorded where poses differ."""
    for tick in sorted(set(first.poses) & set(second.poses)):
        a, b = first.poses[tick], second.poses[tick]
        apart = [
            (robot, math.dist(a[robot][:2], b[robot][:2]))
            for robot in sorted(set(a) | set(b))
            if robot not in a
            or robot not in b
            or max(abs(u - v) for u, v in zip(a[robot], b[robot], strict=True)) > TOLERANCE
        ]
        if apart:
            yield tick, apart


def status_differences(first: Recorded, second: Recorded) -> list[str]:
    """The first differing status of every robot whose statuses differ (over the statuses
    both recorded)."""
    lines = []
    for robot in sorted(set(first.statuses) | set(second.statuses)):
        ours, theirs = first.statuses.get(robot, []), second.statuses.get(robot, [])
        for index, (a, b) in enumerate(zip(ours, theirs, strict=False)):
            if a != b:
                changed = sorted(key for key in a.keys() | b.keys() if a.get(key) != b.get(key))
                lines.append(
                    f"robot {robot}: status #{index} differs in {', '.join(changed)}: "
                    f"tick {a.get('tick')} vs {b.get('tick')}, "
                    f"phase {a.get('phase')} vs {b.get('phase')}"
                )
                break
    return lines


def record_both(args: argparse.Namespace) -> tuple[Path, Path]:
    args.out.mkdir(parents=True, exist_ok=True)
    paths = []
    for engine in ("inprocess", "zenoh"):
        path = args.out / f"{engine}-{args.robots}-{args.seed}.mcap"
        command = [
            str(REPO / ".venv" / "bin" / "swarm"),
            "run",
            "--engine",
            engine,
            "--robots",
            str(args.robots),
            "--sites",
            str(args.sites),
            "--seed",
            str(args.seed),
            "--timeout",
            str(args.until),
            "--state-every",
            "1",
            "--record",
            str(path),
            "--json",
            "--quiet",
        ]
        if engine == "zenoh":
            # A starved robot process must be waited for, or the run leaves lockstep.
            command += ["--stall-timeout", str(ZENOH_STALL_TIMEOUT)]
            if args.robots_per_process:
                command += ["--robots-per-process", str(args.robots_per_process)]
        print("$ swarm", " ".join(command[1:]), file=sys.stderr, flush=True)
        done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=REPO)
        if not done.stdout.strip():
            sys.exit(f"swarm run --engine {engine} printed no summary:\n{done.stderr}")
        summary = json.loads(done.stdout)
        print(
            f"  {engine}: ended {summary['ended']} at {summary['sim_time_s']} s, "
            f"world stalls {summary['world']['stalls']}, rejected {summary['rejected']}",
            file=sys.stderr,
        )
        paths.append(path)
    return paths[0], paths[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", type=Path, nargs=2, metavar="MCAP", help="two recordings")
    parser.add_argument("--robots", type=int, default=200)
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--seed", type=int, default=8)
    parser.add_argument("--until", type=float, default=400.0, help="sim seconds of each run")
    parser.add_argument(
        "--robots-per-process", type=int, default=ROBOTS_PER_PROCESS, help="zenoh run's hosts"
    )
    parser.add_argument("--out", type=Path, default=Path("divergence"), help="recordings here")
    parser.add_argument("--show", type=int, default=5, help="differing ticks to print")
    args = parser.parse_args(argv)
    first_path, second_path = args.compare if args.compare else record_both(args)
    first, second = read(first_path), read(second_path)
    common = sorted(set(first.poses) & set(second.poses))
    print(f"{first_path.name} vs {second_path.name}: {len(common)} ticks recorded by both")
    shown = 0
    for tick, apart in pose_differences(first, second):
        described = ", ".join(f"{robot} ({distance * 1000:.3g} mm)" for robot, distance in apart)
        print(f"tick {tick}: {len(apart)} robot(s) apart: {described[:400]}")
        shown += 1
        if shown >= args.show:
            break
    statuses = status_differences(first, second)
    print("\n".join(statuses[: args.show * 4]) or "statuses: the same")
    if not shown and not statuses:
        print("the runs agree")
        return 0
    return 1


if __name__ == "__main__":
    sys.exit(main())
