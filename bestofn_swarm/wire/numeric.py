"""The portable numeric kernel: the transcendental functions every computation that shapes
a run uses, built from +, -, *, / and exact operations only, so that they give the same
bits on every CPU and in every language that has IEEE-754 doubles.

Why not ``math`` or numpy: glibc's libm picks an FMA variant of sin, cos, atan, exp and
log on CPUs that have FMA, and numpy picks AVX-512 variants of its float64 ufuncs; each
rounds differently in the last bit now and then, and a swarm is chaotic enough that one
bit changes the run. Box2D v3 and Rapier's enhanced determinism make the same choice.

The algorithms are fdlibm's (Sun Microsystems, 1993; as in musl), with every branch on a
bit pattern written as a comparison of doubles and one rule where fdlibm has several:

* the operations are IEEE-754 double +, -, *, / and sqrt, each rounded to nearest, never
  fused (a C port compiles with ``-ffp-contract=off``), in the order written;
* the exact operations ``floor``, ``frexp``, ``ldexp``, ``fabs``, ``copysign`` and
  comparisons also appear; none of them rounds;
* every constant is given as a hex float, so a port copies its bits.

docs/porting.md specifies each function step by step and tests/vectors/numeric.json has
conformance vectors (input bits to output bits). Accuracy (tests/test_numeric.py): within
1 ulp of the true value for sin, cos, atan, atan2, exp and log over the ranges a run uses.

Each function has a scalar form (Python floats) and, where a run needs many at once, an
array form (numpy float64) that performs the same operations element by element, so the
two agree bit for bit. numpy's elementwise +, -, *, / and sqrt are IEEE-exact whatever
SIMD path runs them; only its transcendental ufuncs and reductions are not.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

# --- constants (hex floats: the exact bits a port copies) ---------------------------------

PI: Final = float.fromhex("0x1.921fb54442d18p+1")
HALF_PI: Final = float.fromhex("0x1.921fb54442d18p+0")
PI_LO: Final = float.fromhex("0x1.1a62633145c07p-53")  # pi - PI
TWO_PI: Final = float.fromhex("0x1.921fb54442d18p+2")

# Reduction by pi/2 (Cody and Waite, fdlibm's __rem_pio2 in two rounds): PIO2_1 and
# PIO2_2 hold 33 significant bits, so n * PIO2_1 and n * PIO2_2 are exact for |n| < 2^20.
INV_PIO2: Final = float.fromhex("0x1.45f306dc9c883p-1")  # 2 / pi
PIO2_1: Final = float.fromhex("0x1.921fb544p+0")
PIO2_2: Final = float.fromhex("0x1.0b4611a6p-34")
PIO2_2T: Final = float.fromhex("0x1.3198a2e037073p-69")
# The largest |x| sin and cos take: n stays below 2^19, well inside the exact range.
MAX_ANGLE: Final = 8.0e5

# Kernels on [-pi/4, pi/4] (fdlibm's __kernel_sin and __kernel_cos, musl's arrangement).
# A port evaluates each expression exactly as parenthesised here.
S1: Final = float.fromhex("-0x1.5555555555549p-3")
S2: Final = float.fromhex("0x1.111111110f8a6p-7")
S3: Final = float.fromhex("-0x1.a01a019c161d5p-13")
S4: Final = float.fromhex("0x1.71de357b1fe7dp-19")
S5: Final = float.fromhex("-0x1.ae5e68a2b9cebp-26")
S6: Final = float.fromhex("0x1.5d93a5acfd57cp-33")
C1: Final = float.fromhex("0x1.555555555554cp-5")
C2: Final = float.fromhex("-0x1.6c16c16c15177p-10")
C3: Final = float.fromhex("0x1.a01a019cb159p-16")
C4: Final = float.fromhex("-0x1.27e4f809c52adp-22")
C5: Final = float.fromhex("0x1.1ee9ebdb4b1c4p-29")
C6: Final = float.fromhex("-0x1.8fae9be8838d4p-37")

# atan (fdlibm's s_atan.c): atan(0.5), atan(1), atan(1.5), atan(inf) in two parts each.
ATAN_HI_0: Final = float.fromhex("0x1.dac670561bb4fp-2")
ATAN_HI_1: Final = float.fromhex("0x1.921fb54442d18p-1")
ATAN_HI_2: Final = float.fromhex("0x1.f730bd281f69bp-1")
ATAN_HI_3: Final = float.fromhex("0x1.921fb54442d18p+0")
ATAN_LO_0: Final = float.fromhex("0x1.a2b7f222f65e2p-56")
ATAN_LO_1: Final = float.fromhex("0x1.1a62633145c07p-55")
ATAN_LO_2: Final = float.fromhex("0x1.007887af0cbbdp-56")
ATAN_LO_3: Final = float.fromhex("0x1.1a62633145c07p-54")
AT0: Final = float.fromhex("0x1.555555555550dp-2")
AT1: Final = float.fromhex("-0x1.999999998ebc4p-3")
AT2: Final = float.fromhex("0x1.24924920083ffp-3")
AT3: Final = float.fromhex("-0x1.c71c6fe231671p-4")
AT4: Final = float.fromhex("0x1.745cdc54c206ep-4")
AT5: Final = float.fromhex("-0x1.3b0f2af749a6dp-4")
AT6: Final = float.fromhex("0x1.10d66a0d03d51p-4")
AT7: Final = float.fromhex("-0x1.dde2d52defd9ap-5")
AT8: Final = float.fromhex("0x1.97b4b24760debp-5")
AT9: Final = float.fromhex("-0x1.2b4442c6a6c2fp-5")
AT10: Final = float.fromhex("0x1.0ad3ae322da11p-6")
ATAN_BIG: Final = float.fromhex("0x1p66")  # from here on atan(x) rounds to +-pi/2
# The same constants as tuples (the functions read the names: a name is faster).
ATAN_HI: Final = (ATAN_HI_0, ATAN_HI_1, ATAN_HI_2, ATAN_HI_3)
ATAN_LO: Final = (ATAN_LO_0, ATAN_LO_1, ATAN_LO_2, ATAN_LO_3)
AT: Final = (AT0, AT1, AT2, AT3, AT4, AT5, AT6, AT7, AT8, AT9, AT10)

# exp and log (fdlibm's e_exp.c and e_log.c).
LN2_HI: Final = float.fromhex("0x1.62e42feep-1")  # 32 significant bits: k * LN2_HI exact
LN2_LO: Final = float.fromhex("0x1.a39ef35793c76p-33")
INV_LN2: Final = float.fromhex("0x1.71547652b82fep+0")
EXP_OVERFLOW: Final = float.fromhex("0x1.62e42fefa39efp+9")  # above: inf
EXP_UNDERFLOW: Final = float.fromhex("-0x1.74910d52d3051p+9")  # below: 0
P1: Final = float.fromhex("0x1.555555555553ep-3")
P2: Final = float.fromhex("-0x1.6c16c16bebd93p-9")
P3: Final = float.fromhex("0x1.1566aaf25de2cp-14")
P4: Final = float.fromhex("-0x1.bbd41c5d26bf1p-20")
P5: Final = float.fromhex("0x1.6376972bea4d0p-25")
SQRT_HALF: Final = float.fromhex(
    "0x1.6a09ep-1"
)  # log reduces x to m 2^k, m in [SQRT_HALF, 2 SQRT_HALF)
LG1: Final = float.fromhex("0x1.5555555555593p-1")
LG2: Final = float.fromhex("0x1.999999997fa04p-2")
LG3: Final = float.fromhex("0x1.2492494229359p-2")
LG4: Final = float.fromhex("0x1.c71c51d8e78afp-3")
LG5: Final = float.fromhex("0x1.7466496cb03dep-3")
LG6: Final = float.fromhex("0x1.39a09d078c69fp-3")
LG7: Final = float.fromhex("0x1.2f112df3e5244p-3")

# wrap_angle: 2 pi in two parts, the first with 35 significant bits (4 PIO2_1).
INV_TWO_PI: Final = float.fromhex("0x1.45f306dc9c883p-3")
TWO_PI_HI: Final = 4.0 * PIO2_1
TWO_PI_LO: Final = float.fromhex("0x1.0b4611a626331p-32")  # 2 pi - TWO_PI_HI


# --- sin and cos ---------------------------------------------------------------------------


def sincos(x: float) -> tuple[float, float]:
    """(sin x, cos x) for |x| <= ``MAX_ANGLE``; ValueError for anything else, NaN too.

    x = n pi/2 + (y0 + y1) with |y0 + y1| <= pi/4 (about), by Cody and Waite's reduction in
    two rounds (good to 118 bits); then fdlibm's kernels on (y0, y1), swapped and negated
    by n mod 4. Written out in one function (and again in ``cos``), because the physics
    and the navigator call it more than anything else.
    """
    if not -MAX_ANGLE <= x <= MAX_ANGLE:  # also false for NaN
        raise ValueError(f"angle {x!r} is outside the kernel's range +-{MAX_ANGLE}")
    fn = math.floor(x * INV_PIO2 + 0.5)
    if fn == 0.0:
        # What the reduction below gives for n = 0, without its operations.
        y0, y1 = x, 0.0
    else:
        r = x - fn * PIO2_1
        w = fn * PIO2_2
        t = r
        r = t - w
        w = fn * PIO2_2T - ((t - r) - w)
        y0 = r - w
        y1 = (r - y0) - w
    z = y0 * y0
    w = z * z
    v = z * y0
    r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    s = y0 - ((z * (0.5 * y1 - v * r) - y1) - v * S1)  # the kernel sine of (y0, y1)
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + (z * r - y0 * y1))  # the kernel cosine
    quadrant = int(fn) & 3
    if quadrant == 0:
        return s, c
    if quadrant == 1:
        return c, -s
    if quadrant == 2:
        return -s, -c
    return -c, s


def sin(x: float) -> float:
    return sincos(x)[0]


def cos(x: float) -> float:
    """``sincos(x)[1]``, computing only the kernel it needs (the navigator's one call)."""
    if not -MAX_ANGLE <= x <= MAX_ANGLE:  # also false for NaN
        raise ValueError(f"angle {x!r} is outside the kernel's range +-{MAX_ANGLE}")
    fn = math.floor(x * INV_PIO2 + 0.5)
    if fn == 0.0:
        y0, y1 = x, 0.0
    else:
        r = x - fn * PIO2_1
        w = fn * PIO2_2
        t = r
        r = t - w
        w = fn * PIO2_2T - ((t - r) - w)
        y0 = r - w
        y1 = (r - y0) - w
    z = y0 * y0
    w = z * z
    quadrant = int(fn) & 3
    if quadrant & 1:
        v = z * y0
        r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
        s = y0 - ((z * (0.5 * y1 - v * r) - y1) - v * S1)
        return -s if quadrant == 1 else s
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + (z * r - y0 * y1))
    return c if quadrant == 0 else -c


