"""Where decided robots park, and that nobody can be walled in by them (issue 10).

Large swarms fill the wall and park on further rings. With the rings a body length
apart, robots parked on the second ring stood in front of the wall's slots: a robot in
an empty wall slot (one still on its way, or one pushed there by the crowd) could leave
only through gaps a few centimetres wider than itself, which its obstacle avoidance
cannot find, and 200-robot swarms never finished.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import pytest
from bodies import epuck_nav_params

from bestofn_swarm.wire.rng import Stream
from robot_agent.core.controller import ControllerConfig, parking_rings, parking_slot
from robot_agent.core.navigation import Navigator
from world_server.core.layout import make_layout
from world_server.core.physics import Physics

ROBOT_RADIUS = 0.037
CELL = 0.01  # metres per cell of the free-space map
# A path counts as open only if it keeps this far from every parked body: the navigator
# avoids what its sensors see, so a gap it must squeeze through is not a way out.
PASSING_MARGIN = 0.04


def slots_for(robots: int, site: int, config: ControllerConfig) -> list[tuple[float, float]]:
    layout = make_layout(10, robots, seed=0)
    return [
        parking_slot(
            [s.angle for s in layout.sites],
            site,
            robot,
            arena_radius=layout.arena_radius,
            inner_radius=layout.nest_radius + 3 * ROBOT_RADIUS,
            robot_radius=ROBOT_RADIUS,
            clearance=config.park_clearance,
            spacing=config.park_spacing,
            corridor=config.park_corridor,
            lane=config.park_lane,
        )
        for robot in range(robots)
    ]


def reachable_from_nest(arena_radius: float, parked: list[tuple[float, float]]) -> np.ndarray:
    """Map of where a robot's centre can get to from the nest, keeping ``PASSING_MARGIN``
    from every body in ``parked`` and its own body inside the wall (1 = reachable)."""
    size = 2 * math.ceil(arena_radius / CELL) + 1
    centre = size // 2
    free = np.zeros((size, size), np.uint8)
    cv2.circle(free, (centre, centre), int((arena_radius - ROBOT_RADIUS) / CELL), 1, -1)
    keep_out = math.ceil((2 * ROBOT_RADIUS + PASSING_MARGIN) / CELL)
    for x, y in parked:
        cv2.circle(free, (centre + round(x / CELL), centre + round(y / CELL)), keep_out, 0, -1)
    mask = np.zeros((size + 2, size + 2), np.uint8)
    cv2.floodFill(free, mask, (centre, centre), 2)
    return free == 2


def cell_of(point: tuple[float, float], arena_radius: float) -> tuple[int, int]:
    centre = math.ceil(arena_radius / CELL)
    return centre + round(point[1] / CELL), centre + round(point[0] / CELL)  # row, column


@pytest.mark.parametrize(("robots", "site"), [(10, 0), (100, 3), (200, 8), (500, 0), (500, 5)])
def test_every_slot_stays_reachable_whoever_is_already_parked(robots: int, site: int) -> None:
    """With every other robot of the swarm parked (the worst case: fewer parked robots
    only open more room), each robot can still drive from the nest to its own slot, and
    no free spot among the parked robots is cut off from the nest."""
    config = ControllerConfig()
    layout = make_layout(10, robots, seed=0)
    radius = layout.arena_radius
    slots = slots_for(robots, site, config)
    assert len(set(slots)) == robots  # a slot of its own for every robot, none shared
    for index, (x, y) in enumerate(slots):
        for other in slots[index + 1 :]:
            assert math.dist((x, y), other) >= 2 * ROBOT_RADIUS + 0.02  # no touching bodies

    reachable = reachable_from_nest(radius, slots)
    # Nothing free is enclosed: every spot a passing robot could stand on leads to the nest.
    everything_free = reachable_from_nest(radius, [])
    enclosed = everything_free & ~reachable
    for x, y in slots:  # (the parked bodies themselves are not free spots)
        row, column = cell_of((x, y), radius)
        keep_out = math.ceil((2 * ROBOT_RADIUS + PASSING_MARGIN) / CELL) + 1
        top, left = max(0, row - keep_out), max(0, column - keep_out)
        enclosed[top : row + keep_out + 1, left : column + keep_out + 1] = 0
    assert not enclosed.any()

    for robot, (x, y) in enumerate(slots):
        # The last stretch goes straight in from the slot's mouth, a passing margin inside
        # its neighbours' keep-out: nobody else's slot may lie on that stretch...
        slot_radius = math.hypot(x, y)
        depth = 2 * ROBOT_RADIUS + PASSING_MARGIN + 2 * CELL
        mouth = (x * (1 - depth / slot_radius), y * (1 - depth / slot_radius))
        for other_robot, other in enumerate(slots):
            if other_robot != robot:
                assert _distance_to_segment(other, (x, y), mouth) >= 2 * ROBOT_RADIUS - 1e-9, (
                    f"robot {other_robot} parks in the way of robot {robot}"
                )
        # ... and the mouth is reachable from the nest with everyone else parked.
        others = slots[:robot] + slots[robot + 1 :]
        if robot % 50 == 0 or math.hypot(x, y) < radius - 2 * config.park_clearance:
            reachable_without = reachable_from_nest(radius, others)
        else:
            reachable_without = reachable  # a wall slot's mouth is clear of its own body
        assert reachable_without[cell_of(mouth, radius)], f"robot {robot} is walled out"


def _distance_to_segment(
    point: tuple[float, float], start: tuple[float, float], end: tuple[float, float]
) -> float:
    (px, py), (ax, ay), (bx, by) = point, start, end
    dx, dy = bx - ax, by - ay
    along = max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)))
    return math.hypot(px - (ax + along * dx), py - (ay + along * dy))


@pytest.mark.parametrize("robots", [10, 50, 100])
def test_swarms_that_fit_along_the_wall_park_along_the_wall_as_before(robots: int) -> None:
    """Up to the wall's capacity every slot is on the wall row, so runs of up to about 180
    robots (10 sites) park exactly where they did before the further rings changed."""
    config = ControllerConfig()
    layout = make_layout(10, robots, seed=0)
    for x, y in slots_for(robots, 0, config):
        assert math.hypot(x, y) == pytest.approx(layout.arena_radius - config.park_clearance)


def test_further_rings_leave_a_lane_between_them_and_between_their_robots() -> None:
    config = ControllerConfig()
    layout = make_layout(10, 500, seed=0)
    rings = parking_rings(
        [s.angle for s in layout.sites],
        0,
        arena_radius=layout.arena_radius,
        inner_radius=layout.nest_radius + 3 * ROBOT_RADIUS,
        robot_radius=ROBOT_RADIUS,
        clearance=config.park_clearance,
        spacing=config.park_spacing,
        corridor=config.park_corridor,
        lane=config.park_lane,
    )
    radii = [radius for radius, _ in rings]
    for outer, inner in itertools.pairwise(radii):
        assert outer - inner == pytest.approx(2 * ROBOT_RADIUS + config.park_lane)
    for radius, angles in rings[1:]:
        ordered = sorted(angles)
        for first, second in itertools.pairwise(ordered):
            assert (second - first) * radius >= 2 * ROBOT_RADIUS + config.park_lane - 1e-9
    assert sum(len(angles) for _, angles in rings) >= 500


# --- the failure of issue 10, small --------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("navigator_seed", range(4))
def test_a_robot_caught_in_an_empty_wall_slot_finds_its_way_back_to_the_nest(
    navigator_seed: int,
) -> None:
    """Seed 0 of a 200-robot swarm: robot 130 gave up a site, turned for the nest next to
    the wall among robots parked for site 8 where the slots of robots 22 and 24 were still
    empty, and stayed there for good. The same place with its neighbours parked, and
    robot 130's navigator on real physics: it must get back among the free robots."""
    config = ControllerConfig()
    layout = make_layout(10, 200, seed=0)
    start = (2.083, -2.519)
    physics = Physics(layout.arena_radius)
    for robot, (x, y) in enumerate(slots_for(200, 8, config)):
        if robot not in {22, 24} and math.dist((x, y), start) < 1.0:
            physics.add_robot(robot, x, y, math.atan2(y, x))
    physics.add_robot(130, *start, 0.3)
    navigator = Navigator(epuck_nav_params(), Stream(navigator_seed))
    for _ in range(600):  # 60 s of sim time
        x, y, theta = physics.pose(130)
        if math.hypot(x, y) < layout.arena_radius - 1.0:
            return
        left, right, _ = navigator.drive_to(x, y, theta, physics.proximity(130), (0, 0), 0.05)
        physics.set_wheels(130, left, right)
        physics.step(0.1)
    pytest.fail(f"still at ({x:.2f}, {y:.2f}) after 60 s, {navigator.escapes} escapes")


