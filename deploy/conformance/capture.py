"""What one robot's controller took and gave at every step of a real run (pure).

``capture_run`` runs a lockstep swarm in this process (``deploy.inprocess.engine``, the same
per-robot results as ``swarm run``) with every controller watched: for the robots asked
for, each step's reading, the radio messages that reached the controller (as their
payloads' bytes), the command, the events it fired through ``phases.TRANSITIONS``, the
phase and opinion after it, and the status it published, if any. The controller vectors
(``tests/make_vectors.py``, ``vectors.py``) are made from these, and ``swarm conformance``
compares a program in a swarm with them (``swarm.py``).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bestofn_swarm.wire import protocol
from deploy.inprocess.engine import run_in_process
from robot_agent.core import phases, ports
from robot_agent.core.controller import Controller, ControllerConfig
from world_server.core.world import WorldConfig


@dataclass
class Step:
    """One control step of one robot: what went in, what came out."""

    tick: int
    reading: ports.BodyReading
    received: list[tuple[str, bytes]]  # (sender, payload) in delivery order, as sent
    command: ports.Command
    events: list[tuple[protocol.Phase, phases.Event]]  # (phase left, event), in firing order
    phase: protocol.Phase  # after the step
    opinion: list[float]  # after the step, at full precision
    status: protocol.Status | None  # what the step published (None: nothing changed)


@dataclass
class Capture:
    """The run's summary and the steps of the robots watched."""

    summary: dict[str, Any]
    steps: dict[int, list[Step]] = field(default_factory=dict)


def capture_run(
    world: WorldConfig,
    config: ControllerConfig,
    robots: Collection[int],
    *,
    controller: type[Controller] = Controller,
    **engine: Any,
) -> Capture:
    """Run ``world`` with ``config`` to its end (``engine``: more of ``run_in_process``'s
    arguments: the beacon, the time limits, hooks); every step of ``robots``. Each robot's
    controller is a ``controller`` (a subclass, to run another one)."""
    steps: dict[int, list[Step]] = {robot: [] for robot in robots}

    class Watched(controller):  # type: ignore[valid-type,misc]
        """The controller, with each step written down (it changes nothing)."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.fired: list[tuple[protocol.Phase, phases.Event]] = []

        def _fire(self, event: phases.Event, reading: ports.BodyReading) -> None:
            self.fired.append((self.phase, event))
            super()._fire(event, reading)

        def step(
            self, reading: ports.BodyReading, received: Sequence[ports.Received]
        ) -> ports.Command:
            if self.robot_id not in steps:
                return super().step(reading, received)
            self.fired = []
            command = super().step(reading, received)
            tick = round(reading.t / self.world.dt)
            if not math.isclose(reading.t, tick * self.world.dt, rel_tol=1e-9, abs_tol=1e-6):
                raise RuntimeError(f"sim time {reading.t} is no tick of {self.world.dt} s")
            # The flag the endpoint takes after the step, looked at without taking it.
            changed = self._changed
            steps[self.robot_id].append(
                Step(
                    tick=tick,
                    reading=reading,
                    received=[(m.sender, protocol.encode(m.payload)) for m in received],
                    command=command,
                    events=list(self.fired),
                    phase=self.phase,
                    opinion=self.opinion,
                    status=self.status(tick) if changed else None,
                )
            )
            return command

    summary = run_in_process(world, config, controller_factory=Watched, **engine)
    return Capture(summary, steps)


def frame_png(image: np.ndarray) -> bytes:
    """A BGR frame as an 8-bit RGB PNG whose image data is stored, not compressed: its
    bytes depend on no encoder (a PNG is lossless: any decoder gives the pixels back)."""
    import zlib

    height, width = image.shape[:2]
    rgb = np.ascontiguousarray(image[:, :, ::-1])
    rows = b"".join(b"\x00" + rgb[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")
        )

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes((8, 2, 0, 0, 0))
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows, 0))
        + chunk(b"IEND", b"")
    )
