"""Go-to-goal with obstacle avoidance: kinematic checks, then a crowd on real physics."""

from __future__ import annotations

import itertools
import math
from typing import Any

import pytest
from bodies import epuck_nav_params
from fakes import MAX_SPEED, ROBOT_RADIUS, proximity, unicycle

from bestofn_swarm.wire.numeric import wrap_angle
from bestofn_swarm.wire.rng import Stream
from robot_agent.core.navigation import Navigator, NavParams
from world_server.core.body import EpuckSpec
from world_server.core.layout import make_layout
from world_server.core.physics import Physics

ARENA_RADIUS = 0.75
DT = 0.1


def drive(
    navigator: Navigator,
    pose: tuple[float, float, float],
    goal: tuple[float, float],
    *,
    tolerance: float = 0.015,
    obstacles: tuple[tuple[float, float, float], ...] = (),
    seconds: float = 60.0,
) -> tuple[bool, tuple[float, float, float], list[tuple[float, float, float]]]:
    """Integrate the navigator's wheel speeds until it arrives; the trajectory too."""
    path = [pose]
    for _ in range(round(seconds / DT)):
        left, right, arrived = navigator.drive_to(
            *pose, proximity(pose, ARENA_RADIUS, obstacles), goal, tolerance
        )
        assert abs(left) <= MAX_SPEED + 1e-12 and abs(right) <= MAX_SPEED + 1e-12
        if arrived:
            assert (left, right) == (0.0, 0.0)
            return True, pose, path
        pose = unicycle(pose, left, right, DT)
        path.append(pose)
    return False, pose, path


def random_point(rng: Stream, max_radius: float) -> tuple[float, float]:
    radius = max_radius * math.sqrt(rng.random())
    angle = rng.uniform(-math.pi, math.pi)
    return radius * math.cos(angle), radius * math.sin(angle)


def test_the_robots_sensor_layout_mirrors_the_simulated_epuck() -> None:
    """The robot's own copy of its sensor directions (WorldInfo does not carry them)."""
    assert NavParams.__dataclass_fields__["prox_angles"].default == EpuckSpec().prox_angles


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_speed", 0.0),
        ("wheel_base", -0.05),
        ("control_period", math.nan),
        ("min_speed", 1.0),
        ("detect_level", 1.0),
        ("clearance_level", -0.1),
        ("min_turn_rate", 100.0),
        ("forget_steps", 0),
        ("prox_angles", ()),
    ],
)
def test_params_are_validated(field: str, value: Any) -> None:
    with pytest.raises(ValueError, match=field):
        epuck_nav_params(**{field: value})


def test_inputs_are_validated() -> None:
    navigator = Navigator(epuck_nav_params(), Stream(0))
    with pytest.raises(ValueError, match="8 proximity readings"):
        navigator.drive_to(0.0, 0.0, 0.0, (0.0,) * 7, (0.1, 0.0), 0.01)
    with pytest.raises(ValueError, match="tolerance"):
        navigator.drive_to(0.0, 0.0, 0.0, (0.0,) * 8, (0.1, 0.0), 0.0)
    with pytest.raises(ValueError, match="tolerance"):
        navigator.turn_to(0.0, 1.0, -0.1)


@pytest.mark.timeout(30)
def test_reaches_goals_from_many_start_poses() -> None:
    rng = Stream(1)
    for trial in range(60):
        start = (*random_point(rng, ARENA_RADIUS - 0.1), rng.uniform(-math.pi, math.pi))
        goal = random_point(rng, ARENA_RADIUS - 0.15)
        navigator = Navigator(epuck_nav_params(), Stream(trial))
        arrived, pose, path = drive(navigator, start, goal)
        assert arrived, f"trial {trial}: from {start} to {goal}, stopped at {pose}"
        assert math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= 0.015
        assert max(math.hypot(x, y) for x, y, _ in path) < ARENA_RADIUS - ROBOT_RADIUS


@pytest.mark.timeout(30)
def test_reaches_viewpoints_near_the_wall_from_the_nest() -> None:
    view_radius = ARENA_RADIUS - 0.15
    for index in range(12):
        angle = 2 * math.pi * index / 12
        goal = (view_radius * math.cos(angle), view_radius * math.sin(angle))
        start = (0.05 * math.cos(3 * angle), 0.05 * math.sin(3 * angle), -angle)
        arrived, _, path = drive(Navigator(epuck_nav_params(), Stream(index)), start, goal)
        assert arrived
        # A straight run, not a wander: at most 40% longer than the straight line.
        length = sum(math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(path))
        assert length <= 1.4 * math.dist(start[:2], goal)


def test_turns_to_headings_on_the_spot() -> None:
    rng = Stream(2)
    navigator = Navigator(epuck_nav_params(), rng)
    for _ in range(100):
        theta = rng.uniform(-math.pi, math.pi)
        heading = rng.uniform(-3 * math.pi, 3 * math.pi)  # any representation of an angle
        pose = (0.1, -0.2, theta)
        for _step in range(100):
            left, right, facing = navigator.turn_to(pose[2], heading, 0.05)
            if facing:
                break
            assert left == pytest.approx(-right)  # on the spot
            assert abs(left) <= MAX_SPEED + 1e-12
            pose = unicycle(pose, left, right, DT)
        assert facing
        assert abs(wrap_angle(pose[2] - heading)) <= 0.05
        assert pose[:2] == pytest.approx((0.1, -0.2))


