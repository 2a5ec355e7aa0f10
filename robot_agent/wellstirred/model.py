"""Section 4 of the paper: the well-stirred agent model, vectorised over runs with numpy.

The model. n options with qualities rho_i = ((n-1) - (i-1)) / (n-1), option 1 the best
(index 0 here). A population of N agents starts with uniform opinions. Each step every
agent makes a weighted choice of two distinct options (probabilities = its opinion),
learns that the worse one is not the best and updates with Definition 1 (alpha); then
the agents are shuffled into pools of k (the last pool smaller when k does not divide
N), each pool is combined with MProdOp (Definition 2) and every member adopts the
result. A pool whose product is all zeros keeps its members' own opinions. The paper's
set-up is N = k: the whole population is one pool.

A run reaches consensus at the first step t (0 counts, for a threshold at or below
1/n) after which every agent holds option 1 at or above ``threshold`` (1 = certainty,
the paper's x_1 = 1). A run in which every agent settles on one wrong option, or which
has not reached consensus after ``steps`` steps, is a failure and counts as ``steps``.

Two ways to simulate, chosen by ``simulate(..., method=)``:

* ``"opinions"``, the general path: every agent's full opinion vector, for any alpha
  and any N >= k. This is also the plain reference the fast path is tested against.
* ``"survivors"``, exact in distribution when alpha = 0 and N = k. Every agent then
  holds the same pooled opinion, uniform over the options nobody has eliminated yet
  (Equation 4), so the state of a run is the number m of surviving options. Each agent
  draws a uniformly random pair of survivors and eliminates the worse, which is the
  survivor of higher rank; the next m is m minus the number of distinct ranks
  eliminated. Which survivors remain never matters, only how many, so the simulation
  tracks m per run and draws the pairs by rank.

``"auto"`` (the default) takes the survivors path whenever it is exact.

``exact_consensus_time`` gives the exact distribution of the consensus time under the
same conditions (alpha = 0, N = k, any threshold, any step limit): m is a Markov chain
whose transition probabilities are computed exactly (up to floating point), see
``survivor_transitions``. For alpha > 0 the opinions are no longer uniform over a set,
and for N > k the agents' opinions differ, so there is no such chain: ValueError.

Randomness comes only from the numpy Generator passed in; ``cell_rng`` derives one
Generator per (seed, n, k, N), so a cell's numbers do not depend on which other cells
a sweep contains.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, Protocol

import numpy as np

from bestofn_swarm.wire import numeric
from robot_agent.core.decision import validate_alpha

__all__ = [
    "FIGURE1_OPTIONS",
    "FIGURE1_POOLS",
    "MAX_EXACT_OPTIONS",
    "MAX_EXACT_POOL",
    "Cell",
    "CellModel",
    "ExactTime",
    "Method",
    "Model",
    "Outcome",
    "Summary",
    "cell_rng",
    "exact_consensus_time",
    "opinion_trace",
    "optimal_pool",
    "qualities",
    "simulate",
    "summarise",
    "survivor_transitions",
    "sweep",
]

FIGURE1_OPTIONS: tuple[int, ...] = (10, 20, 50, 100)
FIGURE1_POOLS: tuple[int, ...] = (1, 2, 3, 4, 5, 6, 7, 8, 10, 15, 20, 30, 50)

# The exact chain convolves k draws per step: its cost grows as n * k^3, and binomial
# coefficients C(k, c) p^c stay finite in float64 only up to about k = 1000.
MAX_EXACT_POOL = 1000
# It also holds an (n + 1) x (n + 1) transition matrix of float64: n = 5000 is 200 MB
# (and seconds); n = 100000 would be 74 GiB.
MAX_EXACT_OPTIONS = 5000

# Opinion arrays are processed in chunks of runs holding about this many numbers each,
# so memory stays near 100 MB whatever the number of runs.
_CHUNK_VALUES = 1_000_000

Method = Literal["auto", "survivors", "opinions"]


@dataclass(frozen=True)
class Model:
    """One parameter set of the well-stirred model. ``population`` defaults to ``pool``."""

    options: int
    pool: int
    population: int | None = None
    alpha: float = 0.0
    steps: int = 100
    threshold: float = 1.0

    def __post_init__(self) -> None:
        population = self.pool if self.population is None else self.population
        object.__setattr__(self, "population", population)
        _require_int(self.options, "options", low=2)
        _require_int(self.pool, "pool", low=1)
        _require_int(population, "population", low=1)
        _require_int(self.steps, "steps", low=1)
        if population < self.pool:
            raise ValueError(f"population ({population}) is smaller than the pool ({self.pool})")
        object.__setattr__(self, "alpha", validate_alpha(self.alpha))
        threshold = self.threshold
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float)):
            raise ValueError(f"threshold must be a number in (0, 1], got {threshold!r}")
        if math.isnan(threshold) or not 0.0 < threshold <= 1.0:
            raise ValueError(f"threshold must be in (0, 1], got {threshold!r}")
        object.__setattr__(self, "threshold", float(threshold))

    @property
    def agents(self) -> int:
        """The population size N (``population`` after defaulting)."""
        assert self.population is not None
        return self.population

    @property
    def survivors_exact(self) -> bool:
        """True when the number of surviving options is the whole state (alpha = 0, N = k)."""
        return self.alpha == 0.0 and self.agents == self.pool

    @property
    def exhaustive_steps(self) -> float:
        """The paper's baseline n/2: steps to visit every option two at a time."""
        return self.options / 2


