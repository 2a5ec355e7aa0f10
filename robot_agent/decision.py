"""The decision math of the paper, in pure Python (no numpy: it runs on a robot).

* ``negative_update``: Definition 1, evidence E_i = "option i is not the best".
* ``mprodop``: Definition 2, the multi-option product operator.
* ``choose_pair``: a weighted choice of two distinct options without replacement.
* ``decided_option``: the decision test.

Options are 0-based indices into an opinion vector.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

__all__ = [
    "choose_pair",
    "decided_option",
    "mprodop",
    "negative_update",
    "uniform_opinion",
    "validate_alpha",
    "validate_opinion",
]


def validate_alpha(alpha: float) -> float:
    if not isinstance(alpha, (int, float)) or math.isnan(alpha) or not 0.0 <= alpha <= 0.5:
        raise ValueError(f"alpha must be in [0, 0.5], got {alpha!r}")
    return float(alpha)


def validate_opinion(opinion: Sequence[float], n: int | None = None) -> list[float]:
    """Return ``opinion`` as a list of floats, or raise ValueError saying what is wrong."""
    values = list(opinion)
    if n is not None and len(values) != n:
        raise ValueError(f"opinion has {len(values)} entries, expected {n}")
    if len(values) < 2:
        raise ValueError(f"an opinion needs at least 2 options, got {len(values)}")
    for index, value in enumerate(values):
        if not isinstance(value, (int, float)) or math.isnan(value) or math.isinf(value):
            raise ValueError(f"opinion[{index}] is {value!r}, not a finite number")
        if value < 0.0:
            raise ValueError(f"opinion[{index}] is negative ({value!r})")
    total = math.fsum(values)
    if total <= 0.0:
        raise ValueError("opinion sums to zero")
    return [float(value) for value in values]


def uniform_opinion(n: int) -> list[float]:
    if n < 2:
        raise ValueError(f"need at least 2 options, got {n}")
    return [1.0 / n] * n


def negative_update(opinion: Sequence[float], eliminated: int, alpha: float = 0.0) -> list[float]:
    """Definition 1: the posterior after learning that ``eliminated`` is not the best.

    With alpha = 0 the eliminated option drops to zero and the rest are rescaled; with
    alpha = 0.5 the evidence is worthless and the opinion is unchanged.
    """
    values = validate_opinion(opinion)
    alpha = validate_alpha(alpha)
    if not 0 <= eliminated < len(values):
        raise ValueError(f"eliminated option {eliminated} is outside 0..{len(values) - 1}")
    total = math.fsum(values)
    values = [value / total for value in values]
    x_i = values[eliminated]
    denominator = alpha * x_i + (1.0 - alpha) * (1.0 - x_i)
    if denominator <= 0.0:
        # Certain of the eliminated option and alpha = 0: the evidence contradicts the
        # opinion entirely, so there is nothing Bayesian to do; keep it.
        return values
    updated = [(1.0 - alpha) * value / denominator for value in values]
    updated[eliminated] = alpha * x_i / denominator
    return _normalised(updated)


def mprodop(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """Definition 2: the normalised Hadamard product of ``opinions``.

    Returns None when the product is all zeros (the opinions contradict each other,
    possible with alpha = 0); the caller then keeps its own opinion.
    """
    if not opinions:
        raise ValueError("mprodop needs at least one opinion")
    first = validate_opinion(opinions[0])
    product = [value / math.fsum(first) for value in first]
    for opinion in opinions[1:]:
        values = validate_opinion(opinion, len(product))
        total = math.fsum(values)
        product = [p * value / total for p, value in zip(product, values, strict=True)]
        # Rescale as we go so that long pools of small numbers do not underflow.
        peak = max(product)
        if peak == 0.0:
            return None
        product = [p / peak for p in product]
    return _normalised(product)


def choose_pair(opinion: Sequence[float], rng: random.Random) -> tuple[int, int]:
    """Two distinct options drawn without replacement, with probability = opinion.

    If fewer than two options have positive weight, the second is drawn uniformly from
    the zero-weight options, so a pair always exists.
    """
    values = validate_opinion(opinion)
    first = _weighted_index(values, rng)
    rest = list(values)
    rest[first] = 0.0
    if math.fsum(rest) > 0.0:
        second = _weighted_index(rest, rng)
    else:
        others = [index for index in range(len(values)) if index != first]
        second = others[rng.randrange(len(others))]
    return first, second


def decided_option(opinion: Sequence[float], threshold: float = 1.0) -> int | None:
    """The option whose probability is at least ``threshold`` (1 means certainty), or None."""
    if not 0.0 < threshold <= 1.0 or math.isnan(threshold):
        raise ValueError(f"threshold must be in (0, 1], got {threshold!r}")
    values = validate_opinion(opinion)
    total = math.fsum(values)
    best = max(range(len(values)), key=values.__getitem__)
    return best if values[best] / total >= threshold else None


def _weighted_index(weights: Sequence[float], rng: random.Random) -> int:
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
    return last_positive


def _normalised(values: Sequence[float]) -> list[float]:
    total = math.fsum(values)
    return [value / total for value in values]
