"""Asking the run's queryables (``world/info`` first of all) and believing only true answers.

In a keyed run a query carries a fresh nonce and the asker's tag, and only a reply tagged
for that nonce with the asker's key counts (robot_agent/auth.py): anyone else on the
router can answer too, but cannot make an answer that passes.
"""

from __future__ import annotations

import os
import time

import zenoh

from robot_agent import auth, protocol


def ask(
    session: zenoh.Session,
    key: str,
    keyring: auth.Keyring | None,
    identity: str,
    *,
    payload: bytes = b"",
    timeout: float = 1.0,
) -> tuple[list[bytes], list[str]]:
    """Query ``key`` once as ``identity``: the payloads of the replies that answer it, and
    what was wrong with the others (error replies, replies that fail their check)."""
    nonce = os.urandom(auth.NONCE_BYTES) if keyring is not None else b""
    attachment = auth.query_seal(keyring, identity, key, payload, nonce)
    answers: list[bytes] = []
    refused: list[str] = []
    for reply in session.get(key, payload=payload or None, attachment=attachment, timeout=timeout):
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


def fetch_world_info(
    session: zenoh.Session,
    keys: protocol.Keys,
    timeout: float,
    keyring: auth.Keyring | None = None,
    identity: str = auth.LAUNCHER,
) -> protocol.WorldInfo:
    """Ask ``world/info`` until a world server answers, or raise TimeoutError."""
    deadline = time.monotonic() + timeout
    last_error = "no reply"
    while time.monotonic() < deadline:
        answers, refused = ask(session, keys.world_info, keyring, identity)
        if refused:
            last_error = refused[-1]
        for answer in answers:
            try:
                return protocol.decode(answer, protocol.WorldInfo)
            except protocol.ProtocolError as error:
                last_error = f"invalid world/info: {error}"
        time.sleep(0.1)
    raise TimeoutError(f"no world server answered on {keys.world_info} ({last_error})")
