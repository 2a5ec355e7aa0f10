"""Asking the run's queryables (``world/info`` first of all) and believing only true answers.

In a keyed run a query carries a fresh nonce and the asker's tag, and only a reply tagged
for that nonce with the asker's key counts (bestofn_swarm/wire/auth.py): anyone else on the
router can answer too, but cannot make an answer that passes.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from typing import Any

import zenoh

from bestofn_swarm.wire import auth, keyspace, names, protocol


def ask(
    session: zenoh.Session,
    key: str,
    keyring: auth.Keyring | None,
    identity: str,
    *,
    payload: bytes = b"",
    timeout: float = 1.0,
    worth_waiting: Callable[[], bool] | None = None,
) -> tuple[list[bytes], list[str]]:
    """Query ``key`` once as ``identity``: the payloads of the replies that answer it, and
    what was wrong with the others (error replies, replies that fail their check).

    With ``worth_waiting``, ``timeout`` is only the longest wait: the query is given up as
    soon as ``worth_waiting()``, asked every ``POLL_SECONDS`` while no reply comes, says no.
    """
    nonce = os.urandom(auth.NONCE_BYTES) if keyring is not None else b""
    attachment = auth.query_seal(keyring, identity, key, payload, nonce)
    answers: list[bytes] = []
    refused: list[str] = []
    handler = session.get(key, payload=payload or None, attachment=attachment, timeout=timeout)
    for reply in _replies(handler, worth_waiting):
        ok, err = reply.ok, reply.err
        if ok is None:
            said = err.payload.to_bytes() if err is not None else b"neither an answer nor an error"
            refused.append(said.decode("utf-8", "replace")[:200])
            continue
        data = ok.payload.to_bytes()
        extra = ok.attachment
        try:
            auth.reply_open(
                keyring, identity, key, data, extra.to_bytes() if extra else None, nonce=nonce
            )
        except auth.AuthError as error:
            refused.append(f"a reply that does not check out ({error})")
            continue
        answers.append(data)
    return answers, refused


POLL_SECONDS = 0.5


def _replies(handler: Any, worth_waiting: Callable[[], bool] | None) -> Iterator[Any]:
    """The replies of a query, until it is done or no longer ``worth_waiting``."""
    if worth_waiting is None:
        yield from handler
        return
    while True:
        try:
            reply = handler.try_recv()
        except zenoh.ZError:  # the channel is closed: every reply is in, or the timeout passed
            return
        if reply is not None:
            yield reply
        elif worth_waiting():
            time.sleep(POLL_SECONDS)
        else:
            return


PROOF_TIMEOUT = 2.0  # seconds a world server has to answer for its token
PROOF_ATTEMPTS = 5  # tries before a token counts as no world's (the world may be busy)
NOT_THIS_INSTANCE = "not this world instance"  # a world's answer for another's token


def world_proved(
    session: zenoh.Session,
    keys: keyspace.Keys,
    keyring: auth.Keyring | None,
    identity: str,
    instance: str,
    *,
    timeout: float = PROOF_TIMEOUT,
    attempts: int = PROOF_ATTEMPTS,
) -> bool:
    """Whether the world server ``instance`` (a liveliness token ``alive/world/<instance>``
    says it is there) answers ``world/info`` for that instance: a token is only a hint,
    anyone can declare one, but in a keyed run only the world can make the answer pass.
    The query also proves the asker present to the world (its tag). Asked ``attempts``
    times before giving up: a busy world may not answer in time, and a refusal (the
    world's ``NOT_THIS_INSTANCE``) carries no tag, so anyone could send one. Another
    world's answer comes at once, so a fake token costs a few quick questions."""
    for _ in range(attempts):
        answers, _ = ask(
            session,
            keys.of(keyspace.INFO),
            keyring,
            identity,
            payload=instance.encode(),
            timeout=timeout,
        )
        if answers:
            return True
    return False


def fetch_world_info(
    session: zenoh.Session,
    keys: keyspace.Keys,
    timeout: float,
    keyring: auth.Keyring | None = None,
    identity: str = names.LAUNCHER,
) -> protocol.WorldInfo:
    """Ask ``world/info`` until a world server answers, or raise TimeoutError."""
    deadline = time.monotonic() + timeout
    last_error = "no reply"
    while time.monotonic() < deadline:
        answers, refused = ask(session, keys.of(keyspace.INFO), keyring, identity)
        if refused:
            last_error = refused[-1]
        for answer in answers:
            try:
                return protocol.decode(answer, protocol.WorldInfo)
            except protocol.ProtocolError as error:
                last_error = f"invalid world/info: {error}"
        time.sleep(0.1)
    raise TimeoutError(f"no world server answered on {keys.of(keyspace.INFO)} ({last_error})")
