"""The radio medium: who hears a broadcast, when, and which copies are lost.

Pure: no Zenoh, no clock. The world core hands it every ``radio/tx/<sender>`` message
with the sender's position and everyone's positions at the tick the message was sent,
and asks once per tick for what is due on ``radio/rx/<receiver>``.

A message reaches every receiver within the sender's range (by kind: robot or beacon),
never the sender itself. Each such copy then meets the fault model, every fault off by
default (see ``RadioConfig``): iid loss, Gilbert-Elliott burst loss per directed link,
loss rising with distance, latency with jitter, duplication and reordering.

Determinism. Given the same seed, config and calls, the medium makes the same decisions:

* callers must call ``transmit`` for the messages of a tick sorted by
  ``(sender_order(sender), seq)``; the world does this rather than use arrival order;
* the copies of one message are decided in ``sender_order`` of their receivers;
* every fault draws from its own seeded stream, and draws whenever it is switched on,
  whatever the other faults decided, so switching on one fault never changes what
  another one does;
* ``deliveries(tick)`` is sorted by (receiver, sender, seq) in ``sender_order``, or
  shuffled by its own seeded stream when ``reorder`` is on.

``receivers`` should be the same mapping, unchanged, for every ``transmit`` of one tick:
the medium indexes the positions once per tick and mapping (it keeps the mapping and
rebuilds the index when the tick or the mapping object changes).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

import numpy as np
from msgspec import Meta

from bestofn_swarm.wire import names, numeric, protocol, settings
from bestofn_swarm.wire.rng import Stream
from bestofn_swarm.wire.settings import Flag

SenderKind = Literal["robot", "beacon"]
Metres = Annotated[float, Meta(gt=0.0)]
Probability = Annotated[float, Meta(ge=0.0, le=1.0)]
Ticks = Annotated[int, Meta(ge=0)]
# Where a copy goes in a tick's deliveries: receiver, sender, sequence number, sent tick.
_OrderKey = tuple[tuple[int, int, str], tuple[int, int, str], int, int]
_KINDS = ("robot", "beacon")


@functools.lru_cache(maxsize=65536)
def sender_order(name: str) -> tuple[int, int, str]:
    """Sort key of a radio name: robots (decimal ids) by number, then other names by text."""
    robot = names.robot_of_name(name)
    if robot is not None:
        return (0, robot, name)
    return (1, 0, name)


@dataclass(frozen=True)
class RadioConfig:
    """Ranges and the fault model. Every fault is off by default.

    Ranges are in metres and chosen by the sender's kind. Probabilities are in [0, 1];
    delays are whole control ticks. A copy is lost if any enabled loss cause says so.
    """

    FLAG_GROUP: ClassVar[str] = "radio medium (all faults off by default)"

    robot_range: Annotated[
        Metres, Meta(description="robot radio range in metres"), Flag(name="radio-range")
    ] = 0.5
    beacon_range: Annotated[
        Metres, Meta(description="how far the nest beacon's broadcast carries, in metres")
    ] = 0.2

    drop: Annotated[
        Probability, Meta(description="iid loss probability per message and receiver"), Flag()
    ] = 0.0

    latency: Annotated[
        Ticks,
        Meta(
            description="extra delivery latency in ticks: a copy sent at tick t arrives at "
            "t + 1 + latency"
        ),
        Flag(metavar="TICKS"),
    ] = 0
    jitter: Annotated[
        Ticks,
        Meta(description="a further uniform 0..TICKS delay per copy; copies overtake"),
        Flag(metavar="TICKS"),
    ] = 0

    duplicate: Annotated[
        Probability,
        Meta(description="probability that a delivered copy arrives twice"),
        Flag(),
    ] = 0.0
    duplicate_delay: Annotated[
        Ticks, Meta(description="the duplicate arrives 0..this many ticks after the original")
    ] = 1

    reorder: Annotated[
        bool,
        Meta(description="shuffle each tick's deliveries (seeded) instead of sorting them"),
        Flag(),
    ] = False

    burst_enter: Annotated[
        Probability,
        Meta(description="Gilbert-Elliott burst loss: P(good -> bad) per copy on a link"),
        Flag(
            name="burst-loss",
            joined=("burst_exit", "burst_loss_good", "burst_loss_bad"),
            least=2,
            metavar="ENTER:EXIT[:LG:LB]",
            help="Gilbert-Elliott burst loss per link: P(good->bad), P(bad->good), and loss "
            "probability in the good and bad states (LG 0 and LB 1 when not given)",
            default_text="off",
        ),
    ] = 0.0
    """Each (sender, receiver) link is a two-state Markov chain that starts good and
    advances once per copy sent on that link (transition first, then the loss draw in
    the new state). Burst loss is on when ``burst_enter`` or ``burst_loss_good`` > 0.
    The long-run loss rate is (e * lb + x * lg) / (e + x) with e = burst_enter,
    x = burst_exit, lb = burst_loss_bad, lg = burst_loss_good; a bad spell lasts 1/x
    copies on average.
    """
    burst_exit: Annotated[
        Probability, Meta(description="Gilbert-Elliott: P(bad -> good) per copy on the link")
    ] = 1.0
    burst_loss_good: Annotated[
        Probability, Meta(description="Gilbert-Elliott: loss probability in the good state")
    ] = 0.0
    burst_loss_bad: Annotated[
        Probability, Meta(description="Gilbert-Elliott: loss probability in the bad state")
    ] = 1.0

    range_loss_start: Annotated[
        Probability,
        Meta(description="range-dependent loss starts at this fraction of the range (1: off)"),
        Flag(
            name="range-loss",
            joined=("range_loss_exponent",),
            least=1,
            metavar="START[:EXPONENT]",
            help="loss rising with distance: 0 up to START x range, 1 at the range's edge, "
            "((d/range - START)/(1 - START))^EXPONENT between",
            default_text="off",
        ),
    ] = 1.0
    """With f = distance / range and s = range_loss_start < 1, a copy is lost with
    probability 0 for f <= s and ((f - s) / (1 - s)) ** range_loss_exponent for
    s < f <= 1: rising from 0 to 1 at the range's edge (linear for exponent 1).
    """
    range_loss_exponent: Annotated[
        float,
        Meta(
            gt=0.0,
            description="shape of the range-dependent loss curve (> 1: loss stays "
            "low until nearer the edge)",
        ),
    ] = 1.0

    def __post_init__(self) -> None:
        settings.check(self)

    @property
    def burst_loss(self) -> bool:
        return self.burst_enter > 0.0 or self.burst_loss_good > 0.0

    def range_of(self, kind: SenderKind) -> float:
        return self.robot_range if kind == "robot" else self.beacon_range

    def range_loss_probability(self, distance: float, reach: float) -> float:
        """Loss probability of a copy sent ``distance`` metres by a sender of range ``reach``."""
        start = self.range_loss_start
        fraction = distance / reach
        if start >= 1.0 or fraction <= start:
            return 0.0
        return numeric.power(min(1.0, (fraction - start) / (1.0 - start)), self.range_loss_exponent)


@dataclass(frozen=True)
class Delivery:
    """One copy of a message, due on ``radio/rx/<receiver>``."""

    receiver: str
    sender: str
    seq: int
    sent_tick: int
    payload: bytes


class _ReceiverIndex:
    """Positions of one tick: names in ``sender_order``, and an x-sorted view for windows."""

    def __init__(self, receivers: Mapping[str, tuple[float, float]]) -> None:
        self.names = sorted(receivers, key=sender_order)
        coords = np.array([receivers[name] for name in self.names], dtype=np.float64)
        self.coords = coords.reshape(-1, 2)
        self.by_x = np.argsort(self.coords[:, 0], kind="stable")
        self.sorted_x = self.coords[self.by_x, 0]

    def within(self, x: float, y: float, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """Indices (ascending, so in ``sender_order``) and distances of names within reach."""
        low = np.searchsorted(self.sorted_x, x - reach, side="left")
        high = np.searchsorted(self.sorted_x, x + reach, side="right")
        candidates = np.sort(self.by_x[low:high])
        offsets = self.coords[candidates] - (x, y)
        distances = np.sqrt(offsets[:, 0] * offsets[:, 0] + offsets[:, 1] * offsets[:, 1])
        close = distances <= reach
        return candidates[close], distances[close]


class RadioMedium:
    """Delivers broadcasts to receivers in range through the seeded fault model."""

    sender_order = staticmethod(sender_order)  # also reachable as RadioMedium.sender_order

    def __init__(self, config: RadioConfig, seed: int) -> None:
        self.config = config
        # One stream per fault, so enabling one fault leaves the others' draws unchanged.
        self._streams = {
            name: Stream.named(seed, "radio", name)
            for name in ("drop", "burst", "range", "jitter", "duplicate", "reorder")
        }
        self._link_bad: dict[tuple[str, str], bool] = {}
        self._pending: dict[int, list[tuple[_OrderKey, int, Delivery]]] = {}
        self._scheduled = 0  # tie-breaker that keeps sorting stable for duplicates
        self._index: _ReceiverIndex | None = None
        self._index_key: tuple[int, int] | None = None
        self._index_source: Mapping[str, tuple[float, float]] | None = None
        self.sent = 0
        self.delivered = 0
        self.dropped = 0
        self.rejected = 0
        self.copies = 0  # copies that met the fault model, duplicates included

    # --- counters -------------------------------------------------------------------

    @property
    def counters(self) -> protocol.RadioCounters:
        """sent: messages; delivered and dropped: copies; rejected: invalid tx messages."""
        return protocol.RadioCounters(
            sent=self.sent,
            delivered=self.delivered,
            dropped=self.dropped,
            rejected=self.rejected,
        )

    @property
    def in_flight(self) -> int:
        """Copies scheduled but not yet returned by ``deliveries``."""
        return sum(len(due) for due in self._pending.values())

    def reject(self, n: int = 1) -> None:
        """Count ``n`` transmitted messages the world refused as invalid."""
        if n < 0:
            raise ValueError(f"cannot reject a negative number of messages: {n}")
        self.rejected += n

    # --- the medium -----------------------------------------------------------------

    def transmit(  # noqa: PLR0917 -- the world core's agreed positional API
        self,
        tick: int,
        sender: str,
        seq: int,
        payload: bytes,
        position: tuple[float, float],
        kind: SenderKind,
        receivers: Mapping[str, tuple[float, float]],
    ) -> None:
        """Send one message: decide now who hears it and when, from positions at ``tick``.

        Call in ``(sender_order(sender), seq)`` order within a tick (module docstring).
        Each copy to a receiver in range is lost or scheduled for tick + 1 + latency
        (+ jitter); the sender never hears itself.
        """
        if kind not in _KINDS:
            raise ValueError(f"sender kind must be 'robot' or 'beacon', got {kind!r}")
        if tick < 0 or seq < 0:
            raise ValueError(f"tick and seq must be >= 0, got tick={tick}, seq={seq}")
        x, y = position
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"sender {sender!r}: position must be finite, got {position!r}")
        self.sent += 1
        payload = bytes(payload)
        config = self.config
        reach = config.range_of(kind)
        index = self._receiver_index(tick, receivers)
        nearby, distances = index.within(x, y, reach)
        sender_key = sender_order(sender)
        base_due = tick + 1 + config.latency
        for position_in_order, distance in zip(nearby.tolist(), distances.tolist(), strict=True):
            receiver = index.names[position_in_order]
            if receiver == sender:
                continue
            self.copies += 1
            lost, extra_delay, duplicate_delay = self._fate(sender, receiver, distance, reach)
            if lost:
                self.dropped += 1
                continue
            delivery = Delivery(receiver, sender, seq, tick, payload)
            order_key = (sender_order(receiver), sender_key, seq, tick)
            self._schedule(base_due + extra_delay, order_key, delivery)
            if duplicate_delay is not None:
                self.copies += 1
                self._schedule(base_due + extra_delay + duplicate_delay, order_key, delivery)

    def deliveries(self, tick: int) -> list[Delivery]:
        """Every copy due at ``tick`` (and any left over from earlier ticks), in order."""
        due_ticks = sorted(due for due in self._pending if due <= tick)
        entries = []
        for due in due_ticks:
            entries.extend(self._pending.pop(due))
        entries.sort(key=lambda entry: (entry[0], entry[1]))
        result = [delivery for _, _, delivery in entries]
        if self.config.reorder and len(result) > 1:
            self._streams["reorder"].shuffle(result)
        self.delivered += len(result)
        return result

    # --- internals ------------------------------------------------------------------

    def _receiver_index(
        self, tick: int, receivers: Mapping[str, tuple[float, float]]
    ) -> _ReceiverIndex:
        key = (tick, len(receivers))
        if self._index is None or self._index_key != key or self._index_source is not receivers:
            self._index = _ReceiverIndex(receivers)
            self._index_key = key
            self._index_source = receivers  # held, so its id cannot be reused meanwhile
        return self._index

    def _schedule(self, due: int, order_key: _OrderKey, delivery: Delivery) -> None:
        self._pending.setdefault(due, []).append((order_key, self._scheduled, delivery))
        self._scheduled += 1

    def _fate(
        self, sender: str, receiver: str, distance: float, reach: float
    ) -> tuple[bool, int, int | None]:
        """Lost?, extra delay, and the duplicate's delay (None: no duplicate) of one copy.

        Draws in a fixed order from each enabled fault's own stream, lost or not.
        """
        config = self.config
        streams = self._streams
        lost = False
        if config.drop > 0.0 and streams["drop"].random() < config.drop:
            lost = True
        if config.burst_loss:
            stream = streams["burst"]
            link = (sender, receiver)
            bad = self._link_bad.get(link, False)
            switch = stream.random()
            bad = switch >= config.burst_exit if bad else switch < config.burst_enter
            self._link_bad[link] = bad
            loss = config.burst_loss_bad if bad else config.burst_loss_good
            if stream.random() < loss:
                lost = True
        if config.range_loss_start < 1.0:
            probability = config.range_loss_probability(distance, reach)
            if streams["range"].random() < probability:
                lost = True
        extra_delay = streams["jitter"].randrange(config.jitter + 1) if config.jitter else 0
        duplicate_delay = None
        if config.duplicate > 0.0:
            stream = streams["duplicate"]
            duplicated = stream.random() < config.duplicate
            delay = stream.randrange(config.duplicate_delay + 1)
            if duplicated:
                duplicate_delay = delay
        return lost, extra_delay, duplicate_delay
