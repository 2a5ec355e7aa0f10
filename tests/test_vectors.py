"""The conformance vectors in tests/vectors/ agree with the codec, and with their generator.

A port in another language runs the same checks against the same files (docs/porting.md).
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import make_vectors
import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.core.session import LinkClient, Welcomed
from bestofn_swarm.plumbing.run_keys import read_key_file
from bestofn_swarm.wire import auth, batch, names, protocol
from examples.udp_radio import (
    MAX_DATAGRAM_BYTES,
    MAX_RADIO_PAYLOAD_BYTES,
    FrameError,
    decode_frame,
    encode_frame,
)
from world_server.bridge.core.peer import LinkPeer, SessionOpened

VECTORS = Path(__file__).resolve().parent / "vectors"
ZENOH_PICO_BATCH = 2048  # bytes: one opinion and its attachment must fit one batch


def load(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text(encoding="utf-8"))


MESSAGE_FILES = {
    path.name: load(path)
    for path in sorted(VECTORS.glob("*.json"))
    if path.name
    not in (
        "udp_frame.json",
        "auth.json",
        "tick.json",
        "batch.json",
        "link_frame.json",
        "key_file.json",
        "numeric.json",
        "rng.json",
        "controller.json",
    )
}


def cases(section: str) -> list[Any]:
    return [
        pytest.param(
            name,
            content,
            vector,
            id=f"{name[:-5]}-{vector['name']}",
        )
        for name, content in MESSAGE_FILES.items()
        for vector in content[section]
    ]


def bytes_of(vector: dict[str, Any]) -> bytes:
    data = bytes.fromhex(vector["hex"])
    if vector["utf8"] is not None:
        assert vector["utf8"].encode("utf-8") == data  # the two spellings agree
    return data


def decode(content: dict[str, Any], data: bytes) -> msgspec.Struct:
    if content["decoder"] == "radio":
        return protocol.decode_radio(data)
    assert content["decoder"] == "message"
    return protocol.decode(data, getattr(protocol, content["type"]))


def test_every_message_type_has_vectors_of_every_kind() -> None:
    defined = {
        name
        for name, value in vars(protocol).items()
        if isinstance(value, type)
        and issubclass(
            value,
            protocol.Message
            | protocol.OpinionPayload
            | protocol.BeaconPayload
            | protocol.VotePayload,
        )
        and value is not protocol.Message
    }
    covered = {content["type"] for content in MESSAGE_FILES.values()}
    assert defined == covered
    for name, content in MESSAGE_FILES.items():
        assert content["protocol_version"] == protocol.VERSION
        assert content["valid"], name
        categories = {vector["category"] for vector in content["invalid"]}
        assert {"wrong_version", "unknown_field", "missing_field"} <= categories, name
    every_category = {
        vector["category"] for content in MESSAGE_FILES.values() for vector in content["invalid"]
    }
    assert {
        "nan_token",
        "out_of_range",
        "wrong_length",
        "wrong_type",
        "malformed_json",
        "opinion_sum",
        "bad_enum",
        "bad_name",
        "number_overflow",
    } <= every_category


@pytest.mark.parametrize(("file", "content", "vector"), cases("valid"))
def test_valid_vectors_decode_and_encode_to_the_same_bytes(
    file: str, content: dict[str, Any], vector: dict[str, Any]
) -> None:
    data = bytes_of(vector)
    message = decode(content, data)
    assert type(message).__name__ == content["type"]
    assert protocol.encode(message) == data
    assert json.loads(data) == vector["message"]
    assert msgspec.to_builtins(message) == vector["message"]


@pytest.mark.parametrize(("file", "content", "vector"), cases("accepted"))
def test_accepted_spellings_decode_to_the_canonical_message(
    file: str, content: dict[str, Any], vector: dict[str, Any]
) -> None:
    data = bytes_of(vector)
    canonical = bytes.fromhex(vector["canonical_hex"])
    assert data != canonical
    assert protocol.encode(decode(content, data)) == canonical


@pytest.mark.parametrize(("file", "content", "vector"), cases("invalid"))
def test_invalid_vectors_are_rejected_for_their_reason(
    file: str, content: dict[str, Any], vector: dict[str, Any]
) -> None:
    with pytest.raises(protocol.ProtocolError) as error:
        decode(content, bytes_of(vector))
    if "at" in vector:
        assert f"`{vector['at']}`" in str(error.value)
    if vector["category"] == "opinion_sum":
        assert "sums to" in str(error.value)


UDP = load(VECTORS / "udp_frame.json")


@pytest.mark.parametrize("vector", UDP["valid"], ids=[v["name"] for v in UDP["valid"]])
def test_udp_frame_vectors_are_what_the_radio_sends(vector: dict[str, Any]) -> None:
    frame = bytes.fromhex(vector["hex"])
    payload = vector["payload_utf8"].encode()
    assert encode_frame(vector["sender"], payload) == frame
    assert decode_frame(frame) == (vector["sender"], payload)
    assert len(frame) <= MAX_DATAGRAM_BYTES
    protocol.decode_radio(payload)


@pytest.mark.parametrize("vector", UDP["invalid"], ids=[v["name"] for v in UDP["invalid"]])
def test_udp_frame_vectors_that_the_radio_drops(vector: dict[str, Any]) -> None:
    with pytest.raises(FrameError):
        decode_frame(bytes.fromhex(vector["hex"]))


BATCH = load(VECTORS / "batch.json")


@pytest.mark.parametrize("vector", BATCH["valid"], ids=[v["name"] for v in BATCH["valid"]])
def test_batch_vectors_decode_to_the_robots_own_messages_under_their_host_s_tag(
    vector: dict[str, Any],
) -> None:
    data = bytes.fromhex(vector["hex"])
    decoded: list[tuple[int, msgspec.Struct]]
    if vector["kind"] == "senses":
        senses = batch.decode_senses(data)
        last, decoded = senses.last, list(zip(senses.robots, senses.senses, strict=True))
    else:
        acts = batch.decode_acts(data)
        last, decoded = acts.last, list(acts.acts)
    assert last == vector["last"]
    assert [(robot, msgspec.to_builtins(message)) for robot, message in decoded] == [
        (entry["robot"], entry["message"]) for entry in vector["entries"]
    ]
    keyring = auth.Keyring(secret=bytes.fromhex(BATCH["secret_hex"]))
    assert names.host_range(vector["identity"]) == (3, last)
    attachment = bytes.fromhex(vector["tag_hex"])
    assert keyring.open(vector["identity"], vector["key_expr"], data, attachment) == b""
    with pytest.raises(auth.AuthError):  # a hosted robot's own key does not speak for it
        keyring.open("robot/3", vector["key_expr"], data, attachment)


@pytest.mark.parametrize("vector", BATCH["invalid"], ids=[v["name"] for v in BATCH["invalid"]])
def test_batch_vectors_that_are_refused_whole(vector: dict[str, Any]) -> None:
    decode = batch.decode_senses if vector["kind"] == "senses" else batch.decode_acts
    with pytest.raises(batch.BatchError):
        decode(bytes.fromhex(vector["hex"]))


LINK = load(VECTORS / "link_frame.json")
AUTH = load(VECTORS / "auth.json")
LINK_KEY = bytes.fromhex(LINK["link_key_hex"])
SESSION_KEY = bytes.fromhex(LINK["session_key_hex"])


def test_the_link_keys_derive_from_the_robot_key() -> None:
    robot_key = bytes.fromhex(LINK["robot_key_hex"])
    assert codec.link_key(robot_key) == LINK_KEY
    nonces = bytes.fromhex("0102030405060708"), bytes.fromhex("1112131415161718")
    assert codec.session_key(LINK_KEY, *nonces) == SESSION_KEY


@pytest.mark.parametrize("vector", LINK["valid"], ids=[v["name"] for v in LINK["valid"]])
def test_link_frame_vectors_read_and_seal_to_their_bytes(vector: dict[str, Any]) -> None:
    data = bytes.fromhex(vector["hex"])
    cipher = SESSION_KEY if vector["encrypted"] else None
    frame = codec.open_frame(data, LINK_KEY, cipher)
    codec.check_body(frame)
    assert frame == codec.Frame(
        codec.FrameType[vector["type"]],
        vector["from_bridge"],
        vector["robot"],
        bytes.fromhex(vector["robot_nonce_hex"]),
        bytes.fromhex(vector["bridge_nonce_hex"]),
        vector["seq"],
        bytes.fromhex(vector["body_hex"]),
        vector["encrypted"],
    )
    assert codec.seal(frame, LINK_KEY, cipher) == data
    serial = bytes.fromhex(vector["serial_hex"])
    assert codec.serial_encode(data) == serial
    assert codec.Deframer().feed(serial) == [data]
    if "data" in vector:
        kind, payload, attachment = codec.decode_data(frame.body)
        assert (kind.name, kind.code) == (vector["data"]["kind"], vector["data"]["kind_byte"])
        assert payload.decode() == vector["data"]["payload_utf8"]
        assert (attachment or b"").hex() == vector["data"]["attachment_hex"]
    if frame.type is codec.FrameType.WELCOME:
        assert codec.decode_welcome(frame.body).run == "demo"


LINK_FRAMES = {vector["name"]: bytes.fromhex(vector["hex"]) for vector in LINK["valid"]}
ROBOT_NONCE = bytes.fromhex(LINK["robot_nonce_hex"])
BRIDGE_NONCE = bytes.fromhex(LINK["bridge_nonce_hex"])


def test_the_bounds_are_the_codec_s() -> None:
    assert LINK["max_frame_bytes"] == codec.MAX_FRAME_BYTES == 65507
    assert LINK["max_encoded_bytes"] == codec.MAX_ENCODED_BYTES == 65769
    assert LINK["max_attachment_bytes"] == codec.MAX_ATTACHMENT_BYTES == 1024
    assert LINK["replay_window"] == codec.REPLAY_WINDOW == 64


def robot_receiver(session: str) -> LinkClient:
    """Robot 8's end in ``session`` (LINK["receivers"]["robot"])."""
    client = LinkClient(LINK["robot"], LINK_KEY, nonce=lambda: ROBOT_NONCE)
    client.wake(0.0)  # its hello
    if session != "hello":
        welcome = LINK_FRAMES["welcome" if session == "plain" else "welcome_encrypted"]
        (event,) = client.receive(welcome, 0.0)
        assert isinstance(event, Welcomed)
    client.take_outgoing()
    assert not client.refused
    return client


