"""Writes c_robot/tests/cases.json: what CPython and msgspec give for math.fsum, the wire's
float spelling, wire_opinion's 9 digits and round() (run with the project's venv:
.venv/bin/python c_robot/tests/make_cases.py). The C unit tests compare with it."""

import json
import math
import random
import struct
from pathlib import Path

import msgspec

from bestofn_swarm.wire import protocol


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
        values = [
            rng.random() * 10 ** rng.randrange(-20, 20) * rng.choice((-1, 1)) for _ in range(n)
        ]
    elif kind == 2:
        w = [rng.random() for _ in range(n)]
        t = sum(w)
        values = [x / t for x in w]
    else:
        values = [float(f"{rng.random():.9g}") for _ in range(n)]
    fsum_cases.append({"in": [bits(v) for v in values], "out": bits(math.fsum(values))})

format_cases = []
numbers = [
    0.0,
    -0.0,
    1.0,
    1e16,
    1e15,
    9999999999999998.0,
    1.5e-7,
    1e-5,
    1.5e-5,
    9.999999999999999e-06,
    1795000000.5,
    123456789012345678.0,
    1e-300,
    5e-324,
    1.7976931348623157e308,
    0.1,
    -2.5,
    100.0,
    1e22,
    2.0**-1022,
    2.0**-1074 * 3,
    2.0**60,
    2.0**-30,
    2.0**100,
    0.13,
    0.333333333,
    2.675,
    0.0005,
    8.5,
    9.5,
    0.12345,
]
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

# --- the decision math and parking (robot_agent/core/decision.py, parking.py) -------------
from bestofn_swarm.wire import numeric  # noqa: E402
from bestofn_swarm.wire.rng import Stream  # noqa: E402
from robot_agent.core import decision  # noqa: E402
from robot_agent.core.controller_config import ControllerConfig  # noqa: E402
from robot_agent.core.parking import inner_radius, parking_slot  # noqa: E402
from world_server.core.layout import make_layout  # noqa: E402


def bitlist(values):
    return [bits(v) for v in values]


def opinion_of(n, zeros):
    values = [rng.random() for _ in range(n)]
    for i in rng.sample(range(n), min(zeros, n - 1)):
        values[i] = 0.0
    return decision.normalised(values)


decision_cases = []
for _ in range(300):
    n = rng.choice((2, 3, 5, 10, 37, 100))
    kind = rng.randrange(5)
    if kind == 0:
        opinion = opinion_of(n, rng.randrange(n))
        eliminated = rng.randrange(n)
        alpha = rng.choice((0.0, 0.0, 0.1, 0.25, 0.5))
        out = decision.negative_update(opinion, eliminated, alpha)
        decision_cases.append(
            {"op": "negative_update", "opinion": bitlist(opinion), "eliminated": eliminated,
             "alpha": bits(alpha), "out": bitlist(out)}
        )  # fmt: skip
    elif kind in (1, 2):
        count = rng.choice((1, 2, 3, 8, 40))
        pool = [
            protocol.wire_opinion(opinion_of(n, rng.randrange(n) if rng.random() < 0.5 else 0))
            for _ in range(count)
        ]
        if rng.random() < 0.3:  # tiny probabilities: the product must not underflow
            pool = [[max(v, 0.0) ** 3 for v in o] for o in pool]
            pool = [o if max(o) > 0 else [1.0] * n for o in pool]
        op = "mprodop" if kind == 1 else "loglinear"
        out = decision.mprodop(pool) if kind == 1 else decision.loglinear_pool(pool)
        decision_cases.append(
            {
                "op": op,
                "pool": [bitlist(o) for o in pool],
                "out": None if out is None else bitlist(out),
            }
        )
    elif kind == 3:
        opinion = opinion_of(n, rng.randrange(n))
        seed = rng.getrandbits(64)
        stream = Stream(seed)
        first, second = decision.choose_pair(opinion, stream)
        decision_cases.append(
            {"op": "choose_pair", "opinion": bitlist(opinion), "seed": f"{seed:016x}",
             "out": [first, second], "state_after": f"{stream.state:016x}"}
        )  # fmt: skip
    else:
        opinion = opinion_of(n, rng.randrange(n))
        if rng.random() < 0.3:
            opinion = [0.0] * n
            opinion[rng.randrange(n)] = 1.0
        threshold = rng.choice((1.0, 0.99, 0.5, 0.3))
        out = decision.decided_option(opinion, threshold)
        decision_cases.append(
            {"op": "decided_option", "opinion": bitlist(opinion), "threshold": bits(threshold),
             "out": -1 if out is None else out}
        )  # fmt: skip

parking_cases = []
config = ControllerConfig()
for robots, sites in ((10, 5), (10, 10), (100, 10), (200, 10), (500, 10), (500, 100), (50, 100)):
    layout = make_layout(sites, robots, seed=robots + sites)
    angles = [numeric.atan2(s.y, s.x) for s in sorted(layout.info_sites(), key=lambda s: s.id)]
    world = {
        "arena_radius": bits(layout.arena_radius),
        "nest_radius": bits(layout.nest_radius),
        "sites": [[bits(s.x), bits(s.y)] for s in sorted(layout.info_sites(), key=lambda s: s.id)],
    }
    slots = []
    for robot in sorted({0, 1, 7, robots - 1, robots // 2, 3 * robots + 5, 99999}):
        for site in sorted({0, sites - 1, sites // 2}):
            x, y = parking_slot(
                angles, site, robot, arena_radius=layout.arena_radius,
                inner_radius=inner_radius(layout.nest_radius, 0.037), robot_radius=0.037,
                clearance=config.park_clearance, spacing=config.park_spacing,
                corridor=config.park_corridor, lane=config.park_lane,
            )  # fmt: skip
            slots.append([robot, site, bits(x), bits(y)])
    parking_cases.append({"robots": robots, "world": world, "slots": slots})

data = json.loads(Path(__file__).with_name("cases.json").read_text())
data["decision"] = decision_cases
data["parking"] = parking_cases
Path(__file__).with_name("cases.json").write_text(json.dumps(data, indent=0) + "\n")
print(len(decision_cases), "decision cases,", len(parking_cases), "parking worlds")
