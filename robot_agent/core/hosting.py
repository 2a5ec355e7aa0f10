"""Several robots hosted by one process, answering in batches (pure: no I/O).

The world sends the senses of all of them as one batch on ``host/<lead>/sense`` and takes
the acts of the robots one input stepped as one batch on ``host/<lead>/act`` (``<lead>``:
the first robot hosted; ``wire/batch.py``). Each entry is exactly the message the robot
would have received or sent on its own key, sealed with its own key, so each robot's
endpoint checks its sense as if it had come alone and one bad entry costs only itself.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from robot_agent.core.endpoint import Outgoing, OutputKind, RobotEndpoint, Step
from wire import batch, protocol


class HostedRobots:
    """Splits a batch of senses among the hosted robots and gathers their acts."""

    def __init__(self, endpoints: Sequence[RobotEndpoint]) -> None:
        self.lead = endpoints[0]
        self.hosted = {endpoint.robot_id for endpoint in endpoints}
        keys = self.lead.keys
        self.sense_key = keys.host_sense(self.lead.robot_id)
        self.act_key = keys.host_act(self.lead.robot_id)
        self._acts: list[batch.Entry] = []

    def senses(self, payload: bytes) -> Iterator[batch.Entry]:
        """The entries of a batch of senses, each for a robot hosted here, to hand to that
        robot's endpoint as a sense; a bad batch, or an entry for a robot not hosted here,
        is refused (counted by the lead robot) when it is reached."""
        try:
            entries = batch.decode(payload)
        except batch.BatchError as error:
            self.lead.reject("host sense", error)
            return
        for entry in entries:
            if entry.robot in self.hosted:
                yield entry
            else:
                stranger = protocol.ProtocolError(f"robot {entry.robot} is not hosted here")
                self.lead.reject("host sense", stranger)

    def hold(self, step: Step) -> None:
        """Keep a step's act for the next batch (its other messages go out on their own)."""
        act = step.act
        self._acts.append(batch.Entry(step.robot, act.payload, act.attachment))

    def take_acts(self) -> Outgoing | None:
        """The acts held since the last call, as one batch; None if there are none."""
        if not self._acts:
            return None
        acts = Outgoing(OutputKind.HOST_ACT, self.act_key, batch.encode(self._acts), None)
        self._acts.clear()
        return acts
