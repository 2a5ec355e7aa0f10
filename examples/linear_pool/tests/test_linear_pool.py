"""The linear pool alone, registered as a plug-in, and in a swarm (``python -m pytest
examples/linear_pool/tests`` with the package installed in bestofn-swarm's environment)."""

from __future__ import annotations

import math

import pytest
from bestofn_linear_pool import linear_pool

from deploy.cli import build_parser
from deploy.launcher.inprocess import run_plan
from deploy.launcher.plan import plan_from_args
from robot_agent.plugins import registry
from world_server.core.layout import make_layout


def test_it_is_the_mean_of_the_pools_opinions() -> None:
    pooled = linear_pool([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5]])
    assert pooled == [0.25, 0.5, 0.25]


def test_a_site_stays_possible_while_one_robot_of_the_pool_holds_it() -> None:
    """Unlike the product, which rules out what any robot ruled out."""
    pooled = linear_pool([[1.0, 0.0], [0.5, 0.5]])
    assert pooled is not None and pooled[1] > 0.0
    assert linear_pool([[1.0, 0.0], [1.0, 0.0]]) == [1.0, 0.0]


def test_unnormalised_opinions_count_alike_and_the_result_sums_to_one() -> None:
    pooled = linear_pool([[2.0, 2.0, 4.0], [1.0, 1.0, 2.0], [0.3, 0.3, 0.4]])
    assert pooled is not None
    assert math.isclose(math.fsum(pooled), 1.0, abs_tol=1e-12)
    assert pooled == linear_pool([[0.25, 0.25, 0.5], [0.25, 0.25, 0.5], [0.3, 0.3, 0.4]])


def test_a_pool_of_one_is_the_robots_own_opinion() -> None:
    assert linear_pool([[0.2, 0.8]]) == [0.2, 0.8]


def test_opinions_of_other_lengths_are_refused() -> None:
    with pytest.raises(ValueError, match="an opinion of 3 sites in a pool of 2"):
        linear_pool([[0.5, 0.5], [0.2, 0.3, 0.5]])


def test_it_is_installed_as_the_pooling_operator_linear() -> None:
    plugin = registry.resolve("pooling", "linear")
    assert plugin.target is linear_pool
    assert plugin.origin.distribution == "bestofn-linear-pool"
    assert plugin.origin.version == "0.1.0"
    assert plugin.origin.source is not None and not plugin.builtin


def test_a_swarm_pooling_by_it_decides_for_the_best_site() -> None:
    options = ["--robots", "10", "--sites", "5", "--seed", "0", "--pooling", "linear"]
    argv = ["run", "--engine", "inprocess", "--no-record", "--timeout", "1800", *options]
    summary = run_plan(plan_from_args(build_parser(["run"]).parse_args(argv)))
    assert summary["ended"] == "consensus"
    assert summary["chosen_site"] == make_layout(5, 10, 0).best_site
    assert summary["config"]["plugins"]["pooling"]["distribution"] == "bestofn-linear-pool"
