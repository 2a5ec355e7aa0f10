"""Where are the robots that never decide, and what holds them? (large swarms)

Runs one lockstep swarm in one process (``deploy.inprocess.engine.run_in_process``: the same
world, controllers and beacon as ``swarm run``) and watches it: once a second of sim time
it samples every robot's pose and phase. At the end (``--until`` sim seconds, or
consensus) it prints, for every robot still undecided: its phase, trips, position, what
its navigator is doing (goal, escapes, last progress), and every robot within 0.25 m
(phase, decided site, when it stopped there); and it plots the arena at that moment:
robots by phase, the slots decided robots park in, the viewpoints, the sites, the trail of each
undecided robot, and a close-up of each.

    .venv/bin/python benchmarks/stall_diagnosis.py --robots 200 --seed 0 --until 1500 \
        --plot docs/stall-200-seed0.png

The controller's private state is read here on purpose: this is a diagnostic.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from deploy.inprocess.engine import run_in_process  # noqa: E402
from robot_agent.core.controller import Controller, ControllerConfig  # noqa: E402
from world_server.core.world import World, WorldConfig  # noqa: E402

NEIGHBOUR_RANGE = 0.25  # metres: who counts as "around" a stuck robot
LOOK_BACK = 200.0  # sim seconds of trail printed from before the current leg
PHASE_COLOURS = {
    "to_site": "tab:blue",
    "sensing": "tab:cyan",
    "to_nest": "tab:orange",
    "waiting": "tab:olive",
    "at_nest": "tab:green",
    "lingering": "tab:pink",
    "to_decision": "tab:purple",
    "stopped": "0.6",
}


@dataclass
class Watch:
    """What the diagnostic saw, once a second of sim time."""

    controllers: dict[int, Controller] = field(default_factory=dict)
    trails: dict[int, list[tuple[float, float, float, str]]] = field(default_factory=dict)
    stopped_at: dict[int, float] = field(default_factory=dict)
    undecided: list[tuple[float, int]] = field(default_factory=list)
    last_sample: float = -math.inf
    world: World | None = None


def watch_run(robots: int, sites: int, seed: int, until: float) -> tuple[Watch, dict]:
    watch = Watch()

    class Observed(Controller):
        def __init__(self, robot_id: int, *args: Any, **kwargs: Any) -> None:
            super().__init__(robot_id, *args, **kwargs)
            watch.controllers[robot_id] = self

    def on_tick(world: World) -> None:
        watch.world = world
        if world.t - watch.last_sample < 1.0 - 1e-9:
            return
        watch.last_sample = world.t
        for robot_id, (x, y, _) in world.physics.poses().items():
            controller = watch.controllers[robot_id]
            watch.trails.setdefault(robot_id, []).append((world.t, x, y, controller.phase))
            if controller.phase == "stopped" and robot_id not in watch.stopped_at:
                watch.stopped_at[robot_id] = world.t
        undecided = sum(c.decided_site is None for c in watch.controllers.values())
        watch.undecided.append((world.t, undecided))
        if round(world.t) % 250 == 0:
            print(f"  t = {world.t:6.0f} s: {undecided} undecided", flush=True)

    summary = run_in_process(
        WorldConfig(num_robots=robots, num_sites=sites, seed=seed),
        ControllerConfig(),
        timeout=until,
        on_tick=on_tick,
        controller_factory=Observed,
    )
    return watch, summary


def describe_swarm(watch: Watch) -> None:
    """Print the swarm as a whole: decisions, what undecided robots still believe, who
    stands at each viewpoint, and decided robots that stopped short of their slot."""
    assert watch.world is not None
    world = watch.world
    poses = world.physics.poses()
    controllers = watch.controllers
    decided = Counter(c.decided_site for c in controllers.values() if c.decided_site is not None)
    undecided = [c for c in controllers.values() if c.decided_site is None]
    print(f"decided, by site: {dict(sorted(decided.items()))}; undecided: {len(undecided)}")
    print(f"  undecided by phase: {dict(Counter(c.phase for c in undecided))}")
    supports = Counter(
        tuple(site for site, p in enumerate(c.opinion) if p > 0.0) for c in undecided
    )
    print(f"  undecided by the sites they still hold possible: {dict(supports.most_common(8))}")
    config = ControllerConfig()
    view_radius = world.info.arena_radius - config.view_distance
    for site in world.info.sites:
        angle = math.atan2(site.y, site.x)
        view = (view_radius * math.cos(angle), view_radius * math.sin(angle))
        near = sorted(
            (math.dist(view, pose[:2]), robot)
            for robot, pose in poses.items()
            if math.dist(view, pose[:2]) < NEIGHBOUR_RANGE
        )
        print(
            f"  viewpoint of site {site.id}"
            + (" (best)" if site.id == world.layout.best_site else "")
            + ": "
            + ", ".join(
                f"{robot} {distance:.2f} m {controllers[robot].phase}" for distance, robot in near
            )
        )
    short = [
        (robot, math.dist(poses[robot][:2], c._parking.slot))
        for robot, c in controllers.items()
        if c.phase == "stopped"
        and c._parking.slot is not None
        and math.dist(poses[robot][:2], c._parking.slot) > 2 * world.info.robot_radius
    ]
    print(f"  decided robots stopped more than a body width from their slot: {len(short)}")
    for robot, distance in sorted(short, key=lambda item: -item[1])[:10]:
        x, y, _ = poses[robot]
        print(
            f"    {robot}: {distance:.2f} m short, at r = {math.hypot(x, y):.2f}, "
            f"{math.degrees(math.atan2(y, x)):.0f} deg"
        )


def describe_stuck(watch: Watch, show: int) -> list[int]:
    """Print what holds the first ``show`` undecided robots; return all their ids."""
    assert watch.world is not None
    world = watch.world
    poses = world.physics.poses()
    stuck = [r for r, c in sorted(watch.controllers.items()) if c.decided_site is None]
    print(
        f"arena radius {world.info.arena_radius:.3f} m, nest radius {world.info.nest.radius:.3f}"
        f" m, best site {world.layout.best_site}, sites at "
        + ", ".join(
            f"{i}: {math.degrees(s.angle):.0f} deg" for i, s in enumerate(world.layout.sites)
        )
    )
    for robot_id in stuck[:show]:
        controller = watch.controllers[robot_id]
        x, y, _ = poses[robot_id]
        trail = watch.trails[robot_id]
        # When it last moved more than a body length (its last real progress).
        moved_at = trail[0][0]
        for t, tx, ty, _ in reversed(trail):
            if math.hypot(tx - x, ty - y) > 2 * world.info.robot_radius:
                moved_at = t
                break
        print(
            f"\nrobot {robot_id}: phase {controller.phase}, trips {controller.trips}, opinion "
            f"{[round(p, 3) for p in controller.opinion]}, at "
            f"({x:.3f}, {y:.3f}) r = {math.hypot(x, y):.3f} m, "
            f"{math.degrees(math.atan2(y, x)):.1f} deg; leg since "
            f"{controller._motion.leg_start:.1f} s, pair left {controller._pair}, "
            f"navigator escapes {controller._motion.escapes}; within a body length of here since "
            f"{moved_at:.0f} s"
        )
        around = []
        for other, (ox, oy, _) in poses.items():
            distance = math.hypot(ox - x, oy - y)
            if other != robot_id and distance < NEIGHBOUR_RANGE:
                around.append((distance, other))
        for distance, other in sorted(around):
            ox, oy, _ = poses[other]
            neighbour = watch.controllers[other]
            print(
                f"  {other:4d} {distance:.3f} m away, r = {math.hypot(ox, oy):.3f}, "
                f"{math.degrees(math.atan2(oy, ox)):7.1f} deg, {neighbour.phase}, "
                f"decided {neighbour.decided_site}, stopped at "
                f"{watch.stopped_at.get(other, float('nan')):.0f} s"
            )
        # How it got here: the trail from before this leg began, with each phase change.
        before = [p for p in trail if p[0] >= controller._motion.leg_start - LOOK_BACK]
        print("  trail (sim s: x, y, phase):", end="")
        previous = ""
        for number, (t, tx, ty, phase) in enumerate(before):
            if phase != previous or number % 10 == 0:
                print(f"\n    {t:.0f}: ({tx:.2f}, {ty:.2f}) {phase}", end="")
                previous = phase
        print()
    return stuck


def plot(watch: Watch, stuck: list[int], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    assert watch.world is not None
    world = watch.world
    info = world.info
    config = ControllerConfig()
    poses = world.physics.poses()
    close_ups = stuck[:3]
    fig, axes = plt.subplots(
        1, 1 + len(close_ups), figsize=(7 + 5 * len(close_ups), 7), squeeze=False
    )
    # The slots decided robots drive to (the controller's own choice, whatever the rule).
    slots = [c._parking.slot for c in watch.controllers.values() if c._parking.slot is not None]
    view_radius = info.arena_radius - config.view_distance
    for index, ax in enumerate(axes[0]):
        ax.add_patch(Circle((0, 0), info.arena_radius, fill=False, color="k"))
        ax.add_patch(Circle((0, 0), info.nest.radius, fill=False, color="g", ls="--"))
        if slots:
            ax.plot(*zip(*slots, strict=True), "x", color="0.5", ms=3, label="parking slots")
        for site in info.sites:
            angle = math.atan2(site.y, site.x)
            best = site.id == world.layout.best_site
            ax.plot(site.x, site.y, "s", color="red" if best else "k", ms=6)
            ax.plot(view_radius * math.cos(angle), view_radius * math.sin(angle), "+", color="r")
        for robot_id, (x, y, _) in poses.items():
            phase = watch.controllers[robot_id].phase
            ax.add_patch(
                Circle((x, y), info.robot_radius, color=PHASE_COLOURS[phase], alpha=0.8, lw=0)
            )
            if robot_id in stuck and index > 0:
                ax.annotate(str(robot_id), (x, y), fontsize=7, ha="center", va="center")
            elif index > 0:
                ax.annotate(str(robot_id), (x, y), fontsize=5, ha="center", va="center")
        for robot_id in stuck:
            # Its trail since the current leg began.
            since = watch.controllers[robot_id]._motion.leg_start
            trail = [p for p in watch.trails[robot_id] if p[0] >= since]
            ax.plot([p[1] for p in trail], [p[2] for p in trail], "-", lw=0.6)
        ax.set_aspect("equal")
        if index == 0:
            ax.set_title(f"t = {world.t:.0f} s: {len(stuck)} undecided")
            for name, colour in PHASE_COLOURS.items():
                ax.plot([], [], "o", color=colour, label=name)
            ax.legend(fontsize=6, loc="upper right")
        else:
            robot_id = close_ups[index - 1]
            x, y, _ = poses[robot_id]
            ax.set_xlim(x - 0.4, x + 0.4)
            ax.set_ylim(y - 0.4, y + 0.4)
            ax.set_title(f"robot {robot_id} ({watch.controllers[robot_id].phase})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=200)
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--until", type=float, default=3000.0, help="sim seconds")
    parser.add_argument("--plot", type=Path, help="write the arena at the end here (PNG)")
    parser.add_argument("--show", type=int, default=5, help="undecided robots to detail")
    args = parser.parse_args()
    started = time.monotonic()
    watch, summary = watch_run(args.robots, args.sites, args.seed, args.until)
    print(
        f"consensus {summary['consensus']}, correct {summary['correct']}, sim time "
        f"{summary['sim_time_s']} s, wall {time.monotonic() - started:.0f} s"
    )
    describe_swarm(watch)
    stuck = describe_stuck(watch, args.show)
    if args.plot:
        plot(watch, stuck, args.plot)


if __name__ == "__main__":
    main()
