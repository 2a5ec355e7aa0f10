"""The Wilson score interval of a share of runs: what a count can and cannot say.

7 correct runs of 10 is a share of 70%, but the swarm's true rate could be anything from
39.7% to 89.2% (95% interval): ten runs cannot tell 70% from 50% or from 85%. The
Wilson interval (Wilson, "Probable inference, the law of succession, and statistical
inference", JASA 22, 1927) stays inside [0, 1] and is sound at 0 and n successes, where
the textbook normal interval collapses to a point.

>>> share(7, 10)
'7/10 (39-90%)'

Printed bounds are rounded outwards (the printed interval holds the exact one), to whole
percent, or to as many decimals as it takes to keep a bound off 0% or 100% when the
interval excludes them: 99 runs of 100 cannot say the rate is 100%.

>>> share(99, 100)
'99/100 (94-99.9%)'
>>> share(1, 100)
'1/100 (0.1-6%)'
"""

from __future__ import annotations

import math

Z95 = 1.959963984540054  # the two-sided 95% quantile of the normal distribution
MOST_DIGITS = 6  # decimals of a percent, at most (n of n + 1 keeps a bound off 100% to 6)


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


def percent_bound(value: float, *, upper: bool) -> str:
    """A bound of an interval of shares (0..1) in percent, rounded outwards: to whole
    percent, or to more decimals where rounding would reach 0% or 100% that the bound
    itself does not (``99.9``, ``0.1``).

    >>> percent_bound(0.99823, upper=True), percent_bound(0.00177, upper=False)
    ('99.9', '0.1')
    >>> percent_bound(1.0, upper=True), percent_bound(0.0, upper=False)
    ('100', '0')
    """
    percent = value * 100
    for digits in range(MOST_DIGITS + 1):
        scale = 10**digits
        if upper:  # the 1e-9 keeps float noise at a whole bound from moving it outwards
            rounded = math.ceil(percent * scale - 1e-9) / scale
            if rounded < 100 or percent >= 100:
                return f"{rounded:.{digits}f}"
        else:
            rounded = math.floor(percent * scale + 1e-9) / scale
            if rounded > 0 or percent <= 0:
                return f"{rounded:.{digits}f}"
    return f"{percent:.{MOST_DIGITS}f}"


def interval(successes: int, trials: int) -> str:
    """``39-90%``: the 95% Wilson interval in percent, rounded outwards.

    >>> interval(7, 10), interval(10, 10), interval(0, 40)
    ('39-90%', '72-100%', '0-9%')
    """
    low, high = wilson(successes, trials)
    return f"{percent_bound(low, upper=False)}-{percent_bound(high, upper=True)}%"


def share(successes: int, trials: int) -> str:
    """``7/10 (39-90%)``: a count of runs and its 95% interval; ``-`` for no runs.

    >>> share(0, 0)
    '-'
    """
    if trials == 0:
        return "-"
    return f"{successes}/{trials} ({interval(successes, trials)})"


def rate(successes: int, trials: int) -> str:
    """``52% (42-62%)``: a share of runs in percent and its 95% interval; ``-`` for none.

    >>> rate(52, 100)
    '52% (42-62%)'
    """
    if trials == 0:
        return "-"
    return f"{successes / trials:.0%} ({interval(successes, trials)})"
