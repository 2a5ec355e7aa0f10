"""Robots outside the emulator against live runs (``swarm run --external``), as the Python
program (``robot-agent --link``) and as the C robot (c_robot/): the same run bit for bit
over UDP and over serial lines, a map of 1000 sites on lines of 115200 baud, a robot that
never connects, one whose program is killed and restarted, a bridge that dies and is found
again, a link made worse on purpose in real time, an encrypted link (``--secure``), and
forged, replayed and oversized frames sent at a live link."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from outside_helpers import (
    Relay,
    c_robot_binary,
    decisions,
    in_process,
    outside_run,
    pty_pair,
    udp_link,
)
from swarm_helpers import processes_of

from bestofn_swarm.link.core import codec
from bestofn_swarm.wire import keyspace

pytestmark = pytest.mark.timeout(900)

SMALL = ["--robots", "4", "--sites", "3", "--timeout", "600", "--no-record"]
# The runs compared bit for bit with the all-emulated run: a world that waits long for a
# robot a busy machine starved stays in lockstep (a stall closes a tick without a robot,
# and the run is no longer the seed's, whatever the link).
PATIENT = ["--stall-timeout", "300"]
TEN = ["--robots", "10", "--timeout", "900", "--no-record", *PATIENT]


@pytest.fixture(scope="module")
def c_binary() -> Path | None:
    """The C robot (c_robot/), built for these tests; None without a C compiler."""
    return c_robot_binary()


@pytest.mark.parametrize("seed", [0, 3])
def test_a_python_and_a_c_robot_over_udp_decide_exactly_as_all_emulated(
    tmp_path: Path, c_binary: Path | None, seed: int
) -> None:
    """Lockstep: robot 8 runs as the Python program and robot 9 as the C program, outside,
    on their own clocks and sockets, and every robot's results (and the run's digest) equal
    those of the all-emulated run of the same seed."""
    options = [*TEN, "--seed", str(seed)]
    reference = in_process(options)
    address = udp_link()
    with outside_run(tmp_path, *options, "--external", "8,9", "--link", address) as run:
        run.start(address, 8)
        run.start_c(c_binary, address, 9)
        code, summary, stderr = run.finish(timeout=800)
        programs = run.program_summaries()
    assert code == 0, stderr
    assert summary is not None
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert summary["sim_time_s"] == reference["sim_time_s"]
    assert [r["outside"] for r in summary["per_robot"]] == [None] * 8 + ["udp", "udp"]
    assert summary["world"]["departures"] == 0
    links = summary["links"]
    assert set(links) == {"8", "9"}
    assert all(item["sessions"] == 1 and item["refused"] == 0 for item in links.values())
    assert all(item["rtt_ms"] is not None and item["loss"] == 0 for item in links.values())
    # Each program says how it ended: the bridge told it the run was over.
    decided = [robot["decided_site"] for robot in summary["per_robot"][8:]]
    assert [each["decided_site"] for each in programs] == decided
    assert all(each["sessions"] == 1 and each["refused"] == {} for each in programs)
    assert "robot-agent --link" in stderr and "--key-file" in stderr
    assert oct((tmp_path / "keys" / "robot-8.key").stat().st_mode & 0o777) == "0o600"


def test_a_python_and_a_c_robot_over_serial_lines_decide_exactly_as_all_emulated(
    tmp_path: Path, c_binary: Path | None
) -> None:
    """Robot 2 runs as the C program and robot 3 as the Python program, each on its own
    serial line (a pseudo-terminal pair), and the run is the all-emulated run's."""
    options = [*SMALL, *PATIENT, "--seed", "1"]
    reference = in_process(options)
    lines = [tmp_path / "c", tmp_path / "python"]
    for folder in lines:
        folder.mkdir()
    with pty_pair(lines[0]) as (c_bridge, c_robot), pty_pair(lines[1]) as (py_bridge, py_robot):
        served = ["--link", f"2=serial:{c_bridge}@921600", "--link", f"3=serial:{py_bridge}@921600"]
        with outside_run(tmp_path, *options, "--external", "2,3", *served) as run:
            run.start_c(c_binary, f"serial:{c_robot}@921600", 2)
            run.start(f"serial:{py_robot}@921600", 3)
            code, summary, stderr = run.finish(timeout=800)
    assert code == 0, stderr
    assert summary is not None
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert summary["world"]["departures"] == 0
    for robot in ("2", "3"):
        assert summary["links"][robot]["transport"] == "serial"
        assert summary["links"][robot]["refused"] == 0


