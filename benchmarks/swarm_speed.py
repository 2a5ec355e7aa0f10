"""How fast does a lockstep swarm run? Real-time factor and wall time, to consensus.

For 10, 50 and 100 robots it runs `swarm run --json` to consensus and reports the
real-time factor (sim seconds per wall second while ticking), the wall time of the run,
and the time to start and stop. Then a scale curve: wall time per simulated second and
real-time factor for 10 to 500 robots over a fixed stretch of sim time, with one process
per robot and with robots hosted many to a process.

As a baseline measured in the same run, it times the bare lockstep exchange of the
same number of processes over Zenoh (sense out, act back, no physics,
no controller): the floor our own code sits on, so the ratio says what the swarm's
logic costs on top of the messaging.

    .venv/bin/python benchmarks/swarm_speed.py                 # everything
    .venv/bin/python benchmarks/swarm_speed.py --robots 10 --seeds 0 1 2 --scale
    .venv/bin/python benchmarks/swarm_speed.py --robots 10 --seeds 0 1 2 3 4 --scale \
        --no-floor --with-recording
    .venv/bin/python benchmarks/swarm_speed.py --robots --scale 200 500 --modes hosted

The real-time clock (``--realtime``): for each asked speed, one `swarm run --clock
realtime --speed X` to consensus, and the real-time factor it reached. The world is paced
by the wall clock, so the factor should come close to the asked speed and never pass it
(a busy machine may fall behind it):

    .venv/bin/python benchmarks/swarm_speed.py --robots --scale --engines --realtime 5 25

The engines table (``--engines``) runs each swarm size with ``swarm run --engine
inprocess`` and over Zenoh (``swarm run``), the same seed, one after the other
(``--pairs`` such pairs, alternating), and prints both real-time factors, their ratio, the
ratio of the CPU their processes spent per tick (each run less the same run stopped after
one tick), the messaging floor, and whether the two agree robot for robot; ``--doc
docs/performance.md`` also writes that table into the page between its
``swarm_speed:engines`` markers (``--readme`` is the same option's old spelling; give it
again for another page, such as README.md):

    .venv/bin/python benchmarks/swarm_speed.py --robots --scale --engines 10 100 --pairs 3 \
        --doc docs/performance.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import zenoh  # noqa: E402

from benchmarks.process_cpu import in_process_options  # noqa: E402
from bestofn_swarm.plumbing.tcp import free_port  # noqa: E402
from bestofn_swarm.plumbing.zenoh_session import open_session, reliable_publisher  # noqa: E402
from bestofn_swarm.wire.endings import RESULT_CODES  # noqa: E402
from deploy.reports import pages  # noqa: E402

TARGETS = {10: 50.0, 50: 10.0, 100: 2.0, 200: 3.0, 500: 1.0}

ECHO_ROBOT = """
import sys, time
from bestofn_swarm.plumbing.zenoh_session import open_session, reliable_publisher
robot, endpoint = sys.argv[1], sys.argv[2]
session = open_session("client", [endpoint])
act = reliable_publisher(session, f"floor/robot/{robot}/act")
session.declare_subscriber(f"floor/robot/{robot}/sense", lambda s: act.put(s.payload.to_bytes()))
session.liveliness().declare_token(f"floor/alive/{robot}")
while True:
    time.sleep(3600)
