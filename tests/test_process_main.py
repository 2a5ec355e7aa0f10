"""How the seven programs of a run begin (``bestofn_swarm/plumbing/process_main.py``):
the world server, the nest beacon, robot-agent, the recorder, the bridge, the live page and
Foxglove live. Each ``main`` is called in this process with what it refuses before any
session opens: one line, exit code 2, its own words."""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence

import pytest

from bestofn_swarm.plumbing import cliargs, process_main, run_keys
from bestofn_swarm.wire import auth, keyspace, names
from deploy.viewer import foxglove_live, live
from nest_beacon.node import cli as beacon_cli
from robot_agent.node import cli as robot_cli
from world_server.bridge import cli as bridge_cli
from world_server.recorder import recorder_process
from world_server.server import cli as world_cli

Main = Callable[[Sequence[str] | None], int]
# Each program, with the arguments it cannot go without.
PROGRAMS: dict[str, tuple[Main, list[str]]] = {
    "world-server": (world_cli.main, []),
    "nest-beacon": (beacon_cli.main, []),
    "robot-agent": (robot_cli.main, ["--id", "3"]),
    "recorder": (recorder_process.main, ["--out", "never-written.mcap"]),
    "bridge": (bridge_cli.main, ["--robot", "8=udp://127.0.0.1:47800"]),
    "viewer": (live.main, []),
    "foxglove-live": (foxglove_live.main, []),
}
# What each says when the run keys it is given lack what it needs.
LACKING_KEYS = {
    "world-server": "world-server: error: the world server needs the run secret",
    "nest-beacon": "nest-beacon: error: the beacon needs its own key and the world's",
    "robot-agent": "robot-agent: error: the run keys hold no key for robot 3",
    "recorder": "recorder: error: the recorder needs the run secret",
    "bridge": "bridge: error: the run keys hold no key for the bridge",
    "viewer": "viewer: error: the view needs the run secret",
    "foxglove-live": "foxglove-live: error: Foxglove live needs the run secret",
}


def _refusal(main: Main, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """What ``main(argv)`` says as it exits with code 2, having written nothing else."""
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    return err.rstrip("\n")


@pytest.mark.parametrize("program", PROGRAMS)
def test_run_keys_that_lack_what_a_program_needs_are_refused_in_its_words(
    program: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    robot_5 = auth.Keyring(secret=bytes(32)).only([names.robot_identity(5)])
    monkeypatch.setenv(run_keys.KEYS_ENV, run_keys.to_text(robot_5, "run"))
    main, argv = PROGRAMS[program]
    assert _refusal(main, argv, capsys) == LACKING_KEYS[program]


@pytest.mark.parametrize("program", PROGRAMS)
def test_a_zenoh_configuration_that_cannot_be_read_is_refused_by_every_program(
    program: str, capsys: pytest.CaptureFixture[str]
) -> None:
    main, argv = PROGRAMS[program]
    line = _refusal(main, [*argv, "--zenoh-config", "/nonexistent/zenoh.json5"], capsys)
    assert line.endswith("/nonexistent/zenoh.json5: No such file or directory")


@pytest.mark.parametrize(
    ("program", "argv", "said"),
    [
        ("world-server", ["--config", '{"world": {"run": "other"}}'], "is of run 'other'"),
        ("recorder", ["--config", '{"run_id": "other"}'], "is of run 'other'"),
        ("robot-agent", ["--id", "3"], "the same --id is given twice"),
        ("bridge", ["--robot", "8=udp://127.0.0.1:47801"], "a robot is given twice"),
    ],
)
def test_a_programs_own_checks_come_before_the_run_keys(
    program: str, argv: list[str], said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without run keys a program warns that the run is unauthenticated; a wrong command
    line is refused before that: its one line only."""
    main, needed = PROGRAMS[program]
    line = _refusal(main, [*needed, *argv], capsys)
    assert line.startswith(f"{program}: error: ") and said in line


def test_begin_hands_over_the_command_line_settings_keys_and_run_keys(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    parser = argparse.ArgumentParser(prog="probe")
    parser.add_argument("--count", type=int, default=1)
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    keyring = auth.Keyring(secret=bytes(range(32)))
    monkeypatch.setenv(run_keys.KEYS_ENV, run_keys.to_text(keyring, "demo"))
    seen: list[argparse.Namespace] = []

    def settings(given: argparse.ArgumentParser, args: argparse.Namespace) -> int:
        assert given is parser
        seen.append(args)
        return int(args.count) * 10

    begun = process_main.begin(
        "probe",
        parser,
        ["--run-id", "demo", "--root", "lab", "--count", "4"],
        settings,
        needs_secret="the probe",
    )
    assert seen == [begun.args] and begun.args.count == 4
    assert begun.settings == 40
    assert begun.keyring is not None and begun.keyring.secret == keyring.secret
    assert begun.keys.of(keyspace.CLOCK) == keyspace.Keys("demo", "lab").of(keyspace.CLOCK)
    assert run_keys.KEYS_ENV not in os.environ  # taken out at once
