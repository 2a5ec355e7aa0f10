"""Equations (1) to (4) of the paper's Section 3: the pooled opinion of k agents with
uniform priors after one comparison each, and its exact expectation.

No robot uses these: they are the analysis behind the Section 4 model (``model.py``)
and are tested against it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

from robot_agent.core.decision import as_count, normalised, validate_alpha

__all__ = [
    "MAX_ENUMERATION_TERMS",
    "enumeration_terms",
    "evidence_probability",
    "expected_pooled_opinion",
    "pooled_opinion",
    "pooled_opinion_alpha0",
]

# Equation (3) sums over every way k pieces of evidence can fall on options 2..n:
# C(k + n - 2, n - 2) terms. Beyond this many the enumeration takes minutes in Python.
MAX_ENUMERATION_TERMS = 2_000_000


def evidence_probability(n: int) -> list[float]:
    """P(E_i) for an agent with a uniform opinion: 2(i-1) / (n(n-1)), i = 1..n.

    A uniformly random pair of distinct options eliminates option i when the other
    option of the pair is better, i.e. one of the i - 1 options before it.
    """
    n = as_count(n, "number of options")
    if n < 2:
        raise ValueError(f"need at least 2 options, got {n}")
    return [2.0 * (i - 1) / (n * (n - 1)) for i in range(1, n + 1)]


def pooled_opinion(evidence_counts: Sequence[int], alpha: float) -> list[float]:
    """Equation (1): the pool's opinion when m_i of its members learnt E_i.

    ``evidence_counts`` holds m_1..m_n; the pool size k is their sum. Each member starts
    uniform, so option i keeps alpha^(m_i) (1 - alpha)^(k - m_i) before normalising.
    With alpha = 0, see ``pooled_opinion_alpha0``.
    """
    counts = _evidence_counts(evidence_counts)
    alpha = validate_alpha(alpha)
    if alpha == 0.0:
        return pooled_opinion_alpha0(counts)
    # Divide every weight by (1 - alpha)^k: option i keeps (alpha / (1 - alpha))^(m_i).
    ratio = alpha / (1.0 - alpha)
    return normalised([ratio**m for m in counts])


def pooled_opinion_alpha0(evidence_counts: Sequence[int]) -> list[float]:
    """Equation (4): with alpha = 0, an option any member eliminated is gone, and the
    pool is uniform over the options nobody eliminated.

    If every option was eliminated (impossible when option 1 is the best, since the best
    is never the worse of a pair), there is no pooled opinion: ValueError.
    """
    counts = _evidence_counts(evidence_counts)
    survivors = sum(1 for m in counts if m == 0)
    if survivors == 0:
        raise ValueError("every option was eliminated: the pooled opinion is all zeros")
    return [1.0 / survivors if m == 0 else 0.0 for m in counts]


def enumeration_terms(n: int, k: int) -> int:
    """How many evidence vectors Equation (3) sums over: C(k + n - 2, n - 2)."""
    return math.comb(k + n - 2, n - 2)


def expected_pooled_opinion(
    n: int, k: int, alpha: float, *, max_terms: int = MAX_ENUMERATION_TERMS
) -> list[float]:
    """Equation (3): the exact expected pooled opinion of k agents after one round.

    Each agent starts uniform, compares a uniformly random pair of distinct options and
    updates on the worse; the pool is combined with MProdOp. The expectation is summed
    over every evidence vector m (m_1 = 0, sum m_i = k) weighted by its multinomial
    probability (Equation 2). With alpha = 0 each term is Equation (4). Raises
    ValueError if that needs more than ``max_terms`` terms.
    """
    n = as_count(n, "number of options")
    k = as_count(k, "pool size")
    if n < 2:
        raise ValueError(f"need at least 2 options, got {n}")
    if k < 1:
        raise ValueError(f"pool size must be at least 1, got {k}")
    alpha = validate_alpha(alpha)
    terms = enumeration_terms(n, k)
    if terms > max_terms:
        raise ValueError(
            f"Equation (3) for n={n}, k={k} sums {terms} terms, more than max_terms={max_terms}"
        )
    expected = [0.0] * n
    for counts, probability in _evidence_vectors(n, k):
        pooled = pooled_opinion(counts, alpha)
        for index, value in enumerate(pooled):
            expected[index] += probability * value
    return expected


def _evidence_vectors(n: int, k: int) -> Iterator[tuple[list[int], float]]:
    """Every evidence vector (m_1 = 0, m_2..m_n summing to k) with its probability.

    Equation (2) in exact integer arithmetic: with P(E_i) = 2(i-1) / (n(n-1)) the
    probability is prod_i C(r_i, m_i) (2(i-1))^(m_i) / (n(n-1))^k, where r_i is the
    evidence not yet placed; one correctly rounded division per vector.
    """
    counts = [0] * n
    denominator = (n * (n - 1)) ** k

    def place(index: int, remaining: int, weight: int) -> Iterator[tuple[list[int], float]]:
        if index == n - 1:
            counts[index] = remaining
            yield counts, weight * (2 * index) ** remaining / denominator
            return
        for m in range(remaining + 1):
            counts[index] = m
            yield from place(
                index + 1, remaining - m, weight * math.comb(remaining, m) * (2 * index) ** m
            )
        counts[index] = 0

    # Option 1 (index 0) is the best: never the worse of a pair, so m_1 = 0.
    yield from place(1, k, 1)


def _evidence_counts(evidence_counts: Sequence[int]) -> list[int]:
    counts = [as_count(m, "evidence count") for m in evidence_counts]
    if len(counts) < 2:
        raise ValueError(f"need evidence counts for at least 2 options, got {len(counts)}")
    negative = [index for index, m in enumerate(counts) if m < 0]
    if negative:
        raise ValueError(f"evidence count {negative[0]} is negative ({counts[negative[0]]})")
    return counts