"""


def messaging_floor(robots: int, ticks: int, endpoint: str | None = None) -> float:
    """Ticks per second of a bare lockstep exchange with ``robots`` processes, through a
    router on ``endpoint`` (default: a free loopback TCP port)."""
    endpoint = endpoint or f"tcp/127.0.0.1:{free_port()}"
    session = open_session("router", listen=[endpoint])
    answered: dict[int, int] = {}
    done = threading.Condition()

    def on_act(sample: zenoh.Sample) -> None:
        tick = int(sample.payload.to_bytes())
        with done:
            answered[tick] = answered.get(tick, 0) + 1
            if answered[tick] == robots:
                done.notify()

    session.declare_subscriber("floor/robot/*/act", on_act)
    alive: set[str] = set()
    session.liveliness().declare_subscriber(
        "floor/alive/*", lambda sample: alive.add(str(sample.key_expr)), history=True
    )
    senders = [reliable_publisher(session, f"floor/robot/{r}/sense") for r in range(robots)]
    children = [
        subprocess.Popen([sys.executable, "-c", ECHO_ROBOT, str(r), endpoint], cwd=REPO)
        for r in range(robots)
    ]
    try:
        deadline = time.monotonic() + 120
        while len(alive) < robots and time.monotonic() < deadline:
            time.sleep(0.05)
        if len(alive) < robots:  # a busy machine: some never connected; no floor then
            return 0.0
        time.sleep(0.5)
        start = time.perf_counter()
        for tick in range(ticks):
            payload = str(tick).encode() + b" " * 100  # about the size of a Sense
            for sender in senders:
                sender.put(payload)

            def everyone_answered(tick: int = tick) -> bool:
                return answered.get(tick, 0) >= robots

            with done:
                if not done.wait_for(everyone_answered, timeout=5):
                    return 0.0  # an echo process is gone: no floor rather than a wrong one
        return ticks / (time.perf_counter() - start)
    finally:
        for child in children:
            child.kill()
            child.wait()
        session.close()


def children_cpu() -> float:
    """CPU seconds (user + system) of every finished process this one has waited for,
    their own waited-for children included: a swarm run's launcher reaps all of its."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def swarm_summary(robots: int, seed: int, sites: int, extra: list[str]) -> dict[str, Any]:
    """The ``--json`` summary of one unrecorded ``swarm run`` (a result ending, or an error),
    with ``cpu_s``: the CPU seconds all of the run's processes used, start and stop
    included."""
    cpu = children_cpu()
    command = [
        *(sys.executable, "-m", "deploy.cli", "run", "--robots", str(robots)),
        *("--sites", str(sites), "--seed", str(seed), "--json", "--quiet", "--no-record"),
        *extra,
    ]
    done = subprocess.run(command, capture_output=True, cwd=REPO, timeout=7200)
    if done.returncode not in RESULT_CODES:
        raise RuntimeError(f"swarm run failed: {done.stderr.decode()[-2000:]}")
    return {**json.loads(done.stdout), "cpu_s": children_cpu() - cpu}


def swarm_run(
    robots: int, seed: int, sites: int, extra: list[str], record: Path | None = None
) -> dict[str, float]:
    output = ["--record", str(record)] if record is not None else ["--no-record"]
    command = [
        sys.executable,
        "-m",
        "deploy.cli",
        "run",
        "--robots",
        str(robots),
        "--sites",
        str(sites),
        "--seed",
        str(seed),
        "--json",
        "--quiet",
        *output,
        *extra,
    ]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, cwd=REPO, timeout=7200)
    total = time.perf_counter() - started
    if done.returncode not in RESULT_CODES:  # a timeout (exit 5) is a result here
        raise RuntimeError(f"swarm run failed: {done.stderr.decode()[-2000:]}")
    summary = json.loads(done.stdout)
    wall = summary["wall_time_s"]
    return {
        "rtf": summary["real_time_factor"],
        "wall": wall,
        "sim": summary["sim_time_s"],
        "sim_seen": summary["real_time_factor"] * wall,
        "overhead": total - wall,
        "correct": float(summary["correct"]),
        "timed_out": float(summary["timed_out"]),
    }


def to_consensus(args: argparse.Namespace, extra: list[str]) -> None:
    print("To consensus (lockstep, default robots per process):")
    print(
        f"{'robots':>6} {'RTF':>7} {'target':>7} {'wall s':>8} {'sim s':>8} "
        f"{'start+stop s':>12} {'correct':>7} {'floor RTF':>9} {'RTF/floor':>9}"
    )
    for robots in args.robots:
        runs = [swarm_run(robots, seed, args.sites, extra) for seed in args.seeds]
        rtf = statistics.fmean(run["rtf"] for run in runs)
        floor = 0.0 if args.no_floor else messaging_floor(robots, args.floor_ticks) * 0.1
        print(
            f"{robots:>6} {rtf:>6.1f}x {TARGETS.get(robots, 0):>6.0f}x "
            f"{statistics.fmean(r['wall'] for r in runs):>8.1f} "
            f"{statistics.fmean(r['sim'] for r in runs):>8.1f} "
            f"{statistics.fmean(r['overhead'] for r in runs):>12.1f} "
            f"{sum(r['correct'] for r in runs):>4.0f}/{len(runs):<2} "
            f"{floor:>8.0f}x {rtf / floor if floor else float('nan'):>9.2f}",
            flush=True,
        )
        if args.with_recording:
            with tempfile.TemporaryDirectory(prefix="swarm-speed-") as folder:
                recorded = [
                    swarm_run(robots, seed, args.sites, extra, Path(folder) / f"{seed}.mcap")
                    for seed in args.seeds
                ]
            recorded_rtf = statistics.fmean(run["rtf"] for run in recorded)
            print(
                f"{'':>6} {recorded_rtf:>6.1f}x  the same seeds recorded (the default): "
                f"{recorded_rtf / rtf:.2f} of the unrecorded real-time factor",
                flush=True,
            )


