"""The parts of ``swarm run`` that own threads and time, each on its own: stop signals as
events, the process group's log pumps, the log relay's end, the fault schedule, and the
launcher's look at a run (with its clock given)."""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any, cast

import pytest
import zenoh

from bestofn_swarm.plumbing import stop_signals
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.endings import Ending, Halt, Stop, TimeLimit
from deploy.cli import build_parser
from deploy.launcher.follower import Heard
from deploy.launcher.launcher import Swarm
from deploy.launcher.log_relay import LogRelay
from deploy.launcher.plan import RunPlan, plan_from_args
from deploy.launcher.processes import ProcessGroup
from deploy.launcher.signals import StopSignals
from robot_agent.core import faults

pytestmark = pytest.mark.timeout(60)


def test_a_stop_signal_becomes_one_event_and_later_ones_change_nothing() -> None:
    heard: list[int] = []
    passed_on = threading.Event()

    def notify(signum: int) -> None:
        heard.append(signum)
        passed_on.set()

    before = signal.getsignal(signal.SIGHUP)
    with StopSignals(notify) as signals:
        os.kill(os.getpid(), signal.SIGHUP)  # handled, not the end of this process
        assert passed_on.wait(10.0)
        os.kill(os.getpid(), signal.SIGTERM)
        assert signals.received == signal.SIGHUP
    assert heard == [signal.SIGHUP]  # the relay was joined: nothing more can come
    assert signal.getsignal(signal.SIGHUP) is before


def test_stop_signals_that_come_while_the_lock_notify_takes_is_held_stop_the_process() -> None:
    """What hung a world server after its launcher's SIGKILL: signals arriving while the
    main thread held the lock its handler took. Here the main thread holds the lock
    ``notify`` takes while three SIGTERMs come: notify runs in the relay, once, when the
    lock is free (a handler calling it directly would wait for itself for good)."""
    lock = threading.Lock()
    heard: list[int] = []
    passed_on = threading.Event()

    def notify(signum: int) -> None:
        with lock:
            heard.append(signum)
        passed_on.set()

    with stop_signals.StopSignals(notify):
        with lock:
            for _ in range(3):
                os.kill(os.getpid(), signal.SIGTERM)
            assert not passed_on.wait(0.2)  # the relay waits for the lock
        assert passed_on.wait(10.0)
    assert heard == [signal.SIGTERM]


def test_the_group_joins_each_childs_pump_once_it_read_the_last_line() -> None:
    lines: list[tuple[str, str]] = []
    group = ProcessGroup(lambda name, line: lines.append((name, line)))
    child = group.start(
        "talker", [sys.executable, "-c", "import sys; print('last words', file=sys.stderr)"]
    )
    child.process.wait(timeout=30)  # gone, but its pump may not have read it all yet
    group.stop_all()
    assert child.pump is not None and not child.pump.is_alive()
    assert list(child.log) == ["last words"] and lines == [("talker", "last words")]


class _Session:
    """Keeps what is published on it."""

    def __init__(self) -> None:
        self.put_keys: list[str] = []

    def put(self, key: str, payload: bytes, **options: Any) -> None:
        self.put_keys.append(key)


def test_the_log_relay_holds_lines_for_the_recorder_and_publishes_none_once_detached() -> None:
    keys = keyspace.Keys("parts")
    echoed: list[str] = []
    relay = LogRelay(keys, lambda process, line: echoed.append(line), hold=True)
    session = _Session()
    relay.line("world", "before the session")
    relay.attach(cast(zenoh.Session, session), None)
    relay.line("beacon", "before the recorder")
    assert session.put_keys == []
    relay.release()
    relay.line("robot-0", "while recording")
    assert session.put_keys == [
        keys.of(keyspace.LOG, "world"),
        keys.of(keyspace.LOG, "beacon"),
        keys.of(keyspace.LOG, "robot-0"),
    ]
    relay.detach()
    relay.line("world", "while closing")
    assert len(session.put_keys) == 3
    assert echoed[-1] == "while closing"  # still shown with --verbose


class _Engine:
    """What the faults did to a run, in order."""

    def __init__(self) -> None:
        self.done: list[tuple[str, int]] = []

    def kill(self, robot: int) -> bool:
        self.done.append(("kill", robot))
        return robot != 1

    def restart(self, robot: int) -> None:
        self.done.append(("restart", robot))


