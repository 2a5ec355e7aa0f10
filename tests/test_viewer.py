"""Watching a swarm: the live page in a real browser, the replay of a recording, Foxglove
live, and the promise that watching changes nothing the swarm decides.

Set ``VIEWER_SCREENSHOTS=docs`` to write the screenshots of docs/viewer.md from these
tests (``VIEWER_SCREENSHOTS=docs .venv/bin/python -m pytest tests/test_viewer.py``).
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from browser import Browser, browser, pixel_statistics, save, share_of_colour
from swarm_helpers import REPO, kill_leftovers, processes_of, swarm_command, unique_run_id
from websockets.sync.client import connect

from deploy.processes import free_port
from robot_agent import protocol
from viewer import model, replay
from viewer.decode import Delivery, InvalidSampleError, decode_sample
from viewer.live import MAX_DELIVERIES, LiveSource
from world_server.layout import make_layout
from world_server.recorder import McapRecorder, RunDescription, Sample

pytestmark = pytest.mark.timeout(180)

ROBOTS, SITES, SEED = 10, 5, 2
RUN = ["--robots", str(ROBOTS), "--sites", str(SITES), "--seed", str(SEED)]
SCREENSHOTS = os.environ.get("VIEWER_SCREENSHOTS")


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as sock:
        sock.settimeout(0.2)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def _wait_for_port(port: int, process: subprocess.Popen[bytes], timeout: float = 60.0) -> None:
    import socket

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the command exited with {process.returncode} before serving")
        with socket.socket() as sock:
            sock.settimeout(0.2)
            if sock.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listened on port {port}")


def _finish(process: subprocess.Popen[bytes], run_id: str, timeout: float = 90.0) -> dict[str, Any]:
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    finally:
        kill_leftovers(run_id)
    assert process.returncode == 0, stderr.decode()[-3000:]
    return dict(json.loads(stdout))


def _start(run_id: str, *args: str) -> subprocess.Popen[bytes]:
    command = swarm_command("run", "--run-id", run_id, "--json", "--quiet", *RUN, *args)
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)


def _per_robot(summary: dict[str, Any]) -> list[tuple[Any, ...]]:
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


# --- the live page in a browser ----------------------------------------------------------


@dataclass
class LiveRun:
    summary: dict[str, Any]
    recording: Path
    seen: list[dict[str, str]] = field(default_factory=list)  # the canvas's data, polled
    final: dict[str, str] = field(default_factory=dict)
    header: str = ""
    screenshot: bytes = b""


@pytest.fixture(scope="module")
def chromium() -> Iterator[Browser]:
    with browser() as instance:
        yield instance


@pytest.fixture(scope="module")
def live_run(chromium: Browser, tmp_path_factory: pytest.TempPathFactory) -> LiveRun:
    """A 10-robot lockstep run with --view, watched by the browser from start to end."""
    run_id = unique_run_id("view")
    port = free_port()
    recording = tmp_path_factory.mktemp("view") / "run.mcap"
    process = _start(run_id, "--view", str(port), "--record", str(recording))
    seen: list[dict[str, str]] = []
    midrun: list[bytes] = []
    try:
        _wait_for_port(port, process)
        chromium.navigate(f"http://127.0.0.1:{port}/")
        deadline = time.monotonic() + 90
        while process.poll() is None and time.monotonic() < deadline:
            data = chromium.canvas_data()
            if data:
                seen.append(data)
                if SCREENSHOTS and float(data.get("simTime", 0)) > 25 and not midrun:
                    midrun.append(chromium.screenshot())  # for docs/viewer.md
            time.sleep(0.1)
    finally:
        summary = _finish(process, run_id)
    time.sleep(0.3)  # the page notices the closed connection
    run = LiveRun(summary, recording, seen)
    run.final = chromium.canvas_data()
    run.header = str(chromium.evaluate("document.getElementById('header').innerText"))
    run.screenshot = chromium.screenshot()
    if SCREENSHOTS:
        save(midrun[0] if midrun else run.screenshot, Path(SCREENSHOTS) / "viewer-live.png")
        save(run.screenshot, Path(SCREENSHOTS) / "viewer-live-ended.png")
    return run


def test_the_live_page_draws_every_robot_as_sim_time_advances(live_run: LiveRun) -> None:
    live = [data for data in live_run.seen if data.get("mode") == "live"]
    assert live, live_run.seen[:3]
    assert max(int(data["robots"]) for data in live) == ROBOTS
    times = [float(data["simTime"]) for data in live]
    assert times == sorted(times)  # never backwards
    assert len(set(times)) >= 3, times  # and it moved while the page watched
    assert max(times) > 0


def test_the_live_page_shows_how_the_run_ended(live_run: LiveRun) -> None:
    assert live_run.summary["consensus"]
    assert live_run.final["ended"] == "consensus"
    assert live_run.final["robots"] == str(ROBOTS)
    assert float(live_run.final["simTime"]) >= live_run.summary["sim_time_s"]
    header = live_run.header
    assert live_run.summary["run_id"] in header
    assert f"decided {ROBOTS}/{ROBOTS}" in header
    assert f"consensus on site {live_run.summary['chosen_site']}, the best" in header


def test_the_live_screenshot_shows_the_arena_not_a_blank_page(live_run: LiveRun) -> None:
    stats = pixel_statistics(live_run.screenshot)
    assert stats["width"] == 1280 and stats["height"] == 860
    assert stats["std"] > 20  # a blank or one-colour page has (almost) none
    assert stats["colours"] > 40
    assert 0.05 < stats["non_background"] < 0.95
    best = make_layout(SITES, ROBOTS, SEED).site(live_run.summary["best_site"])
    assert share_of_colour(live_run.screenshot, model.site_hex(best.quality)) > 0.0005


# --- the replay page in a browser -----------------------------------------------------------


def _serve_replay(recording: Path, port: int, *args: str) -> subprocess.Popen[bytes]:
    command = swarm_command("view", str(recording), "--port", str(port), *args)
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)


def _stop(process: subprocess.Popen[bytes]) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _poll(chromium: Browser, done: Any, timeout: float = 20.0) -> dict[str, str]:
    deadline = time.monotonic() + timeout
    data: dict[str, str] = {}
    while time.monotonic() < deadline:
        data = chromium.canvas_data()
        if data and done(data):
            return data
        time.sleep(0.1)
    raise AssertionError(f"the page never got there; last: {data}")


def test_the_replay_page_plays_seeks_and_jumps(chromium: Browser, live_run: LiveRun) -> None:
    port = free_port()
    process = _serve_replay(live_run.recording, port, "--speed", "100")
    try:
        _wait_for_port(port, process)
        chromium.navigate(f"http://127.0.0.1:{port}/")
        first = _poll(chromium, lambda d: d.get("mode") == "replay" and d["robots"] == str(ROBOTS))
        end = _poll(chromium, lambda d: d["ended"] != "", timeout=30)
        assert float(end["simTime"]) > float(first["simTime"])
        assert end["ended"] == "consensus"
        # Jump back to the start, then to the next decision: the page stops on it.
        chromium.evaluate("send({op: 'seek', t: 0})")
        _poll(chromium, lambda d: d["ended"] == "" and float(d["simTime"]) < 5)
        chromium.evaluate("send({op: 'next', kind: 'decision'})")
        first_decision = min(
            r["decision_time_s"] for r in live_run.summary["per_robot"] if r["decision_time_s"]
        )
        jumped = _poll(chromium, lambda d: float(d["simTime"]) > 5)
        assert float(jumped["simTime"]) == pytest.approx(first_decision, abs=0.11)
        header = str(chromium.evaluate("document.getElementById('header').innerText"))
        assert "decided 1/" in header and "(replay)" in header
        chromium.evaluate("selected = 4; send({op: 'select', robot: 4})")  # the detail panel
        time.sleep(0.5)
        png = chromium.screenshot()
        assert pixel_statistics(png)["std"] > 20
        if SCREENSHOTS:
            save(png, Path(SCREENSHOTS) / "viewer-replay.png")
    finally:
        _stop(process)


def test_swarm_view_refuses_a_missing_or_unreadable_recording(tmp_path: Path) -> None:
    missing = subprocess.run(
        swarm_command("view", str(tmp_path / "none.mcap")), capture_output=True, cwd=REPO
    )
    assert missing.returncode == 2
    assert missing.stderr.decode().strip().splitlines() == [
        f"swarm view: error: no such recording: {tmp_path / 'none.mcap'}"
    ]
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    bad = subprocess.run(swarm_command("view", str(junk)), capture_output=True, cwd=REPO)
    assert bad.returncode == 1
    assert "not a readable MCAP recording" in bad.stderr.decode()
    assert "Traceback" not in bad.stderr.decode()


# --- replay without a browser: cut-short and old-style recordings ---------------------------


def _made_up_recording(path: Path, *, states: bool, finish: bool) -> None:
    """A small recording written by the real recorder class, as every version wrote them."""
    run_id = "made-up"
    keys = protocol.Keys(run_id)
    layout = make_layout(3, 2, 5)
    with path.open("wb") as stream:
        mcap = McapRecorder(stream, keys, RunDescription(run_id, 5, 2, 3), chunk_size=1)

        def put(key: str, message: Any) -> None:
            mcap.record(Sample(key, protocol.encode(message), None, time.time_ns()))

        for tick in range(0, 101, 10):
            put(keys.world_clock, protocol.Clock(v=1, tick=tick, t=tick / 10))
            poses = [protocol.Pose(robot, 0.01 * tick, 0.1 * robot, 0.0) for robot in (0, 1)]
            if states:
                put(
                    keys.world_state,
                    protocol.WorldState(
                        v=1,
                        tick=tick,
                        t=tick / 10,
                        robots=poses,
                        radio=protocol.RadioCounters(sent=tick),
                        rejected=0,
                        stalls=0,
                    ),
                )
            for pose in poses:
                sense = protocol.Sense(
                    v=1,
                    tick=tick,
                    t=tick / 10,
                    x=pose.x,
                    y=pose.y,
                    theta=0.0,
                    prox=[0.0] * 8,
                    rx=0,
                    camera=False,
                )
                put(keys.sense(pose.id), sense)
        for robot in (0, 1):
            decided = layout.best_site
            opinion = [1.0 if site == decided else 0.0 for site in range(3)]
            put(
                keys.status(robot),
                protocol.Status(
                    v=1,
                    id=robot,
                    tick=50 + robot,
                    t=5.0 + robot / 10,
                    phase="to_decision",
                    trips=1,
                    opinion=opinion,
                    pool_size=2,
                    poolings=1,
                    decided_site=decided,
                    decision_time=5.0 + robot / 10,
                    decision_trips=1,
                    comparison=None,
                ),
            )
        if finish:
            mcap.finish({"consensus": True, "correct": True, "chosen_site": decided})


@pytest.mark.parametrize("states", [True, False], ids=["world-state", "sense-only"])
def test_replay_reads_a_cut_short_recording_up_to_where_it_ends(
    tmp_path: Path, states: bool
) -> None:
    whole = tmp_path / "whole.mcap"
    _made_up_recording(whole, states=states, finish=False)
    cut = tmp_path / "cut.mcap"
    data = whole.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.8)])
    timeline = replay.load(cut)
    assert not timeline.complete and timeline.problem
    assert 0 < timeline.end <= 10.0
    assert len(timeline.decisions) < 2  # the cut took the last status with it
    source = replay.ReplaySource(timeline)
    source.command({"op": "seek", "t": 1e9})
    frame = source.frame()
    assert len(frame["robots"]) == 2
    assert frame["ended"]["reason"] == "cut short"
    # Poses are between where the robots were at the recording's first and last moment.
    assert 0.0 <= frame["robots"][0][1] <= 0.01 * 100


def test_replay_of_a_finished_recording_knows_decisions_and_the_ending(tmp_path: Path) -> None:
    path = tmp_path / "done.mcap"
    _made_up_recording(path, states=True, finish=True)
    timeline = replay.load(path)
    assert timeline.complete and timeline.problem is None
    assert [robot for _, robot in timeline.decisions] == [0, 1]
    source = replay.ReplaySource(timeline)
    source.command({"op": "next", "kind": "decision"})
    assert source.t == pytest.approx(5.0)
    assert source.frame()["decided"] == 1
    # Interpolated halfway between two world states (x = 0.01 * tick, states every 10 ticks).
    assert replay.poses_at(timeline, 2.5)[0][0] == pytest.approx(0.25)
    source.command({"op": "seek", "t": timeline.end})
    assert source.frame()["ended"] == {
        "reason": "consensus",
        "text": f"consensus on site {make_layout(3, 2, 5).best_site}, the best",
    }


# --- the live bridge's gate and its bounds (no network) --------------------------------------


def test_every_sample_passes_one_gate_that_rejects_what_is_not_a_valid_message() -> None:
    keys = protocol.Keys("gate")
    clock = protocol.encode(protocol.Clock(v=1, tick=3, t=0.3))
    assert decode_sample(keys, keys.world_clock, clock, None) == protocol.Clock(v=1, tick=3, t=0.3)
    assert decode_sample(keys, keys.sense(1), b"{}", None) is None  # a key the view does not use
    with pytest.raises(InvalidSampleError, match="status of robot 4"):
        status = protocol.Status(
            v=1,
            id=4,
            tick=1,
            t=0.1,
            phase="to_site",
            trips=0,
            opinion=[0.5, 0.5],
            pool_size=0,
            poolings=0,
            decided_site=None,
            decision_time=None,
            decision_trips=None,
            comparison=None,
        )
        decode_sample(keys, keys.status(3), protocol.encode(status), None)
    with pytest.raises(InvalidSampleError):
        decode_sample(keys, keys.world_state, b'{"v":1,"tick":-1}', None)
    with pytest.raises(InvalidSampleError, match="without metadata"):
        decode_sample(keys, keys.radio_rx(2), b"{}", None)
    meta = protocol.encode(protocol.RadioRxMeta(v=1, tick=5, sender="7", seq=1, sent_tick=4))
    delivery = decode_sample(keys, keys.radio_rx(2), b"{}", meta)
    assert isinstance(delivery, Delivery) and delivery.receiver == 2


def test_the_bridge_keeps_the_newest_state_and_a_bounded_list_of_deliveries() -> None:
    keys = protocol.Keys("bounded")
    scene = model.Scene("bounded", 0, 3, make_layout(3, 3, 0))
    source = LiveSource(scene, keys)
    for tick in range(5000):
        state = protocol.WorldState(
            v=1,
            tick=tick,
            t=tick / 10,
            robots=[protocol.Pose(0, tick / 1e4, 0.0, 0.0)],
            radio=protocol.RadioCounters(sent=tick),
            rejected=0,
            stalls=0,
        )
        source.take(keys.world_state, protocol.encode(state), None)
        meta = protocol.RadioRxMeta(v=1, tick=tick, sender="1", seq=tick, sent_tick=tick)
        source.take(keys.radio_rx(0), b"{}", protocol.encode(meta))
    source.take(keys.world_state, b"not json", None)
    frame = source.frame()
    assert frame["radio"]["sent"] == 4999  # the newest state, nothing queued behind it
    assert frame["robots"][0][1] == pytest.approx(0.4999)
    assert len(frame["rx"]) == MAX_DELIVERIES
    assert frame["rejected"] == 1
    assert source.frame()["rx"] == []  # each delivery is drawn once


# --- observers change nothing; Foxglove live ---------------------------------------------------


@dataclass
class FoxgloveSeen:
    server_info: dict[str, Any] = field(default_factory=dict)
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, Any] = field(default_factory=dict)  # topic leaf -> first decoded message
    error: str | None = None


FOXGLOVE_WANTED = ("foxglove/scene", "foxglove/transforms")


def _watch_foxglove(port: int, seen: FoxgloveSeen, stop: threading.Event) -> None:
    """A Foxglove WebSocket client: server info, advertised channels, one message each of
    the scene and the transforms (binary message data frames, JSON payload)."""
    try:
        deadline = time.monotonic() + 60
        while not _listening(port):
            if time.monotonic() > deadline or stop.is_set():
                raise TimeoutError(f"Foxglove live never listened on {port}")
            time.sleep(0.05)
        subscriptions: dict[int, str] = {}
        with connect(
            f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], open_timeout=5
        ) as connection:
            while not stop.is_set() and len(seen.messages) < len(FOXGLOVE_WANTED):
                try:
                    data = connection.recv(timeout=0.5)
                except TimeoutError:
                    continue
                if isinstance(data, str):
                    message = json.loads(data)
                    if message["op"] == "serverInfo":
                        seen.server_info = message
                    elif message["op"] == "advertise":
                        for channel in message["channels"]:
                            seen.channels[channel["id"]] = channel
                            leaf = next(
                                (w for w in FOXGLOVE_WANTED if channel["topic"].endswith(w)), None
                            )
                            if leaf and leaf not in subscriptions.values():
                                _subscribe(connection, subscriptions, leaf, channel["id"])
                    elif message["op"] == "status" and "Unknown channel" in message["message"]:
                        # foxglove-sdk 0.30 can refuse a subscription sent the instant a
                        # channel is advertised; the app subscribes later. Ask again.
                        channel_id = int(message["message"].rsplit(":", 1)[-1])
                        topic = seen.channels[channel_id]["topic"]
                        leaf = next(w for w in FOXGLOVE_WANTED if topic.endswith(w))
                        time.sleep(0.05)
                        _subscribe(connection, subscriptions, leaf, channel_id)
                elif data[0] == 1:  # message data: opcode, subscription id, log time, payload
                    _, subscription, _ = struct.unpack_from("<BIQ", data)
                    leaf = subscriptions.get(subscription)
                    if leaf is not None and leaf not in seen.messages:
                        seen.messages[leaf] = json.loads(data[13:])
    except Exception as error:
        topics = sorted(channel["topic"].split("/", 2)[-1] for channel in seen.channels.values())
        seen.error = f"{error!r}; advertised {topics}; decoded {sorted(seen.messages)}"


def _subscribe(connection: Any, subscriptions: dict[int, str], leaf: str, channel: int) -> None:
    subscription = len(subscriptions) + 1
    subscriptions[subscription] = leaf
    request = {"id": subscription, "channelId": channel}
    connection.send(json.dumps({"op": "subscribe", "subscriptions": [request]}))


@dataclass
class ObservedPair:
    plain: dict[str, Any]
    watched: dict[str, Any]
    foxglove: FoxgloveSeen
    run_id: str


@pytest.fixture(scope="module")
def observed_pair() -> ObservedPair:
    """The same seed twice: without observers, and with the page and Foxglove live served
    and a Foxglove client subscribed."""
    plain_id, watched_id = unique_run_id("plain"), unique_run_id("watched")
    plain = _finish(_start(plain_id, "--no-record"), plain_id)
    view_port, foxglove_port = free_port(), free_port()
    seen, stop = FoxgloveSeen(), threading.Event()
    process = _start(
        watched_id, "--no-record", "--view", str(view_port), "--foxglove", str(foxglove_port)
    )
    client = threading.Thread(target=_watch_foxglove, args=(foxglove_port, seen, stop))
    client.start()
    try:
        watched = _finish(process, watched_id)
    finally:
        stop.set()
        client.join(timeout=10)
    return ObservedPair(plain, watched, seen, watched_id)


def test_watching_changes_nothing_the_swarm_decides(observed_pair: ObservedPair) -> None:
    assert _per_robot(observed_pair.watched) == _per_robot(observed_pair.plain)
    assert observed_pair.watched["sim_time_s"] == observed_pair.plain["sim_time_s"]
    assert "view" not in observed_pair.watched["config"]  # watching is not part of the run
    assert processes_of(observed_pair.run_id) == []


def test_foxglove_live_serves_the_recording_channels(observed_pair: ObservedPair) -> None:
    seen = observed_pair.foxglove
    assert seen.error is None, seen.error
    assert seen.server_info["name"] == f"bestofn {observed_pair.run_id}"
    prefix = f"{protocol.DEFAULT_ROOT}/{observed_pair.run_id}"
    by_topic = {channel["topic"]: channel for channel in seen.channels.values()}
    assert by_topic[f"{prefix}/foxglove/scene"]["schemaName"] == "foxglove.SceneUpdate"
    assert by_topic[f"{prefix}/foxglove/transforms"]["schemaName"] == "foxglove.FrameTransforms"
    status = by_topic[f"{prefix}/robot/0/status"]
    assert (status["schemaName"], status["encoding"]) == ("bestofn.Status", "json")
    assert status["schemaEncoding"] == "jsonschema"
    scene = seen.messages["foxglove/scene"]
    assert any(
        entity["id"] in ("arena", "robot-0") or entity["id"].startswith("robot-")
        for entity in scene["entities"]
    )
    transforms = seen.messages["foxglove/transforms"]["transforms"]
    assert transforms and all(t["parent_frame_id"] == "arena" for t in transforms)
    assert {t["child_frame_id"] for t in transforms} <= {f"robot-{i}" for i in range(ROBOTS)}
