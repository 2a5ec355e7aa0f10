"""The UDP radio: framing, loopback exchange, bad datagrams, the worked example, and a
swarm of controllers in separate network namespaces (root only)."""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from netns import UDP_SUBNET, Lan, lan_address, namespaces

from bestofn_swarm.wire import protocol
from examples.udp_radio import (
    MAX_DATAGRAM_BYTES,
    MAX_RADIO_PAYLOAD_BYTES,
    FrameError,
    FrameTooLargeError,
    UdpRadio,
    decode_frame,
    encode_frame,
)
from robot_agent.core import ports

TESTS = Path(__file__).resolve().parent
NODE = TESTS / "udp_swarm_node.py"
EXAMPLES = TESTS.parent / "examples"
LOOPBACK = "127.0.0.1"
OPINION = protocol.OpinionPayload(v=1, id=3, trip=2, decided=False, opinion=[0.5, 0.25, 0.25, 0.0])
BEACON = protocol.BeaconPayload(v=1, id="nest", seq=7)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((LOOPBACK, 0))
        return probe.getsockname()[1]


def poll_until(radio: UdpRadio, count: int, timeout: float = 5.0) -> list[tuple[str, bytes]]:
    """Poll until ``count`` frames have arrived (or the timeout passes)."""
    received: list[tuple[str, bytes]] = []
    deadline = time.monotonic() + timeout
    while len(received) < count and time.monotonic() < deadline:
        select.select([radio], [], [], 0.05)
        received += radio.poll()
    return received


# --- framing -----------------------------------------------------------------------------


def test_frame_layout_is_magic_version_sender_length_sender_payload() -> None:
    assert encode_frame("12", b"{}") == b"BN\x01\x0212{}"
    assert decode_frame(b'BN\x01\x04nest{"a":1}') == ("nest", b'{"a":1}')
    longest = encode_frame("n" * 64, b"x" * MAX_RADIO_PAYLOAD_BYTES)
    assert len(longest) == MAX_DATAGRAM_BYTES == 2116
    assert decode_frame(longest) == ("n" * 64, b"x" * MAX_RADIO_PAYLOAD_BYTES)


@pytest.mark.parametrize(
    ("sender", "payload", "error"),
    [
        ("", b"{}", FrameError),
        ("a b", b"{}", FrameError),
        ("é", b"{}", FrameError),
        ("n" * 65, b"{}", FrameError),
        ("1", b"", FrameError),
        ("1", b"x" * (MAX_RADIO_PAYLOAD_BYTES + 1), FrameTooLargeError),
    ],
)
def test_encode_frame_refuses_what_receivers_would_drop(
    sender: str, payload: bytes, error: type[FrameError]
) -> None:
    with pytest.raises(error):
        encode_frame(sender, payload)


# --- two radios on this host ---------------------------------------------------------------


@pytest.mark.timeout(20)
@pytest.mark.parametrize("address", ["239.255.77.77", "127.255.255.255"])
def test_radios_exchange_opinion_and_beacon_payloads(address: str) -> None:
    port = free_udp_port()
    options: dict[str, Any] = {"address": address, "port": port, "interface": LOOPBACK}
    with (
        UdpRadio("3", **options) as robot,
        UdpRadio("nest", **options) as beacon,
        UdpRadio("5", **options) as listener,
    ):
        robot.send(protocol.encode(OPINION))
        beacon.send(protocol.encode(BEACON))
        heard = poll_until(listener, 2)
        assert sorted(heard) == [("3", protocol.encode(OPINION)), ("nest", protocol.encode(BEACON))]
        rejects = ports.RejectCounter()
        decoded = ports.decode_received(heard, rejects)
        by_sender = {item.sender: item.payload for item in decoded}
        assert by_sender == {"3": OPINION, "nest": BEACON}
        assert rejects.count == 0
        # The robot hears the beacon but not itself; its own datagram came back and was skipped.
        assert poll_until(robot, 1) == [("nest", protocol.encode(BEACON))]
        deadline = time.monotonic() + 5.0
        while robot.stats.own_echoes < 1 and time.monotonic() < deadline:
            assert robot.poll() == []
        assert robot.stats.own_echoes == 1
        assert robot.stats.sent == 1 and robot.stats.received == 1
        assert listener.stats.received == 2 and listener.stats.dropped == 0


