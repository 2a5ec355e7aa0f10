"""``swarm run --view [PORT] --view-host HOST --no-wait --view-linger S --foxglove [PORT]``:
the options, and the observer processes they ask the launcher to start (no server code is
imported here)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.wire.names import Role

VIEW_PORT = 8700
FOXGLOVE_PORT = 8765  # the Foxglove app's default for a WebSocket connection


@dataclass(frozen=True)
class Observer:
    """A process that watches the run and serves it: the page, or Foxglove."""

    name: str  # process name in the launcher's group; also its liveliness role
    module: str
    argv: list[str]
    url: str

    @property
    def role(self) -> Role:
        return Role(self.name)


def add_view_options(group: argparse._ArgumentGroup) -> None:
    group.add_argument(
        "--view",
        nargs="?",
        const=VIEW_PORT,
        default=None,
        type=cliargs.int_range(0, 65535),
        metavar="PORT",
        help=f"serve a live page of the run in the browser (default port {VIEW_PORT}; "
        "0: any free port); the swarm waits at tick 0 until a browser opens it, and the "
        "page stays up with the result after the run (Ctrl-C ends it)",
    )
    group.add_argument(
        "--no-wait",
        action="store_true",
        help="with --view: start the run at once, without waiting for a browser, and stop "
        "the page when the run ends (unless --view-linger)",
    )
    group.add_argument(
        "--view-linger",
        type=cliargs.float_range(0.0, 1e9),
        default=None,
        metavar="S",
        help="with --view: keep the page up S wall seconds after the run ends (default: "
        "until Ctrl-C; with --no-wait, 0)",
    )
    group.add_argument(
        "--view-host",
        default="127.0.0.1",
        metavar="HOST",
        help="address the page and Foxglove servers listen on (default: 127.0.0.1, this "
        "machine only; 0.0.0.0 opens them to the network)",
    )
    group.add_argument(
        "--foxglove",
        nargs="?",
        const=FOXGLOVE_PORT,
        default=None,
        type=cliargs.int_range(0, 65535),
        metavar="PORT",
        help="serve the run live to the Foxglove app over its WebSocket protocol, with the "
        f"recording's channels (default port {FOXGLOVE_PORT})",
    )


# They shape no run: kept out of its config.
VIEW_OPTIONS = {"view", "view_host", "no_wait", "view_linger", "foxglove"}


def holds(args: argparse.Namespace) -> bool:
    """Whether the run waits at tick 0 for the first browser on its live page."""
    return args.view is not None and not args.no_wait


def view_linger(args: argparse.Namespace) -> float | None:
    """Wall seconds the page stays up after the run ends (None: until stopped; 0: it ends
    with the run)."""
    if args.view is None:
        return 0.0
    if args.view_linger is not None:
        return float(args.view_linger)
    return 0.0 if args.no_wait else None


def observers(
    args: argparse.Namespace,
    common: list[str],
    free_port: int,
    free_port_2: int,
) -> list[Observer]:
    """The observers ``args`` ask for; port 0 becomes the free port given. Their network
    options (where to connect, which certificate) are added when the run starts."""
    host = args.view_host
    sizes = ["--robots", str(args.robots), "--sites", str(args.sites)]
    shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else host
    found = []
    if args.view is not None:
        port = args.view or free_port
        found.append(
            Observer(
                "viewer",
                "deploy.viewer.live",
                # The launcher finishes the page with its summary (viewer/finish).
                [*common, *sizes, "--host", host, "--port", str(port), "--await-finish"]
                + (["--hold"] if holds(args) else []),
                f"http://{shown}:{port}/",
            )
        )
    if args.foxglove is not None:
        port = args.foxglove or free_port_2
        found.append(
            Observer(
                "foxglove",
                "deploy.viewer.foxglove_live",
                [*common, *sizes, "--host", host, "--port", str(port)],
                f"ws://{shown}:{port}",
            )
        )
    return found
