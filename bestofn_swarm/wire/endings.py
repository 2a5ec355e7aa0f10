"""How a run ends (pure): the endings with their exit codes and meanings, why an engine
stops following a run, and the one rule that decides it.

An engine of ``swarm run`` (the launcher following processes over Zenoh,
``deploy/launcher/launcher.py``, or the in-process loop, ``deploy/inprocess/engine.py``) asks
``stop_reason`` at every look at its run; the answer (``Halt``) says why it stops
(``Stop``). The summary then names how the run ended (``Ending``, ``ending_of``): a run
stopped because every running robot decided ended in consensus or split. The exit code,
``swarm run --help`` (``exit_codes_help``), ``swarm experiment``, ``swarm report`` and the
viewer take the endings from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum, StrEnum

USAGE_ERROR = 2  # the exit code of a bad command line (argparse's): nothing was started
SIGNAL_EXIT_BASE = 128  # a run ended by a signal exits 128 + the signal's number


class StopSignal(IntEnum):
    """The signals that end a run in order, by their POSIX numbers (the same on every
    Unix; deploy/launcher/signals.py installs them)."""

    SIGINT = 2
    SIGTERM = 15
    SIGHUP = 1

    @property
    def sent_by(self) -> str:
        """Who usually sends it, for the help ('' if nobody in particular)."""
        return _SENT_BY.get(self, "")


_SENT_BY: Mapping[StopSignal, str] = {
    StopSignal.SIGINT: "Ctrl-C",
    StopSignal.SIGTERM: "e.g. timeout(1)",
}


class Ending(StrEnum):
    """How a run ended: the summary's ``ended``, with its exit code and meaning."""

    CONSENSUS = "consensus"
    SPLIT = "split"
    STALLED = "stalled"
    TIMEOUT = "timeout"
    WORLD_STOPPED = "world_stopped"
    INTERRUPTED = "interrupted"
    CRASHED = "crashed"

    @property
    def code(self) -> int:
        """The exit code; an interrupted run's is 128 + the signal (``exit_code``)."""
        return _CODES_AND_MEANINGS[self][0]

    @property
    def meaning(self) -> str:
        """One line (a second one only continues it), as the help says it."""
        return _CODES_AND_MEANINGS[self][1]

    def exit_code(self, signum: int | None = None) -> int:
        """The exit code of this ending; an interrupted run's tells the signal."""
        if self is Ending.INTERRUPTED and signum is not None:
            return SIGNAL_EXIT_BASE + signum
        return self.code

    @property
    def is_result(self) -> bool:
        """Whether the run ran its course (to be counted and reported), rather than
        being cut short from outside or broken."""
        return self not in (Ending.WORLD_STOPPED, Ending.INTERRUPTED, Ending.CRASHED)

    @classmethod
    def named(cls, text: object) -> Ending | None:
        """The ending a summary names; None if it names none."""
        if not isinstance(text, str) or text not in ENDINGS:
            return None
        return cls(text)


_CODES_AND_MEANINGS: Mapping[Ending, tuple[int, str]] = {
    Ending.CONSENSUS: (0, "every running robot decided, all on the same site"),
    Ending.SPLIT: (3, "every running robot decided, not all on the same site"),
    Ending.STALLED: (
        4,
        "no robot at work completed a step of its task for --stall-window\n"
        "sim seconds, with some robot undecided",
    ),
    Ending.TIMEOUT: (
        5,
        "--timeout sim seconds or --wall-timeout wall seconds passed\n"
        '(the summary\'s "timeout_kind": sim or wall)',
    ),
    Ending.WORLD_STOPPED: (
        6,
        "the world's clock did not advance for --world-stop-window wall\n"
        "seconds (the world server hung, or the launcher lost it)",
    ),
    Ending.INTERRUPTED: (
        SIGNAL_EXIT_BASE + StopSignal.SIGINT,
        "by a stop signal: SIGINT, SIGTERM or SIGHUP",
    ),
    Ending.CRASHED: (
        1,
        "a process of the run died on its own, a plug-in failed (the\n"
        'summary\'s "error" says which, where and when), or the run could not start',
    ),
}
# Every ending's name, in the order the report lists them.
ENDINGS: tuple[str, ...] = tuple(ending.value for ending in Ending)
# The exit codes of runs that ended with a result (``Ending.is_result``).
RESULT_CODES = frozenset(ending.code for ending in Ending if ending.is_result)


class Stop(StrEnum):
    """Why an engine stopped following its run; ``DECIDED`` becomes consensus or split."""

    DECIDED = "decided"
    STALLED = "stalled"
    TIMEOUT = "timeout"
    WORLD_STOPPED = "world_stopped"
    INTERRUPTED = "interrupted"
    CRASHED = "crashed"


