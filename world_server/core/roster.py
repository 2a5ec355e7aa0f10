"""Who takes part in the world's ticks (no I/O): liveliness tokens, joins, departures,
ids handed out on ``world/join``, the batch routes of robots hosted together, and the
ticks each beacon answers.

A token that appears is a join that takes effect when the tick under way closes (or at
once, before the start), so a tick's participants never change while it runs; a token
that goes is a departure at once. In a keyed run a token is only a hint: anyone on the
router can declare one. It joins once its identity has proved itself present with an
authenticated query of ``world/info`` (each robot and beacon asks it as it starts and
whenever a world server appears), so tokens without keys never take part, never fill
MAX_BEACONS and never hold a tick up. A robot whose process answers in batches gets its
senses in its process's batch (bestofn_swarm/wire/batch.py) until its process's first robot goes. A
beacon takes part in the ticks it answers: every tick until its first answer, then the
tick each answer names (``Ack.next_tick``).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

from bestofn_swarm.wire import keyspace, names
from bestofn_swarm.wire.names import Role
from world_server.core.counters import Counters
from world_server.core.world import World

log = logging.getLogger("world_server")

MAX_BEACONS = 16  # beacon tokens the world takes part in its barrier
MAX_HINTS = 1024  # tokens of identities not proved present that the world keeps in mind
SUSPEND_AFTER = 3  # consecutive stalled ticks before the barrier stops waiting


class Host(NamedTuple):
    """A process hosting the robots ``first`` to ``last``, which answers in batches."""

    first: int
    last: int

    @property
    def identity(self) -> str:
        """Whose key seals its batches (bestofn_swarm/wire/names.py)."""
        return names.host_identity(self.first, self.last)

    def hosts(self, robot: int) -> bool:
        return self.first <= robot <= self.last


class Token(NamedTuple):
    """A robot's or a beacon's liveliness token: ``alive/<role>/<ident>``."""

    role: Role  # Role.ROBOT or Role.BEACON
    ident: str

    @property
    def identity(self) -> str:
        """Whose key proves it (bestofn_swarm/wire/names.py)."""
        if self.role == Role.ROBOT:
            return names.robot_identity(int(self.ident))
        return names.beacon_identity(self.ident)


class Roster:
    def __init__(
        self, world: World, keys: keyspace.Keys, counters: Counters, proof: bool = False
    ) -> None:
        """``proof``: a token joins only once its identity proved itself present (a keyed
        run); otherwise (no keys to prove anything with) a token joins on its own."""
        self.world = world
        self.keys = keys
        self.counters = counters
        self.proof = proof
        # Identities that proved themselves present (an authenticated world/info query),
        # kept for the run: a restarted process proves itself again, but maybe before its
        # old token's departure arrives. Only holders of a key of the run can add to it.
        self.proven: set[str] = set()
        self.hinted: set[Token] = set()  # tokens present whose identity is not proven yet
        self.pending: list[Token] = []  # joins to apply when the tick under way closes
        self.assigned: set[int] = set()  # ids handed out on world/join (or taken by a token)
        # Robots whose process answers in batches: robot -> that process. Learnt only from
        # acts taken as the answer to the tick under way.
        self.hosts: dict[int, Host] = {}
        # Beacon -> the next tick it answers (its last Ack's next_tick); absent: every tick.
        self.beacon_next: dict[str, int] = {}

    def token(self, key: str, count: bool) -> Token | None:
        """The robot's or beacon's token ``key`` is; None for other roles (the world, the
        recorder), which the barrier does not involve, and for a robot outside the swarm
        or a beacon name no beacon can have (rejected if ``count``)."""
        role = ident = None
        for candidate in (Role.ROBOT, Role.BEACON):
            ident = self.keys.ident_of(keyspace.TOKEN_OF[candidate], key)
            if ident is not None:
                role = candidate
                break
        if role is None or ident is None:
            return None
        if role == Role.ROBOT:
            robot = names.robot_of_name(ident)
            valid = robot is not None and self.world.is_member(robot)
        else:
            valid = names.is_beacon_name(ident)
        if not valid:
            if count:
                self.counters.reject(key, f"no {role} of this run is called {ident!r}")
            return None
        return Token(role, ident)

    def appeared(self, key: str) -> None:
        """A token appeared: a join, once its identity is proven present (keyed runs)."""
        token = self.token(key, count=True)
        if token is None:
            return
        if not self.proof or token.identity in self.proven:
            self.pending.append(token)
        elif len(self.hinted) < MAX_HINTS:
            self.hinted.add(token)
        else:
            self.counters.reject(key, f"more than {MAX_HINTS} tokens not proved present")

    def proved(self, identity: str) -> None:
        """``identity`` asked an authenticated query: it is present; its token, if it has
        one, joins. The world and the other services need no proof: they do not join."""
        role, _, ident = identity.partition("/")
        if role not in (Role.ROBOT, Role.BEACON) or identity in self.proven:
            return
        if role == Role.ROBOT:
            robot = names.robot_of_name(ident)
            if robot is None or not self.world.is_member(robot):
                return
        self.proven.add(identity)
        for token in [token for token in self.hinted if token.identity == identity]:
            self.hinted.discard(token)
            self.pending.append(token)

    def went(self, key: str) -> Token | None:
        """A token went: the robot's body stops and stays as an obstacle, the beacon goes
        silent; counted as a departure if it was taking part. The robots of a process that
        answered in batches get their senses on their own keys again until a batch says
        otherwise (a restarted process may host other robots, or none). The robot or
        beacon that left, for the tick under way to stop waiting for it."""
        token = self.token(key, count=False)
        if token is None:
            return None
        self.hinted.discard(token)
        self.pending = [join for join in self.pending if join != token]
        if token.role == Role.ROBOT:
            gone = int(token.ident)
            self.hosts = {
                robot: host for robot, host in self.hosts.items() if gone not in (robot, host.first)
            }
            if gone in self.world.live_robots():
                self.counters.departures += 1
            log.warning(
                "robot %s left (liveliness lost); its body stays as an obstacle", token.ident
            )
            self.world.leave_robot(gone)
        elif token.ident in self.world.beacons():
            self.beacon_next.pop(token.ident, None)
            self.counters.departures += 1
            log.warning("beacon %s left", token.ident)
            self.world.leave_beacon(token.ident)
        return token

    def apply_joins(self) -> None:
        """Let the robots and beacons whose tokens appeared take part (at most
        MAX_BEACONS beacons: one more is rejected)."""
        for role, ident in self.pending:
            if role == Role.ROBOT:
                robot = int(ident)
                self.assigned.add(robot)
                if robot not in self.world.live_robots():
                    log.info("robot %s joined at tick %d", ident, self.world.tick)
                self.world.join_robot(robot)
            elif ident not in self.world.beacons() and len(self.world.beacons()) >= MAX_BEACONS:
                self.counters.reject(
                    self.keys.token(Role.BEACON, ident), f"more than {MAX_BEACONS} beacons"
                )
            else:
                self.world.join_beacon(ident)
        self.pending.clear()

    def assign_id(self) -> int | None:
        """An id for a robot started with ``--id auto``: the smallest never handed out,
        else (a replacement container) the smallest whose robot is not running; None when
        every robot of the swarm is running."""
        live = set(self.world.live_robots())
        members = range(self.world.config.num_robots)
        free = next((robot for robot in members if robot not in self.assigned | live), None)
        if free is None:
            free = next((robot for robot in sorted(self.assigned) if robot not in live), None)
        if free is not None:
            self.assigned.add(free)
            log.info("assigned id %d to a robot that asked for one", free)
        return free

    def beacons_answering(self, tick: int) -> list[str]:
        """The beacons that answer ``tick``: each is sent its clock for it."""
        return [name for name in self.world.beacons() if self.beacon_next.get(name, 0) <= tick]

    def participants(self, tick: int) -> list[str]:
        """The identities ``tick``, opened now, waits for: every live robot and every beacon
        that answers it, but a controller that went silent (hung, not gone), until it
        answers again, so one stuck process cannot slow the swarm to its stall timeout."""
        everyone = [names.robot_identity(robot) for robot in self.world.live_robots()]
        everyone += [names.beacon_identity(name) for name in self.beacons_answering(tick)]
        missed = self.counters.missed
        return [who for who in everyone if missed.get(who, 0) < SUSPEND_AFTER]
