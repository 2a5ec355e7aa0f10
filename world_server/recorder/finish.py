"""The recorder's finish query: the launcher asks it to close the recording, with the run
summary as the query's payload, and hears back once the file is whole."""

from __future__ import annotations

import json
import logging
import time
from typing import Any

from bestofn_swarm.wire import auth, keyspace, names
from world_server.recording.writer import McapRecorder, Sample

log = logging.getLogger("recorder")


def query_parts(query: Any) -> tuple[bytes, bytes | None]:
    payload = query.payload.to_bytes() if query.payload is not None else b""
    attachment = query.attachment.to_bytes() if query.attachment is not None else None
    return payload, attachment


def refused(recorder: McapRecorder, query: Any, keys: keyspace.Keys) -> bool:
    """Whether a finish query is someone's but the launcher's (then counted and refused).

    In a keyed run only the launcher that started the recorder holds the key to finish it.
    """
    payload, attachment = query_parts(query)
    try:
        asker, _ = auth.query_open(
            recorder.keyring, keys.of(keyspace.RECORDER_FINISH), payload, attachment
        )
        if recorder.keyring is not None and asker != names.LAUNCHER:
            raise auth.AuthError(f"{asker} may not finish the recording")
    except auth.AuthError as error:
        sample = Sample(keys.of(keyspace.RECORDER_FINISH), payload, attachment, time.time_ns())
        recorder.reject(sample, f"finish query refused: {error}")
        query.reply_err(b"unauthenticated query")
        query.drop()
        return True
    return False


def finish_on_query(recorder: McapRecorder, query: Any, keys: keyspace.Keys) -> None:
    """Close the recording with the query's summary, then answer the query."""
    payload, attachment = query_parts(query)
    asker, nonce = auth.query_open(
        recorder.keyring, keys.of(keyspace.RECORDER_FINISH), payload, attachment
    )
    summary: Any = None
    if payload:
        try:
            summary = json.loads(payload)
        except ValueError:
            summary = payload.decode("utf-8", "replace")
    recorder.finish(summary, finished_by="finish query")
    answer = b"ok"
    sealed = auth.reply_seal(
        recorder.keyring, asker, keys.of(keyspace.RECORDER_FINISH), answer, nonce
    )
    query.reply(keys.of(keyspace.RECORDER_FINISH), answer, attachment=sealed)
    query.drop()  # sends the final reply now, not when the object is collected
    log.info("recording complete: %s", dict(sorted(recorder.counts.items())))