def test_faults_fall_due_in_sim_time_order_and_are_noted_as_the_summary_lists_them() -> None:
    engine = _Engine()
    schedule = faults.Schedule(
        [faults.Restart(1, 20.0), faults.Kill(0, 10.0), faults.MotorFailure(2, 5.0)]
    )
    # A motor failure lives in the robot's controller: the engine has nothing to do.
    assert [fault.SWITCH for fault in schedule.pending] == ["kill", "restart"]
    assert schedule.apply_due(engine, 9.9) == [] and schedule.restart_pending()
    (kill,) = schedule.apply_due(engine, 15.04)
    assert (kill.robot, kill.action) == (0, "kill")
    assert engine.done == [("kill", 0)]
    assert schedule.apply_due(engine, 30.0)[0].action == "restart"
    assert engine.done == [("kill", 0), ("kill", 1), ("restart", 1)]
    assert not schedule.restart_pending() and schedule.pending == []
    assert [applied.record() for applied in schedule.applied] == [
        {
            "robot": 2,
            "action": "motor-failure",
            "at_s": 5.0,
            "applied_at_s": 5.0,
            "was_running": True,
        },
        {"robot": 0, "action": "kill", "at_s": 10.0, "applied_at_s": 15.04, "was_running": True},
        {"robot": 1, "action": "restart", "at_s": 20.0, "applied_at_s": 30.0, "was_running": False},
    ]


# --- the launcher's look, with no process started -----------------------------------------


def _plan(*options: str) -> RunPlan:
    args = build_parser(["run"]).parse_args(["run", "--robots", "2", "--no-record", *options])
    return plan_from_args(args)


def _clock_message(t: float, plan: RunPlan) -> Heard:
    """The world's clock at ``t`` on the run's clock key (a key of another run is refused)."""
    clock = protocol.Clock(v=protocol.VERSION, tick=round(t * 10), t=t)
    return Heard(
        keyspace.CLOCK, keyspace.Keys(plan.run_id).of(keyspace.CLOCK), protocol.encode(clock)
    )


def test_the_launcher_looks_with_its_clock_given_and_takes_a_signal_as_an_event() -> None:
    now = [1000.0]
    # A restart still to come: the robots' decisions (there are no processes here) wait.
    plan = _plan("--wall-timeout", "30", "--timeout", "50", "--restart", "0@1000")
    swarm = Swarm(plan, clock=lambda: now[0])
    assert swarm.wall_deadline == 1030.0
    assert swarm.look(signalled=False) is None
    swarm.inbox.put(_clock_message(12.5, plan))
    assert not swarm.take_events(until=now[0])
    assert swarm.follower.run.sim_time == 12.5 and swarm.follower.started_at == 1000.0
    swarm.signalled(signal.SIGINT)
    assert swarm.take_events(until=now[0])  # the relay's event: a stop signal came
    assert swarm.look(signalled=True) == Halt(Stop.INTERRUPTED)
    now[0] = 1030.0
    assert swarm.look(signalled=False) == Halt(Stop.TIMEOUT, TimeLimit.WALL)
    # The sim time limit is the world's to see: the launcher takes its ending, which comes
    # before a stop signal in the rule's order.
    swarm.inbox.put(_clock_message(50.0, plan))
    swarm.take_events(until=now[0])
    assert swarm.look(signalled=True) == Halt(Stop.INTERRUPTED)
    swarm.inbox.put(_ending_message(plan, Stop.TIMEOUT, TimeLimit.SIM))
    swarm.take_events(until=now[0])
    assert swarm.look(signalled=True) == Halt(Stop.TIMEOUT, TimeLimit.SIM)
    assert swarm.world_ended


def _ending_message(plan: RunPlan, stop: Stop, limit: TimeLimit | None = None) -> Heard:
    """The world's ending, as it would publish it (an unkeyed run: the launcher here holds
    no keys, no network having been made)."""
    ended = Ending.TIMEOUT if stop is Stop.TIMEOUT else Ending(stop.value)
    ending = protocol.RunEnding(
        v=protocol.VERSION,
        run=plan.run_id,
        ended=ended,
        code=ended.code,
        stop=stop,
        timeout_kind=limit,
        tick=500,
        t=50.0,
        signal=None,
        lost=[],
        summary={"ended": ended.value},
    )
    keys = keyspace.Keys(plan.run_id)
    payload = protocol.encode(ending)
    attachment = keyspace.seal_for_everyone(None, keys.of(keyspace.ENDING), payload, 2, "world")
    return Heard(keyspace.ENDING, keys.of(keyspace.ENDING), payload, attachment)


def test_the_inbox_takes_a_signal_whatever_else_filled_it() -> None:
    plan = _plan()
    swarm = Swarm(plan)
    swarm.inbox.max_bytes = 0  # full: every sample is dropped and counted
    swarm.inbox.put(_clock_message(1.0, plan), 100)
    swarm.signalled(signal.SIGTERM)
    assert swarm.take_events(until=swarm.clock())
    assert swarm.follower.run.rejected == 1 and swarm.follower.run.sim_time == 0.0
