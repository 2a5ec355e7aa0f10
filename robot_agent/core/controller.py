"""The robot's controller for the paper's Section 5: a sans-IO state machine.

Each control period the transport calls ``step(reading, received)`` with what the body
sensed and the radio messages that arrived, and applies the returned ``Command`` (wheel
speeds, a camera request, opinion broadcasts). The controller reads no clock (time is
``reading.t``), draws randomness only from the ``bestofn_swarm.wire.rng.Stream`` it is given, and
does no I/O, so the same code runs over Zenoh, in tests, or on a real robot
(``ports.control_step``).

One cycle ("trip"):

    to_site -> sensing -> to_site -> sensing     visit the two sites of a weighted pair,
                                                 estimating each one's quality by camera
    compare, negative update (Definition 1)
    to_nest [-> waiting]                         until the nest beacon is heard
    at_nest                                      stop, broadcast the opinion, listen `dwell` s
    pool (MProdOp, or config.pooling) with every neighbour heard; trips += 1; decision test
    -> next pair (to_site), or lingering -> to_decision -> stopped once decided
    (and to_decision again whenever a crowd pushes it out of its slot).

That overview is defined in one place, the table ``phases.TRANSITIONS``: every phase,
the events that leave it and the phase each leads to. The controller changes phase only
by firing an event through it (``_fire``; an event the table does not list for the
current phase raises ``phases.IllegalTransitionError``). ``_behaviour`` says, for each
phase, what the robot does on entering it and each control period in it; a phase's
handler senses, then fires at most the events its phase has. The rest is done by parts
the controller uses:

* ``strategies.Strategy``: what the robot believes and decides, by ``config.strategy``:
  ``beliefs.Beliefs`` (the paper's opinion, its negative updates and pooling, the
  decision), ``voting.VoteBeliefs`` (the strategies it is compared with: one site a
  trip, sensed for ``exploration`` seconds, a dissemination of random length at the nest)
  or a plug-in's (``plugins.py``);
* ``motion.Motion``: legs of travel on the navigator, with the guards a crowded arena
  needs (a viewpoint taken by another robot counts as reached once the robot has been
  stalled close to it; a leg that takes longer than ``leg_allowance`` is given up);
* ``sensing.Sensing``: facing a site, requesting frames, retrying to either side, and
  giving the site up after ``capture_attempts`` failures;
* ``parking.Parking``: the decided robot's slot against the wall (or on a ring further in),
  never on a viewpoint, and backing off to try again when it is kept from its slot.

The radio stays here: opinions are checked before they are heard, the beacon's last
arrival is noted, and broadcasts at the nest are paced by ``broadcast_period``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from bestofn_swarm.wire import names, numeric, protocol
from bestofn_swarm.wire.compiled import mypyc_attr
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import phases, ports, strategies, vision
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.motion import STOP, TIME_EPSILON, Motion, along_radius, distance
from robot_agent.core.navigation import Navigator, NavParams
from robot_agent.core.parking import Parking, parking_rings, parking_slot
from robot_agent.core.sensing import QualityEstimator, Sensing

# A deaf robot waiting at the nest's centre drives back only once pushed farther than this
# many nest tolerances from it.
WAIT_SLACK = 2


# Studies and diagnoses watch a run through interpreted subclasses (deploy/study/observe.py,
# benchmarks/stall_diagnosis.py); compiled, a class refuses them unless it allows them.
@mypyc_attr(allow_interpreted_subclasses=True)
class Controller:
    """One robot's Section 5 behaviour; see the module docstring."""

    def __init__(
        self,
        robot_id: int,
        world: protocol.WorldInfo,
        config: ControllerConfig,
        rng: Stream,
        *,
        estimate_quality: QualityEstimator = vision.estimate_quality,
        nav_params: NavParams | None = None,
        strategy: strategies.Strategy | None = None,
    ) -> None:
        """``strategy``: the robot's strategy, made by the run's strategy plug-in (the
        robot's builder makes it); None: the built-in ``config.strategy`` names."""
        if isinstance(robot_id, bool) or not isinstance(robot_id, int):
            raise ValueError(f"robot id must be an int, got {robot_id!r}")
        if not 0 <= robot_id < names.MAX_ROBOTS:
            raise ValueError(f"robot id {robot_id} is outside 0..{names.MAX_ROBOTS - 1}")
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
        self._name = names.robot_name(robot_id)
        self._n = len(site_ids)
        # The arena is centred on the origin; sites lie on its wall.
        sites = sorted(world.sites, key=lambda site: site.id)
        self._site_xy = [(site.x, site.y) for site in sites]
        self._viewpoints = [along_radius(site.x, site.y, sensing_radius) for site in sites]
        self._nest = (world.nest.x, world.nest.y)
        params = nav_params or NavParams(
            max_speed=world.max_wheel_speed,
            wheel_base=world.wheel_base,
            robot_radius=world.robot_radius,
            control_period=world.dt,
        )
        # Its own stream, so obstacle encounters do not shift the pair choices.
        self._motion = Motion(Navigator(params, rng.fork()), config)
        self._sensing = Sensing(self._motion, config, rng, estimate_quality)
        self._parking = Parking(
            self._motion,
            world,
            config,
            robot_id,
            [numeric.atan2(site.y, site.x) for site in sites],
        )
        self._beliefs = (
            strategy
            if strategy is not None
            else strategies.make_strategy(self._n, config, robot_id)
        )
        self._rejected = 0

        # Trip state.
        self._phases = phases.PhaseMachine()
        self._started = False
        self._t = 0.0
        self._changed = True  # the initial state is news to whoever reports it
        self._pair: list[int] = []  # sites of this trip's pair still to visit, next first
        self._qualities: dict[int, float] = {}  # sites seen this trip, in visiting order
        self._last_beacon: float | None = None
        self._nest_arrival = 0.0
        self._dwell_end = 0.0  # when the robot pools, and from when what it heard counts
        self._listen_from = 0.0
        self._explore_until = 0.0  # a site is sensed at least until then
        self._exploring = False  # the site is seen and the robot stays until _explore_until
        self._next_broadcast = 0.0
        self._linger_end = 0.0
        # For each phase of the table: what the robot does on entering it, and each
        # control period while in it.
        self._behaviour: dict[
            protocol.Phase,
            tuple[
                Callable[[ports.BodyReading], None],
                Callable[[ports.BodyReading], ports.Command],
            ],
        ] = {
            "to_site": (self._start_leg, self._drive_to_site),
            "sensing": (self._start_sensing, self._sense),
            "to_nest": (self._head_home, self._drive_home),
            "waiting": (_nothing, self._wait_for_beacon),
            "at_nest": (self._arrive_at_nest, self._dwell),
            "lingering": (self._start_lingering, self._linger),
            "to_decision": (self._start_parking, self._park),
            "stopped": (_nothing, self._stay),
        }

    # --- read-only state -----------------------------------------------------------

    @property
    def phase(self) -> protocol.Phase:
        return self._phases.phase

    @property
    def opinion(self) -> list[float]:
        return list(self._beliefs.opinion)

    @property
    def trips(self) -> int:
        return self._beliefs.trips

    @property
    def pool_sizes(self) -> list[int]:
        return list(self._beliefs.pool_sizes)

    @property
    def decided_site(self) -> int | None:
        return self._beliefs.decided_site

    @property
    def decision_time(self) -> float | None:
        return self._beliefs.decision_time

    @property
    def decision_trips(self) -> int | None:
        return self._beliefs.decision_trips

    @property
    def rejected(self) -> int:
        return self._rejected

    @property
    def comparison(self) -> protocol.Comparison | None:
        return self._beliefs.comparison

    @property
    def park_retries(self) -> int:
        """How often parking had to back off and try again (a diagnostic)."""
        return self._parking.retries

    def status(self, tick: int) -> protocol.Status:
        beliefs = self._beliefs
        return protocol.Status(
            v=protocol.VERSION,
            id=self.robot_id,
            tick=tick,
            t=self._t,
            phase=self._phases.phase,
            trips=beliefs.trips,
            opinion=protocol.wire_opinion(beliefs.opinion),
            pool_size=beliefs.pool_sizes[-1] if beliefs.pool_sizes else 0,
            poolings=len(beliefs.pool_sizes),
            decided_site=beliefs.decided_site,
            decision_time=beliefs.decision_time,
            decision_trips=beliefs.decision_trips,
            comparison=beliefs.comparison,
            rejected=self._rejected,
        )

    def take_status_change(self) -> bool:
        """True once after any change of phase, trips, opinion, pool size or decision."""
        changed, self._changed = self._changed, False
        return changed

    # --- the step ------------------------------------------------------------------

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        """Advance the state machine by one control period."""
        expected = len(self._motion.navigator.params.prox_angles)
        if len(reading.proximity) != expected:
            raise ValueError(
                f"expected {expected} proximity readings, got {len(reading.proximity)}"
            )
        self._t = reading.t
        self._listen(received)
        if not self._started:
            self._started = True
            self._choose_pair(reading)
            self._fire("start", reading)
        _, act = self._behaviour[self._phases.phase]
        return act(reading)

    def _fire(self, event: phases.Event, reading: ports.BodyReading) -> None:
        """Take the table's transition for ``event`` (``phases.IllegalTransitionError`` if the
        current phase has none) and do what entering the new phase involves."""
        leaving = self._phases.phase
        entering = self._phases.fire(event)
        if entering != leaving:
            self._changed = True
        enter, _ = self._behaviour[entering]
        enter(reading)

    # --- radio ---------------------------------------------------------------------

    def _listen(self, received: Sequence[ports.Received]) -> None:
        for message in received:
            payload = message.payload
            if isinstance(payload, protocol.BeaconPayload):
                self._last_beacon = self._t
            else:
                self._hear_opinion(message.sender, payload)

    def _hear_opinion(self, sender: str, payload: protocol.RobotBroadcast) -> None:
        if sender == self._name and payload.id == self.robot_id:
            return  # our own broadcast echoed back
        if sender != names.robot_name(payload.id):
            self._rejected += 1  # a robot claiming someone else's id
            return
        if not self._beliefs.hear_payload(payload.id, self._t, payload):
            self._rejected += 1  # not an opinion over our sites, or another strategy's
            return

    def _hears_beacon(self, since: float) -> bool:
        heard = self._last_beacon
        return (
            heard is not None
            and heard + TIME_EPSILON >= since
            and self._t - heard <= self.config.beacon_timeout + TIME_EPSILON
        )

    def _broadcasts(self) -> tuple[protocol.RobotBroadcast, ...]:
        if self._t + TIME_EPSILON < self._next_broadcast:
            return ()
        self._next_broadcast = self._t + self.config.broadcast_period
        return (self._beliefs.broadcast(self.robot_id),)

    # --- each control period in a phase: sense, then fire what happened -------------

    def _drive_to_site(self, reading: ports.BodyReading) -> ports.Command:
        goal = self._viewpoints[self._pair[0]]
        left, right, arrived = self._motion.drive_to(reading, goal, self.config.view_tolerance)
        if arrived or self._motion.stalled_near(reading, goal, self.config.near_distance):
            self._fire("reached_viewpoint", reading)
            return self._sense(reading)
        if self._motion.timed_out(reading, goal):
            self._fire("leg_timed_out", reading)
            return STOP
        return ports.Command(left, right)

    def _sense(self, reading: ports.BodyReading) -> ports.Command:
        if self._exploring:  # seen: the strategy keeps the robot at its site a while
            if self._t + TIME_EPSILON >= self._explore_until:
                self._exploring = False
                self._compare(reading)
            return STOP
        look = self._sensing.step(reading)
        if look.quality is not None:
            self._qualities[self._pair.pop(0)] = look.quality
            if self._pair:
                self._fire("sensed_first_site", reading)
            elif self._t + TIME_EPSILON < self._explore_until:
                self._exploring = True
            else:
                self._compare(reading)
        elif look.gave_up:
            self._fire("site_unseen", reading)
        return look.command

    def _compare(self, reading: ports.BodyReading) -> None:
        if self._beliefs.compare(self._qualities):
            self._changed = True
        self._fire("compared", reading)

    def _drive_home(self, reading: ports.BodyReading) -> ports.Command:
        if self._hears_beacon(self._motion.leg_start):
            self._fire("heard_beacon", reading)
            return ports.Command(0.0, 0.0, broadcasts=self._broadcasts())
        left, right, arrived = self._motion.drive_to(
            reading, self._nest, self.config.nest_tolerance
        )
        if arrived:
            self._fire("reached_nest_centre", reading)
            return STOP
        return ports.Command(left, right)

    def _wait_for_beacon(self, reading: ports.BodyReading) -> ports.Command:
        """At the nest centre without hearing the beacon: stay there until it is heard."""
        if self._hears_beacon(self._motion.leg_start):
            self._fire("heard_beacon", reading)
            return ports.Command(0.0, 0.0, broadcasts=self._broadcasts())
        if distance(reading, self._nest) <= WAIT_SLACK * self.config.nest_tolerance:
            return STOP  # pushed a little: not worth driving back yet
        left, right, _ = self._motion.drive_to(reading, self._nest, self.config.nest_tolerance)
        return ports.Command(left, right)

    def _dwell(self, reading: ports.BodyReading) -> ports.Command:
        broadcasts = self._broadcasts()  # the opinion as it was before pooling
        if self._t + TIME_EPSILON >= self._dwell_end:
            self._pool_and_decide(reading)
        return ports.Command(0.0, 0.0, broadcasts=broadcasts)

    def _pool_and_decide(self, reading: ports.BodyReading) -> None:
        self._beliefs.pool(self._listen_from - TIME_EPSILON, self._t, self._rng)
        self._changed = True
        if self._beliefs.decided_site is None:
            self._choose_pair(reading)
            self._fire("pooled_undecided", reading)
        elif self.config.linger > 0.0:
            self._fire("decided_to_linger", reading)
        else:
            self._fire("decided", reading)

    def _linger(self, reading: ports.BodyReading) -> ports.Command:
        broadcasts = self._broadcasts()
        if self._t + TIME_EPSILON >= self._linger_end:
            self._fire("lingered", reading)
        return ports.Command(0.0, 0.0, broadcasts=broadcasts)

    def _park(self, reading: ports.BodyReading) -> ports.Command:
        command = self._parking.step(reading)
        if command is None:
            self._fire("parked", reading)
            return STOP
        return command

    def _stay(self, reading: ports.BodyReading) -> ports.Command:
        if self._parking.displaced(reading):
            self._fire("displaced", reading)
            return self._park(reading)
        return STOP

    # --- on entering a phase -------------------------------------------------------

    def _choose_pair(self, reading: ports.BodyReading) -> None:
        """The sites of the next trip, as the strategy draws them (the paper's: a pair by
        weight from the opinion)."""
        sites = self._beliefs.next_sites(self._rng)
        # Visit the nearer viewpoint first; the sites themselves are what the rng chose.
        if len(sites) == 2:
            first, second = sites
            if distance(reading, self._viewpoints[second]) < distance(
                reading, self._viewpoints[first]
            ):
                sites = [second, first]
        self._pair = sites
        self._qualities = {}

    def _start_leg(self, reading: ports.BodyReading) -> None:
        self._motion.start_leg(self._t)

    def _start_sensing(self, reading: ports.BodyReading) -> None:
        self._sensing.begin(reading, self._site_xy[self._pair[0]])
        self._explore_until = self._t + self._beliefs.exploration(self._rng)

    def _head_home(self, reading: ports.BodyReading) -> None:
        self._pair = []  # whatever is left of the pair is given up
        self._motion.start_leg(self._t)

    def _arrive_at_nest(self, reading: ports.BodyReading) -> None:
        self._nest_arrival = self._t
        self._next_broadcast = self._t
        self._dwell_end, self._listen_from = self._beliefs.nest_visit(self._t, self._rng)

    def _start_lingering(self, reading: ports.BodyReading) -> None:
        self._linger_end = self._t + self.config.linger

    def _start_parking(self, reading: ports.BodyReading) -> None:
        assert self._beliefs.decided_site is not None
        self._parking.begin(self._beliefs.decided_site, self._t)


def _nothing(reading: ports.BodyReading) -> None:
    """Entering this phase involves nothing beyond the phase change."""


# parking_slot and parking_rings live in robot_agent/core/parking.py; they are exported here
# too, where tests and benchmarks have always imported them from.
__all__ = [
    "WAIT_SLACK",
    "Controller",
    "ControllerConfig",
    "QualityEstimator",
    "parking_rings",
    "parking_slot",
]
