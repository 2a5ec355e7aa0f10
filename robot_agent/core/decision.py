"""The decision math of the paper, in pure Python (no numpy: it runs on a robot).

* ``negative_update``: Definition 1, evidence E_i = "option i is not the best".
* ``mprodop``: Definition 2, the multi-option product operator.
* ``loglinear_pool``: a diluting alternative to MProdOp (the paper's future work): a
  weighted log-linear pool that trusts the pooling agent's own opinion fully and each
  neighbour's only with ``neighbour_weight`` < 1. ``POOLING_OPERATORS`` names both.
* ``choose_pair``: a weighted choice of two distinct options without replacement.
* ``decided_option``: the decision test.

Options are 0-based indices into an opinion vector; option 0 is the paper's option 1
(the best). An opinion may be given unnormalised (any non-negative weights with a
positive sum); every result is normalised.
"""

from __future__ import annotations

import math
import numbers
import operator
from collections.abc import Callable, Sequence
from typing import Literal, SupportsIndex

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.rng import Stream

__all__ = [
    "LOGLINEAR_NEIGHBOUR_WEIGHT",
    "POOLING_OPERATORS",
    "PoolingName",
    "PoolingOperator",
    "as_count",
    "choose_pair",
    "decided_option",
    "loglinear_pool",
    "mprodop",
    "negative_update",
    "normalised",
    "uniform_opinion",
    "validate_alpha",
    "validate_opinion",
]


def _is_real(value: object) -> bool:
    # bool is an int subclass, but True is no probability.
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def validate_alpha(alpha: float) -> float:
    """``alpha`` as a float, or ValueError unless it is a number in [0, 0.5]."""
    if not _is_real(alpha) or math.isnan(alpha) or not 0.0 <= alpha <= 0.5:
        raise ValueError(f"alpha must be a number in [0, 0.5], got {alpha!r}")
    return float(alpha)


def validate_opinion(opinion: Sequence[float], n: int | None = None) -> list[float]:
    """Return ``opinion`` as a list of floats, or raise ValueError saying what is wrong.

    Checks: ``n`` entries when ``n`` is given, at least 2 entries, every entry a finite
    non-negative number, and a positive sum.
    """
    values = list(opinion)
    if n is not None and len(values) != n:
        raise ValueError(f"opinion has {len(values)} entries, expected {n}")
    if len(values) < 2:
        raise ValueError(f"an opinion needs at least 2 options, got {len(values)}")
    for index, value in enumerate(values):
        if not _is_real(value) or not math.isfinite(value):
            raise ValueError(f"opinion[{index}] is {value!r}, not a finite number")
        if value < 0.0:
            raise ValueError(f"opinion[{index}] is negative ({value!r})")
    if max(values) <= 0.0:
        raise ValueError("opinion is all zeros: it gives no probability to any option")
    return [float(value) for value in values]


def uniform_opinion(n: int) -> list[float]:
    """The uninformed prior over ``n`` options."""
    n = as_count(n, "number of options")
    if n < 2:
        raise ValueError(f"need at least 2 options, got {n}")
    return [1.0 / n] * n


def negative_update(opinion: Sequence[float], eliminated: int, alpha: float = 0.0) -> list[float]:
    """Definition 1: the posterior after learning that ``eliminated`` is not the best.

    With alpha = 0 the eliminated option drops to zero and the rest are rescaled; with
    alpha = 0.5 the evidence is worthless and the opinion is unchanged. If the opinion
    is already certain of ``eliminated`` and alpha = 0, the evidence contradicts it
    entirely and Bayes' rule would divide by zero: the opinion is returned unchanged
    (normalised), so an agent keeps its own belief, as with an all-zero pool.
    """
    values = normalised(validate_opinion(opinion))
    alpha = validate_alpha(alpha)
    eliminated = _option_index(eliminated, len(values))
    x_eliminated = values[eliminated]
    # 1 - x_i from the other entries, so that x_i = 1 - 1e-17 still leaves a posterior.
    x_rest = math.fsum(values[:eliminated] + values[eliminated + 1 :])
    denominator = alpha * x_eliminated + (1.0 - alpha) * x_rest
    if denominator <= 0.0:
        return values
    updated = [(1.0 - alpha) * value / denominator for value in values]
    updated[eliminated] = alpha * x_eliminated / denominator
    return normalised(updated)


