"""How a run ends, on its own (bestofn_swarm/wire/endings.py): the rule both engines ask at every
look, in every combination of conditions that hold at once; the endings' exit codes and the help
made from them (tests/test_docs.py checks that docs/running.md shows that help)."""

from __future__ import annotations

import itertools
import signal
from dataclasses import replace
from typing import Any

import pytest

from bestofn_swarm.wire.endings import (
    ENDINGS,
    RESULT_CODES,
    Ending,
    Halt,
    Look,
    Stop,
    StopSignal,
    TimeLimit,
    ending_of,
    exit_codes_help,
    stop_reason,
)
from deploy.inprocess.engine import EngineHooks, run_in_process
from robot_agent.core.controller import ControllerConfig
from world_server.core.world import WorldConfig

LIMIT, WALL_LIMIT = 100.0, 60.0
# A look at a run that goes on: nothing holds.
QUIET = Look(
    sim_time=50.0,
    sim_limit=LIMIT,
    all_decided=False,
    last_decision=0.0,
    stalled=False,
    wall_time=10.0,
    wall_limit=WALL_LIMIT,
)
# Each condition that can stop a run, as it changes a look, and the answer it gives when
# it is the first that holds: in the order the rule promises.
DECIDED_IN_TIME: dict[str, Any] = {"all_decided": True, "last_decision": LIMIT}
DECIDED_LATE: dict[str, Any] = {"all_decided": True, "last_decision": LIMIT + 0.1}
CONDITIONS: list[tuple[str, dict[str, Any], Halt]] = [
    ("crashed", {"crashed": True}, Halt(Stop.CRASHED)),
    ("decided", DECIDED_IN_TIME, Halt(Stop.DECIDED)),
    ("decided late", DECIDED_LATE, Halt(Stop.TIMEOUT, TimeLimit.SIM)),
    ("sim limit", {"sim_time": LIMIT}, Halt(Stop.TIMEOUT, TimeLimit.SIM)),
    ("stalled", {"stalled": True}, Halt(Stop.STALLED)),
    ("signal", {"signalled": True}, Halt(Stop.INTERRUPTED)),
    ("world stopped", {"world_stopped": True}, Halt(Stop.WORLD_STOPPED)),
    ("wall limit", {"wall_time": WALL_LIMIT}, Halt(Stop.TIMEOUT, TimeLimit.WALL)),
]


def _combinations() -> list[tuple[str, ...]]:
    """Every set of conditions that can hold at once (robots decided in time or late,
    not both)."""
    names = [name for name, _, _ in CONDITIONS]
    found = []
    for size in range(1, len(names) + 1):
        for chosen in itertools.combinations(names, size):
            if not {"decided", "decided late"} <= set(chosen):
                found.append(chosen)
    return found


@pytest.mark.parametrize("held", _combinations(), ids=" + ".join)
def test_when_conditions_coincide_the_first_in_the_rules_order_decides(
    held: tuple[str, ...],
) -> None:
    look = QUIET
    for name, change, _ in CONDITIONS:
        if name in held:
            look = replace(look, **change)
    first = next(halt for name, _, halt in CONDITIONS if name in held)
    assert stop_reason(look) == first


def test_a_run_goes_on_until_a_condition_holds_and_each_limit_counts_when_reached() -> None:
    assert stop_reason(QUIET) is None
    assert stop_reason(replace(QUIET, sim_time=LIMIT - 0.1)) is None
    assert stop_reason(replace(QUIET, wall_time=WALL_LIMIT - 0.1)) is None
    assert stop_reason(replace(QUIET, wall_limit=None, wall_time=1e9)) is None
    # Robots that decided: what counts is when the last one did, not when it was seen.
    seen_late = replace(QUIET, sim_time=LIMIT + 50.0, all_decided=True, last_decision=LIMIT)
    assert stop_reason(seen_late) == Halt(Stop.DECIDED)


