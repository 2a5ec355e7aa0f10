"""A recording's time series: its statuses and world states, read one message at a time
(``reader.py``) through the key table's gate into the run's observer, which feeds a
``FrameCollector`` (``world_server/observer/frame.py``): the rows the in-process engine
gives for the same run (``EngineHooks.frame``).

``frame_of_recording(path)`` returns the rows as a pandas DataFrame; ``stream(path)``
hands them out as they are finished, so that a file of any length is written with memory
that does not grow with it (``swarm frame``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bestofn_swarm.wire import keyspace
from world_server.core.layout import make_layout
from world_server.observer.frame import FrameCollector
from world_server.observer.observer import RunObserver
from world_server.recording.reader import RecordingReader, count_of, json_of

READS = (keyspace.STATUS, keyspace.STATE)  # what a run's time series is made of


@dataclass
class RecordingFrames:
    """A pass over a recording: its collector (made once the run's description is read)
    and what the pass met."""

    path: Path
    collector: FrameCollector | None = None
    run_id: str = ""
    undecodable: int = 0  # samples that did not pass the gate, or made no sense
    complete: bool = False
    problem: str | None = None

    @property
    def columns(self) -> tuple[tuple[str, str], ...]:
        return self.collector.robot_columns if self.collector is not None else ()


def stream(
    path: Path | str, *, every: int = 1, robot_rows: bool = True, keep: bool = False
) -> Iterator[tuple[RecordingFrames, list[tuple[Any, ...]], list[tuple[Any, ...]]]]:
    """One pass over a recording, yielding after each message that finished rows: the
    pass, the robots' new rows, the swarm's new rows (with ``keep``, the collector's
    tables keep them instead, and nothing is yielded but the pass at its end). Raises
    ValueError if the file is not a recording."""
    frames = RecordingFrames(Path(path))
    reader = RecordingReader(path)
    kinds = {kind.schema: kind for kind in READS}
    observer: RunObserver | None = None
    collector: FrameCollector | None = None
    for message in reader:
        kind = kinds.get(message.schema)
        if kind is None:
            continue
        if observer is None or collector is None:
            collector = collector_for(reader.description, message.data, every, robot_rows, keep)
            frames.collector = collector
            frames.run_id = reader.description.get("run_id") or Path(path).stem
            observer = RunObserver((), open_roster=True, series=collector)
        ident = keyspace.ident_in(kind, message.topic)
        try:
            if ident is None:
                raise keyspace.SampleError(f"{message.topic} is no key of {kind.name}")
            observer.take(keyspace.open_recorded(kind, ident or None, message.data))
        except keyspace.SampleError:
            frames.undecodable += 1
            continue
        if not keep:
            robots, swarm = collector.take()
            if robots or swarm:
                yield frames, robots, swarm
    frames.complete, frames.problem = reader.complete, reader.problem
    if frames.collector is None:  # no status nor state: a recording of nothing
        frames.collector = collector_for(reader.description, b"", every, robot_rows, keep)
    frames.collector.finish()
    robots, swarm = ([], []) if keep else frames.collector.take()
    frames.run_id = frames.run_id or reader.description.get("run_id") or Path(path).stem
    yield frames, robots, swarm


def collector_for(
    description: dict[str, str], first: bytes, every: int, robot_rows: bool, keep: bool
) -> FrameCollector:
    """The collector of the run a recording describes: its sites and best site from the
    recorded layout, else from its shape and seed, else (no description) the sites from the
    first status's opinion and no best site."""
    layout = json_of(description.get("layout"))
    sites = count_of(description.get("sites"))
    if isinstance(layout, dict) and isinstance(layout.get("best_site"), int):
        return FrameCollector(
            sites or len(layout.get("sites") or ()),
            layout["best_site"],
            every=every,
            robot_rows=robot_rows,
            keep=keep,
        )
    robots, seed = count_of(description.get("robots")), count_of(description.get("seed"))
    if sites and robots:
        best: int | None = make_layout(sites, robots, seed or 0).best_site
    else:
        best = None
        opinion = json_of(first.decode(errors="replace")) if first else None
        if isinstance(opinion, dict) and isinstance(opinion.get("opinion"), list):
            sites = len(opinion["opinion"])
    return FrameCollector(max(sites, 2), best, every=every, robot_rows=robot_rows, keep=keep)


def frame_of_recording(path: Path | str, *, swarm: bool = False, every: int = 1) -> Any:
    """A recorded run's time series as a pandas DataFrame (pandas is the ``analysis``
    extra): one row per robot per world state of the run, or with ``swarm`` one row per
    world state (robots decided, each site's share of the swarm's opinion, mean entropy,
    poolings); ``every``: keep every n-th world state. A ``run_id`` column names the run.
    Raises ValueError if the file is not a recording."""
    *_, (frames, _, _) = stream(path, every=every, robot_rows=not swarm, keep=True)
    assert frames.collector is not None
    return frames.collector.dataframe(swarm=swarm, run_id=frames.run_id)


__all__ = ["RecordingFrames", "collector_for", "frame_of_recording", "stream"]
