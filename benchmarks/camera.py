"""Time the camera pipeline: render, PNG encode (world side), decode, estimate (robot side).

Prints microseconds per frame for each stage and the total, then what it would cost if
``--robots`` robots all captured in the same control tick: the world's share (render +
encode, done serially in the world server) and the whole pipeline's, as a share of one
``--tick``. Usage:

    .venv/bin/python benchmarks/camera.py [--sites 100] [--robots 100] [--frames 3000]

With ``--accuracy`` it prints instead how far estimates fall from the true qualities
with noise off (over perturbed viewpoints) and with pixel noise or lighting variation on.
"""

from __future__ import annotations

import argparse
import itertools
import math
import statistics
import time
from collections.abc import Callable

import numpy as np

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core.vision import decode_frame, estimate_quality
from world_server.core.camera import CameraNoise, CameraRenderer
from world_server.core.layout import make_layout


def per_call_us(action: Callable[[], object], calls: int, repeats: int = 5) -> tuple[float, float]:
    """(best, median) over ``repeats`` of the mean time of ``calls`` calls, in us.

    The best sample is the cost on an idle core; the median shows what a busy machine adds.
    """
    action()  # warm caches and lazy initialisation
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            action()
        samples.append((time.perf_counter() - start) / calls * 1e6)
    return min(samples), statistics.median(samples)


def accuracy(spec: protocol.CameraSpec, site_counts: list[int]) -> None:
    """Print estimate errors: clean over perturbed poses, then under each kind of noise."""
    perturbations = list(
        itertools.product(
            (-0.03, 0.0, 0.03), (-math.radians(10), 0.0, math.radians(10)), (-0.02, 0.0, 0.02)
        )
    )
    noises = [CameraNoise(pixel_sigma=s) for s in (5.0, 10.0, 20.0, 30.0, 50.0, 80.0)]
    noises += [CameraNoise(lighting=a) for a in (0.05, 0.1, 0.2, 0.3)]
    for num_sites in site_counts:
        layout = make_layout(num_sites, 10, seed=7)
        half_step = 0.5 / (num_sites - 1)
        renderer = CameraRenderer(layout, spec)
        errors, missing = [], 0
        for site, (sideways, heading, distance) in itertools.product(layout.sites, perturbations):
            pose = layout.sensing_pose(site.id, 0.15 + distance, sideways, heading)
            estimate = estimate_quality(renderer.render(*pose))
            if estimate is None:
                missing += 1
            else:
                errors.append(abs(estimate - site.quality))
        print(f"n = {num_sites}: half a quality step = {half_step:.4f}")
        print(
            f"  no noise, {len(perturbations)} poses per site (+-3 cm, +-10 deg, +-2 cm): "
            f"max |error| {max(errors):.4f}, no reading {missing}"
        )
        frames_per_site = max(1, 200 // num_sites)
        for noise in noises:
            renderer = CameraRenderer(layout, spec, noise=noise, seed=3)
            rng = Stream(1)
            errors, missing = [], 0
            for site in layout.sites:
                for _ in range(frames_per_site if noise.pixel_sigma > 0 else 1):
                    estimate = estimate_quality(
                        renderer.render(*layout.sensing_pose(site.id), rng=rng)
                    )
                    if estimate is None:
                        missing += 1
                    else:
                        errors.append(abs(estimate - site.quality))
            wrong_side = sum(error >= half_step for error in errors)
            label = (
                f"pixel_sigma {noise.pixel_sigma:g}"
                if noise.pixel_sigma > 0
                else f"lighting {noise.lighting:g}"
            )
            print(
                f"  {label:<17} mean |error| {np.mean(errors):.4f}  max {max(errors):.4f}  "
                f">= half step {wrong_side}/{len(errors)}  no reading {missing}"
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sites", type=int, default=100)
    parser.add_argument("--robots", type=int, default=100)
    parser.add_argument("--frames", type=int, default=3000, help="calls per timing sample")
    parser.add_argument("--width", type=int, default=64)
    parser.add_argument("--height", type=int, default=48)
    parser.add_argument("--pixel-sigma", type=float, default=0.0)
    parser.add_argument("--tick", type=float, default=0.1, help="control tick in seconds")
    parser.add_argument(
        "--accuracy", action="store_true", help="print estimate errors instead of timings"
    )
    parser.add_argument("--accuracy-sites", type=int, nargs="+", default=[10, 100])
    args = parser.parse_args(argv)
    if args.accuracy:
        accuracy(
            protocol.CameraSpec(width=args.width, height=args.height, fov=0.84), args.accuracy_sites
        )
        return 0

    layout = make_layout(args.sites, args.robots, seed=1)
    spec = protocol.CameraSpec(width=args.width, height=args.height, fov=0.84)
    renderer = CameraRenderer(layout, spec, noise=CameraNoise(pixel_sigma=args.pixel_sigma))
    site = layout.site(1)
    radius = layout.arena_radius - 0.15
    pose = (radius * math.cos(site.angle), radius * math.sin(site.angle), site.angle)
    # Every other robot at its start pose plus one just in front: the renderer must cull
    # the swarm and still draw the occluder.
    others = [(x, y) for x, y, _ in layout.start_poses[1:]]
    others.append(
        (
            pose[0] + 0.08 * math.cos(site.angle) + 0.05 * math.sin(site.angle),
            pose[1] + 0.08 * math.sin(site.angle) - 0.05 * math.cos(site.angle),
        )
    )
    rng = Stream(0)

    image = renderer.render(*pose, rng=rng)
    data = renderer.encode(image)
    frame = decode_frame(data)
    estimate = estimate_quality(frame)

    stages = {
        "render": per_call_us(lambda: renderer.render(*pose, rng=rng), args.frames),
        "render, swarm in scene": per_call_us(
            lambda: renderer.render(*pose, others=others, rng=rng), args.frames
        ),
        "encode (PNG)": per_call_us(lambda: renderer.encode(image), args.frames),
        "decode": per_call_us(lambda: decode_frame(data), args.frames),
        "estimate": per_call_us(lambda: estimate_quality(frame), args.frames),
    }

    def cost(names: tuple[str, ...], column: int) -> float:
        return sum(stages[name][column] for name in names)

    world = ("render, swarm in scene", "encode (PNG)")
    pipeline = (*world, "decode", "estimate")
    tick_us = args.tick * 1e6

    print(
        f"camera {args.width}x{args.height}, n = {args.sites} sites, "
        f"pixel_sigma = {args.pixel_sigma}, frame {len(data)} bytes, "
        f"estimate {estimate:.4f} (true {site.quality:.4f})"
    )
    print(f"  {'stage':<24} {'best':>8} {'median':>8}   (us per frame)")
    for name, (best, median) in stages.items():
        print(f"  {name:<24} {best:8.1f} {median:8.1f}")
    print(
        f"  {'total':<24} {cost(pipeline, 0):8.1f} {cost(pipeline, 1):8.1f}"
        "   (render with swarm + encode + decode + estimate)"
    )
    print(
        f"{args.robots} robots capturing in one {args.tick * 1000:.0f} ms tick "
        "(best / median, one core):"
    )
    for label, names in (("world server (render + encode)", world), ("whole pipeline", pipeline)):
        best, median = (args.robots * cost(names, column) for column in (0, 1))
        print(
            f"  {label:<31} {best / 1000:6.2f} / {median / 1000:6.2f} ms"
            f" = {100 * best / tick_us:5.2f} / {100 * median / tick_us:5.2f} % of the tick"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
