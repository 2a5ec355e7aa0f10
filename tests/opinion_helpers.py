"""Assertions and strategies on opinion vectors, shared by the decision-math tests."""

from __future__ import annotations

import math

import pytest
from hypothesis import strategies as st

# An alpha so small that alpha * x underflows to zero acts as alpha = 0; where a test
# relies on alpha > 0 keeping every option alive, it draws from these instead.
working_alphas = st.one_of(st.just(0.0), st.floats(min_value=1e-6, max_value=0.5))


def normalise(values: list[float]) -> list[float]:
    total = math.fsum(values)
    return [value / total for value in values]


def assert_close(
    actual: list[float] | None, expected: list[float], tolerance: float = 1e-9
) -> None:
    assert actual is not None
    assert len(actual) == len(expected)
    for a, b in zip(actual, expected, strict=True):
        assert a == pytest.approx(b, abs=tolerance)


def assert_distribution(values: list[float]) -> None:
    assert all(value >= 0.0 for value in values)
    assert math.fsum(values) == pytest.approx(1.0, abs=1e-12)
