"""Writes c_robot/tests/cases.json: what CPython and msgspec give for math.fsum, the wire's
float spelling, wire_opinion's 9 digits and round() (run with the project's venv:
.venv/bin/python c_robot/tests/make_cases.py). The C unit tests compare with it."""

import json
import math
import random
import struct
from pathlib import Path

import msgspec

from wire import protocol


def bits(x: float) -> str:
    if math.isnan(x):
        return "nan"
    return struct.pack(">d", x).hex()


rng = random.Random(20240601)
fsum_cases = []
special = [
    [1e-16, 1.0, 1e16],
    [0.1] * 10,
    [1e308, 1e308, -1e308],
    [1.0, 1e100, 1.0, -1e100],
    [2.0**53, 1.0, 1.0],
    [0.25, 0.25, 0.25, 0.25],
    [1 / 3, 1 / 3, 1 / 3],
    [5e-324, 5e-324, -5e-324],
    [],
    [0.0, -0.0],
    [-0.0],
    [1e308, 1e308],
]
for values in special:
    try:
        out = bits(math.fsum(values))
    except OverflowError:
        out = "overflow"
    fsum_cases.append({"in": [bits(v) for v in values], "out": out})
for _ in range(400):
    n = rng.randrange(1, 60)
    kind = rng.randrange(4)
    if kind == 0:
        values = [rng.random() for _ in range(n)]
    elif kind == 1:
        values = [rng.random() * 10 ** rng.randrange(-20, 20) * rng.choice((-1, 1)) for _ in range(n)]
    elif kind == 2:
        w = [rng.random() for _ in range(n)]
        t = sum(w)
        values = [x / t for x in w]
    else:
        values = [float(f"{rng.random():.9g}") for _ in range(n)]
    fsum_cases.append({"in": [bits(v) for v in values], "out": bits(math.fsum(values))})

format_cases = []
numbers = [0.0, -0.0, 1.0, 1e16, 1e15, 9999999999999998.0, 1.5e-7, 1e-5, 1.5e-5,
           9.999999999999999e-06, 1795000000.5, 123456789012345678.0, 1e-300, 5e-324,
           1.7976931348623157e308, 0.1, -2.5, 100.0, 1e22, 2.0**-1022, 2.0**-1074 * 3,
           2.0**60, 2.0**-30, 2.0**100, 0.13, 0.333333333, 2.675, 0.0005, 8.5, 9.5, 0.12345]
for _ in range(3000):
    kind = rng.randrange(4)
    if kind == 0:
        numbers.append(rng.random())
    elif kind == 1:
        numbers.append(rng.random() * 10 ** rng.randrange(-30, 30) * rng.choice((-1, 1)))
    elif kind == 2:
        numbers.append(struct.unpack(">d", struct.pack(">Q", rng.getrandbits(63)))[0])
    else:
        numbers.append(2.0 ** rng.randrange(-1074, 1023))
for x in numbers:
    if not math.isfinite(x):
        continue
    try:
        r = float(round(x * 1000.0))
    except OverflowError:
        continue
    format_cases.append(
        {
            "in": bits(x),
            "msgspec": msgspec.json.encode(x).decode(),
            "wire9": bits(protocol.wire_opinion([x])[0]),
            "round1000": bits(r),
        }
    )

Path(__file__).with_name("cases.json").write_text(
    json.dumps({"fsum": fsum_cases, "format": format_cases}, indent=0) + "\n"
)
print(len(fsum_cases), "fsum cases,", len(format_cases), "format cases")
