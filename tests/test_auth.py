"""Run keys and message tags (bestofn_swarm/wire/auth.py), key files and the launcher's hand-over of
keys (bestofn_swarm/plumbing/run_keys.py), and a run's private directory
(deploy/security/credentials.py)."""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import stat
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.wire import auth
from deploy.security.credentials import RunNetwork

VECTORS = json.loads((Path(__file__).parent / "vectors" / "auth.json").read_text())
PROTOCOL_DOC = (Path(__file__).resolve().parent.parent / "docs" / "protocol.md").read_text()
SECRET = bytes(range(32))
KEY = "bestofn/run/robot/3/act"


# --- the vectors, which a port checks itself against -------------------------------------


@pytest.mark.parametrize("entry", VECTORS["keys"], ids=lambda entry: entry["identity"])
def test_keys_derive_from_the_secret_as_the_vectors_say(entry: dict[str, Any]) -> None:
    secret = bytes.fromhex(VECTORS["secret_hex"])
    assert auth.derive_key(secret, entry["identity"]).hex() == entry["key_hex"]


@pytest.mark.parametrize("entry", VECTORS["tags"], ids=lambda entry: entry["name"])
def test_tags_are_what_the_vectors_say(entry: dict[str, Any]) -> None:
    keyring = auth.Keyring(secret=bytes.fromhex(VECTORS["secret_hex"]))
    key = keyring.key(entry["identity"])
    assert key is not None
    metadata, payload = entry["metadata_utf8"].encode(), entry["payload_utf8"].encode()
    assert auth.tag(key, entry["key_expr"], metadata, payload).hex() == entry["tag_hex"]
    attachment = bytes.fromhex(entry["attachment_hex"])
    assert attachment == bytes.fromhex(entry["tag_hex"]) + metadata
    assert keyring.open(entry["identity"], entry["key_expr"], payload, attachment) == metadata


def test_the_protocol_document_shows_the_vectors_byte_for_byte() -> None:
    sense = VECTORS["tags"][0]
    for text in (VECTORS["keys"][1]["key_hex"], sense["tag_hex"], sense["key_expr"]):
        assert text in PROTOCOL_DOC


# --- tags --------------------------------------------------------------------------------


def test_a_tag_covers_the_key_the_metadata_and_the_payload() -> None:
    keyring = auth.Keyring(secret=SECRET)
    attachment = keyring.seal("robot/3", KEY, b"payload", b"meta")
    assert keyring.open("robot/3", KEY, b"payload", attachment) == b"meta"
    for identity, key, payload, sealed in [
        ("robot/4", KEY, b"payload", attachment),  # another robot's key
        ("robot/3", "bestofn/run/robot/4/act", b"payload", attachment),  # another key
        ("robot/3", KEY, b"payloaD", attachment),  # another payload
        ("robot/3", KEY, b"payload", attachment[:16] + b"metA"),  # other metadata
        ("robot/3", KEY, b"payload", attachment[:15]),  # cut short
        ("robot/3", KEY, b"payload", None),  # none at all
    ]:
        with pytest.raises(auth.AuthError):
            keyring.open(identity, key, payload, sealed)


def test_the_length_prefixes_keep_parts_from_sliding_into_each_other() -> None:
    key = auth.derive_key(SECRET, "world")
    assert auth.tag(key, "a/b", b"", b"cd") != auth.tag(key, "a/b", b"c", b"d")


def test_a_robot_keyring_speaks_and_checks_only_for_its_robots() -> None:
    robot = auth.Keyring(secret=SECRET).only(["robot/3"])
    assert robot.secret is None and robot.identities == ["robot/3"]
    assert robot.holds("robot/3") and not robot.holds("robot/4") and not robot.holds("world")
    with pytest.raises(auth.AuthError):
        robot.seal("world", "bestofn/run/world/clock", b"{}")
    world_sealed = auth.Keyring(secret=SECRET).seal("robot/3", KEY, b"x")
    assert robot.open("robot/3", KEY, b"x", world_sealed) == b""


@pytest.mark.parametrize(
    "identity", ["robot/007", "robot/-1", "robot/100000", "beacon/", "beacon/a b", "anyone"]
)
def test_an_identity_outside_the_run_has_no_key(identity: str) -> None:
    with pytest.raises(ValueError):
        auth.derive_key(SECRET, identity)


def test_a_reply_answers_one_query_only() -> None:
    keyring = auth.Keyring(secret=SECRET)
    robot = keyring.only(["robot/3"])
    key, nonce, other = "bestofn/run/world/info", b"n" * 16, b"m" * 16
    query = auth.query_seal(robot, "robot/3", key, b"", nonce)
    assert query is not None
    assert auth.query_open(keyring, key, b"", query) == ("robot/3", nonce)
    reply = auth.reply_seal(keyring, "robot/3", key, b"info", nonce)
    auth.reply_open(robot, "robot/3", key, b"info", reply, nonce=nonce)
    with pytest.raises(auth.AuthError, match="another query"):
        auth.reply_open(robot, "robot/3", key, b"info", reply, nonce=other)
    forged = query[:16] + nonce + b"launcher"  # claims to be the launcher
    with pytest.raises(auth.AuthError):
        auth.query_open(keyring, key, b"", forged)


def test_an_unkeyed_run_sends_what_it_always_sent() -> None:
    assert auth.seal(None, "robot/3", KEY, b"x") is None
    assert auth.seal(None, "robot/3", KEY, b"x", b"meta") == b"meta"
    assert auth.unseal(None, "robot/3", KEY, b"x", b"meta") == b"meta"
    assert auth.query_seal(None, "robot/3", KEY, b"", b"") is None


