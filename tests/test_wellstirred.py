"""The Section 4 model: both simulation paths, the exact chain, sweeps and traces."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest

from robot_agent.wellstirred import model as wellstirred
from robot_agent.wellstirred.model import (
    Method,
    Model,
    Outcome,
    cell_rng,
    exact_consensus_time,
    opinion_trace,
    optimal_pool,
    qualities,
    simulate,
    summarise,
    survivor_transitions,
    sweep,
)


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def z_score(outcome: Outcome, expected_mean: float) -> float:
    standard_error = outcome.times.std(ddof=1) / math.sqrt(outcome.runs)
    return (outcome.times.mean() - expected_mean) / standard_error


# --- the model's parameters ------------------------------------------------------------


def test_qualities_follow_the_paper() -> None:
    assert qualities(5).tolist() == [1.0, 0.75, 0.5, 0.25, 0.0]
    assert qualities(2).tolist() == [1.0, 0.0]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"options": 1, "pool": 2}, "options must be at least 2"),
        ({"options": 10, "pool": 0}, "pool must be at least 1"),
        ({"options": 10, "pool": 3, "population": 2}, r"population \(2\) is smaller"),
        ({"options": 10, "pool": 3, "steps": 0}, "steps must be at least 1"),
        ({"options": 10, "pool": 3, "alpha": 0.6}, "alpha"),
        ({"options": 10, "pool": 3, "alpha": float("nan")}, "alpha"),
        ({"options": 10, "pool": 3, "threshold": 0.0}, "threshold"),
        ({"options": 10, "pool": 3, "threshold": 1.5}, "threshold"),
        ({"options": 10.0, "pool": 3}, "options must be an integer"),
    ],
)
def test_bad_models_are_rejected(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Model(**kwargs)


def test_population_defaults_to_the_pool() -> None:
    assert Model(10, 4).agents == 4
    assert Model(10, 4).survivors_exact
    assert not Model(10, 4, 8).survivors_exact
    assert not Model(10, 4, alpha=0.1).survivors_exact


def test_runs_and_method_are_checked() -> None:
    with pytest.raises(ValueError, match="runs must be at least 1"):
        simulate(Model(10, 2), 0, rng())
    with pytest.raises(ValueError, match="survivors path is exact only"):
        simulate(Model(10, 2, 4), 5, rng(), method="survivors")
    with pytest.raises(ValueError, match="unknown method"):
        unknown: Any = "fastest"
        simulate(Model(10, 2), 5, rng(), method=unknown)


# --- the exact chain -------------------------------------------------------------------


def test_transitions_match_brute_force_enumeration() -> None:
    """Every pair of survivors for every agent, counted: the DP must agree."""
    n, k = 7, 3
    transitions = survivor_transitions(n, k)
    for m in range(2, n + 1):
        pairs = list(itertools.combinations(range(m), 2))
        counts = np.zeros(n + 1)
        for combination in itertools.product(pairs, repeat=k):
            counts[m - len({max(pair) for pair in combination})] += 1
        np.testing.assert_allclose(transitions[m], counts / len(pairs) ** k, atol=1e-15)


@pytest.mark.parametrize(("n", "k"), [(2, 1), (10, 1), (10, 3), (30, 7), (100, 50), (5, 200)])
def test_transition_rows_are_distributions(n: int, k: int) -> None:
    transitions = survivor_transitions(n, k)
    np.testing.assert_allclose(transitions[1:].sum(axis=1), 1.0, atol=1e-12)
    assert (transitions >= 0).all()
    # Every step eliminates at least one option and at most min(k, m - 1).
    for m in range(2, n + 1):
        assert transitions[m, m] == 0.0
        assert transitions[m, : max(1, m - k)].sum() == 0.0


@pytest.mark.parametrize("k", [1, 2, 3, 8])
def test_exact_time_for_three_options(k: int) -> None:
    # From 3 survivors all k agents eliminate the same rank with probability
    # (1/3)^k + (2/3)^k, leaving 2, which take one more step.
    exact = exact_consensus_time(Model(3, k))
    assert exact.mean == pytest.approx(1 + (1 / 3) ** k + (2 / 3) ** k, abs=1e-14)
    assert exact.unbounded_mean == pytest.approx(exact.mean, abs=1e-14)


def test_exact_time_with_one_agent_is_n_minus_1() -> None:
    exact = exact_consensus_time(Model(100, 1))
    assert exact.mean == pytest.approx(99.0)
    assert exact.quantile(0.5) == 99


def test_exact_time_respects_the_step_limit_and_threshold() -> None:
    capped = exact_consensus_time(Model(100, 1, steps=50))
    assert capped.mean == pytest.approx(50.0)
    assert capped.unbounded_mean == pytest.approx(99.0)
    # Threshold 0.5: decided once at most 2 options survive.
    assert exact_consensus_time(Model(100, 1, threshold=0.5)).mean == pytest.approx(98.0)


def test_exact_time_only_where_the_chain_is_exact() -> None:
    with pytest.raises(ValueError, match="alpha = 0 and population = pool"):
        exact_consensus_time(Model(10, 2, alpha=0.1))
    with pytest.raises(ValueError, match="alpha = 0 and population = pool"):
        exact_consensus_time(Model(10, 2, 4))
    with pytest.raises(ValueError, match="pools up to"):
        survivor_transitions(10, wellstirred.MAX_EXACT_POOL + 1)


def test_paper_numbers_for_100_options() -> None:
    """Section 4: n = 100, k = 3 'about 35' and k = 5 'about 23' steps on average."""
    assert exact_consensus_time(Model(100, 3)).mean == pytest.approx(35.28, abs=0.01)
    assert exact_consensus_time(Model(100, 5)).mean == pytest.approx(22.40, abs=0.01)


# --- simulations against the exact chain ----------------------------------------------


@pytest.mark.parametrize(("n", "k"), [(10, 2), (10, 3), (20, 6), (50, 20)])
def test_survivors_path_matches_the_exact_mean(n: int, k: int) -> None:
    model = Model(n, k)
    outcome = simulate(model, 20_000, rng(n + k), method="survivors")
    assert abs(z_score(outcome, exact_consensus_time(model).mean)) < 4.5
    assert outcome.success.all()


def test_survivors_path_matches_the_exact_distribution() -> None:
    model = Model(10, 3)
    exact = exact_consensus_time(model)
    outcome = simulate(model, 20_000, rng(5), method="survivors")
    probabilities = -np.diff(np.concatenate([[1.0], exact.survival]))
    observed = np.bincount(outcome.times, minlength=probabilities.size)
    expected = probabilities * outcome.runs
    used = expected > 5
    chi_square = ((observed[used] - expected[used]) ** 2 / expected[used]).sum()
    # 99.99th percentile of chi-square with up to 5 degrees of freedom is about 25.7.
    assert used.sum() >= 4
    assert chi_square < 25.7


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("n", "k"), [(10, 3), (20, 2)])
def test_opinions_path_matches_the_exact_mean(n: int, k: int) -> None:
    """The general path, run where the chain is exact, checks the fast path's shortcut."""
    model = Model(n, k)
    outcome = simulate(model, 20_000, rng(n * k), method="opinions")
    assert abs(z_score(outcome, exact_consensus_time(model).mean)) < 4.5
    assert outcome.success.all()


