"""Opening Zenoh sessions the same way in every process (an adapter, like robot_node.py).

Multicast scouting is always off: a local run is deterministic and sandbox-safe, and
multi-host swarms name their routers explicitly.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from pathlib import Path

import zenoh

from bestofn_swarm.plumbing.bounded_read import (
    CERTIFICATE_BYTES,
    CONFIG_FILE_BYTES,
    read_bounded,
    read_bounded_text,
)

# Small Zenoh thread pools: a machine may host hundreds of sessions' processes. Only
# set when the user has not chosen (an empty value makes zenoh panic).
os.environ.setdefault(
    "ZENOH_RUNTIME",
    "(app: (worker_threads: 1), acc: (worker_threads: 1), tx: (max_blocking_threads: 1),"
    " rx: (max_blocking_threads: 1), net: (worker_threads: 1))",
)


CONNECT_TIMEOUT_MS = 30_000


def read_config_file(config_file: str) -> zenoh.Config:
    """A Zenoh configuration file (JSON5, or YAML by its name), read with a size limit;
    ValueError (one line) if it cannot be read, is too big or is not a configuration."""
    text = read_bounded_text(config_file, CONFIG_FILE_BYTES, "Zenoh configuration")
    try:
        if Path(config_file).suffix in (".yaml", ".yml"):  # read again, now known to be small
            return zenoh.Config.from_file(config_file)
        return zenoh.Config.from_json5(text)
    except zenoh.ZError as error:
        reason = str(error).splitlines()[0] if str(error) else "invalid"
        raise ValueError(f"Zenoh configuration {config_file}: {reason}") from None


def check_config_files(
    parser: argparse.ArgumentParser, args: argparse.Namespace, robots: Sequence[int] = ()
) -> None:
    """A usage error (one line, exit code 2) unless ``--zenoh-config`` (each robot's,
    where ``{id}`` stands for its id) is a configuration that can be read."""
    config_file = args.zenoh_config
    if not config_file:
        return
    files = [config_file.replace("{id}", str(robot)) for robot in robots] or [config_file]
    for path in dict.fromkeys(files):
        try:
            read_config_file(path)
        except ValueError as error:
            parser.exit(2, f"{parser.prog}: error: {error}\n")


def make_config(
    mode: str | None = "client",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
) -> zenoh.Config:
    """ValueError (one line) for a configuration file that cannot be read."""
    config = read_config_file(config_file) if config_file else zenoh.Config()
    if mode is not None:
        config.insert_json5("mode", json.dumps(mode))
    if mode == "client" and not config_file:
        # Machines of a swarm come up in any order: keep trying the router for a while
        # (Zenoh's client default is a single attempt), then fail with a clear error.
        config.insert_json5("connect/timeout_ms", str(CONNECT_TIMEOUT_MS))
        config.insert_json5(
            "connect/retry",
            json.dumps({"period_init_ms": 200, "period_max_ms": 1000, "period_increase_factor": 2}),
        )
    if mode == "router":
        # Room for big swarms: every robot is its own session (Zenoh's default is 1000).
        config.insert_json5("transport/unicast/max_sessions", "100000")
    config.insert_json5("scouting/multicast/enabled", "false")
    # No shared-memory transport: every session would map its own segments, and a router
    # refuses sessions beyond about 350 on this kind of machine.
    config.insert_json5("transport/shared_memory/enabled", "false")
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return config


def open_session(
    mode: str | None = "client",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
) -> zenoh.Session:
    return zenoh.open(make_config(mode, connect, listen, config_file))


def session_mode(args: argparse.Namespace) -> str | None:
    """--mode if given; else the config file's mode; else the program's default."""
    if args.mode is not None:
        return str(args.mode)
    return None if args.zenoh_config else str(args.default_zenoh_mode)


def open_from_args(args: argparse.Namespace, robot: int | None = None) -> zenoh.Session:
    """A session from the options added by ``cliargs.add_zenoh_options``.

    For a hosted robot, ``{id}`` in the --zenoh-config path becomes its id.
    """
    config_file = args.zenoh_config
    if config_file and robot is not None:
        config_file = config_file.replace("{id}", str(robot))
    return open_session(session_mode(args), args.connect, args.listen, config_file)


def reliable_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher that blocks rather than drops under congestion.

    The body link (sense, act, camera) and the recorder must not lose messages: a lost
    ``sense`` would stall a lockstep tick, a lost status would corrupt a summary.
    """
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)


def reliable_put(
    session: zenoh.Session, key: str, payload: bytes, attachment: bytes | None = None
) -> None:
    session.put(
        key, payload, attachment=attachment, congestion_control=zenoh.CongestionControl.BLOCK
    )


def certificate_name(config_file: str) -> str | None:
    """The common name of the client certificate a Zenoh configuration file presents
    (``transport/link/tls/connect_certificate``), or None if it presents none."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    try:
        config = read_config_file(config_file)
        value = config.get_json("transport/link/tls/connect_certificate")
    except (zenoh.ZError, ValueError):
        return None
    path = json.loads(value) if value else None
    if not isinstance(path, str):
        return None
    try:
        pem = read_bounded(path, CERTIFICATE_BYTES, "certificate")
        certificate = x509.load_pem_x509_certificate(pem)
    except ValueError:
        return None
    names = certificate.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(names[0].value) if names else None
