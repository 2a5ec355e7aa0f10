"""A flooded run stays under the memory caps docs/security.md states, process by process
(issue 23, part 5), in the manner of tests/test_attacks.py: a live ``swarm run`` on a
router the test holds, and the test's session on it, without keys, replaying the run's own
authentic acts and statuses as fast as Zenoh takes them, and the largest junk each process
still takes in before it drops it (the world has no inbox since issue 26: it checks each
input in the callback that brings it). benchmarks/flood_memory.py measures the same on a
10-robot run.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from swarm_helpers import REPO, kill_leftovers, loopback_router, processes_of, swarm_command
from swarm_helpers import unique_run_id as new_run_id

from bestofn_swarm.wire import batch, keyspace, protocol

pytestmark = pytest.mark.timeout(240)

SECURITY = REPO / "docs" / "security.md"
FLOOD_SECONDS = 15.0
# The rows of the caps table in docs/security.md, by the process each names.
CAP_ROWS = {
    "world": "world server",
    "recorder": "recorder",
    "launcher": "launcher",
    "robots": "robot process",
    "beacon": "beacon",
}


def stated_caps() -> dict[str, float]:
    """Each process's memory cap in MB, as the table of docs/security.md states it."""
    caps = {}
    text = SECURITY.read_text()
    for role, name in CAP_ROWS.items():
        row = re.search(rf"^\| {name}[^|]*\|[^|]*\| \*\*(\d+) MB\*\* \|", text, re.MULTILINE)
        assert row is not None, f"docs/security.md states no cap for the {name}"
        caps[role] = float(row.group(1))
    return caps


def role_of(pid: int) -> str | None:
    try:
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    for needle, role in (
        (b"world_server.server", "world"),
        (b"world_server.recorder", "recorder"),
        (b"nest_beacon", "beacon"),
        (b"robot_agent.node", "robots"),
        (b"deploy.cli", "launcher"),
    ):
        if needle in cmdline:
            return role
    return None


def peak_mb(pid: int) -> float | None:
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return None


@contextlib.contextmanager
def watched_peaks(run_id: str) -> Iterator[dict[str, float]]:
    """The peak RSS of each process of the run (by role, the largest), read until the end."""
    peaks: dict[str, float] = {}
    stop = threading.Event()

    def watch() -> None:
        while not stop.wait(0.2):
            for pid in processes_of(run_id):
                role, peak = role_of(pid), peak_mb(pid)
                if role is not None and peak is not None:
                    peaks[role] = max(peaks.get(role, 0.0), peak)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield peaks
    finally:
        stop.set()
        thread.join()


def test_the_caps_table_states_a_cap_for_every_process() -> None:
    caps = stated_caps()
    assert set(caps) == set(CAP_ROWS) and all(cap > 0 for cap in caps.values())


def test_a_flood_of_replays_and_junk_leaves_every_process_under_its_cap(tmp_path: Path) -> None:
    caps = stated_caps()
    run_id = new_run_id("flood")
    keys = keyspace.Keys(run_id)
    heard: dict[str, tuple[bytes, bytes | None]] = {}
    ticks: list[int] = []
    with loopback_router() as (session, endpoint):

        def hear(sample: zenoh.Sample) -> None:
            attachment = sample.attachment
            heard[str(sample.key_expr)] = (
                sample.payload.to_bytes(),
                attachment.to_bytes() if attachment is not None else None,
            )

        def on_clock(sample: zenoh.Sample) -> None:
            with contextlib.suppress(protocol.ProtocolError):
                ticks.append(protocol.decode(sample.payload.to_bytes(), protocol.Clock).tick)

        declared = [
            session.declare_subscriber(key, hear)
            for key in (
                keys.of(keyspace.ACT, "*"),
                keys.of(keyspace.HOST_ACT, "*"),
                keys.of(keyspace.STATUS, "*"),
            )
        ]
        declared.append(session.declare_subscriber(keys.of(keyspace.CLOCK), on_clock))
        command = swarm_command(
            "run", "--run-id", run_id, "--json", "--quiet", "--connect", endpoint,
            "--robots", "3", "--sites", "4", "--seed", "1", "--timeout", "600",
            "--robots-per-process", "1", "--spawn", "exec",
            "--record", str(tmp_path / "run.mcap"),
        )  # fmt: skip
        process = subprocess.Popen(
            command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        sent = [0]
        try:
            with watched_peaks(run_id) as peaks:
                deadline = time.monotonic() + 60
                while (not ticks or ticks[-1] < 30) and time.monotonic() < deadline:
                    time.sleep(0.05)
                assert ticks and heard, "the run never got going"
                junk = [
                    (keys.of(keyspace.HOST_ACT, 0), os.urandom(batch.MAX_BATCH_BYTES), None),
                    (
                        keys.of(keyspace.CAMERA, 0),
                        os.urandom(protocol.MAX_CAMERA_FRAME_BYTES),
                        None,
                    ),
                    (keys.of(keyspace.STATUS, 0), os.urandom(60 * 1024), None),
                ]
                replays = [(key, *message) for key, message in heard.items()]
                stop_at = time.monotonic() + FLOOD_SECONDS
                publishers = {
                    key: session.declare_publisher(
                        key, congestion_control=zenoh.CongestionControl.BLOCK
                    )
                    for key, _, _ in [*replays, *junk]
                }
                while time.monotonic() < stop_at and process.poll() is None:
                    for key, payload, attachment in [*replays * 20, *junk]:
                        publishers[key].put(payload, attachment=attachment)
                        sent[0] += 1
                for publisher in publishers.values():
                    publisher.undeclare()
                stdout, stderr = process.communicate(timeout=180)
        finally:
            for entity in declared:
                entity.undeclare()
            if process.poll() is None:
                process.kill()
                process.communicate()
            kill_leftovers(run_id)
    said = stderr.decode()
    assert "Traceback" not in said, said[-3000:]
    summary = json.loads(stdout)
    assert sent[0] > 1000
    assert set(peaks) == set(CAP_ROWS), peaks
    over = {role: round(peak) for role, peak in peaks.items() if peak > caps[role]}
    assert over == {}, f"over the caps of docs/security.md ({caps}): {over}"
    # The flood was taken in and refused, not believed: the run ended as runs end.
    assert summary["ended"] in ("consensus", "split", "timeout", "stalled"), summary["ended"]
    assert summary["rejected"]["observer"] > 0 and summary["rejected"]["world"] > 0
