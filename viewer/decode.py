"""The one gate every sample the live view receives passes through.

``decode_sample(keys, key, payload, attachment)`` returns the decoded, validated message
of a key the view uses, or None (a key it does not use, or a sample that is not a valid
message: counted by the caller, never drawn). Checks that apply to every message of a
run, such as verifying a per-message authentication tag carried in the attachment, belong
here, before the payload is decoded.
"""

from __future__ import annotations

from dataclasses import dataclass

from robot_agent import protocol


@dataclass(frozen=True)
class Delivery:
    """A radio message the medium delivered to ``receiver`` (metadata only: the view never
    needs the payload)."""

    receiver: int
    meta: protocol.RadioRxMeta


Decoded = protocol.Clock | protocol.WorldState | protocol.Status | Delivery


class InvalidSampleError(Exception):
    """A sample on a key the view uses that is not a valid message of that key."""


def decode_sample(
    keys: protocol.Keys, key: str, payload: bytes, attachment: bytes | None
) -> Decoded | None:
    """The message a sample carries, if the view uses its key.

    Raises InvalidSampleError for a sample on a used key that does not decode or validate.
    """
    try:
        if key == keys.world_state:
            return protocol.decode(payload, protocol.WorldState)
        if key == keys.world_clock:
            return protocol.decode(payload, protocol.Clock)
        robot = keys.robot_of(key)
        if robot is not None and key == keys.status(robot):
            status = protocol.decode(payload, protocol.Status)
            if status.id != robot:
                raise InvalidSampleError(f"status of robot {status.id} on {key}")
            return status
        if key.startswith(keys.radio_rx("")):
            receiver = keys.last_chunk(key)
            if not receiver.isdigit() or int(receiver) >= protocol.MAX_ROBOTS:
                return None  # a receiver that is not a robot (none today): nothing to draw
            if attachment is None:
                raise InvalidSampleError(f"radio delivery without metadata on {key}")
            return Delivery(int(receiver), protocol.decode(attachment, protocol.RadioRxMeta))
    except protocol.ProtocolError as error:
        raise InvalidSampleError(f"{key}: {error}") from None
    return None
