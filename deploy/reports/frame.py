"""``swarm frame RUN.mcap --out FILE.csv|FILE.parquet``: a recorded run's time series as a
table file, one row per robot per world state (``--swarm``: one per world state).

The rows are those of ``world_server/recording/frame.py`` (the in-process engine's
``EngineHooks.frame`` gives the same for the same run), written as they are finished, a
block of rows at a time: the memory it takes does not grow with the recording. Parquet
needs pyarrow (the ``analysis`` extra).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

from bestofn_swarm.plumbing.private_files import open_private
from world_server.observer.frame import NULLABLE, PHASES, text_cell
from world_server.recording import frame as recording_frame

FORMATS = (".csv", ".parquet")
PARQUET_BLOCK = 65_536  # rows a Parquet row group holds, at most


class CsvRows:
    """Rows to a CSV file, each as it comes."""

    def __init__(self, stream: IO[str], run_id: str, columns: Sequence[tuple[str, str]]) -> None:
        self.writer = csv.writer(stream, lineterminator="\n")
        self.run_id = run_id
        self.kinds = [kind for _, kind in columns]
        self.writer.writerow(["run_id", *(name for name, _ in columns)])

    def write(self, rows: Sequence[Sequence[Any]]) -> None:
        kinds, run_id = self.kinds, self.run_id
        self.writer.writerows(
            [run_id, *(text_cell(kind, value) for kind, value in zip(kinds, row, strict=True))]
            for row in rows
        )

    def close(self) -> None:
        pass


class ParquetRows:
    """Rows to a Parquet file, a row group at a time."""

    def __init__(self, stream: IO[bytes], run_id: str, columns: Sequence[tuple[str, str]]) -> None:
        import pyarrow
        import pyarrow.parquet

        self.pa = pyarrow
        self.columns = list(columns)
        self.run_id = run_id
        self.types = {
            "p": pyarrow.dictionary(pyarrow.int8(), pyarrow.string()),
            "i": pyarrow.int64(),
            "f": pyarrow.float64(),
        }
        self.schema = pyarrow.schema(
            [("run_id", pyarrow.string())]
            + [(name, self.types[kind]) for name, kind in self.columns]
        )
        self.writer = pyarrow.parquet.ParquetWriter(stream, self.schema)
        self.block: list[Sequence[Any]] = []

    def write(self, rows: Sequence[Sequence[Any]]) -> None:
        self.block.extend(rows)
        if len(self.block) >= PARQUET_BLOCK:
            self._flush()

    def _flush(self) -> None:
        if not self.block:
            return
        pa, rows = self.pa, self.block
        arrays = [pa.array([self.run_id] * len(rows), pa.string())]
        for index, (name, kind) in enumerate(self.columns):
            values = [row[index] for row in rows]
            if kind == "p":
                codes = pa.array(values, pa.int8(), mask=[value < 0 for value in values])
                arrays.append(pa.DictionaryArray.from_arrays(codes, pa.array(list(PHASES))))
            elif kind == "i":
                missing = [value < 0 for value in values] if name in NULLABLE else None
                arrays.append(pa.array(values, pa.int64(), mask=missing))
            else:
                arrays.append(pa.array(values, pa.float64(), mask=[math.isnan(v) for v in values]))
        self.writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.block = []

    def close(self) -> None:
        self._flush()
        self.writer.close()


def write_frame(
    recording: Path,
    out: Path,
    *,
    swarm: bool = False,
    every: int = 1,
) -> tuple[int, recording_frame.RecordingFrames]:
    """Write a recording's rows to ``out`` (CSV or Parquet, by its suffix); the rows
    written and what the pass met. Raises ValueError for a file that is not a recording,
    ImportError for Parquet without pyarrow."""
    if out.suffix.lower() == ".parquet":
        import pyarrow  # noqa: F401  (before the file is made: a one-line error without it)

        with open_private(out, "wb") as binary:
            return _write(
                recording, lambda run, columns: ParquetRows(binary, run, columns), swarm, every
            )
    with open_private(out, "w", newline="") as text:
        return _write(recording, lambda run, columns: CsvRows(text, run, columns), swarm, every)


def _write(
    recording: Path,
    make: Callable[[str, Sequence[tuple[str, str]]], CsvRows | ParquetRows],
    swarm: bool,
    every: int,
) -> tuple[int, recording_frame.RecordingFrames]:
    written = 0
    sink: CsvRows | ParquetRows | None = None
    frames = None
    for frames, robots, rows_of_swarm in recording_frame.stream(
        recording, every=every, robot_rows=not swarm
    ):
        assert frames.collector is not None
        if sink is None:
            collector = frames.collector
            sink = make(
                frames.run_id, collector.swarm_columns if swarm else collector.robot_columns
            )
        rows = rows_of_swarm if swarm else robots
        sink.write(rows)
        written += len(rows)
    assert frames is not None and sink is not None  # the pass yields once at its end
    sink.close()
    return written, frames


# --- command line --------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", type=Path, metavar="RUN.mcap", help="a run's recording")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="FILE",
        help="the table to write: FILE.csv, or FILE.parquet (needs pyarrow)",
    )
    parser.add_argument(
        "--swarm",
        action="store_true",
        help="one row per world state for the whole swarm (robots decided, each site's "
        "share of the swarm's opinion, mean entropy, poolings) instead of one per robot",
    )
    parser.add_argument(
        "--every",
        type=int,
        default=1,
        metavar="N",
        help="keep every N-th world state (default: 1, every one: each --state-every ticks)",
    )


def run(args: argparse.Namespace) -> int:
    from bestofn_swarm.plumbing.cliargs import UsageError

    if not args.recording.is_file():
        raise UsageError(f"no such recording: {args.recording}")
    if args.out.suffix.lower() not in FORMATS:
        raise UsageError(f"--out {args.out}: name a .csv or a .parquet file")
    if args.every < 1:
        raise UsageError(f"--every must be at least 1, got {args.every}")
    if args.out.is_dir():
        raise UsageError(f"--out {args.out} is a directory")
    try:
        written, frames = write_frame(args.recording, args.out, swarm=args.swarm, every=args.every)
    except ImportError:
        raise UsageError(
            "a .parquet file needs pyarrow: pip install 'bestofn-swarm[analysis]'"
        ) from None
    except (ValueError, OSError) as error:
        print(f"swarm frame: {error}", file=sys.stderr)
        return 1
    if frames.problem:
        print(
            f"swarm frame: {args.recording}: {frames.problem}; wrote what was recorded",
            file=sys.stderr,
        )
    if frames.undecodable:
        print(
            f"swarm frame: {frames.undecodable} recorded message(s) not valid: left out",
            file=sys.stderr,
        )
    print(f"swarm frame: wrote {written:,} rows of run {frames.run_id} to {args.out}")
    return 0
