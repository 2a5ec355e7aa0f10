"""What a plug-in gives, checked as a run goes (pure).

A plug-in is someone else's code inside a robot's step. The built-ins are trusted and run
as they are; a plug-in is wrapped so that whatever it raises, and whatever it gives that
the controller could not use (a site that is not one, a wrong type, an opinion with a NaN
or a negative weight, an opinion that does not sum to 1), becomes a ``PluginCallError``
naming it and what it did; the robot's ``CheckedController`` adds the robot and the tick
and raises the ``PluginError`` that ends the run (a stated ending, the recording finished).
The checks change nothing a good plug-in gives: a plug-in that only hands each call to a
built-in makes the built-in's run, bit for bit.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from typing import Any

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import decision, ports
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import Plugin, PluginCallError, PluginError, error_text
from robot_agent.core.wrapped import WrappedController

# How far from 1 the sum of a pooled opinion may be: a few roundings of a normalisation.
SUM_TOLERANCE = 1e-9


def _number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _count(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def opinion_problem(value: object, sites: int, *, normalised: bool) -> str | None:
    """What is wrong with ``value`` as an opinion over ``sites`` sites (None: nothing):
    a list of ``sites`` finite non-negative numbers with a positive sum (summing to 1 when
    ``normalised``)."""
    if not isinstance(value, Sequence) or isinstance(value, str | bytes):
        return f"{_shown(value)}, not a list of {sites} probabilities"
    if len(value) != sites:
        return f"an opinion of {len(value)} entries over {sites} sites"
    for index, entry in enumerate(value):
        if not _number(entry):
            return f"an opinion with {_shown(entry)} at [{index}]"
        if not math.isfinite(entry):
            return f"an opinion with {entry} at [{index}]"
        if entry < 0.0:
            return f"an opinion with a negative weight {entry} at [{index}]"
    total = math.fsum(float(entry) for entry in value)
    if total <= 0.0:
        return "an opinion of all zeros"
    if normalised and abs(total - 1.0) > SUM_TOLERANCE:
        return f"an opinion that sums to {total:.12g}, not 1"
    return None


def checked_pooling(plugin: Plugin) -> decision.PoolingOperator:
    """The pooling plug-in's operator, checked: it may raise nothing, and gives None or an
    opinion as long as the pool's, normalised (None, not zeros, says the pool
    contradicts itself)."""
    operator: decision.PoolingOperator = plugin.target

    def pool(opinions: Sequence[Sequence[float]]) -> list[float] | None:
        try:
            pooled = operator(opinions)
        except PluginCallError:
            raise
        except Exception as error:
            raise PluginCallError(plugin, f"raised {error_text(error)}") from None
        if pooled is None:
            return None
        problem = opinion_problem(pooled, len(opinions[0]), normalised=True)
        if problem is not None:
            hint = " (return None for a pool that contradicts itself)" if "zeros" in problem else ""
            raise PluginCallError(plugin, f"returned {problem}{hint}")
        return [float(value) for value in pooled]

    return pool


def make_strategy(
    plugin: Plugin,
    sites: int,
    config: ControllerConfig,
    robot_id: int,
    pooling: decision.PoolingOperator,
) -> CheckedStrategy:
    """Robot ``robot_id``'s strategy from the strategy plug-in, checked."""
    try:
        made = plugin.target(sites, config, robot_id, pooling)
    except PluginCallError as failure:
        raise failure.at(robot_id, None) from None
    except Exception as error:
        raise PluginError(
            f"{plugin.describe()} raised {error_text(error)} making robot {robot_id}'s strategy"
        ) from None
    missing = [
        member
        for member in (*STRATEGY_METHODS, *STRATEGY_VALUES)
        if not hasattr(made, member)
        or (member in STRATEGY_METHODS and not callable(getattr(made, member)))
    ]
    if missing:
        raise PluginError(
            f"{plugin.describe()} made {_shown(made)} for robot {robot_id}, not a strategy "
            f"(it lacks {', '.join(missing)})"
        )
    return CheckedStrategy(made, plugin, sites)


