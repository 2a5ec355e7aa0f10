"""The recorder's writer thread: Zenoh callbacks only put samples (and a finish query, the
run's ending, or a stop) into one inbox, and this thread records them in arrival order."""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

from bestofn_swarm.plumbing.inbox import BoundedInbox
from bestofn_swarm.wire import keyspace, protocol
from world_server.recorder.finish import finish_on_query, refused
from world_server.recording.writer import McapRecorder, Sample

log = logging.getLogger("recorder")

# After a finish query (or a stop signal), keep recording until nothing arrived for QUIET
# seconds, but no longer than LIMIT (the stop's 3 s grace bounds STOP_DRAIN_LIMIT).
FINISH_QUIET, FINISH_DRAIN_LIMIT = 0.2, 10.0
STOP_QUIET, STOP_DRAIN_LIMIT = 0.1, 1.0


class Finish:
    """A finish query in the queue: everything queued before it is recorded first."""

    def __init__(self, query: Any) -> None:
        self.query = query


STOP = object()  # a stop signal in the queue


class Ended:
    """The run's ending, heard (``world/ending``): closes the recording with its summary,
    unless a launcher finishes it (``await_finish``)."""

    def __init__(self, ending: protocol.RunEnding) -> None:
        self.ending = ending


def write_loop(
    recorder: McapRecorder,
    inbox: BoundedInbox[Any],
    keys: keyspace.Keys,
    done: threading.Event,
    *,
    await_finish: bool = False,
    ended: list[protocol.RunEnding] | None = None,
) -> None:
    """The writer thread: record samples in arrival order until a finish query, a stop, or
    (unless ``await_finish``) the run's ending, which it appends to ``ended``."""
    try:
        while True:
            item = inbox.get()
            if isinstance(item, Sample):
                recorder.record(item)
            elif isinstance(item, Ended):
                if await_finish:
                    continue  # recorded as a sample; the launcher's query finishes the file
                _drain(recorder, inbox, FINISH_QUIET, FINISH_DRAIN_LIMIT)
                recorder.finish(item.ending.summary, finished_by="ending")
                if ended is not None:
                    ended.append(item.ending)
                log.info("recording complete, the run ended %s", item.ending.ended)
                return
            elif isinstance(item, Finish):
                if refused(recorder, item.query, keys):
                    continue
                _drain(recorder, inbox, FINISH_QUIET, FINISH_DRAIN_LIMIT)
                finish_on_query(recorder, item.query, keys)
                return
            elif item is STOP:
                _drain(recorder, inbox, STOP_QUIET, STOP_DRAIN_LIMIT)
                recorder.rejected += inbox.take_dropped(None)
                recorder.finish(finished_by="signal")
                log.info("recording closed on a signal, without a run summary")
                return
    finally:
        done.set()


def _drain(recorder: McapRecorder, inbox: BoundedInbox[Any], quiet: float, limit: float) -> None:
    """Record what still arrives until the inbox stays empty for ``quiet`` seconds.

    Zenoh keeps order per publisher, not between a query and other publishers' samples:
    a sample published just before the finish query can arrive just after it.
    """
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        try:
            item = inbox.get(timeout=quiet)
        except queue.Empty:
            break
        if isinstance(item, Sample):
            recorder.record(item)
    recorder.rejected += inbox.take_dropped(None)
