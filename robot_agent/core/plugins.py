"""Plug-ins: a decision rule, a pooling operator or a whole controller of one's own, by name.

Three points of the robot take code from outside the project (docs/extending.md):

=============  ===============  ============================  ==================================
kind           option           entry-point group             what it is
=============  ===============  ============================  ==================================
strategy       ``--strategy``   ``bestofn_swarm.strategies``  ``strategies.StrategyFactory``
pooling        ``--pooling``    ``bestofn_swarm.pooling``     ``decision.PoolingOperator``
controller     ``--controller`` ``bestofn_swarm.controllers`` ``ControllerFactory``: anything
                                                              that meets the port contract
=============  ===============  ============================  ==================================

A plug-in is named by an installed package's entry point in its group (``linear``) or by
where it is (``package.module:attribute``). The built-ins are plug-ins of the same groups,
registered by the project under their names (pyproject.toml): the strategies ``paper``,
``dmvd``, ``dmmd`` and ``dc``, the pooling operators ``mprodop`` and ``loglinear``, and
the controller ``paper`` (the Section 5 controller, which takes the strategy and pooling
operator of the run). A strategy and a pooling operator plug into the built-in controller;
a whole controller decides for itself and takes neither.

Finding a plug-in by its name (importing it, reading the entry points, hashing its source)
is ``robot_agent/plugins/registry.py``'s. Here, pure: what a resolved plug-in is
(``Plugin``, with where it came from: ``Origin``), a run's three (``Plugins``), the
built-ins, the check that an object is of its kind, and how a robot's controller is made
from them. What a plug-in gives while a run goes is checked by ``plugin_checks.py``; a
plug-in that fails ends the run with ``PluginError``, one line that names it (and the robot
and tick).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import decision, plugin_checks, ports, strategies
from robot_agent.core.controller import Controller
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.plugin import (
    DEFAULTS,
    KINDS,
    OPTIONS,
    Kind,
    Plugin,
    PluginError,
)


class ControllerFactory(Protocol):
    """What makes one robot's whole controller: a controller plug-in. Its generator is
    ``rng`` (the robot's stream of the world's seed); ``config`` holds the run's controller
    settings. What it returns meets the port contract (``ports.RobotController``,
    docs/porting.md)."""

    def __call__(
        self, robot_id: int, world: protocol.WorldInfo, config: ControllerConfig, rng: Stream
    ) -> ports.RobotController: ...


BUILTINS: Mapping[Kind, Mapping[str, Any]] = {
    "strategy": strategies.BUILTIN_STRATEGIES,
    "pooling": decision.POOLING_OPERATORS,
    "controller": {"paper": Controller},
}
"""The built-in plug-ins of each kind, by name (what the project registers in
pyproject.toml; tests/test_plugins.py compares the two)."""

# What an object of each kind must have, for the check at resolution (a function is called
# with these many positional arguments; a class must have these methods).
_ARGUMENTS: Mapping[Kind, int] = {"strategy": 4, "pooling": 1, "controller": 4}
_METHODS: Mapping[Kind, tuple[str, ...]] = {
    "strategy": plugin_checks.STRATEGY_METHODS,
    "pooling": (),
    "controller": ("step", "status", "take_status_change"),
}
_WHAT: Mapping[Kind, str] = {
    "strategy": "a strategy factory (num_sites, config, robot_id, pooling) -> Strategy",
    "pooling": "a pooling operator (opinions) -> opinion or None",
    "controller": "a controller factory (robot_id, world, config, rng) -> controller",
}


def builtin(kind: Kind, name: str) -> Plugin:
    """The built-in plug-in ``name`` of ``kind``, with no origin (the registry gives the
    same with its distribution and source); PluginError if there is none."""
    found = BUILTINS[kind].get(name)
    if found is None:
        raise PluginError(
            f"{kind} plug-in {name!r} is not built in (built in: {', '.join(BUILTINS[kind])}); "
            "a plug-in of one's own is resolved by robot_agent.plugins.registry"
        )
    return Plugin(kind, name, found, where=where_of(found), builtin=True)


def is_builtin(kind: Kind, target: object) -> bool:
    """Whether ``target`` is one of the built-ins of ``kind`` (the object itself)."""
    return any(target is found for found in BUILTINS[kind].values())


def where_of(target: object) -> str:
    """``module:qualified.name`` of an object ('' when it has none)."""
    module = getattr(target, "__module__", None)
    name = getattr(target, "__qualname__", None) or getattr(target, "__name__", None)
    return f"{module}:{name}" if module and name else ""


def check_kind(kind: Kind, name: str, target: object) -> None:
    """PluginError unless ``target`` can be a plug-in of ``kind``: something callable with
    the kind's arguments (a class: with the kind's methods). What it makes and gives is
    checked when it is called (``plugin_checks.py``)."""
    what = _WHAT[kind]
    if not callable(target):
        raise PluginError(
            f"{kind} plug-in {name!r} is {_kind_of(target)}, not {what} ({OPTIONS[kind]})"
        )
    if inspect.isclass(target):
        missing = [
            method for method in _METHODS[kind] if not callable(getattr(target, method, None))
        ]
        if kind == "pooling" or missing:
            lacks = f", which lacks {', '.join(missing)}" if missing else ""
            raise PluginError(f"{kind} plug-in {name!r} is {_kind_of(target)}{lacks}: not {what}")
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):  # compiled or built in: no signature to read
        return
    try:
        signature.bind(*([None] * _ARGUMENTS[kind]))
    except TypeError:
        raise PluginError(
            f"{kind} plug-in {name!r} takes {_parameters(signature)}: not {what}"
        ) from None


def _kind_of(target: object) -> str:
    if inspect.isclass(target):
        return f"the class {target.__qualname__}"
    if inspect.ismodule(target):
        return f"the module {target.__name__}"
    return f"a {type(target).__name__}"


def _parameters(signature: inspect.Signature) -> str:
    names = [name for name in signature.parameters if name != "self"]
    return f"({', '.join(names)})" if names else "no arguments"


@dataclass(frozen=True)
class Plugins:
    """The plug-ins of a run: the strategy and pooling operator the built-in controller
    takes, and the controller. A plug-in controller decides for itself: it comes with the
    default strategy and pooling operator only (PluginError otherwise)."""

    strategy: Plugin
    pooling: Plugin
    controller: Plugin

    def __post_init__(self) -> None:
        for kind in KINDS:
            if self.of(kind).kind != kind:
                raise ValueError(f"the {kind} of a run is a {self.of(kind).kind} plug-in")
        if not self.controller.builtin and (
            self.strategy.name != DEFAULTS["strategy"] or self.pooling.name != DEFAULTS["pooling"]
        ):
            raise PluginError(
                f"{self.controller.describe()} is a whole controller: it takes no --strategy "
                f"or --pooling (they are the built-in controller's; got {self.strategy.name} "
                f"and {self.pooling.name})"
            )

    def of(self, kind: Kind) -> Plugin:
        found: Plugin = getattr(self, kind)
        return found

    @property
    def all_builtin(self) -> bool:
        return all(self.of(kind).builtin for kind in KINDS)

    def names(self) -> dict[str, str]:
        return {kind: self.of(kind).name for kind in KINDS}

    def record(self) -> dict[str, dict[str, Any]]:
        """What a run's summary, recording and study rows keep: each kind's record."""
        return {kind: self.of(kind).record() for kind in KINDS}

    def sources(self) -> dict[str, str]:
        """The source hash of each plug-in that has one, by kind: what a robot started
        elsewhere must find in its own (``robot_agent.plugins.registry.check_sources``)."""
        return {
            kind: source for kind in KINDS if (source := self.of(kind).origin.source) is not None
        }


def builtin_plugins(config: ControllerConfig, controller: str = DEFAULTS["controller"]) -> Plugins:
    """The run's plug-ins when each is a built-in (PluginError for one that is not)."""
    return Plugins(
        builtin("strategy", config.strategy),
        builtin("pooling", config.pooling),
        builtin("controller", controller),
    )


