"""The 95% Wilson score interval of a share of runs, against known values."""

from __future__ import annotations

import doctest

import pytest

from deploy.analysis import wilson as wilson_module
from deploy.analysis.wilson import interval, share, wilson


@pytest.mark.parametrize(
    ("successes", "trials", "low", "high"),
    [
        # The bounds are the roots p of (k/n - p)^2 = z^2 p (1 - p) / n, z = 1.96: at 0 of
        # n the upper one is z^2 / (n + z^2), at n of n the lower one 1 minus that.
        (0, 10, 0.0, 0.277533),
        (10, 10, 0.722467, 1.0),
        (5, 10, 0.236593, 0.763407),
        (7, 10, 0.396778, 0.892209),
        (1, 40, 0.004427, 0.128814),
        (95, 100, 0.888250, 0.978456),
    ],
)
def test_known_intervals(successes: int, trials: int, low: float, high: float) -> None:
    found = wilson(successes, trials)
    assert found == pytest.approx((low, high), abs=1e-6)


def test_no_trials_say_nothing_and_bad_counts_are_refused() -> None:
    assert wilson(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError):
        wilson(3, 2)


def test_a_share_is_shown_with_its_interval_rounded_outwards() -> None:
    assert interval(7, 10) == "39-90%"
    assert share(7, 10) == "7/10 (39-90%)"
    assert share(0, 40) == "0/40 (0-9%)"
    assert share(0, 0) == "-"


@pytest.mark.parametrize(
    ("successes", "trials", "shown"),
    [
        (99, 100, "99/100 (94-99.9%)"),  # whole percent would say 100%, which it excludes
        (1, 100, "1/100 (0.1-6%)"),  # and 0% here
        (100, 100, "100/100 (96-100%)"),  # n of n: 100% is in the interval
        (0, 100, "0/100 (0-4%)"),
        (999, 1000, "999/1000 (99-99.99%)"),
        (1, 10000, "1/10000 (0.001-1%)"),
    ],
)
def test_a_bound_is_printed_to_the_digits_that_keep_it_true(
    successes: int, trials: int, shown: str
) -> None:
    assert share(successes, trials) == shown
    low, high = wilson(successes, trials)
    printed = shown.split("(")[1].rstrip("%)").split("-")
    assert float(printed[0]) / 100 <= low and high <= float(printed[1]) / 100  # outwards
    assert (float(printed[1]) < 100) == (high < 1) and (float(printed[0]) > 0) == (low > 0)


def test_the_docstrings_examples_are_what_the_code_prints() -> None:
    tried = doctest.testmod(wilson_module)
    assert tried.attempted >= 8 and tried.failed == 0
