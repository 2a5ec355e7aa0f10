"""Cost of the world's pure modules: one physics control tick, one radio tick.

Physics: robots start on the layout's rings around the nest and wander with seeded
random wheel speeds (changed every 20 ticks); one tick is ``step(dt)`` plus
``proximity_all()``, timed after a warm-up so the swarm has spread and collided.
Contacts: how deep bodies sink into each other and into the wall (contacts exist only
once shapes overlap), with and without the ``max_substep`` cap: robots converge on the
nest at full speed, then the same swarm drives outwards into the wall.
Radio: 500 robots spread over their arena, 10% of them broadcast one 200-byte message a
tick; one tick is the transmits plus ``deliveries(tick)``.

Run: .venv/bin/python benchmarks/physics_radio.py [--ticks N] [--dt S] [--no-compare]
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import time

import numpy as np

from bestofn_swarm.wire import names
from world_server.core import layout
from world_server.core.physics import MAX_SUBSTEP, Physics, wrap_angle
from world_server.core.radio import RadioConfig, RadioMedium, sender_order

NUM_SITES = 10
WANDER_PERIOD = 20  # ticks between wheel changes


def make_world(
    num_robots: int, spatial_hash: bool, seed: int, max_substep: float | None = MAX_SUBSTEP
) -> tuple[Physics, random.Random]:
    arena = layout.make_layout(NUM_SITES, num_robots, seed)
    physics = Physics(arena.arena_radius, spatial_hash=spatial_hash, max_substep=max_substep)
    for robot_id, (x, y, theta) in enumerate(arena.start_poses):
        physics.add_robot(robot_id, x, y, theta)
    return physics, random.Random(seed)


def wander(physics: Physics, rng: random.Random) -> None:
    top = physics.spec.max_wheel_speed
    for robot_id in physics.robot_ids():
        physics.set_wheels(robot_id, rng.uniform(0.3, 1.0) * top, rng.uniform(0.3, 1.0) * top)


def time_physics(
    num_robots: int,
    ticks: int,
    dt: float,
    *,
    spatial_hash: bool,
    max_substep: float | None = MAX_SUBSTEP,
    seed: int = 1,
) -> tuple[float, float, int]:
    """Median and 95th percentile milliseconds of step + proximity_all, and substeps."""
    physics, rng = make_world(num_robots, spatial_hash, seed, max_substep)
    warm_up = 100
    samples = []
    for tick in range(warm_up + ticks):
        if tick % WANDER_PERIOD == 0:
            wander(physics, rng)
        start = time.perf_counter()
        physics.step(dt)
        physics.proximity_all()
        if tick >= warm_up:
            samples.append(1e3 * (time.perf_counter() - start))
    samples.sort()
    return statistics.median(samples), samples[int(0.95 * len(samples))], physics.substeps_for(dt)


def worst_contacts(
    num_robots: int, dt: float, max_substep: float | None, seed: int = 1
) -> tuple[float, float, float]:
    """Worst robot-robot overlap while converging, after settling, and wall penetration (mm)."""
    physics, _ = make_world(num_robots, True, seed, max_substep)
    radius = physics.spec.radius
    top = physics.spec.max_wheel_speed

    def overlap() -> float:
        xy = np.array([pose[:2] for pose in physics.poses().values()])
        gaps = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        np.fill_diagonal(gaps, np.inf)
        return 2 * radius - float(gaps.min())

    converging = []
    for _ in range(300):
        for robot_id, (x, y, theta) in physics.poses().items():
            error = wrap_angle(math.atan2(-y, -x) - theta)
            physics.set_wheels(robot_id, top - 0.1 * error, top + 0.1 * error)
        physics.step(dt)
        converging.append(overlap())
    penetration = 0.0
    for _ in range(600):
        for robot_id, (x, y, theta) in physics.poses().items():
            error = wrap_angle(math.atan2(y, x) - theta)
            physics.set_wheels(robot_id, top - 0.1 * error, top + 0.1 * error)
        physics.step(dt)
        farthest = max(math.hypot(x, y) for x, y, _ in physics.poses().values())
        penetration = max(penetration, farthest - (physics.arena_radius - radius))
    return 1e3 * max(converging), 1e3 * max(converging[-20:]), 1e3 * penetration


def time_radio(num_robots: int, ticks: int, senders_fraction: float, seed: int = 1) -> dict:
    """Per-tick milliseconds of transmit + deliveries, clean and with every fault on."""
    arena_radius = layout.arena_radius_for(num_robots, NUM_SITES)
    rng = random.Random(seed)
    positions = {}
    for robot_id in range(num_robots):
        # Uniform over the disc, inside the wall.
        radius = (arena_radius - 0.04) * math.sqrt(rng.random())
        angle = rng.uniform(-math.pi, math.pi)
        positions[names.robot_name(robot_id)] = (
            radius * math.cos(angle),
            radius * math.sin(angle),
        )
    everyone = sorted(positions, key=sender_order)
    payload = bytes(200)
    results = {}
    configs = {
        "clean": RadioConfig(),
        "all faults": RadioConfig(
            drop=0.05,
            latency=1,
            jitter=2,
            duplicate=0.05,
            reorder=True,
            burst_enter=0.05,
            burst_exit=0.3,
            burst_loss_bad=0.8,
            range_loss_start=0.7,
        ),
    }
    for label, config in configs.items():
        medium = RadioMedium(config, seed)
        samples = []
        copies = 0
        for tick in range(ticks):
            senders = sorted(
                rng.sample(everyone, int(senders_fraction * num_robots)), key=sender_order
            )
            start = time.perf_counter()
            for sender in senders:
                medium.transmit(tick, sender, tick, payload, positions[sender], "robot", positions)
            copies += len(medium.deliveries(tick))
            samples.append(1e3 * (time.perf_counter() - start))
        results[label] = (statistics.median(samples), copies / ticks)
    return results


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=300)
    parser.add_argument("--dt", type=float, default=0.1, help="control period, seconds")
    parser.add_argument(
        "--no-compare",
        action="store_true",
        help="skip the bounding-box-tree and plain-substeps comparisons",
    )
    args = parser.parse_args(argv)

    print(f"physics: step({args.dt}) + proximity_all(), {args.ticks} ticks after warm-up")
    print(f"{'robots':>7} {'index':>12} {'substeps':>9} {'median ms':>10} {'p95 ms':>8}")
    variants: list[tuple[bool, float | None]] = [(True, MAX_SUBSTEP)]
    if not args.no_compare:
        variants += [(False, MAX_SUBSTEP), (True, None)]
    for num_robots in (10, 100, 200, 500):
        for spatial_hash, max_substep in variants:
            median, p95, substeps = time_physics(
                num_robots, args.ticks, args.dt, spatial_hash=spatial_hash, max_substep=max_substep
            )
            index = "spatial hash" if spatial_hash else "bb-tree"
            print(f"{num_robots:>7} {index:>12} {substeps:>9} {median:>10.3f} {p95:>8.3f}")

    print()
    print(f"contacts: worst overlaps in mm at dt {args.dt} (robots converge, then hit the wall)")
    print(f"{'robots':>7} {'substeps':>9} {'converging':>11} {'settled':>8} {'wall':>6}")
    for num_robots in (50, 200):
        for max_substep in (MAX_SUBSTEP, None):
            converging, settled, wall = worst_contacts(num_robots, args.dt, max_substep)
            substeps = Physics(1.0, max_substep=max_substep).substeps_for(args.dt)
            print(f"{num_robots:>7} {substeps:>9} {converging:>11.1f} {settled:>8.1f} {wall:>6.1f}")
    print("  (pymunk's collision slop allows 1.0 mm of overlap at rest)")

    print()
    print("radio: 500 robots, 10% broadcast each tick, transmit + deliveries per tick")
    print(f"{'config':>12} {'median ms':>10} {'copies/tick':>12}")
    for label, (median, copies) in time_radio(500, args.ticks, 0.1).items():
        print(f"{label:>12} {median:>10.3f} {copies:>12.1f}")


if __name__ == "__main__":
    main()
