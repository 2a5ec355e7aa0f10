"""Who is who in a run, each rule said once: names, roles, robot and beacon names,
identities and certificate names.

* A **name** (run id, key root, beacon, process, radio sender) is one chunk of a key
  expression, a certificate's common name and part of an HMAC identity at once: 1 to 64
  ASCII letters, digits, ``_``, ``.``, ``-``. ``str.isalnum`` is not the rule (it takes 'é').
* A **robot** is named by its id in decimal, one spelling per id (``7``, never ``07``), with
  ids below ``MAX_ROBOTS``: that name is its radio sender and its key chunk.
* A **beacon** has a name that is not all digits, so that it is never a robot's.
* A **role** is what a process is to the run (``Role``); the liveliness tokens are
  ``alive/<role>/<id>``.
* An **identity** says whose run key tags a message: ``robot/<id>``, ``beacon/<name>``,
  ``host/<first>-<last>`` (a process hosting the robots ``first`` to ``last``: the identity
  says which robots it may speak for), or the role itself for the run's single processes
  (``world``, ``launcher``, ...).
* A **certificate name** (``--secure``: the common name of a process's TLS certificate) is
  the identity with ``-`` for ``/``: ``robot-7``, ``beacon-nest``, ``world``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from enum import StrEnum
from typing import Annotated, Final

import msgspec

NAME_CHARACTERS = "A-Za-z0-9_.-"
MAX_NAME_LENGTH = 64
NAME_RE = re.compile(f"[{NAME_CHARACTERS}]{{1,{MAX_NAME_LENGTH}}}")
# For msgspec and JSON Schema: '$' must not let a final newline through (Python's would).
_NAME_PATTERN = rf"^[{NAME_CHARACTERS}]+$(?!\n)"
Name = Annotated[str, msgspec.Meta(min_length=1, max_length=MAX_NAME_LENGTH, pattern=_NAME_PATTERN)]

MAX_ROBOTS = 100_000  # robot ids are below this (the protocol's bound; a run has fewer)
DEFAULT_BEACON = "nest"  # the nest beacon of a local run


class Role(StrEnum):
    """What a process is to the run; its liveliness token is ``alive/<role>/<id>``."""

    WORLD = "world"
    ROBOT = "robot"
    BEACON = "beacon"
    LAUNCHER = "launcher"
    RECORDER = "recorder"
    VIEWER = "viewer"  # the live page (an observer: it only listens and asks)
    FOXGLOVE = "foxglove"  # Foxglove live (an observer)
    OBSERVER = "observer"  # --secure: a certificate for any other reader
    BRIDGE = "bridge"  # serves robots outside the emulator over their links


# The identities of the run's single processes: the role is the identity.
WORLD, LAUNCHER, RECORDER = Role.WORLD.value, Role.LAUNCHER.value, Role.RECORDER.value
VIEWER, FOXGLOVE, OBSERVER = Role.VIEWER.value, Role.FOXGLOVE.value, Role.OBSERVER.value
BRIDGE = Role.BRIDGE.value
SINGLE_ROLES = (Role.WORLD, Role.LAUNCHER, Role.RECORDER, Role.VIEWER, Role.FOXGLOVE, Role.BRIDGE)

_ROBOT_ID = "0|[1-9][0-9]{0,4}"  # below MAX_ROBOTS, one spelling per id
HOST = "host"  # the identity of a process hosting robots: host/<first>-<last>
_HOST = re.compile(f"{HOST}/({_ROBOT_ID})-({_ROBOT_ID})")
_IDENTITY = re.compile(
    "(" + "|".join(role.value for role in SINGLE_ROLES) + ")"
    f"|robot/({_ROBOT_ID})|beacon/({NAME_RE.pattern})|{_HOST.pattern}"
)


def is_name(text: object) -> bool:
    """Whether ``text`` is a valid name (see NAME_CHARACTERS)."""
    return isinstance(text, str) and NAME_RE.fullmatch(text) is not None


def check_name(text: str, what: str = "name") -> str:
    """``text`` if it is a valid name; ValueError saying what a name may be otherwise."""
    if not is_name(text):
        raise ValueError(
            f"invalid {what} {text!r}: use 1 to {MAX_NAME_LENGTH} ASCII letters, digits, "
            "'-', '_', '.'"
        )
    return text


# --- robots and beacons ----------------------------------------------------------------


def robot_name(robot: int) -> str:
    """A robot's name: its radio sender and key chunk (its id in decimal)."""
    return str(robot)