class CellModel(Protocol):
    """What a sweep's table and figures read of a cell's model: ``Model`` (the paper's
    strategy) or ``robot_agent.wellstirred.voting.VoteModel`` (the strategies it is compared
    with)."""

    @property
    def options(self) -> int: ...

    @property
    def pool(self) -> int: ...

    @property
    def agents(self) -> int: ...

    @property
    def alpha(self) -> float: ...

    @property
    def steps(self) -> int: ...

    @property
    def exhaustive_steps(self) -> float: ...

    @property
    def survivors_exact(self) -> bool: ...


@dataclass(frozen=True)
class Outcome:
    """Per-run results: the consensus time (``steps`` for a failure) and whether it succeeded."""

    model: CellModel
    times: np.ndarray = field(repr=False)
    success: np.ndarray = field(repr=False)

    @property
    def runs(self) -> int:
        return int(self.times.size)


@dataclass(frozen=True)
class Summary:
    """Statistics of the consensus times of many runs (failures count as the step limit)."""

    mean: float
    median: float
    q1: float
    q3: float
    maximum: int
    success_rate: float


@dataclass(frozen=True)
class ExactTime:
    """The exact distribution of the consensus time T for alpha = 0 and N = k.

    ``survival[t]`` is P(T > t) for t = 0..steps. ``mean`` is E[min(T, steps)], the
    quantity a simulation's mean estimates (runs that fail count as ``steps``);
    ``unbounded_mean`` is E[T] without a step limit.
    """

    model: Model
    survival: tuple[float, ...]
    mean: float
    unbounded_mean: float

    def quantile(self, q: float) -> int:
        """The smallest t with P(min(T, steps) <= t) >= q."""
        if not 0.0 < q <= 1.0:
            raise ValueError(f"quantile must be in (0, 1], got {q!r}")
        for t, tail in enumerate(self.survival):
            if 1.0 - tail >= q - 1e-12:
                return t
        return self.model.steps


@dataclass(frozen=True)
class Cell:
    """One parameter set of a sweep with its simulated runs and, if asked, the exact time."""

    model: CellModel
    outcome: Outcome = field(repr=False)
    summary: Summary
    exact: ExactTime | None = None


def qualities(n: int) -> np.ndarray:
    """rho_i = ((n-1) - (i-1)) / (n-1) for i = 1..n: option 1 best, option n worth 0."""
    _require_int(n, "options", low=2)
    return (n - 1 - np.arange(n)) / (n - 1)


def cell_rng(seed: int, model: Model) -> np.random.Generator:
    """The Generator for one (seed, n, k, N), independent of any other cell's."""
    sequence = np.random.SeedSequence(seed, spawn_key=(model.options, model.pool, model.agents))
    return np.random.default_rng(sequence)


