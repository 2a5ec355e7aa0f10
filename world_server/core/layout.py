"""The arena of one run: its size, the sites on its edge, the nest, where robots start.

Pure geometry, decided once from the run's parameters and seed. Site ids number the
sites by position (counter-clockwise from +x); which site gets which quality is a
seeded permutation, so the best site's id differs from run to run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bestofn_swarm.wire import numeric, protocol
from bestofn_swarm.wire.rng import Stream
from world_server.core.body import EPUCK

BASE_ARENA_RADIUS = 0.75  # the paper's 1.5 m disc
BASE_ROBOTS = 10  # the paper's swarm size for that disc
BASE_NEST_RADIUS = 0.2  # beacon range at the base size: room for about ten e-pucks
MIN_SITE_SPACING = 0.2  # metres of wall per site, so a camera can tell neighbours apart
SITE_HALF_WIDTH_FRACTION = 0.35  # a site panel covers 70% of its share of the wall
MAX_SITE_HALF_WIDTH = 0.15  # metres


@dataclass(frozen=True)
class SiteSpec:
    id: int
    angle: float  # radians, position on the wall
    x: float  # the panel's centre on the wall
    y: float
    half_width: float  # half the panel's angular width, radians
    quality: float  # rho in [0, 1]; never leaves the world server
    rank: int  # the paper's i: 1 is the best


@dataclass(frozen=True)
class Layout:
    arena_radius: float
    nest_radius: float
    sites: tuple[SiteSpec, ...]
    start_poses: tuple[tuple[float, float, float], ...]

    @property
    def best_site(self) -> int:
        return min(self.sites, key=lambda site: site.rank).id

    def site(self, site_id: int) -> SiteSpec:
        return self.sites[site_id]

    def sensing_pose(
        self,
        site_id: int,
        distance: float = 0.15,
        sideways: float = 0.0,
        heading_error: float = 0.0,
    ) -> tuple[float, float, float]:
        """A robot's pose for looking at a site: ``distance`` from the wall on the site's
        radius, facing it; shifted left by ``sideways`` and turned by ``heading_error``
        (for tests and benchmarks of imperfect poses)."""
        angle = self.site(site_id).angle
        radius = self.arena_radius - distance
        sin, cos = numeric.sincos(angle)
        x = radius * cos - sideways * sin
        y = radius * sin + sideways * cos
        return x, y, angle + heading_error

    def info_sites(self) -> list[protocol.Site]:
        return [protocol.Site(site.id, site.x, site.y) for site in self.sites]


def quality_of_rank(rank: int, num_sites: int) -> float:
    """The paper's rho_i = ((n-1) - (i-1)) / (n-1) for rank i (1 = best)."""
    return ((num_sites - 1) - (rank - 1)) / (num_sites - 1)


def arena_radius_for(num_robots: int, num_sites: int) -> float:
    """0.75 m for the paper's ten robots; grows so robot density and site spacing hold."""
    by_robots = BASE_ARENA_RADIUS * math.sqrt(max(num_robots, BASE_ROBOTS) / BASE_ROBOTS)
    by_sites = num_sites * MIN_SITE_SPACING / (2 * math.pi)
    return max(by_robots, by_sites)


def nest_radius_for(num_robots: int) -> float:
    """The beacon's reach: the nest's area grows with the swarm."""
    return BASE_NEST_RADIUS * math.sqrt(max(num_robots, BASE_ROBOTS) / BASE_ROBOTS)


def make_layout(
    num_sites: int, num_robots: int, seed: int, robot_radius: float = EPUCK.radius
) -> Layout:
    if num_sites < 2:
        raise ValueError(f"need at least 2 sites, got {num_sites}")
    if num_robots < 1:
        raise ValueError(f"need at least 1 robot, got {num_robots}")
    arena_radius = arena_radius_for(num_robots, num_sites)
    nest_radius = nest_radius_for(num_robots)
    rng = Stream.named(seed, "layout")
    ranks = list(range(1, num_sites + 1))
    rng.shuffle(ranks)
    spacing = 2 * math.pi / num_sites
    half_width = min(SITE_HALF_WIDTH_FRACTION * spacing, MAX_SITE_HALF_WIDTH / arena_radius)
    sites = tuple(
        SiteSpec(
            id=index,
            angle=index * spacing,
            x=arena_radius * numeric.cos(index * spacing),
            y=arena_radius * numeric.sin(index * spacing),
            half_width=half_width,
            quality=quality_of_rank(rank, num_sites),
            rank=rank,
        )
        for index, rank in enumerate(ranks)
    )
    poses = start_poses(num_robots, nest_radius, robot_radius)
    return Layout(arena_radius, nest_radius, sites, poses)


def start_poses(
    num_robots: int, nest_radius: float, robot_radius: float
) -> tuple[tuple[float, float, float], ...]:
    """Robots start on rings around the nest, facing outwards, one body-width apart.

    Robot ``i`` always gets pose ``i``, so a run's start does not depend on join order.
    """
    poses: list[tuple[float, float, float]] = []
    ring = 0
    while len(poses) < num_robots:
        radius = nest_radius + robot_radius * (2 + 2.5 * ring)
        slots = max(1, int(2 * math.pi * radius / (2.5 * robot_radius)))
        offset = 0.5 * ring * (2 * math.pi / slots)
        for slot in range(slots):
            if len(poses) == num_robots:
                break
            angle = offset + slot * 2 * math.pi / slots
            sin, cos = numeric.sincos(angle)
            poses.append((radius * cos, radius * sin, angle))
        ring += 1
    return tuple(poses)