# Below this many elements a loop of ``sincos`` is faster than numpy's per-call overhead.
_SCALAR_BELOW: Final = 24
_SINE_SIGN: Final = np.array([1.0, 1.0, -1.0, -1.0])  # by quadrant: sin(x) = +-(kernel sin or cos)
_COSINE_SIGN: Final = np.array([1.0, -1.0, -1.0, 1.0])


def sincos_array(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``sincos`` of every element (the same operations, so the same bits)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < _SCALAR_BELOW:
        pairs = [sincos(value) for value in x.ravel().tolist()]
        return (
            np.array([pair[0] for pair in pairs], dtype=np.float64).reshape(x.shape),
            np.array([pair[1] for pair in pairs], dtype=np.float64).reshape(x.shape),
        )
    if not np.all(np.abs(x) <= MAX_ANGLE):  # also false for NaN
        raise ValueError(f"an angle is outside the kernel's range +-{MAX_ANGLE}")
    fn = np.floor(x * INV_PIO2 + 0.5)
    r = x - fn * PIO2_1
    w = fn * PIO2_2
    t = r
    r = t - w
    w = fn * PIO2_2T - ((t - r) - w)
    y0 = r - w
    y1 = (r - y0) - w
    z = y0 * y0
    w = z * z
    v = z * y0
    r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    s = y0 - ((z * (0.5 * y1 - v * r) - y1) - v * S1)
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + (z * r - y0 * y1))
    quadrant = fn.astype(np.int64) & 3
    odd = (quadrant & 1).astype(bool)
    # Multiplying by +-1 is exact: the same as the scalar form's negations.
    sine: FloatArray = np.where(odd, c, s) * _SINE_SIGN[quadrant]
    cosine: FloatArray = np.where(odd, s, c) * _COSINE_SIGN[quadrant]
    return sine, cosine