@pytest.mark.parametrize("method", ["survivors", "opinions"])
def test_one_agent_takes_n_minus_1_steps(method: Method) -> None:
    outcome = simulate(Model(12, 1), 50, rng(), method=method)
    assert (outcome.times == 11).all()
    assert outcome.success.all()


def test_auto_takes_the_survivors_path_only_where_exact(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[str] = []
    original_survivors = wellstirred._simulate_survivors
    original_opinions = wellstirred._simulate_opinions

    def survivors(*args: Any) -> Any:
        calls.append("survivors")
        return original_survivors(*args)

    def opinions(*args: Any) -> Any:
        calls.append("opinions")
        return original_opinions(*args)

    monkeypatch.setattr(wellstirred, "_simulate_survivors", survivors)
    monkeypatch.setattr(wellstirred, "_simulate_opinions", opinions)
    simulate(Model(10, 3), 5, rng())
    simulate(Model(10, 3, 6), 5, rng())
    simulate(Model(10, 3, alpha=0.1, threshold=0.9), 5, rng())
    assert calls == ["survivors", "opinions", "opinions"]


def test_step_limit_counts_failures_as_the_limit() -> None:
    outcome = simulate(Model(50, 1, steps=10), 20, rng(), method="survivors")
    assert (outcome.times == 10).all()
    assert not outcome.success.any()
    summary = summarise(outcome)
    assert summary.mean == 10.0
    assert summary.success_rate == 0.0


def test_a_low_threshold_can_be_met_at_the_start() -> None:
    for method in ("survivors", "opinions"):
        outcome = simulate(Model(4, 2, threshold=0.25), 5, rng(), method=method)
        assert (outcome.times == 0).all() and outcome.success.all()


# --- beyond the paper: alpha > 0 and populations larger than the pool -----------------


def test_worthless_evidence_never_converges() -> None:
    outcome = simulate(Model(5, 3, alpha=0.5, steps=20, threshold=0.9), 30, rng())
    assert (outcome.times == 20).all()
    assert summarise(outcome).success_rate == 0.0


def test_noisy_evidence_still_finds_the_best_option() -> None:
    means = {}
    for alpha in (0.1, 0.4):
        outcome = simulate(Model(10, 5, alpha=alpha, threshold=0.99), 200, rng(1))
        assert summarise(outcome).success_rate == 1.0
        means[alpha] = outcome.times.mean()
    # Less trust in the evidence, slower decisions; alpha = 0 takes 3.20 steps (exact).
    assert exact_consensus_time(Model(10, 5)).mean + 0.3 < means[0.1] < means[0.4] - 1.0


def test_population_larger_than_the_pool() -> None:
    """Agents shuffled into pools of 1: nobody shares evidence, so n - 1 steps each."""
    isolated = simulate(Model(8, 1, 6), 40, rng())
    assert (isolated.times == 7).all()
    # Pools of 2 out of 9 agents (four pairs and a single agent) are slower than one
    # pool of all 9 agents and faster than agents on their own.
    split = simulate(Model(20, 2, 9), 400, rng(2))
    together = exact_consensus_time(Model(20, 9)).mean
    assert together + 1 < split.times.mean() < 19
    assert split.success.all()


def test_pools_get_shuffled_members_and_a_smaller_last_pool() -> None:
    """5 agents in pools of 2: two pairs adopt their pair's product, one agent is alone."""
    updated = rng(4).dirichlet(np.ones(4), size=(1, 5))
    pairs_seen: set[frozenset[int]] = set()
    for seed in range(20):
        pooled = wellstirred._pool(updated, 2, rng(seed))[0]
        own = updated[0] / updated[0].sum(axis=-1, keepdims=True)
        alone = [a for a in range(5) if np.allclose(pooled[a], own[a], rtol=1e-12)]
        assert len(alone) == 1
        partners = {}
        for a, b in itertools.permutations(range(5), 2):
            product = updated[0, a] * updated[0, b]
            if np.allclose(pooled[a], product / product.sum(), rtol=1e-12):
                partners[a] = b
        assert set(partners) == set(range(5)) - set(alone)
        assert all(partners[partners[a]] == a for a in partners)
        pairs_seen.update(frozenset((a, b)) for a, b in partners.items())
    # The shuffle varies who pools with whom.
    assert len(pairs_seen) >= 6


def test_contradictory_pools_keep_their_own_opinions() -> None:
    updated = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    pooled = wellstirred._pool(updated, 2, rng())
    np.testing.assert_array_equal(pooled, updated)


def test_consensus_on_a_wrong_option_is_a_failure() -> None:
    opinions = np.array(
        [
            [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]],  # both certain of option 2: wrong consensus
            [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]],  # both certain of option 1: consensus
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],  # disagree: neither
            [[0.6, 0.4, 0.0], [1.0, 0.0, 0.0]],  # one undecided: neither
        ]
    )
    reached, wrong = wellstirred._consensus(opinions, 1.0)
    assert reached.tolist() == [False, True, False, False]
    assert wrong.tolist() == [True, False, False, False]


