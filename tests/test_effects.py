"""Effect sizes of times with bootstrap intervals (deploy/analysis/effects.py): known
values, what too few runs give, determinism, and that a 95% interval holds the truth
about 95% of the time."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bestofn_swarm.wire.rng import Stream
from deploy.analysis import effects

TIMES = [111.6, 141.1, 135.1, 187.1, 134.6, 121.6, 156.6, 156.6, 125.1, 150.1]


def test_the_ratio_of_medians_and_its_interval() -> None:
    slower = [1.2 * time for time in TIMES]
    found = effects.median_ratio(slower, TIMES)
    assert found is not None
    assert found.value == pytest.approx(1.2)
    assert 1.0 < found.low < 1.2 < found.high < 1.45
    same = effects.median_ratio([100.0] * 6, [50.0] * 7)
    assert same == effects.Estimate(2.0, 2.0, 2.0)  # no spread, no width


def test_too_few_runs_compare_no_time() -> None:
    """Fewer than 6 runs: even their range holds the median less than 95% of the time."""
    assert effects.median_ratio(TIMES[:5], TIMES) is None
    assert effects.median_ratio(TIMES, TIMES[:1]) is None
    assert effects.median_ratio(TIMES[:6], TIMES[:6]) is not None
    assert effects.median_interval(TIMES[:5]) is None
    assert effects.a_faster(TIMES, TIMES[:5]) is None
    assert effects.estimate_text(None) == "-"


def test_an_interval_depends_on_the_runs_alone() -> None:
    shuffled = TIMES[::-1]
    assert effects.median_ratio(shuffled, TIMES[:7]) == effects.median_ratio(TIMES, TIMES[:7])
    assert effects.median_interval(shuffled) == effects.median_interval(TIMES)
    moved = effects.median_ratio([*TIMES[:-1], 150.2], TIMES[:7])
    assert moved != effects.median_ratio(TIMES, TIMES[:7])  # other runs, another draw


def test_the_chance_that_one_run_is_faster_than_another() -> None:
    fast, slow = [1.0, 2.0, 3.0] * 2, [4.0, 5.0, 6.0] * 2
    assert effects.a_faster(fast, slow) == effects.Estimate(1.0, 1.0, 1.0)
    assert effects.a_faster(slow, fast) == effects.Estimate(0.0, 0.0, 0.0)
    even = effects.a_faster(TIMES, TIMES)
    assert even is not None and even.value == 0.5 and even.low < 0.5 < even.high
    # A run given up is slower than any finished run, and ties with the others given up.
    given_up = [math.inf] * 7 + [1000.0, 1100.0, 1200.0]
    found = effects.a_faster([900.0, 950.0, 1050.0] * 2, given_up)
    assert found is not None and found.value == pytest.approx((10 + 10 + 9) / 30)


def test_a_share_of_events_grouped_in_runs() -> None:
    found = effects.clustered_share([3, 5, 7, 1], [10, 10, 10, 10])
    assert found is not None and found.value == 0.4 and found.low < 0.4 < found.high
    # The same events in one run and spread evenly: the spread between runs is the width.
    even = effects.clustered_share([4, 4, 4, 4], [10, 10, 10, 10])
    assert even == effects.Estimate(0.4, 0.4, 0.4)
    assert effects.clustered_share([0, 0], [0, 0]) is None


def test_a_power_law_through_exact_points_is_found_exactly() -> None:
    sizes = [10, 10, 100, 100, 1000]
    fit = effects.power_law(sizes, [3.0 * size**0.7 for size in sizes])
    assert fit is not None
    assert fit.exponent.value == pytest.approx(0.7) and fit.scale.value == pytest.approx(3.0)
    assert fit.exponent.high - fit.exponent.low == pytest.approx(0.0, abs=1e-12)
    assert fit.doubling.value == pytest.approx(2**0.7) and fit.r2 == pytest.approx(1.0)
    central, low, high = fit.curve([20.0])
    assert central[0] == pytest.approx(3.0 * 20**0.7) == low[0] == high[0]
    assert effects.power_law([10, 10], [1.0, 2.0]) is None  # one size: no slope


def test_a_power_law_through_noisy_runs_holds_its_exponent() -> None:
    noise = Stream(7).normal_array(60)
    sizes = [size for size in (10, 50, 100, 200, 500, 1000) for _ in range(10)]
    times = [
        40.0 * size**0.6 * math.exp(0.1 * float(e)) for size, e in zip(sizes, noise, strict=True)
    ]
    fit = effects.power_law(sizes, times)
    assert fit is not None and fit.exponent.low < 0.6 < fit.exponent.high
    assert fit.exponent.high - fit.exponent.low < 0.1


def test_a_95_percent_interval_holds_the_true_ratio_about_95_times_in_100() -> None:
    """Two groups of 20 from one log-normal distribution: the true ratio is 1."""
    draws = Stream(11).normal_array(200 * 40).reshape(200, 40)
    held = 0
    for row in draws:
        times = np.exp(0.3 * row).tolist()
        found = effects.median_ratio(times[:20], times[20:])
        assert found is not None
        held += found.low <= 1.0 <= found.high
    assert 180 <= held <= 200  # 95% of 200 is 190; a binomial's 99.9% range is about 179-198


def test_intervals_are_printed_outwards() -> None:
    assert effects.estimate_text(effects.Estimate(1.18, 0.9549, 1.4211)) == "1.18 (0.95-1.43)"
    assert effects.outwards(0.5, 2.0, 1) == "0.5-2.0"


def test_runs_paired_by_seed_are_resampled_together() -> None:
    by_seed = dict(enumerate(TIMES))
    # The same runs (two settings that change nothing): 1, with no width.
    assert effects.paired_median_ratio(by_seed, by_seed) == effects.Estimate(1.0, 1.0, 1.0)
    # Each seed 10% slower, whatever its time: the pairing sees it exactly.
    slower = {seed: 1.1 * time for seed, time in by_seed.items()}
    found = effects.paired_median_ratio(slower, by_seed)
    assert found is not None and found.low == pytest.approx(1.1) == found.high
    apart = effects.median_ratio(list(slower.values()), TIMES)
    assert apart is not None and apart.high - apart.low > 0.2  # unpaired: a spread of seeds
    # A seed in one group only counts in that group's median.
    fewer = {seed: time for seed, time in slower.items() if seed != 3}
    found = effects.paired_median_ratio(fewer, by_seed)
    assert found is not None and found.value == pytest.approx(
        float(np.median(list(fewer.values())) / np.median(TIMES))
    )
    assert effects.paired_median_ratio(dict(list(by_seed.items())[:5]), by_seed) is None
