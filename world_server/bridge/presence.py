"""Which robots outside the emulator the run sees: presence, in one place.

The world counts a robot in its barrier while the robot's liveliness token lives. For a
robot outside the emulator the bridge holds that token on the robot's own Zenoh session,
and only while the robot is there in fact: from the first message the robot itself sent
in a link session (its status, sealed with its run key: the bridge cannot make one) until
that session ends (the program said bye or went quiet, its serial line closed, or a newer
session replaced it). Between sessions the world counts a departure, and keeps the body as
an obstacle, as for any robot whose process went.

Everything that decides presence is here, so that when presence itself must be proven
(a token only a hint, a robot taken into the barrier on an authenticated message of its
own) this is the one place that relays that message.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import zenoh

from bestofn_swarm.wire import keyspace
from bestofn_swarm.wire.names import Role

log = logging.getLogger("bridge")

# The first message of a session that makes the robot present: the node publishes its
# first status just before it declares its token (robot_agent/node/robot_node.py).
ANNOUNCES = keyspace.link(keyspace.STATUS)


class Presence:
    def __init__(self, sessions: Mapping[int, zenoh.Session], keys: keyspace.Keys) -> None:
        self.sessions = sessions  # each outside robot's own session
        self.keys = keys
        self.tokens: dict[int, Any] = {}

    def present(self, robot: int) -> bool:
        return robot in self.tokens

    def spoke(self, robot: int, kind: keyspace.LinkCode) -> None:
        """The robot sent ``kind`` (relayed already): present from its first status."""
        if kind is ANNOUNCES and robot not in self.tokens:
            token = (
                self.sessions[robot].liveliness().declare_token(self.keys.token(Role.ROBOT, robot))
            )
            self.tokens[robot] = token
            log.info("robot %d is present", robot)

    def gone(self, robot: int) -> None:
        """The robot's link session ended."""
        token = self.tokens.pop(robot, None)
        if token is not None:
            token.undeclare()
            log.info("robot %d is gone", robot)

    def close(self) -> None:
        for robot in list(self.tokens):
            self.gone(robot)