def test_a_map_of_1000_sites_reaches_robots_on_serial_lines_at_115200_baud(
    tmp_path: Path, c_binary: Path | None
) -> None:
    """A map of 1000 sites is 57 KB: 5 s on a line of 115200 baud, longer than the 3 s of
    silence after which a session is gone. Robot 1 (the C program) and robot 2 (the Python
    one), each on its own line at 115200, get it in their first session (a frame under way
    is not silence, and the question is not asked again while it comes), and the run is the
    all-emulated run's. 3 s of sim time: the map, the proof of the world, 30 steps."""
    options = ["--robots", "3", "--sites", "1000", "--seed", "0", "--timeout", "3"]
    options += ["--no-record", *PATIENT]
    reference = in_process(options)
    lines = [tmp_path / "c", tmp_path / "python"]
    for folder in lines:
        folder.mkdir()
    with pty_pair(lines[0]) as (c_bridge, c_robot), pty_pair(lines[1]) as (py_bridge, py_robot):
        served = ["--link", f"1=serial:{c_bridge}@115200", "--link", f"2=serial:{py_bridge}@115200"]
        with outside_run(tmp_path, *options, "--external", "1,2", *served) as run:
            run.start_c(c_binary, f"serial:{c_robot}@115200", 1)
            run.start(f"serial:{py_robot}@115200", 2)
            code, summary, stderr = run.finish(timeout=300)
            programs = run.program_summaries()
    assert summary is not None, stderr
    assert (code, summary["ended"]) == (5, "timeout") == (5, reference["ended"]), stderr
    assert decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    assert summary["world"]["departures"] == 0
    for robot in ("1", "2"):
        assert summary["links"][robot]["sessions"] == 1, summary["links"]
        assert summary["links"][robot]["refused"] == 0
    assert [each["sessions"] for each in programs] == [1, 1]
    assert all(each["last_tick"] >= 29 and each["refused"] == {} for each in programs)


def test_an_outside_robot_that_never_connects_ends_the_run_naming_it(tmp_path: Path) -> None:
    address = udp_link()
    options = [*SMALL, "--external", "3", "--link", address, "--link-wait", "2"]
    with outside_run(tmp_path, *options) as run:
        code, summary, stderr = run.finish(timeout=120)
        run_id = run.run_id
    assert code == 1 and summary is None
    assert f"robot 3 on {address}" in stderr and "did not connect within 2 s" in stderr
    assert processes_of(run_id) == []


def test_a_killed_program_is_a_departure_and_its_restart_rejoins_and_decides(
    tmp_path: Path,
) -> None:
    address = udp_link()
    options = [*SMALL, "--seed", "0", "--external", "3", "--link", address]
    with outside_run(tmp_path, *options) as run, Relay.to(address) as relay:
        first = run.start(relay.address, 3)
        relay.wait_for(100)  # frames from the program: well into the run, far from its end
        first.kill()
        first.wait()
        run.start(relay.address, 3)
        code, summary, stderr = run.finish()
    assert code == 0, stderr
    assert summary is not None and summary["ended"] == "consensus"
    assert summary["world"]["departures"] >= 1  # the link went: the world saw it leave
    assert summary["links"]["3"]["sessions"] == 2
    assert summary["per_robot"][3]["decided_site"] == summary["chosen_site"]


def test_a_bridge_that_dies_is_started_again_and_its_robot_finds_it(tmp_path: Path) -> None:
    """In real time (a lockstep run this small would be over before the robot noticed)."""
    address = udp_link()
    options = [*SMALL, "--seed", "2", "--clock", "realtime", "--speed", "4"]
    options += ["--external", "3", "--link", address]
    with outside_run(tmp_path, *options) as run, Relay.to(address) as relay:
        started = run.start(relay.address, 3)
        relay.wait_for(100)
        bridges = [pid for pid in processes_of(run.run_id) if _is_bridge(pid)]
        assert len(bridges) == 1
        os.kill(bridges[0], signal.SIGKILL)
        code, summary, stderr = run.finish()
        (program,) = run.program_summaries()
    assert code == 0, stderr
    assert summary is not None and summary["ended"] == "consensus", stderr
    assert program["sessions"] == 2  # it said hello again until the new bridge answered
    assert summary["per_robot"][3]["decided_site"] == summary["chosen_site"]
    assert started.returncode == 0


def _is_bridge(pid: int) -> bool:
    try:
        return b"world_server.bridge" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


def test_a_real_time_swarm_with_a_bad_link_reaches_the_right_consensus(tmp_path: Path) -> None:
    """50 ms each way and 20% of the frames lost on the outside robot's link: the figures
    say so, and the swarm still decides for the best site."""
    address = udp_link()
    options = [*SMALL, "--seed", "0", "--clock", "realtime", "--speed", "2"]
    impaired = ["--link-delay", "50", "--link-loss", "0.2"]
    with outside_run(tmp_path, *options, *impaired, "--external", "3", "--link", address) as run:
        run.start(address, 3)
        code, summary, stderr = run.finish()
    assert code == 0, stderr
    assert summary is not None and summary["correct"]
    figures = summary["links"]["3"]
    assert figures["rtt_ms"] >= 100  # two delays of 50 ms
    assert 0 < figures["loss"] < 1 and figures["impaired"] > 0
    assert summary["config"]["link_delay"] == 50.0 and summary["config"]["link_loss"] == 0.2