def test_goes_round_an_obstacle_on_either_side_without_touching_it() -> None:
    obstacle = (0.0, 0.0, ROBOT_RADIUS)
    sides = set()
    for seed in range(16):
        navigator = Navigator(epuck_nav_params(), Stream(seed))
        arrived, _, path = drive(navigator, (-0.4, 0.0, 0.0), (0.4, 0.0), obstacles=(obstacle,))
        assert arrived
        clearance = min(math.hypot(x, y) for x, y, _ in path) - 2 * ROBOT_RADIUS
        assert clearance > 0.0
        passing = min(path, key=lambda pose: abs(pose[0]))
        sides.add(math.copysign(1.0, passing[1]))
    # The goal is dead ahead behind the obstacle: the RNG picks the side, both occur.
    assert sides == {-1.0, 1.0}


def test_same_rng_same_wheel_speeds() -> None:
    obstacles = ((0.1, 0.02, ROBOT_RADIUS), (0.3, -0.1, ROBOT_RADIUS))
    runs = []
    for _ in range(2):
        navigator = Navigator(epuck_nav_params(), Stream(5))
        runs.append(drive(navigator, (-0.3, 0.0, 0.2), (0.5, 0.0), obstacles=obstacles)[2])
    assert runs[0] == runs[1]


@pytest.mark.timeout(30)
def test_head_on_robots_pass_each_other_on_physics() -> None:
    for seed in range(4):
        physics = Physics(ARENA_RADIUS)
        starts = {0: (-0.4, 0.0, 0.0), 1: (0.4, 0.0, math.pi)}
        goals = {0: (0.4, 0.0), 1: (-0.4, 0.0)}
        for robot, pose in starts.items():
            physics.add_robot(robot, *pose)
        rng = Stream(seed)
        navigators = {robot: Navigator(epuck_nav_params(), rng.fork()) for robot in goals}
        arrived = dict.fromkeys(goals, False)
        for _ in range(600):
            for robot, navigator in navigators.items():
                x, y, theta = physics.pose(robot)
                left, right, arrived[robot] = navigator.drive_to(
                    x, y, theta, physics.proximity(robot), goals[robot], 0.015
                )
                physics.set_wheels(robot, left, right)
            if all(arrived.values()):
                break
            physics.step(DT)
        assert all(arrived.values()), f"seed {seed}: {physics.poses()}"


def nest_site_cycles(
    seed: int, robots: int = 10, sites: int = 10, minutes: float = 10.0, dwell: float = 3.0
) -> tuple[list[list[float]], list[int]]:
    """Robots shuttle nest -> random site viewpoint -> nest on pymunk physics.

    Entering the nest radius stands for hearing the beacon; a robot then stops there for
    ``dwell`` seconds, as the controller does. Returns each robot's nest-arrival times
    and how often each navigator had to escape a stall.
    """
    layout = make_layout(sites, robots, seed)
    physics = Physics(layout.arena_radius)
    rng = Stream(seed)
    view_radius = layout.arena_radius - 0.15
    viewpoints = [
        (view_radius * math.cos(site.angle), view_radius * math.sin(site.angle))
        for site in layout.sites
    ]
    navigators = []
    goals: list[tuple[float, float] | None] = []
    resume_at = [0.0] * robots
    arrivals: list[list[float]] = [[] for _ in range(robots)]
    for robot in range(robots):
        physics.add_robot(robot, *layout.start_poses[robot])
        navigators.append(Navigator(epuck_nav_params(), rng.fork()))
        goals.append(rng.choice(viewpoints))
    for tick in range(round(minutes * 60 / DT)):
        t = tick * DT
        readings = physics.proximity_all()
        for robot in range(robots):
            x, y, theta = physics.pose(robot)
            goal = goals[robot]
            left = right = 0.0
            if goal is None:  # dwelling at the nest
                if t >= resume_at[robot]:
                    goals[robot] = rng.choice(viewpoints)
            elif goal == (0.0, 0.0):
                if math.hypot(x, y) <= layout.nest_radius:
                    goals[robot] = None
                    resume_at[robot] = t + dwell
                    arrivals[robot].append(t)
                else:
                    left, right, _ = navigators[robot].drive_to(
                        x, y, theta, readings[robot], goal, 0.05
                    )
            else:
                left, right, arrived = navigators[robot].drive_to(
                    x, y, theta, readings[robot], goal, 0.015
                )
                if arrived:
                    goals[robot] = (0.0, 0.0)
            physics.set_wheels(robot, left, right)
        physics.step(DT)
    return arrivals, [navigator.escapes for navigator in navigators]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("seed", [0, 1])
def test_ten_robots_keep_cycling_through_a_crowded_nest(seed: int) -> None:
    minutes = 10.0
    arrivals, _ = nest_site_cycles(seed, minutes=minutes)
    end = minutes * 60
    for robot, times in enumerate(arrivals):
        # A cycle is about 20 s when nothing is in the way; demand a steady pace.
        assert len(times) >= 15, f"robot {robot} completed only {len(times)} cycles"
        gaps = [b - a for a, b in zip([0.0, *times], [*times, end], strict=True)]
        assert max(gaps) < 150.0, f"robot {robot} went {max(gaps):.0f} s without a cycle"