def simulate(
    model: Model, runs: int, rng: np.random.Generator, *, method: Method = "auto"
) -> Outcome:
    """``runs`` independent runs of ``model``; all randomness from ``rng``."""
    _require_int(runs, "runs", low=1)
    if method == "auto":
        method = "survivors" if model.survivors_exact else "opinions"
    if method == "survivors":
        if not model.survivors_exact:
            raise ValueError("the survivors path is exact only for alpha = 0 and population = pool")
        times, success = _simulate_survivors(model, runs, rng)
    elif method == "opinions":
        times, success = _simulate_opinions(model, runs, rng)
    else:
        raise ValueError(f"unknown method {method!r}: use auto, survivors or opinions")
    return Outcome(model, times, success)


def summarise(outcome: Outcome) -> Summary:
    times = outcome.times
    q1, median, q3 = np.percentile(times, [25, 50, 75])
    return Summary(
        mean=float(times.mean()),
        median=float(median),
        q1=float(q1),
        q3=float(q3),
        maximum=int(times.max()),
        success_rate=float(outcome.success.mean()),
    )


def sweep(
    options: Sequence[int],
    pools: Sequence[int],
    *,
    runs: int,
    seed: int,
    population: int | None = None,
    alpha: float = 0.0,
    steps: int = 100,
    threshold: float = 1.0,
    exact: bool = False,
    method: Method = "auto",
    on_cell: Callable[[Cell], None] | None = None,
) -> list[Cell]:
    """Every (n, k) of ``options`` x ``pools``, in that order, each with its own Generator.

    ``exact`` adds ``exact_consensus_time`` to the cells where it is defined (alpha = 0
    and N = k); ``on_cell`` is called after each cell, for progress reports.
    """
    models = [
        Model(n, k, population, alpha=alpha, steps=steps, threshold=threshold)
        for n in options
        for k in pools
    ]
    cells = []
    for model in models:
        outcome = simulate(model, runs, cell_rng(seed, model), method=method)
        exact_time = exact_consensus_time(model) if exact and model.survivors_exact else None
        cell = Cell(model, outcome, summarise(outcome), exact_time)
        cells.append(cell)
        if on_cell is not None:
            on_cell(cell)
    return cells


def optimal_pool(cells: Sequence[Cell], options: int) -> int | None:
    """k*: the smallest pool whose mean time is at or below n/2 for ``options`` = n."""
    candidates = [
        cell.model.pool
        for cell in cells
        if cell.model.options == options and cell.summary.mean <= cell.model.exhaustive_steps
    ]
    return min(candidates, default=None)


# --- the exact chain on the number of surviving options --------------------------------


def exact_consensus_time(model: Model) -> ExactTime:
    """The exact distribution of the consensus time, for alpha = 0 and N = k only.

    Exact because with alpha = 0 and one pool every agent holds the pooled opinion,
    uniform over the m surviving options, so m is a Markov chain (see
    ``survivor_transitions``); consensus is m at or below the largest m with
    1/m >= threshold. Raises ValueError for alpha > 0, N > k, k > MAX_EXACT_POOL or
    n > MAX_EXACT_OPTIONS.
    """
    if not model.survivors_exact:
        raise ValueError(
            "the exact consensus time needs alpha = 0 and population = pool "
            f"(got alpha={model.alpha:g}, population={model.agents}, pool={model.pool})"
        )
    n, steps = model.options, model.steps
    decided = _decided_survivors(model.threshold, n)
    transitions = survivor_transitions(n, model.pool)
    distribution = np.zeros(n + 1)
    distribution[n] = 1.0
    survival = []
    for t in range(steps + 1):
        survival.append(float(distribution[decided + 1 :].sum()))
        if t < steps:
            distribution = _vector_matrix(distribution, transitions)
    # E[T] by first-step analysis; every step eliminates at least one option.
    expected = np.zeros(n + 1)
    for m in range(decided + 1, n + 1):
        expected[m] = 1.0 + float((transitions[m, :m] * expected[:m]).sum())
    return ExactTime(
        model=model,
        survival=tuple(survival),
        mean=math.fsum(survival[:steps]),
        unbounded_mean=float(expected[n]),
    )


