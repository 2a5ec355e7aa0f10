"""The portable numeric kernel (``bestofn_swarm/wire/numeric.py``) and the project's generator
(``bestofn_swarm/wire/rng.py``): accurate, the same in scalar and array form, and equal to the
conformance vectors of ``tests/vectors/numeric.json`` and ``rng.json`` that a port checks
itself against (docs/kernel.md)."""

from __future__ import annotations

import json
import math
import statistics
import struct
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bestofn_swarm.wire import numeric
from bestofn_swarm.wire.rng import GAMMA, MASK, Stream, mix, seed_of

VECTORS = Path(__file__).resolve().parent / "vectors"


def bits(value: float) -> str:
    """The IEEE-754 bits in hex; every NaN alike (their payloads are not specified)."""
    return "nan" if math.isnan(value) else struct.pack(">d", value).hex()


def from_bits(text: str) -> float:
    if text == "nan":
        return math.nan
    value: float = struct.unpack(">d", bytes.fromhex(text))[0]
    return value


def ulps(ours: float, reference: float) -> float:
    """How many units in the last place apart two finite doubles are."""
    if ours == reference:
        return 0.0
    return abs(ours - reference) / math.ulp(max(abs(ours), abs(reference)))


angles = st.floats(-numeric.MAX_ANGLE, numeric.MAX_ANGLE, allow_nan=False)
moderate = st.floats(-50.0, 50.0, allow_nan=False)


# --- accuracy against the C library ------------------------------------------------------


@given(st.floats(-100.0, 100.0, allow_nan=False))
def test_sine_and_cosine_are_within_an_ulp_of_the_c_library(x: float) -> None:
    sin, cos = numeric.sincos(x)
    assert ulps(sin, math.sin(x)) <= 1.0 or abs(sin - math.sin(x)) < 1e-300
    assert ulps(cos, math.cos(x)) <= 1.0


@given(st.floats(-1e6, 1e6, allow_nan=False), st.floats(-1e6, 1e6, allow_nan=False))
def test_atan2_is_within_an_ulp_of_the_c_library(y: float, x: float) -> None:
    assert ulps(numeric.atan2(y, x), math.atan2(y, x)) <= 1.0
    assert ulps(numeric.atan(y), math.atan(y)) <= 1.0


@given(st.floats(-700.0, 700.0, allow_nan=False), st.floats(1e-300, 1e300))
def test_exp_and_log_are_within_an_ulp_of_the_c_library(x: float, y: float) -> None:
    assert ulps(numeric.exp(x), math.exp(x)) <= 1.0
    assert ulps(numeric.log(y), math.log(y)) <= 1.0


def test_a_sample_of_every_function_agrees_with_the_c_library_to_an_ulp() -> None:
    stream = Stream(3)
    worst: dict[str, float] = dict.fromkeys(("sin", "cos", "atan2", "exp", "log"), 0.0)
    for _ in range(20000):
        x = stream.uniform(-30.0, 30.0)
        y = stream.uniform(-30.0, 30.0)
        positive = math.ldexp(1.0 + stream.random(), int(stream.uniform(-100.0, 100.0)))
        for name, ours, theirs in (
            ("sin", numeric.sin(x), math.sin(x)),
            ("cos", numeric.cos(x), math.cos(x)),
            ("atan2", numeric.atan2(y, x), math.atan2(y, x)),
            ("exp", numeric.exp(x), math.exp(x)),
            ("log", numeric.log(positive), math.log(positive)),
        ):
            worst[name] = max(worst[name], ulps(ours, theirs))
    assert max(worst.values()) <= 1.0, worst


