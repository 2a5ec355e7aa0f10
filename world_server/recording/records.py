"""What a recording holds, record by record: the names of its metadata records, the
types of the samples it records and their JSON Schemas, and which key is which kind.

One channel per key, topic = the key, schema encoding ``jsonschema`` with the schema
generated from the message's one definition in ``bestofn_swarm/wire/protocol.py`` (refs inlined),
message encoding ``json``. Radio samples are recorded as ``{"meta": <attachment>, "payload":
<payload>}`` (``RadioTxRecord``, ``RadioRxRecord``); camera frames as
``foxglove.CompressedImage``; samples refused as ``RejectedSample``. The writer
(``writer.py``) and the reader (``reader.py``) both go by these names.
"""

from __future__ import annotations

import functools
from typing import Any

import msgspec

from bestofn_swarm.wire import keyspace, protocol
from world_server.observer.frame import SwarmSample
from world_server.recording import foxglove

START_METADATA = "bestofn.start"  # written when recording begins
RUN_METADATA = "bestofn.run"  # written at the end, with the recorder's counts and the summary
SCHEMA_PREFIX = "bestofn."


class RejectedSample(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """A sample that did not decode as its key's message (or failed its tag): its first
    bytes, raw, with the reason."""

    key: str
    reason: str
    payload: str  # base64 of at most writer.REJECTED_SAMPLE_BYTES
    attachment: str | None  # base64 of at most writer.REJECTED_SAMPLE_BYTES
    payload_bytes: int  # the whole payload's size


REJECTED = "rejected"  # the recorder's own channel of the samples it refused
SWARM = "swarm"  # the swarm's curves, one message per world state (<prefix>/foxglove/swarm)
# The recorder's own channels beside the key table's, by name: the type of their messages.
DERIVED: dict[str, type[msgspec.Struct]] = {REJECTED: RejectedSample, SWARM: SwarmSample}


def schema_name(kind: keyspace.KeyKind | str) -> str:
    """The MCAP schema name of a kind of sample (``bestofn.Sense``, ``foxglove.CompressedImage``,
    from the key table), or of one of the recorder's own channels (``DERIVED``)."""
    if isinstance(kind, str):
        return SCHEMA_PREFIX + DERIVED[kind].__name__
    assert kind.schema is not None, f"a recording keeps no {kind.name} samples"
    return kind.schema


def inline_refs(schema: dict[str, Any]) -> dict[str, Any]:
    """A self-contained copy of a msgspec JSON Schema: every ``$ref`` replaced by its
    definition, as in Foxglove's own schemas (viewers need not resolve references)."""
    definitions = schema.get("$defs", {})

    def resolve(node: Any) -> Any:
        if isinstance(node, dict):
            if "$ref" in node:
                return resolve(definitions[node["$ref"].rsplit("/", 1)[-1]])
            return {
                key: resolve(value)
                for key, value in node.items()
                if key not in ("$defs", "discriminator")  # the mapping names $defs entries
            }
        if isinstance(node, list):
            return [resolve(item) for item in node]
        return node

    return dict(resolve(schema))


@functools.cache
def message_schema(kind: keyspace.KeyKind | str) -> dict[str, Any]:
    """The JSON Schema of a recorded kind, from its definition in the protocol (the key
    table says which type that is), or of one of the recorder's own channels."""
    if isinstance(kind, str):
        return inline_refs(protocol.json_schema(DERIVED[kind]))
    if kind.recorded is keyspace.Recorded.IMAGE:
        return foxglove.schema(foxglove.COMPRESSED_IMAGE)
    return inline_refs(protocol.json_schema(kind.record_type))


def classify(keys: keyspace.Keys, key: str) -> keyspace.Classified | None:
    """The kind of sample a key carries and the name it gives (the key table's,
    ``bestofn_swarm/wire/keyspace.py``), or None for a key outside the protocol, or whose name
    no robot, beacon or process of a run can have, or a kind a recording does not keep as
    samples of their own (a host's batch is recorded as its robots' own messages:
    ``writer.py``)."""
    found = keyspace.classify(keys, key)
    if found is None or found.kind.recorded in (None, keyspace.Recorded.BATCH):
        return None
    return found