class TimeLimit(StrEnum):
    """Which limit a timeout hit: the summary's ``timeout_kind``."""

    SIM = "sim"  # --timeout, in sim seconds
    WALL = "wall"  # --wall-timeout, in wall seconds since the launch


@dataclass(frozen=True)
class Halt:
    """An engine's answer to "stop now?": why, and for a timeout which limit."""

    stop: Stop
    limit: TimeLimit | None = None


@dataclass(frozen=True)
class Look:
    """What an engine sees of its run at one look."""

    sim_time: float  # the run's sim time now
    sim_limit: float  # --timeout
    all_decided: bool  # every running honest robot decided (and no restart is to come)
    last_decision: float  # the sim time the last of them decided (when all_decided)
    stalled: bool  # the watchdog: no undecided robot progressed for the stall window
    wall_time: float = 0.0  # wall seconds since the launch
    wall_limit: float | None = None  # --wall-timeout; None: no limit
    crashed: bool = False  # a process of the run other than a robot died on its own
    signalled: bool = False  # a stop signal came
    world_stopped: bool = False  # the world's clock did not advance for its wall window
    ended: Halt | None = None  # the world's ending, heard (it judged 2 to 4 itself)


def stop_reason(look: Look) -> Halt | None:
    """Whether the run stops at this look, and why (None: it goes on).

    When several hold at once, the first of these decides:

    1. a crash: a run whose process died has no result to trust;
    2. every running robot decided: the run's result, unless the last of them decided
       after the sim time limit (a fast run can pass it between two looks: what counts
       is when it decided, not when the engine looked), which is a sim timeout;
    3. the sim time limit;
    4. the stall watchdog;
    5. a stop signal;
    6. the world stopped ticking (no new sim time for its wall window);
    7. the wall time limit.

    What the run did in sim time (2 to 4, the same at every look of a lockstep run) comes
    before what happened outside it on the wall clock (5 to 7), whose coinciding with a
    look is chance: a run that decided as the signal came ended in its decision. A stop
    signal is someone's intent, and comes before what the wall clock alone says.

    The world server asks this rule with 1 (a beacon lost), 2 to 4 and 5 (a stop signal
    to it); a launcher that heard the world's ending (``ended``) takes it for 2 to 4, after
    its own 1 (a process it started died) and before its own 5 to 7.
    """
    if look.crashed:
        return Halt(Stop.CRASHED)
    if look.ended is not None:
        return look.ended
    if look.all_decided:
        if look.last_decision <= look.sim_limit:
            return Halt(Stop.DECIDED)
        return Halt(Stop.TIMEOUT, TimeLimit.SIM)
    if look.sim_time >= look.sim_limit:
        return Halt(Stop.TIMEOUT, TimeLimit.SIM)
    if look.stalled:
        return Halt(Stop.STALLED)
    if look.signalled:
        return Halt(Stop.INTERRUPTED)
    if look.world_stopped:
        return Halt(Stop.WORLD_STOPPED)
    if look.wall_limit is not None and look.wall_time >= look.wall_limit:
        return Halt(Stop.TIMEOUT, TimeLimit.WALL)
    return None


def ending_of(stop: Stop | None, all_decided: bool, consensus: bool) -> Ending | None:
    """How the run ended, from why it stopped and what the robots decided.

    With no stop reason (a run rebuilt from its recording), what the robots decided is
    all there is: consensus or split if every running robot decided, else not known.
    """
    if stop is Stop.DECIDED or (stop is None and all_decided):
        if consensus:
            return Ending.CONSENSUS
        return Ending.SPLIT if all_decided else Ending.STALLED  # stalled: no robot left running
    return None if stop is None else Ending(stop.value)


def exit_codes_help() -> str:
    """``swarm run --help``'s epilog: how a run ends, and the exit code of each."""
    rows = [(ending.code, ending.value, _help_meaning(ending)) for ending in Ending]
    rows.append((USAGE_ERROR, "-", "usage error: nothing was started"))
    lines = ['how a run ends (the summary\'s "ended"), and the exit code of each:']
    for code, name, meaning in sorted(rows):
        first, *more = meaning.split("\n")
        lines.append(f"  {code:<4} {name:<12} {first}")
        lines += [" " * 20 + line for line in more]
    lines.append(
        'Unless it ended in consensus, the summary lists the undecided robots under "stuck".'
    )
    return "\n".join(lines) + "\n"


def _help_meaning(ending: Ending) -> str:
    """An ending's row in the help; the interrupted row names each stop signal with its
    exit code (the first one's is the row's own)."""
    if ending is not Ending.INTERRUPTED:
        return ending.meaning
    parts: list[str] = []
    for stop in StopSignal:
        code = f"{Ending.INTERRUPTED.exit_code(stop)} " if parts else ""
        sent_by = f" ({stop.sent_by})" if stop.sent_by else ""
        parts.append(f"{code}by {stop.name}{sent_by}")
    return "; ".join(parts)