def test_weighted_choice_never_picks_a_zero_weight() -> None:
    weights = np.tile(np.array([0.0, 0.3, 0.0, 0.7, 0.0]), (20_000, 1))
    chosen = wellstirred._weighted_choice(weights, rng(9))
    counts = np.bincount(chosen, minlength=5)
    assert counts[[0, 2, 4]].sum() == 0
    assert abs(counts[3] / 20_000 - 0.7) < 0.02


def test_negative_update_matches_the_pure_python_version() -> None:
    from robot_agent.core.decision import negative_update

    opinions = rng(3).dirichlet(np.ones(6), size=(4, 5))
    eliminated = rng(4).integers(0, 6, size=(4, 5))
    for alpha in (0.0, 0.2, 0.5):
        updated = wellstirred._negative_update(opinions, eliminated, alpha)
        for run, agent in itertools.product(range(4), range(5)):
            opinion, option = opinions[run, agent].tolist(), int(eliminated[run, agent])
            expected = negative_update(opinion, option, alpha)
            np.testing.assert_allclose(updated[run, agent], expected, rtol=1e-12, atol=1e-15)


# --- determinism, sweeps, traces -------------------------------------------------------


@pytest.mark.parametrize("model", [Model(20, 3), Model(10, 2, 5, alpha=0.1, threshold=0.95)])
def test_same_seed_same_result(model: Model) -> None:
    first = simulate(model, 100, rng(42))
    second = simulate(model, 100, rng(42))
    np.testing.assert_array_equal(first.times, second.times)
    third = simulate(model, 100, rng(43))
    assert not np.array_equal(first.times, third.times)