def bridge_receiver(session: str) -> LinkPeer:
    """The bridge's end of robot 8 in ``session`` (LINK["receivers"]["bridge"])."""
    name = "welcome" if session == "plain" else "welcome_encrypted"
    body = bytes.fromhex(next(v for v in LINK["valid"] if v["name"] == name)["body_hex"])
    peer = LinkPeer(
        LINK["robot"],
        LINK_KEY,
        codec.decode_welcome(body),
        transport="udp",
        address="udp://127.0.0.1:47800",
        nonce=lambda: BRIDGE_NONCE,
    )
    assert peer.receive(LINK_FRAMES["hello"], "robot", 0.0) == []
    ping = "ping_from_the_robot" + ("" if session == "plain" else "_encrypted")
    assert peer.receive(LINK_FRAMES[ping], "robot", 0.0) == [SessionOpened(LINK["robot"])]
    peer.take_outgoing()
    assert not peer.refused
    return peer


def refused_by(receiver: str, session: str, frames: list[bytes]) -> list[str | None]:
    """What a receiver in ``session`` refuses of ``frames`` in turn: each one's refusal, or
    None if it took it."""
    end = robot_receiver(session) if receiver == "robot" else bridge_receiver(session)
    found: list[str | None] = []
    for data in frames:
        before = Counter(end.refused)
        if isinstance(end, LinkClient):
            end.receive(data, 0.0)
        else:
            end.receive(data, "robot", 0.0)
        added = Counter(end.refused) - before
        assert sum(added.values()) <= 1
        found.append(next(iter(added), None))
    return found


