"""The key table (bestofn_swarm/wire/keyspace.py): every key of the run is read back as its kind and
the name it gives, its speaker is whose key tags it, and the readers and the access control
that go by it agree with it."""

from __future__ import annotations

from pathlib import Path

import pytest

from bestofn_swarm.wire import keyspace, names
from bestofn_swarm.wire.keyspace import Party
from deploy.security import zenoh_acl
from deploy.viewer.core import decode
from world_server.recording import records

KEYS = keyspace.Keys("run-1")


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
        if chunk == "{instance}":
            return "w-1"
    return None


@pytest.mark.parametrize("kind", keyspace.KINDS, ids=lambda kind: kind.name)
def test_every_kind_reads_back_from_its_key(kind: keyspace.KeyKind) -> None:
    ident = sample_ident(kind.pattern)
    key = KEYS.of(kind, ident)
    spelled = [ident if chunk.startswith("{") else chunk for chunk in kind.pattern]
    assert key == "/".join([KEYS.prefix, *map(str, spelled)])
    found = keyspace.classify(KEYS, key)
    assert found is not None and found.kind is kind and found.ident == ident
    assert KEYS.ident_of(kind, key) == (ident if ident is not None else "")
    # Another kind's key is none of this kind's.
    for other in keyspace.KINDS:
        if other is not kind:
            assert KEYS.ident_of(other, key) is None


def test_speakers_are_whose_key_tags_each_kind() -> None:
    def speaker(key: str) -> str | None:
        found = keyspace.classify(KEYS, key)
        assert found is not None
        return found.speaker

    assert (
        speaker(KEYS.of(keyspace.STATE))
        == speaker(KEYS.of(keyspace.BEACON_CLOCK, "nest"))
        == names.WORLD
    )
    # What the world sends a robot is tagged with that robot's key.
    assert (
        speaker(KEYS.of(keyspace.SENSE, 3))
        == speaker(KEYS.of(keyspace.RADIO_RX, 3))
        == names.robot_identity(3)
    )
    assert (
        speaker(KEYS.of(keyspace.ACT, 3))
        == speaker(KEYS.of(keyspace.RADIO_TX, 3))
        == names.robot_identity(3)
    )
    assert (
        speaker(KEYS.of(keyspace.RADIO_TX, "nest"))
        == speaker(KEYS.of(keyspace.ACK, "nest"))
        == "beacon/nest"
    )
    assert speaker(KEYS.of(keyspace.LINK, 2)) == names.BRIDGE
    assert speaker(KEYS.of(keyspace.LOG, "world")) == names.LAUNCHER
    assert speaker(KEYS.of(keyspace.HOST_ACT, 0)) is None  # the batch names its last robot


@pytest.mark.parametrize(
    "key",
    [
        KEYS.of(keyspace.SENSE, "07"),  # one spelling per robot id
        KEYS.of(keyspace.ACK, "12"),  # a beacon's name is never a number
        f"{KEYS.prefix}/robot/3/unknown",
        f"{KEYS.prefix}/world/nothing",
        "bestofn/another-run/world/clock",
        KEYS.of(keyspace.RADIO_RX, "nest"),  # only robots receive
    ],
)
def test_keys_outside_the_table_are_none_of_its_kinds(key: str) -> None:
    assert keyspace.classify(KEYS, key) is None
    assert records.classify(KEYS, key) is None
    assert decode.speaker(KEYS, key) is None


def test_the_recorder_and_the_view_read_keys_by_the_table() -> None:
    for kind in keyspace.KINDS:
        key = KEYS.of(kind, sample_ident(kind.pattern))
        recorded = records.classify(KEYS, key)
        # Batches are recorded as their robots' own messages, not as batches; queries and
        # tokens are not recorded.
        kept = kind.recorded not in (None, keyspace.Recorded.BATCH)
        assert (recorded.kind if recorded is not None else None) == (kind if kept else None)
        viewed = decode.speaker(KEYS, key)
        found = keyspace.classify(KEYS, key)
        assert found is not None
        assert viewed == (found.speaker if kind in decode.VIEWED else None)