# --- atan and atan2 ------------------------------------------------------------------------


def atan2(y: float, x: float) -> float:
    """The angle of the point (x, y), in [-pi, pi]; signed zeros as in C's atan2.

    z = atan(a) for a = |y / x| by fdlibm's reduction to one of five intervals and its odd
    polynomial of degree 23 in two halves; then pi - (z - PI_LO) if x < 0; with the sign
    of y. Written out in one function: the navigator calls it every step.
    """
    ax = abs(x)
    ay = abs(y)
    if not (0.0 < ax < math.inf and 0.0 < ay < math.inf):  # true for NaN too
        return _atan2_special(y, x)
    a = ay / ax
    if a >= ATAN_BIG:
        z = ATAN_HI_3
    elif a < 0.4375:
        zz = a * a
        w = zz * zz
        s1 = zz * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))))
        s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))))
        z = a - a * (s1 + s2)
    else:
        if a < 0.6875:
            hi, lo, t = ATAN_HI_0, ATAN_LO_0, (2.0 * a - 1.0) / (2.0 + a)
        elif a < 1.1875:
            hi, lo, t = ATAN_HI_1, ATAN_LO_1, (a - 1.0) / (a + 1.0)
        elif a < 2.4375:
            hi, lo, t = ATAN_HI_2, ATAN_LO_2, (a - 1.5) / (1.0 + 1.5 * a)
        else:
            hi, lo, t = ATAN_HI_3, ATAN_LO_3, -1.0 / a
        zz = t * t
        w = zz * zz
        s1 = zz * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))))
        s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))))
        z = hi - ((t * (s1 + s2) - lo) - t)
    if x < 0.0:
        z = PI - (z - PI_LO)
    return z if y > 0.0 else -z