STRATEGY_METHODS = (
    "next_sites",
    "compare",
    "exploration",
    "nest_visit",
    "hear_payload",
    "broadcast",
    "pool",
)
STRATEGY_VALUES = (
    "opinion",
    "trips",
    "pool_sizes",
    "comparison",
    "decided_site",
    "decision_time",
    "decision_trips",
)


class CheckedStrategy:
    """A strategy plug-in's strategy (``strategies.Strategy``), each call checked."""

    def __init__(self, inner: Any, plugin: Plugin, sites: int) -> None:
        self._inner = inner
        self._plugin = plugin
        self._sites = sites

    def _fail(self, what: str) -> PluginCallError:
        return PluginCallError(self._plugin, what)

    def _call(self, method: str, *args: Any) -> Any:
        try:
            return getattr(self._inner, method)(*args)
        except PluginCallError:
            raise
        except Exception as error:
            raise self._fail(f"raised {error_text(error)} in {method}") from None

    def _read(self, name: str) -> Any:
        try:
            return getattr(self._inner, name)
        except PluginCallError:
            raise
        except Exception as error:
            raise self._fail(f"raised {error_text(error)} reading {name}") from None

    def _site(self, value: object) -> bool:
        return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < self._sites

    # --- what the status reads -------------------------------------------------------

    @property
    def opinion(self) -> list[float]:
        value = self._read("opinion")
        problem = opinion_problem(value, self._sites, normalised=False)
        if problem is not None:
            raise self._fail(f"holds {problem} (its opinion)")
        return [float(entry) for entry in value]

    @property
    def trips(self) -> int:
        value = self._read("trips")
        if not _count(value) or value < 0:
            raise self._fail(f"counts {_shown(value)} trips, not a whole number")
        return int(value)

    @property
    def pool_sizes(self) -> list[int]:
        value = self._read("pool_sizes")
        if not isinstance(value, Sequence) or not all(_count(size) and size >= 1 for size in value):
            raise self._fail(f"holds pool sizes {_shown(value)}, not a list of counts")
        return [int(size) for size in value]

    @property
    def comparison(self) -> protocol.Comparison | None:
        value = self._read("comparison")
        if value is not None and not isinstance(value, protocol.Comparison):
            raise self._fail(f"holds the comparison {_shown(value)}, not a Comparison or None")
        return value

    @property
    def decided_site(self) -> int | None:
        value = self._read("decided_site")
        if value is not None and not self._site(value):
            raise self._fail(f"decided on {_shown(value)}, not a site (0..{self._sites - 1})")
        return None if value is None else int(value)

    @property
    def decision_time(self) -> float | None:
        value = self._read("decision_time")
        if value is not None and not (_number(value) and math.isfinite(value)):
            raise self._fail(f"decided at {_shown(value)}, not a sim time")
        return None if value is None else float(value)

    @property
    def decision_trips(self) -> int | None:
        value = self._read("decision_trips")
        if value is not None and not (_count(value) and value >= 0):
            raise self._fail(f"decided after {_shown(value)} trips, not a whole number")
        return None if value is None else int(value)

    # --- what the controller asks ----------------------------------------------------

    def next_sites(self, rng: Stream) -> list[int]:
        sites = self._call("next_sites", rng)
        if (
            not isinstance(sites, Sequence)
            or not 1 <= len(sites) <= 2
            or not all(self._site(site) for site in sites)
            or len(set(sites)) != len(sites)
        ):
            raise self._fail(
                f"chose the sites {_shown(sites)}: one or two distinct sites of "
                f"0..{self._sites - 1}"
            )
        return [int(site) for site in sites]

    def compare(self, qualities: dict[int, float]) -> bool:
        changed = self._call("compare", qualities)
        if not isinstance(changed, bool):
            raise self._fail(f"returned {_shown(changed)} from compare, not True or False")
        return changed

    def exploration(self, rng: Stream) -> float:
        seconds = self._call("exploration", rng)
        if not _number(seconds) or not math.isfinite(seconds) or seconds < 0.0:
            raise self._fail(f"returned {_shown(seconds)} from exploration, not seconds >= 0")
        return float(seconds)

    def nest_visit(self, arrival: float, rng: Stream) -> tuple[float, float]:
        times = self._call("nest_visit", arrival, rng)
        if (
            not isinstance(times, Sequence)
            or len(times) != 2
            or not all(_number(value) and math.isfinite(value) for value in times)
        ):
            raise self._fail(
                f"returned {_shown(times)} from nest_visit, not two sim times (pool at, "
                "heard since)"
            )
        return float(times[0]), float(times[1])

    def hear_payload(self, robot_id: int, t: float, payload: object) -> bool:
        taken = self._call("hear_payload", robot_id, t, payload)
        if not isinstance(taken, bool):
            raise self._fail(f"returned {_shown(taken)} from hear_payload, not True or False")
        return taken

    def broadcast(self, robot_id: int) -> protocol.RobotBroadcast:
        payload = self._call("broadcast", robot_id)
        problem = broadcast_problem(payload, robot_id, self._sites)
        if problem is not None:
            raise self._fail(f"broadcast {problem}")
        broadcast: protocol.RobotBroadcast = payload
        return broadcast

    def pool(self, since: float, t: float, rng: Stream) -> None:
        self._call("pool", since, t, rng)


