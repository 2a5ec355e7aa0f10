"""Reading a recording back, message by message, as far as it is readable.

``RecordingReader`` makes one pass over an MCAP file with ``mcap``'s stream reader and
hands out each message as it comes: it holds one chunk of the file at a time (the writer
makes them ``chunk_bytes(robots)``), never the whole file, so what a reader of a long recording
keeps is up to it (``swarm report``'s ``Recording``, the replay's ``Timeline``).

A file cut short by a crash is read up to its last complete record: whatever stops the
stream reader there (``EndOfFile``, ``struct.error``, a chunk's codec or CRC error) ends
the pass quietly, and the reader says why. Only a file that is not a recording at all (the
pass stops before any schema or metadata record) raises ValueError; a path that cannot be
opened, OSError. A pass opens its file when its first message is asked for.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any, NamedTuple

from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from world_server.recording.records import RUN_METADATA, START_METADATA


class RecordedMessage(NamedTuple):
    """One message of a recording, with its channel's topic and schema name."""

    topic: str  # the key it was published on, or a derived ``foxglove/...`` topic
    schema: str  # "bestofn.Sense", "foxglove.Log" ...; "" for a channel never declared
    log_time: int  # sim time, nanoseconds
    publish_time: int  # wall time of arrival, nanoseconds
    data: bytes


class RecordingReader:
    """One pass over a recording: iterating it yields its messages in file order; as it
    goes (and once it has ended) ``metadata``, ``complete`` and ``stopped_by`` tell what
    the file held beside them and how it ended.

    ``source``: a path (opened and closed by each pass) or a binary stream (read from where
    it is, left open).
    """

    def __init__(self, source: Path | str | IO[bytes]) -> None:
        self.source = source
        self.name = str(source) if isinstance(source, Path | str) else _stream_name(source)
        self.metadata: dict[str, dict[str, str]] = {}  # record name -> its key-value pairs
        self.complete = False  # the pass reached the footer
        self.stopped_by: Exception | None = None  # what ended the pass before the end

    def __iter__(self) -> Iterator[RecordedMessage]:
        if isinstance(self.source, Path | str):
            with open(self.source, "rb") as stream:
                yield from self._messages(stream)
        else:
            yield from self._messages(self.source)

    def _messages(self, stream: IO[bytes]) -> Iterator[RecordedMessage]:
        self.metadata, self.complete, self.stopped_by = {}, False, None
        schemas: dict[int, str] = {}  # id -> name
        channels: dict[int, tuple[str, str]] = {}  # id -> (topic, schema name)
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Message):
                    topic, schema = channels.get(record.channel_id, ("", ""))
                    yield RecordedMessage(
                        topic, schema, record.log_time, record.publish_time, record.data
                    )
                elif isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Metadata):
                    self.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Footer):
                    self.complete = True
        # A cut-short file ends in McapError or struct.error; a corrupt chunk raises its
        # codec's own error type: whatever stops the reader, keep what was read before it.
        except Exception as error:
            if not self.metadata and not schemas:
                raise ValueError(
                    f"{self.name}: not a readable MCAP recording ({error!r})"
                ) from None
            self.stopped_by = error

    @property
    def problem(self) -> str | None:
        """Why the recording is not whole, or None once a pass read all of it."""
        if self.stopped_by is not None:
            return f"cut short: {type(self.stopped_by).__name__} {self.stopped_by}".strip()
        return None if self.complete else "cut short: no footer"

    @property
    def description(self) -> dict[str, str]:
        """The run's description: the final metadata record if the run finished, else the
        one written at start."""
        return run_description(self.metadata)


def run_description(metadata: Mapping[str, dict[str, str]]) -> dict[str, str]:
    """Of a recording's metadata records, the final one if the run finished, else the one
    written at start (empty if neither was read)."""
    return metadata.get(RUN_METADATA) or metadata.get(START_METADATA) or {}


def count_of(text: str | None) -> int:
    """A count in a metadata record (its values are text): 0 when absent or not one."""
    return int(text) if text and text.isdigit() else 0


def json_of(text: str | None) -> Any:
    """A JSON value of a recording (a metadata value, a message's text): None when absent or
    not JSON."""
    try:
        return json.loads(text) if text else None
    except ValueError:
        return None


def _stream_name(stream: IO[bytes]) -> str:
    name = getattr(stream, "name", None)
    return str(name) if name is not None else "recording"
