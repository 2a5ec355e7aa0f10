"""Effect sizes of times, each with a 95% bootstrap interval, for the published pages.

A time to consensus is compared as the **ratio of medians** (a setting's median time over
the baseline's): 1.18 means 18% slower. Its interval is a percentile bootstrap (Efron and
Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 13): the runs are resampled with
replacement, ``RESAMPLES`` times, and the 2.5th and 97.5th percentiles of the resampled
ratios are the bounds. Where the runs of two groups are paired by seed (the same seed,
the same layout and draws: two settings of one study), the seeds are resampled, so a
seed's two runs stay together (``paired_median_ratio``): two settings that give the same
runs then give 1 with no width, where groups resampled on their own would show a spread
that is not there. Unpaired groups (``median_ratio``) are resampled each on its own. A
group of fewer than ``MIN_RUNS`` runs has no time to compare: a resampled median is one of
a few values, and even the range of 5 runs holds the true median only 94% of the time
(1 - 2 / 2^5), so no 95% interval can be had.

Where times are cut off (a run given up at its timeout is slower than any finished run,
by how much unknown), the comparison is the Vargha-Delaney A (Vargha and Delaney, "A
critique and improvement of the CL common language effect size statistics of McGraw and
Wong", J. Educ. Behav. Stat. 25(2), 2000), rank-based, so a cut-off run counts as slower
than every finished run and ties with the others cut off: A = P(X < Y) + P(X = Y) / 2, the
chance that a run of the first group is faster than one of the second (0.5: no
difference; 0.71 and above is what Vargha and Delaney call large).

How consensus time grows with swarm size is fitted as a power law, time = a N^b, by least
squares on log time against log N, every run one point; its interval resamples the runs
of each size on their own.

Every resampling draws from the project's generator (``bestofn_swarm.wire.rng.Stream``, specified in
docs/porting.md), seeded by the SHA-256 of the values it resamples, in sorted order: the
same runs give the same interval, in any order, on any machine and with any numpy. What
is computed from them is too: medians and percentiles select, sums of floats add in order
(``_sum``: numpy's reductions take another order on another SIMD path), and logarithms,
exponentials and powers are the portable kernel's (``bestofn_swarm.wire.numeric``).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.rng import Stream

RESAMPLES = 4000
MIN_RUNS = 6  # fewer runs in a group: no time to compare (see above)
LOW, HIGH = 0.025, 0.975  # the 95% interval's percentiles

Floats = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Estimate:
    """A value and its 95% interval."""

    value: float
    low: float
    high: float


def stream_for(*groups: Sequence[float]) -> Stream:
    """The generator of a resampling of ``groups`` (each sorted): seeded by their values."""
    text = "|".join(",".join(repr(float(value)) for value in group) for group in groups)
    return Stream(int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "little"))


def resample(stream: Stream, values: Floats, count: int = RESAMPLES) -> Floats:
    """``count`` resamples of ``values`` with replacement, one a row."""
    size = len(values)
    picks = (stream.random_array(count * size) * size).astype(np.int64).reshape(count, size)
    chosen: Floats = values[picks]
    return chosen


def percentiles(samples: Floats) -> tuple[float, float]:
    """The 2.5th and 97.5th percentiles of ``samples``, as order statistics taken outwards."""
    ordered = np.sort(samples)
    last = len(ordered) - 1
    return float(ordered[math.floor(LOW * last)]), float(ordered[math.ceil(HIGH * last)])


def median_interval(values: Sequence[float]) -> Estimate | None:
    """The median and its 95% bootstrap interval; None for fewer than ``MIN_RUNS`` values."""
    if len(values) < MIN_RUNS:
        return None
    data = np.sort(np.asarray(values, dtype=np.float64))
    medians = np.median(resample(stream_for(data.tolist()), data), axis=1)
    low, high = percentiles(medians)
    return Estimate(float(np.median(data)), low, high)


def median_ratio(treated: Sequence[float], baseline: Sequence[float]) -> Estimate | None:
    """median(treated) / median(baseline) and its 95% bootstrap interval; None when a group
    has fewer than ``MIN_RUNS`` runs."""
    if len(treated) < MIN_RUNS or len(baseline) < MIN_RUNS:
        return None
    first = np.sort(np.asarray(treated, dtype=np.float64))
    second = np.sort(np.asarray(baseline, dtype=np.float64))
    stream = stream_for(first.tolist(), second.tolist())
    top = np.median(resample(stream, first), axis=1)
    bottom = np.median(resample(stream, second), axis=1)
    low, high = percentiles(top / bottom)
    return Estimate(float(np.median(first) / np.median(second)), low, high)


def paired_median_ratio(
    treated: Mapping[int, float], baseline: Mapping[int, float]
) -> Estimate | None:
    """median(treated) / median(baseline), each a time by seed, and its 95% bootstrap
    interval with the seeds resampled (a seed in one group only counts in that group's
    median); None when a group has fewer than ``MIN_RUNS`` runs."""
    if len(treated) < MIN_RUNS or len(baseline) < MIN_RUNS:
        return None
    seeds = sorted(set(treated) | set(baseline))
    first = np.asarray([treated.get(seed, math.nan) for seed in seeds], dtype=np.float64)
    second = np.asarray([baseline.get(seed, math.nan) for seed in seeds], dtype=np.float64)
    stream = stream_for([float(seed) for seed in seeds], first.tolist(), second.tolist())
    picks = resample(stream, np.arange(len(seeds), dtype=np.float64)).astype(np.int64)
    top, bottom = first[picks], second[picks]
    # A resample without a run of one group has no median of it: left out (rare).
    kept = ~np.isnan(top).all(axis=1) & ~np.isnan(bottom).all(axis=1)
    ratios = np.nanmedian(top[kept], axis=1) / np.nanmedian(bottom[kept], axis=1)
    low, high = percentiles(ratios)
    value = float(np.nanmedian(first) / np.nanmedian(second))
    return Estimate(value, low, high)


def _faster(first: Floats, second: Floats) -> Floats:
    """A per row: P(a value of ``first`` is below one of ``second``) + ties / 2."""
    below = (first[..., :, None] < second[..., None, :]).mean(axis=(-2, -1))
    ties = (first[..., :, None] == second[..., None, :]).mean(axis=(-2, -1))
    found: Floats = below + ties / 2
    return found


def a_faster(first: Sequence[float], second: Sequence[float]) -> Estimate | None:
    """The Vargha-Delaney A that a run of ``first`` is faster than one of ``second``
    (``math.inf`` for a run given up) and its 95% bootstrap interval; None when a group has
    fewer than ``MIN_RUNS`` runs."""
    if len(first) < MIN_RUNS or len(second) < MIN_RUNS:
        return None
    one = np.sort(np.asarray(first, dtype=np.float64))
    two = np.sort(np.asarray(second, dtype=np.float64))
    stream = stream_for(one.tolist(), two.tolist())
    resampled = _faster(resample(stream, one), resample(stream, two))
    low, high = percentiles(resampled)
    return Estimate(float(_faster(one, two)), low, high)


def clustered_share(hits: Sequence[int], totals: Sequence[int]) -> Estimate | None:
    """A share of events grouped in runs (robots of a run, poolings of a run): sum of
    ``hits`` over sum of ``totals``, its interval by resampling whole runs, since the
    events of one run are not independent. None without events."""
    if sum(totals) == 0:
        return None
    pairs = sorted(zip(hits, totals, strict=True))
    top = np.asarray([hit for hit, _ in pairs], dtype=np.float64)
    bottom = np.asarray([total for _, total in pairs], dtype=np.float64)
    stream = stream_for(top.tolist(), bottom.tolist())
    rows = len(top)
    picks = (stream.random_array(RESAMPLES * rows) * rows).astype(np.int64)
    picks = picks.reshape(RESAMPLES, rows)
    sums = bottom[picks].sum(axis=1)
    shares = np.where(sums > 0, top[picks].sum(axis=1) / np.maximum(sums, 1.0), 0.0)
    low, high = percentiles(shares)
    return Estimate(float(top.sum() / bottom.sum()), low, high)


@dataclass(frozen=True)
class PowerLaw:
    """time = scale * size ** exponent, fitted on log-log axes; ``doubling`` = 2 **
    exponent, what doubling the size multiplies the time by; ``r2`` on log-log axes."""

    exponent: Estimate
    scale: Estimate
    doubling: Estimate
    r2: float
    runs: int
    fits: Floats  # the resampled (log scale, exponent) pairs, one a row

    def curve(self, sizes: Sequence[float]) -> tuple[Floats, Floats, Floats]:
        """The fitted time at each size and its pointwise 95% interval."""
        logs = numeric.log_array(np.asarray(sizes, dtype=np.float64))
        central = self.scale.value * numeric.exp_array(self.exponent.value * logs)
        resampled = numeric.exp_array(self.fits[:, :1] + self.fits[:, 1:] * logs[None, :])
        ordered = np.sort(resampled, axis=0)
        last = len(ordered) - 1
        low = ordered[math.floor(LOW * last)]
        high = ordered[math.ceil(HIGH * last)]
        return central, low, high


def _sum(values: Floats) -> Floats:
    """Sums along the last axis, added in order (the same bits on every CPU)."""
    summed: Floats = np.cumsum(values, axis=-1)[..., -1]
    return summed


def _fit(logs: Floats, times: Floats) -> tuple[Floats, Floats]:
    """Least-squares (intercept, slope) per row of ``logs`` and ``times`` (log values)."""
    count = logs.shape[-1]
    mean_x = (_sum(logs) / count)[..., None]
    mean_y = (_sum(times) / count)[..., None]
    slope = _sum((logs - mean_x) * (times - mean_y)) / _sum((logs - mean_x) ** 2)
    intercept = mean_y[..., 0] - slope * mean_x[..., 0]
    return intercept, slope


def power_law(sizes: Sequence[float], times: Sequence[float]) -> PowerLaw | None:
    """The power law through (size, time) points, one a run, and its 95% intervals (the
    runs of each size resampled on their own); None for fewer than two sizes."""
    if len(set(sizes)) < 2 or len(sizes) != len(times):
        return None
    points = sorted(zip(sizes, times, strict=True))
    sizes = [size for size, _ in points]
    times = [time for _, time in points]
    x = numeric.log_array(np.asarray(sizes, dtype=np.float64))
    y = numeric.log_array(np.asarray(times, dtype=np.float64))
    intercept, slope = _fit(x[None, :], y[None, :])
    residual = y - (intercept[0] + slope[0] * x)
    r2 = 1.0 - float(_sum(residual**2) / _sum((y - _sum(y) / len(y)) ** 2))
    stream = stream_for(list(sizes), list(times))
    columns = []
    for size in sorted(set(sizes)):  # resample within each size, sizes in order
        where = np.flatnonzero(np.asarray(sizes, dtype=np.float64) == size)
        columns.append(resample(stream, where.astype(np.float64)).astype(np.int64))
    picks = np.concatenate(columns, axis=1)
    fitted_intercepts, fitted_slopes = _fit(x[picks], y[picks])
    fits = np.stack([fitted_intercepts, fitted_slopes], axis=1)
    slope_low, slope_high = percentiles(fitted_slopes)
    scale_low, scale_high = percentiles(numeric.exp_array(fitted_intercepts))
    return PowerLaw(
        exponent=Estimate(float(slope[0]), slope_low, slope_high),
        scale=Estimate(numeric.exp(float(intercept[0])), scale_low, scale_high),
        doubling=Estimate(
            numeric.power(2.0, float(slope[0])),
            numeric.power(2.0, slope_low),
            numeric.power(2.0, slope_high),
        ),
        r2=r2,
        runs=len(sizes),
        fits=fits,
    )


def outwards(low: float, high: float, digits: int) -> str:
    """``0.95-1.42``: an interval rounded outwards to ``digits`` decimals (the printed
    interval holds the computed one)."""
    scale = 10**digits
    down = math.floor(low * scale + 1e-9) / scale
    up = math.ceil(high * scale - 1e-9) / scale
    return f"{down:.{digits}f}-{up:.{digits}f}"


def times_text(estimate: Estimate, digits: int = 2, more: str = "") -> str:
    """``1.18 times (95% interval 0.95-1.43)``, ``more`` added inside the brackets."""
    bounds = outwards(estimate.low, estimate.high, digits)
    return f"{estimate.value:.{digits}f} times (95% interval {bounds}{more})"


def estimate_text(estimate: Estimate | None, digits: int = 2) -> str:
    """``1.18 (0.95-1.42)``: the value and its interval, rounded outwards; ``-`` for none."""
    if estimate is None:
        return "-"
    return f"{estimate.value:.{digits}f} ({outwards(estimate.low, estimate.high, digits)})"
