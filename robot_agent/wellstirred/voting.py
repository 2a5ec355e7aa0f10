"""The voting strategies (DMVD, DMMD, DC; ``robot_agent/core/voting.py``) in the
well-stirred model, vectorised over runs with numpy.

The set-up is Section 4's: n options with qualities rho_i = ((n-1) - (i-1)) / (n-1), a
population of N agents and steps. Each step every agent explores the option it favours
(it learns rho of that option, without noise) and disseminates; then every agent, at
once, applies its decision rule to neighbours drawn from the other agents. Well stirred:
any agent may be heard, each with a weight proportional to how long it disseminates,
the mean of the robots' dissemination time: g * rho + L (``dissemination``, ``listen``;
DC: g + L, since its dissemination is not modulated). Neighbours are drawn without
replacement.

* ``dmvd``: adopt the option of one neighbour;
* ``dmmd``: adopt the option most of itself and ``pool - 1`` neighbours favour (the
  group of ``pool`` agents; a tie: one of the tied at random);
* ``dc``: adopt one neighbour's option if its quality is higher than one's own.

The population starts spread evenly over the options in a random order (agent a
favours option perm[a mod n]), so with N >= n every option starts with a share, as the
papers start theirs. A run reaches consensus at the first step after which every agent
favours option 1 (the best); one in which every agent favours one other option, or that
has not reached consensus after ``steps`` steps, is a failure and counts as ``steps``.
Both kinds of consensus are final: nobody then hears another option.

A step is one exploration, dissemination and update per agent, as a step of Section 4 is
one comparison and one pooling per agent. Randomness only from the Generator passed in.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bestofn_swarm.wire import numeric
from robot_agent.core.voting import VOTING, StrategyName
from robot_agent.wellstirred.model import Cell, Outcome, qualities, summarise

__all__ = ["VoteModel", "simulate_votes", "vote_cell_rng", "vote_sweep"]

# The robots' defaults (ControllerConfig): g and the listening window, in sim seconds.
DEFAULT_DISSEMINATION = 10.0
DEFAULT_LISTEN = 3.0
# Runs are processed in chunks of about this many neighbour keys (runs x N x N).
_CHUNK_VALUES = 2_000_000


@dataclass(frozen=True)
class VoteModel:
    """One parameter set of a voting strategy in the well-stirred model."""

    strategy: StrategyName
    options: int
    pool: int  # the group of dmmd: the agent and pool - 1 neighbours (dmvd, dc: one)
    population: int | None = None
    steps: int = 100
    dissemination: float = DEFAULT_DISSEMINATION
    listen: float = DEFAULT_LISTEN

    def __post_init__(self) -> None:
        if self.strategy not in VOTING:
            raise ValueError(f"{self.strategy!r} is not a voting strategy: {', '.join(VOTING)}")
        population = self.pool if self.population is None else self.population
        object.__setattr__(self, "population", population)
        for name, value, low in (
            ("options", self.options, 2),
            ("pool", self.pool, 2),
            ("population", population, 2),
            ("steps", self.steps, 1),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be a whole number of at least {low}, got {value!r}")
        if population < self.pool:
            raise ValueError(f"population ({population}) is smaller than the pool ({self.pool})")
        for name, number in (("dissemination", self.dissemination), ("listen", self.listen)):
            if not math.isfinite(number) or number < 0.0:
                raise ValueError(f"{name} must be a number >= 0, got {number!r}")
        if self.dissemination + self.listen <= 0.0:
            raise ValueError("dissemination and listen cannot both be 0: nobody would be heard")

    @property
    def agents(self) -> int:
        assert self.population is not None
        return self.population

    @property
    def alpha(self) -> float:
        return 0.0  # no evidence reliability: a vote is an option, not a probability

    @property
    def survivors_exact(self) -> bool:
        return False  # no exact chain for these strategies

    @property
    def exhaustive_steps(self) -> float:
        return self.options / 2

    @property
    def heard(self) -> int:
        """Neighbours an agent's rule takes: the group less itself for dmmd, else one."""
        return self.pool - 1 if self.strategy == "dmmd" else 1


