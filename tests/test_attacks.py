"""One well-formed message must not crash, stall or mislead a run: each attack of the trust
issue against a live ``swarm run``, by a test client on the run's router.

The run connects to a router the test holds (``--connect``), which puts the attacker
where any client of the run's router would be: it can put, query and declare liveliness
tokens on every key of the run, but holds none of the run's keys. Each test checks that
the run ends as it would without the attack, and that the attack was counted.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh
from mcap.reader import make_reader
from swarm_helpers import (
    REPO,
    kill_leftovers,
    loopback_router,
    processes_of,
    stop_processes,
    swarm_command,
    unique_run_id,
)

from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.plumbing.world_info import ask, fetch_world_info
from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from bestofn_swarm.wire.names import Role
from deploy.launcher.processes import python_module
from robot_agent.core import tick_assembly
from robot_agent.node import robot_node as node
from world_server.core.layout import make_layout

pytestmark = pytest.mark.timeout(180)

ROBOTS, SITES, SEED = 3, 4, 1
SMALL = ["--robots", str(ROBOTS), "--sites", str(SITES), "--seed", str(SEED), "--timeout", "600"]


@dataclass
class Attacked:
    """A live run and the attacker's session on its router."""

    run_id: str
    keys: keyspace.Keys
    session: zenoh.Session
    process: subprocess.Popen[bytes]
    ticks: list[int] = field(default_factory=list)

    @property
    def tick(self) -> int:
        return self.ticks[-1]

    def wait_for_tick(self, tick: int, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while (not self.ticks or self.ticks[-1] < tick) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert self.ticks and self.ticks[-1] >= tick, "the run never reached that tick"

    def finish(self, timeout: float = 120.0) -> tuple[int, dict[str, Any] | None, str]:
        stdout, stderr = self.process.communicate(timeout=timeout)
        text = stdout.decode().strip()
        return self.process.returncode, json.loads(text) if text else None, stderr.decode()


@contextmanager
def attacked_run(*options: str) -> Iterator[Attacked]:
    """``swarm run`` on a router the test holds, with the test's session on it."""
    run_id = unique_run_id("attack")
    keys = keyspace.Keys(run_id)
    with loopback_router() as (session, endpoint):
        command = swarm_command(
            "run", "--run-id", run_id, "--json", "--quiet", "--connect", endpoint, *options
        )
        process = subprocess.Popen(
            command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        attacked = Attacked(run_id, keys, session, process)

        def on_clock(sample: zenoh.Sample) -> None:
            with contextlib.suppress(protocol.ProtocolError):  # the attacker's own forgeries
                clock = protocol.decode(sample.payload.to_bytes(), protocol.Clock)
                attacked.ticks.append(clock.tick)

        subscriber = session.declare_subscriber(keys.of(keyspace.CLOCK), on_clock)
        try:
            yield attacked
        finally:
            subscriber.undeclare()
            if process.poll() is None:
                process.kill()
                process.communicate()
            kill_leftovers(run_id)


def best_site() -> int:
    return make_layout(SITES, ROBOTS, SEED).best_site


def wrong_site() -> int:
    return (best_site() + 1) % SITES


def one_hot(site: int, sender: int) -> bytes:
    opinion = [0.0] * SITES
    opinion[site] = 1.0
    return protocol.encode(
        protocol.OpinionPayload(v=1, id=sender, trip=1, decided=True, opinion=opinion)
    )


def assert_right_consensus(code: int, summary: dict[str, Any] | None, stderr: str) -> None:
    assert code == 0, stderr[-3000:]
    assert summary is not None
    assert summary["correct"], summary["per_robot"]
    assert [robot["decided_site"] for robot in summary["per_robot"]] == [best_site()] * ROBOTS
    assert "Traceback" not in stderr


def repeat_every_tick(attacked: Attacked, attack: Callable[[int], None]) -> threading.Event:
    """Call ``attack(tick)`` on every new tick until the returned event is set."""
    stop = threading.Event()

    def loop() -> None:
        seen = -1
        while not stop.is_set() and attacked.process.poll() is None:
            if attacked.ticks and attacked.ticks[-1] != seen:
                seen = attacked.ticks[-1]
                attack(seen)
            time.sleep(0.002)

    threading.Thread(target=loop, daemon=True).start()
    return stop


# --- crash ------------------------------------------------------------------------------


KEYED = pytest.mark.parametrize("keys", [[], ["--no-keys"]], ids=["keyed", "no-keys"])


@KEYED
def test_a_liveliness_token_of_a_robot_outside_the_swarm_is_refused(keys: list[str]) -> None:
    with attacked_run(*SMALL, "--no-record", *keys) as run:
        run.wait_for_tick(10)
        token = run.session.liveliness().declare_token(run.keys.token(Role.ROBOT, 99999))
        code, summary, stderr = run.finish()
        token.undeclare()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None and summary["rejected"]["world"] == 1


# --- stall ------------------------------------------------------------------------------


@KEYED
def test_a_forged_clock_far_in_the_future_does_not_silence_the_beacon(keys: list[str]) -> None:
    """Keyed, the clock lacks the world's tag; without keys, its time is not its tick's."""
    with attacked_run(*SMALL, "--no-record", *keys) as run:
        run.wait_for_tick(10)
        forged = protocol.Clock(v=1, tick=run.tick + 1, t=1e9)
        run.session.put(run.keys.of(keyspace.BEACON_CLOCK, "nest"), protocol.encode(forged))
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None and summary["rejected"]["beacon"] == 1


@KEYED
def test_a_forged_sense_for_the_last_tick_does_not_freeze_a_robot(keys: list[str]) -> None:
    """Keyed, the sense lacks robot 0's tag; without keys, its tick is out of reach."""
    with attacked_run(*SMALL, "--no-record", *keys) as run:
        run.wait_for_tick(10)
        for tick, t in ((2**53, 1.0), (run.tick + 10_000, (run.tick + 10_000) * 0.1)):
            forged = protocol.Sense(
                v=1, tick=tick, t=t, x=0, y=0, theta=0, prox=[0.0] * 8, rx=0, camera=False
            )
            run.session.put(run.keys.of(keyspace.SENSE, 0), protocol.encode(forged))
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None and summary["per_robot"][0]["rejected"] == 2


def test_forged_and_malformed_batches_are_refused_and_counted() -> None:
    """One process hosts the three robots, so robot 0 leads it and the senses and acts go
    as batches (``host/0/...``), each sealed with the key of its host identity ``host/0-2``.
    Forged and malformed batches, both ways: each is refused whole and counted once (by the
    world, or by robot 0 for its process), and the run goes on."""
    with attacked_run(*SMALL, "--no-record", "--robots-per-process", "3") as run:
        run.wait_for_tick(10)
        tick = run.tick + 1
        act = protocol.Act(v=1, tick=tick, left=0.1, right=0.1, capture=False, radio_tx=0)
        acts = batch.encode_acts(2, [(1, act)])
        senses = batch.encode_senses(
            2,
            tick=tick,
            t=0.1 * tick,
            robots=[1],
            values=[[0.0] * 11],
            rx=[0],
            camera=[False],
        )
        twice = batch.encode_senses(
            2,
            tick=tick,
            t=0.1 * tick,
            robots=[2, 2],
            values=[[0.0] * 11] * 2,
            rx=[0, 0],
            camera=[False, False],
        )
        forged_tag = b"\x00" * auth.TAG_BYTES
        to_world = [
            (
                run.keys.of(keyspace.HOST_ACT, 0),
                acts,
                forged_tag,
            ),  # the world: 1 (not host/0-2's tag)
            (run.keys.of(keyspace.HOST_ACT, 0), b"BNA1\xff\xff", None),  # 1: malformed
            (
                run.keys.of(keyspace.HOST_ACT, 0),
                b"\x00" * (batch.MAX_BATCH_BYTES + 1),
                None,
            ),  # 1: oversized
            (
                run.keys.of(keyspace.HOST_ACT, 99_999),
                batch.encode_acts(99_999, []),
                None,
            ),  # 1: no robot
        ]
        to_host = [
            (
                run.keys.of(keyspace.HOST_SENSE, 0),
                senses,
                None,
            ),  # robot 0, for its process: untagged
            (run.keys.of(keyspace.HOST_SENSE, 0), senses, forged_tag),  # robot 0: a forged tag
            (run.keys.of(keyspace.HOST_SENSE, 0), b"BNS1", None),  # robot 0: malformed
            (
                run.keys.of(keyspace.HOST_SENSE, 0),
                twice,
                None,
            ),  # robot 0: robot 2 twice (and no tag)
        ]
        for key, payload, attachment in [*to_world, *to_host]:
            run.session.put(
                key,
                payload,
                attachment=attachment,
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None
    assert summary["rejected"]["world"] == 4
    assert [robot["rejected"] for robot in summary["per_robot"]] == [4, 0, 0]


def test_a_copied_act_in_a_batch_of_the_attacker_s_does_not_divert_a_robot_s_senses() -> None:
    """Robot 1's own act, authentic, copied by an eavesdropper into a batch on robot 2's
    key (``host/2/act``): without host 2's key the batch is refused, and it must not teach
    the world that robot 1 answers from there, or robot 1's senses would go where nobody
    hears them."""
    with attacked_run(*SMALL, "--no-record", "--robots-per-process", "1") as run:
        seen: list[bytes] = []

        def on_act(sample: zenoh.Sample) -> None:
            seen.append(sample.payload.to_bytes())

        subscriber = run.session.declare_subscriber(run.keys.of(keyspace.ACT, 1), on_act)
        run.wait_for_tick(10)
        subscriber.undeclare()
        act = protocol.decode(seen[-1], protocol.Act)
        copied = batch.encode_acts(2, [(1, msgspec.structs.replace(act, tick=run.tick))])
        run.session.put(
            run.keys.of(keyspace.HOST_ACT, 2),
            copied,
            congestion_control=zenoh.CongestionControl.BLOCK,
        )
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None and summary["world"]["stalls"] == 0
    assert summary["rejected"]["world"] == 1


def test_a_host_that_speaks_for_a_robot_it_does_not_host_is_refused_for_that_robot(
    tmp_path: Path,
) -> None:
    """The process of robots 0 and 1 (host/0-1), compromised: with its own key it puts robot
    2's act for the tick under way into its batch, on every tick. The world refuses and
    counts that entry each time, takes robot 2's answer from robot 2's own process, and
    learns no route for robot 2 (its senses would go to a process that does not run it)."""
    run_id = unique_run_id("host")
    keys = keyspace.Keys(run_id)
    assert (
        run_keys.main(
            [
                "--run-id",
                run_id,
                "--robots",
                "3",
                "--out",
                str(tmp_path),
                "--robots-per-process",
                "2",
            ]
        )
        == 0
    )
    secret = run_keys.from_text((tmp_path / "secret.json").read_text(), run_id)
    host = run_keys.from_text((tmp_path / "host-0-1.json").read_text(), run_id)
    identity = names.host_identity(0, 1)
    common = ["--run-id", run_id, "--seed", str(SEED), "--mode", "client"]
    with loopback_router() as (session, endpoint):
        connect = ["--connect", endpoint]
        started = [
            subprocess.Popen(
                python_module(
                    "world_server.server",
                    *common,
                    *connect,
                    *["--robots", "3", "--sites", str(SITES), "--stall-timeout", "2"],
                    *["--key-file", str(tmp_path / "secret.json")],
                ),
                cwd=REPO,
                stderr=subprocess.PIPE,
            )
        ]
        for module, options, key_file in [
            ("nest_beacon", [], "secret"),
            ("robot_agent.node", ["--id", "0", "--id", "1"], "host-0-1"),  # one process
            ("robot_agent.node", ["--id", "2"], "robot-2"),
        ]:
            key_option = ["--key-file", str(tmp_path / f"{key_file}.json")]
            command = python_module(module, *common, *connect, *options, *key_option)
            started.append(subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE))
        ticks: list[int] = []
        forged: list[int] = []

        def on_clock(sample: zenoh.Sample) -> None:
            tick = protocol.decode(sample.payload.to_bytes(), protocol.Clock).tick
            ticks.append(tick)
            if tick < 5 or len(forged) >= 10:
                return
            act = protocol.Act(v=1, tick=tick, left=0.1, right=0.1, capture=False, radio_tx=0)
            payload = batch.encode_acts(1, [(2, act)])
            key = keys.of(keyspace.HOST_ACT, 0)
            session.put(key, payload, attachment=host.seal(identity, key, payload))
            forged.append(tick)

        session.declare_subscriber(keys.of(keyspace.CLOCK), on_clock)
        try:
            assert _wait_until(lambda: len(forged) >= 10, 60), "the run never got going"
            last = ticks[-1]
            assert _wait_until(lambda: ticks[-1] >= last + 30, 60), "the world stopped ticking"
            assert all(process.poll() is None for process in started), "a process exited"
            answers, refused = ask(
                session, keys.of(keyspace.STATS), secret, names.LAUNCHER, timeout=5.0
            )
            assert answers, refused
            stats = protocol.decode(answers[0], protocol.WorldState)
        finally:
            stop_processes(started)
            kill_leftovers(run_id)
    errors = b"".join(process.stderr.read() for process in started if process.stderr)
    assert b"Traceback" not in errors, errors.decode()[-3000:]
    assert stats.rejected == len(forged)  # each forged entry, and nothing else
    assert stats.stalls == 0  # robot 2 answered every tick from its own process


# --- mislead ----------------------------------------------------------------------------


def test_only_the_launcher_can_finish_the_recording(tmp_path: Path) -> None:
    recording = tmp_path / "run.mcap"
    with attacked_run(*SMALL, "--record", str(recording)) as run:
        run.wait_for_tick(10)
        forged = json.dumps({"run_id": "forged", "correct": True}).encode()
        replies = list(
            run.session.get(run.keys.of(keyspace.RECORDER_FINISH), payload=forged, timeout=5.0)
        )
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert not [reply for reply in replies if reply.ok is not None]
    with recording.open("rb") as stream:
        metadata = {record.name: record.metadata for record in make_reader(stream).iter_metadata()}
    final = metadata["bestofn.run"]
    assert final["finished_by"] == "finish query"
    assert json.loads(final["summary"])["run_id"] == run.run_id
    assert json.loads(final["recorder"])["rejected"] == 1


def test_forged_decisions_do_not_end_the_run() -> None:
    with attacked_run(*SMALL, "--no-record") as run:
        run.wait_for_tick(3)
        for robot in range(ROBOTS):
            status = protocol.Status(
                v=1,
                id=robot,
                tick=run.tick,
                t=run.tick * 0.1,
                phase="stopped",
                trips=1,
                opinion=[1.0 if site == wrong_site() else 0.0 for site in range(SITES)],
                pool_size=1,
                poolings=1,
                decided_site=wrong_site(),
                decision_time=run.tick * 0.1,
                decision_trips=1,
                comparison=None,
            )
            run.session.put(run.keys.of(keyspace.STATUS, robot), protocol.encode(status))
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert summary is not None and summary["rejected"]["observer"] == ROBOTS


@pytest.mark.parametrize("path", ["rx", "tx"])
def test_forged_opinions_on_the_radio_are_not_believed(path: str) -> None:
    """A one-hot opinion for a wrong site, in every robot's name, on every tick."""
    with attacked_run(*SMALL, "--no-record") as run:
        sent = [0]

        def forge(tick: int) -> None:
            for robot in range(ROBOTS):
                other = (robot + 1) % ROBOTS
                meta: protocol.RadioRxMeta | protocol.RadioTxMeta
                if path == "rx":  # straight to the receiver, past the medium
                    meta = protocol.RadioRxMeta(
                        v=1, tick=tick + 1, sender=str(other), seq=10_000 + tick, sent_tick=tick
                    )
                    key = run.keys.of(keyspace.RADIO_RX, robot)
                    payload = one_hot(wrong_site(), other)
                else:  # to the medium, in the robot's own name
                    meta = protocol.RadioTxMeta(v=1, tick=tick, seq=10_000 + tick)
                    key = run.keys.of(keyspace.RADIO_TX, robot)
                    payload = one_hot(wrong_site(), robot)
                run.session.put(key, payload, attachment=protocol.encode(meta))
                sent[0] += 1

        stop = repeat_every_tick(run, forge)
        code, summary, stderr = run.finish()
        stop.set()
    assert_right_consensus(code, summary, stderr)
    assert sent[0] > 100
    assert summary is not None
    rejected = summary["radio"]["rejected"] if path == "tx" else summary["rejected"]["robots"]
    assert rejected > 0


# --- memory -----------------------------------------------------------------------------


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for {pid}")


def _robot_pid(run_id: str, robot: int) -> int:
    for pid in processes_of(run_id):
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if (
            b"robot_agent.node" in cmdline
            and cmdline[cmdline.index(b"--id") + 1] == str(robot).encode()
        ):
            return pid
    raise AssertionError(f"no process for robot {robot}")


@pytest.mark.parametrize("keyed", [True, False], ids=["keyed", "no-keys"])
def test_a_flood_of_radio_messages_for_future_ticks_does_not_grow_a_robot(keyed: bool) -> None:
    flood, size = 4000, 20_000  # 76 MiB, more than three times what robot 0 may hold
    # What one robot process may hold: its inbox and the robot's pending inputs. The
    # allocator and Zenoh's buffers add to that, so allow twice it, still below the flood.
    held = node.INBOX_BYTES + node.INBOX_BYTES_PER_ROBOT + tick_assembly.PENDING_BYTES
    allowed = 2 * held / 2**20
    # Paced by the wall clock, so that the run outlasts the flood.
    options = [*SMALL, "--no-record", "--spawn", "exec", "--clock", "realtime", "--speed", "5"]
    with attacked_run(*options, *([] if keyed else ["--no-keys"])) as run:
        run.wait_for_tick(10)
        pid = _robot_pid(run.run_id, 0)
        before = _rss_mib(pid)
        junk = b'{"kind":"opinion"' + b" " * (size - 17)
        for index in range(flood):
            meta = protocol.RadioRxMeta(
                # For the next 5 s of sim time: what robot 0 holds for them it counts at
                # their ticks, before the run can end (held for later ticks, some were
                # never counted when the run ended first on a busy machine).
                v=1,
                tick=run.tick + 5 + index % 50,
                sender="1",
                seq=index,
                sent_tick=run.tick,
            )
            run.session.put(
                run.keys.of(keyspace.RADIO_RX, 0),
                junk,
                attachment=protocol.encode(meta),
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        time.sleep(2.0)  # let robot 0 take in the flood
        grown = _rss_mib(pid) - before
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    assert grown < allowed, f"robot 0 grew by {grown:.0f} MiB (allowed {allowed:.0f})"
    assert summary is not None and summary["per_robot"][0]["rejected"] == flood


def test_junk_on_the_run_keys_does_not_blow_up_the_recording(tmp_path: Path) -> None:
    recording = tmp_path / "run.mcap"
    with attacked_run(*SMALL, "--record", str(recording)) as run:
        run.wait_for_tick(10)
        junk = os.urandom(2**20)  # 1 MiB that does not compress
        for index in range(100):
            run.session.put(
                run.keys.of(keyspace.STATUS, index % ROBOTS),
                junk,
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        code, summary, stderr = run.finish()
    assert_right_consensus(code, summary, stderr)
    size_mib = recording.stat().st_size / 2**20
    assert size_mib < 8, f"the recording is {size_mib:.0f} MiB"
    with recording.open("rb") as stream:
        metadata = {record.name: record.metadata for record in make_reader(stream).iter_metadata()}
    assert json.loads(metadata["bestofn.run"]["recorder"])["rejected"] == 100


# --- a sender that leaves ---------------------------------------------------------------


@pytest.mark.parametrize("role", ["robot", "beacon"])
def test_a_sender_that_leaves_with_its_transmission_queued_does_not_crash_the_world(
    role: str, tmp_path: Path
) -> None:
    """Robot 2 (or a second beacon), played by the test with its own key, transmits in a
    tick and leaves before answering it: the world drops the transmission (late) and goes on."""
    run_id = unique_run_id("leave")
    keys = keyspace.Keys(run_id)
    assert run_keys.main(["--run-id", run_id, "--robots", "3", "--out", str(tmp_path)]) == 0
    secret = run_keys.from_text((tmp_path / "secret.json").read_text(), run_id)
    mine = run_keys.from_text((tmp_path / "robot-2.json").read_text(), run_id)
    common = ["--run-id", run_id, "--seed", str(SEED), "--mode", "client"]
    with loopback_router() as (session, endpoint):
        connect = ["--connect", endpoint]
        world_command = [
            *python_module("world_server.server", *common, *connect),
            # Robot 2 is the test's; in the beacon case the swarm is robots 0 and 1.
            *["--robots", "3" if role == "robot" else "2", "--sites", str(SITES)],
            *["--stall-timeout", "2"],
            *["--key-file", str(tmp_path / "secret.json")],
        ]
        started = [subprocess.Popen(world_command, cwd=REPO, stderr=subprocess.PIPE)]
        for module, options in [
            ("nest_beacon", ["--key-file", str(tmp_path / "secret.json")]),
            ("robot_agent.node", ["--id", "0", "--key-file", str(tmp_path / "robot-0.json")]),
            ("robot_agent.node", ["--id", "1", "--key-file", str(tmp_path / "robot-1.json")]),
        ]:
            command = python_module(module, *common, *connect, *options)
            started.append(subprocess.Popen(command, cwd=REPO, stderr=subprocess.PIPE))
        ticks: list[int] = []
        sent: list[int] = []  # the tick of the test's one transmission
        if role == "robot":
            name, keyring, identity = "2", mine, names.robot_identity(2)
        else:
            name, keyring, identity = "spare", secret, names.beacon_identity("spare")
        joined_at: list[int] = []

        def transmit(tick: int) -> None:
            """One radio message in this tick, and no answer to it."""
            key, payload = (
                keys.of(keyspace.RADIO_TX, name),
                b'{"kind":"beacon","v":1,"id":"x","seq":1}',
            )
            meta = protocol.encode(protocol.RadioTxMeta(v=1, tick=tick, seq=1))
            session.put(key, payload, attachment=keyring.seal(identity, key, payload, meta))
            sent.append(tick)

        def on_sense(sample: zenoh.Sample) -> None:  # robot 2's first tick
            if not sent:
                transmit(protocol.decode(sample.payload.to_bytes(), protocol.Sense).tick)

        def on_clock(sample: zenoh.Sample) -> None:
            tick = protocol.decode(sample.payload.to_bytes(), protocol.Clock).tick
            ticks.append(tick)
            if role != "beacon" or not joined_at or sent:
                return
            if tick >= joined_at[0] + 10:  # by now in the world's barrier
                transmit(tick)
            else:  # a well-behaved beacon until then
                key = keys.of(keyspace.ACK, name)
                ack = protocol.encode(protocol.Ack(v=1, tick=tick, radio_tx=0))
                session.put(key, ack, attachment=keyring.seal(identity, key, ack))

        session.declare_subscriber(keys.of(keyspace.CLOCK), on_clock)
        session.declare_subscriber(keys.of(keyspace.SENSE, 2), on_sense)
        try:
            if role == "beacon":
                assert _wait_until(lambda: len(ticks) > 3, 60), "the run never started"
                joined_at.append(ticks[-1])
            # As every robot and beacon does: prove itself present (world/info with its key),
            # then declare its token, which the world takes only with that proof.
            fetch_world_info(session, keys, 60.0, keyring, identity)
            token = session.liveliness().declare_token(keys.token(Role(role), name))
            assert _wait_until(lambda: bool(sent), 60), "the test's sender never took part"
            tick = sent[0]
            time.sleep(0.5)  # the world has it queued, and waits for an answer that never comes
            token.undeclare()  # ... and leaves
            assert _wait_until(lambda: ticks[-1] >= tick + 20, 60), "the world stopped ticking"
            assert started[0].poll() is None, "the world server exited"
            answers, refused = ask(
                session, keys.of(keyspace.STATS), secret, names.LAUNCHER, timeout=5.0
            )
            assert answers, refused
            stats = protocol.decode(answers[0], protocol.WorldState)
        finally:
            stop_processes(started)
            kill_leftovers(run_id)
    errors = b"".join(process.stderr.read() for process in started if process.stderr)
    assert b"Traceback" not in errors, errors.decode()[-3000:]
    # The transmission of the sender that left is late (test_coordinator shows it is not
    # transmitted): no forgery, so neither the world nor the radio refused anything.
    assert (stats.radio.rejected, stats.rejected) == (0, 0)
    assert stats.departures == 1
    assert len(sent) == 1


def _wait_until(condition: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True
