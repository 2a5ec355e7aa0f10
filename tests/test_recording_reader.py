"""The one MCAP reader (world_server/recording/reader.py) that ``swarm report`` and the
replay build on: a whole recording, recordings cut short anywhere, and that it streams.

The recordings are written by the real writer from made-up samples, one message per
chunk, with the file's size noted after every sample: so for any cut it is known exactly
which messages were whole on disk before it.
"""

from __future__ import annotations

import io
import time
from pathlib import Path

import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader

from bestofn_swarm.wire import keyspace, protocol
from world_server.recording.description import RunDescription
from world_server.recording.reader import RecordedMessage, RecordingReader
from world_server.recording.records import RUN_METADATA, START_METADATA
from world_server.recording.writer import McapRecorder, Sample

ROBOTS, SITES, SEED, TICKS = 3, 4, 5, 60


class Written:
    """A recording in memory and, after each sample, (file size, messages written)."""

    def __init__(self) -> None:
        self.stream = io.BytesIO()
        self.keys = keyspace.Keys("reader-test")
        self.recorder = McapRecorder(
            self.stream,
            self.keys,
            RunDescription("reader-test", SEED, ROBOTS, SITES),
            chunk_size=1,  # every message in a chunk of its own, on file once written
        )
        self.header_end = self.stream.tell()  # the header and the start metadata record
        self.whole: list[tuple[int, int]] = []

    def put(self, key: str, payload: bytes) -> None:
        self.recorder.record(Sample(key, payload, None, time.time_ns()))
        self.whole.append((self.stream.tell(), sum(self.recorder.counts.values())))

    def messages_whole_before(self, cut: int) -> int:
        return max((count for size, count in self.whole if size <= cut), default=0)

    def size_once_written(self, messages: int) -> int:
        """The file's size once its first ``messages`` messages were on it."""
        return min(size for size, count in self.whole if count >= messages)

    @property
    def data(self) -> bytes:
        return self.stream.getvalue()


def write_run(*, finish: bool = True) -> Written:
    """Clocks, senses (with the poses they derive), statuses, a log line and junk."""
    written = Written()
    keys = written.keys
    for tick in range(TICKS):
        written.put(
            keys.of(keyspace.CLOCK), protocol.encode(protocol.Clock(v=1, tick=tick, t=tick / 10))
        )
        for robot in range(ROBOTS):
            sense = protocol.Sense(
                v=1,
                tick=tick,
                t=tick / 10,
                x=0.01 * tick,
                y=0.1 * robot,
                theta=0.0,
                prox=[0.0] * 8,
                rx=0,
                camera=False,
            )
            written.put(keys.of(keyspace.SENSE, robot), protocol.encode(sense))
        if tick % 20 == 0:
            line = protocol.LogLine(v=1, process="world", wall_time=1.0, line=f"tick {tick}")
            written.put(keys.of(keyspace.LOG, "world"), protocol.encode(line))
            written.put(keys.of(keyspace.SENSE, 0), b"not a sense")  # kept on the rejected channel
    if finish:
        written.recorder.finish({"run_id": "reader-test"})
    return written


def read_all(source: Path | io.BytesIO) -> tuple[RecordingReader, list[RecordedMessage]]:
    reader = RecordingReader(source)
    return reader, list(reader)


def test_a_whole_recording_reads_as_mcaps_own_indexed_reader_reads_it() -> None:
    written = write_run()
    reader, messages = read_all(io.BytesIO(written.data))
    indexed = [
        RecordedMessage(
            channel.topic,
            schema.name if schema is not None else "",
            message.log_time,
            message.publish_time,
            message.data,
        )
        for schema, channel, message in make_reader(io.BytesIO(written.data)).iter_messages(
            log_time_order=False
        )
    ]
    assert messages == indexed
    assert len(messages) == sum(written.recorder.counts.values())
    assert {message.schema for message in messages} >= {
        "bestofn.Clock",
        "bestofn.Sense",
        "bestofn.LogLine",
        "bestofn.RejectedSample",
        "foxglove.FrameTransforms",
        "foxglove.Log",
    }
    assert reader.complete and reader.stopped_by is None and reader.problem is None
    assert set(reader.metadata) == {START_METADATA, RUN_METADATA}
    assert reader.description["run_id"] == "reader-test"
    assert reader.description is reader.metadata[RUN_METADATA]


