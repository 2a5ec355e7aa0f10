"""The robot's controller for the paper's Section 5: a sans-IO state machine.

Each control period the transport calls ``step(reading, received)`` with what the body
sensed and the radio messages that arrived, and applies the returned ``Command`` (wheel
speeds, a camera request, opinion broadcasts). The controller reads no clock (time is
``reading.t``), draws randomness only from the ``random.Random`` it is given, and does no
I/O, so the same code runs over Zenoh, in tests, or on a real robot (``ports.control_step``).

One cycle ("trip"):

    to_site -> sensing -> to_site -> sensing     visit the two sites of a weighted pair,
                                                 estimating each one's quality by camera
    compare, negative update (Definition 1)
    to_nest [-> waiting]                         until the nest beacon is heard
    at_nest                                      stop, broadcast the opinion, listen `dwell` s
    pool (MProdOp, or config.pooling) with every neighbour heard; trips += 1; decision test
    -> next pair (to_site), or lingering -> to_decision -> stopped once decided.

Where the paper leaves the robot to its path planner, this controller adds the guards a
crowded arena needs: a viewpoint taken by another robot counts as reached once the robot
has been stalled close to it; a site that cannot be seen after ``capture_attempts`` tries
is given up (no update that trip); a leg to a site that takes longer than
``travel_timeout`` is abandoned. A decided robot parks in a slot of its own against the
wall, as near its site as its slot allows, never on a viewpoint: robots still sensing
need the viewpoints, the views and the paths to them, and a crowd parked round a site
would wall them in (with a hundred robots it did, and the swarm never finished). Slots
are ``park_spacing`` apart along the wall, outside a corridor of ``park_corridor`` either
side of every site; robot k takes the k-th slot nearest its site, so no two robots ever
want the same slot and none has to pass another to reach its own. When the wall is
full (about 180 robots with 10 sites), further slots lie on rings further in, each a
free lane of ``park_lane`` in from the robots parked on the previous one and with that
lane between its own robots: whichever slots are taken, every slot and every free spot
among them stays joined to the interior by paths wide enough for the navigator, so no
robot, parking or passing, can be walled in (``parking_rings``). That holds only while
every decided robot ends in its slot, so a robot never parks short of it: when its
parking leg runs out of time, or it stalls more than a body radius away, it backs off
towards the nest for ``stall_timeout`` seconds and tries again.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from robot_agent import decision, ports, protocol, vision
from robot_agent.navigation import Navigator, NavParams

QualityEstimator = Callable[[np.ndarray], "float | None"]

_TIME_EPSILON = 1e-9  # seconds: sums of control periods are not exact in binary


@dataclass(frozen=True)
class ControllerConfig:
    """Parameters of the Section 5 behaviour (seconds, metres, radians)."""

    alpha: float = 0.0  # Definition 1 reliability parameter, in [0, 0.5]
    threshold: float = 1.0  # decide when an option reaches it (use < 1 with alpha > 0)
    pooling: decision.PoolingName = "mprodop"  # operator at the nest (decision.POOLING_OPERATORS)
    dwell: float = 3.0  # seconds at the nest broadcasting + listening before pooling
    broadcast_period: float = 0.5  # seconds between opinion broadcasts at the nest
    linger: float = 0.0  # seconds broadcasting at the nest after deciding (the paper's fix)
    view_distance: float = 0.15  # metres from the wall to the robot centre when sensing
    beacon_timeout: float = 1.5  # heard the beacon within this -> at the nest
    capture_timeout: float = 1.0  # seconds to wait for a requested frame
    capture_attempts: int = 3  # frames tried at one site before giving up the pair
    view_tolerance: float = 0.015  # metres from the viewpoint that count as there
    heading_tolerance: float = 0.05  # radians off the site's direction when capturing
    wiggle: float = 0.12  # radians: a retry aims up to this far either side of the site
    nest_tolerance: float = 0.05  # metres from the nest centre where a deaf robot waits
    stall_timeout: float = 4.0  # seconds without progress near a goal -> take it as reached
    near_distance: float = 0.2  # metres: how near a stalled robot must be to sense from there
    travel_timeout: float = 120.0  # seconds for a leg to a site (or parking) before giving up
    travel_crawl: float = 1 / 30  # m/s: a longer leg gets the time to cover its length at this
    park_clearance: float = 0.06  # metres from the wall to the centre of a parking slot
    park_spacing: float = 0.1  # metres between parking slots along the wall
    park_corridor: float = 0.11  # metres either side of each site kept free of parking
    park_lane: float = 0.2  # metres kept free between parked robots beyond the wall row

    def __post_init__(self) -> None:
        decision.validate_alpha(self.alpha)
        if not isinstance(self.pooling, str) or self.pooling not in decision.POOLING_OPERATORS:
            raise ValueError(
                f"pooling must be one of {', '.join(decision.POOLING_OPERATORS)}, "
                f"got {self.pooling!r}"
            )
        if not (isinstance(self.threshold, (int, float)) and 0.0 < self.threshold <= 1.0):
            raise ValueError(f"threshold must be in (0, 1], got {self.threshold!r}")
        if self.alpha > 0.0 and self.threshold >= 1.0:
            raise ValueError(
                f"with alpha = {self.alpha} > 0 no option ever reaches probability 1: "
                "set threshold below 1 (e.g. 0.99)"
            )
        positive = {
            "dwell": self.dwell,
            "broadcast_period": self.broadcast_period,
            "view_distance": self.view_distance,
            "beacon_timeout": self.beacon_timeout,
            "capture_timeout": self.capture_timeout,
            "view_tolerance": self.view_tolerance,
            "heading_tolerance": self.heading_tolerance,
            "nest_tolerance": self.nest_tolerance,
            "stall_timeout": self.stall_timeout,
            "near_distance": self.near_distance,
            "travel_timeout": self.travel_timeout,
            "travel_crawl": self.travel_crawl,
        }
        for name, value in positive.items():
            if not _finite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive number of its unit, got {value!r}")
        for name, value in (
            ("linger", self.linger),
            ("wiggle", self.wiggle),
            ("park_clearance", self.park_clearance),
            ("park_corridor", self.park_corridor),
        ):
            if not _finite(value) or value < 0.0:
                raise ValueError(f"{name} must be zero or positive, got {value!r}")
        for name, value in (("park_spacing", self.park_spacing), ("park_lane", self.park_lane)):
            if not _finite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive distance, got {value!r}")
        if self.wiggle > math.pi / 2:
            raise ValueError(f"wiggle must be at most pi/2 radians, got {self.wiggle!r}")
        if isinstance(self.capture_attempts, bool) or not isinstance(self.capture_attempts, int):
            raise ValueError(f"capture_attempts must be an int, got {self.capture_attempts!r}")
        if self.capture_attempts < 1:
            raise ValueError(f"capture_attempts must be at least 1, got {self.capture_attempts}")

    def leg_allowance(self, length: float) -> float:
        """Sim seconds a leg of ``length`` metres may take before the robot gives it up:
        ``travel_timeout``, or for a long leg (the arena grows with the swarm) the time to
        cover it at ``travel_crawl``, so a crowd on the way slows a robot without making
        it give up."""
        return max(self.travel_timeout, length / self.travel_crawl)


class Controller:
    """One robot's Section 5 behaviour; see the module docstring."""

    def __init__(
        self,
        robot_id: int,
        world: protocol.WorldInfo,
        config: ControllerConfig,
        rng: random.Random,
        *,
        estimate_quality: QualityEstimator = vision.estimate_quality,
        nav_params: NavParams | None = None,
    ) -> None:
        if isinstance(robot_id, bool) or not isinstance(robot_id, int):
            raise ValueError(f"robot id must be an int, got {robot_id!r}")
        if not 0 <= robot_id < protocol.MAX_ROBOTS:
            raise ValueError(f"robot id {robot_id} is outside 0..{protocol.MAX_ROBOTS - 1}")
        site_ids = [site.id for site in world.sites]
        if sorted(site_ids) != list(range(len(site_ids))):
            raise ValueError(f"site ids must be 0..{len(site_ids) - 1} once each, got {site_ids}")
        if len(site_ids) < 2:
            raise ValueError(f"need at least 2 sites, got {len(site_ids)}")
        sensing_radius = world.arena_radius - config.view_distance
        if world.arena_radius - config.park_clearance < world.nest.radius + world.robot_radius:
            raise ValueError(
                f"park_clearance {config.park_clearance} leaves no room to park in an arena "
                f"of radius {world.arena_radius}"
            )
        if config.view_distance < world.robot_radius:
            raise ValueError(
                f"view_distance {config.view_distance} puts the robot (radius "
                f"{world.robot_radius}) into the wall"
            )

        self.robot_id = robot_id
        self.world = world
        self.config = config
        self._rng = rng
        self._estimate_quality = estimate_quality
        self._name = protocol.radio_name(robot_id)
        self._n = len(site_ids)
        # The arena is centred on the origin; sites lie on its wall.
        sites = sorted(world.sites, key=lambda site: site.id)
        self._site_xy = [(site.x, site.y) for site in sites]
        self._viewpoints = [_along_radius(site.x, site.y, sensing_radius) for site in sites]
        self._site_angles = [math.atan2(site.y, site.x) for site in sites]
        self._park_goal: tuple[float, float] | None = None
        self._park_retries = 0
        # While backing off from a parking attempt: where to, and until when.
        self._backoff: tuple[tuple[float, float], float] | None = None
        params = nav_params or NavParams(
            max_speed=world.max_wheel_speed,
            wheel_base=world.wheel_base,
            robot_radius=world.robot_radius,
            control_period=world.dt,
        )
        # Its own stream, so obstacle encounters do not shift the pair choices.
        self._navigator = Navigator(params, random.Random(rng.getrandbits(64)))

        # Decision state.
        self._opinion = decision.uniform_opinion(self._n)
        self._trips = 0
        self._pool_sizes: list[int] = []
        self._decided_site: int | None = None
        self._decision_time: float | None = None
        self._decision_trips: int | None = None
        self._comparison: protocol.Comparison | None = None
        self._rejected = 0

        # Trip state.
        self._t = 0.0
        self._phase: protocol.Phase = "to_site"
        self._changed = True  # the initial state is news to whoever reports it
        self._pair: list[int] = []
        self._qualities: dict[int, float] = {}
        self._leg_start = 0.0
        self._leg_allowance: float | None = None  # seconds this leg may take
        self._best_distance = math.inf
        self._last_progress = 0.0
        self._aim = 0.0
        self._attempts = 0
        self._capture_time: float | None = None
        self._last_beacon: float | None = None
        self._nest_arrival = 0.0
        self._next_broadcast = 0.0
        self._linger_end = 0.0
        self._heard: dict[int, tuple[float, list[float]]] = {}
        self._started = False
        self._handlers: dict[str, Callable[[ports.BodyReading], ports.Command]] = {
            "to_site": self._to_site,
            "sensing": self._sensing,
            "to_nest": self._to_nest,
            "waiting": self._waiting,
            "at_nest": self._at_nest,
            "lingering": self._lingering,
            "to_decision": self._to_decision,
            "stopped": self._stopped,
        }

    # --- read-only state -----------------------------------------------------------

    @property
    def phase(self) -> protocol.Phase:
        return self._phase

    @property
    def opinion(self) -> list[float]:
        return list(self._opinion)

    @property
    def trips(self) -> int:
        return self._trips

    @property
    def pool_sizes(self) -> list[int]:
        return list(self._pool_sizes)

    @property
    def decided_site(self) -> int | None:
        return self._decided_site

    @property
    def decision_time(self) -> float | None:
        return self._decision_time

    @property
    def decision_trips(self) -> int | None:
        return self._decision_trips

    @property
    def rejected(self) -> int:
        return self._rejected

    @property
    def comparison(self) -> protocol.Comparison | None:
        return self._comparison

    @property
    def park_retries(self) -> int:
        """How often parking had to back off and try again (a diagnostic)."""
        return self._park_retries

    @property
    def escapes(self) -> int:
        """How often navigation had to break out of a stall (a diagnostic)."""
        return self._navigator.escapes

    def status(self, tick: int) -> protocol.Status:
        return protocol.Status(
            v=protocol.VERSION,
            id=self.robot_id,
            tick=tick,
            t=self._t,
            phase=self._phase,
            trips=self._trips,
            opinion=protocol.wire_opinion(self._opinion),
            pool_size=self._pool_sizes[-1] if self._pool_sizes else 0,
            poolings=len(self._pool_sizes),
            decided_site=self._decided_site,
            decision_time=self._decision_time,
            decision_trips=self._decision_trips,
            comparison=self._comparison,
            rejected=self._rejected,
        )

    def take_status_change(self) -> bool:
        """True once after any change of phase, trips, opinion, pool size or decision."""
        changed, self._changed = self._changed, False
        return changed

    # --- the step ------------------------------------------------------------------

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        """Advance the state machine by one control period."""
        if len(reading.proximity) != len(self._navigator.params.prox_angles):
            raise ValueError(
                f"expected {len(self._navigator.params.prox_angles)} proximity readings, "
                f"got {len(reading.proximity)}"
            )
        self._t = reading.t
        self._listen(received)
        if not self._started:
            self._started = True
            self._start_trip(reading)
        return self._handlers[self._phase](reading)

    # --- radio ---------------------------------------------------------------------

    def _listen(self, received: Sequence[ports.Received]) -> None:
        for message in received:
            payload = message.payload
            if isinstance(payload, protocol.BeaconPayload):
                self._last_beacon = self._t
            elif isinstance(payload, protocol.OpinionPayload):
                self._hear_opinion(message.sender, payload)
            else:
                self._rejected += 1

    def _hear_opinion(self, sender: str, payload: protocol.OpinionPayload) -> None:
        if sender == self._name and payload.id == self.robot_id:
            return  # our own broadcast echoed back
        if sender != protocol.radio_name(payload.id):
            self._rejected += 1  # a robot claiming someone else's id
            return
        try:
            opinion = decision.validate_opinion(payload.opinion, self._n)
        except ValueError:
            self._rejected += 1  # wrong length, negative, NaN: not an opinion over our sites
            return
        # The latest opinion of each robot, with when it was heard; pooling takes those
        # heard since arriving at the nest.
        self._heard[payload.id] = (self._t, opinion)

    def _hears_beacon(self, since: float) -> bool:
        heard = self._last_beacon
        return (
            heard is not None
            and heard + _TIME_EPSILON >= since
            and self._t - heard <= self.config.beacon_timeout + _TIME_EPSILON
        )

    def _broadcasts(self) -> tuple[protocol.OpinionPayload, ...]:
        if self._t + _TIME_EPSILON < self._next_broadcast:
            return ()
        self._next_broadcast = self._t + self.config.broadcast_period
        payload = protocol.OpinionPayload(
            v=protocol.VERSION,
            id=self.robot_id,
            trip=self._trips,
            decided=self._decided_site is not None,
            opinion=protocol.wire_opinion(self._opinion),
        )
        return (payload,)

    # --- phases --------------------------------------------------------------------

    def _to_site(self, reading: ports.BodyReading) -> ports.Command:
        site = self._pair[0]
        goal = self._viewpoints[site]
        left, right, arrived = self._navigator.drive_to(
            reading.x,
            reading.y,
            reading.theta,
            reading.proximity,
            goal,
            self.config.view_tolerance,
        )
        if arrived or self._stalled_near(reading, goal, self.config.near_distance):
            self._start_sensing(reading, site)
            return self._sensing(reading)
        if self._leg_timed_out(reading, goal):
            self._head_home()  # the site is out of reach: no update this trip
            return _stop()
        return ports.Command(left, right)

    def _sensing(self, reading: ports.BodyReading) -> ports.Command:
        site = self._pair[0]
        failed = False
        if self._capture_time is not None:
            if reading.frame is not None:
                self._capture_time = None
                quality = self._estimate(reading.frame)
                if quality is not None:
                    self._sensed(site, quality)
                    return _stop()
                failed = True
            elif self._t - self._capture_time > self.config.capture_timeout + _TIME_EPSILON:
                self._capture_time = None
                failed = True
            else:
                return _stop()  # the frame is on its way
        if failed:
            self._attempts += 1
            if self._attempts >= self.config.capture_attempts:
                self._head_home()  # cannot see the site: give up the pair
                return _stop()
            # Look slightly to one side: an occluder or a pose error may hide the panel.
            self._aim = self._site_heading(reading, site) + self._rng.uniform(
                -self.config.wiggle, self.config.wiggle
            )
        left, right, facing = self._navigator.turn_to(
            reading.theta, self._aim, self.config.heading_tolerance
        )
        if facing:
            self._capture_time = self._t
            return ports.Command(0.0, 0.0, capture=True)
        return ports.Command(left, right)

    def _to_nest(self, reading: ports.BodyReading) -> ports.Command:
        if self._hears_beacon(self._leg_start):
            return self._arrive_at_nest()
        left, right, arrived = self._drive_to_nest(reading)
        if arrived:
            self._set_phase("waiting")
            return _stop()
        return ports.Command(left, right)

    def _waiting(self, reading: ports.BodyReading) -> ports.Command:
        """At the nest centre without hearing the beacon: stay there until it is heard."""
        if self._hears_beacon(self._leg_start):
            return self._arrive_at_nest()
        nest = (self.world.nest.x, self.world.nest.y)
        if math.hypot(reading.x - nest[0], reading.y - nest[1]) <= 2 * self.config.nest_tolerance:
            return _stop()  # pushed a little: not worth driving back yet
        left, right, _ = self._drive_to_nest(reading)
        return ports.Command(left, right)

    def _drive_to_nest(self, reading: ports.BodyReading) -> tuple[float, float, bool]:
        nest = (self.world.nest.x, self.world.nest.y)
        return self._navigator.drive_to(
            reading.x,
            reading.y,
            reading.theta,
            reading.proximity,
            nest,
            self.config.nest_tolerance,
        )

    def _at_nest(self, reading: ports.BodyReading) -> ports.Command:
        broadcasts = self._broadcasts()
        if self._t + _TIME_EPSILON >= self._nest_arrival + self.config.dwell:
            self._pool_and_decide(reading)
        return ports.Command(0.0, 0.0, broadcasts=broadcasts)

    def _lingering(self, reading: ports.BodyReading) -> ports.Command:
        broadcasts = self._broadcasts()
        if self._t + _TIME_EPSILON >= self._linger_end:
            self._start_leg("to_decision")
        return ports.Command(0.0, 0.0, broadcasts=broadcasts)

    def _to_decision(self, reading: ports.BodyReading) -> ports.Command:
        assert self._decided_site is not None
        if self._park_goal is None:
            self._park_goal = parking_slot(
                self._site_angles,
                self._decided_site,
                self.robot_id,
                arena_radius=self.world.arena_radius,
                inner_radius=self.world.nest.radius + 3 * self.world.robot_radius,
                robot_radius=self.world.robot_radius,
                clearance=self.config.park_clearance,
                spacing=self.config.park_spacing,
                corridor=self.config.park_corridor,
                lane=self.config.park_lane,
            )
        goal = self._park_goal
        if self._backoff is not None:
            waypoint, until = self._backoff
            if self._t + _TIME_EPSILON < until:
                left, right, _ = self._navigator.drive_to(
                    reading.x,
                    reading.y,
                    reading.theta,
                    reading.proximity,
                    waypoint,
                    self.config.view_tolerance,
                )
                return ports.Command(left, right)
            self._backoff = None
            self._start_leg("to_decision")
        if self._leg_timed_out(reading, goal):
            return self._back_off(reading)
        # The last stretch into the slot goes straight in: the wall and the neighbouring
        # parked robots are expected there, not obstacles to steer round.
        near = _distance(reading, goal) <= self.config.near_distance
        sensed = (0.0,) * len(reading.proximity) if near else reading.proximity
        left, right, arrived = self._navigator.drive_to(
            reading.x, reading.y, reading.theta, sensed, goal, self.config.view_tolerance
        )
        if arrived:
            self._set_phase("stopped")
            return _stop()
        if self._stalled_near(reading, goal, self.config.near_distance):
            # Someone is in the way. Stopping here, in a lane, could wall a robot in.
            if _distance(reading, goal) > self.world.robot_radius:
                return self._back_off(reading)
            self._set_phase("stopped")
            return _stop()
        return ports.Command(left, right)

    def _back_off(self, reading: ports.BodyReading) -> ports.Command:
        """Give up this parking attempt: head towards the nest, clear of the parking rows,
        for ``stall_timeout`` seconds, then try the slot again with a fresh leg."""
        self._park_retries += 1
        inner = self.world.nest.radius + 3 * self.world.robot_radius
        radius = max(inner, math.hypot(reading.x, reading.y) - self.config.near_distance)
        waypoint = _along_radius(reading.x, reading.y, radius)
        self._backoff = (waypoint, self._t + self.config.stall_timeout)
        self._navigator.reset()
        return _stop()

    def _stopped(self, reading: ports.BodyReading) -> ports.Command:
        return _stop()

    # --- transitions ---------------------------------------------------------------

    def _start_trip(self, reading: ports.BodyReading) -> None:
        first, second = decision.choose_pair(self._opinion, self._rng)
        # Visit the nearer viewpoint first; the pair itself is what the rng chose.
        if _distance(reading, self._viewpoints[second]) < _distance(
            reading, self._viewpoints[first]
        ):
            first, second = second, first
        self._pair = [first, second]
        self._qualities = {}
        self._start_leg("to_site")

    def _start_leg(self, phase: protocol.Phase) -> None:
        self._navigator.reset()
        self._leg_start = self._t
        self._leg_allowance = None
        self._best_distance = math.inf
        self._last_progress = self._t
        self._set_phase(phase)

    def _start_sensing(self, reading: ports.BodyReading, site: int) -> None:
        self._attempts = 0
        self._capture_time = None
        self._aim = self._site_heading(reading, site)
        self._set_phase("sensing")

    def _sensed(self, site: int, quality: float) -> None:
        self._qualities[site] = quality
        self._pair.pop(0)
        if self._pair:
            self._start_leg("to_site")
            return
        self._compare()
        self._head_home()

    def _compare(self) -> None:
        (site_a, quality_a), (site_b, quality_b) = self._qualities.items()
        if quality_a == quality_b:
            return  # no evidence either way; an update would be a coin toss
        worse = site_a if quality_a < quality_b else site_b
        self._comparison = protocol.Comparison(site_a, quality_a, site_b, quality_b, worse)
        updated = decision.negative_update(self._opinion, worse, self.config.alpha)
        if updated != self._opinion:
            self._opinion = updated
            self._changed = True

    def _head_home(self) -> None:
        self._pair = []
        self._start_leg("to_nest")

    def _arrive_at_nest(self) -> ports.Command:
        self._nest_arrival = self._t
        self._next_broadcast = self._t
        self._set_phase("at_nest")
        return ports.Command(0.0, 0.0, broadcasts=self._broadcasts())

    def _pool_and_decide(self, reading: ports.BodyReading) -> None:
        since = self._nest_arrival - _TIME_EPSILON
        neighbours = [
            opinion for _, (heard, opinion) in sorted(self._heard.items()) if heard >= since
        ]
        pool = [self._opinion, *neighbours]
        pooled = decision.POOLING_OPERATORS[self.config.pooling](pool)
        if pooled is not None:  # None: contradictory evidence, keep our own opinion
            self._opinion = pooled
        self._heard = {}
        self._pool_sizes.append(len(pool))
        self._trips += 1
        self._changed = True
        decided = decision.decided_option(self._opinion, self.config.threshold)
        if decided is None:
            self._start_trip(reading)
            return
        self._decided_site = decided
        self._decision_time = self._t
        self._decision_trips = self._trips
        if self.config.linger > 0.0:
            self._linger_end = self._t + self.config.linger
            self._set_phase("lingering")
        else:
            self._start_leg("to_decision")

    def _set_phase(self, phase: protocol.Phase) -> None:
        if phase != self._phase:
            self._phase = phase
            self._changed = True

    # --- helpers -------------------------------------------------------------------

    def _estimate(self, frame: np.ndarray) -> float | None:
        try:
            quality = self._estimate_quality(frame)
        except ValueError:
            return None  # a malformed frame is no view of the site
        if quality is None or not math.isfinite(quality):
            return None
        return min(max(float(quality), 0.0), 1.0)

    def _site_heading(self, reading: ports.BodyReading, site: int) -> float:
        """Facing the site's panel from where the robot stands (radially at the viewpoint)."""
        site_x, site_y = self._site_xy[site]
        return math.atan2(site_y - reading.y, site_x - reading.x)

    def _leg_timed_out(self, reading: ports.BodyReading, goal: tuple[float, float]) -> bool:
        """Whether the current leg has taken longer than ``leg_allowance`` of its length,
        measured when the leg's first step saw where it starts."""
        if self._leg_allowance is None:
            self._leg_allowance = self.config.leg_allowance(_distance(reading, goal))
        return self._t - self._leg_start > self._leg_allowance

    def _stalled_near(
        self, reading: ports.BodyReading, goal: tuple[float, float], near: float
    ) -> bool:
        """Within ``near`` of ``goal`` but no closer for ``stall_timeout``: someone is there."""
        distance = _distance(reading, goal)
        if distance < self._best_distance - 0.01:
            self._best_distance = distance
            self._last_progress = self._t
            return False
        return distance <= near and self._t - self._last_progress >= self.config.stall_timeout


def _stop() -> ports.Command:
    return ports.Command(0.0, 0.0)


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


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
    # More robots than slots down to the nest: the count starts again at the wall.
    remaining = robot_id % max(1, sum(len(slots) for _, slots in rings))
    for radius, slots in rings:
        if remaining < len(slots):
            return radius * math.cos(slots[remaining]), radius * math.sin(slots[remaining])
        remaining -= len(slots)
    radius, slots = rings[0]
    angle = slots[0] if slots else site_angles[site]
    return radius * math.cos(angle), radius * math.sin(angle)


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


def _along_radius(x: float, y: float, radius: float) -> tuple[float, float]:
    """The point at ``radius`` from the centre on the ray through (x, y)."""
    angle = math.atan2(y, x)
    return radius * math.cos(angle), radius * math.sin(angle)


def _distance(reading: ports.BodyReading, point: tuple[float, float]) -> float:
    return math.hypot(reading.x - point[0], reading.y - point[1])


__all__ = ["Controller", "ControllerConfig", "QualityEstimator"]
