"""The voting strategies in the well-stirred model (robot_agent/wellstirred/voting.py)."""

from __future__ import annotations

import numpy as np
import pytest

from robot_agent.wellstirred.model import cell_rng
from robot_agent.wellstirred.voting import (
    VoteModel,
    _step,
    simulate_votes,
    vote_cell_rng,
    vote_sweep,
)


def test_a_model_refuses_what_it_cannot_run() -> None:
    with pytest.raises(ValueError, match="voting strategy"):
        VoteModel("paper", 10, 3, 50)
    with pytest.raises(ValueError, match="pool"):
        VoteModel("dmvd", 10, 1, 50)
    with pytest.raises(ValueError, match="smaller than the pool"):
        VoteModel("dmmd", 10, 5, 4)
    model = VoteModel("dmmd", 10, 3, 50)
    assert (model.agents, model.heard, model.alpha, model.survivors_exact) == (50, 2, 0.0, False)
    assert VoteModel("dmvd", 10, 3, 50).heard == 1


def test_the_same_seed_gives_the_same_runs_and_cells_differ() -> None:
    model = VoteModel("dmvd", 5, 3, 20, steps=300)
    first = simulate_votes(model, 30, vote_cell_rng(4, model))
    again = simulate_votes(model, 30, vote_cell_rng(4, model))
    assert np.array_equal(first.times, again.times)
    assert np.array_equal(first.success, again.success)
    other = VoteModel("dmmd", 5, 3, 20)
    assert vote_cell_rng(4, model).random() != vote_cell_rng(4, other).random()
    assert vote_cell_rng(4, model).random() != cell_rng(4, model).random()  # type: ignore[arg-type]


def test_direct_comparison_always_finds_the_best_without_noise() -> None:
    """With every option held at the start and exact qualities, an agent only ever moves
    to a better option: the best one can only spread."""
    model = VoteModel("dc", 20, 3, 40, steps=500)
    outcome = simulate_votes(model, 50, vote_cell_rng(0, model))
    assert outcome.success.all()
    assert (outcome.times >= 1).all()


def test_the_majority_is_faster_and_less_accurate_than_the_voter() -> None:
    """Valentini et al.'s ordering (AAMAS 2015, JAAMAS 2016), in the well-stirred model."""
    runs = 200
    voter = VoteModel("dmvd", 10, 3, 50, steps=2000)
    major = VoteModel("dmmd", 10, 3, 50, steps=2000)
    dmvd = simulate_votes(voter, runs, vote_cell_rng(1, voter))
    dmmd = simulate_votes(major, runs, vote_cell_rng(1, major))
    assert dmmd.success.mean() < dmvd.success.mean()
    assert np.median(dmmd.times[dmmd.success]) < np.median(dmvd.times[dmvd.success])


def test_modulation_favours_better_options() -> None:
    """With one agent on each of two options, an agent of the better one is heard more."""
    model = VoteModel("dmvd", 2, 2, 2, dissemination=10.0, listen=0.0)
    opinions = np.array([[0, 1]] * 4000)
    rho = np.array([1.0, 0.0])
    weights = model.dissemination * rho + model.listen + 1e-12
    after = _step(model, opinions, rho, weights, np.random.default_rng(0))
    # Each agent hears the other (the only neighbour): a swap, whatever the weights.
    assert (after == opinions[:, ::-1]).all()
    many = VoteModel("dmvd", 2, 2, 10, listen=0.0)
    spread = np.array([[0] * 5 + [1] * 5] * 2000)
    moved = _step(many, spread, rho, many.dissemination * rho + 0.5, np.random.default_rng(1))
    assert (moved == 0).mean() > 0.9  # the best option's agents dominate what is heard


def test_a_consensus_on_a_worse_option_is_a_failure_at_the_step_limit() -> None:
    model = VoteModel("dmmd", 8, 3, 8, steps=400)
    outcome = simulate_votes(model, 100, vote_cell_rng(2, model))
    assert (~outcome.success).any()
    assert (outcome.times[~outcome.success] == 400).all()


def test_a_sweep_gives_one_cell_per_n_and_k() -> None:
    cells = vote_sweep("dc", [5, 10], [3], runs=10, seed=0, population=20, steps=200)
    assert [(cell.model.options, cell.model.pool) for cell in cells] == [(5, 3), (10, 3)]
    assert all(cell.summary.success_rate == 1.0 for cell in cells)