def simulate_votes(model: VoteModel, runs: int, rng: np.random.Generator) -> Outcome:
    """``runs`` independent runs of ``model``; all randomness from ``rng``."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ValueError(f"runs must be a whole number of at least 1, got {runs!r}")
    chunk = max(1, _CHUNK_VALUES // (model.agents * model.agents))
    times = np.full(runs, model.steps, dtype=np.int64)
    success = np.zeros(runs, dtype=bool)
    for start in range(0, runs, chunk):
        stop = min(runs, start + chunk)
        times[start:stop], success[start:stop] = _simulate_chunk(model, stop - start, rng)
    return Outcome(model, times, success)


def vote_cell_rng(seed: int, model: VoteModel) -> np.random.Generator:
    """The Generator for one (seed, strategy, n, k, N), independent of any other cell's
    (and of the paper's cells, whose keys have no strategy)."""
    key = (model.options, model.pool, model.agents, 1 + VOTING.index(model.strategy))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def vote_sweep(
    strategy: StrategyName,
    options: Sequence[int],
    pools: Sequence[int],
    *,
    runs: int,
    seed: int,
    population: int | None = None,
    steps: int = 100,
    on_cell: Callable[[Cell], None] | None = None,
) -> list[Cell]:
    """Every (n, k) of ``options`` x ``pools`` for ``strategy``, as ``model.sweep`` does for
    the paper's: each cell with its own Generator."""
    cells = []
    for n in options:
        for k in pools:
            model = VoteModel(strategy, n, k, population, steps=steps)
            outcome = simulate_votes(model, runs, vote_cell_rng(seed, model))
            cell = Cell(model, outcome, summarise(outcome))
            cells.append(cell)
            if on_cell is not None:
                on_cell(cell)
    return cells


def _simulate_chunk(
    model: VoteModel, runs: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    n, agents = model.options, model.agents
    rho = qualities(n)
    weight_of = np.full(n, model.dissemination + model.listen)
    if model.strategy != "dc":
        weight_of = model.dissemination * rho + model.listen
    order = rng.permuted(np.broadcast_to(np.arange(n), (runs, n)), axis=1)
    opinions = order[:, np.arange(agents) % n]
    times = np.full(runs, model.steps, dtype=np.int64)
    success = np.zeros(runs, dtype=bool)
    active = np.arange(runs)
    for step in range(1, model.steps + 1):
        opinions = _step(model, opinions, rho, weight_of, rng)
        same = (opinions == opinions[:, :1]).all(axis=1)
        if same.any():
            right = same & (opinions[:, 0] == 0)
            times[active[right]] = step
            success[active[right]] = True
            active, opinions = active[~same], opinions[~same]
            if active.size == 0:
                break
    return times, success


def _step(
    model: VoteModel,
    opinions: np.ndarray,
    rho: np.ndarray,
    weight_of: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """Every agent's rule at once, on the opinions of the step before."""
    runs, agents = opinions.shape
    heard = model.heard
    # Weighted draws without replacement: the ``heard`` largest of log(weight) + Gumbel
    # noise per listener, with the listener itself left out.
    keys = numeric.log_array(weight_of[opinions])[:, None, :] + _gumbel(rng, (runs, agents, agents))
    keys[:, np.arange(agents), np.arange(agents)] = -np.inf
    if heard == 1:
        chosen = keys.argmax(axis=-1)[..., None]
    else:
        chosen = np.argpartition(-keys, heard - 1, axis=-1)[..., :heard]
    neighbours = np.take_along_axis(opinions[:, None, :], chosen, axis=-1)
    if model.strategy == "dmvd":
        return neighbours[..., 0]
    if model.strategy == "dc":
        better = rho[neighbours[..., 0]] > rho[opinions]
        return np.where(better, neighbours[..., 0], opinions)
    group = np.concatenate([opinions[..., None], neighbours], axis=-1)
    counts = (group[..., :, None] == group[..., None, :]).sum(axis=-1)
    top = counts == counts.max(axis=-1, keepdims=True)
    # A tie between options: each tied option has as many members as the top count, so a
    # member drawn uniformly among the top ones is a tied option drawn uniformly.
    pick = np.where(top, rng.random(group.shape), -1.0).argmax(axis=-1)
    majority: np.ndarray = np.take_along_axis(group, pick[..., None], axis=-1)[..., 0]
    return majority


def _gumbel(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Standard Gumbel draws, -log(-log(1 - u)) with u uniform on [0, 1), with the portable
    kernel's logarithm (numpy's own ``gumbel`` calls the C library's)."""
    gumbel: np.ndarray = -numeric.log_array(-numeric.log_array(1.0 - rng.random(shape)))
    return gumbel
