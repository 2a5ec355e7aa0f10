"""``--trace``: one JSON line per tick of the world (bestofn_swarm/plumbing/trace.py), assembled
from the coordinator's timeline outputs, each stamped with the clock when it comes out.

A line holds what the tick opened with (tick, robots, frames, rx, batched), when its
inputs started going out and were all out (open_start, opened), each answer it took
(answers: who, arrived at the callback, handled), and when it closed (close_start),
the world had advanced (advanced) and the radio was delivered (delivered).
``benchmarks/tick_timeline.py`` reads it.
"""

from __future__ import annotations

from typing import Any

from bestofn_swarm.plumbing.trace import TraceWriter, now
from world_server.core.events import Answered, Mark, Moment, Opened


def _stamp(time: float) -> float:
    return round(time, 6)


class TickTimeline:
    def __init__(self, writer: TraceWriter) -> None:
        self.writer = writer
        self._open_start = 0.0
        self._tick: dict[str, Any] = {}  # the line of the tick under way, so far
        self._close: dict[str, float] = {}

    def note(self, output: Mark | Opened | Answered) -> None:
        if isinstance(output, Answered):
            answers = self._tick.setdefault("answers", [])
            answers.append([output.who, _stamp(output.arrived), _stamp(output.handled)])
        elif isinstance(output, Opened):
            self._tick = {
                "tick": output.tick,
                "robots": output.robots,
                "frames": output.frames,
                "rx": output.rx,
                "batched": output.batched,
                "open_start": self._open_start,
            }
        elif output.moment == Moment.OPEN_START:
            self._open_start = _stamp(now())
        elif output.moment == Moment.OPENED:
            self._tick["opened"] = _stamp(now())
        elif output.moment == Moment.DELIVERED:
            self.writer.write(**self._tick, **self._close, delivered=_stamp(now()))
        else:  # CLOSE_START, ADVANCED
            self._close[output.moment.value] = _stamp(now())

    def close(self) -> None:
        self.writer.close()
