"""Run keys: who may say what, checked with a message authentication code (no Zenoh).

Every run has a random 32-byte secret. Each identity of the run has its own key derived
from it, ``HMAC-SHA256(secret, b"bestofn-key:" + identity)``; identities are ``world``,
``robot/<id>``, ``beacon/<name>``, ``launcher``, ``recorder``, and the observers ``viewer``
and ``foxglove``. The processes that run or watch the run (world server, launcher,
recorder, beacon, observers) hold the secret; a robot process holds only the keys of the
robots it hosts, so whatever it says can only be in their names.

Every message of a keyed run carries a 16-byte tag in front of its Zenoh attachment::

    attachment = tag + metadata       (metadata: what the attachment held before, or b"")
    tag = HMAC-SHA256(key, u32(len(key_expr)) key_expr u32(len(metadata)) metadata
                           u32(len(payload)) payload)[:16]

with ``u32`` a 4-byte big-endian length and the key expression in UTF-8. The key is the
sender's, except for what the world sends a robot (``sense``, ``camera``, ``radio/rx``),
which carries the receiving robot's key: a robot holds no other. docs/protocol.md gives
the byte-exact rules and a test vector (tests/vectors/auth.json).
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import json
import struct
from collections.abc import Iterable, Mapping
from typing import Any

from bestofn_swarm.wire.names import check_identity

SECRET_BYTES = 32
KEY_BYTES = 32
TAG_BYTES = 16
NONCE_BYTES = 16
KEY_LABEL = b"bestofn-key:"


class AuthError(ValueError):
    """A message without a valid tag for the identity it claims."""


def derive_key(secret: bytes, identity: str) -> bytes:
    """The key of one identity of the run."""
    if len(secret) != SECRET_BYTES:
        raise ValueError(f"a run secret has {SECRET_BYTES} bytes, not {len(secret)}")
    return hmac.digest(secret, KEY_LABEL + check_identity(identity).encode(), hashlib.sha256)


_U32 = struct.Struct(">I")


@functools.lru_cache(maxsize=4096)
def _framed_key(key_expr: str) -> bytes:
    """``u32(len K) K``: a process tags on a few keys, over and over."""
    encoded = key_expr.encode()
    return _U32.pack(len(encoded)) + encoded


def _framed(key_expr: str, metadata: bytes, payload: bytes) -> bytes:
    pack = _U32.pack
    return b"".join(
        (_framed_key(key_expr), pack(len(metadata)), metadata, pack(len(payload)), payload)
    )


_BLOCK = 64  # SHA-256's block size, HMAC's key length


@functools.lru_cache(maxsize=4096)
def _hmac_pads(key: bytes) -> tuple[Any, Any]:
    """SHA-256 states that have taken in HMAC's inner and outer padded keys (RFC 2104).

    A process tags with a few keys over and over; ``hmac.digest`` starts from the key each
    time, which made it most of the cost of a tag (4 of 5 microseconds): copying these
    states is the same HMAC-SHA256, byte for byte (tests/vectors/auth.json)."""
    if len(key) > _BLOCK:
        key = hashlib.sha256(key).digest()
    key = key.ljust(_BLOCK, b"\0")
    inner = hashlib.sha256(bytes(byte ^ 0x36 for byte in key))
    outer = hashlib.sha256(bytes(byte ^ 0x5C for byte in key))
    return inner, outer


def tag(key: bytes, key_expr: str, metadata: bytes, payload: bytes) -> bytes:
    """The 16-byte tag of one message: its key expression, metadata and payload."""
    inner_pad, outer_pad = _hmac_pads(key)
    inner = inner_pad.copy()
    inner.update(_framed(key_expr, metadata, payload))
    outer = outer_pad.copy()
    outer.update(inner.digest())
    return bytes(outer.digest()[:TAG_BYTES])


class Keyring:
    """The keys one process holds: the run secret (any identity), or some identities' keys."""

    def __init__(self, secret: bytes | None = None, keys: Mapping[str, bytes] | None = None):
        if secret is not None and len(secret) != SECRET_BYTES:
            raise ValueError(f"a run secret has {SECRET_BYTES} bytes, not {len(secret)}")
        for identity, key in (keys or {}).items():
            check_identity(identity)
            if len(key) != KEY_BYTES:
                raise ValueError(f"the key of {identity} has {len(key)} bytes, not {KEY_BYTES}")
        self.secret = secret
        self._keys: dict[str, bytes] = dict(keys or {})
        self._derived: dict[str, bytes] = {}  # keys derived from the secret, kept

    @property
    def identities(self) -> list[str]:
        """Identities whose keys are held without the secret."""
        return sorted(self._keys)

    def key(self, identity: str) -> bytes | None:
        """The key of ``identity``, or None if this keyring cannot speak or check for it."""
        key = self._keys.get(identity) or self._derived.get(identity)
        if key is None and self.secret is not None:
            key = self._derived[identity] = derive_key(self.secret, identity)
        return key

    def holds(self, identity: str) -> bool:
        return self.key(identity) is not None

    def only(self, identities: Iterable[str]) -> Keyring:
        """A keyring with just these identities' keys (what a robot process is given)."""
        keys = {}
        for identity in identities:
            key = self.key(identity)
            if key is None:
                raise ValueError(f"no key for {identity}")
            keys[identity] = key
        return Keyring(keys=keys)

    def seal(self, identity: str, key_expr: str, payload: bytes, metadata: bytes = b"") -> bytes:
        """The attachment of a message sent as (or to) ``identity``: tag + metadata."""
        key = self.key(identity)
        if key is None:
            raise AuthError(f"no key for {identity}")
        return tag(key, key_expr, metadata, payload) + metadata

    def open(self, identity: str, key_expr: str, payload: bytes, attachment: bytes | None) -> bytes:
        """The metadata of a message whose tag is ``identity``'s; AuthError otherwise."""
        key = self.key(identity)
        if key is None:
            raise AuthError(f"no key to check {identity}")
        if attachment is None or len(attachment) < TAG_BYTES:
            raise AuthError("no authentication tag")
        metadata = attachment[TAG_BYTES:]
        if not hmac.compare_digest(attachment[:TAG_BYTES], tag(key, key_expr, metadata, payload)):
            raise AuthError(f"not tagged by {identity}'s key")
        return metadata


