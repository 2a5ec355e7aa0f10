"""The one gate every sample the live view receives passes through: the key table's.

``decode_sample(keys, key, payload, attachment, keyring=...)`` returns the sample of a key
the view uses, opened (``keyspace.Opened``: its kind, the robot it names, its message and
metadata), or None (a key it does not use). A sample on a used key that is not a valid
message raises InvalidSampleError: counted by the caller, never drawn. In a keyed run the
tag at the start of the attachment is checked first, against the identity whose key tags
that key (docs/protocol.md): ``world/state`` and ``world/clock`` the world's,
``link/<id>/stats`` the bridge's, ``robot/<id>/status`` robot ``<id>``'s, ``radio/rx/<id>``
the *receiving* robot's (the world tags what it sends a robot with that robot's key).
Only then is the tag stripped and the metadata and payload decoded.
"""

from __future__ import annotations

from bestofn_swarm.wire import auth, keyspace
from bestofn_swarm.wire.keyspace import Party

# A sample on a used key that is not a valid message of that key, or does not carry its
# speaker's tag.
InvalidSampleError = keyspace.SampleError

# The kinds the view draws: those the key table says the views hear.
VIEWED = frozenset(keyspace.heard_by(Party.VIEWER))


def speaker(keys: keyspace.Keys, key: str) -> str | None:
    """The identity whose tag a sample on ``key`` must carry, if the view uses the key."""
    found = keyspace.classify(keys, key)
    return found.speaker if found is not None and found.kind in VIEWED else None


def decode_sample(
    keys: keyspace.Keys,
    key: str,
    payload: bytes,
    attachment: bytes | None,
    *,
    keyring: auth.Keyring | None,
) -> keyspace.Opened | None:
    """The sample, opened, if the view uses its key (``keyring``: the run's keys, None in
    an unkeyed run, where the attachment is the bare metadata).

    Raises InvalidSampleError for a sample on a used key that fails its tag, or does not
    decode or validate.
    """
    return keyspace.open_sample(keys, key, payload, attachment, keyring=keyring, kinds=VIEWED)