def broadcast_problem(payload: object, robot_id: int, sites: int) -> str | None:
    """What is wrong with ``payload`` as robot ``robot_id``'s broadcast (None: nothing)."""
    if not isinstance(payload, protocol.OpinionPayload | protocol.VotePayload):
        return f"{_shown(payload)}, not an OpinionPayload or a VotePayload"
    if payload.id != robot_id:
        return f"in the name of robot {payload.id}"
    if isinstance(payload, protocol.OpinionPayload):
        return opinion_problem(payload.opinion, sites, normalised=False)
    if not 0 <= payload.site < sites or not math.isfinite(payload.quality):
        return f"a vote for site {payload.site} of quality {payload.quality}"
    return None


def controller_plugin_maker(plugin: Plugin) -> Callable[..., ports.RobotController]:
    """What makes each robot's controller from a controller plug-in: its factory called with
    the robot's id, map, settings and generator, and what it makes checked to be a
    controller (a Byzantine behaviour that changes the built-in controller, ``inverted``,
    cannot be given to it)."""

    def make(
        robot_id: int,
        world: protocol.WorldInfo,
        config: ControllerConfig,
        rng: Stream,
        **extra: Any,
    ) -> ports.RobotController:
        if extra:
            raise PluginError(
                f"{plugin.describe()} is a whole controller: a robot made to misbehave by "
                f"changing the built-in controller ({', '.join(extra)}) cannot run it"
            )
        try:
            made = plugin.target(robot_id, world, config, rng)
        except Exception as error:
            raise PluginError(
                f"{plugin.describe()} raised {error_text(error)} making robot {robot_id}"
            ) from None
        missing = [
            member
            for member in ("step", "status", "take_status_change", "decided_site")
            if not hasattr(made, member)
        ]
        if missing:
            raise PluginError(
                f"{plugin.describe()} made {_shown(made)} for robot {robot_id}, not a "
                f"controller (it lacks {', '.join(missing)}; docs/porting.md)"
            )
        controller: ports.RobotController = made
        return controller

    return make


