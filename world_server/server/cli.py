"""``world-server``: the world of one run on Zenoh, from the command line.

By default the server is the Zenoh router of a local run: ``swarm run`` has it listen on a
Unix socket in a private directory (TLS on loopback with ``--secure``); started by hand it
listens on loopback TCP unless told otherwise. Its settings come from ``--config`` (what
``swarm run`` hands over) or its own options.

It ends the run (``world_server/observer/referee.py``): once the ending went out on
``world/ending``, it exits with the run's exit code, after ``ENDING_LINGER`` seconds in
which the ending reaches every process (it may be their router); with ``--until-stopped``
(``swarm run``, whose router it is) it serves on until a stop signal. A stop signal before
the ending ends the run as interrupted.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from collections.abc import Sequence

import msgspec
import zenoh

from bestofn_swarm.plumbing import cliargs, process_main, settings_cli
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.plumbing.trace import open_trace
from bestofn_swarm.plumbing.zenoh_session import open_from_args, session_mode
from world_server.core.world import World, WorldConfig
from world_server.observer.referee import Referee, RunShape
from world_server.server.options import WORLD_SERVER_OPTIONS, WorldServerConfig, world_server_config
from world_server.server.zenoh_adapter import WorldServer

log = logging.getLogger("world_server")

# Wall seconds a world server that ended its run stays, so that the ending reaches every
# process before its session (maybe their router) closes.
ENDING_LINGER = 1.0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="world-server",
        description="The world of one swarm: physics, cameras, the radio medium and the clock. "
        "By default it is the Zenoh router of a local run.",
    )
    WORLD_SERVER_OPTIONS.add_to(parser)
    settings_cli.add_config_option(parser, WorldServerConfig)
    parser.add_argument(
        "--trace",
        metavar="PATH",
        default=None,
        help="write a timeline of every tick to PATH as JSON lines: when it opened, when "
        "each answer arrived, how long the world's own work took (docs/performance.md)",
    )
    parser.add_argument(
        "--until-stopped",
        action="store_true",
        help="once the run ended, keep serving (routing, answering world/stats) until a stop "
        "signal, rather than exit with the run's exit code (swarm run, whose router the "
        "world server is, finishes the recording through it)",
    )
    cliargs.add_zenoh_options(parser, default_mode="router")
    cliargs.add_log_level(parser)
    return parser


def config_from_args(args: argparse.Namespace) -> WorldConfig:
    """The WorldConfig of ``world-server``'s options."""
    return world_server_config(args).world


def checked_config(parser: argparse.ArgumentParser, args: argparse.Namespace) -> WorldServerConfig:
    """The server's settings (``--config`` or its options), checked against ``--run-id``;
    by default a router listens on loopback."""
    config: WorldServerConfig = settings_cli.config_from(
        parser, args, WORLD_SERVER_OPTIONS, {"world.run": args.run_id}
    )
    if config.world.run != args.run_id:
        parser.exit(
            2,
            f"world-server: error: --config is of run {config.world.run!r}, "
            f"not --run-id {args.run_id!r}\n",
        )
    if session_mode(args) == "router" and not args.listen and not args.zenoh_config:
        args.listen = [cliargs.LOCAL_ENDPOINT]
    return config


def referee_of(config: WorldServerConfig, world: World) -> Referee:
    """The referee of the world's run; the summary's ``config`` is the world's settings."""
    shape = RunShape(
        run_id=config.world.run,
        seed=config.world.seed,
        num_robots=config.world.num_robots,
        num_sites=config.world.num_sites,
        best_site=world.layout.best_site,
        info=world.info,
        beacons=config.beacons,
    )
    recorded = WORLD_SERVER_OPTIONS.record(config)
    recorded.pop("controller", None)
    referee = Referee(shape, config.rules)
    referee.config = {
        **recorded,
        "run_id": config.world.run,
        "stall_window": referee.stall_window,
        "controller": msgspec.to_builtins(config.rules.controller),
    }
    return referee


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin(
        "world-server", parser, argv, checked_config, needs_secret="the world server"
    )
    args, config, keyring, keys = begun.args, begun.settings, begun.keyring, begun.keys
    world = World(config.world)
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"world-server: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    with session:
        server = WorldServer(
            session,
            world,
            keys,
            config=config,
            expect_robots=config.world.num_robots,
            expect_beacons=config.beacons,
            keyring=keyring,
            trace=open_trace(args.trace),
            referee=referee_of(config, world),
        )
        on_stop_signals(server.stop)
        log.info(
            "run %s: %d sites, arena radius %.2f m, best site %d, listening on %s",
            args.run_id,
            config.world.num_sites,
            world.layout.arena_radius,
            world.layout.best_site,
            ", ".join(args.listen) or "(client)",
        )
        # The loop runs in its own thread so that this one stays free for the signals.
        thread_result: list[int] = []
        worker = threading.Thread(target=lambda: thread_result.append(server.run()), daemon=True)
        worker.start()
        lingering = not args.until_stopped
        while worker.is_alive():
            if lingering and server.ended.wait(0.2):
                ending = server.ending
                assert ending is not None
                log.info("the run ended: %s (exit code %d)", ending.ended, ending.code)
                time.sleep(ENDING_LINGER)
                server.stop()
                lingering = False
            worker.join(0.0 if lingering else 0.2)
        server.undeclare()
        server.close_trace()
        code = thread_result[0] if thread_result else 1
    process_main.end(code)


if __name__ == "__main__":
    sys.exit(main())