def mprodop(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """Definition 2: the normalised Hadamard product of ``opinions``.

    Returns None when the product is all zeros (the opinions contradict each other,
    possible with alpha = 0); the caller then keeps its own opinion. Every opinion must
    have the same number of entries as the first. The product is kept as mantissa and
    exponent per option, so pooling many small probabilities never underflows to a
    false contradiction.
    """
    pool = _validated_pool(opinions, "mprodop")
    size = len(pool[0])
    mantissas = [1.0] * size
    exponents = [0] * size
    for values in pool:
        for index, value in enumerate(values):
            # Not scaled by the opinion's peak first: 5e-324 / 2.0 underflows to zero.
            value_mantissa, value_exponent = math.frexp(value)
            mantissa, exponent = math.frexp(mantissas[index] * value_mantissa)
            mantissas[index] = mantissa
            exponents[index] += value_exponent + exponent
    alive = [index for index in range(size) if mantissas[index] > 0.0]
    if not alive:
        return None
    top = max(exponents[index] for index in alive)
    product = [
        math.ldexp(mantissas[index], exponents[index] - top) if mantissas[index] > 0.0 else 0.0
        for index in range(size)
    ]
    return normalised(product)


# How far a robot trusts each neighbour's opinion in ``loglinear_pool``: half way between
# ignoring it (0) and MProdOp (1). Chosen a priori, not tuned; see docs/robustness.md.
LOGLINEAR_NEIGHBOUR_WEIGHT = 0.5


def loglinear_pool(
    opinions: Sequence[Sequence[float]], neighbour_weight: float = LOGLINEAR_NEIGHBOUR_WEIGHT
) -> list[float] | None:
    """A diluting pool: the weighted log-linear (logarithmic) opinion pool

        c(x_1, ..., x_k)_i  proportional to  x_1i * (x_2i * ... * x_ki) ** neighbour_weight

    where ``opinions[0]`` = x_1 is the pooling agent's own opinion (weight 1) and the rest
    are its neighbours' (weight ``neighbour_weight`` each, in [0, 1]).

    The log-linear pool with weights w_r, prod_r x_r ** w_r normalised, is one of the two
    classical pooling families (the other is the linear pool of Stone 1961); see Genest &
    Zidek, "Combining probability distributions: a critique and an annotated
    bibliography", Statistical Science 1(1), 1986, and Dietrich & List, "Probabilistic
    opinion pooling", Oxford Handbook of Probability and Philosophy, 2016. All weights 1
    is the product, MProdOp (Definition 2); weights summing to 1 is geometric pooling.

    Evidence (the paper's terms, after Lee, Lawry & Winfield, IJCAI 2018): MProdOp
    *preserves* evidence, c(x_1, ..., x_r | E, ..., x_k) = c(x_1, ..., x_k) | E, so an
    opinion that comes back through repeated poolings is counted again each time. Here a
    neighbour's evidence is *diluted*: its likelihood ratio enters raised to
    ``neighbour_weight``, while the agent's own evidence is kept whole. With
    ``neighbour_weight`` = 1 this is MProdOp exactly, and with 0 the neighbours are ignored.

    Zeros stay zeros (0 ** w = 0 for w > 0): with alpha = 0 every opinion is uniform over
    the options it has not eliminated, and for any ``neighbour_weight`` > 0 this pool then
    gives exactly MProdOp's result. Distrust needs alpha > 0 as well. Symmetric in the
    neighbours, not in the agent.

    Why this one (docs/robustness.md): the linear pool and geometric pooling average
    instead of accumulating evidence, and under camera noise our swarm did not decide
    with them within 1800 s. With alpha = 0.1 this pool decided as accurately as MProdOp
    with alpha = 0.1 (and far better than the paper's alpha = 0), but not better.

    Returns None when every option is zero in some weighted opinion (a contradiction, as
    in ``mprodop``); the caller then keeps its own opinion. Validation as in ``mprodop``.
    """
    if (
        not _is_real(neighbour_weight)
        or math.isnan(neighbour_weight)
        or not 0.0 <= neighbour_weight <= 1.0
    ):
        raise ValueError(f"neighbour_weight must be a number in [0, 1], got {neighbour_weight!r}")
    pool = _validated_pool(opinions, "loglinear_pool")
    weights = [1.0] + [float(neighbour_weight)] * (len(pool) - 1)
    # Sums of logarithms: products of many small probabilities neither underflow nor
    # overflow. Each opinion is scaled by its peak, which normalisation cancels.
    terms = [
        (weight, values, numeric.log(max(values)))
        for weight, values in zip(weights, pool, strict=True)
        if weight > 0.0  # a weight of 0 ignores the opinion entirely, zeros included
    ]
    logs: list[float] = []
    for index in range(len(pool[0])):
        total = 0.0
        for weight, values, log_peak in terms:
            if values[index] == 0.0:
                total = -math.inf
                break
            total += weight * (numeric.log(values[index]) - log_peak)
        logs.append(total)
    top = max(logs)
    if top == -math.inf:
        return None
    return normalised([numeric.exp(value - top) for value in logs])


PoolingName = Literal["mprodop", "loglinear"]
PoolingOperator = Callable[[Sequence[Sequence[float]]], list[float] | None]
"""A pooling operator: the pool's opinions (the pooling robot's own first, then its
neighbours', each as long as the first) to the pooled opinion, or None when they contradict
each other (the robot then keeps its own). A plug-in of the group ``bestofn_swarm.pooling``
(docs/extending.md)."""
POOLING_OPERATORS: dict[str, PoolingOperator] = {
    "mprodop": mprodop,
    "loglinear": loglinear_pool,
}
"""The built-in pooling operators, by name (their plug-in names); the first element of a
pool is the pooling agent's own opinion."""


def choose_pair(opinion: Sequence[float], rng: Stream) -> tuple[int, int]:
    """Two distinct options drawn without replacement, with probability = opinion.

    If fewer than two options have positive weight, the second is drawn uniformly from
    the zero-weight options, so a pair always exists.
    """
    values = normalised(validate_opinion(opinion))
    first = _weighted_index(values, rng)
    rest = list(values)
    rest[first] = 0.0
    if max(rest) > 0.0:
        second = _weighted_index(rest, rng)
    else:
        others = [index for index in range(len(values)) if index != first]
        second = others[rng.randrange(len(others))]
    return first, second


def decided_option(opinion: Sequence[float], threshold: float = 1.0) -> int | None:
    """The option whose probability is at least ``threshold`` (1 means certainty), or None.

    With a threshold of 0.5 or less two options can both pass; the lower index wins.
    """
    if not _is_real(threshold) or math.isnan(threshold) or not 0.0 < threshold <= 1.0:
        raise ValueError(f"threshold must be a number in (0, 1], got {threshold!r}")
    values = normalised(validate_opinion(opinion))
    best = max(range(len(values)), key=values.__getitem__)
    return best if values[best] >= threshold else None


# --- helpers -------------------------------------------------------------------------------


def as_count(value: object, what: str) -> int:
    """``value`` as an int (ValueError naming ``what`` unless it is an integer, not a bool)."""
    if isinstance(value, bool) or not isinstance(value, SupportsIndex):
        raise ValueError(f"{what} must be an integer, got {value!r}")
    try:
        return operator.index(value)
    except TypeError:  # an __index__ that does not return an int
        raise ValueError(f"{what} must be an integer, got {value!r}") from None


def _option_index(value: object, size: int) -> int:
    index = as_count(value, "option index")
    if not 0 <= index < size:
        raise ValueError(f"option index {index} is outside 0..{size - 1}")
    return index


def _validated_pool(opinions: Sequence[Sequence[float]], operator: str) -> list[list[float]]:
    """The opinions of a pool as lists of floats, all as long as the first; ValueError
    saying which opinion is wrong otherwise."""
    if not opinions:
        raise ValueError(f"{operator} needs at least one opinion")
    pool: list[list[float]] = []
    for position, opinion in enumerate(opinions):
        try:
            pool.append(validate_opinion(opinion, len(pool[0]) if pool else None))
        except ValueError as error:
            raise ValueError(f"opinion {position} of the pool: {error}") from None
    return pool


def _weighted_index(weights: Sequence[float], rng: Stream) -> int:
    total = math.fsum(weights)
    target = rng.random() * total
    running = 0.0
    last_positive = 0
    for index, weight in enumerate(weights):
        if weight > 0.0:
            running += weight
            last_positive = index
            if target < running:
                return index
    # Rounding can leave target at the very top of the range: the last positive wins.
    return last_positive


def normalised(values: Sequence[float]) -> list[float]:
    """``values`` divided by their sum (a normalised opinion comes back unchanged)."""
    try:
        total = math.fsum(values)
    except OverflowError:
        total = math.inf
    if math.isinf(total):
        # Weights near the float maximum: scale by the peak so the sum fits.
        peak = max(values)
        values = [value / peak for value in values]
        total = math.fsum(values)
    return [value / total for value in values]
