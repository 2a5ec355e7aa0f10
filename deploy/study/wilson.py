"""The Wilson score interval of a share of runs: what a count can and cannot say.

7 correct runs of 10 is a share of 70%, but the swarm's true rate could be anything from
about 40% to 89% (95% interval): ten runs cannot tell 70% from 50% or from 85%. The
Wilson interval (Wilson, "Probable inference, the law of succession, and statistical
inference", JASA 22, 1927) stays inside [0, 1] and is sound at 0 and n successes, where
the textbook normal interval collapses to a point.
"""

from __future__ import annotations

import math

Z95 = 1.959963984540054  # the two-sided 95% quantile of the normal distribution


def wilson(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """The interval (low, high) for ``successes`` of ``trials``; (0, 1) for no trials."""
    if trials < 0 or not 0 <= successes <= trials:
        raise ValueError(f"{successes} successes of {trials} trials")
    if trials == 0:
        return 0.0, 1.0
    share = successes / trials
    spread = z * z / trials
    centre = (share + spread / 2) / (1 + spread)
    half = z * math.sqrt(share * (1 - share) / trials + spread / (4 * trials)) / (1 + spread)
    low, high = max(0.0, centre - half), min(1.0, centre + half)
    # At 0 and at every trial the bound is exact; keep rounding from moving it.
    return (0.0 if successes == 0 else low), (1.0 if successes == trials else high)


def interval(successes: int, trials: int) -> str:
    """``40-89%``: the 95% Wilson interval in whole percent, low rounded down and high up."""
    low, high = wilson(successes, trials)
    return f"{math.floor(low * 100 + 1e-9)}-{math.ceil(high * 100 - 1e-9)}%"


def share(successes: int, trials: int) -> str:
    """``7/10 (40-89%)``: a count of runs and its 95% interval; ``-`` for no runs."""
    if trials == 0:
        return "-"
    return f"{successes}/{trials} ({interval(successes, trials)})"
