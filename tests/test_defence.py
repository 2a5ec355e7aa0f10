"""The trimmed-pooling defence (robot_agent/core/defence.py): a site is ruled out by peers'
reports only when more than F peers report it, so F liars cannot rule out the best."""

from __future__ import annotations

import random

import pytest
from fakes import make_swarm
from hypothesis import given, settings
from hypothesis import strategies as st

from bestofn_swarm.wire.rng import Stream
from robot_agent.core import byzantine, defence, ports
from robot_agent.core.beliefs import Beliefs
from robot_agent.core.controller import ControllerConfig
from robot_agent.core.decision import mprodop, negative_update, uniform_opinion

TRIMMED = ControllerConfig(defence="trimmed", trim=1)


def support(*sites: int, n: int = 5) -> list[float]:
    return [1.0 / len(sites) if site in sites else 0.0 for site in range(n)]


def test_a_lone_report_is_dropped_and_a_second_one_counts() -> None:
    own = support(0, 1, 2, 3, 4)
    assert defence.trimmed_support(own, [support(0, 1, 2, 3)], trim=1) == own
    both = defence.trimmed_support(own, [support(0, 1, 2, 3), support(0, 2, 3)], trim=1)
    assert both == support(0, 1, 2, 3)  # site 4 reported twice; site 1 once


def test_the_robots_own_eliminations_are_never_trimmed() -> None:
    own = support(0, 2)
    assert defence.trimmed_support(own, [support(0, 1, 2, 3, 4)] * 3, trim=1) == own


def test_trim_zero_is_the_intersection_as_mprodop_gives_it_at_alpha_0() -> None:
    own, peer = support(0, 1, 2), support(1, 2, 3)
    assert defence.trimmed_support(own, [peer], trim=0) == mprodop([own, peer])


def test_a_liars_certainty_is_dropped_site_by_site() -> None:
    own = support(0, 1, 2, 3, 4)
    liar = byzantine.one_hot(3, 5)
    assert defence.trimmed_support(own, [liar], trim=1) == own
    pooler = defence.TrimmedPooling(1)
    pooler.hear(7, liar)
    pooler.hear(7, liar)
    assert pooler.pool([own]) == own
    pooler.hear(8, liar)  # a second liar: more than F
    assert pooler.pool([own]) == support(3)


def test_nothing_left_keeps_the_robots_own_opinion() -> None:
    own = support(2)
    assert defence.trimmed_support(own, [support(0, 1)] * 2, trim=1) is None


def test_the_defence_is_for_the_papers_strategy_with_alpha_0() -> None:
    with pytest.raises(ValueError, match="alpha = 0"):
        ControllerConfig(defence="trimmed", alpha=0.1, threshold=0.99)
    with pytest.raises(ValueError, match="strategy"):
        ControllerConfig(defence="trimmed", strategy="dmvd")
    assert isinstance(defence.make_pooler("none", "mprodop", 1), defence.PaperPooling)


def test_a_robot_with_the_defence_does_not_adopt_a_liars_certainty() -> None:
    honest = Beliefs(5, TRIMMED)
    honest.hear(4, 10.0, byzantine.one_hot(3, 5))
    honest.pool(since=9.0, t=13.0)
    assert honest.opinion == uniform_opinion(5) and honest.decided_site is None
    paper = Beliefs(5, ControllerConfig())
    paper.hear(4, 10.0, byzantine.one_hot(3, 5))
    paper.pool(since=9.0, t=13.0)
    assert paper.decided_site == 3  # without it, one message decides


def test_reports_heard_at_earlier_visits_count() -> None:
    honest = Beliefs(4, TRIMMED)
    honest.hear(1, 5.0, support(0, 1, 2, n=4))
    honest.pool(since=4.0, t=8.0)
    assert honest.opinion == uniform_opinion(4)
    honest.hear(2, 30.0, support(0, 2, n=4))
    honest.pool(since=29.0, t=33.0)  # robot 1's report of site 3 is remembered
    assert honest.opinion == support(0, 1, 2, n=4)


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(3, 8),
    trim=st.integers(0, 3),
    seed=st.integers(0, 2**32),
    honest_trips=st.lists(st.integers(0, 6), min_size=1, max_size=6),
)
def test_with_at_most_f_liars_the_best_site_is_never_ruled_out(
    n: int, trim: int, seed: int, honest_trips: list[int]
) -> None:
    """Honest robots rule out only worse sites; liars report anything. Site 0 is the best."""
    rng = random.Random(seed)
    robot = Beliefs(n, ControllerConfig(defence="trimmed", trim=trim))
    for peer, trips in enumerate(honest_trips):
        opinion = uniform_opinion(n)
        for _ in range(trips):
            opinion = negative_update(opinion, rng.randrange(1, n))
        robot.hear(peer, 1.0, opinion)
    for liar in range(trim):
        claim = [rng.random() * (site != 0) for site in range(n)]
        if max(claim) == 0.0:
            claim[1] = 1.0
        robot.hear(100 + liar, 1.0, claim)
    robot.pool(since=0.0, t=2.0)
    assert robot.opinion[0] > 0.0


def test_one_liar_does_not_win_against_a_defended_swarm() -> None:
    """Six robots, five sites, robot 0 lies; with the defence every honest robot decides
    the best site."""
    swarm = make_swarm(6, 5, seed=11, config=TRIMMED)
    best = swarm.best_site
    liar_site = next(site for site in range(5) if site != best)
    robots: list[ports.RobotController] = list(swarm.controllers)
    robots[0] = byzantine.build_controller(
        0,
        swarm.controllers[0].world,
        TRIMMED,
        Stream.named(11, "robot", 0),
        byzantine.Behaviour("liar", liar_site),
    )
    honest = swarm.controllers[1:]
    for _ in range(24_000):
        if all(robot.phase == "stopped" for robot in honest):
            break
        for robot, body, radio, rejects in zip(
            robots, swarm.bodies, swarm.radios, swarm.rejects, strict=True
        ):
            ports.control_step(robot, body, radio, rejects)
        swarm.world.advance()
    assert [robot.decided_site for robot in honest] == [best] * 5
