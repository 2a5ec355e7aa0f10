"""The controller's ``pooling`` option: configuration, command line, and the operator used."""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from fakes import make_swarm

from bestofn_swarm.wire import protocol
from robot_agent.core import decision, ports
from robot_agent.core.controller import Controller, ControllerConfig

N_ROBOTS = 10


# --- configuration and command line ----------------------------------------------------


@pytest.mark.parametrize("pooling", ["", None, 1, ["mprodop"], "two words", "a:b:c"])
def test_config_rejects_what_is_no_plugin_name(pooling: Any) -> None:
    with pytest.raises(ValueError, match=r"^pooling "):
        ControllerConfig(pooling=pooling)


@pytest.mark.parametrize("pooling", ["lineer", "MProdOp"])
def test_a_pooling_operator_nobody_provides_is_refused_by_name(pooling: str) -> None:
    """A name is a plug-in's (docs/extending.md): one no installed package registers does
    not resolve, and the error names it and what there is."""
    from robot_agent.core.plugin import PluginError
    from robot_agent.plugins import registry

    config = ControllerConfig(pooling=pooling)
    with pytest.raises(PluginError, match=f"no pooling plug-in '{pooling}'.*mprodop"):
        registry.resolve_plugins(config)


def test_config_defaults_to_the_papers_operator() -> None:
    assert ControllerConfig().pooling == "mprodop"
    assert ControllerConfig(alpha=0.1, threshold=0.99, pooling="loglinear").pooling == "loglinear"


def test_robot_agent_takes_pooling_from_its_command_line() -> None:
    from robot_agent.node import cli as node
    from robot_agent.node import options

    parser = node.build_parser()
    default = options.controller_config(parser.parse_args(["--id", "0"]))
    chosen = options.controller_config(
        parser.parse_args(["--id", "0", "--alpha", "0.1", "--pooling", "loglinear"])
    )
    assert default.pooling == "mprodop"
    assert (chosen.pooling, chosen.alpha, chosen.threshold) == ("loglinear", 0.1, 0.99)
    with pytest.raises(SystemExit) as stopped:  # a name no package provides: before Zenoh
        node.main(["--id", "0", "--pooling", "no-such-operator"])
    assert stopped.value.code == 2


def test_swarm_run_forwards_pooling_to_every_robot_and_records_it() -> None:
    from bestofn_swarm.wire import settings
    from deploy.cli import build_parser
    from deploy.launcher.plan import plan_from_args
    from robot_agent.node.options import RobotAgentConfig

    parser = build_parser(["run"])
    plan = plan_from_args(parser.parse_args(["run", "--pooling", "loglinear", "--no-record"]))
    argv = plan.robot_argv([0])
    handed = settings.decode(argv[argv.index("--config") + 1], RobotAgentConfig)
    assert handed.controller.pooling == "loglinear"
    assert plan.config["pooling"] == "loglinear"
    # The paper's operator is the default, and in the config too.
    plan = plan_from_args(parser.parse_args(["run", "--no-record"]))
    argv = plan.robot_argv([0])
    assert settings.decode(argv[argv.index("--config") + 1], RobotAgentConfig).controller == (
        ControllerConfig()
    )
    assert plan.config["pooling"] == "mprodop"


# --- the operator the controller pools with --------------------------------------------


def _pool_steps(
    events: list[tuple[int, list[float]]],
) -> list[tuple[list[float], list[float]]]:
    """(opinion before, opinion after) for each pooling, from (trips, opinion) events."""
    return [
        (before[1], after[1])
        for before, after in itertools.pairwise(events)
        if after[0] == before[0] + 1
    ]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("pooling", ["mprodop", "loglinear"])
def test_the_robot_pools_with_the_configured_operator(pooling: decision.PoolingName) -> None:
    num_sites = 5
    # A neighbour fairly sure that option 0 is not the best and leaning to option 1.
    neighbour = [0.05, 0.4, 0.2, 0.2, 0.15]

    def neighbour_at_the_nest(tick: int, controller: Controller) -> list[ports.Received]:
        if controller.phase != "at_nest":
            return []
        payload = protocol.OpinionPayload(v=1, id=5, trip=1, decided=False, opinion=neighbour)
        return [ports.Received("5", payload)]

    config = ControllerConfig(alpha=0.1, threshold=0.99, pooling=pooling)
    swarm = make_swarm(1, num_sites, seed=21, config=config)
    swarm.inject = neighbour_at_the_nest
    robot = swarm.controllers[0]
    events: list[tuple[int, list[float]]] = [(0, robot.opinion)]
    for _ in range(6000):
        swarm.step()
        events.append((robot.trips, robot.opinion))
        if robot.trips >= 4:
            break
    steps = _pool_steps(events)
    assert len(steps) == 4
    assert robot.pool_sizes == [2, 2, 2, 2]
    operator = decision.POOLING_OPERATORS[pooling]
    other = decision.loglinear_pool if pooling == "mprodop" else decision.mprodop
    for before, after in steps:
        expected = operator([before, neighbour])
        assert expected is not None
        assert after == pytest.approx(expected, abs=1e-12)
        assert after != pytest.approx(other([before, neighbour]), abs=1e-6)


@pytest.mark.timeout(60)
def test_a_swarm_with_distrust_and_the_diluting_pool_decides_on_the_best() -> None:
    config = ControllerConfig(alpha=0.1, threshold=0.99, pooling="loglinear")
    for seed in (3, 4):
        swarm = make_swarm(N_ROBOTS, 6, seed=seed, config=config)
        swarm.run(3000)
        assert max(size for robot in swarm.controllers for size in robot.pool_sizes) > 1
        for robot in swarm.controllers:
            assert robot.decided_site == swarm.best_site
            assert max(robot.opinion) >= 0.99
            assert min(robot.opinion) > 0.0  # alpha > 0: nothing is ever ruled out
