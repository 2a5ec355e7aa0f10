"""Where a decided robot parks, and its drive there (the controller's ``to_decision``).

A decided robot parks in a slot of its own against the wall, as near its site as its slot
allows, never on a viewpoint: robots still sensing need the viewpoints, the views and the
paths to them, and a crowd parked round a site would wall them in (with a hundred robots
it did, and the swarm never finished). Slots are ``park_spacing`` apart along the wall,
outside a corridor of ``park_corridor`` either side of every site; robot k takes the k-th
slot nearest its site, so no two robots ever want the same slot and none has to pass
another to reach its own. When the wall is full (about 180 robots with 10 sites), further
slots lie on rings further in, each a free lane of ``park_lane`` in from the robots parked
on the previous one and with that lane between its own robots: whichever slots are taken,
every slot and every free spot among them stays joined to the interior by paths wide
enough for the navigator, so no robot, parking or passing, can be walled in
(``parking_rings``). That holds only while every decided robot is in its slot, so a
robot never parks short of it: when its parking leg runs out of time, or it stalls more
than a body radius away, it backs off towards the nest for ``stall_timeout`` seconds and
tries again (``Parking``). Nor does it stay where a crowd pushed it: a parked robot more
than a body width from its slot drives back (``Parking.displaced``), since a robot pushed
along the wall into a site's corridor stands between the viewpoint and the panel, and the
robots that still need that site could never see it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from bestofn_swarm.wire import numeric, protocol
from robot_agent.core import ports
from robot_agent.core.motion import STOP, TIME_EPSILON, Motion, along_radius, distance

if TYPE_CHECKING:
    from robot_agent.core.controller_config import ControllerConfig

# Parking slots stop this many robot radii short of the nest (and backing off goes no
# further in).
INNER_BODIES = 3
# A parked robot farther than this many robot radii from its slot has been pushed out.
DISPLACED_BODIES = 2


class Parking:
    """A decided robot's drive into its slot: ``begin`` once decided, then ``step``."""

    def __init__(
        self,
        motion: Motion,
        world: protocol.WorldInfo,
        config: ControllerConfig,
        robot_id: int,
        site_angles: Sequence[float],
    ) -> None:
        self._motion = motion
        self._world = world
        self._config = config
        self._robot_id = robot_id
        self._site_angles = list(site_angles)
        # Slots stop short of the nest, and backing off never goes further in than this.
        self._inner_radius = inner_radius(world.nest.radius, world.robot_radius)
        self.slot: tuple[float, float] | None = None
        self.retries = 0  # how often it backed off and tried again (a diagnostic)
        # While backing off from a parking attempt: where to, and until when.
        self._backoff: tuple[tuple[float, float], float] | None = None

    def begin(self, site: int, t: float) -> None:
        """Head for this robot's slot for ``site``, on a leg starting at sim time ``t``."""
        self.slot = parking_slot(
            self._site_angles,
            site,
            self._robot_id,
            arena_radius=self._world.arena_radius,
            inner_radius=self._inner_radius,
            robot_radius=self._world.robot_radius,
            clearance=self._config.park_clearance,
            spacing=self._config.park_spacing,
            corridor=self._config.park_corridor,
            lane=self._config.park_lane,
        )
        self._backoff = None
        self._motion.start_leg(t)

    def step(self, reading: ports.BodyReading) -> ports.Command | None:
        """What to do this period, or None once the robot is in its slot."""
        if self.slot is None:
            raise RuntimeError("Parking.step before begin: no slot chosen yet")
        goal = self.slot
        if self._backoff is not None:
            waypoint, until = self._backoff
            if reading.t + TIME_EPSILON < until:
                left, right, _ = self._motion.drive_to(
                    reading, waypoint, self._config.view_tolerance
                )
                return ports.Command(left, right)
            self._backoff = None
            self._motion.start_leg(reading.t)
        if self._motion.timed_out(reading, goal):
            return self._back_off(reading)
        # The last stretch into the slot goes straight in: the wall and the neighbouring
        # parked robots are expected there, not obstacles to steer round.
        near = distance(reading, goal) <= self._config.near_distance
        left, right, arrived = self._motion.drive_to(
            reading, goal, self._config.view_tolerance, avoid=not near
        )
        if arrived:
            return None
        if self._motion.stalled_near(reading, goal, self._config.near_distance):
            # Someone is in the way. Stopping here, in a lane, could wall a robot in.
            if distance(reading, goal) > self._world.robot_radius:
                return self._back_off(reading)
            return None
        return ports.Command(left, right)

    def displaced(self, reading: ports.BodyReading) -> bool:
        """Whether a parked robot has been pushed out of its slot: more than a body width
        from it (it parks within a body radius, so a robot that settles there stays)."""
        if self.slot is None:
            raise RuntimeError("Parking.displaced before begin: no slot chosen yet")
        return distance(reading, self.slot) > DISPLACED_BODIES * self._world.robot_radius

    def _back_off(self, reading: ports.BodyReading) -> ports.Command:
        """Give up this parking attempt: head towards the nest, clear of the parking rows,
        for ``stall_timeout`` seconds, then try the slot again with a fresh leg."""
        self.retries += 1
        radius = max(
            self._inner_radius, numeric.hypot(reading.x, reading.y) - self._config.near_distance
        )
        self._backoff = (
            along_radius(reading.x, reading.y, radius),
            reading.t + self._config.stall_timeout,
        )
        self._motion.navigator.reset()
        return STOP