# --- key files and the hand-over ----------------------------------------------------------


def test_key_files_are_private_and_hold_only_their_keys(tmp_path: Path) -> None:
    assert run_keys.main(["--run-id", "demo", "--robots", "2", "--out", str(tmp_path)]) == 0
    assert stat.S_IMODE(tmp_path.stat().st_mode) == 0o700
    for name in ("secret.json", "robot-0.json", "robot-1.json"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o600
    robot = run_keys.from_text((tmp_path / "robot-1.json").read_text(), "demo")
    assert robot.secret is None and robot.identities == ["robot/1"]
    secret = run_keys.from_text((tmp_path / "secret.json").read_text(), "demo")
    assert robot.key("robot/1") == secret.key("robot/1")
    with pytest.raises(ValueError, match="not 'other'"):
        run_keys.from_text((tmp_path / "robot-1.json").read_text(), "other")
    assert run_keys.main(["--run-id", "demo", "--robots", "2", "--out", str(tmp_path)]) == 2


def test_keys_from_the_launcher_leave_the_environment_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    text = run_keys.to_text(auth.Keyring(secret=SECRET), "demo")
    monkeypatch.setenv(run_keys.KEYS_ENV, text)
    keyring = run_keys.load("demo", None, "test")
    assert keyring is not None and keyring.secret == SECRET
    assert run_keys.KEYS_ENV not in os.environ


def test_no_keys_means_an_unauthenticated_process_that_says_so(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(run_keys.KEYS_ENV, raising=False)
    assert run_keys.load("demo", None, "robot-agent") is None
    assert "unauthenticated" in caplog.text


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("not json", "not JSON"),
        ('{"v": 2, "run": "demo"}', "not a run key object"),
        ('{"v": 1, "run": "demo"}', 'neither "secret" nor "keys"'),
        ('{"v": 1, "run": "demo", "secret": "00"}', "32 bytes"),
        ('{"v": 1, "run": "demo", "keys": {"robot/1": "zz"}}', "non-hexadecimal"),
        ('{"v": 1, "run": "demo", "keys": {"someone": "' + "00" * 32 + '"}}', "not an identity"),
    ],
)
def test_a_bad_key_file_says_what_is_wrong(text: str, reason: str, tmp_path: Path) -> None:
    path = tmp_path / "keys.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=reason):
        run_keys.load("demo", str(path), "test")


# --- a run's private directory ------------------------------------------------------------


def test_a_local_run_listens_on_a_socket_only_its_user_can_reach() -> None:
    network = RunNetwork.create("demo", 2, janitor=False)  # the janitor: test_private_runs
    try:
        assert network.directory is not None
        assert stat.S_IMODE(network.directory.stat().st_mode) == 0o700
        assert network.endpoint == f"unixsock-stream/{network.directory / 'zenoh.sock'}"
        assert network.world_args() == ["--mode", "router", "--listen", network.endpoint]
        robot_env = json.loads(network.env(["robot/1"])[run_keys.KEYS_ENV])
        assert set(robot_env) == {"v", "run", "keys"} and list(robot_env["keys"]) == ["robot/1"]
        assert "secret" in json.loads(network.env()[run_keys.KEYS_ENV])
    finally:
        directory = network.directory
        network.close()
    assert directory is not None and not directory.exists()


def test_a_secure_run_has_a_certificate_per_process_and_no_ca_key_left() -> None:
    network = RunNetwork.create("demo", 2, secure=True, janitor=False)
    try:
        directory = network.directory
        assert directory is not None and network.endpoint.startswith("tls/127.0.0.1:")
        certificates = sorted(path.name for path in (directory / "certs").glob("*.pem"))
        assert certificates == sorted(
            f"{name}.pem"
            for name in (
                "ca",
                "router",
                "world",
                "robot-0",
                "robot-1",
                "beacon-nest",
                "observer",
                "launcher",
                "recorder",
                "viewer",
                "foxglove",
                "bridge",
            )
        )
        assert not (directory / "ca.key").exists()
        for key in (directory / "certs").glob("*.key"):
            assert stat.S_IMODE(key.stat().st_mode) == 0o600
        router = json.loads(
            "\n".join(
                line
                for line in (directory / "routers" / "router.json5").read_text().splitlines()
                if not line.startswith("//")
            )
        )
        assert router["listen"]["endpoints"] == [network.endpoint]
        assert router["access_control"]["default_permission"] == "deny"
        assert network.client_args("robot-{id}")[-1].endswith("clients/robot-{id}.json5")
    finally:
        network.close()
    assert not directory.exists()


def test_a_run_on_an_existing_router_makes_no_directory() -> None:
    network = RunNetwork.create("demo", 2, connect="tcp/127.0.0.1:7447", keyed=False)
    assert network.directory is None and network.keyring is None and network.env() == {}
    assert network.world_args() == ["--mode", "client", "--connect", "tcp/127.0.0.1:7447"]


@given(st.binary(max_size=100), st.text(max_size=30), st.binary(max_size=40), st.binary())
def test_a_tag_is_hmac_sha256_whatever_the_key(
    key: bytes, key_expr: str, metadata: bytes, payload: bytes
) -> None:
    """The tag reuses the padded key's hash states (speed); it must stay plain HMAC."""
    framed = auth._framed(key_expr, metadata, payload)
    expected = hmac.digest(key, framed, hashlib.sha256)[: auth.TAG_BYTES]
    assert auth.tag(key, key_expr, metadata, payload) == expected
