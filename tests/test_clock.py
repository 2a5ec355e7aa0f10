"""The lockstep barrier and the real-time pacer (pure)."""

from __future__ import annotations

import pytest

from world_server.core.clock import Barrier, Pacer


def test_a_tick_closes_when_everyone_answered_and_their_radio_arrived() -> None:
    barrier = Barrier()
    barrier.open(5, ["robot/0", "robot/1", "beacon/nest"])
    assert not barrier.complete
    assert barrier.answer(5, "robot/0", 0)
    assert barrier.answer(5, "robot/1", 2)
    assert barrier.answer(5, "beacon/nest", 1)
    assert barrier.missing() == ["beacon/nest", "robot/1"]  # radio still to come
    assert barrier.transmitted(5, "robot/1") and barrier.transmitted(5, "robot/1")
    assert barrier.transmitted(5, "beacon/nest")
    assert barrier.complete and barrier.missing() == []


def test_stale_foreign_and_repeated_answers_are_refused() -> None:
    barrier = Barrier()
    barrier.open(5, ["robot/0"])
    assert not barrier.answer(4, "robot/0", 0)  # stale
    assert not barrier.answer(5, "robot/9", 0)  # not a participant
    assert not barrier.transmitted(5, "robot/9")
    assert barrier.answer(5, "robot/0", 1)
    assert not barrier.answer(5, "robot/0", 0)  # repeated
    assert not barrier.transmitted(6, "robot/0")  # wrong tick
    assert not barrier.complete


def test_a_participant_that_leaves_is_not_waited_for() -> None:
    barrier = Barrier()
    barrier.open(0, ["robot/0", "robot/1"])
    barrier.answer(0, "robot/0", 0)
    barrier.leave("robot/1")
    assert barrier.complete


def test_the_pacer_spaces_ticks_by_dt_over_speed_from_the_first_call() -> None:
    pacer = Pacer(dt=0.1, speed=4.0)
    assert pacer.deadline(0, now=100.0) == pytest.approx(100.025)
    assert pacer.deadline(1, now=100.01) == pytest.approx(100.05)
    assert pacer.deadline(40, now=123.0) == pytest.approx(100.0 + 41 * 0.025)


@pytest.mark.parametrize(("dt", "speed"), [(0.0, 1.0), (0.1, 0.0), (-0.1, 2.0)])
def test_the_pacer_refuses_a_clock_that_does_not_advance(dt: float, speed: float) -> None:
    with pytest.raises(ValueError, match="positive"):
        Pacer(dt=dt, speed=speed)
