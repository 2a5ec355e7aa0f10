"""``python -m world_server.recorder``: the process that records every message of one run
into one MCAP file (``world_server/recording/writer.py`` writes it).

It subscribes to ``<root>/<run>/**`` before it declares its liveliness token, and Zenoh
callbacks only append ``(key, payload, attachment, wall time)`` to an inbox that one
writer thread (``write_loop.py``) empties, in arrival order, until the launcher's finish
query (``finish.py``) or a stop signal.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing import cliargs, run_keys, settings_cli
from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.plumbing.lifecycle import die_with_launcher
from bestofn_swarm.plumbing.private_files import open_private
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.names import Role
from world_server.recorder.finish import query_parts
from world_server.recorder.options import RECORDER_OPTIONS, build_parser
from world_server.recorder.write_loop import STOP, Finish, write_loop
from world_server.recording.description import RunDescription
from world_server.recording.writer import McapRecorder, Sample

log = logging.getLogger("recorder")

INBOX_BYTES = 256 * 2**20  # what may wait for the writer thread, at most
MAX_SAMPLE_BYTES = protocol.MAX_CAMERA_FRAME_BYTES + 1024  # a frame and its attachment


def _lower_priority(niceness: int) -> None:
    """Yield the CPU to the swarm; a platform without nice() just records at full priority."""
    try:
        os.nice(niceness)
    except (AttributeError, OSError) as error:
        log.info("could not lower the recorder's priority: %s", error)


def _world_info(
    session: Any, keys: keyspace.Keys, timeout: float, keyring: auth.Keyring | None
) -> protocol.WorldInfo | None:
    """The world's info if a world server answers in time (it gives dt and robot size)."""
    from bestofn_swarm.plumbing.world_info import fetch_world_info

    try:
        return fetch_world_info(session, keys, timeout, keyring, names.RECORDER)
    except TimeoutError as error:
        log.warning("%s; sim times will follow world/clock", error)
        return None


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()
    parser = build_parser()
    args = parser.parse_args(argv)
    run: RunDescription = settings_cli.config_from(
        parser, args, RECORDER_OPTIONS, {"run_id": args.run_id}
    )
    if run.run_id != args.run_id:
        parser.exit(
            2, f"recorder: error: --config is of run {run.run_id!r}, not --run-id {args.run_id!r}\n"
        )
    cliargs.configure_logging("recorder", args.log_level)
    from bestofn_swarm.plumbing.zenoh_session import check_config_files, open_from_args

    check_config_files(parser, args)  # before the keys' warning: one line if it fails
    keyring = run_keys.from_args(parser, args, "recorder")
    if keyring is not None and keyring.secret is None:
        parser.exit(2, "recorder: error: the recorder needs the run secret\n")
    if args.niceness:  # before Zenoh starts its threads, so that they inherit it
        _lower_priority(args.niceness)
    import zenoh

    keys = keyspace.Keys(args.run_id, args.root)
    out = Path(args.out)
    try:
        stream = open_private(out, "wb")  # a recording holds the whole run: its owner's
    except OSError as error:
        print(f"recorder: cannot write {out}: {error}", file=sys.stderr)
        return 1
    # Anything bigger than a camera frame is junk: dropped on arrival, counted.
    inbox: BoundedInbox[Any] = BoundedInbox(INBOX_BYTES, MAX_SAMPLE_BYTES)
    on_stop_signals(lambda _: inbox.put(STOP, control=True))  # the writer sees it later

    def on_sample(sample: zenoh.Sample) -> None:
        attachment = sample.attachment
        payload = sample.payload.to_bytes()
        extra = attachment.to_bytes() if attachment is not None else None
        key = str(sample.key_expr)
        inbox.put(Sample(key, payload, extra, time.time_ns()), message_bytes(payload, extra, key))

    def on_finish(query: zenoh.Query) -> None:
        """The finish query, after what came before it; refused at once if no room."""
        payload, attachment = query_parts(query)
        size = message_bytes(payload, attachment, keys.of(keyspace.RECORDER_FINISH))
        if not inbox.put(Finish(query), size, once=True):
            query.reply_err(b"the recorder has no room for the query")
            query.drop()

    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"recorder: cannot open Zenoh session: {error}", file=sys.stderr)
        stream.close()
        return 1
    with session, stream:
        subscriber = session.declare_subscriber(keys.all, on_sample)
        queryable = session.declare_queryable(keys.of(keyspace.RECORDER_FINISH), on_finish)
        info = _world_info(session, keys, args.info_timeout, keyring)
        recorder = McapRecorder(stream, keys, run, info, keyring=keyring)
        done = threading.Event()
        writer = threading.Thread(
            target=write_loop,
            args=(recorder, inbox, keys, done),
            name="mcap-writer",
            daemon=True,
        )
        writer.start()
        token = session.liveliness().declare_token(keys.token(Role.RECORDER, 0))
        log.info("recording %s to %s", keys.all, out)
        while not done.wait(0.2):  # wake up for signals
            pass
        token.undeclare()
        queryable.undeclare()
        subscriber.undeclare()
        if not recorder.closed:  # the writer thread failed: keep what can be kept
            with contextlib.suppress(Exception):
                recorder.finish(finished_by="error")
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
