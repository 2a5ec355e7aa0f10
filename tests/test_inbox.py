"""The bounded inbox (bestofn_swarm/plumbing/inbox.py) charges what a queued message really costs,
and the recorder's writer keeps no more keys than a run has (world_server/recording/writer.py)."""

from __future__ import annotations

import io
import os
import queue
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import pytest

from bestofn_swarm.plumbing.inbox import ITEM_OVERHEAD_BYTES, BoundedInbox, message_bytes
from bestofn_swarm.wire import keyspace, protocol
from deploy.launcher.follower import Heard
from nest_beacon.node.beacon_node import Event as BeaconEvent
from robot_agent.node.robot_node import Event as RobotEvent
from robot_agent.node.robot_node import LatestSenses
from world_server.core.events import Event
from world_server.recording import writer
from world_server.recording.description import RunDescription
from world_server.recording.writer import KEYS_OF_A_RUN, KEYS_PER_ROBOT, McapRecorder, Sample

KEY = "bestofn/run/robot/7/act"


def test_every_message_costs_its_bytes_and_a_fixed_overhead_empty_ones_included() -> None:
    inbox: BoundedInbox[str] = BoundedInbox(max_bytes=10 * ITEM_OVERHEAD_BYTES)
    assert inbox.put("empty")  # size 0: charged all the same
    assert inbox.queued_bytes == ITEM_OVERHEAD_BYTES
    assert inbox.put("act", message_bytes(b"x" * 100, b"t" * 16, KEY))
    assert inbox.queued_bytes == 2 * ITEM_OVERHEAD_BYTES + 116 + len(KEY)
    inbox.get(timeout=0)
    inbox.get(timeout=0)
    assert inbox.queued_bytes == 0
    assert inbox.peak_bytes == 2 * ITEM_OVERHEAD_BYTES + 116 + len(KEY)


def test_a_flood_of_empty_messages_is_capped_and_counted() -> None:
    inbox: BoundedInbox[int] = BoundedInbox(max_bytes=100 * ITEM_OVERHEAD_BYTES)
    accepted = sum(inbox.put(index, 0, "flood") for index in range(10_000))
    assert accepted == 100
    assert inbox.take_dropped("flood") == 9_900
    assert inbox.queued_bytes <= inbox.max_bytes


def test_what_comes_once_has_a_reserve_and_a_stop_always_goes_in() -> None:
    inbox: BoundedInbox[str] = BoundedInbox(max_bytes=8 * ITEM_OVERHEAD_BYTES)
    while inbox.put("tick after tick"):
        pass
    assert inbox.put("a robot joined", once=True)  # the reserve: an eighth of the cap
    assert not inbox.put("another", once=True)
    assert inbox.queued_bytes == inbox.limit_bytes
    assert inbox.put("stop", control=True)
    assert inbox.queued_bytes == inbox.limit_bytes + ITEM_OVERHEAD_BYTES
    items = [inbox.get(timeout=0) for _ in range(10)]
    assert items[-2:] == ["a robot joined", "stop"]
    with pytest.raises(queue.Empty):
        inbox.get(timeout=0)
    assert inbox.queued_bytes == 0


def test_a_message_too_big_to_be_valid_is_dropped_whatever_room_there_is() -> None:
    inbox: BoundedInbox[str] = BoundedInbox(max_bytes=2**20, max_item_bytes=100)
    assert not inbox.put("big", 101, "robot 3", once=True)
    assert inbox.take_dropped("robot 3") == 1 and inbox.queued_bytes == 0


def _measured_bytes(make: Callable[[bytes, bytes], Any], payload: int, count: int) -> float:
    """What ``count`` queued items made by ``make`` hold beyond their bytes, per item."""
    held: queue.SimpleQueue[tuple[int, Any]] = queue.SimpleQueue()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(count):
            held.put((0, make(os.urandom(payload), os.urandom(16))))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    return grown / count - payload - 16


# What each process's inbox holds, as its Zenoh callback makes it (a key string per message).
QUEUED: dict[str, Callable[[bytes, bytes], Any]] = {
    "world": lambda payload, tag: Event(keyspace.ACT, KEY[:-3] + "act", payload, tag),
    "recorder": lambda payload, tag: Sample(KEY[:-3] + "act", payload, tag, time.time_ns()),
    "launcher": lambda payload, tag: Heard(keyspace.STATUS, KEY[:-3] + "act", payload, tag),
    "robot": lambda payload, tag: RobotEvent(1, keyspace.RADIO_RX, payload, tag),
    "beacon": lambda payload, tag: BeaconEvent(keyspace.BEACON_CLOCK, payload, tag),
}


@pytest.mark.parametrize("process", sorted(QUEUED))
@pytest.mark.parametrize("payload", [0, 120, 4000])
def test_the_overhead_charged_covers_what_a_queued_message_holds(
    process: str, payload: int
) -> None:
    """Measured with tracemalloc, as benchmarks/flood_memory.py prints it."""
    overhead = _measured_bytes(QUEUED[process], payload, 2000) - len(KEY)
    assert 0 < overhead < ITEM_OVERHEAD_BYTES


def test_the_recorder_keeps_no_more_keys_than_a_run_has_and_no_channel_for_junk(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(writer, "versions", dict)  # they would ask git, in a process
    keys = keyspace.Keys("run")
    recorder = McapRecorder(io.BytesIO(), keys, RunDescription("run", robots=2))
    status = protocol.Status(
        v=1, id=0, tick=1, t=0.1, phase="waiting", trips=0, opinion=[0.5, 0.5],
        pool_size=0, poolings=0, decided_site=None, decision_time=None, decision_trips=0,
        comparison=None,
    )  # fmt: skip
    recorder.record(Sample(keys.of(keyspace.STATUS, 0), protocol.encode(status), None, 0))
    limit = KEYS_PER_ROBOT * 2 + KEYS_OF_A_RUN
    for robot in range(2, 2 * limit):  # robots of no run: junk, each on a key of its own
        recorder.record(Sample(keys.of(keyspace.STATUS, robot), b"junk", None, 0))
        recorder.record(Sample(f"{keys.prefix}/junk/{robot}", b"junk", None, 0))
    assert len(recorder._routes) == limit
    assert recorder.rejected == 2 * (2 * limit - 2)
    recorder.finish()
    channels = {channel.topic for channel in recorder._channels.values()}
    assert keys.of(keyspace.STATUS, 0) in channels
    assert not [topic for topic in channels if "/junk/" in topic or topic.endswith("/2/status")]


# --- a real-time robot's newest sense ------------------------------------------------------


def test_a_real_time_robot_steps_only_its_newest_sense_and_counts_the_skipped() -> None:
    """What waits for a robot is replaced by its newer sense; each robot (or host) keeps its
    place; a step that fails is logged and the others still run."""
    ran: list[str] = []
    latest = LatestSenses()

    def step(name: str) -> Callable[[], None]:
        return lambda: ran.append(name)

    def fails() -> None:
        raise RuntimeError("a broken step")

    latest.offer(1, step("robot 1, tick 5"))
    latest.offer(2, fails)
    latest.offer(1, step("robot 1, tick 6"))  # the thread has not come to tick 5: skipped
    latest.offer("host", step("host, tick 6"))
    latest.start()
    deadline = time.monotonic() + 10.0
    while len(ran) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    latest.offer(2, step("robot 2, tick 7"))
    while len(ran) < 3 and time.monotonic() < deadline:
        time.sleep(0.01)
    latest.stop()
    assert ran == ["robot 1, tick 6", "host, tick 6", "robot 2, tick 7"]
    assert latest.skipped == 1
    assert not latest._thread.is_alive()