def inner_radius(nest_radius: float, robot_radius: float) -> float:
    """How far in parking slots go: short of the nest by a little more than a body."""
    return nest_radius + INNER_BODIES * robot_radius


class ParkingSlots:
    """Every robot's slot for every site, as ``Parking.begin`` chooses it, for whoever
    follows a run from outside (the stall watchdog: a decided robot progresses when it
    gets closer to its slot). The rings of each site are worked out once."""

    def __init__(
        self,
        site_xy: Sequence[tuple[float, float]],
        *,
        arena_radius: float,
        nest_radius: float,
        robot_radius: float,
        config: ControllerConfig,
    ) -> None:
        self._site_angles = [numeric.atan2(y, x) for x, y in site_xy]
        self._geometry = {
            "arena_radius": arena_radius,
            "inner_radius": inner_radius(nest_radius, robot_radius),
            "robot_radius": robot_radius,
            "clearance": config.park_clearance,
            "spacing": config.park_spacing,
            "corridor": config.park_corridor,
            "lane": config.park_lane,
        }
        self._rings: dict[int, list[tuple[float, list[float]]]] = {}

    @classmethod
    def of_world(cls, world: protocol.WorldInfo, config: ControllerConfig) -> ParkingSlots:
        return cls(
            [(site.x, site.y) for site in sorted(world.sites, key=lambda site: site.id)],
            arena_radius=world.arena_radius,
            nest_radius=world.nest.radius,
            robot_radius=world.robot_radius,
            config=config,
        )

    def slot(self, robot_id: int, site: int) -> tuple[float, float]:
        """Where robot ``robot_id`` parks once it decided for ``site``."""
        rings = self._rings.get(site)
        if rings is None:
            rings = parking_rings(self._site_angles, site, **self._geometry)
            self._rings[site] = rings
        return _slot_in_rings(rings, self._site_angles[site], robot_id)


def parking_slot(
    site_angles: Sequence[float],
    site: int,
    robot_id: int,
    *,
    arena_radius: float,
    inner_radius: float,
    robot_radius: float,
    clearance: float,
    spacing: float,
    corridor: float,
    lane: float,
) -> tuple[float, float]:
    """Robot ``robot_id``'s parking slot for ``site``: the ``robot_id``-th slot nearest the
    site (see ``parking_rings``)."""
    rings = parking_rings(
        site_angles,
        site,
        arena_radius=arena_radius,
        inner_radius=inner_radius,
        robot_radius=robot_radius,
        clearance=clearance,
        spacing=spacing,
        corridor=corridor,
        lane=lane,
    )
    return _slot_in_rings(rings, site_angles[site], robot_id)


def _slot_in_rings(
    rings: Sequence[tuple[float, Sequence[float]]], home: float, robot_id: int
) -> tuple[float, float]:
    """The ``robot_id``-th slot of ``rings`` (``home``: the site's angle)."""
    # More robots than slots down to the nest: the count starts again at the wall.
    remaining = robot_id % max(1, sum(len(slots) for _, slots in rings))
    for radius, slots in rings:
        if remaining < len(slots):
            sin, cos = numeric.sincos(slots[remaining])
            return radius * cos, radius * sin
        remaining -= len(slots)
    # No ring has a single slot (an arena too small to park in): the wall by the site.
    radius = rings[0][0]
    sin, cos = numeric.sincos(home)
    return radius * cos, radius * sin


def parking_rings(
    site_angles: Sequence[float],
    site: int,
    *,
    arena_radius: float,
    inner_radius: float,
    robot_radius: float,
    clearance: float,
    spacing: float,
    corridor: float,
    lane: float,
) -> list[tuple[float, list[float]]]:
    """Every parking slot for robots that chose ``site``: (radius, slot angles nearest the
    site first) for each ring, from the wall inwards.

    Ring 0 lies ``clearance`` in from the wall with slots ``spacing`` apart, outside a
    corridor of ``corridor`` metres either side of every site. Each further ring lies a
    free ``lane`` in from the bodies parked on the previous one, with ``lane`` free between
    its own slots and a corridor of ``corridor + lane / 2`` either side of every site. So
    whichever slots are taken, every slot and every point among them is joined to the
    arena's interior by paths at least ``lane`` wide: no parked robot stands in front of
    another's slot, and nobody, parking or passing, can be walled in.
    """
    pitch = 2 * robot_radius + lane  # centre to centre, across a lane
    rings: list[tuple[float, list[float]]] = []
    ring = 0
    radius = arena_radius - clearance
    while radius >= inner_radius or not rings:
        if ring == 0:
            step, keep_clear = spacing / radius, corridor
        else:
            step, keep_clear = pitch / radius, corridor + lane / 2
        slots = [
            index * step
            for index in range(int(2 * math.pi / step))
            if all(
                abs(math.remainder(index * step - other, 2 * math.pi)) * radius >= keep_clear
                for other in site_angles
            )
        ]
        home = site_angles[site]
        slots.sort(key=lambda angle: abs(math.remainder(angle - home, 2 * math.pi)))
        rings.append((radius, slots))
        ring += 1
        radius = arena_radius - clearance - ring * pitch
    return rings


__all__ = [
    "DISPLACED_BODIES",
    "INNER_BODIES",
    "Parking",
    "ParkingSlots",
    "inner_radius",
    "parking_rings",
    "parking_slot",
]
