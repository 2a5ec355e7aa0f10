"""How the world ends its run (pure: no I/O, no clock): the world server's referee.

The world server decides every run's ending itself, by the rules ``swarm run`` has always
used (``bestofn_swarm.wire.endings.stop_reason``, in its order), with the run's one
observer (``RunObserver``: each robot's record from its status, the stall watchdog, the
summary). The server's adapter (``world_server/server/zenoh_adapter.py``) feeds it the
robots' statuses and their links' figures as they come, and at each look the world's own
tick, sim time and who is live (its liveliness roster); at every ``--state-every`` tick
the world's state, as the launcher sees it. ``look`` answers whether the run ends now;
``ending`` is the ``world/ending`` message every process of the run exits on.

What the world knows, and decides:

* every running robot decided (consensus or split), the sim time limit, the stall
  watchdog;
* a robot or beacon whose liveliness went, not as a fault of the run's plan
  (``departures``), is *away*: its process died, or its link was cut (a machine suspended
  for longer than Zenoh's lease loses every token and gets them back once it wakes). For
  ``LOST_AFTER`` wall seconds it counts as if it were there (an undecided robot away holds
  the run up, as a frozen process does); back by then, nothing happened. After that it is
  lost: a lost beacon ends the run ``crashed`` at once; a lost robot holds nothing up and is
  not among those whose decisions count, and the run goes on and ends ``crashed``
  (``lost_robot`` ``continue``, what ``swarm run`` does on one machine), or ends ``crashed``
  at once without waiting (``end``, what ``swarm run --dask`` asks: a lost host takes its
  robots with it). What is still away when the run ends is not lost: it may be frozen
  (a launcher that saw its process die says so: docs/running.md). A lost robot that comes
  back runs again;
* a robot killed or restarted by the run's plan (``--kill``, ``--restart``: the launcher
  applies them, the world is told them): killed, or restarting until it rejoins, as the
  launcher counts it; a robot outside the emulator whose link went: departed;
* a stop signal to the world server: interrupted.

What only a launcher knows stays its own (docs/running.md): a stop signal to the launcher,
its wall time limit, a process it started that died, a world that stopped ticking.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Annotated, Any, ClassVar

from msgspec import Meta

from bestofn_swarm.wire import names, protocol, settings, shape
from bestofn_swarm.wire.endings import Ending, Halt, Look, Stop, stop_reason
from bestofn_swarm.wire.settings import Flag
from robot_agent.core import byzantine
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.parking import ParkingSlots
from world_server.observer.observer import RunObserver
from world_server.observer.watchdog import Watchdog, default_stall_window

# Wall seconds a robot or beacon whose liveliness went may take to come back before it is
# lost: Zenoh's 10 s lease, the seconds a thawed process takes to reconnect, and room.
LOST_AFTER = 30.0


class LostRobot(StrEnum):
    """What a robot lost mid-run does to the run."""

    CONTINUE = "continue"  # the rest go on; the run ends crashed when it ends
    END = "end"  # the run ends crashed at once


@dataclass(frozen=True)
class PlannedDeparture:
    """A fault of the run's plan: robot ``robot``'s process is stopped once the run's sim
    time reaches ``at``, and (``returns``) a fresh one started (``--kill``, ``--restart``)."""

    robot: Annotated[int, Meta(ge=0, lt=names.MAX_ROBOTS)]
    at: Annotated[float, Meta(ge=0.0, le=protocol.MAX_SIM_TIME)]
    returns: bool = False


@dataclass(frozen=True)
class OutsideRobot:
    """A robot run by a program outside the emulator, over a link of ``transport``."""

    robot: Annotated[int, Meta(ge=0, lt=names.MAX_ROBOTS)]
    transport: Annotated[str, Meta(max_length=16)]


def _controller(text: str) -> ControllerConfig:
    return settings.decode(text, ControllerConfig)


@dataclass(frozen=True)
class EndingRules:
    """How the world ends its run: the limits ``swarm run`` hands it, what the robots are
    (their controller's settings, the Byzantine ones, those outside), the faults its plan
    applies, and what a lost robot does."""

    FLAG_GROUP: ClassVar[str] = "ending"

    timeout: Annotated[
        float,
        Meta(
            gt=0.0,
            le=protocol.MAX_SIM_TIME,
            description="end the run as timeout after this much sim time",
        ),
        Flag(metavar="SIM_SECONDS"),
    ] = shape.DEFAULT_TIMEOUT
    stall_window: Annotated[
        Annotated[float, Meta(gt=0.0, le=protocol.MAX_SIM_TIME)] | None,
        Meta(
            description="end the run as stalled when, with some robot undecided, no robot at "
            "work completed a step of its task for this much sim time"
        ),
        Flag(
            metavar="SIM_SECONDS",
            default_text="as swarm run's, for this arena, the robots' controller settings "
            "and a beacon without outages",
        ),
    ] = None
    lost_robot: Annotated[
        LostRobot,
        Meta(
            description="what a robot lost mid-run (its liveliness gone, not by a fault of "
            "the run's plan) does: continue (the rest go on, the run ends crashed) or end "
            "(the run ends crashed at once)"
        ),
        Flag(),
    ] = LostRobot.CONTINUE
    controller: Annotated[
        ControllerConfig,
        Meta(
            description="the robots' controller settings (a ControllerConfig), for where "
            "decided robots park and the default stall window"
        ),
        Flag(
            name="controller-settings",
            metavar="JSON",
            parse=_controller,
            default_text="the controller's defaults",
        ),
    ] = field(default_factory=ControllerConfig)
    byzantine: Annotated[
        tuple[byzantine.ByzantineRobot, ...],
        Meta(
            description="robot ROBOT misbehaves (as its robot-agent was told): its decision "
            "is not the swarm's, and consensus counts the honest robots"
        ),
        Flag(metavar="ROBOT[:MODE]"),
    ] = ()
    departures: tuple[PlannedDeparture, ...] = ()  # --kill, --restart (swarm run's plan)
    outside: tuple[OutsideRobot, ...] = ()  # --external (swarm run's plan)

    def __post_init__(self) -> None:
        settings.check(self)


@dataclass(frozen=True)
class RunShape:
    """What the referee needs of the world itself."""

    run_id: str
    seed: int
    num_robots: int
    num_sites: int
    best_site: int
    info: protocol.WorldInfo
    beacons: int = 1  # beacons the world waits for


class Referee:
    """The world's judge of its run: fed what happens, asked whether it ends."""

    def __init__(
        self, shape: RunShape, rules: EndingRules, config: dict[str, Any] | None = None
    ) -> None:
        """``config``: the summary's ``config`` (the settings the world runs with)."""
        self.shape = shape
        self.rules = rules
        self.config = dict(config or {})
        info = shape.info
        self.behaviours = byzantine.resolve_liar_sites(
            {switch.robot: switch.behaviour for switch in rules.byzantine},
            shape.num_sites,
            shape.best_site,
            shape.seed,
        )
        self.stall_window = rules.stall_window or default_stall_window(
            info.arena_radius,
            info.max_wheel_speed,
            # The longest leg a robot may take before it gives up: across the arena.
            rules.controller.leg_allowance(2 * info.arena_radius),
            time_limit=rules.timeout,
        )
        robots = range(shape.num_robots)
        self.outside = {linked.robot: linked.transport for linked in rules.outside}
        self.observer = RunObserver(
            robots,
            watchdog=Watchdog(
                robots,
                self.stall_window,
                body_length=2 * info.robot_radius,
                slot_of=ParkingSlots.of_world(info, rules.controller).slot,
            ),
            byzantine=self.behaviours,
            outside=self.outside,
        )
        self.started = False  # the world opened its first tick
        self.tick = 0
        self.t = 0.0
        self._live: set[int] = set()
        self._beacons: set[str] = set()
        self._planned = sorted(rules.departures, key=lambda planned: planned.at)
        self._restarting: set[int] = set()  # restarted by the plan, not yet back
        self._away: dict[int | str, float] = {}  # robot or beacon -> wall time it went
        self._returned: set[int] = set()  # back after it went: its next status tells how
        self.lost: list[str] = []  # robots (ids) and beacons (names) lost, in order
        self.beacon_lost = False

    # --- fed -------------------------------------------------------------------------

    def take(self, opened: Any) -> None:
        """A robot's status, a beacon's ack or a link's figures, through the key table's
        gate (raises ``keyspace.SampleError`` for one that makes no sense: the adapter
        counts it). A robot back after it went that reports from an older tick than it
        did is a fresh process: restarted."""
        message = opened.message
        if isinstance(message, protocol.Status) and message.id in self._returned:
            self._returned.discard(message.id)
            last = self.observer.records[message.id].status
            if last is not None and message.tick < last.tick:
                self.observer.restarted(message.id)
        self.observer.take(opened)

    def state(self, state: protocol.WorldState) -> None:
        """The world's state, as it publishes it (every ``--state-every`` ticks)."""
        self.observer.state(state)

    def now(
        self,
        tick: int,
        t: float,
        live: Iterable[int],
        beacons: Iterable[str],
        wall: float = 0.0,
    ) -> None:
        """The world at a look: its tick and sim time, the robots and beacons live now, and
        the wall time (for how long those that went have been away)."""
        now_live, now_beacons = set(live), set(beacons)
        if not self.started:
            self.started = True
            self._live, self._beacons = now_live, now_beacons
        self.tick, self.t = tick, t
        self.observer.clock(protocol.Clock(v=protocol.VERSION, tick=tick, t=t))
        for robot in sorted(self._live - now_live):
            self._left(robot, wall)
        for robot in sorted(now_live - self._live):
            self._came_back(robot)
        for beacon in sorted(self._beacons - now_beacons):
            self._away.setdefault(beacon, wall)
        for beacon in now_beacons:
            self._away.pop(beacon, None)
        self._live = now_live
        self._beacons = now_beacons | {gone for gone in self._away if isinstance(gone, str)}
        for gone, since in list(self._away.items()):
            at_once = isinstance(gone, int) and self.rules.lost_robot is LostRobot.END
            if at_once or wall - since >= LOST_AFTER:
                del self._away[gone]
                # A beacon beyond those the run waits for (a spare) is not missed.
                if isinstance(gone, int) or len(now_beacons) < self.shape.beacons:
                    self._lose(gone)

    def _left(self, robot: int, wall: float) -> None:
        if robot in self.outside:
            return  # its link went: it counts again when its program is back
        planned = next((p for p in self._planned if p.robot == robot and p.at <= self.t), None)
        if planned is not None:
            self._planned.remove(planned)
            self.observer.killed(robot)
            if planned.returns:
                self.observer.restarted(robot)
                self._restarting.add(robot)
            return
        self._away.setdefault(robot, wall)

    def _lose(self, gone: int | str) -> None:
        if isinstance(gone, str):
            self.lost.append(gone)
            self.beacon_lost = True
            return
        self.observer.crashed(gone)
        self.lost.append(names.robot_name(gone))

    def _came_back(self, robot: int) -> None:
        if robot in self._restarting:
            self._restarting.discard(robot)
            return
        # Killed by the plan earlier, now started again by it (--kill, then --restart).
        planned = next((p for p in self._planned if p.robot == robot and p.returns), None)
        if planned is not None and self.observer.records[robot].killed:
            self._planned.remove(planned)
            self.observer.restarted(robot)
            return
        if self._away.pop(robot, None) is not None:
            self._returned.add(robot)  # back in time: as if it never went
            return
        name = names.robot_name(robot)
        if name in self.lost:  # lost, and back: it runs again
            self.lost.remove(name)
            self.observer.returned(robot)
            self._returned.add(robot)

    # --- asked -----------------------------------------------------------------------

    @property
    def lost_robots(self) -> list[int]:
        return [robot for name in self.lost if (robot := names.robot_of_name(name)) is not None]

    def running(self) -> list[int]:
        """The robots whose decisions count now: live (an outside one: its link up),
        restarting by the plan, or away and not yet lost."""
        away = {gone for gone in self._away if isinstance(gone, int)}
        return sorted(self._live | self._restarting | away)

    def look(self, signalled: bool = False) -> Halt | None:
        """Whether the run ends at this look, and why (``stop_reason``, in its order)."""
        if not self.started:
            return Halt(Stop.INTERRUPTED) if signalled else None
        observer = self.observer
        # A restart still to come will make progress: wait for it, as swarm run does.
        waiting = any(planned.returns for planned in self._planned)
        running = self.running()
        # With no robot running (every one gone), the world waits for them: nobody decided.
        all_decided = not waiting and bool(running) and observer.all_decided(running)
        lost_ends = self.rules.lost_robot is LostRobot.END and bool(self.lost_robots)
        return stop_reason(
            Look(
                sim_time=self.t,
                sim_limit=self.rules.timeout,
                all_decided=all_decided,
                last_decision=observer.last_decision(running) if all_decided else 0.0,
                stalled=not waiting and observer.stalled(self.t),
                crashed=self.beacon_lost or lost_ends,
                signalled=signalled,
            )
        )

    def ending(
        self,
        halt: Halt,
        state: protocol.WorldState | None,
        wall_time: float,
        signum: int | None = None,
        signal_name: str | None = None,
    ) -> protocol.RunEnding:
        """The run's ending once ``look`` said ``halt``: ``state``, the world's last state
        and counters; ``wall_time``, wall seconds since its first tick."""
        stop = halt.stop
        if self.lost_robots and stop is not Stop.INTERRUPTED:
            stop = Stop.CRASHED  # a robot lost: as swarm run, the run has no result
        observer = self.observer
        if state is not None:
            observer.state(state)
        observer.departed(robot for robot in self.outside if robot in self._live)
        shape = self.shape
        summary = observer.summary(
            run_id=shape.run_id,
            num_robots=shape.num_robots,
            num_sites=shape.num_sites,
            seed=shape.seed,
            best_site=shape.best_site,
            wall_time_s=wall_time,
            config=self.config,
            stop=stop,
            timeout_kind=halt.limit,
            world=state,
            byzantine={robot: str(how) for robot, how in self.behaviours.items()},
        )
        if signal_name is not None:
            summary["signal"] = signal_name
        if self.lost:
            summary["lost"] = list(self.lost)
        ended = Ending(summary["ended"])
        return protocol.RunEnding(
            v=protocol.VERSION,
            run=shape.run_id,
            ended=ended,
            code=ended.exit_code(signum),
            stop=stop,
            timeout_kind=halt.limit if stop is Stop.TIMEOUT else None,
            tick=self.tick,
            t=min(self.t, protocol.MAX_SIM_TIME),
            signal=signal_name,
            lost=list(self.lost),
            summary=summary,
        )


__all__ = [
    "EndingRules",
    "LostRobot",
    "OutsideRobot",
    "PlannedDeparture",
    "Referee",
    "RunShape",
]