def _atan2_special(y: float, x: float) -> float:
    """``atan2`` where x or y is zero, infinite or NaN."""
    if math.isnan(x) or math.isnan(y):
        return x + y
    x_negative = math.copysign(1.0, x) < 0.0
    if y == 0.0:
        return math.copysign(PI, y) if x_negative else y
    if x == 0.0:
        return math.copysign(HALF_PI, y)
    if math.isinf(x):
        if math.isinf(y):
            z = 3.0 * PI / 4.0 if x_negative else PI / 4.0
        else:
            z = PI if x_negative else 0.0
        return math.copysign(z, y)
    return math.copysign(HALF_PI, y)  # y is infinite, x finite


def atan(x: float) -> float:
    """The arc tangent, in [-pi/2, pi/2]: atan2(|x|, 1) with the sign of x (the same
    steps for a = |x|); NaN for NaN, +-0 for +-0, +-pi/2 for +-inf."""
    if math.isnan(x) or x == 0.0:
        return x
    if math.isinf(x):
        return math.copysign(ATAN_HI_3, x)
    return math.copysign(atan2(abs(x), 1.0), x)


# --- exp, log, power ---------------------------------------------------------------------


def exp(x: float) -> float:
    """e to the x (inf above ``EXP_OVERFLOW``, 0 below ``EXP_UNDERFLOW``)."""
    if math.isnan(x):
        return x
    if x > EXP_OVERFLOW:
        return math.inf
    if x < EXP_UNDERFLOW:
        return 0.0
    k = math.floor(x * INV_LN2 + 0.5)
    hi = x - k * LN2_HI
    lo = k * LN2_LO
    r = hi - lo
    rr = r * r
    c = r - rr * (P1 + rr * (P2 + rr * (P3 + rr * (P4 + rr * P5))))
    y = 1.0 + ((r * c / (2.0 - c) - lo) + hi)
    return math.ldexp(y, int(k))


