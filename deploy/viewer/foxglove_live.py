"""``python -m deploy.viewer.foxglove_live``: the run, live, in the Foxglove app (``swarm run
--foxglove``).

The server is the official ``foxglove-sdk``'s WebSocket server (the Foxglove WebSocket
protocol). What it serves is what the recorder writes: the recorder's own
``McapRecorder`` builds every record, and ``FoxgloveSink`` hands them to SDK channels
instead of an MCAP file. So the channels (one per key, plus the derived
``foxglove/{scene,transforms,log}``), their schemas and their messages are the
recording's, byte for byte, and a layout made for a recording works live.

Like the recorder it subscribes to ``<root>/<run>/**`` and declares ``alive/foxglove/0``
once it serves, and like the recorder it holds the run secret: ``McapRecorder`` checks
every sample's tag before it builds a record, so a forged sample goes to the
``recorder/rejected`` channel, never to its key's. Zenoh callbacks put samples into a
bounded queue (a sample that finds it full is dropped and counted: the view must not
grow without bound while the machine is busy: ``bestofn_swarm/plumbing/inbox.py``, charged at what a
sample really costs); one thread passes them to the recorder's
logic. The SDK keeps at most ``BACKLOG`` messages per connected app and drops the oldest
beyond that. It stops on a stop signal or on the run's ending (``world/ending``), passing
on what it holds first; after the ending it exits with the run's exit code.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

from bestofn_swarm.plumbing import cliargs, process_main
from bestofn_swarm.plumbing.ending import hear_ending
from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.wire import names, protocol
from bestofn_swarm.wire.names import Role
from deploy.viewer.options import FOXGLOVE_PORT
from world_server.recording.description import RunDescription
from world_server.recording.writer import McapRecorder, Sample

log = logging.getLogger("foxglove-live")

INBOX_BYTES = 64 * 2**20  # samples waiting for the writer thread, at most
MAX_SAMPLE_BYTES = protocol.MAX_CAMERA_FRAME_BYTES + 1024  # a frame and its attachment
BACKLOG = 4096  # messages the SDK buffers per connected app
DEFAULT_NICENESS = 10
DRAIN_SECONDS, SEND_SECONDS = 1.5, 0.3  # at a stop: to pass on what is queued, to send it


class FoxgloveSink:
    """The part of ``mcap.writer.Writer`` that ``McapRecorder`` uses, onto SDK channels."""

    def __init__(self, context: Any) -> None:
        import foxglove

        self._foxglove = foxglove
        self._context = context
        self._schemas: list[Any] = []
        self._channels: list[Any] = []
        self.metadata: dict[str, dict[str, str]] = {}

    def start(self, library: str = "", profile: str = "") -> None:
        """Nothing to open: the server is already listening."""

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._schemas.append(self._foxglove.Schema(name=name, encoding=encoding, data=data))
        return len(self._schemas) - 1

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: Any = None
    ) -> int:
        channel = self._foxglove.Channel(
            topic,
            schema=self._schemas[schema_id],
            message_encoding=message_encoding,
            context=self._context,
        )
        self._channels.append(channel)
        return len(self._channels) - 1

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        self._channels[channel_id].log(bytes(data), log_time=log_time)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self.metadata[name] = dict(data)  # a WebSocket has no place for it; kept for tests

    def finish(self) -> None:
        for channel in self._channels:
            channel.close()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="deploy.viewer.foxglove_live",
        description="Serve one run live to the Foxglove app (Foxglove WebSocket protocol).",
    )
    cliargs.add_run_shape(parser, "of the run, for its layout")
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=cliargs.int_range(0, 65535),
        default=FOXGLOVE_PORT,
        help=f"TCP port (default: {FOXGLOVE_PORT}, the Foxglove app's default)",
    )
    parser.add_argument(
        "--niceness",
        type=cliargs.int_range(0, 19),
        default=DEFAULT_NICENESS,
        help=f"how much to lower this process's CPU priority (default: {DEFAULT_NICENESS})",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin(
        "foxglove-live",
        parser,
        argv,
        process_main.no_settings,
        runs_cores=False,
        # Like the recorder, it checks every identity's tags: only the secret gives them all.
        needs_secret="Foxglove live",
        lower_priority=True,
    )
    args, keyring, keys = begun.args, begun.keyring, begun.keys
    import foxglove
    import zenoh

    from bestofn_swarm.plumbing.world_info import fetch_world_info
    from bestofn_swarm.plumbing.zenoh_session import open_from_args

    context = foxglove.Context()
    try:
        server = foxglove.start_server(
            name=f"bestofn {args.run_id}",
            host=args.host,
            port=args.port,
            context=context,
            message_backlog_size=BACKLOG,
        )
    except RuntimeError as error:  # the SDK reports a port in use as a RuntimeError
        print(f"foxglove-live: cannot serve on {args.host}:{args.port}: {error}", file=sys.stderr)
        return 1
    inbox: BoundedInbox[Sample | None] = BoundedInbox(INBOX_BYTES, MAX_SAMPLE_BYTES)
    dropped = [0]
    stopping = threading.Event()
    on_stop_signals(lambda _: stopping.set())

    def on_sample(sample: Any) -> None:
        attachment = sample.attachment
        key, payload = str(sample.key_expr), sample.payload.to_bytes()
        extra = attachment.to_bytes() if attachment is not None else None
        if not inbox.put(
            Sample(key, payload, extra, time.time_ns()), message_bytes(payload, extra, key)
        ):
            dropped[0] += 1
            if dropped[0] == 1:
                log.warning("falling behind the run: dropping samples (logged once)")

    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"foxglove-live: cannot open Zenoh session: {error}", file=sys.stderr)
        server.stop()
        return 1
    ended: list[int] = []  # the run's exit code, once its ending came

    def on_ending(ending: protocol.RunEnding) -> None:
        ended.append(ending.code)
        stopping.set()

    with session:
        subscriber = session.declare_subscriber(keys.all, on_sample)
        hearing = hear_ending(session, keys, keyring, on_ending)
        try:
            info: protocol.WorldInfo | None = fetch_world_info(
                session, keys, 10.0, keyring, names.FOXGLOVE
            )
        except TimeoutError as error:
            log.warning("%s; sim times will follow world/clock", error)
            info = None
        sink = FoxgloveSink(context)
        run = RunDescription(args.run_id, args.seed, args.robots, args.sites)
        recorder = McapRecorder(
            None,  # no file: records go to the sink's writer
            keys,
            run,
            info,
            writer=sink,
            keyring=keyring,
        )
        writer = threading.Thread(target=_forward, args=(recorder, inbox), daemon=True)
        writer.start()
        token = session.liveliness().declare_token(keys.token(Role.FOXGLOVE, 0))
        log.info("serving the run to Foxglove on ws://%s:%d", args.host, server.port)
        while not stopping.wait(0.2):
            pass
        token.undeclare()
        hearing.undeclare()
        subscriber.undeclare()
        # What arrived before the stop still reaches the app: a niced process on a busy
        # machine may lag the run, and the end of a run is what a person wants to see.
        inbox.put(None, control=True)
        writer.join(timeout=DRAIN_SECONDS)
        time.sleep(SEND_SECONDS)
    server.stop()
    if dropped[0]:
        log.info("dropped %d samples while falling behind", dropped[0])
    if recorder.rejected:
        log.info("refused %d samples (the recorder/rejected channel)", recorder.rejected)
    return ended[0] if ended else 0


def _forward(recorder: McapRecorder, inbox: BoundedInbox[Sample | None]) -> None:
    """The one thread that builds records, in arrival order."""
    while (item := inbox.get()) is not None:
        recorder.record(item)


if __name__ == "__main__":
    process_main.end(main())
