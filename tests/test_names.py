"""One rule for a name (run id, key root, beacon, radio sender), the same everywhere: the
command line refuses what the wire, the keys and the run keys would refuse later."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import msgspec
import pytest

from bestofn_swarm.wire import keyspace, names, protocol
from examples import udp_radio

NOT_NAMES = ["ünïcode", "run\n", "a b", "a/b", "x" * 65, "", "*", "é"]
NAMES = ["run", "exp-N10-n5-r01", "a.b_c", "x" * 64, "0"]


def _parser(command: str) -> Callable[[list[str]], argparse.Namespace]:
    if command == "swarm run":
        from deploy.cli import build_parser

        parser = build_parser(["run"])
        return lambda argv: parser.parse_args(["run", *argv])
    from robot_agent.node import cli as node

    return lambda argv: node.build_parser().parse_args(["--id", "0", *argv])


@pytest.mark.parametrize("command", ["swarm run", "robot-agent"])
@pytest.mark.parametrize("run_id", ["ünïcode", "run\n", "a b"])
def test_a_run_id_that_is_not_a_name_is_refused_at_the_command_line(
    command: str, run_id: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A non-ASCII run id used to pass the command line and fail 30 s later."""
    parse = _parser(command)
    with pytest.raises(SystemExit) as exit_info:
        parse(["--run-id", run_id])
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert [line for line in lines if "error" in line] == [lines[-1]]
    assert lines[-1].startswith(f"{command}: error: argument --run-id: invalid name ")


@pytest.mark.parametrize("text", NOT_NAMES)
def test_everything_that_checks_a_name_refuses_the_same_texts(text: str) -> None:
    assert not names.is_name(text)
    with pytest.raises(ValueError, match="invalid run id"):
        keyspace.Keys(text)
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(text, protocol._Name)
    with pytest.raises(ValueError):
        names.check_identity(names.beacon_identity(text))
    with pytest.raises(ValueError):
        udp_radio.sender_bytes(text)


@pytest.mark.parametrize("text", NAMES)
def test_everything_that_checks_a_name_takes_the_same_texts(text: str) -> None:
    assert names.is_name(text)
    assert keyspace.Keys(text).run == text
    assert msgspec.convert(text, protocol._Name) == text
    assert names.check_identity(names.beacon_identity(text))
    assert udp_radio.sender_bytes(text) == text.encode()
