"""``swarm run``'s options, in the groups its help shows them (the exit codes of its
endings as the epilog).

Here rather than in ``deploy/launcher/``: ``swarm experiment`` parses each of its runs' options
with them before it starts any (``deploy/launcher/plan.py`` likewise), and a folder of the
layers may not import one that imports it back (tests/test_layering.py).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.wire import shape
from bestofn_swarm.wire.endings import exit_codes_help
from deploy.launcher.outside import add_outside_options
from deploy.launcher.plan import (
    ONE_PROCESS_PER_ROBOT_UP_TO,
    ROBOT_PROCESSES_PER_CORE,
    ROBOTS_PER_PROCESS,
)
from deploy.launcher.switches import add_swarm_switches
from deploy.viewer.options import add_view_options

ENGINES = ("zenoh", "inprocess")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = exit_codes_help()
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    swarm = parser.add_argument_group("swarm")
    cliargs.add_run_shape(swarm)
    add_engine_option(swarm)
    swarm.add_argument(
        "--run-id",
        type=cliargs.name,
        default=None,
        help="names this swarm on the network (default: run-<seed>-<time>)",
    )
    swarm.add_argument(
        "--timeout",
        type=cliargs.positive_float,
        default=shape.DEFAULT_TIMEOUT,
        metavar="SIM_SECONDS",
        help=f"give up after this much sim time (default: {shape.DEFAULT_TIMEOUT:g})",
    )
    swarm.add_argument(
        "--wall-timeout",
        type=cliargs.positive_float,
        default=None,
        metavar="SECONDS",
        help="give up after this much wall time since the launch, so that an unattended "
        "sweep cannot hang (default: no limit)",
    )
    swarm.add_argument(
        "--stall-window",
        type=cliargs.positive_float,
        default=None,
        metavar="SIM_SECONDS",
        help="end the run as stalled when, with some robot undecided, no robot at work "
        "completed a step of its task (reached or looked at a site, heard the beacon at the "
        "nest, pooled, decided; a decided robot: came closer to its parking slot, parked) "
        "for this much sim time (default: twice the time a robot may take for a leg across "
        "the arena, plus two arena crossings at full speed, plus every --beacon-outage that "
        "ends before --timeout)",
    )
    swarm.add_argument(
        "--world-stop-window",
        type=cliargs.positive_float,
        default=None,
        metavar="SECONDS",
        help="end the run as world_stopped when the world's clock has not advanced for this "
        "many wall seconds, whatever the sim clock says: the world server hung or the "
        "launcher lost it (default: twice the world's --stall-timeout plus 60 s; --engine "
        "inprocess: the world is the launcher's own loop, it cannot stop on its own)",
    )
    add_swarm_switches(parser)
    processes = parser.add_argument_group("processes")
    processes.add_argument(
        "--robots-per-process",
        type=cliargs.int_range(1, 1000),
        default=None,
        metavar="K",
        help="host K robots in each robot process, each robot still with its own Zenoh "
        f"session, keys and RNG (default: every robot its own process up to "
        f"{ONE_PROCESS_PER_ROBOT_UP_TO} robots; a larger swarm in {ROBOT_PROCESSES_PER_CORE} "
        f"processes per core of at least {ROBOTS_PER_PROCESS} robots each, which exchange "
        "one batch of senses and acts per tick with the world)",
    )
    processes.add_argument(
        "--no-batch",
        action="store_true",
        help="a process hosting several robots answers on each robot's own keys, one message "
        "per robot per tick, instead of one batch per tick (docs/protocol.md); for comparison",
    )
    processes.add_argument(
        "--spawn",
        choices=["fork", "exec"],
        default="fork",
        help="start robot processes by forking a preloaded server (fast) "
        "or as fresh interpreters (default: fork)",
    )
    processes.add_argument(
        "--dask",
        default=None,
        metavar="ADDRESS",
        help="place the robot processes on the workers of the Dask scheduler at ADDRESS "
        "(tcp://HOST:PORT), split by the workers' cores, each a client of its own host's "
        "Zenoh router (a worker's --router, else its host's $BESTOFN_ROUTER, else "
        "tcp/127.0.0.1:7447); the world, the beacon and the recorder run here, clients of "
        "--connect (default: this host's router, the same way). Needs Dask: pip install "
        "'.[dask]' (deploy/README.md)",
    )
    processes.add_argument(
        "--dask-world",
        default=None,
        metavar="WORKER",
        help="with --dask: run the world server and the beacon on this worker of the cluster "
        "(its name, address or host) instead of here; only it is handed the run secret",
    )
    network = parser.add_argument_group("network")
    network.add_argument(
        "--connect",
        type=cliargs.endpoint,
        default=None,
        metavar="ENDPOINT",
        help="use this existing Zenoh router instead of making the world "
        "server the router of the run (several runs can share one router)",
    )
    network.add_argument(
        "--secure",
        action="store_true",
        help="TLS on loopback with certificates made for this run, and Zenoh access "
        "control: each process may publish only on its own keys (docs/security.md)",
    )
    network.add_argument(
        "--no-keys",
        action="store_true",
        help="do not tag and check messages with run keys (every message is believed, "
        "as before run keys; for measuring what they cost)",
    )
    output = parser.add_argument_group("output")
    recording = output.add_mutually_exclusive_group()
    recording.add_argument(
        "--record",
        metavar="PATH",
        default=None,
        help="MCAP recording of the run (default: runs/<run-id>.mcap)",
    )
    recording.add_argument("--no-record", action="store_true", help="do not record the run")
    output.add_argument(
        "--json", action="store_true", help="print one JSON object with the summary on stdout"
    )
    output.add_argument("--quiet", action="store_true", help="no progress display")
    output.add_argument("--verbose", action="store_true", help="echo the processes' logs on stderr")
    output.add_argument(
        "--trace",
        type=Path,
        default=None,
        metavar="DIR",
        help="write each tick's timeline to DIR: world.jsonl from the world server, "
        "robot-<ids>.jsonl from each robot process (benchmarks/tick_timeline.py reads them; "
        "docs/performance.md)",
    )
    add_view_options(parser.add_argument_group("watching"))
    add_outside_options(parser)


def add_engine_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="zenoh",
        help="zenoh: every robot, the world and the beacon a process of their own, over "
        "Zenoh; inprocess: the same lockstep computation in one process, with the same "
        "summary and per-robot results, for sweeps (no network, no real-time clock, no "
        "robot faults, no live view) (default: zenoh)",
    )
