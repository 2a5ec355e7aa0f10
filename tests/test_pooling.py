"""The diluting pooling operator (``loglinear_pool``) against MProdOp (Definition 2)."""

from __future__ import annotations

import math
import random
import typing
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from robot_agent.core.decision import (
    LOGLINEAR_NEIGHBOUR_WEIGHT,
    POOLING_OPERATORS,
    PoolingName,
    loglinear_pool,
    mprodop,
    negative_update,
)

weights = st.floats(min_value=0.0, max_value=1e6, allow_nan=False, allow_infinity=False)
neighbour_weights = st.floats(min_value=0.0, max_value=1.0)
# Entries bounded away from zero, so that products stay representable and comparable.
positive_entries = st.floats(min_value=1e-3, max_value=1.0)
# Alphas that are real distrust: 0 < alpha < 0.5, far enough from both ends to measure.
distrust_alphas = st.floats(min_value=0.01, max_value=0.45)


@st.composite
def pools(draw: st.DrawFn, entries: st.SearchStrategy[float] = weights) -> list[list[float]]:
    """1 to 6 opinions over the same 2 to 8 options; non-negative, each with a positive sum."""
    n = draw(st.integers(2, 8))
    pool = draw(st.lists(st.lists(entries, min_size=n, max_size=n), min_size=1, max_size=6))
    assume(all(max(opinion) > 0.0 for opinion in pool))
    return pool


def assert_close(
    actual: list[float] | None, expected: list[float], tolerance: float = 1e-9
) -> None:
    assert actual is not None
    assert len(actual) == len(expected)
    for a, b in zip(actual, expected, strict=True):
        assert a == pytest.approx(b, abs=tolerance)


def diluted_alpha(alpha: float, weight: float) -> float:
    """The alpha of Definition 1 whose evidence is that of ``alpha`` raised to ``weight``.

    Definition 1 scales the eliminated option by alpha and the rest by 1 - alpha; raised
    to ``weight`` the odds alpha / (1 - alpha) become (alpha / (1 - alpha)) ** weight.
    """
    odds = (alpha / (1.0 - alpha)) ** weight
    return odds / (1.0 + odds)


# --- definition and validation ---------------------------------------------------------


def test_matches_the_weighted_log_linear_formula() -> None:
    # Own [0.5, 0.5], neighbour [0.2, 0.8] at weight 1/2: [0.5 sqrt(0.2), 0.5 sqrt(0.8)].
    assert_close(loglinear_pool([[0.5, 0.5], [0.2, 0.8]], 0.5), [1 / 3, 2 / 3], 1e-12)
    # Two neighbours at weight 1/2 count as one at weight 1.
    own, other = [0.1, 0.3, 0.6], [0.5, 0.25, 0.25]
    assert_close(loglinear_pool([own, other, other], 0.5), mprodop([own, other]) or [], 1e-12)


def test_the_default_weight_dilutes() -> None:
    assert 0.0 < LOGLINEAR_NEIGHBOUR_WEIGHT < 1.0
    assert loglinear_pool([[0.5, 0.5], [0.2, 0.8]]) == loglinear_pool(
        [[0.5, 0.5], [0.2, 0.8]], LOGLINEAR_NEIGHBOUR_WEIGHT
    )


@pytest.mark.parametrize("weight", [-0.1, 1.5, math.nan, math.inf, True, "0.5", None])
def test_neighbour_weight_outside_0_1_is_rejected(weight: Any) -> None:
    with pytest.raises(ValueError, match="neighbour_weight"):
        loglinear_pool([[0.5, 0.5], [0.2, 0.8]], weight)


