"""The real swarm: world server, nest beacon and robot processes over Zenoh on loopback."""

from __future__ import annotations

import importlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import (
    REPO,
    call_main,
    kill_leftovers,
    loopback_router,
    processes_of,
    reference_run,
    run_swarm,
    swarm_cli,
    swarm_command,
    unique_run_id,
    wait_for_processes,
)

from bestofn_swarm.wire import keyspace, protocol

pytestmark = pytest.mark.timeout(240)

SMALL = ["--robots", "4", "--sites", "5", "--timeout", "900", "--no-record"]


def test_a_small_swarm_reaches_the_right_consensus_and_leaves_nothing_behind() -> None:
    run_id = unique_run_id("consensus")
    code, summary, stderr = run_swarm([*SMALL, "--seed", "1"], run_id)
    assert code == 0, stderr
    assert summary["consensus"] and summary["correct"], summary
    assert summary["chosen_site"] == summary["best_site"]
    assert not summary["timed_out"]
    robots = summary["per_robot"]
    assert [robot["id"] for robot in robots] == [0, 1, 2, 3]
    for robot in robots:
        assert robot["decided_site"] == summary["best_site"]
        assert robot["steps"] >= 1
        assert len(robot["pool_sizes"]) == robot["steps"]
        assert all(size >= 1 for size in robot["pool_sizes"])
        assert 0 < robot["decision_time_s"] <= summary["sim_time_s"]
    assert summary["radio"]["sent"] > 0 and summary["radio"]["delivered"] > 0
    assert summary["radio"]["dropped"] == 0
    assert summary["real_time_factor"] > 0
    assert processes_of(run_id) == []


# The runs compared bit for bit with the in-process run: a world that waits long for a
# robot a busy machine starved stays in lockstep (a stall closes a tick without a robot,
# and the run is no longer the seed's).
PATIENT = ["--stall-timeout", "120"]


def test_the_same_seed_gives_the_same_per_robot_results() -> None:
    """Ten robots, one process each (the default), crowd the nest: contacts make any
    order-dependence in the world show. The run is robot for robot the in-process run of
    the same seed, which is deterministic (tests/test_inprocess.py): so is this one."""
    options = ["--robots", "10", "--sites", "8", "--seed", "2", "--no-record", *PATIENT]
    code, summary, stderr = run_swarm(options, unique_run_id("same"))
    assert code == 0, stderr
    assert summary["robot_processes"] == 10
    reference = reference_run(options)
    assert _decisions(summary) == _decisions(reference)
    assert summary["digest"] == reference["digest"]


