"""The voting strategies (robot_agent/core/voting.py) and the controller's seam for them
(strategies.py): the rules, one robot's beliefs, a robot's trip, and whole swarms."""

from __future__ import annotations

import dataclasses

import pytest
from fakes import make_swarm

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import ports, strategies, voting
from robot_agent.core.beliefs import Beliefs
from robot_agent.core.controller import ControllerConfig
from robot_agent.core.voting import Vote, VoteBeliefs, majority, update


def vote(robot: int, site: int, quality: float = 0.5, t: float = 10.0, order: int = 0) -> Vote:
    return Vote(robot, t, order or robot, site, quality)


def vote_payload(robot: int, site: int, quality: float = 0.5) -> protocol.VotePayload:
    return protocol.VotePayload(v=1, id=robot, trip=0, decided=False, site=site, quality=quality)


# --- the rules ---------------------------------------------------------------------------


@pytest.mark.parametrize("strategy", voting.VOTING)
def test_with_no_votes_a_robot_keeps_its_site_and_draws_nothing(strategy: str) -> None:
    rng = Stream(3)
    state = rng.state
    assert update(strategy, 2, 0.4, [], rng) == 2  # type: ignore[arg-type]
    assert rng.state == state


def test_the_voter_copies_one_neighbour_drawn_at_random() -> None:
    votes = [vote(1, 0), vote(2, 3)]
    chosen = {update("dmvd", 4, 0.9, votes, Stream(seed)) for seed in range(50)}
    assert chosen == {0, 3}  # never its own site 4, whatever its quality


def test_the_majority_counts_the_robot_itself() -> None:
    rng = Stream(0)
    assert majority(2, [2, 5], rng) == 2
    assert majority(2, [5, 5], rng) == 5
    assert majority(2, [5, 2, 5, 7], rng) == 5


def test_a_majority_tie_is_drawn_among_the_tied_sites_only() -> None:
    outcomes = {majority(1, [4, 6], Stream(seed)) for seed in range(60)}
    assert outcomes == {1, 4, 6}
    outcomes = {majority(1, [1, 4, 4, 6], Stream(seed)) for seed in range(60)}
    assert outcomes == {1, 4}


def test_direct_comparison_switches_only_to_a_higher_estimate() -> None:
    better, worse = [vote(1, 3, quality=0.8)], [vote(1, 3, quality=0.2)]
    assert update("dc", 0, 0.5, better, Stream(0)) == 3
    assert update("dc", 0, 0.5, worse, Stream(0)) == 0
    assert update("dc", 0, 0.8, better, Stream(0)) == 0  # equal: no switch
    assert update("dc", 0, None, worse, Stream(0)) == 3  # no estimate yet: 0


def test_the_swarm_starts_spread_evenly_over_the_sites() -> None:
    sites = [voting.initial_site(robot, 4) for robot in range(10)]
    assert sites == [0, 1, 2, 3, 0, 1, 2, 3, 0, 1]


# --- one robot's beliefs -------------------------------------------------------------------


def beliefs(
    strategy: str = "dmvd", robot: int = 1, sites: int = 5, **settings: object
) -> VoteBeliefs:
    config = ControllerConfig(strategy=strategy, **settings)  # type: ignore[arg-type]
    made = strategies.make_strategy(sites, config, robot)
    assert isinstance(made, VoteBeliefs)
    return made


def test_the_strategy_is_chosen_by_the_setting() -> None:
    assert isinstance(strategies.make_strategy(5, ControllerConfig(), 0), Beliefs)
    for strategy in voting.VOTING:
        made = strategies.make_strategy(5, ControllerConfig(strategy=strategy), 0)
        assert isinstance(made, VoteBeliefs)


def test_a_voting_robot_explores_the_one_site_it_favours() -> None:
    mine = beliefs(robot=7)
    assert mine.site == 2 and mine.next_sites(Stream(0)) == [2]
    assert mine.opinion == [0.0, 0.0, 1.0, 0.0, 0.0]
    assert mine.compare({2: 0.75}) is False  # an estimate, not a change of site
    assert mine.quality == 0.75
    payload = mine.broadcast(7)
    assert (payload.site, payload.quality, payload.decided, payload.trip) == (2, 0.75, False, 0)


def test_dissemination_is_modulated_by_the_estimate_except_for_direct_comparison() -> None:
    draws = 4000
    for strategy, quality, mean in (("dmvd", 0.5, 5.0), ("dmmd", 1.0, 10.0), ("dc", 0.5, 10.0)):
        mine = beliefs(strategy)
        mine.quality = quality
        rng = Stream(1)
        lengths = []
        for _ in range(draws):
            end, listen_from = mine.nest_visit(100.0, rng)
            assert end - listen_from == pytest.approx(3.0)  # the listening window
            lengths.append(listen_from - 100.0)
        assert sum(lengths) / draws == pytest.approx(mean, rel=0.06), strategy


def test_exploration_lasts_an_exponential_time_with_mean_sigma() -> None:
    mine = beliefs(exploration=8.0)
    rng = Stream(2)
    times = [mine.exploration(rng) for _ in range(4000)]
    assert min(times) >= 0.0
    assert sum(times) / len(times) == pytest.approx(8.0, rel=0.06)


