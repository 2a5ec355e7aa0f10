"""The decision math: Definitions 1 and 2, pair choice, decision test."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from opinion_helpers import assert_close, assert_distribution, normalise, working_alphas

from bestofn_swarm.wire.rng import Stream
from robot_agent.core.decision import (
    choose_pair,
    decided_option,
    mprodop,
    negative_update,
    uniform_opinion,
    validate_alpha,
    validate_opinion,
)

# --- strategies ------------------------------------------------------------------------

weights = st.floats(min_value=0.0, max_value=1e6, allow_nan=False, allow_infinity=False)
alphas = st.floats(min_value=0.0, max_value=0.5, allow_nan=False)


@st.composite
def opinions(draw: st.DrawFn, size: int | None = None) -> list[float]:
    """Non-negative weights with a positive sum (not necessarily normalised)."""
    n = size if size is not None else draw(st.integers(2, 12))
    values = draw(st.lists(weights, min_size=n, max_size=n))
    assume(max(values) > 0.0)
    return values


@st.composite
def opinion_with_option(draw: st.DrawFn) -> tuple[list[float], int]:
    values = draw(opinions())
    return values, draw(st.integers(0, len(values) - 1))


@st.composite
def pools(draw: st.DrawFn) -> list[list[float]]:
    n = draw(st.integers(2, 8))
    return draw(st.lists(opinions(n), min_size=1, max_size=6))


# --- validation ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("opinion", "message"),
    [
        ([0.5, float("nan")], r"opinion\[1\] is nan"),
        ([0.5, float("inf")], r"opinion\[1\] is inf"),
        ([0.5, -0.1, 0.6], r"opinion\[1\] is negative"),
        ([0.0, 0.0], "all zeros"),
        ([1.0], "at least 2 options"),
        ([], "at least 2 options"),
        ([True, 0.5], r"opinion\[0\] is True"),
        (["0.5", 0.5], r"opinion\[0\] is '0.5'"),
    ],
)
def test_bad_opinions_say_what_is_wrong(opinion: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        validate_opinion(opinion)
    with pytest.raises(ValueError, match=message):
        negative_update(opinion, 0, 0.0)
    with pytest.raises(ValueError, match=message):
        mprodop([opinion])
    with pytest.raises(ValueError, match=message):
        choose_pair(opinion, Stream(0))
    with pytest.raises(ValueError, match=message):
        decided_option(opinion)


def test_wrong_length_is_reported() -> None:
    with pytest.raises(ValueError, match="opinion has 3 entries, expected 2"):
        validate_opinion([0.2, 0.3, 0.5], 2)
    expected = "opinion 2 of the pool: opinion has 3 entries, expected 2"
    with pytest.raises(ValueError, match=expected):
        mprodop([[0.5, 0.5], [0.1, 0.9], [0.2, 0.3, 0.5]])


@pytest.mark.parametrize("alpha", [-0.01, 0.51, 1.0, float("nan"), float("inf"), "0.1", None, True])
def test_alpha_outside_the_range_is_rejected(alpha: Any) -> None:
    with pytest.raises(ValueError, match=r"alpha must be a number in \[0, 0.5\]"):
        validate_alpha(alpha)
    with pytest.raises(ValueError, match="alpha"):
        negative_update([0.5, 0.5], 0, alpha)


@pytest.mark.parametrize("eliminated", [-1, 3, 1.0, "1", None])
def test_eliminated_must_be_an_option_index(eliminated: Any) -> None:
    with pytest.raises(ValueError, match="option index"):
        negative_update([0.2, 0.3, 0.5], eliminated, 0.0)


@pytest.mark.parametrize("threshold", [0.0, -0.5, 1.01, float("nan"), "1"])
def test_threshold_outside_the_range_is_rejected(threshold: Any) -> None:
    with pytest.raises(ValueError, match=r"threshold must be a number in \(0, 1\]"):
        decided_option([0.5, 0.5], threshold)


def test_empty_pool_is_rejected() -> None:
    with pytest.raises(ValueError, match="at least one opinion"):
        mprodop([])


def test_uniform_opinion() -> None:
    assert uniform_opinion(4) == [0.25] * 4
    with pytest.raises(ValueError, match="at least 2 options"):
        uniform_opinion(1)


# --- Definition 1: negative updating ---------------------------------------------------


def test_update_with_reliable_evidence_eliminates_the_option() -> None:
    assert negative_update([0.25] * 4, 2, 0.0) == pytest.approx([1 / 3, 1 / 3, 0.0, 1 / 3])


def test_update_matches_definition_1() -> None:
    x, alpha = [0.1, 0.2, 0.3, 0.4], 0.2
    denominator = alpha * 0.3 + (1 - alpha) * 0.7
    expected = [(1 - alpha) * v / denominator for v in x]
    expected[2] = alpha * 0.3 / denominator
    assert_close(negative_update(x, 2, alpha), expected, 1e-15)


def test_update_with_worthless_evidence_changes_nothing() -> None:
    assert_close(negative_update([1.0, 2.0, 5.0], 1, 0.5), [0.125, 0.25, 0.625], 1e-15)


def test_contradicting_a_certain_opinion_keeps_it() -> None:
    # Bayes would divide by zero; the agent keeps its belief instead.
    assert negative_update([0.0, 1.0, 0.0], 1, 0.0) == [0.0, 1.0, 0.0]


def test_update_uses_the_rest_not_one_minus_x() -> None:
    # x_0 rounds to 1.0 in the sum, yet the evidence still moves all mass to option 1.
    assert negative_update([1.0, 1e-20], 0, 0.0) == [0.0, 1.0]


@given(opinion_with_option(), alphas)
def test_update_stays_a_distribution(case: tuple[list[float], int], alpha: float) -> None:
    opinion, eliminated = case
    assert_distribution(negative_update(opinion, eliminated, alpha))


@given(opinion_with_option(), alphas)
def test_update_never_raises_the_eliminated_option(
    case: tuple[list[float], int], alpha: float
) -> None:
    opinion, eliminated = case
    before = normalise(opinion)[eliminated]
    after = negative_update(opinion, eliminated, alpha)[eliminated]
    assert after <= before * (1 + 1e-12) + 1e-300


# --- Definition 2: MProdOp -------------------------------------------------------------


def test_product_matches_definition_2() -> None:
    assert_close(mprodop([[0.5, 0.5, 0.0], [0.2, 0.3, 0.5]]), [0.4, 0.6, 0.0], 1e-15)


def test_contradictory_pool_is_reported_as_none() -> None:
    assert mprodop([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) is None
    assert mprodop([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]]) is None


def test_product_of_tiny_probabilities_does_not_underflow() -> None:
    # The true product is (0, 1e-400, 0): tiny, but not a contradiction.
    assert mprodop([[1.0, 1e-200, 0.0], [0.0, 1e-200, 1.0]]) == [0.0, 1.0, 0.0]
    # Found by hypothesis: the smallest subnormal next to a weight of 2 (not normalised).
    assert mprodop([[0.0, 1.0], [2.0, 5e-324]]) == [0.0, 1.0]
    many = [[0.5, 1e-10, 0.5 - 1e-10]] * 200
    result = mprodop(many)
    assert result is not None
    assert result[0] == pytest.approx(1 / (1 + ((0.5 - 1e-10) / 0.5) ** 200), rel=1e-9)


def test_huge_weights_do_not_overflow() -> None:
    assert mprodop([[1e308, 1e308], [1e308, 3e307]]) == pytest.approx([1 / 1.3, 0.3 / 1.3])
    assert negative_update([1e308, 1e308, 1e308], 0, 0.0) == pytest.approx([0, 0.5, 0.5])


@given(pools())
def test_product_stays_a_distribution(pool: list[list[float]]) -> None:
    result = mprodop(pool)
    if result is None:
        # Reported only for a true contradiction: every option is zero in some opinion.
        assert all(0.0 in values for values in zip(*pool, strict=True))
    else:
        assert_distribution(result)


@given(pools(), st.randoms(use_true_random=False))
def test_pooling_is_commutative(pool: list[list[float]], rng: Stream) -> None:
    shuffled = list(pool)
    rng.shuffle(shuffled)
    first, second = mprodop(pool), mprodop(shuffled)
    assert (first is None) == (second is None)
    if first is not None and second is not None:
        assert_close(first, second, 1e-12)


@settings(max_examples=200)
@given(st.data(), working_alphas)
def test_pooling_preserves_evidence(data: st.DataObject, alpha: float) -> None:
    """Pooling updated opinions equals updating the pooled opinion (Section 3).

    The reference side applies the updates one after another to a normalised opinion,
    so an option hit twice by a subnormal alpha (hypothesis found 5e-324) underflows
    to zero there while the pooled side keeps it; ``working_alphas`` keeps every
    alpha ** 5 representable.
    """
    n = data.draw(st.integers(2, 8))
    # Bounded away from zero so the products stay representable and comparable.
    entry = st.floats(min_value=1e-3, max_value=1.0)
    pool = data.draw(st.lists(st.lists(entry, min_size=n, max_size=n), min_size=1, max_size=5))
    evidence = data.draw(st.lists(st.integers(0, n - 1), min_size=len(pool), max_size=len(pool)))
    updated = [negative_update(x, e, alpha) for x, e in zip(pool, evidence, strict=True)]
    pooled_after = mprodop(updated)
    assume(pooled_after is not None)  # with alpha = 0 the evidence can eliminate everything
    assert pooled_after is not None
    pooled_first = mprodop(pool)
    assert pooled_first is not None
    for eliminated in evidence:
        pooled_first = negative_update(pooled_first, eliminated, alpha)
    assert_close(pooled_after, pooled_first, 1e-9)


# --- pair choice and decisions ---------------------------------------------------------


@given(opinions(), st.randoms(use_true_random=False))
def test_pair_is_two_distinct_options_the_first_with_weight(
    opinion: list[float], rng: Stream
) -> None:
    first, second = choose_pair(opinion, rng)
    assert first != second
    assert 0 <= first < len(opinion) and 0 <= second < len(opinion)
    assert opinion[first] > 0.0
    if sum(1 for value in opinion if value > 0.0) >= 2:
        assert opinion[second] > 0.0


def test_pair_frequencies_follow_the_weights_without_replacement() -> None:
    weights = [0.5, 0.3, 0.2, 0.0]
    rng = Stream(7)
    draws = 60_000
    counts = Counter(choose_pair(weights, rng) for _ in range(draws))
    for (i, j), count in counts.items():
        p = weights[i] * weights[j] / (1 - weights[i])
        standard_error = math.sqrt(p * (1 - p) / draws)
        assert abs(count / draws - p) < 5 * standard_error, (i, j)
    assert set(counts) == {(i, j) for i in range(3) for j in range(3) if i != j}


def test_a_certain_opinion_pairs_its_option_with_a_uniform_other() -> None:
    rng = Stream(3)
    counts = Counter(choose_pair([0.0, 1.0, 0.0, 0.0], rng) for _ in range(3000))
    assert {pair[0] for pair in counts} == {1}
    assert set(counts) == {(1, 0), (1, 2), (1, 3)}
    assert min(counts.values()) > 850


def test_decided_option() -> None:
    assert decided_option([0.0, 1.0, 0.0]) == 1
    assert decided_option([0.1, 0.9]) is None
    assert decided_option([0.1, 0.9], 0.9) == 1
    assert decided_option([2.0, 8.0], 0.8) == 1  # normalised first
    assert decided_option([0.5, 0.5], 0.5) == 0  # a tie goes to the lower index