@pytest.mark.timeout(20)
def test_bad_datagrams_are_counted_and_dropped_never_raised() -> None:
    port = free_udp_port()
    malformed = [
        b"",  # empty datagram
        b"BN\x01",  # shorter than the header
        b"XX\x01\x011{}",  # bad magic
        b"BN\x02\x011{}",  # unknown frame version
        b"BN\x01\x00{}",  # empty sender
        b"BN\x01\x05ab{}",  # sender length beyond the datagram
        b"BN\x01\x03a b{}",  # space in the sender name
        b"BN\x01\x011",  # no payload
    ]
    oversize = [
        b"BN\x01\x011" + b"x" * (MAX_RADIO_PAYLOAD_BYTES + 1),  # payload over the limit
        b"x" * 4000,  # datagram over MAX_DATAGRAM_BYTES
    ]
    good = encode_frame("4", protocol.encode(OPINION))
    not_a_message = encode_frame("6", b'{"kind":"opinion","v":1}')  # a frame, a bad payload
    with (
        UdpRadio("1", port=port, interface=LOOPBACK) as radio,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw,
    ):
        raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(LOOPBACK))
        for datagram in [*malformed, *oversize, not_a_message, good]:
            raw.sendto(datagram, (radio.address, port))
        heard = poll_until(radio, 2)
        assert heard == [("6", b'{"kind":"opinion","v":1}'), ("4", protocol.encode(OPINION))]
        assert radio.stats.malformed == len(malformed)
        assert radio.stats.oversize == len(oversize)
        # The radio only checks frames; payloads are the protocol's job, as on Zenoh.
        rejects = ports.RejectCounter()
        assert [item.sender for item in ports.decode_received(heard, rejects)] == ["4"]
        assert rejects.count == 1


@pytest.mark.timeout(20)
def test_send_takes_payloads_up_to_2048_bytes_and_refuses_larger() -> None:
    port = free_udp_port()
    largest = b"y" * MAX_RADIO_PAYLOAD_BYTES
    with (
        UdpRadio("1", port=port, interface=LOOPBACK) as sender,
        UdpRadio("2", port=port, interface=LOOPBACK) as receiver,
    ):
        sender.send(largest)
        with pytest.raises(FrameTooLargeError):
            sender.send(largest + b"y")
        with pytest.raises(FrameError):
            sender.send(b"")
        assert poll_until(receiver, 1) == [("1", largest)]
        assert sender.stats.sent == 1 and sender.stats.send_failures == 0


@pytest.mark.timeout(20)
def test_one_poll_takes_at_most_max_per_poll_datagrams() -> None:
    port = free_udp_port()
    with (
        UdpRadio("1", port=port, interface=LOOPBACK) as sender,
        UdpRadio("2", port=port, interface=LOOPBACK, max_per_poll=2) as receiver,
    ):
        for seq in range(5):
            sender.send(protocol.encode(protocol.BeaconPayload(v=1, id="b", seq=seq)))
        batches: list[list[tuple[str, bytes]]] = []
        deadline = time.monotonic() + 5.0
        while sum(map(len, batches)) < 5 and time.monotonic() < deadline:
            select.select([receiver], [], [], 0.05)
            batches.append(receiver.poll())
        assert all(len(batch) <= 2 for batch in batches)
        beacons = [protocol.decode_radio(p) for batch in batches for _, p in batch]
        sequence = [b.seq for b in beacons if isinstance(b, protocol.BeaconPayload)]
        assert sequence == [0, 1, 2, 3, 4]  # one sender's datagrams keep their order
        assert receiver.poll() == []  # nothing left, and an empty poll returns at once


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("a/b", {}, "sender"),
        ("1", {"port": 0}, "port"),
        ("1", {"ttl": 0}, "ttl"),
        ("1", {"max_per_poll": 0}, "max_per_poll"),
        ("1", {"address": "robots.local"}, "IPv4"),
        ("1", {"address": "255.255.255.255", "interface": "lo"}, "broadcast mode"),
        ("1", {"interface": "no-such-if0"}, "no network interface"),
    ],
)
def test_bad_options_are_refused_with_a_reason(
    name: str, options: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        UdpRadio(name, **options)


# --- processes ---------------------------------------------------------------------------


@dataclass
class Processes:
    """Child processes that are always killed, by pid, whatever happens."""

    started: list[subprocess.Popen[str]] = field(default_factory=list)

    def start(self, command: Sequence[str]) -> subprocess.Popen[str]:
        process = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=TESTS.parent,
        )
        self.started.append(process)
        return process

    def kill_all(self) -> None:
        for process in self.started:
            if process.poll() is None:
                os.kill(process.pid, signal.SIGKILL)
            process.wait(timeout=10)