def robot_of_name(text: str) -> int | None:
    """The robot id ``text`` names, or None: ASCII decimal, one spelling, below MAX_ROBOTS."""
    if not (text.isascii() and text.isdigit()) or len(text) > len(str(MAX_ROBOTS)):
        return None
    robot = int(text)
    return robot if robot < MAX_ROBOTS and str(robot) == text else None


def is_beacon_name(text: str) -> bool:
    """Whether ``text`` can name a beacon: a valid name that is not all digits."""
    return is_name(text) and not text.isdigit()


def check_beacon_name(text: str) -> str:
    """``text`` if it can name a beacon; ValueError otherwise."""
    check_name(text, "beacon name")
    if text.isdigit():
        raise ValueError(f"beacon name {text!r} is a number: it would be a robot's")
    return text


# --- identities ------------------------------------------------------------------------


# Formatting the enum costs more than the rest of a tick's book-keeping for a robot.
_ROBOT_PREFIX: Final = f"{Role.ROBOT.value}/"
_BEACON_PREFIX: Final = f"{Role.BEACON.value}/"
# Each robot's identity, made once: the world asks for every robot's several times a tick,
# and the same string object hashes once for the dictionaries it keys.
_ROBOT_IDENTITIES: Final[dict[int, str]] = {}


def robot_identity(robot: int) -> str:
    identity = _ROBOT_IDENTITIES.get(robot)
    if identity is None:
        identity = _ROBOT_PREFIX + str(robot)
        if 0 <= robot < MAX_ROBOTS:  # a bounded cache: only ids a swarm can have
            _ROBOT_IDENTITIES[robot] = identity
    return identity


def beacon_identity(name: str) -> str:
    return _BEACON_PREFIX + name


def sender_identity(sender: str) -> str | None:
    """The identity of a radio sender (a robot's or a beacon's name), or None if no robot
    or beacon of a run can have that name."""
    robot = robot_of_name(sender)
    if robot is not None:
        return robot_identity(robot)
    return beacon_identity(sender) if is_beacon_name(sender) else None


def host_identity(first: int, last: int) -> str:
    """The identity of a process hosting the robots ``first`` to ``last`` (every id between
    them): its run key seals the batches it exchanges with the world, and the world takes
    from them only entries of those robots."""
    if not 0 <= first <= last < MAX_ROBOTS:
        raise ValueError(f"no process hosts robots {first} to {last}")
    return f"{HOST}/{first}-{last}"


def host_range(identity: str) -> tuple[int, int] | None:
    """The robots (first, last) a host identity speaks for; None if it is not one."""
    match = _HOST.fullmatch(identity)
    if match is None:
        return None
    first, last = int(match[1]), int(match[2])
    return (first, last) if first <= last else None


def hosted_range(robots: Sequence[int]) -> tuple[int, int] | None:
    """(first, last) if ``robots`` are every id from the first to the last once, in order,
    as ``swarm run`` hosts them; None otherwise (such a process has no host identity)."""
    if not robots or list(robots) != list(range(robots[0], robots[0] + len(robots))):
        return None
    return robots[0], robots[-1]


def is_identity(identity: str) -> bool:
    if _IDENTITY.fullmatch(identity) is None:
        return False
    return not identity.startswith(f"{HOST}/") or host_range(identity) is not None


def check_identity(identity: str) -> str:
    if not is_identity(identity):
        raise ValueError(f"{identity!r} is not an identity of a run")
    return identity


# --- certificate names -----------------------------------------------------------------


def certificate_name(identity: str) -> str:
    """The common name of ``identity``'s TLS certificate (``robot/7`` -> ``robot-7``)."""
    return identity.replace("/", "-", 1)


def robot_certificate(robot: int | str) -> str:
    """A robot's certificate name; ``robot_certificate("{id}")`` is the pattern a process
    hosting several robots fills in per robot (bestofn_swarm/plumbing/zenoh_session.py)."""
    return f"{Role.ROBOT}-{robot}"


def beacon_certificate(name: str) -> str:
    return certificate_name(beacon_identity(name))


def robot_of_certificate(name: str | None) -> int | None:
    """The robot a certificate's common name names (``robot-7``), or None."""
    prefix = f"{Role.ROBOT}-"
    if name is None or not name.startswith(prefix):
        return None
    return robot_of_name(name[len(prefix) :])