def seal(
    keyring: Keyring | None, identity: str, key_expr: str, payload: bytes, metadata: bytes = b""
) -> bytes | None:
    """The attachment to send: tag + metadata in a keyed run; the bare metadata (or none)
    in an unkeyed one, as the wire was before run keys."""
    if keyring is None:
        return metadata or None
    return keyring.seal(identity, key_expr, payload, metadata)


def unseal(
    keyring: Keyring | None,
    identity: str,
    key_expr: str,
    payload: bytes,
    attachment: bytes | None,
) -> bytes | None:
    """The metadata of a received message (None: no attachment in an unkeyed run)."""
    if keyring is None:
        return attachment
    return keyring.open(identity, key_expr, payload, attachment)


# --- queries and replies -----------------------------------------------------------------
# A query's metadata is a fresh nonce and the asker's identity, tagged with the asker's key;
# the reply's metadata is the same nonce, tagged with the asker's key too (the replier holds
# the run secret), so a robot that holds only its own key can check the world's answers and
# no old answer can be replayed to a new question.


def query_seal(
    keyring: Keyring | None, identity: str, key_expr: str, payload: bytes, nonce: bytes
) -> bytes | None:
    """The attachment of a query asked as ``identity`` (None in an unkeyed run)."""
    if keyring is None:
        return None
    if len(nonce) != NONCE_BYTES:
        raise ValueError(f"a nonce has {NONCE_BYTES} bytes")
    return keyring.seal(identity, key_expr, payload, nonce + identity.encode())


def query_open(
    keyring: Keyring | None, key_expr: str, payload: bytes, attachment: bytes | None
) -> tuple[str, bytes]:
    """Who asked, and the nonce to answer with; AuthError unless the tag is theirs."""
    if keyring is None:
        return "", b""
    if attachment is None or len(attachment) < TAG_BYTES + NONCE_BYTES:
        raise AuthError("no authentication tag")
    metadata = attachment[TAG_BYTES:]
    try:
        identity = check_identity(metadata[NONCE_BYTES:].decode())
    except (UnicodeDecodeError, ValueError):
        raise AuthError("the query names no identity of the run") from None
    keyring.open(identity, key_expr, payload, attachment)
    return identity, metadata[:NONCE_BYTES]


def reply_seal(
    keyring: Keyring | None, identity: str, key_expr: str, payload: bytes, nonce: bytes
) -> bytes | None:
    """The attachment of the answer to ``identity``'s query (None in an unkeyed run)."""
    if keyring is None:
        return None
    return keyring.seal(identity, key_expr, payload, nonce)


def reply_open(
    keyring: Keyring | None,
    identity: str,
    key_expr: str,
    payload: bytes,
    attachment: bytes | None,
    *,
    nonce: bytes,
) -> None:
    """Raise AuthError unless this reply answers ``identity``'s query with ``nonce``."""
    if keyring is None:
        return
    if keyring.open(identity, key_expr, payload, attachment) != nonce:
        raise AuthError("the reply answers another query")


# --- key files -----------------------------------------------------------------------------
# A key file (or the launcher's variable) is one JSON object: the run secret for the run's
# infrastructure, or some identities' keys for a robot:
#     {"v": 1, "run": "<run id>", "secret": "<64 hex digits>"}
#     {"v": 1, "run": "<run id>", "keys": {"robot/3": "<64 hex digits>"}}


def keyring_to_text(keyring: Keyring, run: str) -> str:
    content: dict[str, object] = {"v": 1, "run": run}
    if keyring.secret is not None:
        content["secret"] = keyring.secret.hex()
    else:
        content["keys"] = {
            identity: (keyring.key(identity) or b"").hex() for identity in keyring.identities
        }
    return json.dumps(content, separators=(",", ":"))


def keyring_from_text(text: str) -> tuple[str, Keyring]:
    """The run and the keyring in a key file's ``text``; ValueError says what is wrong
    (never echoes a key)."""
    try:
        content = json.loads(text)
    except ValueError:
        raise ValueError("not JSON") from None
    if not isinstance(content, dict) or content.get("v") != 1:
        raise ValueError('not a run key object ({"v": 1, ...})')
    run = content.get("run")
    if not isinstance(run, str):
        raise ValueError("the keys name no run")
    try:
        if "secret" in content:
            return run, Keyring(secret=bytes.fromhex(content["secret"]))
        keys = content.get("keys")
        if not isinstance(keys, dict) or not keys:
            raise ValueError('neither "secret" nor "keys"')
        return run, Keyring(keys={str(name): bytes.fromhex(value) for name, value in keys.items()})
    except (TypeError, AttributeError):
        raise ValueError("keys must be hexadecimal strings") from None