def read_ready(processes: Sequence[subprocess.Popen[str]], timeout: float) -> None:
    """Wait for every process's ``ready`` line (the handshake of udp_swarm_node.py)."""
    deadline = time.monotonic() + timeout
    for process in processes:
        assert process.stdout is not None
        readable, _, _ = select.select([process.stdout], [], [], deadline - time.monotonic())
        line = process.stdout.readline() if readable else ""
        if line.strip() != "ready":
            process.kill()
            _, errors = process.communicate(timeout=10)
            pytest.fail(f"{process.args!r} did not get ready: {line!r} {errors}")


def start_all(processes: Sequence[subprocess.Popen[str]], delay: float = 0.3) -> None:
    start = f"{time.time() + delay}\n"
    for process in processes:
        assert process.stdin is not None
        process.stdin.write(start)
        process.stdin.flush()


def summary_of(process: subprocess.Popen[str], timeout: float) -> tuple[dict[str, Any], str]:
    """The JSON summary a process prints last, and what it wrote on stderr."""
    output, errors = process.communicate(timeout=timeout)
    assert process.returncode == 0, f"{process.args!r} failed:\n{errors}"
    return json.loads(output.strip().splitlines()[-1]), errors


@pytest.mark.timeout(90)
def test_worked_example_robots_decide_over_udp() -> None:
    """examples/udp_robot.py and udp_beacon.py, as documented, as a small swarm on this host."""
    port = free_udp_port()
    qualities = [0.25, 1.0, 0.5, 0.0]
    common = ["--port", str(port), "--interface", LOOPBACK, "--speed", "20"]
    processes = Processes()
    try:
        beacon = processes.start([sys.executable, str(EXAMPLES / "udp_beacon.py"), *common])
        start_at = time.time() + 3.0  # robots import numpy and OpenCV first
        robots = [
            processes.start(
                [
                    sys.executable,
                    str(EXAMPLES / "udp_robot.py"),
                    "--id",
                    str(robot),
                    "--robots",
                    "3",
                    "--qualities",
                    ",".join(map(str, qualities)),
                    *common,
                    "--start-at",
                    str(start_at),
                    "--max-seconds",
                    "400",
                ]
            )
            for robot in range(3)
        ]
        summaries = [summary_of(robot, timeout=60)[0] for robot in robots]
        beacon.send_signal(signal.SIGTERM)
        beacon_summary, _ = summary_of(beacon, timeout=10)
    finally:
        processes.kill_all()
    for summary in summaries:
        assert summary["phase"] == "stopped", summaries
        assert summary["decided_site"] == qualities.index(max(qualities))
        assert summary["rejected_payloads"] == 0
        radio = summary["radio"]
        assert radio["sent"] > 0 and radio["received"] > 0
        assert radio["malformed"] == radio["oversize"] == radio["send_failures"] == 0
    assert beacon_summary["transmissions"] == beacon_summary["radio"]["sent"] > 0


# --- network namespaces ------------------------------------------------------------------


@pytest.fixture(scope="module")
def lan() -> Iterator[Lan]:
    with namespaces("bon", 3, UDP_SUBNET) as network:
        yield network


def node(lan: Lan, index: int, *args: str) -> list[str]:
    return lan.run(index, sys.executable, str(NODE), *args)


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ("address", "interfaces"),
    [
        # Multicast, the interface chosen by name, by address, and by the route.
        ("239.255.77.77", ["eth0", lan_address(1), None]),
        ("10.77.0.255", [lan_address(index) for index in range(3)]),  # subnet broadcast
        ("255.255.255.255", [lan_address(index) for index in range(3)]),  # limited broadcast
    ],
)
def test_every_namespace_hears_every_other(
    lan: Lan, address: str, interfaces: list[str | None]
) -> None:
    processes = Processes()
    try:
        talkers = []
        for index, interface in enumerate(interfaces):
            options = ["--address", address, "--speed", "20", "--max-sim", "10"]
            if interface is not None:
                options += ["--interface", interface]
            talkers.append(
                processes.start(node(lan, index, *options, "hello", "--name", f"n{index}"))
            )
        read_ready(talkers, timeout=30)
        start_all(talkers)
        summaries = [summary_of(talker, timeout=30)[0] for talker in talkers]
    finally:
        processes.kill_all()
    for index, summary in enumerate(summaries):
        others = {f"n{other}" for other in range(lan.size) if other != index}
        assert summary["heard"] == dict.fromkeys(others, 5), summary
        assert summary["local_address"] == [lan_address(index), summary["local_address"][1]]
        radio = summary["radio"]
        assert radio["own_echoes"] == radio["sent"] == 5
        assert radio["malformed"] == radio["oversize"] == 0


