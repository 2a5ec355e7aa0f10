"""Hearing the run's ending: every process of a run subscribes to ``world/ending`` and
exits once its world says the run ended (world_server/observer/referee.py decides).

A sample is believed only through the key table's gate (``keyspace.open_sample``): with
the world's tag for a process that holds the world's key or the run secret, else with the
tag the world added for one of its own keys (a robot's, the bridge's: ``EndingSeals``). A
sample that is not believed (forged, replayed from another run, junk) is handed to
``on_refused`` and changes nothing; the first believed one is handed to ``on_ending``,
once, from Zenoh's callback thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from bestofn_swarm.wire import auth, keyspace, protocol

# A sample larger than this cannot be an ending: dropped before it is read.
MAX_ENDING_SAMPLE_BYTES = 2 * protocol.MAX_ENDING_BYTES
_KINDS = frozenset({keyspace.ENDING})


def open_ending(
    keys: keyspace.Keys,
    key: str,
    payload: bytes,
    attachment: bytes | None,
    keyring: auth.Keyring | None,
) -> protocol.RunEnding:
    """The ending a sample holds, checked; raises ``keyspace.SampleError``."""
    if len(payload) + len(attachment or b"") > MAX_ENDING_SAMPLE_BYTES:
        raise keyspace.SampleError(f"{key}: {len(payload)} bytes, too large for an ending")
    opened = keyspace.open_sample(keys, key, payload, attachment, keyring=keyring, kinds=_KINDS)
    if opened is None:
        raise keyspace.SampleError(f"{key} is not the run's ending")
    ending: protocol.RunEnding = opened.message
    if ending.run != keys.run:
        raise keyspace.SampleError(f"{key}: the ending of run {ending.run!r}")
    return ending


def hear_ending(
    session: Any,
    keys: keyspace.Keys,
    keyring: auth.Keyring | None,
    on_ending: Callable[[protocol.RunEnding], object],
    on_refused: Callable[[str], object] | None = None,
) -> Any:
    """Subscribe ``session`` to the run's ending; the subscriber (undeclare it to stop:
    a ``zenoh.Subscriber``)."""
    heard = threading.Event()

    def callback(sample: Any) -> None:
        payload = sample.payload.to_bytes()
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        try:
            ending = open_ending(keys, str(sample.key_expr), payload, attachment, keyring)
        except keyspace.SampleError as error:
            if on_refused is not None:
                on_refused(str(error))
            return
        if not heard.is_set():
            heard.set()
            on_ending(ending)

    return session.declare_subscriber(keys.of(keyspace.ENDING), callback)


__all__ = ["MAX_ENDING_SAMPLE_BYTES", "hear_ending", "open_ending"]