@pytest.mark.parametrize(
    ("pool", "message"),
    [
        ([], "at least one opinion"),
        ([[0.5, 0.5], [0.2, 0.3, 0.5]], r"opinion 1 of the pool: opinion has 3 entries"),
        ([[0.5, math.nan]], r"opinion 0 of the pool: opinion\[1\] is nan"),
        ([[0.5, 0.5], [0.5, -0.1]], r"opinion 1 of the pool: opinion\[1\] is negative"),
        ([[0.0, 0.0]], "all zeros"),
        ([[1.0]], "at least 2 options"),
    ],
)
def test_bad_pools_say_what_is_wrong(pool: list[list[float]], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        loglinear_pool(pool)


def test_contradictory_pool_is_reported_as_none() -> None:
    assert loglinear_pool([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) is None
    # An ignored neighbour (weight 0) contradicts nothing.
    assert loglinear_pool([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 0.0) == [1.0, 0.0, 0.0]


def test_tiny_and_huge_weights_neither_underflow_nor_overflow() -> None:
    assert loglinear_pool([[1.0, 1e-200, 0.0], [0.0, 1e-200, 1.0]]) == [0.0, 1.0, 0.0]
    assert loglinear_pool([[5e-324, 1.0], [1.0, 1.0]]) == [5e-324, 1.0]
    assert loglinear_pool([[1e308, 1e308], [1e308, 3e307]], 1.0) == pytest.approx(
        [1 / 1.3, 0.3 / 1.3]
    )
    many = [[0.5, 1e-10, 0.5 - 1e-10]] * 200
    result = loglinear_pool(many, 1.0)
    assert result is not None
    assert result[0] == pytest.approx(1 / (1 + ((0.5 - 1e-10) / 0.5) ** 200), rel=1e-9)


def test_pooling_operators_are_named_by_the_config_literal() -> None:
    assert list(POOLING_OPERATORS) == list(typing.get_args(PoolingName))
    assert POOLING_OPERATORS["mprodop"] is mprodop
    assert POOLING_OPERATORS["loglinear"] is loglinear_pool


# --- properties ------------------------------------------------------------------------


@given(pools(), neighbour_weights)
def test_result_is_normalised_and_non_negative(pool: list[list[float]], weight: float) -> None:
    result = loglinear_pool(pool, weight)
    counted = pool if weight > 0.0 else pool[:1]
    if result is None:
        # Only for a true contradiction: every option is zero in some counted opinion.
        assert all(0.0 in values for values in zip(*counted, strict=True))
    else:
        assert all(value >= 0.0 for value in result)
        assert math.fsum(result) == pytest.approx(1.0, abs=1e-12)
        # An option that some counted opinion rules out stays ruled out.
        for index, value in enumerate(result):
            if any(opinion[index] == 0.0 for opinion in counted):
                assert value == 0.0


@given(pools(), neighbour_weights, st.randoms(use_true_random=False))
def test_commutative_in_the_neighbours(
    pool: list[list[float]], weight: float, rng: random.Random
) -> None:
    own, neighbours = pool[0], pool[1:]
    shuffled = list(neighbours)
    rng.shuffle(shuffled)
    first, second = (
        loglinear_pool([own, *neighbours], weight),
        loglinear_pool([own, *shuffled], weight),
    )
    assert (first is None) == (second is None)
    if first is not None and second is not None:
        assert_close(first, second, 1e-12)


def test_not_commutative_between_the_agent_and_a_neighbour() -> None:
    # The agent trusts its own opinion more than a neighbour's: swapping them matters.
    mine, theirs = [0.8, 0.2], [0.2, 0.8]
    trusting_mine, trusting_theirs = loglinear_pool([mine, theirs]), loglinear_pool([theirs, mine])
    assert trusting_mine is not None and trusting_theirs is not None
    assert trusting_mine[0] > 0.5 > trusting_theirs[0]


@given(pools(positive_entries))
def test_full_trust_is_mprodop(pool: list[list[float]]) -> None:
    assert_close(loglinear_pool(pool, 1.0) or [], mprodop(pool) or [], 1e-9)


@given(pools())
def test_no_trust_keeps_the_own_opinion(pool: list[list[float]]) -> None:
    own = pool[0]
    total = math.fsum(own)
    assert_close(loglinear_pool(pool, 0.0) or [], [value / total for value in own], 1e-12)


@given(pools(positive_entries), neighbour_weights)
def test_a_single_opinion_is_returned_normalised(pool: list[list[float]], weight: float) -> None:
    own = pool[0]
    total = math.fsum(own)
    assert_close(loglinear_pool([own], weight) or [], [value / total for value in own], 1e-12)


@settings(max_examples=200)
@given(st.data(), st.floats(min_value=1e-3, max_value=1.0))
def test_at_alpha_zero_it_is_mprodop(data: st.DataObject, weight: float) -> None:
    """With alpha = 0 every opinion is uniform over what it has not eliminated: with any
    positive weight the same pool as MProdOp, so dilution cannot undo an elimination."""
    n = data.draw(st.integers(2, 8))
    supports = data.draw(
        st.lists(
            st.lists(st.booleans(), min_size=n, max_size=n).filter(any), min_size=2, max_size=6
        )
    )
    pool = [[1.0 / sum(support) if kept else 0.0 for kept in support] for support in supports]
    diluted, product = loglinear_pool(pool, weight), mprodop(pool)
    assert (diluted is None) == (product is None)
    if diluted is not None and product is not None:
        assert_close(diluted, product, 1e-12)


# --- evidence: MProdOp preserves it, the log-linear pool dilutes a neighbour's --------


@settings(max_examples=200)
@given(st.data(), distrust_alphas, st.floats(min_value=0.1, max_value=0.9))
def test_a_neighbours_evidence_is_diluted_where_mprodop_preserves_it(
    data: st.DataObject, alpha: float, weight: float
) -> None:
    n = data.draw(st.integers(2, 8))
    opinion = st.lists(positive_entries, min_size=n, max_size=n)
    own, neighbour = data.draw(opinion), data.draw(opinion)
    eliminated = data.draw(st.integers(0, n - 1))
    informed = negative_update(neighbour, eliminated, alpha)  # the neighbour learnt E

    # MProdOp: pooling after the update = updating the pool (evidence preserving).
    product_after = mprodop([own, informed])
    product_first = mprodop([own, neighbour])
    assert product_after is not None and product_first is not None
    assert_close(product_after, negative_update(product_first, eliminated, alpha))

    # Log-linear pool: the same evidence arrives with the odds alpha/(1-alpha) raised to
    # the weight, i.e. as the weaker evidence of a larger alpha.
    diluted_after = loglinear_pool([own, informed], weight)
    diluted_first = loglinear_pool([own, neighbour], weight)
    assert diluted_after is not None and diluted_first is not None
    weaker = diluted_alpha(alpha, weight)
    assert alpha < weaker < 0.5
    assert_close(diluted_after, negative_update(diluted_first, eliminated, weaker))
    # So not evidence preserving: the eliminated option keeps more than E alone leaves it.
    preserved = negative_update(diluted_first, eliminated, alpha)
    assert diluted_after[eliminated] > preserved[eliminated]


@settings(max_examples=200)
@given(st.data(), distrust_alphas, neighbour_weights)
def test_the_agents_own_evidence_is_kept_whole(
    data: st.DataObject, alpha: float, weight: float
) -> None:
    n = data.draw(st.integers(2, 8))
    opinion = st.lists(positive_entries, min_size=n, max_size=n)
    pool = data.draw(st.lists(opinion, min_size=1, max_size=5))
    eliminated = data.draw(st.integers(0, n - 1))
    after = loglinear_pool([negative_update(pool[0], eliminated, alpha), *pool[1:]], weight)
    first = loglinear_pool(pool, weight)
    assert after is not None and first is not None
    assert_close(after, negative_update(first, eliminated, alpha))


def test_repeated_pooling_of_the_same_evidence_is_bounded_by_dilution() -> None:
    """Two robots that keep pooling each other's opinions: MProdOp counts one piece of
    evidence again every round (echo), the diluting pool by a factor 1 + w per round."""
    alpha = 0.1
    start = negative_update([0.5, 0.5], 1, alpha)  # robot A learnt "option 1 is not best"
    odds_of_evidence = (1 - alpha) / alpha
    for pool, growth in ((mprodop, 2.0), (loglinear_pool, 1.0 + LOGLINEAR_NEIGHBOUR_WEIGHT)):
        a, b = start, [0.5, 0.5]
        for _ in range(3):
            pooled_a, pooled_b = pool([a, b]), pool([b, a])
            assert pooled_a is not None and pooled_b is not None
            a, b = pooled_a, pooled_b
        # The odds in favour of option 0, as a power of the evidence's odds.
        exponent = math.log(a[0] / a[1]) / math.log(odds_of_evidence)
        # Linear recurrence (a, b) -> (a + w b, b + w a): the sum grows by 1 + w a round.
        assert exponent + math.log(b[0] / b[1]) / math.log(odds_of_evidence) == pytest.approx(
            growth**3, rel=1e-9
        )
