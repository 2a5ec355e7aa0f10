"""One lockstep tick of a robot, without I/O: the world's messages in, the answer out.

``node.py`` calls this with what arrived over Zenoh; ``deploy/inmemory.py`` calls it with
what an in-process World produced. Both therefore make exactly the same decisions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from robot_agent import protocol, vision
from robot_agent.ports import BodyReading, RejectCounter, RobotController, decode_received


@dataclass(frozen=True)
class TickAnswer:
    act: protocol.Act
    transmissions: tuple[tuple[int, bytes], ...]  # (seq, payload) in sending order
    next_seq: int


def answer_tick(
    controller: RobotController,
    sense: protocol.Sense,
    radio: Sequence[tuple[str, bytes]],
    frame: bytes | None,
    rejects: RejectCounter,
    *,
    seq: int,
) -> TickAnswer:
    """Step the controller on tick ``sense.tick``; number its broadcasts from ``seq + 1``."""
    image = None
    if frame is not None:
        try:
            image = vision.decode_frame(frame)
        except ValueError as error:
            rejects.reject("camera", error)
    reading = BodyReading(
        t=sense.t,
        x=sense.x,
        y=sense.y,
        theta=sense.theta,
        proximity=tuple(sense.prox),
        frame=image,
    )
    command = controller.step(reading, decode_received(radio, rejects))
    transmissions = []
    for payload in command.broadcasts:
        seq += 1
        transmissions.append((seq, protocol.encode(payload)))
    act = protocol.Act(
        v=protocol.VERSION,
        tick=sense.tick,
        left=command.left,
        right=command.right,
        capture=command.capture,
        radio_tx=len(transmissions),
    )
    return TickAnswer(act, tuple(transmissions), seq)
