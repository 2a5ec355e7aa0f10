"""A message on its way out: typed for whoever takes it in the same process, bytes for a
transport (pure: no I/O).

The cores (the world's coordinator, a robot's endpoint, a hosting process, the beacon)
hand over what they send as a ``Parcel``: its key, the message itself, and what makes its
bytes. A core in the same process (the in-process engine) takes ``message`` and never
pays for bytes; a transport (Zenoh, a hardware link, a recorder) reads ``payload`` and
``attachment``, which are encoded and sealed the first time they are asked for, and
then kept. So encoding, sealing and decoding happen only at the edges, and the bytes a
transport sends are those the message always had.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bestofn_swarm.wire import auth

# What makes a message's bytes: None when the message is already bytes (a radio payload,
# a camera frame).
Encoder = Callable[[Any], bytes] | None


class Parcel:
    """One message to send on ``key``; ``payload`` and ``attachment`` are made on demand.

    ``meta`` is what the attachment carries beside the sender's tag (a radio message's or
    a camera frame's metadata), made by ``meta_encode``; ``identity`` is whose key tags it
    when ``keyring`` is set (an unkeyed run sends the bare metadata, or no attachment).
    """

    def __init__(
        self,
        key: str,
        message: Any,
        encode: Encoder,
        *,
        identity: str,
        keyring: auth.Keyring | None,
        meta: Any = None,
        meta_encode: Encoder = None,
    ) -> None:
        self.key = key
        self.message = message
        self.encode = encode
        self.identity = identity
        self.keyring = keyring
        self.meta = meta
        self.meta_encode = meta_encode
        self._payload: bytes | None = None
        self._attachment: bytes | None = None
        self._sealed = False

    @property
    def payload(self) -> bytes:
        """The message's bytes (encoded once)."""
        payload = self._payload
        if payload is None:
            message = self.message
            payload = message if self.encode is None else self.encode(message)
            self._payload = payload
        return payload

    @property
    def attachment(self) -> bytes | None:
        """The tag and metadata to send beside the payload (sealed once)."""
        if not self._sealed:
            meta = self.meta
            if meta is None:
                metadata = b""
            else:
                metadata = meta if self.meta_encode is None else self.meta_encode(meta)
            self._attachment = auth.seal(
                self.keyring, self.identity, self.key, self.payload, metadata
            )
            self._sealed = True
        return self._attachment

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.key!r}, {self.message!r})"


__all__ = ["Encoder", "Parcel"]
