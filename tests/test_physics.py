"""The world's physics: differential drive, walls, collisions, proximity rays, determinism."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from world_server.core import layout
from world_server.core.body import EpuckSpec
from world_server.core.physics import MAX_SUBSTEP, Physics, wrap_angle

pytestmark = pytest.mark.timeout(60)

SPEC = EpuckSpec()
DT = 0.1
# A body may sink speed * substep into what it meets before the solver pushes back
# (contacts exist only once shapes overlap), plus pymunk's allowed overlap, the slop.
SLOP = 0.001
WALL_TOLERANCE = SPEC.max_wheel_speed * MAX_SUBSTEP + SLOP + 0.0005
HEAD_ON_TOLERANCE = 2 * SPEC.max_wheel_speed * MAX_SUBSTEP + SLOP + 0.0005


def radial(pose: tuple[float, float, float]) -> float:
    return math.hypot(pose[0], pose[1])


def min_gap(physics: Physics) -> float:
    """Smallest centre distance between two robots, minus a body width (< 0: overlap)."""
    xy = np.array([pose[:2] for pose in physics.poses().values()])
    distances = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(distances, np.inf)
    return float(distances.min()) - 2 * SPEC.radius


# --- differential drive --------------------------------------------------------------


def test_straight_line_moves_at_wheel_speed_along_the_heading() -> None:
    physics = Physics(0.75)
    heading = 0.6
    physics.add_robot(3, -0.2, -0.1, heading)
    physics.set_wheels(3, 0.1, 0.1)
    physics.step(DT)  # the first substep still runs at the old speed (zero)
    previous = physics.pose(3)
    for _ in range(20):
        physics.step(DT)
        x, y, theta = physics.pose(3)
        assert math.hypot(x - previous[0], y - previous[1]) == pytest.approx(0.1 * DT, abs=1e-9)
        assert math.atan2(y - previous[1], x - previous[0]) == pytest.approx(heading, abs=1e-9)
        assert theta == pytest.approx(heading, abs=1e-12)
        previous = (x, y, theta)
    travelled = math.hypot(previous[0] + 0.2, previous[1] + 0.1)
    substep = DT / physics.substeps_for(DT)
    assert travelled == pytest.approx(0.1 * 21 * DT - 0.1 * substep, abs=1e-9)


def test_turning_on_the_spot_turns_at_the_differential_rate() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, 0.1, 0.2, 3.0)
    physics.set_wheels(0, -0.05, 0.05)
    expected_rate = (0.05 - -0.05) / SPEC.wheel_base
    physics.step(DT)
    previous = physics.pose(0)
    for _ in range(40):  # long enough to wrap past pi several times
        physics.step(DT)
        pose = physics.pose(0)
        assert -math.pi <= pose[2] <= math.pi
        assert wrap_angle(pose[2] - previous[2]) == pytest.approx(expected_rate * DT, abs=1e-9)
        assert pose[:2] == pytest.approx((0.1, 0.2), abs=1e-9)
        previous = pose


def test_arc_follows_a_circle_of_radius_v_over_omega() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, 0.0, 0.0, 0.0)
    left, right = 0.04, 0.08
    physics.set_wheels(0, left, right)
    turning_radius = 0.5 * (left + right) / ((right - left) / SPEC.wheel_base)
    points = []
    for _ in range(60):
        physics.step(DT)
        points.append(physics.pose(0)[:2])
    # Least-squares circle x^2 + y^2 + D x + E y + F = 0 through the visited points.
    xy = np.array(points)
    design = np.column_stack([xy, np.ones(len(xy))])
    (d, e, f), *_ = np.linalg.lstsq(design, -(xy**2).sum(axis=1), rcond=None)
    centre = np.array([-d / 2, -e / 2])
    fitted_radius = math.sqrt(centre @ centre - f)
    assert fitted_radius == pytest.approx(turning_radius, rel=1e-3)
    assert np.hypot(*(xy - centre).T) == pytest.approx(fitted_radius, abs=1e-5)


def test_wheel_speeds_are_clamped_and_hold_until_changed() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, 0.0, 0.0, 0.0)
    physics.set_wheels(0, 5.0, -5.0)
    assert physics.wheels(0) == (SPEC.max_wheel_speed, -SPEC.max_wheel_speed)
    physics.set_wheels(0, 0.05, 0.05)
    for _ in range(3):
        physics.step(DT)
    assert physics.wheels(0) == (0.05, 0.05)
    with pytest.raises(ValueError):
        physics.set_wheels(0, math.nan, 0.0)
    with pytest.raises(KeyError):
        physics.set_wheels(99, 0.0, 0.0)


def test_adding_robots_checks_ids_and_the_arena() -> None:
    physics = Physics(0.75)
    physics.step(DT)  # an empty arena steps
    physics.add_robot(5, 0.0, 0.0, 0.0)
    physics.add_robot(2, 0.3, 0.0, 0.0)
    assert physics.robot_ids() == [2, 5]
    assert list(physics.poses()) == [2, 5]
    assert physics.has_robot(5) and not physics.has_robot(3)
    with pytest.raises(ValueError):
        physics.add_robot(5, -0.3, 0.0, 0.0)
    with pytest.raises(ValueError):
        physics.add_robot(7, 0.74, 0.0, 0.0)


# --- walls and collisions ------------------------------------------------------------


@pytest.mark.parametrize("arena_radius", [0.75, layout.arena_radius_for(500, 10)])
def test_robot_driven_into_the_wall_for_a_minute_stays_inside(arena_radius: float) -> None:
    physics = Physics(arena_radius)
    physics.add_robot(0, 0.0, 0.0, 0.4)  # straight into the wall
    physics.add_robot(1, 0.3, 0.2, 1.0)  # a wide arc that ends up scraping along it
    physics.set_wheels(0, SPEC.max_wheel_speed, SPEC.max_wheel_speed)
    physics.set_wheels(1, SPEC.max_wheel_speed, 0.95 * SPEC.max_wheel_speed)
    limit = arena_radius - SPEC.radius
    farthest = 0.0
    for _ in range(600):
        physics.step(DT)
        farthest = max(farthest, *(radial(pose) for pose in physics.poses().values()))
    assert farthest <= limit + WALL_TOLERANCE
    if arena_radius < 1.0:  # the small arena: both reached the wall and are pressed to it
        assert all(radial(pose) > limit - 0.003 for pose in physics.poses().values())


def test_a_crowd_pushing_outwards_stays_inside() -> None:
    arena = layout.make_layout(10, 50, seed=3)  # start poses face outwards
    physics = Physics(arena.arena_radius)
    for robot_id, pose in enumerate(arena.start_poses):
        physics.add_robot(robot_id, *pose)
        physics.set_wheels(robot_id, SPEC.max_wheel_speed, SPEC.max_wheel_speed)
    limit = arena.arena_radius - SPEC.radius
    for _ in range(600):
        physics.step(DT)
        assert max(radial(pose) for pose in physics.poses().values()) <= limit + WALL_TOLERANCE
    assert min(radial(pose) for pose in physics.poses().values()) > limit - 0.003


def test_head_on_robots_stop_at_contact_without_overlap() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, -0.2, 0.0, 0.0)
    physics.add_robot(1, 0.2, 0.0, math.pi)
    for robot_id in (0, 1):
        physics.set_wheels(robot_id, SPEC.max_wheel_speed, SPEC.max_wheel_speed)
    for _ in range(100):
        physics.step(DT)
        assert min_gap(physics) >= -HEAD_ON_TOLERANCE
    assert min_gap(physics) == pytest.approx(-SLOP, abs=2e-4)  # at rest: only the slop
    assert physics.pose(0)[0] == pytest.approx(-physics.pose(1)[0], abs=1e-6)


def test_a_driving_robot_pushes_a_stopped_one() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, -0.3, 0.0, 0.0)
    physics.add_robot(1, -0.1, 0.0, 1.0)  # a dead controller: wheels at zero
    physics.set_wheels(0, 0.1, 0.1)
    for _ in range(50):
        physics.step(DT)
        assert min_gap(physics) >= -(0.1 * MAX_SUBSTEP + SLOP + 0.0005)
    pushed = physics.pose(1)
    assert pushed[0] > -0.1 + 0.05  # it was shoved along +x
    assert abs(pushed[1]) < 0.01


def test_a_converging_crowd_settles_without_overlap() -> None:
    arena = layout.make_layout(10, 50, seed=4)
    physics = Physics(arena.arena_radius)
    for robot_id, (x, y, theta) in enumerate(arena.start_poses):
        physics.add_robot(robot_id, x, y, theta + math.pi)  # facing the nest
    worst = 0.0
    for _ in range(300):
        for robot_id, (x, y, theta) in physics.poses().items():
            error = wrap_angle(math.atan2(-y, -x) - theta)
            physics.set_wheels(robot_id, 0.13 - 0.1 * error, 0.13 + 0.1 * error)
        physics.step(DT)
        worst = min(worst, min_gap(physics))
    assert worst >= -HEAD_ON_TOLERANCE - 0.002  # a pile adds a little to two robots' impact
    assert min_gap(physics) >= -SLOP - 2e-4  # settled: only pymunk's slop


# --- proximity -----------------------------------------------------------------------


def test_a_lone_robot_far_from_walls_reads_zero() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, 0.0, 0.0, 1.2)
    assert physics.proximity(0) == (0.0,) * 8


def test_wall_on_the_right_is_seen_by_the_right_sensors_at_its_distance() -> None:
    physics = Physics(0.75)
    gap = 0.03
    # Facing +y at the wall's +x side: the right-hand sensor ps2 (-90 degrees) faces it.
    physics.add_robot(0, 0.75 - SPEC.radius - gap, 0.0, math.pi / 2)
    readings = physics.proximity(0)
    assert readings[2] == pytest.approx(1.0 - gap / SPEC.prox_range, abs=2e-3)
    assert readings[1] < readings[2] and readings[3] < readings[2]  # oblique: farther
    assert readings[4:] == (0.0,) * 4  # the left side sees nothing


def test_robot_on_the_left_is_seen_by_the_left_sensor_at_its_distance() -> None:
    physics = Physics(0.75)
    gap = 0.02
    physics.add_robot(0, 0.0, 0.0, 0.0)
    physics.add_robot(1, 0.0, 2 * SPEC.radius + gap, 0.0)  # to robot 0's left
    readings = physics.proximity(0)
    assert readings[5] == pytest.approx(1.0 - gap / SPEC.prox_range, abs=1e-3)  # ps5: +90
    assert readings[:4] == (0.0,) * 4
    other = physics.proximity(1)
    assert other[2] == pytest.approx(readings[5], abs=1e-3)  # and it sees 0 on its right
    assert physics.proximity_all() == {0: readings, 1: other}


def test_touching_reads_one_and_beyond_range_reads_zero() -> None:
    physics = Physics(0.75)
    physics.add_robot(0, 0.0, 0.0, 0.0)
    physics.add_robot(1, 2 * SPEC.radius, 0.0, 0.0)  # touching robot 0's front
    physics.add_robot(2, 0.0, -(2 * SPEC.radius + SPEC.prox_range + 0.005), 0.0)  # too far
    readings = physics.proximity(0)
    front = readings[0], readings[7]  # ps0 and ps7, 0.3 rad either side of ahead
    assert min(front) > 0.9
    assert readings[2] == 0.0


def test_analytic_rays_match_pymunk_raycasts() -> None:
    arena = layout.make_layout(10, 60, seed=2)
    physics = Physics(arena.arena_radius)
    rng = random.Random(5)
    for robot_id, pose in enumerate(arena.start_poses):
        physics.add_robot(robot_id, *pose)
        physics.set_wheels(robot_id, rng.uniform(0.05, 0.13), rng.uniform(0.05, 0.13))
    seen = 0
    for _ in range(8):
        for _ in range(10):
            physics.step(DT)
        readings = physics.proximity_all()
        for robot_id, values in readings.items():
            reference = physics.proximity_raycast(robot_id)
            # The pymunk wall is a polygon that may bulge WALL_SAG beyond the circle.
            assert values == pytest.approx(reference, abs=0.005)
            seen += sum(value > 0 for value in values)
    assert seen > 100  # the comparison covered many rays that hit something


# --- determinism ---------------------------------------------------------------------


def run_world(seed: int) -> tuple[dict, dict]:
    arena = layout.make_layout(10, 40, seed=1)
    physics = Physics(arena.arena_radius)
    for robot_id, pose in enumerate(arena.start_poses):
        physics.add_robot(robot_id, *pose)
    rng = random.Random(seed)
    for tick in range(150):
        if tick % 10 == 0:
            for robot_id in physics.robot_ids():
                physics.set_wheels(robot_id, rng.uniform(-0.13, 0.13), rng.uniform(-0.13, 0.13))
        physics.step(DT)
    return physics.poses(), physics.proximity_all()


def test_same_commands_give_bit_identical_worlds() -> None:
    first, second = run_world(seed=9), run_world(seed=9)
    assert first == second
    assert run_world(seed=10)[0] != first[0]


# --- one robot at a time, or all at once: the same bits --------------------------------


def crowded_world(robots: int, seed: int) -> Physics:
    """``robots`` robots at a swarm's start, driven at random for a few seconds."""
    arena = layout.make_layout(10, robots, seed=seed)
    physics = Physics(arena.arena_radius)
    for robot_id, pose in enumerate(arena.start_poses):
        physics.add_robot(robot_id, *pose)
    rng = random.Random(seed)
    for robot_id in physics.robot_ids():
        physics.set_wheels(robot_id, rng.uniform(-0.13, 0.13), rng.uniform(-0.13, 0.13))
    return physics


@pytest.mark.parametrize("robots", [12, 60, 150])
def test_the_numpy_forms_give_the_bits_of_the_robot_by_robot_ones(robots: int) -> None:
    """Large swarms work out a substep's forces and the proximity readings with numpy
    (``VECTOR_FROM``): the same operations in the same order, so the same bits, whatever
    the swarm's size."""
    one_by_one, at_once = crowded_world(robots, 3), crowded_world(robots, 3)
    substeps = one_by_one.substeps_for(DT)
    for _ in range(30):
        one_by_one._step_robot_by_robot(substeps, DT / substeps)
        at_once._step_vectorised(substeps, DT / substeps)
        # The robots' rows (a list read from pymunk goes on with the wall's body).
        assert one_by_one._state_rows()[: 6 * robots] == at_once._state_rows()
        assert one_by_one._compute_proximity() == at_once._compute_proximity_vectorised().tolist()
    readings = one_by_one._compute_proximity()
    assert any(0.0 < value < 1.0 for row in readings for value in row)  # robots see robots
