"""How much memory a flooded run takes, process by process, against the caps that
docs/security.md states.

A live ``swarm run`` (10 robots hosted in one robot process, 10 sites, seed 3, recorded)
on a Zenoh router this benchmark starts (``swarm router``, loopback TCP), with an
attacker's session on that router that holds no keys: the place of any client of the
run's router. The robots stay in one process (``--robots-per-process 10``; the default
is a process per robot up to 25 robots), as when the figures of
docs/security.md were first measured, so that they compare and the batch path (sealed
by the host identity) is the one flooded. The attacker
hears the run's authentic messages and, from ``--flood-at`` sim seconds on, sends copies
of them back on their own keys as fast as Zenoh takes them, for ``--flood-for`` wall
seconds, then lets the run end. Each process's peak resident set (VmHWM) is read from
/proc until it exits. Cases:

* ``clean``: no flood (what each process takes anyway);
* ``replayed-acts-realtime`` (case 4 of docs/security.md): ``--clock realtime``, old
  acts and radio transmissions replayed (the freshness checks of
  world_server/core/intake.py and bestofn_swarm/wire/guard.py refuse them);
* ``replayed-acts-statuses``: lockstep, old acts and statuses replayed;
* ``empty``: empty messages on the acts' and statuses' keys;
* ``junk-1mb``: 1 MiB of random bytes on the status keys;
* ``junk-largest``: the largest junk each process still takes in before it drops it: a
  4 MiB "batch of acts" for the world, 1 MiB on a camera key for the recorder, 60 KiB on
  the status keys for the launcher.

It also prints what one queued message holds beyond its bytes in each inbox there is
(tracemalloc), the overhead ``bestofn_swarm.plumbing.inbox`` charges for, and (``--fill``) what an
inbox filled to its cap with small messages adds to a process's resident set, charged as now
and as without the per-message overhead (payload and attachment only): a flood only fills
an inbox when its process falls behind, which on a given machine it may not, so this is
the bound a flood reaches at worst. The world server has no inbox (each Zenoh callback
hands its input to the coordinator at once, under one lock): there is none of its to
fill or measure, and the benchmark says so.

    .venv/bin/python benchmarks/flood_memory.py                    # every case
    .venv/bin/python benchmarks/flood_memory.py --cases clean empty --flood-for 10
    .venv/bin/python benchmarks/flood_memory.py --fill --cases    # only the inboxes filled
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import zenoh  # noqa: E402

from bestofn_swarm.plumbing import inbox as inbox_module  # noqa: E402
from bestofn_swarm.plumbing.tcp import free_port  # noqa: E402
from bestofn_swarm.plumbing.zenoh_session import open_session  # noqa: E402
from bestofn_swarm.wire import batch, keyspace, protocol  # noqa: E402
from deploy.launcher.supervisor import RUN_ID_ENV  # noqa: E402

CASES = (
    "clean",
    "replayed-acts-realtime",
    "replayed-acts-statuses",
    "empty",
    "junk-1mb",
    "junk-largest",
)
MIB = 2**20


@dataclass
class Captured:
    """Authentic messages heard, by key, to replay (the last few of each key)."""

    messages: dict[str, list[tuple[bytes, bytes | None]]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    tick: int = 0

    def keep(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        with self.lock:
            kept = self.messages.setdefault(key, [])
            kept.append((payload, attachment))
            del kept[:-20]

    def snapshot(self) -> list[tuple[str, bytes, bytes | None]]:
        with self.lock:
            return [(k, p, a) for k, kept in self.messages.items() for p, a in kept]


def role_of(pid: int) -> str | None:
    """Which process of the run ``pid`` is, from its command line (a forked robot has
    its fork server's, and the fork server is its parent)."""
    cmdline = _cmdline(pid)
    if "forkserver" in cmdline:
        try:
            parent = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            return None
        return "robots" if "forkserver" in _cmdline(parent) else "fork server"
    for needle, role in (
        ("world_server.server", "world"),
        ("world_server.recorder", "recorder"),
        ("nest_beacon", "beacon"),
        ("robot_agent", "robots"),
        ("deploy.cli run", "launcher"),
    ):
        if needle in cmdline:
            return role
    return None


def run_pids(run_id: str) -> list[int]:
    found = []
    marker = f"{RUN_ID_ENV}={run_id}".encode()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes()
            environ = (entry / "environ").read_bytes()
        except OSError:
            continue
        if run_id.encode() in cmdline or marker in environ.split(b"\0"):
            found.append(int(entry.name))
    return found


def peak_kib(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


class PeakWatch:
    """Reads every process's VmHWM of the run (and the router's) until stopped."""

    def __init__(self, run_id: str, router_pid: int) -> None:
        self.run_id = run_id
        self.router_pid = router_pid
        self.peaks: dict[int, tuple[str, int]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(0.2):
            pids = {pid: role_of(pid) for pid in run_pids(self.run_id)}
            pids[self.router_pid] = "router"
            for pid, role in pids.items():
                if role is None:
                    continue
                kib = peak_kib(pid)
                if kib is not None:
                    self.peaks[pid] = (role, max(kib, self.peaks.get(pid, (role, 0))[1]))

    def stop(self) -> dict[str, float]:
        """Peak RSS in MB per role (the largest robot process for ``robots``)."""
        self._stop.set()
        self._thread.join()
        by_role: dict[str, float] = {}
        for role, kib in self.peaks.values():
            by_role[role] = max(by_role.get(role, 0.0), kib / 1024)
        return by_role


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except (OSError, UnicodeDecodeError):
        return ""


def flood(
    session: zenoh.Session,
    messages: Callable[[], list[tuple[str, bytes, bytes | None]]],
    seconds: float,
) -> int:
    """Put ``messages()`` round and round for ``seconds``; how many were put."""
    publishers: dict[str, Any] = {}
    sent = 0
    deadline = time.monotonic() + seconds
    batch = messages()
    while time.monotonic() < deadline:
        for key, payload, attachment in batch:
            publisher = publishers.get(key)
            if publisher is None:
                publisher = publishers[key] = session.declare_publisher(
                    key, congestion_control=zenoh.CongestionControl.BLOCK
                )
            publisher.put(payload, attachment=attachment)
            sent += 1
        if time.monotonic() >= deadline:
            break
    for publisher in publishers.values():
        publisher.undeclare()
    return sent


def flood_from(
    endpoint: str,
    messages: Callable[[], list[tuple[str, bytes, bytes | None]]],
    seconds: float,
    flooders: int,
) -> int:
    """``flood`` from ``flooders`` threads, each with a session of its own."""
    counts: list[int] = []

    def one() -> None:
        with open_session("client", [endpoint]) as session:
            counts.append(flood(session, messages, seconds))

    threads = [threading.Thread(target=one) for _ in range(flooders)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return sum(counts)


def run_case(case: str, args: argparse.Namespace, workdir: Path) -> dict[str, Any]:
    run_id = f"flood-{uuid.uuid4().hex[:8]}"
    keys = keyspace.Keys(run_id)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen(
        [sys.executable, "-m", "deploy.cli", "router", "--listen", endpoint],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with (
            contextlib.suppress(OSError),
            __import__("socket").create_connection(("127.0.0.1", port), timeout=0.5),
        ):
            break
        time.sleep(0.1)
    clock = ["--clock", "realtime", "--speed", "4"] if case.endswith("realtime") else []
    command = [
        *(sys.executable, "-m", "deploy.cli", "run", "--run-id", run_id, "--json", "--quiet"),
        *("--robots", "10", "--sites", "10", "--seed", str(args.seed)),
        *("--robots-per-process", "10"),
        *("--connect", endpoint, "--record", str(workdir / f"{case}.mcap")),
        *("--wall-timeout", str(args.wall_timeout), *clock),
    ]
    session = open_session("client", [endpoint])
    captured = Captured()
    subscribers = []

    def hear(sample: zenoh.Sample) -> None:
        attachment = sample.attachment
        captured.keep(
            str(sample.key_expr),
            sample.payload.to_bytes(),
            attachment.to_bytes() if attachment is not None else None,
        )

    def on_clock(sample: zenoh.Sample) -> None:
        with contextlib.suppress(protocol.ProtocolError):
            captured.tick = protocol.decode(sample.payload.to_bytes(), protocol.Clock).tick

    replayed = {
        "replayed-acts-realtime": [
            keys.of(keyspace.ACT, "*"),
            keys.of(keyspace.HOST_ACT, "*"),
            keys.of(keyspace.RADIO_TX, "*"),
        ],
        "replayed-acts-statuses": [
            keys.of(keyspace.ACT, "*"),
            keys.of(keyspace.HOST_ACT, "*"),
            keys.of(keyspace.STATUS, "*"),
        ],
        "empty": [
            keys.of(keyspace.ACT, "*"),
            keys.of(keyspace.HOST_ACT, "*"),
            keys.of(keyspace.STATUS, "*"),
        ],
        "junk-1mb": [keys.of(keyspace.STATUS, "*")],
    }.get(case, [])
    for key in replayed:
        subscribers.append(session.declare_subscriber(key, hear))
    subscribers.append(session.declare_subscriber(keys.of(keyspace.CLOCK), on_clock))
    launcher = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    watch = PeakWatch(run_id, router.pid)
    sent = 0
    flooded_for = 0.0
    try:
        flood_tick = round(args.flood_at / 0.1)
        while launcher.poll() is None and captured.tick < flood_tick:
            time.sleep(0.05)
        if launcher.poll() is None and case != "clean":
            if case == "empty":

                def messages() -> list[tuple[str, bytes, bytes | None]]:
                    return [(key, b"", None) for key, _, _ in captured.snapshot()]

            elif case == "junk-1mb":
                junk = os.urandom(MIB)

                def messages() -> list[tuple[str, bytes, bytes | None]]:
                    return [(keys.of(keyspace.STATUS, robot), junk, None) for robot in range(10)]

            elif case == "junk-largest":
                largest: list[tuple[str, bytes, bytes | None]] = [
                    (keys.of(keyspace.HOST_ACT, 0), os.urandom(batch.MAX_BATCH_BYTES), None),
                    (
                        keys.of(keyspace.CAMERA, 0),
                        os.urandom(protocol.MAX_CAMERA_FRAME_BYTES),
                        None,
                    ),
                    *(
                        (keys.of(keyspace.STATUS, robot), os.urandom(60 * 1024), None)
                        for robot in range(10)
                    ),
                ]

                def messages() -> list[tuple[str, bytes, bytes | None]]:
                    return largest

            else:
                messages = captured.snapshot
            started = time.monotonic()
            sent = flood_from(endpoint, messages, args.flood_for, args.flooders)
            flooded_for = time.monotonic() - started
        stdout, stderr = launcher.communicate(timeout=args.wall_timeout + 120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.communicate()
        peaks = watch.stop()
        for subscriber in subscribers:
            subscriber.undeclare()
        session.close()
        for pid in run_pids(run_id):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        router.terminate()
        try:
            router.wait(timeout=10)
        except subprocess.TimeoutExpired:
            router.kill()
            router.wait()
    text = stdout.decode().strip()
    summary = json.loads(text) if text else None
    if summary is None:
        print(stderr.decode()[-3000:], file=sys.stderr)
    return {
        "case": case,
        "sent": sent,
        "flooded_s": round(flooded_for, 1),
        "peaks_mb": {role: round(mb, 1) for role, mb in sorted(peaks.items())},
        "exit": launcher.returncode,
        "summary": summary,
    }


def per_robot(summary: dict[str, Any] | None) -> list[tuple[Any, ...]] | None:
    if summary is None:
        return None
    return [
        (robot["id"], robot["decided_site"], robot["decision_time_s"])
        for robot in summary["per_robot"]
    ]


def queued_overheads() -> dict[str, float]:
    """Bytes one queued message holds beyond its payload, attachment and key, per inbox
    (the world has none: ``NO_INBOX``)."""
    from deploy.launcher.follower import Heard
    from nest_beacon.node.beacon_node import Event as BeaconEvent
    from robot_agent.node.robot_node import Event as RobotEvent
    from world_server.recording.writer import Sample

    key = "bestofn/flood-0000/robot/7/act"
    makers: dict[str, Callable[[bytes, bytes], Any]] = {
        "recorder": lambda p, a: Sample(key[:-1] + "t", p, a, time.time_ns()),
        "launcher": lambda p, a: Heard(keyspace.STATUS, key[:-1] + "t", p, a),
        "robot": lambda p, a: RobotEvent(1, keyspace.RADIO_RX, p, a),
        "beacon": lambda p, a: BeaconEvent(keyspace.BEACON_CLOCK, p, a),
    }
    found = {}
    for name, make in makers.items():
        held: queue.SimpleQueue[tuple[int, Any]] = queue.SimpleQueue()
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(20_000):
            held.put((0, make(os.urandom(120), os.urandom(16))))
        grown = tracemalloc.get_traced_memory()[0] - before
        tracemalloc.stop()
        keyed = len(key) if name in ("recorder", "launcher") else 0
        found[name] = grown / 20_000 - 136 - keyed
    return found


# Why the world is not among the inboxes measured or filled: it has none.
NO_INBOX = (
    "the world server has no inbox: each Zenoh callback hands its input to the "
    "coordinator at once, under one lock, so there is none to measure or fill"
)
FILLED = {  # the inboxes a flood can fill: their caps, and a small message of each
    "recorder": ("world_server.recorder.recorder_process", "INBOX_BYTES", "robot/3/status", 300),
    "launcher": ("deploy.launcher.launcher", "EVENTS_BYTES", "robot/3/status", 300),
}


def fill_one(process: str, charged_as: str) -> None:
    """In a process of its own: fill ``process``'s inbox to its cap with small messages
    (an authentic-sized payload and a 16-byte tag), charged ``as now`` or ``as before``;
    print the messages it took and what the resident set grew by."""
    import importlib

    module, cap_name, leaf, payload_bytes = FILLED[process]
    cap = getattr(importlib.import_module(module), cap_name)
    if charged_as == "before":
        inbox_module.ITEM_OVERHEAD_BYTES = 0
    inbox: Any = inbox_module.BoundedInbox(cap)
    key = f"bestofn/flood-00000000/{leaf}"
    from deploy.launcher.follower import Heard
    from world_server.recording.writer import Sample

    def queued(key: str, payload: bytes, tag: bytes) -> Any:
        """What the process's Zenoh callback queues for such a message."""
        if process == "recorder":
            return Sample(key, payload, tag, time.time_ns())
        return Heard(keyspace.STATUS, key, payload, tag)

    def rss_mb() -> float:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return 0.0

    before = rss_mb()
    held = 0
    while True:
        payload, tag = os.urandom(payload_bytes), os.urandom(16)
        copied = (key + " ")[:-1]  # a new string per message, as str(sample.key_expr) makes
        size = payload_bytes + 16 + (len(copied) if charged_as == "now" else 0)
        if not inbox.put(queued(copied, payload, tag), size):
            break
        held += 1
    print(json.dumps({"held": held, "grew_mb": round(rss_mb() - before, 1), "cap": cap}))


def fill_all() -> None:
    print("An inbox filled to its cap with small messages (a fresh process each):")
    print(f"  {NO_INBOX}")
    for process in FILLED:
        for charged_as in ("before", "now"):
            done = subprocess.run(
                [sys.executable, __file__, "--fill-one", process, charged_as],
                capture_output=True,
                check=True,
                cwd=REPO,
            )
            result = json.loads(done.stdout)
            print(
                f"  {process:9s} cap {result['cap'] / MIB:4.0f} MiB, charged as {charged_as}: "
                f"{result['held']:>9,} messages, resident set +{result['grew_mb']:.0f} MB",
                flush=True,
            )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="*", choices=CASES, default=list(CASES))
    parser.add_argument("--fill", action="store_true", help="fill each inbox to its cap too")
    parser.add_argument("--fill-one", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--flood-at", type=float, default=10.0, help="sim seconds")
    parser.add_argument("--flood-for", type=float, default=60.0, help="wall seconds")
    parser.add_argument("--flooders", type=int, default=3, help="threads, a session each")
    parser.add_argument("--wall-timeout", type=float, default=600.0)
    parser.add_argument("--out", type=Path, help="also write the results as JSON here")
    args = parser.parse_args()
    if args.fill_one:
        fill_one(*args.fill_one)
        return 0
    charged = getattr(inbox_module, "ITEM_OVERHEAD_BYTES", 0)  # 0 in older checkouts
    print(f"charged per queued message: {charged} bytes + its bytes")
    for name, bytes_ in queued_overheads().items():
        print(f"  measured in the {name}'s inbox: {bytes_:.0f} bytes beyond its bytes")
    print(f"  {NO_INBOX}")
    if args.fill:
        fill_all()
    results = []
    with tempfile.TemporaryDirectory() as work:
        for case in args.cases:
            result = run_case(case, args, Path(work))
            results.append(result)
            summary = result["summary"] or {}
            print(
                f"{case}: sent {result['sent']:,} in {result['flooded_s']} s; exit "
                f"{result['exit']}, ended {summary.get('ended')}, sim "
                f"{summary.get('sim_time_s')} s, rejected {summary.get('rejected')}, "
                f"stalls {summary.get('world', {}).get('stalls')}",
                flush=True,
            )
            print(f"  peak RSS MB: {result['peaks_mb']}", flush=True)
    clean = next((r for r in results if r["case"] == "clean"), None)
    if clean is not None:
        for result in results:
            same = per_robot(result["summary"]) == per_robot(clean["summary"])
            print(f"{result['case']}: same per-robot results as clean: {same}")
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
