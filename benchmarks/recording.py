"""What does recording cost, and does the recorder keep everything?

1. Overhead: for each swarm size, ``swarm run`` with ``--no-record`` and with ``--record``,
   same seed, alternating, ``--repeats`` times each. Every run lasts exactly
   ``--sim-seconds`` of sim time (the timeout comes before consensus), so both modes do
   the same work. Prints the wall time of the whole command, the real-time factor while
   ticking, and the recording's size.
2. Published vs recorded, for every recorded run: each message kind's count in the file
   against the count its publishers declared or must have sent (Sense.rx, Sense.camera,
   Act/Ack.radio_tx, contiguous ticks, the world's own radio counters); see
   ``deploy.reports.audit.audit``.
3. Capacity: a recorder process on a loopback router, flooded with ``--flood`` sense
   messages from one publisher as fast as Zenoh takes them; the time until its finish
   query is answered gives the messages per second it records, and the file must hold all.

    .venv/bin/python benchmarks/recording.py                     # 10 and 100 robots
    .venv/bin/python benchmarks/recording.py --robots 10 --repeats 3 --flood 0
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from bestofn_swarm.wire.names import Role

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bestofn_swarm.plumbing.tcp import free_port  # noqa: E402
from bestofn_swarm.plumbing.zenoh_session import open_session, reliable_publisher  # noqa: E402
from bestofn_swarm.wire import keyspace, protocol  # noqa: E402
from bestofn_swarm.wire.endings import RESULT_CODES  # noqa: E402
from deploy.reports import audit, collect  # noqa: E402
from world_server.recorder.write_loop import FINISH_QUIET  # noqa: E402

SIM_SECONDS = {10: 100.0, 100: 60.0}


def swarm_run(
    robots: int, seed: int, sim_seconds: float, record: Path | None, run_id: str
) -> dict[str, Any]:
    output = ["--record", str(record)] if record else ["--no-record"]
    command = [
        sys.executable,
        "-m",
        "deploy.cli",
        "run",
        "--robots",
        str(robots),
        "--sites",
        "10",
        "--seed",
        str(seed),
        "--timeout",
        str(sim_seconds),
        "--run-id",
        run_id,
        "--json",
        "--quiet",
        *output,
    ]
    started = time.monotonic()
    done = subprocess.run(command, capture_output=True, timeout=3600, cwd=REPO)
    elapsed = time.monotonic() - started
    if done.returncode not in RESULT_CODES:  # a timeout (exit 5) is a result here
        raise RuntimeError(f"swarm run failed:\n{done.stderr.decode()[-2000:]}")
    summary = json.loads(done.stdout)
    return {"command_s": elapsed, "summary": summary}


def overhead(robots: int, seed: int, sim_seconds: float, repeats: int, folder: Path) -> None:
    print(f"\n== {robots} robots, 10 sites, seed {seed}, {sim_seconds:g} sim seconds per run ==")
    rows: dict[str, list[dict[str, Any]]] = {"no record": [], "record": []}
    audits = []
    for repeat in range(repeats):
        for mode in ("no record", "record"):
            path = folder / f"bench-{robots}-{repeat}.mcap" if mode == "record" else None
            result = swarm_run(
                robots,
                seed,
                sim_seconds,
                path,
                f"bench-{robots}-{repeat}-{'rec' if path else 'norec'}-{int(time.time())}",
            )
            if path is not None:
                recording = collect.read_recording(path)
                result["bytes"] = path.stat().st_size
                result["messages"] = recording.messages.total()
                audits.append((audit.audit(recording), result["summary"]))
            rows[mode].append(result)
            summary = result["summary"]
            print(
                f"  {mode:9}  command {result['command_s']:6.1f} s   ticking "
                f"{summary['wall_time_s']:6.1f} s   {summary['real_time_factor']:6.1f}x real "
                f"time   sim {summary['sim_time_s']:.0f} s"
                + (
                    f"   {result['bytes'] / 1e6:.1f} MB, {result['messages']} messages"
                    if path
                    else ""
                )
            )
    print("  median:")
    medians = {}
    for mode, results in rows.items():
        command = statistics.median(r["command_s"] for r in results)
        ticking = statistics.median(r["summary"]["wall_time_s"] for r in results)
        factor = statistics.median(r["summary"]["real_time_factor"] for r in results)
        medians[mode] = (command, ticking, factor)
        print(
            f"  {mode:9}  command {command:6.1f} s   ticking {ticking:6.1f} s   "
            f"{factor:6.1f}x real time"
        )
    (c0, t0, f0), (c1, t1, f1) = medians["no record"], medians["record"]
    print(
        f"  recording adds {100 * (c1 / c0 - 1):+.1f}% to the command's wall time, "
        f"{100 * (t1 / t0 - 1):+.1f}% to the ticking time (real-time factor "
        f"{f0:.1f}x -> {f1:.1f}x)"
    )
    print("  published (declared) vs recorded, every recorded run:")
    for found, summary in audits:
        lost = {
            kind: c["expected"] - c["recorded"]
            for kind, c in found.items()
            if c["expected"] != c["recorded"]
        }
        total = sum(c["recorded"] for c in found.values())
        delivered = summary["radio"]["delivered"]
        print(
            f"    {total} protocol messages recorded; radio/rx recorded "
            f"{found['radio/rx/*']['recorded']} of {delivered} the world delivered; "
            f"mismatches: {lost or 'none'}"
        )
    kinds = audits[0][0] if audits else {}
    for kind in kinds:
        expected = sum(audit[kind]["expected"] for audit, _ in audits)
        recorded = sum(audit[kind]["recorded"] for audit, _ in audits)
        print(f"    {kind:16} expected {expected:9d}   recorded {recorded:9d}")


def flood(count: int, folder: Path) -> None:
    """Messages per second the recorder process takes in and writes, losing none."""
    print(f"\n== recorder capacity: {count} sense messages from one publisher ==")
    run_id = f"flood-{int(time.time())}"
    keys = keyspace.Keys(run_id)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out = folder / "flood.mcap"
    router = open_session("router", listen=[endpoint])
    recorder = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "world_server.recorder",
            "--run-id",
            run_id,
            "--mode",
            "client",
            "--connect",
            endpoint,
            "--out",
            str(out),
            "--robots",
            "100",
            "--sites",
            "10",
            "--info-timeout",
            "0.2",
            "--log-level",
            "WARNING",
        ],
        cwd=REPO,
    )
    try:
        while not list(router.liveliness().get(keys.token(Role.RECORDER, 0), timeout=1.0)):
            if recorder.poll() is not None:
                raise RuntimeError("the recorder did not start")
            time.sleep(0.05)
        publishers = [
            reliable_publisher(router, keys.of(keyspace.SENSE, robot)) for robot in range(100)
        ]
        payloads = [
            protocol.encode(
                protocol.Sense(
                    v=1,
                    tick=tick,
                    t=tick * 0.1,
                    x=0.1,
                    y=0.2,
                    theta=0.3,
                    prox=[0.0] * 8,
                    rx=0,
                    camera=False,
                )
            )
            for tick in range(count // 100 + 1)
        ]
        started, started_ns = time.monotonic(), time.time_ns()
        for index in range(count):
            publishers[index % 100].put(payloads[index // 100])
        published = time.monotonic() - started
        replies = list(router.get(keys.of(keyspace.RECORDER_FINISH), payload=b"{}", timeout=600.0))
        finished = time.monotonic() - started
        exit_code = recorder.wait(timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        router.close()
    recording = collect.read_recording(out)
    recorded = recording.messages["bestofn.Sense"]
    with open(out, "rb") as stream:  # publish time = when the recorder's callback got it
        last_arrival = max(
            message.publish_time for _, _, message in make_reader(stream).iter_messages()
        )
    received = (last_arrival - started_ns) / 1e9
    print(
        f"  published {count} in {published:.2f} s ({count / published:,.0f} msg/s); "
        f"all received by {received:.2f} s ({count / received:,.0f} msg/s); "
        f"closed after {finished:.2f} s (incl. {FINISH_QUIET:g} s quiet); "
        f"{recorded} of {count} in the file; finish reply: "
        f"{'ok' if replies and replies[0].ok is not None else 'MISSING'}; recorder exit "
        f"code {exit_code}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--robots",
        type=int,
        nargs="*",
        default=[10, 100],
        help="swarm sizes (none: only the capacity test)",
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument(
        "--sim-seconds",
        type=float,
        default=None,
        help="sim seconds per run (default: 100 for 10 robots, 60 for 100)",
    )
    parser.add_argument(
        "--flood", type=int, default=200_000, help="messages for the capacity test (0: skip it)"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for robots in args.robots:
            sim_seconds = args.sim_seconds or SIM_SECONDS.get(robots, 60.0)
            overhead(robots, args.seed, sim_seconds, args.repeats, Path(folder))
        if args.flood:
            flood(args.flood, Path(folder))


if __name__ == "__main__":
    main()