def scale_curve(args: argparse.Namespace, extra: list[str]) -> None:
    print(
        f"\nScale curve ({args.scale_sim:g} s of sim time each; 'hosted' = the default "
        "robots per process):"
    )
    print(f"{'robots':>6} {'processes':>10} {'RTF':>7} {'wall s / sim s':>14} {'start+stop s':>12}")
    for robots in args.scale:
        for mode in args.modes:
            per_process = ["--robots-per-process", "1"] if mode == "1" else []
            run = swarm_run(
                robots, 0, args.sites, [*per_process, "--timeout", str(args.scale_sim), *extra]
            )
            label = "1 per robot" if mode == "1" else "hosted"
            print(
                f"{robots:>6} {label:>10} {run['rtf']:>6.2f}x "
                f"{run['wall'] / max(run['sim_seen'], 1e-9):>14.3f} "
                f"{run['overhead']:>12.1f}",
                flush=True,
            )


def realtime_pacing(args: argparse.Namespace, extra: list[str]) -> None:
    """The real-time factor a wall-clock-paced run reaches against the speed asked."""
    robots = args.realtime_robots
    print(f"\nReal-time clock ({robots} robots, seed {args.seeds[0]}, to consensus):")
    print(f"{'asked':>7} {'RTF':>7} {'RTF/asked':>9} {'wall s':>8} {'sim s':>8}")
    for speed in args.realtime:
        run = swarm_run(
            robots,
            args.seeds[0],
            args.sites,
            ["--clock", "realtime", "--speed", f"{speed:g}", *extra],
        )
        print(
            f"{speed:>6g}x {run['rtf']:>6.2f}x {run['rtf'] / speed:>9.2f} "
            f"{run['wall']:>8.1f} {run['sim']:>8.1f}",
            flush=True,
        )


TABLE_BEGIN = "<!-- swarm_speed:engines -->"
TABLE_END = "<!-- /swarm_speed:engines -->"