@pytest.mark.parametrize("vector", LINK["invalid"], ids=[v["name"] for v in LINK["invalid"]])
@pytest.mark.parametrize("receiver", ["robot", "bridge"])
def test_link_frame_vectors_that_each_end_refuses_for_its_reason(
    vector: dict[str, Any], receiver: str
) -> None:
    data = bytes.fromhex(vector["hex"])
    assert refused_by(receiver, vector["session"], [data]) == [vector["refusal"][receiver]]


@pytest.mark.parametrize("vector", LINK["valid"], ids=[v["name"] for v in LINK["valid"]])
def test_a_valid_frame_is_taken_by_the_end_it_goes_to(vector: dict[str, Any]) -> None:
    """Each end in its state (LINK["receivers"]) takes the other end's frames: a welcome from
    a robot saying hello, the robot's frames after the one that opened the session."""
    data = bytes.fromhex(vector["hex"])
    session = "encrypted" if vector["encrypted"] else "plain"
    if vector["type"] == "WELCOME":
        assert refused_by("robot", "hello", [data]) == [None]
    elif vector["from_bridge"]:
        assert refused_by("robot", session, [data]) == [None]
    elif vector["type"] != "HELLO" and vector["seq"] > 1:
        assert refused_by("bridge", session, [data]) == [None]


@pytest.mark.parametrize("sequence", LINK["sequences"], ids=[s["name"] for s in LINK["sequences"]])
def test_link_frame_sequences(sequence: dict[str, Any]) -> None:
    frames = [bytes.fromhex(item["hex"]) for item in sequence["frames"]]
    expected = [item["refused"] for item in sequence["frames"]]
    assert refused_by(sequence["receiver"], sequence["session"], frames) == expected


def test_the_replay_window_takes_63_behind_and_refuses_64() -> None:
    window = codec.ReplayWindow()
    window.take(100)
    assert window.refuses(37) is None  # 63 behind
    assert window.refuses(36) is not None  # 64 behind
    assert window.refuses(100) is not None and window.refuses(101) is None


