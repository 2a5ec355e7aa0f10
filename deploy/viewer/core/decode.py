"""The one gate every sample the live view receives passes through.

``decode_sample(keys, key, payload, attachment, keyring=...)`` returns the decoded,
validated message of a key the view uses, or None (a key it does not use). A sample on a
used key that is not a valid message raises InvalidSampleError: counted by the caller,
never drawn. In a keyed run the tag at the start of the attachment is checked first,
against the identity whose key tags that key (docs/protocol.md): ``world/state`` and
``world/clock`` the world's, ``link/<id>/stats`` the bridge's, ``robot/<id>/status``
robot ``<id>``'s, ``radio/rx/<id>`` the *receiving* robot's (the world tags what it sends
a robot with that robot's key).
Only then is the tag stripped and the metadata and payload decoded.
"""

from __future__ import annotations

from dataclasses import dataclass

from bestofn_swarm.wire import auth, keyspace, protocol


@dataclass(frozen=True)
class Delivery:
    """A radio message the medium delivered to ``receiver`` (metadata only: the view never
    needs the payload)."""

    receiver: int
    meta: protocol.RadioRxMeta


Decoded = protocol.Clock | protocol.WorldState | protocol.Status | protocol.LinkStats | Delivery


class InvalidSampleError(Exception):
    """A sample on a key the view uses that is not a valid message of that key, or does
    not carry its speaker's tag."""


# The kinds of the key table (bestofn_swarm/wire/keyspace.py) the view draws.
VIEWED = frozenset({"state", "clock", "link", "status", "radio_rx"})


def _viewed(keys: keyspace.Keys, key: str) -> keyspace.Classified | None:
    """The key, read by the key table, if the view uses it."""
    found = keyspace.classify(keys, key)
    return found if found is not None and found.kind.name in VIEWED else None


def speaker(keys: keyspace.Keys, key: str) -> str | None:
    """The identity whose tag a sample on ``key`` must carry, if the view uses the key."""
    found = _viewed(keys, key)
    return None if found is None else found.speaker


def decode_sample(
    keys: keyspace.Keys,
    key: str,
    payload: bytes,
    attachment: bytes | None,
    *,
    keyring: auth.Keyring | None,
) -> Decoded | None:
    """The message a sample carries, if the view uses its key (``keyring``: the run's
    keys, None in an unkeyed run, where the attachment is the bare metadata).

    Raises InvalidSampleError for a sample on a used key that fails its tag, or does not
    decode or validate.
    """
    found = _viewed(keys, key)
    if found is None:
        return None
    identity = found.speaker
    assert identity is not None  # every viewed kind has a speaker of its own
    try:
        metadata = auth.unseal(keyring, identity, key, payload, attachment)
    except auth.AuthError as error:
        raise InvalidSampleError(f"{key}: {identity}: {error}") from None
    kind, robot = found.kind.name, found.robot
    try:
        if kind == "state":
            return protocol.decode(payload, protocol.WorldState)
        if kind == "clock":
            return protocol.decode(payload, protocol.Clock)
        if kind == "link":
            stats = protocol.decode(payload, protocol.LinkStats)
            if stats.robot != robot:
                raise InvalidSampleError(f"the link of robot {stats.robot} on {key}")
            return stats
        if kind == "radio_rx":
            if not metadata:
                raise InvalidSampleError(f"radio delivery without metadata on {key}")
            assert robot is not None
            return Delivery(robot, protocol.decode(metadata, protocol.RadioRxMeta))
        status = protocol.decode(payload, protocol.Status)
        if status.id != robot:
            raise InvalidSampleError(f"status of robot {status.id} on {key}")
        return status
    except protocol.ProtocolError as error:
        raise InvalidSampleError(f"{key}: {error}") from None