def test_only_votes_for_our_sites_are_taken() -> None:
    mine = beliefs(sites=5)
    assert mine.hear_payload(3, 1.0, vote_payload(3, 4))
    assert not mine.hear_payload(3, 1.0, vote_payload(3, 5))  # no site 5
    opinion = protocol.OpinionPayload(v=1, id=3, trip=0, decided=False, opinion=[0.5, 0.5])
    assert not mine.hear_payload(3, 1.0, opinion)  # the paper's payload
    paper = strategies.make_strategy(5, ControllerConfig(), 0)
    assert not paper.hear_payload(3, 1.0, vote_payload(3, 4))


def test_the_rule_takes_the_last_g_votes_heard_in_the_listening_window() -> None:
    mine = beliefs("dmmd", robot=0, neighbours=2)  # favours site 0
    mine.hear_payload(4, 5.0, vote_payload(4, 3))  # before the window: not counted
    mine.hear_payload(1, 20.0, vote_payload(1, 2))  # in it, but not among the last two
    mine.hear_payload(2, 21.0, vote_payload(2, 1))
    mine.hear_payload(3, 21.5, vote_payload(3, 1))
    mine.pool(since=19.0, t=22.0, rng=Stream(0))
    assert mine.site == 1  # site 1 twice against its own 0 once
    assert mine.pool_sizes == [3] and mine.trips == 1
    assert mine.quality is None  # site 1 is yet to be explored


def test_a_robot_decides_after_settle_updates_without_dissent() -> None:
    mine = beliefs("dmvd", robot=0, settle=3)
    rng = Stream(0)
    mine.hear_payload(1, 1.0, vote_payload(1, 0))
    mine.pool(0.0, 2.0, rng)
    mine.pool(0.0, 3.0, rng)  # hearing nobody is no dissent
    assert mine.decided_site is None and mine.settled == 2
    mine.hear_payload(2, 3.5, vote_payload(2, 0))
    mine.hear_payload(3, 3.6, vote_payload(3, 4))  # dissent, though not drawn
    mine.pool(3.0, 4.0, Stream(5))
    assert mine.settled == 0  # whatever it drew
    for t in (5.0, 6.0, 7.0):
        mine.pool(t - 0.5, t, rng)
    assert mine.decided_site == mine.site
    assert mine.decision_time == 7.0 and mine.decision_trips == 6
    assert mine.broadcast(0).decided


def test_the_paper_strategy_draws_nothing_for_exploration_or_the_nest() -> None:
    """The default path draws no extra random number: runs stay what they were."""
    paper = strategies.make_strategy(5, ControllerConfig(), 0)
    rng = Stream(9)
    state = rng.state
    assert paper.exploration(rng) == 0.0
    assert paper.nest_visit(12.0, rng) == (15.0, 12.0)  # dwell 3 s, pooling all of it
    paper.pool(12.0, 15.0, rng)
    assert rng.state == state


def test_a_liar_under_a_voting_strategy_never_settles() -> None:
    config = voting.never_settles(ControllerConfig(strategy="dmmd"))
    assert config.settle == voting.NEVER_SETTLE
    assert dataclasses.replace(config, settle=3).settle == 3


# --- a robot's trip, and swarms ------------------------------------------------------------


def test_a_voting_robot_senses_its_site_for_the_exploration_time_then_disseminates() -> None:
    config = ControllerConfig(strategy="dmvd", exploration=20.0)
    swarm = make_swarm(1, 4, seed=3, config=config)
    robot, body, radio = swarm.controllers[0], swarm.bodies[0], swarm.radios[0]
    sensing_since: float | None = None
    sensed_for = 0.0
    sent: list[ports.Command] = []
    while robot.trips < 1 and swarm.world.t < 400:
        command = ports.control_step(robot, body, radio, swarm.rejects[0])
        if robot.phase == "sensing" and sensing_since is None:
            sensing_since = swarm.world.t
        if robot.phase != "sensing" and sensing_since is not None and not sensed_for:
            sensed_for = swarm.world.t - sensing_since
        if command.broadcasts:
            sent.append(command)
        swarm.world.advance()
    assert robot.trips == 1
    assert sensed_for > 0.0
    payloads = [payload for command in sent for payload in command.broadcasts]
    assert payloads and all(isinstance(p, protocol.VotePayload) for p in payloads)
    assert {p.site for p in payloads if isinstance(p, protocol.VotePayload)} == {0}


@pytest.mark.parametrize("strategy", voting.VOTING)
def test_a_voting_swarm_decides_and_parks(strategy: str) -> None:
    config = ControllerConfig(strategy=strategy)
    swarm = make_swarm(6, 3, seed=4, config=config)
    swarm.run(3000)
    decided = [robot.decided_site for robot in swarm.controllers]
    assert all(site is not None for site in decided), decided
    assert all(robot.phase == "stopped" for robot in swarm.controllers)
    assert sum(swarm.rejects[i].count for i in range(6)) == 0
