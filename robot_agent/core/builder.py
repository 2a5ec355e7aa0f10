"""One robot, assembled the one way every engine and host assembles it: its controller (the
paper's, or one that misbehaves: ``byzantine.py``; made with the run's plug-ins:
``plugins.py``) with its generator seeded from the world's seed (``WorldInfo.seed``) and its
id, inside its end of the wire (``RobotEndpoint``). ``robot-agent`` (a process per robot, or
hosting several), the in-process engine, the robot outside the emulator (``robot-agent
--link``) and the examples build robots here, so a robot started by hand in a world of seed
7 makes the run ``swarm run --seed 7`` makes. A robot with a plug-in in it is wrapped in
``plugin_checks.CheckedController``: a plug-in that fails ends the run with one line naming
it, the robot and the tick."""

from __future__ import annotations

from collections.abc import Sequence

from bestofn_swarm.wire import auth, keyspace, protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import byzantine, faults, plugin_checks, ports
from robot_agent.core import plugins as plugin_set
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.endpoint import RobotEndpoint


class SeedMismatchError(ValueError):
    """A seed given to a robot that is not its world's: the robot would make another run."""


def run_seed(world: protocol.WorldInfo, given: int | None = None) -> int:
    """The seed a robot of ``world`` draws from: the world's. ``given`` (a ``--seed`` a robot
    was started with) must be the same; SeedMismatchError says otherwise."""
    if given is not None and given != world.seed:
        raise SeedMismatchError(
            f"--seed {given} is not the seed of the world of run {world.run} ({world.seed}); "
            "leave --seed out to take the world's"
        )
    return world.seed


def build_controller(
    robot_id: int,
    world: protocol.WorldInfo,
    config: ControllerConfig,
    *,
    behaviour: byzantine.Behaviour | None = None,
    factory: type[Controller] | None = None,
    plugins: plugin_set.Plugins | None = None,
    robot_faults: Sequence[faults.RobotFault] = (),
) -> ports.RobotController:
    """Robot ``robot_id``'s controller in ``world``: its generator is the world's seed's
    stream for the robot (docs/kernel.md), honest unless ``behaviour`` says how it
    misbehaves, made with the run's ``plugins`` (resolved by
    ``robot_agent.plugins.registry``; None: the built-ins ``config`` names) and, for the
    built-in controller, as ``factory`` (a subclass of Controller that watches it), then
    wrapped by each of ``robot_faults`` that changes what it does (a motor failure).
    Raises ValueError for a behaviour the world cannot have (a liar's site), PluginError
    for a plug-in that cannot make this robot."""
    rng = Stream.named(world.seed, "robot", robot_id)
    chosen = plugins if plugins is not None else plugin_set.builtin_plugins(config)
    made = byzantine.build_controller(
        robot_id,
        world,
        config,
        rng,
        behaviour,
        factory=plugin_set.controller_maker(chosen, factory),
    )
    if not chosen.all_builtin:  # the built-ins are trusted: nothing between them and the robot
        controller = None if chosen.controller.builtin else chosen.controller
        made = plugin_checks.CheckedController(made, robot_id, world.dt, controller)
    return faults.wrapped(made, faults.wrapping(robot_faults, robot_id))


def build_robot(
    robot_id: int,
    world: protocol.WorldInfo,
    config: ControllerConfig,
    *,
    keys: keyspace.Keys,
    keyring: auth.Keyring | None = None,
    behaviour: byzantine.Behaviour | None = None,
    factory: type[Controller] | None = None,
    plugins: plugin_set.Plugins | None = None,
    robot_faults: Sequence[faults.RobotFault] = (),
) -> RobotEndpoint:
    """Robot ``robot_id`` of ``world``: its controller (``build_controller``) in its end of
    the wire, holding ``keyring`` (its own key; None: an unkeyed run)."""
    controller = build_controller(
        robot_id,
        world,
        config,
        behaviour=behaviour,
        factory=factory,
        plugins=plugins,
        robot_faults=robot_faults,
    )
    return RobotEndpoint(robot_id, keys=keys, controller=controller, world=world, keyring=keyring)


__all__ = ["SeedMismatchError", "build_controller", "build_robot", "run_seed"]