@lru_cache(maxsize=64)
def survivor_transitions(n: int, k: int) -> np.ndarray:
    """P[m, m'] = P(m' options survive a step | m survive), for k agents and alpha = 0.

    Among m survivors ranked 1 (best) .. m, a uniformly random pair eliminates rank r
    with probability p_r = (r - 1) / C(m, 2). With k agents, m' = m - D where D is the
    number of distinct ranks eliminated. Its distribution comes from a dynamic
    programme over ranks: h[d, j] is the probability that j labelled draws all land on
    the ranks processed so far and hit d distinct ones. Adding rank r with c of the j
    draws gives h'[d, j] = h[d, j] + sum_c C(j, c) p_r^c h[d-1, j-c]. Going from m - 1
    to m survivors only adds rank m and rescales the old probabilities by
    C(m-1, 2) / C(m, 2) per draw, so one pass over m = 2..n serves every m; then
    P(D = d | m) = h[d, k]. The result is read-only and cached.
    """
    _require_int(n, "options", low=2)
    _require_int(k, "pool", low=1)
    if k > MAX_EXACT_POOL:
        raise ValueError(f"the exact chain supports pools up to {MAX_EXACT_POOL}, got {k}")
    if n > MAX_EXACT_OPTIONS:
        raise ValueError(
            f"the exact chain supports up to {MAX_EXACT_OPTIONS} options, got {n}: its "
            f"transition matrix would take {8 * (n + 1) ** 2 / 2**30:.1f} GiB"
        )
    draws = np.arange(k + 1)
    binomial = np.array(
        [[float(math.comb(j, i)) for j in range(k + 1)] for i in range(k + 1)]
    )  # binomial[i, j] = C(j, i)
    gap = draws[None, :] - draws[:, None]  # j - i: draws given to the new rank
    later = gap > 0
    max_distinct = min(k, n - 1)
    h = np.zeros((max_distinct + 1, k + 1))
    h[0, 0] = 1.0
    transitions = np.zeros((n + 1, n + 1))
    transitions[1, 1] = 1.0
    for m in range(2, n + 1):
        pairs = m * (m - 1) / 2
        h *= _powers((m - 2) / m, k)  # old ranks' probabilities shrink from 1/C(m-1,2) scale
        p_new = (m - 1) / pairs
        added = np.where(later, binomial * _powers(p_new, k)[np.where(later, gap, 0)], 0.0)
        h[1:] += _matrix_product(h[:-1], added)
        distinct = h[:, k]
        for d in range(1, min(k, m - 1) + 1):
            transitions[m, m - d] = distinct[d]
    transitions.setflags(write=False)
    return transitions


# The chain's products are summed by numpy in a fixed order, never handed to BLAS (whose
# kernel, and so whose rounding, depends on the CPU), and powers are repeated products
# (numpy's float power takes a CPU-dependent path): the exact times are the same bits on
# every machine.


def _powers(base: float, top: int) -> np.ndarray:
    """base^0, base^1, ..., base^top, each the one before times base."""
    factors = np.full(top + 1, base)
    factors[0] = 1.0
    powers: np.ndarray = np.cumprod(factors)
    return powers