def test_a_path_reads_as_its_bytes_do(tmp_path: Path) -> None:
    written = write_run()
    path = tmp_path / "run.mcap"
    path.write_bytes(written.data)
    from_path, from_stream = read_all(path), read_all(io.BytesIO(written.data))
    assert from_path[1] == from_stream[1]
    assert from_path[0].metadata == from_stream[0].metadata
    assert from_path[0].name == str(path)


def test_a_recording_cut_anywhere_gives_every_message_before_the_cut() -> None:
    written = write_run()
    data = written.data
    _, whole = read_all(io.BytesIO(data))
    unfinished = written.whole[-1][0]  # where finishing the file began
    cuts = sorted(
        {
            written.header_end,  # nothing but the start metadata
            written.header_end + 1,
            *range(written.header_end, unfinished, max((unfinished - written.header_end) // 9, 1)),
            written.whole[len(written.whole) // 2][0] + 7,  # inside a chunk
            unfinished,  # every message, no final metadata
            unfinished + 20,  # inside the final metadata record
            len(data) - 1,  # all but the last byte of the closing magic
        }
    )
    assert len(cuts) >= 10
    for cut in cuts:
        reader, messages = read_all(io.BytesIO(data[:cut]))  # raises nothing
        assert messages == whole[: len(messages)], cut
        assert len(messages) >= written.messages_whole_before(cut), cut
        assert not reader.complete or cut == len(data) - 1
        assert reader.problem is not None and reader.problem.startswith("cut short"), cut
        assert START_METADATA in reader.metadata
        if cut <= unfinished:
            assert RUN_METADATA not in reader.metadata
            assert reader.description is reader.metadata[START_METADATA]


def test_a_recording_never_finished_ends_without_a_footer() -> None:
    written = write_run(finish=False)
    reader, messages = read_all(io.BytesIO(written.data))
    assert len(messages) == sum(written.recorder.counts.values())
    assert not reader.complete and isinstance(reader.stopped_by, EndOfFile)
    assert reader.problem == "cut short: EndOfFile"


def test_a_file_that_is_no_recording_is_a_value_error(tmp_path: Path) -> None:
    path = tmp_path / "junk.mcap"
    path.write_bytes(b"no mcap here " * 40)
    with pytest.raises(ValueError, match="not a readable MCAP recording"):
        read_all(path)
    with pytest.raises(ValueError, match="not a readable MCAP recording"):
        read_all(io.BytesIO(write_run().data[: 8 + 20]))  # magic and a piece of the header


class CountingStream(io.BytesIO):
    """A file that counts the bytes read from it."""

    def __init__(self, data: bytes) -> None:
        super().__init__(data)
        self.bytes_read = 0

    def read(self, size: int | None = -1, /) -> bytes:
        data = super().read(size)
        self.bytes_read += len(data)
        return data


def test_the_reader_streams_reading_only_as_far_as_the_messages_taken() -> None:
    written = write_run()
    data = written.data
    stream = CountingStream(data)
    reader = RecordingReader(stream)
    messages = iter(reader)
    assert stream.bytes_read == 0  # nothing is read before the first message is asked for
    first = next(messages)
    assert first.schema == "bestofn.Clock"
    assert stream.bytes_read <= written.size_once_written(1)
    assert set(reader.metadata) == {START_METADATA}  # the final record is far ahead
    for _ in range(50):
        next(messages)
    assert stream.bytes_read <= written.size_once_written(51) < len(data) // 2
    rest = list(messages)
    assert stream.bytes_read == len(data) and rest and reader.complete


def test_a_broken_tail_is_not_seen_until_the_pass_reaches_it(tmp_path: Path) -> None:
    written = write_run()
    path = tmp_path / "broken.mcap"
    path.write_bytes(written.data[: written.whole[-1][0]] + b"\xff" * 64)
    reader = RecordingReader(path)
    messages = iter(reader)
    next(messages)
    assert reader.stopped_by is None and not reader.complete
    rest = list(messages)
    assert len(rest) + 1 == written.whole[-1][1]
    assert reader.stopped_by is not None and reader.problem is not None
