"""Several robots hosted by one process, answering in batches (pure: no I/O).

The process hosting the robots ``first`` to ``last`` is one trust boundary: its robots share
its memory, and so its keys. So the world sends their senses as one batch on
``host/<first>/sense`` and takes their acts as one batch on ``host/<first>/act``
(``bestofn_swarm/wire/batch.py``), each sealed once with the process's own key, that of the host
identity ``host/<first>-<last>`` (``bestofn_swarm/wire/names.py``), which the world takes only for
those robots. Everything else a robot sends or receives (radio, camera, status, and its senses until
the world has learnt the batched path) stays on its own keys, sealed with its own key.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from robot_agent.core.endpoint import Outgoing, RobotEndpoint, Step


class HostedRobots:
    """Checks and splits a batch of senses among the hosted robots, and gathers their acts
    into batches."""

    def __init__(self, endpoints: Sequence[RobotEndpoint], keyring: auth.Keyring | None) -> None:
        """``endpoints``: robots ``first`` to ``last``, each once, in order (ValueError
        otherwise); ``keyring``: the host identity's key (None: an unauthenticated run)."""
        hosted = names.hosted_range([endpoint.robot_id for endpoint in endpoints])
        if hosted is None:
            raise ValueError("a process answers in batches for robots first to last, in order")
        self.first, self.last = hosted
        self.identity = names.host_identity(self.first, self.last)
        if keyring is not None and not keyring.holds(self.identity):
            raise ValueError(f"no key for {self.identity}")
        self.keyring = keyring
        self.lead = endpoints[0]  # counts what is refused of the batches
        self.by_id = {endpoint.robot_id: endpoint for endpoint in endpoints}
        for endpoint in endpoints:
            endpoint.batched = True
        keys = self.lead.keys
        self.sense_key = keys.of(keyspace.HOST_SENSE, self.first)
        self.act_key = keys.of(keyspace.HOST_ACT, self.first)
        self._acts: list[tuple[int, protocol.Act]] = []

    def senses(
        self, payload: bytes, attachment: bytes | None
    ) -> Iterator[tuple[RobotEndpoint, protocol.Sense]]:
        """Each sense of a batch of senses with the robot it is for, to hand to that robot's
        endpoint (``receive_sense``). A batch without this host's tag, or that is not exactly
        a valid batch of this host's, is refused whole; an entry for a robot not hosted
        here is refused when it is reached; both counted by the first robot."""
        try:
            auth.unseal(self.keyring, self.identity, self.sense_key, payload, attachment)
            senses = batch.decode_senses(payload)
        except (auth.AuthError, protocol.ProtocolError) as error:
            self.lead.reject("host sense", error)
            return
        yield from self.senses_of(senses)

    def senses_of(self, senses: batch.SenseBatch) -> Iterator[tuple[RobotEndpoint, protocol.Sense]]:
        """``senses`` as a batch of senses that passed its checks (``senses``, or handed
        over typed in the same process) is taken: refused whole unless it is this host's."""
        if senses.last != self.last:
            error = batch.BatchError(f"a batch of host/{self.first}-{senses.last}'s")
            self.lead.reject("host sense", error)
            return
        for robot, sense in zip(senses.robots, senses.senses, strict=True):
            endpoint = self.by_id.get(robot)
            if endpoint is None:
                stranger = protocol.ProtocolError(f"robot {robot} is not hosted here")
                self.lead.reject("host sense", stranger)
            else:
                yield endpoint, sense

    def hold(self, step: Step) -> None:
        """Keep a step's act for the next batch (its other messages go out on their own)."""
        self._acts.append((step.robot, step.answer))

    def take_acts(self) -> Outgoing | None:
        """The acts held since the last call, as one batch (sealed when sent); None if
        there are none."""
        if not self._acts:
            return None
        acts = batch.ActBatch(self.last, self._acts)
        self._acts = []
        return Outgoing(
            keyspace.HOST_ACT,
            self.act_key,
            acts,
            batch.encode_act_batch,
            identity=self.identity,
            keyring=self.keyring,
        )