def test_the_access_control_lets_each_party_say_what_the_table_says_it_publishes() -> None:
    plan = zenoh_acl.SwarmPlan(KEYS, robots=(0, 1))
    rules = {rule["id"]: rule["key_exprs"] for rule in zenoh_acl.access_control(plan)["rules"]}
    world = keyspace.keys_for(KEYS, keyspace.published_by(Party.WORLD))
    assert rules["world-speak"] == world
    robot = names.robot_certificate(1)
    assert set(rules[f"{robot}-speak"]) == {
        KEYS.of(keyspace.ACT, 1),
        KEYS.of(keyspace.STATUS, 1),
        KEYS.of(keyspace.HOST_ACT, 1),
        KEYS.of(keyspace.RADIO_TX, 1),
    }
    assert set(rules[f"{robot}-receive"]) == {
        KEYS.of(keyspace.SENSE, 1),
        KEYS.of(keyspace.CAMERA, 1),
        KEYS.of(keyspace.HOST_SENSE, 1),
        KEYS.of(keyspace.RADIO_RX, 1),
    }
    assert rules["launcher-log"] == [KEYS.of(keyspace.LOG, "*")]
    assert rules["bridge-speak"] == [KEYS.of(keyspace.LINK, "*")]
    # Every kind the world publishes is spoken by no one else.
    others = [
        key
        for rule_id, keys in rules.items()
        if rule_id.endswith("-speak") and rule_id != "world-speak"
        for key in keys
    ]
    assert not set(others) & set(world)


def test_the_c_robots_header_is_the_tables() -> None:
    """c_robot/src/kinds.h is generated from the table; a new link code reaches the C robot
    by writing it again (``python -m bestofn_swarm.wire.keyspace --c-header``)."""
    header = Path(__file__).resolve().parent.parent / "c_robot" / "src" / "kinds.h"
    assert header.read_text() == keyspace.c_header(), (
        "stale: .venv/bin/python -m bestofn_swarm.wire.keyspace --c-header > c_robot/src/kinds.h"
    )


def test_link_codes_go_to_the_robot_below_16_and_from_it_above() -> None:
    assert {1, 2, 3, 4, 5, 6, 7} == keyspace.TO_ROBOT
    assert {16, 17, 18, 19} == keyspace.FROM_ROBOT
    names = {code: found.name for code, found in keyspace.LINK_CODES.items()}
    assert names == {
        1: "SENSE",
        2: "CAMERA",
        3: "RADIO_RX",
        4: "INFO_REPLY",
        5: "INFO_ERROR",
        6: "WORLD_UP",
        7: "WORLD_DOWN",
        16: "ACT",
        17: "RADIO_TX",
        18: "STATUS",
        19: "INFO_QUERY",
    }
    # What a robot hears on the link are the kinds the table says it hears.
    heard = {found.kind for found in keyspace.LINK_CODES.values() if found.to_robot}
    assert set(keyspace.heard_by(Party.ROBOT)) <= heard


def test_a_sample_is_opened_by_its_kind_and_its_robot_checked() -> None:
    from bestofn_swarm.wire import protocol

    status = protocol.Status(
        v=1, id=3, tick=1, t=0.1, phase="waiting", trips=0, opinion=[0.5, 0.5], pool_size=0,
        poolings=0, decided_site=None, decision_time=None, decision_trips=None, comparison=None,
    )  # fmt: skip
    opened = keyspace.open_message(keyspace.STATUS, "3", protocol.encode(status), None)
    assert opened.message == status and opened.robot == 3
    with pytest.raises(keyspace.SampleError, match="robot 3 on the key of 4"):
        keyspace.open_message(keyspace.STATUS, "4", protocol.encode(status), None)
    with pytest.raises(keyspace.SampleError):
        keyspace.open_message(keyspace.RADIO_RX, "3", b'{"v":1}', None)


def test_the_protocol_documents_every_key_as_the_table_says() -> None:
    """docs/protocol.md's table of keys is generated from the table of kinds."""
    text = (Path(__file__).resolve().parent.parent / "docs" / "protocol.md").read_text()
    begin = text.index("<!-- BEGIN generated by `python -m bestofn_swarm.wire.keyspace --markdown`")
    block = text[text.index("\n", begin) + 1 : text.index("<!-- END generated", begin)]
    assert block == keyspace.markdown_table(), (
        "stale: .venv/bin/python -m bestofn_swarm.wire.keyspace --markdown, into docs/protocol.md"
    )