class CheckedController(WrappedController):
    """A robot's controller when any plug-in is in it: a ``PluginCallError`` from within
    becomes the ``PluginError`` naming the robot and the tick (``dt``: the world's step, for
    the tick of a reading's time); ``plugin`` (a controller plug-in) has whatever it raises
    and gives checked too."""

    def __init__(
        self,
        inner: ports.RobotController,
        robot_id: int,
        dt: float,
        plugin: Plugin | None = None,
    ) -> None:
        super().__init__(inner)
        self.robot_id = robot_id
        self._dt = dt
        self._plugin = plugin

    def _tick(self, t: float) -> int:
        return round(t / self._dt)

    def _raised(self, error: Exception, where: str, tick: int | None) -> PluginError:
        if isinstance(error, PluginCallError):
            return error.at(self.robot_id, tick)
        assert self._plugin is not None
        return PluginCallError(self._plugin, f"raised {error_text(error)} in {where}").at(
            self.robot_id, tick
        )

    def _guards(self, error: Exception) -> bool:
        return isinstance(error, PluginCallError) or self._plugin is not None

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        try:
            command = self._controller.step(reading, received)
        except Exception as error:
            if not self._guards(error):
                raise
            raise self._raised(error, "step", self._tick(reading.t)) from None
        if self._plugin is not None:
            problem = command_problem(command, self.robot_id)
            if problem is not None:
                raise PluginCallError(self._plugin, f"returned {problem} from step").at(
                    self.robot_id, self._tick(reading.t)
                )
        return command

    def status(self, tick: int) -> protocol.Status:
        try:
            status = self._controller.status(tick)
        except Exception as error:
            if not self._guards(error):
                raise
            raise self._raised(error, "status", tick) from None
        if self._plugin is not None:
            problem = status_problem(status, self.robot_id, tick)
            if problem is not None:
                raise PluginCallError(self._plugin, f"returned {problem} from status").at(
                    self.robot_id, tick
                )
        return status

    def take_status_change(self) -> bool:
        try:
            changed = self._controller.take_status_change()
        except Exception as error:
            if not self._guards(error):
                raise
            raise self._raised(error, "take_status_change", None) from None
        if self._plugin is not None and not isinstance(changed, bool):
            raise PluginCallError(
                self._plugin, f"returned {_shown(changed)} from take_status_change"
            ).at(self.robot_id, None)
        return changed

    @property
    def decided_site(self) -> int | None:
        try:
            site = self._controller.decided_site
        except Exception as error:
            if not self._guards(error):
                raise
            raise self._raised(error, "decided_site", None) from None
        if self._plugin is not None and site is not None and not _count(site):
            raise PluginCallError(self._plugin, f"decided on {_shown(site)}").at(
                self.robot_id, None
            )
        return site


def command_problem(command: object, robot_id: int) -> str | None:
    """What is wrong with ``command`` as a controller's answer (None: nothing)."""
    if not isinstance(command, ports.Command):
        return f"{_shown(command)}, not a Command"
    for side in ("left", "right"):
        speed = getattr(command, side)
        if not _number(speed) or not math.isfinite(speed):
            return f"a {side} wheel speed of {_shown(speed)}"
    if not isinstance(command.capture, bool):
        return f"a capture request of {_shown(command.capture)}"
    if not isinstance(command.broadcasts, tuple):
        return f"broadcasts {_shown(command.broadcasts)}, not a tuple"
    for payload in command.broadcasts:
        if not isinstance(payload, protocol.OpinionPayload | protocol.VotePayload):
            return f"a broadcast {_shown(payload)}"
        if payload.id != robot_id:
            return f"a broadcast in the name of robot {payload.id}"
    return None


def status_problem(status: object, robot_id: int, tick: int) -> str | None:
    """What is wrong with ``status`` as robot ``robot_id``'s status at ``tick``."""
    if not isinstance(status, protocol.Status):
        return f"{_shown(status)}, not a Status"
    if status.id != robot_id or status.tick != tick:
        return f"the status of robot {status.id} at tick {status.tick}"
    if not all(math.isfinite(value) for value in status.opinion):
        return "a status whose opinion is not finite"
    return None


__all__ = [
    "STRATEGY_METHODS",
    "STRATEGY_VALUES",
    "CheckedController",
    "CheckedStrategy",
    "broadcast_problem",
    "checked_pooling",
    "command_problem",
    "controller_plugin_maker",
    "make_strategy",
    "opinion_problem",
    "status_problem",
]