@pytest.mark.timeout(90)
def test_controllers_in_separate_namespaces_pool_opinions_and_decide(lan: Lan) -> None:
    """The Section 5 controller in one process per namespace, over UDP multicast only."""
    sites, seed = 4, 0
    interfaces = ["eth0", lan_address(1), None]
    processes = Processes()
    try:
        beacon = processes.start(
            node(lan, 0, "--interface", lan_address(0), "--seed", str(seed), "beacon")
        )
        robots = []
        for index, interface in enumerate(interfaces):
            options = ["--seed", str(seed)]
            if interface is not None:
                options += ["--interface", interface]
            robots.append(
                processes.start(
                    node(
                        lan,
                        index,
                        *options,
                        "robot",
                        "--id",
                        str(index),
                        "--robots",
                        str(lan.size),
                        "--sites",
                        str(sites),
                        "--dwell",
                        "5",
                    )
                )
            )
        read_ready([beacon, *robots], timeout=30)
        start_all([beacon, *robots])
        results = [summary_of(robot, timeout=60) for robot in robots]
        beacon.send_signal(signal.SIGTERM)
        beacon_summary, _ = summary_of(beacon, timeout=10)
    finally:
        processes.kill_all()
    summaries = [summary for summary, _ in results]
    traces = "\n".join(trace for _, trace in results)  # phase changes, for failure messages
    for index, summary in enumerate(summaries):
        # Opinions crossed the namespaces: each robot heard every other one.
        others = {str(other) for other in range(lan.size) if other != index}
        assert set(summary["opinion_senders"]) == others, (summary, traces)
        assert summary["beacons_heard"] > 0 and summary["beacons_out_of_range"] > 0
        assert summary["phase"] == "stopped", (summaries, traces)
        assert summary["decided_site"] == summary["best_site"], (summaries, traces)
        assert summary["rejected_payloads"] == 0
        radio = summary["radio"]
        assert radio["malformed"] == radio["oversize"] == radio["send_failures"] == 0
    # And the controllers pooled what they heard: some pool held more than the robot itself.
    pooled = [size for summary in summaries for size in summary["pool_sizes"]]
    assert max(pooled) > 1, (summaries, traces)
    assert beacon_summary["radio"]["sent"] > 0


# One send per line on stdin, the counts after it on stdout.
SEND_PER_LINE = """
import dataclasses, json, sys
from examples.udp_radio import UdpRadio
with UdpRadio("1", interface=sys.argv[1]) as radio:
    for _ in sys.stdin:
        radio.send(b'{"kind":"beacon","v":1,"id":"x","seq":0}')
        print(json.dumps(dataclasses.asdict(radio.stats)), flush=True)
"""


@pytest.mark.timeout(60)
def test_a_link_going_down_costs_broadcasts_not_the_robot(lan: Lan) -> None:
    ns, address = lan.robot_ns(2), lan_address(2)

    def set_link(state: str) -> None:
        subprocess.run(["ip", "-n", ns, "link", "set", "eth0", state], check=True, timeout=10)

    processes = Processes()
    try:
        sender = processes.start(lan.run(2, sys.executable, "-c", SEND_PER_LINE, address))
        to_sender, from_sender = sender.stdin, sender.stdout
        assert to_sender is not None and from_sender is not None

        def send() -> dict[str, int]:
            to_sender.write("\n")
            to_sender.flush()
            readable, _, _ = select.select([from_sender], [], [], 30)
            assert readable, "the sender did not answer"
            return dict(json.loads(from_sender.readline()))

        assert send()["sent"] == 1
        set_link("down")
        assert send() == {
            "sent": 1,
            "send_failures": 1,
            "received": 0,
            "own_echoes": 0,
            "malformed": 0,
            "oversize": 0,
        }
        set_link("up")
        assert send()["sent"] == 2
        to_sender.close()
        assert sender.wait(timeout=30) == 0
    finally:
        processes.kill_all()
        # Taking the link down dropped its routes; put the multicast route back.
        subprocess.run(
            ["ip", "-n", ns, "route", "replace", "224.0.0.0/4", "dev", "eth0"],
            check=True,
            timeout=10,
        )
