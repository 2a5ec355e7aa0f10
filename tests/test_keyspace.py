"""The key table (bestofn_swarm/wire/keyspace.py): every key of the run is read back as its kind and
the name it gives, its speaker is whose key tags it, and the readers and the access control
that go by it agree with it."""

from __future__ import annotations

import pytest

from bestofn_swarm.wire import keyspace, names, protocol
from bestofn_swarm.wire.keyspace import Party
from deploy.security import zenoh_acl
from deploy.viewer.core import decode
from world_server.recording import records

KEYS = protocol.Keys("run-1")


def sample_ident(pattern: tuple[str, ...]) -> str | None:
    for chunk in pattern:
        if chunk in ("{robot}", "{lead}"):
            return "7"
        if chunk == "{beacon}":
            return "nest"
        if chunk == "{sender}":
            return "7"
        if chunk == "{process}":
            return "world"
    return None


@pytest.mark.parametrize("kind", keyspace.KINDS, ids=lambda kind: kind.name)
def test_every_kind_reads_back_from_its_key(kind: keyspace.KeyKind) -> None:
    ident = sample_ident(kind.pattern)
    key = keyspace.key_of(KEYS, kind.name, ident)
    found = keyspace.classify(KEYS, key)
    assert found is not None and found.kind is kind and found.ident == ident
    # The protocol's own spelling of the key is the table's.
    spelled = {
        "clock": KEYS.world_clock,
        "state": KEYS.world_state,
        "sense": KEYS.sense(7),
        "camera": KEYS.camera(7),
        "act": KEYS.act(7),
        "status": KEYS.status(7),
        "host_sense": KEYS.host_sense(7),
        "host_act": KEYS.host_act(7),
        "beacon_clock": KEYS.beacon_clock("nest"),
        "ack": KEYS.beacon_ack("nest"),
        "radio_tx": KEYS.radio_tx(7),
        "radio_rx": KEYS.radio_rx(7),
        "link": KEYS.link_stats(7),
        "log": KEYS.log("world"),
    }
    assert spelled[kind.name] == key


def test_speakers_are_whose_key_tags_each_kind() -> None:
    def speaker(key: str) -> str | None:
        found = keyspace.classify(KEYS, key)
        assert found is not None
        return found.speaker

    assert speaker(KEYS.world_state) == speaker(KEYS.beacon_clock("nest")) == names.WORLD
    # What the world sends a robot is tagged with that robot's key.
    assert speaker(KEYS.sense(3)) == speaker(KEYS.radio_rx(3)) == names.robot_identity(3)
    assert speaker(KEYS.act(3)) == speaker(KEYS.radio_tx(3)) == names.robot_identity(3)
    assert speaker(KEYS.radio_tx("nest")) == speaker(KEYS.beacon_ack("nest")) == "beacon/nest"
    assert speaker(KEYS.link_stats(2)) == names.BRIDGE
    assert speaker(KEYS.log("world")) == names.LAUNCHER
    assert speaker(KEYS.host_act(0)) is None  # the batch names its last robot


@pytest.mark.parametrize(
    "key",
    [
        KEYS.sense("07"),  # one spelling per robot id
        KEYS.beacon_ack("12"),  # a beacon's name is never a number
        f"{KEYS.prefix}/robot/3/unknown",
        f"{KEYS.prefix}/world/nothing",
        "bestofn/another-run/world/clock",
        KEYS.radio_rx("nest"),  # only robots receive
    ],
)
def test_keys_outside_the_table_are_none_of_its_kinds(key: str) -> None:
    assert keyspace.classify(KEYS, key) is None
    assert records.classify(KEYS, key) is None
    assert decode.speaker(KEYS, key) is None


def test_the_recorder_and_the_view_read_keys_by_the_table() -> None:
    for kind in keyspace.KINDS:
        key = keyspace.key_of(KEYS, kind.name, sample_ident(kind.pattern))
        recorded = records.classify(KEYS, key)
        # Batches are recorded as their robots' own messages, not as batches.
        assert recorded == (None if kind.name.startswith("host_") else kind.name)
        viewed = decode.speaker(KEYS, key)
        found = keyspace.classify(KEYS, key)
        assert found is not None
        assert viewed == (found.speaker if kind.name in decode.VIEWED else None)


def test_the_access_control_lets_each_party_say_what_the_table_says_it_publishes() -> None:
    plan = zenoh_acl.SwarmPlan(KEYS, robots=(0, 1))
    rules = {rule["id"]: rule["key_exprs"] for rule in zenoh_acl.access_control(plan)["rules"]}
    world = keyspace.keys_for(KEYS, keyspace.published_by(Party.WORLD))
    assert rules["world-speak"] == world
    robot = names.robot_certificate(1)
    assert set(rules[f"{robot}-speak"]) == {
        KEYS.act(1),
        KEYS.status(1),
        KEYS.host_act(1),
        KEYS.radio_tx(1),
    }
    assert set(rules[f"{robot}-receive"]) == {
        KEYS.sense(1),
        KEYS.camera(1),
        KEYS.host_sense(1),
        KEYS.radio_rx(1),
    }
    assert rules["launcher-log"] == [KEYS.log("*")]
    assert rules["bridge-speak"] == [KEYS.link_stats("*")]
    # Every kind the world publishes is spoken by no one else.
    others = [
        key
        for rule_id, keys in rules.items()
        if rule_id.endswith("-speak") and rule_id != "world-speak"
        for key in keys
    ]
    assert not set(others) & set(world)