@pytest.mark.parametrize(
    "vector",
    [v for v in LINK["valid"] if "query" in v.get("data", {})],
    ids=lambda v: v["name"],
)
def test_the_questions_on_world_info_and_their_answers(vector: dict[str, Any]) -> None:
    """Kind 19: the attachment is tag || nonce || identity under the robot's run key; kind
    4: tag || nonce, under the robot's run key too (bestofn_swarm/wire/auth.py)."""
    keyring = auth.Keyring(keys={"robot/8": bytes.fromhex(LINK["robot_key_hex"])})
    data, query = vector["data"], vector["data"]["query"]
    payload = data["payload_utf8"].encode()
    attachment = bytes.fromhex(data["attachment_hex"])
    nonce = bytes.fromhex(query["nonce_hex"])
    assert attachment == bytes.fromhex(query["tag_hex"] + query["metadata_hex"])
    if data["kind"] == "INFO_QUERY":
        assert attachment[16:] == nonce + query["identity"].encode()
        secret = auth.Keyring(secret=bytes.fromhex(AUTH["secret_hex"]))
        assert auth.query_open(secret, query["key_expr"], payload, attachment) == (
            query["identity"],
            nonce,
        )
    else:
        assert attachment[16:] == nonce
        auth.reply_open(
            keyring, query["identity"], query["key_expr"], payload, attachment, nonce=nonce
        )
        protocol.decode(payload, protocol.WorldInfo)


KEY_FILES = load(VECTORS / "key_file.json")


@pytest.mark.parametrize("vector", KEY_FILES["valid"], ids=lambda v: v["name"])
def test_key_files_that_a_robot_reads(vector: dict[str, Any], tmp_path: Path) -> None:
    path = tmp_path / "robot-8.key"
    path.write_text(vector["utf8"], encoding="utf-8")
    path.chmod(0o600)
    run, keyring = read_key_file(path, KEY_FILES["identity"])
    assert run == KEY_FILES["run"]
    assert keyring.key(KEY_FILES["identity"]) == bytes.fromhex(KEY_FILES["key_hex"])


@pytest.mark.parametrize("vector", KEY_FILES["invalid"], ids=lambda v: v["name"])
def test_key_files_that_a_robot_refuses(vector: dict[str, Any], tmp_path: Path) -> None:
    path = tmp_path / "robot-8.key"
    path.write_text(vector["utf8"], encoding="utf-8")
    path.chmod(0o600)
    with pytest.raises(ValueError):
        read_key_file(path, KEY_FILES["identity"])


@pytest.mark.parametrize(
    "vector", LINK["serial_invalid"], ids=[v["name"] for v in LINK["serial_invalid"]]
)
def test_serial_vectors_that_a_receiver_refuses_as_corrupt(vector: dict[str, Any]) -> None:
    (found,) = codec.Deframer().feed(bytes.fromhex(vector["hex"]))
    assert isinstance(found, codec.LinkError) and found.refusal.value == vector["category"]


def test_the_files_are_exactly_what_the_generator_writes() -> None:
    """All but the controller vectors, which the generator makes from swarms it runs
    (tests/test_controller_vectors.py checks those)."""
    on_disk = {
        path.name: path.read_text(encoding="utf-8")
        for path in VECTORS.glob("*.json")
        if path.name != "controller.json"
    }
    assert on_disk == make_vectors.build(controller=False), "run: python tests/make_vectors.py"


# --- the 2 KB budget ---------------------------------------------------------------------


def test_the_longest_opinion_over_100_sites_fits_one_2kb_batch() -> None:
    worst = make_vectors.worst_case_opinion(100)
    assert len(set(worst)) == 100
    assert protocol.wire_opinion(worst) == worst  # already at the wire's precision
    assert sorted(len(msgspec.json.encode(value)) for value in worst)[-99:] == [15] * 99
    payload = protocol.encode(
        protocol.OpinionPayload(
            v=1,
            id=names.MAX_ROBOTS - 1,
            trip=2**53,
            decided=False,
            opinion=worst,
        )
    )
    message = protocol.decode_radio(payload)
    assert isinstance(message, protocol.OpinionPayload) and message.opinion == worst
    attachment = protocol.encode(protocol.RadioTxMeta(v=1, tick=2**53, seq=2**53))
    assert len(payload) + len(attachment) <= ZENOH_PICO_BATCH
    assert len(payload) <= MAX_RADIO_PAYLOAD_BYTES
    assert len(encode_frame(str(names.MAX_ROBOTS - 1), payload)) <= MAX_DATAGRAM_BYTES


@given(st.floats(min_value=0.0, max_value=1.0))
def test_no_opinion_value_takes_more_than_15_characters_on_the_wire(value: float) -> None:
    """What makes the vector above the worst case: 9 significant digits never print longer."""
    (rounded,) = protocol.wire_opinion([value])
    assert len(msgspec.json.encode(rounded)) <= 15