def exp_array(x: FloatArray) -> FloatArray:
    """``exp`` of every element (the same operations, so the same bits)."""
    x = np.asarray(x, dtype=np.float64)
    inside = (x >= EXP_UNDERFLOW) & (x <= EXP_OVERFLOW)
    x_in = np.where(inside, x, 0.0)
    k = np.floor(x_in * INV_LN2 + 0.5)
    hi = x_in - k * LN2_HI
    lo = k * LN2_LO
    r = hi - lo
    rr = r * r
    c = r - rr * (P1 + rr * (P2 + rr * (P3 + rr * (P4 + rr * P5))))
    y = 1.0 + ((r * c / (2.0 - c) - lo) + hi)
    result: FloatArray = np.ldexp(y, k.astype(np.int32))
    outside = np.where(x > EXP_OVERFLOW, math.inf, np.where(x < EXP_UNDERFLOW, 0.0, x))
    return np.where(inside, result, outside)


def log(x: float) -> float:
    """The natural logarithm (-inf at 0, NaN below 0, inf at inf)."""
    if math.isnan(x) or x == math.inf:
        return x
    if x <= 0.0:
        return -math.inf if x == 0.0 else math.nan
    m, k = math.frexp(x)
    if m < SQRT_HALF:
        m = 2.0 * m
        k -= 1
    f = m - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (LG2 + w * (LG4 + w * LG6))
    t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)))
    r = t2 + t1
    dk = float(k)
    return (((s * (hfsq + r) + dk * LN2_LO) - hfsq) + f) + dk * LN2_HI


def log_array(x: FloatArray) -> FloatArray:
    """``log`` of every element (the same operations, so the same bits)."""
    x = np.asarray(x, dtype=np.float64)
    finite_positive = np.isfinite(x) & (x > 0.0)
    m, k = np.frexp(np.where(finite_positive, x, 1.0))
    low = m < SQRT_HALF
    m = np.where(low, 2.0 * m, m)
    dk = (k - low).astype(np.float64)
    f = m - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (LG2 + w * (LG4 + w * LG6))
    t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)))
    r = t2 + t1
    result: FloatArray = (((s * (hfsq + r) + dk * LN2_LO) - hfsq) + f) + dk * LN2_HI
    special = np.where(x == 0.0, -math.inf, np.where(x > 0.0, x, math.nan))
    return np.where(finite_positive, result, special)


def power(x: float, y: float) -> float:
    """x to the y for x >= 0, as exp(y log x) (within a few ulp; 0 ** y = 0 for y > 0)."""
    if not x >= 0.0:
        raise ValueError(f"power takes x >= 0, got {x!r}")
    if y == 0.0:
        return 1.0
    if x == 0.0:
        return 0.0 if y > 0.0 else math.inf
    return exp(y * log(x))


# --- helpers built on them ----------------------------------------------------------------


def hypot(x: float, y: float) -> float:
    """The length of (x, y): sqrt(x * x + y * y) (no guard against overflow)."""
    return math.sqrt(x * x + y * y)


def wrap_angle(angle: float) -> float:
    """``angle`` less the nearest multiple of 2 pi: in [-pi, pi], give or take an ulp."""
    k = math.floor(angle * INV_TWO_PI + 0.5)
    return (angle - k * TWO_PI_HI) - k * TWO_PI_LO


def wrap_angle_array(angle: FloatArray) -> FloatArray:
    """``wrap_angle`` of every element."""
    k = np.floor(angle * INV_TWO_PI + 0.5)
    wrapped: FloatArray = (angle - k * TWO_PI_HI) - k * TWO_PI_LO
    return wrapped


__all__ = [
    "HALF_PI",
    "MAX_ANGLE",
    "PI",
    "TWO_PI",
    "atan",
    "atan2",
    "cos",
    "exp",
    "exp_array",
    "hypot",
    "log",
    "log_array",
    "power",
    "sin",
    "sincos",
    "sincos_array",
    "wrap_angle",
    "wrap_angle_array",
]
