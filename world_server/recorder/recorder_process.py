"""``python -m world_server.recorder``: the process that records every message of one run
into one MCAP file (``world_server/recording/writer.py`` writes it).

It subscribes to ``<root>/<run>/**`` before it declares its liveliness token, and Zenoh
callbacks only append ``(key, payload, attachment, wall time)`` to an inbox that one
writer thread (``write_loop.py``) empties, in arrival order, until the run's ending
(``world/ending``: the file is closed with the summary it carries, and the recorder exits
with the run's exit code), the launcher's finish query (``finish.py``; with
``--await-finish``, as ``swarm run`` starts it, only that closes the file) or a stop
signal.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing import process_main, settings_cli
from bestofn_swarm.plumbing.ending import MAX_ENDING_SAMPLE_BYTES, hear_ending
from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.plumbing.private_files import open_private
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.names import Role
from world_server.recorder.finish import query_parts
from world_server.recorder.options import RECORDER_OPTIONS, build_parser
from world_server.recorder.write_loop import STOP, Ended, Finish, write_loop
from world_server.recording.description import RunDescription
from world_server.recording.writer import McapRecorder, Sample

log = logging.getLogger("recorder")

INBOX_BYTES = 256 * 2**20  # what may wait for the writer thread, at most
# A camera frame and its attachment, or the run's ending (it carries the summary).
MAX_SAMPLE_BYTES = max(protocol.MAX_CAMERA_FRAME_BYTES + 1024, MAX_ENDING_SAMPLE_BYTES)


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


def recorded_run(parser: argparse.ArgumentParser, args: argparse.Namespace) -> RunDescription:
    """The run being recorded (``--config`` or the options), checked against ``--run-id``."""
    run: RunDescription = settings_cli.config_from(
        parser, args, RECORDER_OPTIONS, {"run_id": args.run_id}
    )
    if run.run_id != args.run_id:
        parser.exit(
            2, f"recorder: error: --config is of run {run.run_id!r}, not --run-id {args.run_id!r}\n"
        )
    return run


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin(
        "recorder",
        parser,
        argv,
        recorded_run,
        runs_cores=False,
        needs_secret="the recorder",
        lower_priority=True,
    )
    args, run, keyring, keys = begun.args, begun.settings, begun.keyring, begun.keys
    import zenoh

    from bestofn_swarm.plumbing.zenoh_session import open_from_args

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
        ending = hear_ending(
            session, keys, keyring, lambda heard: inbox.put(Ended(heard), control=True)
        )
        info = _world_info(session, keys, args.info_timeout, keyring)
        recorder = McapRecorder(stream, keys, run, info, keyring=keyring)
        done = threading.Event()
        ended: list[protocol.RunEnding] = []
        writer = threading.Thread(
            target=write_loop,
            args=(recorder, inbox, keys, done),
            kwargs={"await_finish": args.await_finish, "ended": ended},
            name="mcap-writer",
            daemon=True,
        )
        writer.start()
        token = session.liveliness().declare_token(keys.token(Role.RECORDER, 0))
        log.info("recording %s to %s", keys.all, out)
        while not done.wait(0.2):  # wake up for signals
            pass
        token.undeclare()
        ending.undeclare()
        queryable.undeclare()
        subscriber.undeclare()
        if not recorder.closed:  # the writer thread failed: keep what can be kept
            with contextlib.suppress(Exception):
                recorder.finish(finished_by="error")
            return 1
    return ended[0].code if ended else 0


if __name__ == "__main__":
    process_main.end(main())