def test_a_cell_does_not_depend_on_the_rest_of_the_sweep() -> None:
    full = sweep([10, 20], [2, 3], runs=200, seed=7)
    alone = sweep([20], [3], runs=200, seed=7)
    np.testing.assert_array_equal(full[-1].outcome.times, alone[0].outcome.times)
    assert [(cell.model.options, cell.model.pool) for cell in full] == [
        (10, 2),
        (10, 3),
        (20, 2),
        (20, 3),
    ]


def test_sweep_reports_cells_and_exact_times() -> None:
    seen: list[tuple[int, int]] = []
    cells = sweep(
        [10],
        [1, 3, 5],
        runs=300,
        seed=0,
        exact=True,
        on_cell=lambda cell: seen.append((cell.model.options, cell.model.pool)),
    )
    assert seen == [(10, 1), (10, 3), (10, 5)]
    assert all(cell.exact is not None for cell in cells)
    assert cells[0].summary.mean == 9.0
    assert optimal_pool(cells, 10) == 3
    assert optimal_pool(cells, 20) is None
    split = sweep([10], [2], runs=20, seed=0, population=4, exact=True)
    assert split[0].exact is None


def test_summary_statistics() -> None:
    times = np.array([1, 2, 3, 4, 100])
    outcome = Outcome(Model(10, 2), times, np.array([True, True, True, True, False]))
    summary = summarise(outcome)
    assert summary.mean == 22.0
    assert (summary.q1, summary.median, summary.q3) == (2.0, 3.0, 4.0)
    assert summary.maximum == 100
    assert summary.success_rate == 0.8


def test_cell_rng_depends_on_seed_and_cell() -> None:
    draws = {
        (seed, n, k): cell_rng(seed, Model(n, k)).integers(1 << 62)
        for seed in (0, 1)
        for n in (10, 20)
        for k in (2, 3)
    }
    assert len(set(draws.values())) == len(draws)
    assert cell_rng(0, Model(10, 2)).integers(1 << 62) == draws[(0, 10, 2)]


def test_opinion_trace_runs_to_consensus() -> None:
    trace = opinion_trace(Model(10, 3), rng(11))
    assert trace.shape[1] == 10
    np.testing.assert_allclose(trace[0], 0.1)
    np.testing.assert_allclose(trace.sum(axis=1), 1.0)
    assert trace[-1, 0] == 1.0
    assert (trace[:-1, 0] < 1.0).all()
    # With alpha = 0 eliminated options never come back.
    assert ((trace[1:] > 0) <= (trace[:-1] > 0)).all()
