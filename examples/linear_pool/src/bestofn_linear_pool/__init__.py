"""A linear opinion pool: a pooling operator plug-in for bestofn-swarm.

The paper pools opinions with the product operator (MProdOp, its Definition 2): the pooled
opinion is the normalised product of the pool's opinions, so a site any robot ruled out is
ruled out for all, and evidence accumulates. The linear pool (Stone, "The opinion pool",
Annals of Mathematical Statistics 32(4), 1961) is the other classical way: the pooled
opinion is the mean of the pool's opinions,

    c(x_1, ..., x_k)_i = (x_1i + ... + x_ki) / k,

so a site is ruled out only when every robot of the pool ruled it out: opinions are
averaged, not multiplied, and a robot's evidence is diluted by its neighbours' doubts.
The paper contrasts the two (its Section 2); ``study.py`` beside this package compares them
in the swarm.

A pooling operator takes the pool's opinions (the pooling robot's own first, each a list of
probabilities over the sites) and returns the pooled opinion, normalised, or None when the
pool contradicts itself (the robot then keeps its own). The mean of probability vectors
never contradicts itself, so this one always returns an opinion. It draws nothing at
random and reads no clock: a run with it is the same run in one process and over a
network.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["linear_pool"]
__version__ = "0.1.0"


def linear_pool(opinions: Sequence[Sequence[float]]) -> list[float] | None:
    """The mean of the pool's opinions (each normalised first), normalised.

    Sums are taken with ``math.fsum``, correctly rounded, so the result is the same bits
    on every machine whatever the order of the terms' rounding.
    """
    if not opinions:
        raise ValueError("a pool holds at least the pooling robot's own opinion")
    sites = len(opinions[0])
    scaled = []
    for opinion in opinions:
        if len(opinion) != sites:
            raise ValueError(f"an opinion of {len(opinion)} sites in a pool of {sites}")
        total = math.fsum(opinion)
        scaled.append([value / total for value in opinion])
    mean = [math.fsum(opinion[site] for opinion in scaled) / len(scaled) for site in range(sites)]
    total = math.fsum(mean)
    return [value / total for value in mean]
