"""What a recorder process is configured with: the run it records (``RunDescription``,
which ``swarm run`` hands over as ``--config JSON``; by hand, its options are made from the
settings' own definitions), where to write, and how it yields the CPU."""

from __future__ import annotations

import argparse

from bestofn_swarm.plumbing import cliargs, settings_cli
from bestofn_swarm.plumbing.settings_cli import Options
from world_server.recording.description import RunDescription

# Nothing waits for the recorder, so it yields the CPU to the swarm: at nice 10 recording
# costs a 10-robot run 8% of its real-time factor instead of 21% (docs/recording.md).
DEFAULT_NICENESS = 10

RECORDER_OPTIONS = Options(RunDescription)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="recorder",
        description="Record every message of one run to an MCAP file (opens in Foxglove).",
    )
    parser.add_argument("--out", required=True, metavar="PATH", help="the MCAP file to write")
    RECORDER_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, RunDescription)
    parser.add_argument(
        "--info-timeout",
        type=cliargs.positive_float,
        default=10.0,
        help="wall seconds to wait for world/info (default: 10)",
    )
    parser.add_argument(
        "--niceness",
        type=cliargs.int_range(0, 19),
        default=DEFAULT_NICENESS,
        help="how much to lower this process's CPU priority, 0 to 19: "
        "recording is off the barrier's critical path, so on a busy "
        f"machine it yields to the swarm and catches up (default: "
        f"{DEFAULT_NICENESS})",
    )
    parser.add_argument(
        "--await-finish",
        action="store_true",
        help="close the file only when the launcher's finish query comes (swarm run, which "
        "hands the recorder its own summary), not when the run's ending is heard",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser
