"""Plug-ins for the tests (``tests/test_plugins.py``, ``tests/test_plugin_runs.py``), named as
``plugin_samples:NAME`` with tests/ on the module path: ones that only hand each call to a
built-in (the run must be the built-in's, bit for bit), and ones that go wrong in each way
a plug-in can (raise, give garbage, be of the wrong kind)."""

from __future__ import annotations

from collections.abc import Sequence

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import decision, ports
from robot_agent.core.beliefs import Beliefs
from robot_agent.core.controller import Controller
from robot_agent.core.controller_config import ControllerConfig

# --- plug-ins that only delegate to the built-ins --------------------------------------------


def product(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """The paper's product operator, by way of a plug-in."""
    return decision.mprodop(opinions)


def paper_strategy(
    num_sites: int, config: ControllerConfig, robot_id: int, pooling: decision.PoolingOperator
) -> Beliefs:
    """The paper's strategy, by way of a plug-in."""
    return Beliefs(num_sites, config, pooling)


def paper_controller(
    robot_id: int, world: protocol.WorldInfo, config: ControllerConfig, rng: Stream
) -> ports.RobotController:
    """The paper's whole controller, by way of a plug-in (a port written in Python that
    is the controller itself)."""
    return Controller(robot_id, world, config, rng)


# --- plug-ins that go wrong -------------------------------------------------------------------


def raising(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """Fails at the first pool that holds a neighbour's opinion."""
    if len(opinions) > 1:
        raise ZeroDivisionError("a pool of more than one")
    return decision.mprodop(opinions)


def not_a_number(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """Gives an opinion with a NaN once a pool holds a neighbour's opinion."""
    if len(opinions) > 1:
        return [float("nan")] * len(opinions[0])
    return decision.mprodop(opinions)


def wrong_type(opinions: Sequence[Sequence[float]]) -> object:
    """Gives text where an opinion belongs."""
    return "certain of site 0"


def unmade_strategy(
    num_sites: int, config: ControllerConfig, robot_id: int, pooling: decision.PoolingOperator
) -> Beliefs:
    """Cannot make robot 2's strategy."""
    if robot_id == 2:
        raise RuntimeError("no strategy for robot 2")
    return Beliefs(num_sites, config, pooling)


class LostStrategy(Beliefs):
    """Chooses a site that is not there after its first trip."""

    def __init__(
        self,
        num_sites: int,
        config: ControllerConfig,
        robot_id: int,
        pooling: decision.PoolingOperator,
    ) -> None:
        super().__init__(num_sites, config, pooling)
        self.sites = num_sites

    def next_sites(self, rng: Stream) -> list[int]:
        chosen = super().next_sites(rng)
        return chosen if self.trips == 0 else [chosen[0], self.sites + 3]


class StallingController(Controller):
    """A whole controller whose wheels turn at a speed that is not a number from 2 s on."""

    def step(self, reading: ports.BodyReading, received: Sequence[ports.Received]) -> ports.Command:
        command = super().step(reading, received)
        if reading.t >= 2.0:
            return ports.Command(float("inf"), command.right)
        return command


NOT_A_PLUGIN = 42
