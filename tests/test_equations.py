"""Section 3's Equations (1)-(4) (``robot_agent.wellstirred.equations``), against the primitives."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from opinion_helpers import assert_close, assert_distribution, normalise, working_alphas

from bestofn_swarm.wire.rng import Stream
from robot_agent.core.decision import choose_pair, mprodop, negative_update, uniform_opinion
from robot_agent.wellstirred.equations import (
    enumeration_terms,
    evidence_probability,
    expected_pooled_opinion,
    pooled_opinion,
    pooled_opinion_alpha0,
)


def test_evidence_probability() -> None:
    assert evidence_probability(4) == pytest.approx([0, 2 / 12, 4 / 12, 6 / 12])
    assert math.fsum(evidence_probability(37)) == pytest.approx(1.0)


def test_equation_1() -> None:
    # k = 3; counts (0, 2, 1): option i keeps alpha^m_i (1-alpha)^(3-m_i).
    alpha = 0.2
    raw = [0.8**3, 0.2**2 * 0.8, 0.2 * 0.8**2]
    assert_close(pooled_opinion([0, 2, 1], alpha), normalise(raw), 1e-15)


@given(st.lists(st.integers(0, 5), min_size=2, max_size=8))
def test_equation_4_is_equation_1_at_alpha_0(counts: list[int]) -> None:
    assume(0 in counts)
    survivors = counts.count(0)
    expected = [1 / survivors if m == 0 else 0.0 for m in counts]
    assert pooled_opinion_alpha0(counts) == pytest.approx(expected)
    assert pooled_opinion(counts, 0.0) == pytest.approx(expected)
    # Equation (1) with a tiny alpha tends to Equation (4).
    assert_close(pooled_opinion(counts, 1e-12), expected, 1e-9)


@given(st.lists(st.integers(0, 4), min_size=2, max_size=6), working_alphas)
def test_equation_1_is_mprodop_of_updated_uniform_opinions(counts: list[int], alpha: float) -> None:
    assume(sum(counts) > 0 and (alpha > 0 or 0 in counts))
    n = len(counts)
    updated = [
        negative_update(uniform_opinion(n), option, alpha)
        for option, m in enumerate(counts)
        for _ in range(m)
    ]
    pooled = mprodop(updated)
    assert pooled is not None
    assert_close(pooled, pooled_opinion(counts, alpha), 1e-9)


def test_all_eliminated_has_no_pooled_opinion() -> None:
    with pytest.raises(ValueError, match="every option was eliminated"):
        pooled_opinion_alpha0([1, 2])


@pytest.mark.parametrize(("n", "k", "alpha"), [(2, 3, 0.1), (5, 3, 0.0), (6, 4, 0.3), (4, 1, 0.0)])
def test_equation_3_is_a_distribution(n: int, k: int, alpha: float) -> None:
    expected = expected_pooled_opinion(n, k, alpha)
    assert_distribution(expected)
    # Better options keep more belief on average.
    assert all(a >= b for a, b in itertools.pairwise(expected))


def test_equation_3_closed_cases() -> None:
    # n = 2: option 2 is always eliminated by all k agents.
    ratio = (0.1 / 0.9) ** 3
    assert_close(expected_pooled_opinion(2, 3, 0.1), [1 / (1 + ratio), ratio / (1 + ratio)], 1e-15)
    # alpha = 0.5: evidence is worthless, the pool stays uniform.
    assert_close(expected_pooled_opinion(5, 3, 0.5), [0.2] * 5, 1e-12)
    # k = 1, alpha = 0: option i survives unless eliminated, then it shares 1/(n-1).
    n = 5
    p = evidence_probability(n)
    by_hand = [(1 - p[i]) / (n - 1) if i > 0 else 1 / (n - 1) for i in range(n)]
    assert_close(expected_pooled_opinion(n, 1, 0.0), by_hand, 1e-15)


def test_equation_3_refuses_enumerations_that_are_too_large() -> None:
    assert enumeration_terms(10, 5) == math.comb(13, 8)
    with pytest.raises(ValueError, match="sums 1287 terms"):
        expected_pooled_opinion(10, 5, 0.0, max_terms=1000)


def _monte_carlo_pool(n: int, k: int, alpha: float, samples: int, seed: int) -> list[list[float]]:
    """Samples of the pooled opinion after one round, built from the primitives."""
    rng = Stream(seed)
    results = []
    for _ in range(samples):
        updated = []
        for _agent in range(k):
            pair = choose_pair(uniform_opinion(n), rng)
            updated.append(negative_update(uniform_opinion(n), max(pair), alpha))
        pooled = mprodop(updated)
        assert pooled is not None
        results.append(pooled)
    return results


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("n", "k", "alpha"), [(5, 3, 0.0), (4, 4, 0.2), (6, 2, 0.1)])
def test_equation_3_and_4_match_monte_carlo(n: int, k: int, alpha: float) -> None:
    samples = _monte_carlo_pool(n, k, alpha, 6000, seed=n * 100 + k)
    exact = expected_pooled_opinion(n, k, alpha)
    for option in range(n):
        values = [sample[option] for sample in samples]
        mean = math.fsum(values) / len(values)
        spread = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1))
        standard_error = spread / math.sqrt(len(values))
        assert abs(mean - exact[option]) <= 4.5 * standard_error + 1e-12, option