def test_a_secure_run_encrypts_the_links_and_decides_as_all_emulated(
    tmp_path: Path, c_binary: Path | None
) -> None:
    """``--secure``: every frame of each session (robot 2 the C program, robot 3 the Python
    one) is ChaCha20-Poly1305 under its session key, and the run is the all-emulated run's."""
    options = [*SMALL, *PATIENT, "--seed", "1"]
    reference = in_process(options)
    address = udp_link()
    secure = ["--secure", "--external", "2,3", "--link", address]
    with (
        outside_run(tmp_path, *options, *secure) as run,
        Relay.to(address) as c_relay,
        Relay.to(address) as py_relay,
    ):
        run.start_c(c_binary, c_relay.address, 2)
        run.start(py_relay.address, 3)
        code, summary, stderr = run.finish()
        programs = run.program_summaries()
    assert code == 0, stderr
    assert summary is not None and decisions(summary) == decisions(reference)
    assert summary["digest"] == reference["digest"]
    for robot in ("2", "3"):  # the bridge's figures pass the access rules
        assert summary["links"][robot]["sessions"] == 1
        assert summary["links"][robot]["refused"] == 0
    assert all(each["refused"] == {} and each["sessions"] == 1 for each in programs)
    for relay in (c_relay, py_relay):
        sessions = [frame for frame in relay.captured if frame[3] != codec.FrameType.HELLO]
        assert sessions and all(frame[4] & codec.ENCRYPTED for frame in sessions)


def test_forged_replayed_and_oversized_frames_are_refused_counted_and_change_nothing(
    tmp_path: Path,
) -> None:
    options = [*SMALL, *PATIENT, "--seed", "3"]
    reference = in_process(options)
    address = udp_link()
    attacked = ["--external", "3", "--link", address]
    with outside_run(tmp_path, *options, *attacked) as run, Relay.to(address) as relay:
        run.start(relay.address, 3)
        relay.wait_for(60)
        captured = list(relay.captured)
        for frame in captured[:30]:  # the hello, acts, statuses, pongs: all seen before
            relay.inject(frame)
        last = bytearray(captured[-1])
        for position in range(40, 50):  # a bit changed in the body: the tag fails
            forged = bytearray(last)
            forged[position] ^= 0x01
            relay.inject(bytes(forged))
        for _ in range(5):  # a robot's frame is never this big
            relay.inject(bytes(last[: codec.HEADER_BYTES]) + bytes(40_000))
        code, summary, stderr = run.finish()
    assert code == 0, stderr
    assert summary is not None
    assert decisions(summary) == decisions(reference)
    refused = summary["links"]["3"]["refused_by"]
    assert refused["replayed"] >= 30 and refused["forged"] >= 10 and refused["oversize"] >= 5
    assert summary["world"]["departures"] == 0 and summary["links"]["3"]["sessions"] == 1


def test_a_mixed_run_is_recorded_reported_and_replayed_with_its_outside_robots(
    tmp_path: Path,
) -> None:
    from deploy.reports.collect import read_recording, rebuild_summary
    from deploy.reports.rows import run_summary
    from deploy.viewer.replay import ReplaySource, load

    path = tmp_path / "mixed.mcap"
    options = ["--robots", "3", "--sites", "3", "--seed", "0", "--record", str(path)]
    address = udp_link()
    with outside_run(tmp_path, *options, "--external", "2", "--link", address) as run:
        run.start(address, 2)
        code, summary, stderr = run.finish()
    assert code == 0, stderr
    assert summary is not None
    recording = read_recording(path)
    assert recording.complete and recording.messages[keyspace.LINK.name] > 0
    assert recording.messages.get("bestofn.RejectedSample", 0) == 0
    reported = run_summary(recording)
    assert reported["links"]["2"]["transport"] == "udp"
    rebuilt = rebuild_summary(recording)
    assert [robot["outside"] for robot in rebuilt["per_robot"]] == [None, None, "udp"]
    assert decisions(rebuilt) == decisions(summary)
    assert json.loads(recording.description["config"])["links"] == [f"2={address}"]
    replay = ReplaySource(load(path))
    replay.command({"op": "seek", "t": 10.0})
    frame = replay.frame()
    assert frame["links"]["2"]["transport"] == "udp"
