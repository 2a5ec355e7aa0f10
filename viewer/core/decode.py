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

from wire import auth, names, protocol


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


def speaker(keys: protocol.Keys, key: str) -> str | None:
    """The identity whose tag a sample on ``key`` must carry, if the view uses the key."""
    if key in (keys.world_state, keys.world_clock):
        return names.WORLD
    outside = keys.robot_of(key, "link")
    if outside is not None and key == keys.link_stats(outside):
        return names.BRIDGE
    robot = keys.robot_of(key)
    if robot is not None and key == keys.status(robot):
        return names.robot_identity(robot)
    receiver = _receiver(keys, key)
    if receiver is not None:
        return names.robot_identity(receiver)
    return None


def _receiver(keys: protocol.Keys, key: str) -> int | None:
    """The robot in ``radio/rx/<id>``; None for any other key, or a receiver that is not a
    robot (none today: nothing to draw). One spelling per robot: "07" names none."""
    name = keys.last_chunk(key)
    if key != keys.radio_rx(name):
        return None
    return names.robot_of_name(name)


def decode_sample(
    keys: protocol.Keys,
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
    identity = speaker(keys, key)
    if identity is None:
        return None
    try:
        metadata = auth.unseal(keyring, identity, key, payload, attachment)
    except auth.AuthError as error:
        raise InvalidSampleError(f"{key}: {identity}: {error}") from None
    try:
        if key == keys.world_state:
            return protocol.decode(payload, protocol.WorldState)
        if key == keys.world_clock:
            return protocol.decode(payload, protocol.Clock)
        outside = keys.robot_of(key, "link")
        if outside is not None:
            stats = protocol.decode(payload, protocol.LinkStats)
            if stats.robot != outside:
                raise InvalidSampleError(f"the link of robot {stats.robot} on {key}")
            return stats
        receiver = _receiver(keys, key)
        if receiver is not None:
            if not metadata:
                raise InvalidSampleError(f"radio delivery without metadata on {key}")
            return Delivery(receiver, protocol.decode(metadata, protocol.RadioRxMeta))
        status = protocol.decode(payload, protocol.Status)
        if status.id != keys.robot_of(key):
            raise InvalidSampleError(f"status of robot {status.id} on {key}")
        return status
    except protocol.ProtocolError as error:
        raise InvalidSampleError(f"{key}: {error}") from None