def results_of(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Each robot's results, without where it was when the run stopped (over Zenoh the
    launcher notices the last decision a few ticks late, and the robots move on)."""
    return [{**robot, "phase": None} for robot in summary["per_robot"]]


def decisions_until(summary: dict[str, Any], cut: float) -> list[tuple[Any, ...]]:
    """Each robot's decision (site and sim time) if it came by ``cut`` sim seconds: what two
    runs stopped by --timeout at slightly different times can be compared on (over Zenoh
    the launcher notices the timeout a tick or two late, and robots decide in between)."""
    return [
        (robot["id"], robot["decided_site"], robot["decision_time_s"])
        if robot["decision_time_s"] is not None and robot["decision_time_s"] <= cut
        else (robot["id"], None, None)
        for robot in summary["per_robot"]
    ]


def engines(args: argparse.Namespace, extra: list[str]) -> list[str]:
    """In one process against over Zenoh, per swarm size: the markdown rows."""
    print(
        "\nIn-process engine against the distributed swarm (lockstep, the same seed; "
        f"sizes of {args.consensus_max} robots and fewer to consensus, larger ones for "
        f"{args.scale_sim:g} s of sim time):"
    )
    print(
        f"{'robots':>6} {'sim s':>7} {'in-process':>10} {'distributed':>11} {'ratio':>6} "
        f"{'CPU x':>6} {'floor':>7} {'dist/floor':>10} {'same results':>12}"
    )
    rows = []
    loads = [os.getloadavg()[0]]  # how busy the machine was: said under the table
    for robots in args.engines:
        limit = [] if robots <= args.consensus_max else ["--timeout", str(args.scale_sim)]
        options = [*limit, *extra]
        seed = args.seeds[0]
        # Alternating pairs, each pair's ratio measured back to back: on a shared machine
        # the load changes between pairs more than within one.
        fast_runs, slow_runs, ratios, same, stalls = [], [], [], True, 0
        pairs = []  # (in process, over Zenoh) summaries
        alone = ["--engine", "inprocess", *in_process_options(options)]
        for _ in range(args.pairs):
            in_process = swarm_summary(robots, seed, args.sites, alone)
            distributed = swarm_summary(robots, seed, args.sites, options)
            if limit:
                cut = min(in_process["sim_time_s"], distributed["sim_time_s"])
                agreed = decisions_until(in_process, cut) == decisions_until(distributed, cut)
            else:
                agreed = results_of(in_process) == results_of(distributed)
            same = same and agreed
            # A tick the world closed without a silent controller (--stall-timeout) breaks
            # lockstep's determinism: say so when the results differ.
            stalls += distributed["world"]["stalls"]
            fast_runs.append(in_process["real_time_factor"])
            slow_runs.append(distributed["real_time_factor"])
            ratios.append(slow_runs[-1] / fast_runs[-1])
            pairs.append((in_process, distributed))
            loads.append(os.getloadavg()[0])
        # CPU per sim second while ticking, over Zenoh / in one process: each run's CPU less
        # that of the same run stopped after its first tick (starting and stopping).
        first_tick = ["--timeout", str(pairs[0][0]["config"]["dt"]), *extra]
        start_stop = [
            swarm_summary(robots, seed, args.sites, options)["cpu_s"]
            for options in (
                ["--engine", "inprocess", *in_process_options(first_tick)],
                first_tick,
            )
        ]
        cpu_ratios = [
            ((distributed["cpu_s"] - start_stop[1]) / distributed["sim_time_s"])
            / ((in_process["cpu_s"] - start_stop[0]) / in_process["sim_time_s"])
            for in_process, distributed in pairs
        ]
        fast, slow = statistics.median(fast_runs), statistics.median(slow_runs)
        ratio = statistics.median(ratios)
        cpu_ratio = statistics.median(cpu_ratios)
        spread = f" ({min(ratios):.2f}-{max(ratios):.2f})" if len(ratios) > 1 else ""
        floor = 0.0
        if robots <= args.floor_max and not args.no_floor:
            floor = messaging_floor(robots, args.floor_ticks) * 0.1
        floor_text = f"{floor:.1f}x" if floor else "-"
        to_floor = f"{slow / floor:.2f}" if floor else "-"
        ended = "to consensus" if not limit else f"{args.scale_sim:g} s of sim time"
        agree = "yes" if same else f"no ({stalls} stalled ticks)"
        if limit and same:
            agree = "yes (decisions)"
        print(
            f"{robots:>6} {distributed['sim_time_s']:>7.1f} {fast:>9.1f}x {slow:>10.1f}x "
            f"{ratio:>6.2f}{spread} {cpu_ratio:>5.1f}x {floor_text:>7} {to_floor:>10} {agree:>12}",
            flush=True,
        )
        rows.append(
            f"| {robots} robots, seed {seed}, {ended} ({distributed['sim_time_s']:.0f} s) "
            f"| {fast:.1f}x | {slow:.1f}x | **{ratio:.2f}**{spread} | {cpu_ratio:.1f}x "
            f"| {floor_text} | {to_floor} | {agree} |"
        )
    args.loads = (min(loads), max(loads))
    return rows


def write_table(path: Path, rows: list[str], command: str, args: argparse.Namespace) -> None:
    """Replace the table between the page's markers with this run's."""
    table = [
        f"| swarm (lockstep, {args.sites} sites) | in one process | over Zenoh | ratio "
        "| CPU over Zenoh / in one process | messaging floor | over Zenoh / floor "
        "| same per-robot results |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
    ]
    low, high = args.loads
    note = (
        f"Written by `{command}` on {platform.machine()} Linux with {os.cpu_count()} cores, "
        f"{time.strftime('%Y-%m-%d')}, its 1-minute load average between {low:.0f} and "
        f"{high:.0f} while the table was measured (the runs' own processes count in it). "
        "Absolute real-time factors depend on the machine and its load; each ratio is of "
        "two runs measured back to back (with --pairs, the median of the pairs and their "
        "range). The CPU column divides the CPU time that all of a run's processes used per "
        "second of sim time while ticking (a run's CPU less that of the same run stopped "
        "after its first tick), over Zenoh by in one process: the distributed swarm, with "
        f"{os.cpu_count()} cores, cannot reach a ratio above {os.cpu_count()} / that figure. "
        f"{args.machine_note}"
    ).strip()
    if any("yes (decisions)" in row for row in rows):
        note += (
            " A run cut at a sim time is compared on its robots' decisions up to the earlier"
            " of the two stops (over Zenoh the launcher notices the limit a tick or two late)."
        )
    pages.write_between(path, TABLE_BEGIN, TABLE_END, f"{chr(10).join(table)}\n\n{note}")
    print(f"wrote the engines table into {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--robots",
        type=int,
        nargs="*",
        default=[10, 50, 100],
        help="swarm sizes to run to consensus",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--sites", type=int, default=10)
    parser.add_argument("--floor-ticks", type=int, default=300)
    parser.add_argument("--no-floor", action="store_true", help="skip the messaging baseline")
    parser.add_argument(
        "--with-recording",
        action="store_true",
        help="also run every seed recorded to MCAP, as `swarm run` does by default, and compare",
    )
    parser.add_argument(
        "--scale",
        type=int,
        nargs="*",
        default=[10, 50, 100, 200, 500],
        help="swarm sizes of the scale curve (fixed sim time)",
    )
    parser.add_argument(
        "--scale-sim", type=float, default=60.0, help="sim seconds per scale-curve run"
    )
    parser.add_argument(
        "--modes",
        nargs="+",
        default=["1", "hosted"],
        choices=["1", "hosted"],
        help="robots per process in the scale curve: 1, or the default",
    )
    parser.add_argument(
        "--engines",
        type=int,
        nargs="*",
        default=[10, 100],
        help="swarm sizes to run both in one process and over Zenoh (default: 10 100)",
    )
    parser.add_argument(
        "--pairs",
        type=int,
        default=1,
        help="engines: in-process and distributed runs of each size, alternating; the "
        "table shows the medians and the range of the pairs' ratios (default: 1)",
    )
    parser.add_argument(
        "--consensus-max",
        type=int,
        default=100,
        help="engines: larger swarms run for --scale-sim seconds, not to consensus",
    )
    parser.add_argument(
        "--floor-max",
        type=int,
        default=100,
        help="engines: no messaging floor above this many processes (default: 100)",
    )
    parser.add_argument(
        "--realtime",
        type=float,
        nargs="*",
        default=[25.0],
        help="speeds to run with the real-time clock (--clock realtime --speed X)",
    )
    parser.add_argument(
        "--realtime-robots",
        type=int,
        default=4,
        help="swarm size of the real-time clock runs (default: 4)",
    )
    parser.add_argument(
        "--doc",
        "--readme",
        dest="doc",
        type=Path,
        action="append",
        default=[],
        help="write the engines table into this page (docs/performance.md), between its "
        "swarm_speed:engines markers; repeat it for several pages (README.md too)",
    )
    parser.add_argument(
        "--machine-note", default="", help="said of the machine under the engines table"
    )
    parser.add_argument(
        "swarm_args", nargs=argparse.REMAINDER, help="extra `swarm run` options after --"
    )
    args = parser.parse_args()
    extra = [a for a in args.swarm_args if a != "--"]
    if args.robots:
        to_consensus(args, extra)
    if args.scale:
        scale_curve(args, extra)
    if args.realtime:
        realtime_pacing(args, extra)
    if args.engines:
        rows = engines(args, extra)
        if args.doc:
            shown = [arg for arg in sys.argv[1:] if arg != args.machine_note]
            shown = [arg for arg in shown if arg != "--machine-note"]
            command = "benchmarks/swarm_speed.py " + shlex.join(shown)
            for page in args.doc:
                write_table(page, rows, command, args)


if __name__ == "__main__":
    main()