ControllerMaker = Callable[..., ports.RobotController]
"""Makes one robot's controller: ``(robot_id, world, config, rng, **extra)``, ``extra``
being what a Byzantine behaviour passes (``estimate_quality``)."""


def controller_maker(plugins: Plugins, factory: type[Controller] | None = None) -> ControllerMaker:
    """What makes each robot's controller of a run with ``plugins`` (``factory``: a subclass
    of the built-in Controller that watches it, for the built-in controller only). The
    built-in controller is given the strategy the run's strategy plug-in makes, with its
    pooling operator; a plug-in's output is checked (``plugin_checks.py``)."""
    if not plugins.controller.builtin:
        if factory is not None:
            raise PluginError(
                f"{plugins.controller.describe()} cannot be watched as the built-in controller is"
            )
        return plugin_checks.controller_plugin_maker(plugins.controller)
    made = factory or plugins.controller.target
    strategy, pooling = plugins.strategy, plugins.pooling
    operator = pooling.target if pooling.builtin else plugin_checks.checked_pooling(pooling)

    def make(
        robot_id: int,
        world: protocol.WorldInfo,
        config: ControllerConfig,
        rng: Stream,
        **extra: Any,
    ) -> ports.RobotController:
        sites = len(world.sites)
        if strategy.builtin:
            chosen = strategy.target(sites, config, robot_id, operator)
        else:
            chosen = plugin_checks.make_strategy(strategy, sites, config, robot_id, operator)
        controller: ports.RobotController = made(
            robot_id, world, config, rng, strategy=chosen, **extra
        )
        return controller

    return make


__all__ = [
    "BUILTINS",
    "ControllerFactory",
    "ControllerMaker",
    "Plugins",
    "builtin",
    "builtin_plugins",
    "check_kind",
    "controller_maker",
    "is_builtin",
    "where_of",
]
