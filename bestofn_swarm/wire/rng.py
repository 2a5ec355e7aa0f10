"""The project's random number generator: every random choice that shapes a run draws from
a ``Stream``, an algorithm specified here and in docs/porting.md, so that a port in C,
Rust or MicroPython draws the same numbers from the same seed (tests/vectors/rng.json has
seeds and what they draw).

The generator is SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number
generators", OOPSLA 2014; the seeder of the xoshiro family): a 64-bit counter that steps
by a fixed odd constant, and a mixing function of the counter. The k-th draw of a stream
is a function of its seed and k alone, so a frame's worth of pixel noise is drawn at once
with numpy (``random_array``), and a port needs six lines of C. Period 2^64; it passes
BigCrush.

Everything is specified on top of ``next_u64``:

* ``random()``: the top 53 bits over 2^53, in [0, 1), exact;
* ``uniform(a, b)``: ``a + (b - a) * random()``;
* ``randrange(n)``: k = bit length of n - 1; 0 with no draw if k = 0; otherwise draw
  ``next_u64() >> (64 - k)`` until it is below n (no bias);
* ``choice(s)``: ``s[randrange(len(s))]``;
* ``shuffle(s)``: for i = len(s) - 1 down to 1, swap s[i] and s[randrange(i + 1)];
* ``sample(s, k)``: on a copy p of s, for i = 0 to k - 1, swap p[i] and
  p[i + randrange(len(s) - i)]; then p[:k];
* ``expovariate(rate)``: ``-log(1 - random()) / rate`` with the kernel's ``log``;
* ``normal()``: Box-Muller on two draws, u then v: ``sqrt(-2 log(1 - u)) cos(2 pi v)``
  with the kernel's ``log`` and ``cos``;
* ``fork()``: a new stream seeded with this one's next ``next_u64``.

Streams are seeded from the run seed and a name by ``seed_of`` (SHA-256), never from one
another's state except by ``fork``.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import MutableSequence, Sequence
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from bestofn_swarm.wire import numeric

GAMMA = 0x9E3779B97F4A7C15  # the counter's step: 2^64 over the golden ratio, made odd
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB
MASK = (1 << 64) - 1
TO_UNIT = 2.0**-53

T = TypeVar("T")


def seed_of(run_seed: int, *parts: int | str) -> int:
    """A 64-bit seed for one consumer of randomness (a robot, the radio, the layout): the
    first 8 bytes, little-endian, of the SHA-256 of ``run_seed`` and the parts joined by
    colons in decimal or as given (``"7:robot:3"``)."""
    text = ":".join([str(run_seed), *map(str, parts)]).encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:8], "little")


def mix(z: int) -> int:
    """SplitMix64's output function of a counter value."""
    z = ((z ^ (z >> 30)) * MIX1) & MASK
    z = ((z ^ (z >> 27)) * MIX2) & MASK
    return z ^ (z >> 31)


class Stream:
    """One seeded stream of random numbers (see the module docstring for the algorithm)."""

    def __init__(self, seed: object) -> None:
        # ``object``: a seed of another type gets this error, compiled
        # (bestofn_swarm/plumbing/cores.py) or not, rather than the compiled code's TypeError.
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MASK:
            raise ValueError(f"a stream's seed is an integer in [0, 2^64), got {seed!r}")
        self._state = seed

    @classmethod
    def named(cls, run_seed: int, *parts: int | str) -> Stream:
        """The stream of one consumer of a run's randomness (``seed_of``)."""
        return cls(seed_of(run_seed, *parts))

    @property
    def state(self) -> int:
        """The counter: the seed plus GAMMA times the draws so far, modulo 2^64."""
        return self._state

    def next_u64(self) -> int:
        self._state = (self._state + GAMMA) & MASK
        return mix(self._state)

    def random(self) -> float:
        """A float in [0, 1): a multiple of 2^-53."""
        return (self.next_u64() >> 11) * TO_UNIT

    def uniform(self, low: float, high: float) -> float:
        return low + (high - low) * self.random()

    def randrange(self, stop: int) -> int:
        """An integer in [0, stop), every one equally likely."""
        if stop < 1:
            raise ValueError(f"randrange needs stop >= 1, got {stop}")
        bits = (stop - 1).bit_length()
        if bits == 0:
            return 0
        while True:
            value = self.next_u64() >> (64 - bits)
            if value < stop:
                return value

    def choice(self, items: Sequence[T]) -> T:
        if not items:
            raise IndexError("cannot choose from an empty sequence")
        return items[self.randrange(len(items))]

    def shuffle(self, items: MutableSequence[T]) -> None:
        """Fisher and Yates, from the end."""
        for i in range(len(items) - 1, 0, -1):
            j = self.randrange(i + 1)
            items[i], items[j] = items[j], items[i]

    def sample(self, items: Sequence[T], count: int) -> list[T]:
        """``count`` distinct elements of ``items`` in the order drawn."""
        if not 0 <= count <= len(items):
            raise ValueError(f"cannot sample {count} of {len(items)} elements")
        pool = list(items)
        for i in range(count):
            j = i + self.randrange(len(pool) - i)
            pool[i], pool[j] = pool[j], pool[i]
        return pool[:count]

    def expovariate(self, rate: float) -> float:
        """An exponential draw with mean 1 / ``rate``."""
        if not rate > 0.0:
            raise ValueError(f"expovariate needs a positive rate, got {rate!r}")
        return -numeric.log(1.0 - self.random()) / rate

    def normal(self) -> float:
        """A standard normal draw (Box-Muller, two draws)."""
        u = self.random()
        v = self.random()
        return math.sqrt(-2.0 * numeric.log(1.0 - u)) * numeric.cos(numeric.TWO_PI * v)

    def fork(self) -> Stream:
        """A new stream seeded with this one's next draw."""
        return Stream(self.next_u64())

    # --- many draws at once (the same numbers as as many calls, in order) ----------------

    def u64_array(self, count: int) -> npt.NDArray[np.uint64]:
        """The next ``count`` values of ``next_u64``."""
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        steps = np.arange(1, count + 1, dtype=np.uint64)
        with np.errstate(over="ignore"):
            z = np.uint64(self._state) + steps * np.uint64(GAMMA)
            z = (z ^ (z >> np.uint64(30))) * np.uint64(MIX1)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(MIX2)
        self._state = (self._state + count * GAMMA) & MASK
        drawn: npt.NDArray[np.uint64] = z ^ (z >> np.uint64(31))
        return drawn

    def random_array(self, count: int) -> npt.NDArray[np.float64]:
        """The next ``count`` values of ``random``."""
        unit: npt.NDArray[np.float64] = (self.u64_array(count) >> np.uint64(11)).astype(
            np.float64
        ) * TO_UNIT
        return unit

    def normal_array(self, count: int) -> npt.NDArray[np.float64]:
        """The next ``count`` values of ``normal`` (2 ``count`` draws, u and v in turn)."""
        pairs = self.random_array(2 * count).reshape(count, 2)
        radius = np.sqrt(-2.0 * numeric.log_array(1.0 - pairs[:, 0]))
        _, cosine = numeric.sincos_array(numeric.TWO_PI * pairs[:, 1])
        normal: npt.NDArray[np.float64] = radius * cosine
        return normal


__all__ = ["Stream", "mix", "seed_of"]
