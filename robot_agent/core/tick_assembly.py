"""A robot's inputs gathered into ticks (pure: no I/O, no clock).

Each tick the world sends a robot a ``Sense`` and, on their own keys, the radio messages
and camera frame of that tick; they may arrive in any order and ahead of the tick the robot
is at. ``TickAssembly`` holds them per tick until the tick can be stepped:

* lockstep: when the sense and everything it announces (``sense.rx`` radio messages, a
  frame if ``sense.camera``) are in, so the order of arrival cannot change a run; older
  ticks that never completed are forgotten (an input was dropped, and the world went on
  without this robot's answer: its stall is counted there);
* real time: as soon as the sense is in, with the radio of earlier ticks that never
  completed merged in front of its own, and the latest of their camera frames if its own
  tick has none (a robot that fell behind skips to its newest sense: robot_node.py).

It believes a tick only within the window of ``bestofn_swarm.wire.guard.TickWindow`` and holds at
most ``PENDING_BYTES`` / ``PENDING_MESSAGES`` for ticks not reached; an input for a tick already
stepped is stale and dropped quietly (late, not wrong).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

import numpy as np

from bestofn_swarm.wire import guard, protocol

# A camera frame: its encoding (PNG, as a transport carries it), or the image itself when
# the world runs in the same process.
Frame = bytes | np.ndarray

# What may wait for one robot: the inputs of ticks it has not reached (a lockstep robot
# needs one tick's; a camera frame and the radio of a crowded nest are well under this).
PENDING_BYTES = 4 * 2**20
PENDING_MESSAGES = 4000


class TickRefused(protocol.ProtocolError):
    """An input for a tick that is not believable now, or that does not fit the budget."""


@dataclass(slots=True)
class TickInputs:
    """What has arrived for one tick."""

    sense: protocol.Sense | None = None
    rx: list[tuple[str, bytes]] = field(default_factory=list)  # (sender, payload)
    frame: Frame | None = None
    size: int = 0  # bytes held for this tick
    messages: int = 0
    # The latest mark its inputs came with: the transport's arrival time when it traces
    # (bestofn_swarm/plumbing/trace.py), carried through untouched; 0 otherwise.
    arrived: float = 0.0


class ReadyTick:
    """A tick's inputs, complete enough to step (a plain class: one per robot per tick,
    and a NamedTuple's or a dataclass's constructor runs interpreted in the compiled
    cores)."""

    sense: Final[protocol.Sense]
    rx: Final[list[tuple[str, bytes]]]  # (sender, payload) in delivery order
    frame: Final[Frame | None]
    arrived: Final[float]  # the latest mark of its inputs (see TickInputs)

    def __init__(
        self,
        sense: protocol.Sense,
        rx: list[tuple[str, bytes]],
        frame: Frame | None,
        arrived: float,
    ) -> None:
        self.sense = sense
        self.rx = rx
        self.frame = frame
        self.arrived = arrived


class TickAssembly:
    """The pending inputs of one robot, per tick, and the tick window they must fall in."""

    def __init__(
        self,
        lockstep: bool,
        *,
        max_bytes: int = PENDING_BYTES,
        max_messages: int = PENDING_MESSAGES,
    ) -> None:
        self.lockstep = lockstep
        self.max_bytes = max_bytes
        self.max_messages = max_messages
        self.pending: dict[int, TickInputs] = {}
        self.pending_bytes = 0
        self.pending_messages = 0
        self.ticks = guard.TickWindow()

    @property
    def last_tick(self) -> int:
        """The last tick stepped; -1 before the first (or after a new world)."""
        return self.ticks.last

    def step_alone(self, sense: protocol.Sense, arrived: float = 0.0) -> ReadyTick | None:
        """Lockstep's common case, done at once: a sense that announces no radio and no
        frame, with nothing else waiting, is a complete tick by itself. The same result as
        ``add_sense`` then ``take_ready`` (None if stale; TickRefused outside the window),
        without holding it; None also when the case does not apply (hold it as usual)."""
        if not self.lockstep or self.pending or sense.rx or sense.camera:
            return None
        tick = sense.tick
        if not self.ticks.ahead(tick):
            return None
        refused = self.ticks.refuses(tick)
        if refused is not None:
            raise TickRefused(refused)
        self.ticks.acted(tick)
        return ReadyTick(sense, [], None, arrived)

    def add_sense(self, sense: protocol.Sense, arrived: float = 0.0) -> bool:
        """Hold a tick's sense (a repeat replaces it); False if stale. TickRefused if the
        tick is out of the window or over the budget."""
        inputs = self._admit(sense.tick, 0, arrived)
        if inputs is None:
            return False
        inputs.sense = sense
        return True

    def add_rx(self, tick: int, sender: str, payload: bytes, arrived: float = 0.0) -> bool:
        """Hold a radio message delivered in ``tick``; as ``add_sense``."""
        inputs = self._admit(tick, len(payload), arrived)
        if inputs is None:
            return False
        inputs.rx.append((sender, payload))
        return True

    def add_frame(self, tick: int, frame: Frame, arrived: float = 0.0) -> bool:
        """Hold the camera frame of ``tick`` (encoded, or the image itself when the world
        is in the same process); as ``add_sense``."""
        size = frame.nbytes if isinstance(frame, np.ndarray) else len(frame)
        inputs = self._admit(tick, size, arrived)
        if inputs is None:
            return False
        inputs.frame = frame
        return True

    def take_ready(self, tick: int) -> ReadyTick | None:
        """The inputs of ``tick`` if it can be stepped now, taken out and the tick counted
        as stepped; None if it must wait."""
        inputs = self.pending.get(tick)
        if inputs is None or inputs.sense is None:
            return None
        sense = inputs.sense
        if self.lockstep:
            complete = len(inputs.rx) >= sense.rx and (inputs.frame is not None or not sense.camera)
            if not complete:
                return None
            if len(self.pending) > 1:  # most ticks, this one is all that waits
                self._drop([old for old in self.pending if old < tick])
        else:
            earlier = sorted(old for old in self.pending if old < tick)
            inputs.rx[:0] = [item for old in earlier for item in self.pending[old].rx]
            if inputs.frame is None:  # a frame of a tick whose sense was skipped still counts
                frames = [self.pending[old].frame for old in earlier]
                inputs.frame = next((f for f in reversed(frames) if f is not None), None)
            self._drop(earlier)
        self._drop([tick])
        self.ticks.acted(tick)
        return ReadyTick(sense, inputs.rx, inputs.frame, inputs.arrived)

    def follow_new_world(self) -> None:
        """Another world counts ticks from zero: forget the pending ticks and the window."""
        self._drop(list(self.pending))
        self.ticks = guard.TickWindow()

    def rejoin(self) -> None:
        """The followed world ticked on while cut off from this robot, perhaps farther than
        the window: forget the pending ticks and take its next tick however far ahead (one
        already stepped stays refused)."""
        self._drop(list(self.pending))
        self.ticks.rejoin()

    def _admit(self, tick: int, size: int, arrived: float) -> TickInputs | None:
        """Room for one input of ``tick``: None if stale; TickRefused if not believable or
        over the budget."""
        if not self.ticks.ahead(tick):
            return None
        refused = self.ticks.refuses(tick)
        if refused is None and (
            self.pending_bytes + size > self.max_bytes or self.pending_messages >= self.max_messages
        ):
            refused = f"more than {self.max_bytes} bytes or {self.max_messages} messages waiting"
        if refused is not None:
            raise TickRefused(refused)
        inputs = self.pending.get(tick)
        if inputs is None:
            inputs = self.pending[tick] = TickInputs()
        inputs.arrived = max(inputs.arrived, arrived)
        inputs.size += size
        inputs.messages += 1
        self.pending_bytes += size
        self.pending_messages += 1
        return inputs

    def _drop(self, ticks: list[int]) -> None:
        for tick in ticks:
            inputs = self.pending.pop(tick)
            self.pending_bytes -= inputs.size
            self.pending_messages -= inputs.messages