def test_special_values() -> None:
    assert numeric.sincos(0.0) == (0.0, 1.0)
    assert math.copysign(1.0, numeric.sin(-0.0)) == -1.0
    assert numeric.atan2(0.0, -0.0) == numeric.PI
    assert numeric.atan2(-0.0, -1.0) == -numeric.PI
    assert math.copysign(1.0, numeric.atan2(-0.0, 1.0)) == -1.0
    assert numeric.atan2(1.0, 0.0) == numeric.HALF_PI
    assert numeric.atan2(-5.0, -0.0) == -numeric.HALF_PI
    assert math.isnan(numeric.atan2(math.nan, 1.0))
    assert numeric.exp(0.0) == 1.0 and numeric.log(1.0) == 0.0
    assert numeric.exp(1000.0) == math.inf and numeric.exp(-1000.0) == 0.0
    assert numeric.log(0.0) == -math.inf and math.isnan(numeric.log(-1.0))
    assert numeric.log(math.inf) == math.inf
    assert numeric.power(0.0, 2.0) == 0.0 and numeric.power(0.3, 0.0) == 1.0
    assert numeric.power(0.25, 0.5) == 0.5
    with pytest.raises(ValueError, match="x >= 0"):
        numeric.power(-1.0, 2.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, numeric.MAX_ANGLE * 1.01])
def test_sine_refuses_what_it_cannot_reduce(bad: float) -> None:
    with pytest.raises(ValueError, match="outside the kernel's range"):
        numeric.sincos(bad)
    with pytest.raises(ValueError, match="outside the kernel's range"):
        numeric.sincos_array(np.full(100, bad))
    with pytest.raises(ValueError, match="outside the kernel's range"):
        numeric.sincos_array(np.array([0.0, bad]))  # the short, scalar path


@given(moderate)
def test_wrap_angle_lands_in_minus_pi_to_pi_and_keeps_the_direction(x: float) -> None:
    wrapped = numeric.wrap_angle(x)
    assert -numeric.PI - 1e-15 <= wrapped <= numeric.PI + 1e-15
    assert abs(math.remainder(x - wrapped, 2 * math.pi)) < 1e-12


# --- scalar and array forms agree bit for bit ---------------------------------------------


@given(st.lists(angles, min_size=0, max_size=80))
def test_the_array_sine_is_the_scalar_one_element_by_element(values: list[float]) -> None:
    sin, cos = numeric.sincos_array(np.array(values, dtype=np.float64))
    assert [bits(v) for v in sin.tolist()] == [bits(numeric.sincos(v)[0]) for v in values]
    assert [bits(v) for v in cos.tolist()] == [bits(numeric.sincos(v)[1]) for v in values]


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=60))
def test_the_array_exp_log_and_wrap_are_the_scalar_ones(values: list[float]) -> None:
    array = np.array(values, dtype=np.float64)
    assert [bits(v) for v in numeric.log_array(array).tolist()] == [
        bits(numeric.log(v)) for v in values
    ]
    assert [bits(v) for v in numeric.exp_array(array).tolist()] == [
        bits(numeric.exp(v)) for v in values
    ]
    finite = np.array([v for v in values if abs(v) < 1e6])
    assert [bits(v) for v in numeric.wrap_angle_array(finite).tolist()] == [
        bits(numeric.wrap_angle(v)) for v in finite.tolist()
    ]


# --- the generator ------------------------------------------------------------------------


def test_splitmix64_is_the_reference_algorithm() -> None:
    # Vigna's splitmix64.c from seed 1234567: its first three outputs.
    stream = Stream(1234567)
    assert [stream.next_u64() for _ in range(3)] == [
        6457827717110365317,
        3203168211198807973,
        9817491932198370423,
    ]
    assert Stream(5).state == 5
    first = Stream(5)
    first.next_u64()
    assert first.state == (5 + GAMMA) & MASK and mix(first.state) == Stream(5).next_u64()


@pytest.mark.parametrize("bad", [-1, 2**64, 1.5, True, "3"])
def test_a_stream_takes_only_a_64_bit_seed(bad: Any) -> None:
    with pytest.raises(ValueError, match="seed"):
        Stream(bad)