def _vector_matrix(vector: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """vector @ matrix, each column summed over the rows in order."""
    product: np.ndarray = (vector[:, None] * matrix).sum(axis=0)
    return product


def _matrix_product(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """left @ right, each entry summed over the inner index in order."""
    product: np.ndarray = (left[:, :, None] * right[None, :, :]).sum(axis=1)
    return product


def _decided_survivors(threshold: float, n: int) -> int:
    """The largest m whose uniform opinion 1/m is at or above ``threshold`` (at least 1)."""
    return max(m for m in range(1, n + 1) if 1.0 / m >= threshold)


# --- the survivors path (alpha = 0, N = k) ---------------------------------------------


def _simulate_survivors(
    model: Model, runs: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    n, k, steps = model.options, model.pool, model.steps
    decided = _decided_survivors(model.threshold, n)
    times = np.full(runs, steps, dtype=np.int64)
    success = np.zeros(runs, dtype=bool)
    if n <= decided:
        times[:] = 0
        success[:] = True
        return times, success
    active = np.arange(runs)
    survivors = np.full(runs, n, dtype=np.int64)
    for step in range(1, steps + 1):
        m = survivors[:, None]
        # Each agent's pair of distinct ranks among the survivors (0 = best).
        first = rng.integers(0, m, size=(active.size, k))
        second = rng.integers(0, m - 1, size=(active.size, k))
        second += second >= first
        worse = np.maximum(first, second)
        if k > 1:
            worse.sort(axis=1)
            eliminated = 1 + np.count_nonzero(np.diff(worse, axis=1), axis=1)
        else:
            eliminated = np.ones(active.size, dtype=np.int64)
        survivors = survivors - eliminated
        done = survivors <= decided
        if done.any():
            finished = active[done]
            times[finished] = step
            success[finished] = True
            active = active[~done]
            survivors = survivors[~done]
            if active.size == 0:
                break
    return times, success


# --- the opinions path (any alpha, N >= k) ---------------------------------------------


def _simulate_opinions(
    model: Model, runs: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    per_run = model.agents * model.options
    chunk = max(1, _CHUNK_VALUES // per_run)
    times = np.full(runs, model.steps, dtype=np.int64)
    success = np.zeros(runs, dtype=bool)
    for start in range(0, runs, chunk):
        stop = min(runs, start + chunk)
        times[start:stop], success[start:stop] = _simulate_opinion_chunk(model, stop - start, rng)
    return times, success


def _simulate_opinion_chunk(
    model: Model, runs: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    n, steps = model.options, model.steps
    times = np.full(runs, steps, dtype=np.int64)
    success = np.zeros(runs, dtype=bool)
    opinions = np.full((runs, model.agents, n), 1.0 / n)
    active = np.arange(runs)
    for step in range(steps + 1):
        if step > 0:
            opinions = _opinion_step(opinions, model, rng)
        reached, wrong = _consensus(opinions, model.threshold)
        times[active[reached]] = step
        success[active[reached]] = True
        # A wrong consensus is a failure: it keeps the step limit as its time.
        unfinished = ~(reached | wrong)
        if not unfinished.all():
            active = active[unfinished]
            opinions = opinions[unfinished]
            if active.size == 0:
                break
    return times, success


def opinion_trace(model: Model, rng: np.random.Generator, agent: int = 0) -> np.ndarray:
    """One run of the opinions path: agent ``agent``'s opinion after each step.

    Row t is the opinion after step t (row 0 the uniform prior); the trace ends at
    consensus, at a wrong consensus, or after ``model.steps`` steps. For Figure 2.
    """
    _require_int(agent, "agent", low=0)
    if agent >= model.agents:
        raise ValueError(f"agent {agent} is outside 0..{model.agents - 1}")
    opinions = np.full((1, model.agents, model.options), 1.0 / model.options)
    trace = [opinions[0, agent].copy()]
    for _ in range(model.steps):
        reached, wrong = _consensus(opinions, model.threshold)
        if reached[0] or wrong[0]:
            break
        opinions = _opinion_step(opinions, model, rng)
        trace.append(opinions[0, agent].copy())
    return np.array(trace)


def _consensus(opinions: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Per run: (every agent decided for option 1, every agent decided for one wrong option).

    An agent has decided for its most likely option (lowest index on a tie) when that
    option's probability is at or above ``threshold``.
    """
    best = opinions.argmax(axis=-1)
    top = np.take_along_axis(opinions, best[..., None], axis=-1)[..., 0]
    decided = top >= threshold
    all_decided = decided.all(axis=1)
    reached = all_decided & (best == 0).all(axis=1)
    wrong = all_decided & ~reached & (best == best[:, :1]).all(axis=1)
    return reached, wrong


def _opinion_step(opinions: np.ndarray, model: Model, rng: np.random.Generator) -> np.ndarray:
    """One step for opinions of shape (runs, agents, options): compare, update, pool."""
    eliminated = _draw_worse(opinions, rng)
    updated = _negative_update(opinions, eliminated, model.alpha)
    return _pool(updated, model.pool, rng)


def _draw_worse(opinions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each agent's weighted pair without replacement; the worse (higher index) of the two.

    As ``decision.choose_pair``: if only one option has weight, the second is uniform
    over the others.
    """
    n = opinions.shape[-1]
    first = _weighted_choice(opinions, rng)
    remaining = opinions.copy()
    np.put_along_axis(remaining, first[..., None], 0.0, axis=-1)
    second = _weighted_choice(remaining, rng)
    lone = remaining.max(axis=-1) <= 0.0
    if lone.any():
        offset = rng.integers(1, n, size=int(lone.sum()))
        second[lone] = (first[lone] + offset) % n
    later: np.ndarray = np.maximum(first, second)
    return later


def _weighted_choice(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """An index per row of ``weights`` (last axis) with probability proportional to weight.

    Rows of all zeros give an arbitrary index; the caller replaces those.
    """
    cumulative = np.cumsum(weights, axis=-1)
    target = rng.random(weights.shape[:-1]) * cumulative[..., -1]
    # Index i is chosen when cumulative[i-1] <= target < cumulative[i]: never a zero weight.
    chosen: np.ndarray = np.count_nonzero(cumulative <= target[..., None], axis=-1)
    overflow = chosen >= weights.shape[-1]
    if overflow.any():
        # Rounding put the target at the very top: take the last positive weight.
        reversed_positive = weights[overflow][:, ::-1] > 0.0
        chosen[overflow] = weights.shape[-1] - 1 - reversed_positive.argmax(axis=-1)
    return chosen


def _negative_update(opinions: np.ndarray, eliminated: np.ndarray, alpha: float) -> np.ndarray:
    """Definition 1 for every agent at once; a certain-and-contradicted opinion is kept."""
    x_eliminated = np.take_along_axis(opinions, eliminated[..., None], axis=-1)[..., 0]
    x_rest = opinions.sum(axis=-1) - x_eliminated
    denominator = alpha * x_eliminated + (1.0 - alpha) * x_rest
    keep = denominator <= 0.0
    safe = np.where(keep, 1.0, denominator)[..., None]
    updated = opinions * ((1.0 - alpha) / safe)
    np.put_along_axis(
        updated, eliminated[..., None], (alpha * x_eliminated)[..., None] / safe, axis=-1
    )
    if keep.any():
        updated[keep] = opinions[keep]
    return updated


def _pool(updated: np.ndarray, pool: int, rng: np.random.Generator) -> np.ndarray:
    """Shuffle agents into pools of ``pool`` (last smaller), combine with MProdOp, adopt.

    The product is taken in log space so long pools of small numbers do not underflow;
    a pool whose product is all zeros keeps its members' own (normalised) opinions.
    """
    runs, agents, n = updated.shape
    logs = numeric.log_array(updated)
    if pool == agents:
        pooled, contradicted = _normalised_product(logs.sum(axis=1))
        # Every agent adopts the same vector: a read-only broadcast view suffices, since
        # the next step only reads opinions.
        adopted = np.broadcast_to(pooled[:, None, :], updated.shape)
        if contradicted.any():
            adopted = adopted.copy()
            adopted[contradicted] = _normalised_rows(updated[contradicted])
        return adopted
    order = rng.permuted(np.broadcast_to(np.arange(agents), (runs, agents)), axis=1)
    shuffled_logs = np.take_along_axis(logs, order[..., None], axis=1)
    pools = -(-agents // pool)
    padded = np.zeros((runs, pools * pool, n))  # log 1 = 0: padding leaves products alone
    padded[:, :agents] = shuffled_logs
    pooled, contradicted = _normalised_product(padded.reshape(runs, pools, pool, n).sum(axis=2))
    slot_opinions = np.repeat(pooled, pool, axis=1)[:, :agents]
    slot_contradicted = np.repeat(contradicted, pool, axis=1)[:, :agents]
    if slot_contradicted.any():
        shuffled = np.take_along_axis(updated, order[..., None], axis=1)
        slot_opinions[slot_contradicted] = _normalised_rows(shuffled[slot_contradicted])
    adopted = np.empty_like(updated)
    np.put_along_axis(adopted, order[..., None], slot_opinions, axis=1)
    return adopted


def _normalised_rows(opinions: np.ndarray) -> np.ndarray:
    rows: np.ndarray = opinions / opinions.sum(axis=-1, keepdims=True)
    return rows


def _normalised_product(log_sums: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """exp(log_sums) normalised over the last axis, and where it was all zeros."""
    top = log_sums.max(axis=-1, keepdims=True)
    contradicted = np.isneginf(top[..., 0])
    shifted = numeric.exp_array(log_sums - np.where(np.isneginf(top), 0.0, top))
    totals = shifted.sum(axis=-1, keepdims=True)
    return shifted / np.where(totals > 0.0, totals, 1.0), contradicted


def _require_int(value: object, name: str, *, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < low:
        raise ValueError(f"{name} must be at least {low}, got {value}")
