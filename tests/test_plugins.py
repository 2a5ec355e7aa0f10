"""Plug-ins by name (robot_agent/core/plugins.py, robot_agent/plugins/registry.py,
docs/extending.md): the built-ins registered as every plug-in is, names that resolve and
names that do not, objects of the wrong kind, what a plug-in gives checked as a run goes,
and runs in one process: a plug-in that only hands each call to a built-in makes the
built-in's run, bit for bit; one that raises or gives garbage ends the run crashed with one
line naming it, the robot and the tick. The same over Zenoh, on two hosts and in studies:
tests/test_plugin_runs.py and tests/test_multihost.py."""

from __future__ import annotations

import math
import re
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from bestofn_swarm.wire.rng import Stream
from deploy.cli import build_parser, main
from deploy.launcher.inprocess import run_plan
from deploy.launcher.plan import plan_from_args
from robot_agent.core import decision, plugin_checks, plugins
from robot_agent.core.beliefs import Beliefs
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import GROUPS, KINDS, Origin, Plugin, PluginCallError, PluginError
from robot_agent.plugins import registry

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))  # plugin_samples, named by module:attribute
SAMPLES = "plugin_samples"
SWARM = ["--robots", "6", "--sites", "4", "--seed", "3", "--timeout", "600"]


def swarm_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``swarm ARGV`` in this process: (exit code, standard output, standard error). For
    what ends before anything starts."""
    try:
        code = main(argv)
    except SystemExit as leaving:
        code = leaving.code if isinstance(leaving.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def run(*options: str) -> dict[str, Any]:
    """``swarm run --engine inprocess --no-record OPTIONS``: its summary."""
    argv = ["run", "--engine", "inprocess", "--no-record", *options]
    return run_plan(plan_from_args(build_parser(["run"]).parse_args(argv)))


# --- the built-ins, registered -----------------------------------------------------------------


def test_the_project_registers_its_built_ins_as_plugins_of_their_groups() -> None:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    registered = project["entry-points"]
    for kind in KINDS:
        group = registered[GROUPS[kind]]
        assert set(group) == set(plugins.BUILTINS[kind]), kind
        for name, value in group.items():
            module, _, attribute = value.partition(":")
            found = sys.modules.get(module) or __import__(module, fromlist=["_"])
            assert getattr(found, attribute) is plugins.BUILTINS[kind][name], value


def test_a_built_in_resolves_to_itself_with_its_distribution_and_source() -> None:
    found = registry.resolve("pooling", "mprodop")
    assert found.target is decision.mprodop and found.builtin
    assert found.where == "robot_agent.core.decision:mprodop"
    source = registry.source_file(decision.mprodop)
    assert source == REPO / "robot_agent" / "core" / "decision.py"
    assert found.origin.source == registry.source_hash(decision.mprodop)
    assert found.origin.source is not None and len(found.origin.source) == 16
    assert found.origin.distribution == "bestofn-swarm"


def test_the_default_run_resolves_to_the_built_ins() -> None:
    found = registry.resolve_plugins(ControllerConfig())
    assert found.all_builtin
    assert found.names() == {"strategy": "paper", "pooling": "mprodop", "controller": "paper"}
    record = found.record()
    assert set(record) == set(KINDS)
    assert set(record["pooling"]) == {"name", "target", "distribution", "version", "source"}


def test_a_module_attribute_name_resolves_and_is_no_built_in() -> None:
    found = registry.resolve("pooling", f"{SAMPLES}:product")
    assert found.name == f"{SAMPLES}:product" and not found.builtin
    assert found.where == f"{SAMPLES}:product"
    assert found.origin == Origin(None, None, registry.source_hash(found.target))


def test_a_built_in_named_by_where_it_is_is_still_the_built_in() -> None:
    assert registry.resolve("pooling", "robot_agent.core.decision:mprodop").builtin


# --- names that do not resolve, objects of the wrong kind ------------------------------------


@pytest.mark.parametrize(
    ("kind", "name", "message"),
    [
        (
            "pooling",
            "linear-nobody-made",
            r"^no pooling plug-in 'linear-nobody-made' \(--pooling\)",
        ),
        ("strategy", "no_such_package.rules:mine", r"no module 'no_such_package'"),
        ("strategy", f"{SAMPLES}:no_such_rule", rf"{SAMPLES} has no attribute 'no_such_rule'"),
        ("pooling", f"{SAMPLES}:NOT_A_PLUGIN", r"is a int, not a pooling operator"),
        ("pooling", f"{SAMPLES}:LostStrategy", r"is the class LostStrategy: not a pooling"),
        ("strategy", f"{SAMPLES}:product", r"takes \(opinions\): not a strategy factory"),
        ("controller", f"{SAMPLES}:product", r"takes \(opinions\): not a controller factory"),
        ("controller", "robot_agent.core.beliefs:Beliefs", r"lacks step, status"),
        ("strategy", "robot_agent.core:decision", r"is the module robot_agent.core.decision"),
    ],
)
def test_a_name_that_does_not_resolve_or_the_wrong_kind_is_one_line(
    kind: Any, name: str, message: str
) -> None:
    with pytest.raises(PluginError, match=message) as raised:
        registry.resolve(kind, name)
    text = str(raised.value)
    assert "\n" not in text and f"{kind} plug-in" in text and name in text


def test_two_distributions_registering_one_name_make_it_ambiguous(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    twice = [
        registry.Entry("pooling", "mean", "one.pool:mean", "one", "1.0"),
        registry.Entry("pooling", "mean", "two.pool:mean", "two", "2.0"),
    ]
    monkeypatch.setattr(registry, "entries", lambda kind: twice if kind == "pooling" else [])
    with pytest.raises(PluginError, match=r"'mean' is ambiguous: one.pool:mean \(one\), two"):
        registry.resolve("pooling", "mean")


def test_a_whole_controller_takes_no_strategy_or_pooling_of_the_run() -> None:
    config = ControllerConfig(pooling="loglinear", alpha=0.1, threshold=0.99)
    with pytest.raises(PluginError, match="is a whole controller: it takes no --strategy"):
        registry.resolve_plugins(config, f"{SAMPLES}:paper_controller")


def test_a_robot_elsewhere_must_run_the_source_the_run_ran() -> None:
    found = registry.resolve_plugins(ControllerConfig(pooling=f"{SAMPLES}:product"))
    registry.check_sources(found, found.sources())  # the same code: nothing to say
    with pytest.raises(PluginError, match=r"its source here \([0-9a-f]{16}\) is not the run's"):
        registry.check_sources(found, {"pooling": "0" * 16})


def test_swarm_run_refuses_a_bad_name_before_anything_starts(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    record = tmp_path / "never.mcap"
    for engine in ("inprocess", "zenoh"):
        code, _, error = swarm_cli(
            ["run", "--engine", engine, "--record", str(record), "--pooling", "no-such-pool"],
            capsys,
        )
        assert code == 2
        assert error.startswith("swarm run: error: no pooling plug-in 'no-such-pool'")
        assert error.count("\n") == 1
    code, _, error = swarm_cli(["run", "--strategy", f"{SAMPLES}:NOT_A_PLUGIN"], capsys)
    assert code == 2 and error.count("\n") == 1 and "is a int" in error
    assert list(tmp_path.iterdir()) == []  # nothing was started, nothing written


# --- what a plug-in gives, checked ------------------------------------------------------------


def _pooling(target: Any) -> decision.PoolingOperator:
    return plugin_checks.checked_pooling(Plugin("pooling", "p", target))


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ([0.5, math.nan], r"returned an opinion with nan at \[1\]"),
        ([1.5, -0.5], r"a negative weight -0.5 at \[1\]"),
        ([1.0], "an opinion of 1 entries over 2 sites"),
        ("certain", "'certain', not a list of 2 probabilities"),
        ([0.0, 0.0], "all zeros .return None for a pool that contradicts itself"),
        ([0.5, 0.6], "sums to 1.1, not 1"),
        ([True, 0.0], r"an opinion with True at \[0\]"),
    ],
)
def test_a_pooling_operators_garbage_is_named(given: Any, message: str) -> None:
    with pytest.raises(PluginCallError, match=message):
        _pooling(lambda opinions: given)([[0.5, 0.5], [0.2, 0.8]])


def test_a_good_pooling_operator_passes_unchanged_and_none_is_a_contradiction() -> None:
    pool = [[0.5, 0.5, 0.0], [0.25, 0.25, 0.5]]
    assert _pooling(decision.mprodop)(pool) == decision.mprodop(pool)
    assert _pooling(lambda opinions: None)(pool) is None


def test_what_a_pooling_operator_raises_is_named() -> None:
    def broken(opinions: Any) -> list[float]:
        raise ValueError("two\nlines")

    with pytest.raises(PluginCallError, match=r"pooling plug-in 'p' raised ValueError: two lines$"):
        _pooling(broken)([[0.5, 0.5]])


def test_a_strategys_site_that_is_not_there_is_named_with_its_robot_and_tick() -> None:
    class Lost(Beliefs):
        def next_sites(self, rng: Stream) -> list[int]:
            return [0, 7]

    plugin = Plugin("strategy", "lost", Lost)
    good = plugin_checks.CheckedStrategy(Beliefs(4, ControllerConfig()), plugin, 4)
    assert good.next_sites(Stream(1)) == Beliefs(4, ControllerConfig()).next_sites(Stream(1))
    strategy = plugin_checks.CheckedStrategy(Lost(4, ControllerConfig()), plugin, 4)
    with pytest.raises(PluginCallError) as raised:
        strategy.next_sites(Stream(1))
    error = raised.value.at(3, 120)
    assert str(error) == (
        "strategy plug-in 'lost' chose the sites [0, 7]: one or two distinct sites of 0..3 "
        "(robot 3, tick 120)"
    )
    assert (error.robot, error.tick) == (3, 120)


# --- runs in one process --------------------------------------------------------------------


@pytest.mark.parametrize(
    "options",
    [
        ["--pooling", f"{SAMPLES}:product"],
        ["--strategy", f"{SAMPLES}:paper_strategy"],
        ["--controller", f"{SAMPLES}:paper_controller"],
    ],
    ids=["pooling", "strategy", "controller"],
)
def test_a_plugin_that_only_delegates_makes_the_built_ins_run_exactly(options: list[str]) -> None:
    built_in = run(*SWARM)
    plugged = run(*SWARM, *options)
    assert built_in["ended"] == "consensus"
    assert plugged["per_robot"] == built_in["per_robot"]
    assert plugged["digest"] == built_in["digest"]
    kind = options[0].removeprefix("--")
    assert plugged["config"]["plugins"][kind]["name"] == options[1]
    assert built_in["config"]["plugins"][kind]["distribution"] == "bestofn-swarm"


@pytest.mark.parametrize(
    ("options", "error"),
    [
        (
            ["--pooling", f"{SAMPLES}:raising"],
            r"^pooling plug-in 'plugin_samples:raising' raised ZeroDivisionError: a pool of "
            r"more than one \(robot \d+, tick \d+\)$",
        ),
        (
            ["--pooling", f"{SAMPLES}:not_a_number"],
            r"^pooling plug-in 'plugin_samples:not_a_number' returned an opinion with nan at "
            r"\[0\] \(robot \d+, tick \d+\)$",
        ),
        (
            ["--pooling", f"{SAMPLES}:wrong_type"],
            r"returned 'certain of site 0', not a list of 4 probabilities \(robot \d+, tick \d+\)$",
        ),
        (
            ["--strategy", f"{SAMPLES}:LostStrategy"],
            r"^strategy plug-in 'plugin_samples:LostStrategy' chose the sites \[\d, 7\]: one or "
            r"two distinct sites of 0..3 \(robot \d+, tick \d+\)$",
        ),
        (
            ["--controller", f"{SAMPLES}:StallingController"],
            r"^controller plug-in 'plugin_samples:StallingController' returned a left wheel "
            r"speed of inf from step \(robot 0, tick 20\)$",
        ),
    ],
    ids=["raises", "nan", "wrong-type", "no-such-site", "controller-garbage"],
)
def test_a_plugin_that_fails_in_a_step_ends_the_run_crashed_naming_it(
    options: list[str], error: str
) -> None:
    summary = run(*SWARM, *options)
    assert summary["ended"] == "crashed" and summary["sim_time_s"] > 0.0
    assert "\n" not in summary["error"]
    named = re.search(error, summary["error"])
    assert named is not None, summary["error"]
    robot = re.search(r"\(robot (\d+), tick", summary["error"])
    assert robot is not None
    crashed = [entry["id"] for entry in summary["per_robot"] if entry["crashed"]]
    assert crashed == [int(robot.group(1))]  # as its process would have, over Zenoh


def test_a_plugin_that_cannot_make_a_robot_ends_the_run_before_its_first_tick() -> None:
    summary = run(*SWARM, "--strategy", f"{SAMPLES}:unmade_strategy")
    assert summary["ended"] == "crashed" and summary["sim_time_s"] == 0.0
    assert summary["error"] == (
        "strategy plug-in 'plugin_samples:unmade_strategy' raised RuntimeError: no strategy "
        "for robot 2 making robot 2's strategy"
    )


def test_swarm_plugins_lists_the_built_ins(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = swarm_cli(["plugins"], capsys)
    assert code == 0
    assert "pooling (--pooling; entry points bestofn_swarm.pooling)" in out
    assert "  mprodop    robot_agent.core.decision:mprodop  (bestofn-swarm" in out
    assert "controller (--controller; entry points bestofn_swarm.controllers)" in out


def test_swarm_plugins_names_one_that_cannot_be_loaded(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    broken = [registry.Entry("pooling", "broken", "no_such_module:pool", "someone", "0.1")]
    monkeypatch.setattr(registry, "entries", lambda kind: broken if kind == "pooling" else [])
    code, out, err = swarm_cli(["plugins", "pooling"], capsys)
    assert code == 1
    assert "  broken     cannot be loaded: pooling plug-in 'broken': no module" in out
    assert err.startswith("swarm plugins: pooling plug-in 'broken': no module 'no_such_module'")