def test_the_ending_from_why_the_run_stopped_and_what_the_robots_decided() -> None:
    assert ending_of(Stop.DECIDED, all_decided=True, consensus=True) is Ending.CONSENSUS
    assert ending_of(Stop.DECIDED, all_decided=True, consensus=False) is Ending.SPLIT
    assert ending_of(Stop.DECIDED, all_decided=False, consensus=False) is Ending.STALLED
    for stop in (Stop.STALLED, Stop.TIMEOUT, Stop.WORLD_STOPPED, Stop.INTERRUPTED, Stop.CRASHED):
        # Whatever the robots decided by then: the run did not stop because they had.
        assert ending_of(stop, all_decided=True, consensus=True) == stop.value
    assert ending_of(None, all_decided=False, consensus=False) is None


def test_each_ending_has_its_exit_code_and_an_interrupted_run_tells_the_signal() -> None:
    codes = {ending.value: ending.exit_code() for ending in Ending}
    assert codes == {
        "consensus": 0,
        "split": 3,
        "stalled": 4,
        "timeout": 5,
        "world_stopped": 6,
        "interrupted": 130,
        "crashed": 1,
    }
    assert Ending.INTERRUPTED.exit_code(signal.SIGTERM) == 143
    assert Ending.INTERRUPTED.exit_code(signal.SIGHUP) == 129
    assert Ending.SPLIT.exit_code(signal.SIGTERM) == 3  # a signal only tells an interruption
    assert {0, 3, 4, 5} == RESULT_CODES
    assert [ending for ending in Ending if not ending.is_result] == [
        Ending.WORLD_STOPPED,
        Ending.INTERRUPTED,
        Ending.CRASHED,
    ]
    assert ENDINGS == (
        "consensus",
        "split",
        "stalled",
        "timeout",
        "world_stopped",
        "interrupted",
        "crashed",
    )
    assert Ending.named("split") is Ending.SPLIT
    assert Ending.named("aborted") is None and Ending.named(None) is None


def test_the_stop_signals_have_their_posix_numbers() -> None:
    assert {stop.name: int(stop) for stop in StopSignal} == {
        name: int(getattr(signal, name)) for name in ("SIGINT", "SIGTERM", "SIGHUP")
    }


def test_the_help_has_one_row_per_exit_code_in_order() -> None:
    rows = [line.split() for line in exit_codes_help().splitlines() if line.startswith("  ")]
    codes = [int(row[0]) for row in rows if row[0].isdigit()]
    assert codes == sorted(codes) == [0, 1, 2, 3, 4, 5, 6, 130]
    named = {row[1] for row in rows if row[0].isdigit()}
    assert named == {*ENDINGS, "-"}


# --- the in-process engine asks the same rule -------------------------------------------


def _four_robots() -> WorldConfig:
    return WorldConfig(run="rule", seed=0, num_sites=3, num_robots=4)


@pytest.mark.timeout(60)
def test_the_in_process_engine_stops_on_a_signal_or_the_wall_limit_at_once() -> None:
    signalled = run_in_process(
        _four_robots(), ControllerConfig(), hooks=EngineHooks(stop_signal=lambda: True)
    )
    assert signalled["ended"] == "interrupted" and "timeout_kind" not in signalled
    assert signalled["sim_time_s"] == pytest.approx(0.0)
    assert [robot["id"] for robot in signalled["stuck"]] == [0, 1, 2, 3]
    walled = run_in_process(
        _four_robots(),
        ControllerConfig(),
        hooks=EngineHooks(since_launch=lambda: 10.0, wall_timeout=10.0),
    )
    assert (walled["ended"], walled["timeout_kind"]) == ("timeout", "wall")
    # Both at once: the signal comes first (wire.endings.stop_reason).
    both = run_in_process(
        _four_robots(),
        ControllerConfig(),
        hooks=EngineHooks(stop_signal=lambda: True, since_launch=lambda: 10.0, wall_timeout=1.0),
    )
    assert both["ended"] == "interrupted"
