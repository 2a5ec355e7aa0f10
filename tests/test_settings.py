"""Each setting is defined once, on its config dataclass: the command lines are made from
it, the processes of a run are handed their configuration as one validated JSON object,
and what a command line says is what the dataclass says."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from typing import Any

import pytest

from bestofn_swarm.plumbing.settings_cli import Options
from bestofn_swarm.wire import settings
from deploy.cli import build_parser
from deploy.launcher import switches as run_switches
from deploy.launcher.plan import plan_from_args
from nest_beacon.core.beacon import BeaconConfig
from nest_beacon.node import cli as beacon_main
from nest_beacon.node.options import NEST_BEACON_OPTIONS, NestBeaconConfig
from robot_agent.core.byzantine import Behaviour, ByzantineRobot
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import ControllerChoice
from robot_agent.node import cli as node
from robot_agent.node.options import AGENT_OPTIONS, RobotAgentConfig
from world_server.core.camera import CameraNoise
from world_server.core.radio import RadioConfig
from world_server.core.world import WorldConfig
from world_server.recorder import recorder_process as recorder_main
from world_server.recording.description import RunDescription
from world_server.server import cli as server
from world_server.server.options import WORLD_SERVER_OPTIONS, WorldServerConfig

CONFIGS = [
    ControllerConfig,
    RadioConfig,
    CameraNoise,
    WorldConfig,
    BeaconConfig,
    WorldServerConfig,
    RobotAgentConfig,
    NestBeaconConfig,
    run_switches.RobotFaults,
    RunDescription,
]
# Many switches at once, in every form an option takes: a number, a choice, a switch, a
# joined A:B[:C:D], a repeated START:END, ROBOT@SIMTIME and ROBOT:MODE.
MANY = [
    *("--alpha", "0.1", "--pooling", "loglinear", "--dwell", "2.5", "--linger", "4"),
    *("--clock", "lockstep", "--dt", "0.05", "--stall-timeout", "7", "--state-every", "3"),
    *("--radio-range", "0.4", "--beacon-range", "0.3", "--drop", "0.2", "--latency", "2"),
    *("--jitter", "1", "--duplicate", "0.1", "--reorder", "--burst-loss", "0.1:0.3:0.05:0.9"),
    *("--range-loss", "0.3:2", "--camera-noise", "4", "--lighting", "0.05"),
    *("--beacon-period", "0.7", "--beacon-outage", "0:5", "--beacon-outage", "10:20.5"),
    *("--beacon-flaky", "0.25", "--kill", "1@15.5", "--restart", "2@30"),
    *("--byzantine", "3", "--byzantine", "4:liar=1", "--byzantine", "5:inverted"),
]


def _run_args(*argv: str) -> argparse.Namespace:
    return build_parser(["run"]).parse_args(["run", "--no-record", *argv])


def _switches(args: argparse.Namespace) -> run_switches.RunSwitches:
    return run_switches.run_switches(args, run_id="r", seed=3, sites=6, robots=8)


@pytest.mark.parametrize("config_type", CONFIGS, ids=lambda kind: kind.__name__)
def test_every_setting_says_what_it_is_and_its_default_is_valid(config_type: type) -> None:
    for setting in settings.settings_of(config_type):
        assert setting.description or setting.config_type, setting.name
        assert setting.default is not dataclasses.MISSING, setting.name
    config_type()  # the defaults pass the checks


@pytest.mark.parametrize(
    ("config_type", "options"),
    [
        (RobotAgentConfig, AGENT_OPTIONS),
        (WorldServerConfig, WORLD_SERVER_OPTIONS),
        (NestBeaconConfig, NEST_BEACON_OPTIONS),
    ],
    ids=["robot-agent", "world-server", "nest-beacon"],
)
def test_a_command_line_without_options_makes_the_dataclass_defaults(
    config_type: type, options: Options
) -> None:
    parser = argparse.ArgumentParser()
    options.add_to(parser)
    built = options.build(parser.parse_args([]), {"world.run": "run"})
    assert built == config_type()


def test_swarm_run_without_options_makes_the_dataclass_defaults() -> None:
    built = _switches(_run_args())
    world = WorldConfig(run="r", seed=3, num_sites=6, num_robots=8)
    assert built == run_switches.RunSwitches(world=WorldServerConfig(world=world))


def test_each_option_sets_its_setting() -> None:
    built = _switches(_run_args(*MANY))
    assert built.controller == ControllerConfig(
        alpha=0.1, threshold=0.99, pooling="loglinear", dwell=2.5, linger=4.0
    )
    radio = built.world.world.radio
    assert (radio.robot_range, radio.drop, radio.latency, radio.jitter) == (0.4, 0.2, 2, 1)
    assert (radio.duplicate, radio.reorder) == (0.1, True)
    assert (radio.burst_enter, radio.burst_exit) == (0.1, 0.3)
    assert (radio.burst_loss_good, radio.burst_loss_bad) == (0.05, 0.9)
    assert (radio.range_loss_start, radio.range_loss_exponent) == (0.3, 2.0)
    world = built.world.world
    assert (world.dt, world.beacon_range, world.camera_noise) == (0.05, 0.3, CameraNoise(4, 0.05))
    assert (built.world.stall_timeout, built.world.state_every) == (7.0, 3)
    assert built.beacon == BeaconConfig(period=0.7, outages=((0, 5), (10, 20.5)), flaky=0.25)
    assert built.faults == run_switches.RobotFaults(
        kill=(run_switches.RobotAtTime(1, 15.5),),
        restart=(run_switches.RobotAtTime(2, 30.0),),
        byzantine=(
            ByzantineRobot(3, Behaviour("liar")),
            ByzantineRobot(4, Behaviour("liar", 1)),
            ByzantineRobot(5, Behaviour("inverted")),
        ),
    )


def test_joined_options_leave_out_what_is_not_given() -> None:
    radio = _switches(_run_args("--burst-loss", "0.1:0.3", "--range-loss", "0.2")).world.world
    assert (radio.radio.burst_loss_good, radio.radio.burst_loss_bad) == (0.0, 1.0)
    assert radio.radio.range_loss_exponent == 1.0


def test_the_options_given_are_written_out_again_exactly() -> None:
    """``swarm experiment`` passes its run-shaping options on to every ``swarm run``."""
    args = _run_args(*MANY)
    argv = run_switches.switches_argv(args)
    assert _switches(_run_args(*argv)) == _switches(args)
    assert run_switches.switches_argv(_run_args()) == []


def test_the_record_of_a_run_has_every_option_once() -> None:
    record = _switches(_run_args(*MANY)).record()
    dests = set().union(*(options.dests for options in run_switches.SWITCHES))
    assert set(record) == dests
    assert record["threshold"] == 0.99  # the one in force, though not given
    assert record["burst_loss"] == "0.1:0.3:0.05:0.9"
    assert record["range_loss"] == "0.3:2"
    assert record["beacon_outage"] == ["0:5", "10:20.5"]
    assert record["kill"] == ["1@15.5"]
    assert record["byzantine"] == ["3:liar", "4:liar=1", "5:inverted"]
    json.dumps(record)
    quiet = _switches(_run_args()).record()
    assert (quiet["burst_loss"], quiet["range_loss"], quiet["beacon_outage"]) == (None, None, [])


@pytest.mark.parametrize("config_type", CONFIGS, ids=lambda kind: kind.__name__)
def test_a_config_goes_to_a_child_and_back_unchanged(config_type: type) -> None:
    switches = _switches(_run_args(*MANY))
    examples: dict[type, Any] = {
        ControllerConfig: switches.controller,
        RadioConfig: switches.world.world.radio,
        CameraNoise: switches.world.world.camera_noise,
        WorldConfig: switches.world.world,
        BeaconConfig: switches.beacon,
        WorldServerConfig: switches.world,
        RobotAgentConfig: RobotAgentConfig(3, switches.controller, switches.faults.byzantine),
        NestBeaconConfig: NestBeaconConfig(3, switches.beacon),
        run_switches.RobotFaults: switches.faults,
        RunDescription: RunDescription("r", 3, 8, 6, switches.record()),
    }
    config = examples[config_type]
    assert settings.decode(settings.encode(config), config_type) == config


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"controller": {"alpha": 0.7}}', r"<= 0.5 - at `\$.controller.alpha`"),
        ('{"controller": {"alpha": 0.2}}', "threshold below 1"),
        ('{"controller": {"dwel": 3}}', "unknown setting 'controller.dwel'"),
        ('{"seed": -1}', ">= 0"),
        ('{"seed": "1"}', "Expected `int | null`"),
        ('{"byzantine": [{"robot": 1, "behaviour": {"mode": "lie"}}]}', "Invalid enum"),
        ("[1]", "Expected `object`"),
        ("{", "truncated"),
    ],
)
def test_a_child_refuses_a_bad_config_object(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        settings.decode(text, RobotAgentConfig)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"world": {"radio": {"drop": 2}}}', r"<= 1.0 - at `\$.world.radio.drop`"),
        ('{"world": {"radio": {"dorp": 0.1}}}', "unknown setting 'world.radio.dorp'"),
        ('{"world": {"run": "é"}}', "matching regex"),
        ('{"world": {"clock": "fast"}}', "Invalid enum value 'fast'"),
        ('{"world": {"beacon_range": 0}}', "> 0.0"),
        ('{"state_every": 0}', ">= 1"),
    ],
)
def test_the_world_server_refuses_a_bad_config_object(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        settings.decode(text, WorldServerConfig)


def test_outages_are_checked_once_in_the_beacon_config() -> None:
    with pytest.raises(ValueError, match="START < END"):
        settings.decode('{"beacon": {"outages": [[5, 1]]}}', NestBeaconConfig)
    with pytest.raises(ValueError, match="START < END"):
        BeaconConfig(outages=((5.0, 1.0),))
    with pytest.raises(ValueError, match=r"outages\[0\]\[0\] must be in \[0, inf\)"):
        BeaconConfig(outages=((-1.0, 1.0),))


@pytest.mark.parametrize(
    ("config_type", "fields", "name"),
    [
        (RadioConfig, {"latency": 1.5}, "latency"),
        (RadioConfig, {"reorder": 1}, "reorder"),
        (RadioConfig, {"range_loss_exponent": math.nan}, "range_loss_exponent"),
        (CameraNoise, {"lighting": 1.0}, "lighting"),
        (WorldConfig, {"num_sites": 1}, "num_sites"),
        (WorldConfig, {"clock": "fast"}, "clock"),
        (WorldConfig, {"run": "a b"}, "run"),
        (BeaconConfig, {"flaky": -0.1}, "flaky"),
        (BeaconConfig, {"name": "é"}, "name"),
        (WorldServerConfig, {"speed": 0.0}, "speed"),
    ],
)
def test_a_config_made_in_python_is_checked_by_the_same_definitions(
    config_type: type, fields: dict[str, Any], name: str
) -> None:
    with pytest.raises(ValueError, match=name):
        config_type(**fields)


@pytest.mark.parametrize(
    ("main", "argv", "message"),
    [
        (node.main, ["--id", "0", "--config", "{}", "--dwell", "2"], "--dwell cannot be given"),
        (node.main, ["--id", "0", "--config", '{"x": 1}'], "--config: unknown setting 'x'"),
        (server.main, ["--config", "{}", "--drop", "0.1"], "--drop cannot be given"),
        (server.main, ["--config", '{"world": {"run": "a"}}'], "not --run-id 'run'"),
        (beacon_main.main, ["--config", "{}", "--outage", "1:2"], "--outage cannot be given"),
        (beacon_main.main, ["--outage", "5:1"], "outage 5:1 must have START < END"),
        (recorder_main.main, ["--out", "x", "--config", "{}", "--seed", "1"], "--seed cannot be"),
        (recorder_main.main, ["--out", "x", "--config-json", "[]"], "not a JSON object"),
    ],
)
def test_a_child_refuses_options_beside_its_config_in_one_line(
    main: Any, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert [line for line in lines if "error" in line] == [lines[-1]]
    assert message in lines[-1]


def test_swarm_run_hands_each_process_the_configs_its_options_make() -> None:
    plan = plan_from_args(_run_args("--robots", "8", "--sites", "6", "--seed", "3", *MANY[:-6]))
    switches = plan.switches

    def handed(argv: list[str], config_type: type) -> Any:
        assert argv[argv.index("--run-id") + 1] == plan.run_id
        return settings.decode(argv[argv.index("--config") + 1], config_type)

    # The world is also told how to end the run: this run's limits and robots.
    world = handed(plan.world_argv(), WorldServerConfig)
    assert world == dataclasses.replace(switches.world, rules=plan.ending_rules())
    assert world.rules.timeout == plan.timeout and world.rules.stall_window == plan.stall_window
    assert world.rules.controller == switches.controller
    assert switches.world.world == dataclasses.replace(
        switches.world.world, run=plan.run_id, seed=3, num_sites=6, num_robots=8
    )
    assert handed(plan.beacon_argv(), NestBeaconConfig) == NestBeaconConfig(3, switches.beacon)
    assert plan.plugins is not None
    assert handed(plan.robot_argv([0, 1]), RobotAgentConfig) == RobotAgentConfig(
        3, switches.controller, (), ControllerChoice("paper", plan.plugins.sources())
    )
    assert handed(plan.recorder_args, RunDescription) == RunDescription(
        plan.run_id, 3, 8, 6, plan.config
    )