def _polar(radius: float, degrees: float) -> tuple[float, float]:
    return radius * math.cos(math.radians(degrees)), radius * math.sin(math.radians(degrees))


@pytest.mark.timeout(60)
@pytest.mark.parametrize("navigator_seed", range(2))
def test_robots_pressed_in_behind_the_wall_row_push_their_way_out(navigator_seed: int) -> None:
    """Seed 0 of a 500-robot swarm: the crowd round site 0 pressed robots 65 and 169 against
    the wall at -5 degrees, where robots 114 and 118 then parked either side of them with
    robot 116 between them, and they stayed there for good: every gap out is narrower
    than a body, and the navigator steers round every body it senses. Their places and
    their neighbours' as `benchmarks/stall_diagnosis.py --robots 500 --seed 0 --until 2000`
    printed them, on real physics: both must get back among the free robots."""
    config = ControllerConfig()
    layout = make_layout(10, 500, seed=0)
    pressed_in = {65: _polar(5.253, -5.4), 169: _polar(5.257, -4.3)}
    pushed_aside = {114: _polar(5.232, -6.2), 116: _polar(5.200, -4.8), 118: _polar(5.230, -3.6)}
    physics = Physics(layout.arena_radius)
    for robot, slot in enumerate(slots_for(500, 8, config)):
        if robot % 2 == 0 and math.dist(slot, pressed_in[65]) < 1.0:  # site 8's even robots
            x, y = pushed_aside.get(robot, slot)
            physics.add_robot(robot, x, y, math.atan2(y, x))
    for robot, (x, y) in pressed_in.items():
        physics.add_robot(robot, x, y, math.atan2(-y, -x))
    navigators = {
        robot: Navigator(epuck_nav_params(), Stream(navigator_seed * 1000 + robot))
        for robot in pressed_in
    }
    still_in = set(pressed_in)
    for _ in range(600):  # 60 s of sim time
        for robot, navigator in navigators.items():
            x, y, theta = physics.pose(robot)
            if math.hypot(x, y) < layout.arena_radius - 0.5:
                still_in.discard(robot)
            wheels = (0.0, 0.0)
            if robot in still_in:
                wheels = navigator.drive_to(x, y, theta, physics.proximity(robot), (0, 0), 0.05)[:2]
            physics.set_wheels(robot, *wheels)
        if not still_in:
            break
        physics.step(0.1)
    assert not still_in, {
        robot: (physics.pose(robot)[:2], navigators[robot].escapes) for robot in still_in
    }
    assert all(navigator.pushes >= 1 for navigator in navigators.values())