@given(st.integers(0, MASK), st.integers(0, 300))
def test_array_draws_are_the_scalar_draws_in_order(seed: int, count: int) -> None:
    one, many = Stream(seed), Stream(seed)
    assert many.u64_array(count).tolist() == [one.next_u64() for _ in range(count)]
    assert many.state == one.state
    assert many.random_array(count).tolist() == [one.random() for _ in range(count)]
    assert [bits(v) for v in many.normal_array(count // 3).tolist()] == [
        bits(one.normal()) for _ in range(count // 3)
    ]
    assert many.state == one.state


def test_draws_are_uniform_and_normal_in_the_large() -> None:
    stream = Stream(8)
    counts = Counter(stream.randrange(6) for _ in range(60000))
    assert sorted(counts) == list(range(6))
    assert all(abs(count - 10000) < 400 for count in counts.values())  # about 4 sigma
    units = stream.random_array(100000)
    assert units.min() >= 0.0 and units.max() < 1.0
    assert abs(float(units.mean()) - 0.5) < 0.005
    normals = stream.normal_array(100000)
    assert abs(float(normals.mean())) < 0.015 and abs(float(normals.std()) - 1.0) < 0.015
    waits = [stream.expovariate(2.0) for _ in range(50000)]
    assert abs(statistics.fmean(waits) - 0.5) < 0.01


def test_bounded_draws_choice_shuffle_and_sample() -> None:
    stream = Stream(1)
    state = stream.state
    assert stream.randrange(1) == 0 and stream.state == state  # no draw for one choice
    with pytest.raises(ValueError, match="stop >= 1"):
        stream.randrange(0)
    with pytest.raises(IndexError):
        stream.choice([])
    items = list(range(30))
    stream.shuffle(items)
    assert sorted(items) == list(range(30)) and items != list(range(30))
    drawn = stream.sample(range(30), 10)
    assert len(set(drawn)) == 10 and set(drawn) <= set(range(30))
    with pytest.raises(ValueError, match="cannot sample"):
        stream.sample([1, 2], 3)
    fork = Stream(9).fork()
    assert fork.state == Stream(9).next_u64()


def test_seeds_of_a_run_are_sha256_of_its_seed_and_names() -> None:
    assert seed_of(0, "robot", 3) == seed_of(0, "robot", "3")
    assert seed_of(0, "robot", 3) != seed_of(0, "robot", 4) != seed_of(1, "robot", 3)
    assert Stream.named(7, "radio", "drop").state == seed_of(7, "radio", "drop")


# --- the conformance vectors ------------------------------------------------------------


def load(name: str) -> dict[str, Any]:
    content: dict[str, Any] = json.loads((VECTORS / name).read_text(encoding="utf-8"))
    return content


def test_every_numeric_vector_holds() -> None:
    functions: dict[str, Callable[..., float | tuple[float, float]]] = {
        "sincos": numeric.sincos,
        "atan": numeric.atan,
        "atan2": numeric.atan2,
        "exp": numeric.exp,
        "log": numeric.log,
        "power": numeric.power,
        "wrap_angle": numeric.wrap_angle,
    }
    cases = load("numeric.json")["cases"]
    assert set(cases) == set(functions)
    for name, vectors in cases.items():
        assert len(vectors) >= 20, name
        for vector in vectors:
            result = functions[name](*(from_bits(text) for text in vector["in"]))
            outputs = result if isinstance(result, tuple) else (result,)
            assert [bits(value) for value in outputs] == vector["out"], (name, vector)


def test_every_generator_vector_holds() -> None:
    content = load("rng.json")
    for case in content["cases"]:
        stream = Stream(int(case["seed"], 16))
        for (method, arguments), expected in zip(case["calls"], case["returns"], strict=True):
            value = getattr(stream, method)(*arguments)
            if method == "shuffle":
                value = arguments[0]
            elif method == "fork":
                value = f"{value.state:016x}"
            elif method == "next_u64":
                value = f"{value:016x}"
            assert (bits(value) if isinstance(value, float) else value) == expected, case["name"]
        assert f"{stream.state:016x}" == case["state_after"], case["name"]
    for entry in content["seed_of"]:
        assert f"{seed_of(entry['run_seed'], *entry['parts']):016x}" == entry["seed"]