def _decisions(summary: dict[str, Any]) -> list[tuple[object, ...]]:
    return [
        (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
        for r in summary["per_robot"]
    ]


def test_killing_a_robot_mid_run_does_not_hang_the_world() -> None:
    run_id = unique_run_id("kill")
    keys = keyspace.Keys(run_id)
    with loopback_router() as (session, endpoint):
        sim_time = [0.0]
        session.declare_subscriber(
            keys.of(keyspace.CLOCK),
            lambda sample: sim_time.__setitem__(
                0, protocol.decode(sample.payload.to_bytes(), protocol.Clock).t
            ),
        )
        command = swarm_command(
            "run",
            "--run-id",
            run_id,
            "--json",
            "--quiet",
            *SMALL,
            "--seed",
            "2",
            "--stall-timeout",
            "1",
            "--connect",
            endpoint,
            "--spawn",
            "exec",
            "--robots-per-process",
            "1",
        )
        process = subprocess.Popen(
            command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        try:
            robots = wait_for_processes(run_id, "robot_agent.node", 4, timeout=60)
            victim = next(pid for pid in robots if "--id 3 " in _cmdline(pid))
            deadline = time.monotonic() + 60
            while sim_time[0] < 5.0 and time.monotonic() < deadline:
                time.sleep(0.01)
            assert sim_time[0] >= 5.0, "the run never started"
            os.kill(victim, signal.SIGKILL)
            killed_at = sim_time[0]
            stdout, stderr = process.communicate(timeout=180)
        finally:
            if process.poll() is None:
                process.kill()
            left = kill_leftovers(run_id)
    assert process.returncode == 1, stderr.decode()  # a component crashed
    summary = json.loads(stdout)
    by_id = {robot["id"]: robot for robot in summary["per_robot"]}
    assert by_id[3]["crashed"]
    assert by_id[3]["decided_site"] is None or by_id[3]["decision_time_s"] <= killed_at
    for robot in (0, 1, 2):
        assert not by_id[robot]["crashed"]
        assert by_id[robot]["decided_site"] == summary["best_site"]
    assert "crashed" in stderr.decode()
    assert left == []


def _cmdline(pid: int) -> str:
    with open(f"/proc/{pid}/cmdline", "rb") as file:
        return file.read().replace(b"\0", b" ").decode() + " "


def _garbage(run: keyspace.Keys, tick: int) -> list[tuple[str, bytes, bytes | None]]:
    """Malformed, wrong-version, wrong-length, NaN, oversized and impostor messages."""
    huge = b"[" + b"0," * 60_000 + b"0]"
    good_sense = protocol.encode(
        protocol.Sense(
            v=1, tick=tick, t=0.0, x=0.0, y=0.0, theta=0.0, prox=[0.0] * 8, rx=0, camera=False
        )
    )
    impostor = protocol.encode(
        protocol.OpinionPayload(v=1, id=2, trip=1, decided=True, opinion=[1.0, 0, 0, 0, 0])
    )
    tx_meta = protocol.encode(protocol.RadioTxMeta(v=1, tick=tick, seq=1))
    bad = [
        b"not json",
        b"",
        good_sense.replace(b'"v":1', b'"v":2'),
        good_sense.replace(b'"prox":[0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0]', b'"prox":[0.0]'),
        good_sense.replace(b'"x":0.0', b'"x":NaN'),
        huge,
    ]
    keys = [
        run.of(keyspace.SENSE, 0),
        run.of(keyspace.ACT, 0),
        run.of(keyspace.STATUS, 0),
        run.of(keyspace.CLOCK),
        run.of(keyspace.STATE),
        run.of(keyspace.ACK, "nest"),
        run.of(keyspace.RADIO_TX, 0),
        run.of(keyspace.RADIO_TX, 77),
        run.of(keyspace.CAMERA, 0),
        run.of(keyspace.RADIO_RX, 0),
        run.of(keyspace.LOG, "world"),
    ]
    messages: list[tuple[str, bytes, bytes | None]] = [
        (key, payload, None) for key in keys for payload in bad
    ]
    messages += [(run.of(keyspace.RADIO_TX, 1), payload, tx_meta) for payload in bad]
    messages += [(run.of(keyspace.RADIO_RX, 0), payload, b"{}") for payload in bad]
    messages.append(
        (run.of(keyspace.RADIO_TX, 1), impostor, tx_meta)
    )  # robot 1 claiming to be robot 2
    messages.append((run.of(keyspace.RADIO_TX, 77), impostor, tx_meta))  # no such robot
    return messages


def test_malformed_payloads_on_every_key_are_rejected_and_counted() -> None:
    run_id = unique_run_id("junk")
    keys = keyspace.Keys(run_id)
    with loopback_router() as (session, endpoint):
        ticks: list[int] = []
        session.declare_subscriber(
            keys.of(keyspace.CLOCK),
            lambda sample: ticks.append(
                protocol.decode(sample.payload.to_bytes(), protocol.Clock).tick
            ),
        )
        command = swarm_command(
            "run",
            "--run-id",
            run_id,
            "--json",
            "--quiet",
            *SMALL,
            "--seed",
            "3",
            "--connect",
            endpoint,
        )
        process = subprocess.Popen(
            command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        try:
            deadline = time.monotonic() + 60
            while len(ticks) < 20 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert ticks, "the run never started"
            for _ in range(3):
                for key, payload, attachment in _garbage(keys, ticks[-1]):
                    session.put(key, payload, attachment=attachment)
                time.sleep(0.3)
            stdout, stderr = process.communicate(timeout=180)
        finally:
            if process.poll() is None:
                process.kill()
            left = kill_leftovers(run_id)
    assert process.returncode == 0, stderr.decode()
    summary = json.loads(stdout)
    assert summary["correct"], summary
    assert summary["rejected"]["world"] > 0
    assert summary["rejected"]["robots"] > 0
    assert summary["rejected"]["observer"] > 0
    assert summary["radio"]["rejected"] > 0
    for robot in summary["per_robot"]:
        assert robot["decided_site"] == summary["best_site"]
    assert left == []


def test_bad_arguments_exit_with_code_2_and_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    for bad in (
        ["--robots", "0"],
        ["--alpha", "0.7"],
        ["--drop", "1.5"],
        ["--sites", "1"],
        ["--run-id", "a/b"],
        ["--threshold", "0"],
        ["--timeout", "nan"],
        ["--record", "x.mcap", "--no-record"],
    ):
        code, _, err = swarm_cli(["run", *bad], capsys)
        assert code == 2, bad
        lines = err.strip().splitlines()
        assert lines[-1].startswith("swarm run: error:"), lines
        assert "Traceback" not in err


@pytest.mark.parametrize("module", ["world_server.server", "nest_beacon.node", "robot_agent.node"])
def test_every_component_prints_its_help(module: str, capsys: pytest.CaptureFixture[str]) -> None:
    main = importlib.import_module(f"{module}.cli").main
    code, out, _ = call_main(main, ["--help"], capsys)
    assert code == 0
    assert "usage:" in out
    assert "--connect" in out


def test_alpha_without_threshold_is_a_usage_error_not_a_traceback(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, _, err = swarm_cli(["run", "--alpha", "0.2", "--threshold", "1"], capsys)
    assert code == 2
    assert "Traceback" not in err
    assert "threshold" in err


def test_lockstep_over_zenoh_decides_exactly_as_the_in_memory_run(tmp_path: Path) -> None:
    """Same seed: the distributed run and the single-process run agree robot by robot. Over
    Zenoh, robots 0-4 share a process that exchanges batches with the world, and robot 5
    has one of its own, on its own keys (the world's timeline says which went how)."""
    from deploy.inprocess.engine import run_in_process
    from robot_agent.node import cli as node
    from robot_agent.node import options
    from world_server.server import cli as server

    seed, robots, sites = 5, 6, 6
    common = ["--seed", str(seed), "--robots", str(robots), "--sites", str(sites)]
    world_config = server.config_from_args(
        server.build_parser().parse_args([*common, "--run-id", "memory"])
    )
    controller_config = options.controller_config(node.build_parser().parse_args(["--id", "0"]))
    in_memory = run_in_process(world_config, controller_config, timeout=900)
    trace = tmp_path / "trace"
    hosts = ["--robots-per-process", "5", "--trace", str(trace), *PATIENT]
    code, over_zenoh, stderr = run_swarm(
        [*common, "--timeout", "900", "--no-record", *hosts], unique_run_id("vs-memory")
    )
    assert code == 0, stderr
    ticks = [json.loads(line) for line in (trace / "world.jsonl").read_text().splitlines()]
    # From the second tick on, robots 0-4 are sensed in their process's batch.
    assert {tick["batched"] for tick in ticks[2:]} == {5}

    def decisions(summary: dict[str, Any]) -> list[tuple[object, ...]]:
        return [
            (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
            for r in summary["per_robot"]
        ]

    assert decisions(over_zenoh) == decisions(in_memory)
    assert over_zenoh["sim_time_s"] == in_memory["sim_time_s"]
    assert over_zenoh["digest"] == in_memory["digest"]
    # `swarm run --engine inprocess`: the same summary, field for field, robot for robot.
    code_in_process, in_process, stderr = run_swarm(
        [*common, "--timeout", "900", "--no-record", "--engine", "inprocess"],
        unique_run_id("inprocess"),
    )
    assert code_in_process == code, stderr
    assert in_process.keys() == over_zenoh.keys()
    assert in_process["config"].keys() == over_zenoh["config"].keys()
    for field in ("ended", "consensus", "chosen_site", "correct", "sim_time_s", "stuck", "digest"):
        assert in_process.get(field) == over_zenoh.get(field), field
    # Everything of each robot but where it is when the run stops: over Zenoh the
    # launcher notices the last decision a few ticks later, and the robots move on.
    assert [{**r, "phase": None} for r in in_process["per_robot"]] == [
        {**r, "phase": None} for r in over_zenoh["per_robot"]
    ]


def test_the_process_layout_changes_no_robot_s_results() -> None:
    """Robots hosted three to a process (batches sealed by their host) give the same seed's
    results robot for robot, as one process per robot does
    (test_the_same_seed_gives_the_same_per_robot_results): both are the in-process run."""
    common = ["--robots", "6", "--sites", "6", "--seed", "3", "--timeout", "900", "--no-record"]
    common += PATIENT
    code, summary, stderr = run_swarm(
        [*common, "--robots-per-process", "3"], unique_run_id("layout-3")
    )
    assert code == 0, stderr
    assert summary["robot_processes"] == 2
    reference = reference_run(common)
    # Everything of each robot but where it is when the run stops (the launcher notices
    # the last decision a tick or two late, and the robots move on).
    assert [{**r, "phase": None} for r in summary["per_robot"]] == [
        {**r, "phase": None} for r in reference["per_robot"]
    ]
    assert summary["digest"] == reference["digest"]


HOSTED_FOUR = ["--robots-per-process", "4"]


def test_a_swarm_on_the_realtime_clock_reaches_the_right_consensus() -> None:
    """How closely the world keeps to the asked speed is a figure, not a check: measured by
    ``benchmarks/swarm_speed.py --realtime``. Its robots are hosted in one process: as four
    robot processes at 25x (a tick every 4 ms) on 2 shared cores they answered late enough
    for the run to end stalled in a fresh-clone ``make test`` (docs/performance.md, "Real
    time"); one process per robot in real time is run at 1-2x by test_secure and
    test_outside."""
    code, summary, stderr = run_swarm(
        [*SMALL, "--seed", "1", "--clock", "realtime", "--speed", "10", *HOSTED_FOUR],
        unique_run_id("realtime"),
    )
    assert code == 0, stderr
    assert summary["correct"]


@pytest.mark.parametrize(
    ("command", "bad", "named"),
    [
        (["world-server"], ["--sites", "1"], "--sites"),
        (["world-server"], ["--drop", "2"], "--drop"),
        (["world-server"], ["--burst-loss", "0.1"], "--burst-loss"),
        (["nest-beacon"], ["--outage", "5:1"], "START < END"),
        (["nest-beacon"], ["--name", "7"], "'7'"),
        (["robot-agent"], ["--id", "-1"], "--id"),
        (["robot-agent"], ["--id", "1", "--alpha", "0.9"], "--alpha"),
        (["robot-agent"], ["--id", "1", "--connect", "nowhere"], "'nowhere'"),
        (["swarm", "wellstirred"], ["--pool", "0"], "--pool"),
        (["swarm", "report"], ["--out"], "--out"),
        (["swarm", "experiment"], ["--runs", "0"], "--runs"),
        (["swarm", "router"], ["--listen", "x"], "'x'"),
        (["swarm", "run"], ["--kill", "3"], "--kill"),
        (["swarm", "run"], ["--robots", "2", "--kill", "5@10"], "robot 5"),
        (["swarm"], ["nonsense"], "'nonsense'"),
    ],
)
def test_every_command_rejects_bad_arguments_in_one_line_with_code_2(
    command: list[str], bad: list[str], named: str
) -> None:
    """Each bad argument is refused for what is wrong with it (``named``: the option or
    the rule), not for some other reason such as an option the command does not have."""
    modules = {
        "world-server": "world_server.server",
        "nest-beacon": "nest_beacon",
        "robot-agent": "robot_agent.node",
        "swarm": "deploy.cli",
    }
    argv = [sys.executable, "-m", modules[command[0]], *command[1:], *bad]
    done = subprocess.run(argv, capture_output=True, timeout=60, cwd=REPO)
    errors = done.stderr.decode()
    assert done.returncode == 2, errors
    assert "Traceback" not in errors
    last = errors.strip().splitlines()[-1]
    assert "error:" in last and named in last, last
    assert "unrecognized arguments" not in last, last
