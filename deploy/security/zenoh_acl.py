"""Who may speak: Zenoh TLS and access-control configurations for a multi-host swarm.

Every process of a secured swarm is a Zenoh client of its host's router over mutual TLS;
the certificate's common name is its identity (``robot-3``, ``world``, ``beacon-nest``,
``observer``, ``launcher``, ``recorder``, ``viewer``, ``foxglove``; routers use their host
name). The router's
access control denies by default and allows each identity exactly its part of the
protocol (bestofn_swarm/wire/protocol.py), so a robot can only publish its own ``act``,
``status`` and ``radio/tx/<id>`` and only the world server can publish ``sense``,
``camera`` and ``radio/rx``. See deploy/zenoh/README.md.

    python -m deploy.security.zenoh_acl --robots 10 --run-id run --ca ca.pem --ca-key ca.key \\
        --new-ca --out swarm-zenoh

writes ``routers/<router>.json5``, ``clients/<identity>.json5`` and, when the CA key is
given, a key and certificate per identity in ``certs/`` (deploy/security/certificates.py).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.bounded_read import CERTIFICATE_BYTES, read_bounded
from bestofn_swarm.plumbing.private_files import make_private_folder, write_private
from bestofn_swarm.wire import keyspace, names, protocol
from bestofn_swarm.wire.keyspace import Party
from bestofn_swarm.wire.names import Role
from deploy.security.certificates import create_ca, is_ip, issue_all

DEFAULT_PORT = cliargs.ZENOH_PORT
DEFAULT_ROUTER = "router"
# Certificate names of the processes that are neither robots nor beacons
# (bestofn_swarm/wire/names.py): the observers of swarm run --view and --foxglove are readers with a
# token (and the page a queryable) of their own; OBSERVER is any other reader.
OBSERVER, LAUNCHER, RECORDER, WORLD = names.OBSERVER, names.LAUNCHER, names.RECORDER, names.WORLD
VIEWER, FOXGLOVE = names.VIEWER, names.FOXGLOVE
# The bridge to robots outside the emulator: its own session publishes the links' figures;
# it speaks for each robot on a session with that robot's certificate.
BRIDGE = names.BRIDGE
# Zenoh 1.10's ACL message types (the config parser rejects any other name).
ALL_MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
)
_HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,62}[A-Za-z0-9])?")


@dataclass(frozen=True)
class SwarmPlan:
    """Who takes part in one secured run: the identities the router will know."""

    keys: keyspace.Keys
    robots: tuple[int, ...]
    beacons: tuple[str, ...] = (names.DEFAULT_BEACON,)
    routers: tuple[str, ...] = (DEFAULT_ROUTER,)
    port: int = DEFAULT_PORT

    def __post_init__(self) -> None:
        if len(set(self.robots)) != len(self.robots) or any(
            not 0 <= robot < names.MAX_ROBOTS for robot in self.robots
        ):
            raise ValueError(f"robot ids must be distinct and in [0, {names.MAX_ROBOTS})")
        for beacon in self.beacons:
            names.check_beacon_name(beacon)
        if len(set(self.beacons)) != len(self.beacons):
            raise ValueError("each beacon name may be given once")
        clients = set(self.client_identities())
        for router in self.routers:
            if not _HOST_NAME.fullmatch(router) and not is_ip(router):
                raise ValueError(f"router name {router!r} is not a host name or IP address")
            # A router's certificate grants everything: it must not name a client too.
            if router in clients:
                raise ValueError(f"router name {router!r} is also a client identity")
        if not self.routers or len(set(self.routers)) != len(self.routers):
            raise ValueError("give at least one router, each name once")
        if not 0 < self.port < 65536:
            raise ValueError(f"port {self.port} is outside [1, 65535]")

    def client_identities(self) -> list[str]:
        return [
            WORLD,
            *(names.robot_certificate(robot) for robot in self.robots),
            *(names.beacon_certificate(beacon) for beacon in self.beacons),
            OBSERVER,
            LAUNCHER,
            RECORDER,
            VIEWER,
            FOXGLOVE,
            BRIDGE,
        ]


# --- access control ------------------------------------------------------------------


# Who may say what, from the key table (bestofn_swarm/wire/keyspace.py): the kinds each party
# publishes, and the kinds the world sends each robot or beacon alone.
WORLD_SPEAKS = keyspace.published_by(Party.WORLD)
ROBOT_SPEAKS = keyspace.published_by(Party.ROBOT, Party.HOST, Party.SENDER)
ROBOT_HEARS = keyspace.inputs_of(Party.ROBOT, Party.HOST, Party.RECEIVER)
BEACON_SPEAKS = keyspace.published_by(Party.BEACON, Party.SENDER)
BEACON_HEARS = keyspace.inputs_of(Party.BEACON)
LAUNCHER_SPEAKS = keyspace.published_by(Party.LAUNCHER)
BRIDGE_SPEAKS = keyspace.published_by(Party.BRIDGE)
VIEWER_SPEAKS = keyspace.published_by(Party.VIEWER)


def _rule(
    rule_id: str, flow: str, messages: Sequence[str], key_exprs: Sequence[str]
) -> dict[str, Any]:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": [flow],
        "messages": list(messages),
        "key_exprs": list(key_exprs),
    }


def access_control(plan: SwarmPlan) -> dict[str, Any]:
    """The router's ``access_control`` section: deny by default, allow each role its keys.

    A router checks a message twice: ``ingress`` rules of the identity it comes from
    (may it say this?) and ``egress`` rules of the identity it goes to (may it hear
    this?). Rules only allow, so the deny-by-default decides everything else; rule key
    expressions must include a message's key (a wider subscription is not matched).
    """
    keys = plan.keys
    everything = [keys.all]
    world_services = [keys.of(keyspace.INFO), keys.of(keyspace.STATS)]
    finishes = [keys.of(keyspace.RECORDER_FINISH), keys.of(keyspace.VIEWER_FINISH)]
    rules: list[dict[str, Any]] = [
        # Watching: subscribe to anything of the run, see who is alive, read world services.
        _rule(
            "read-subscribe",
            "ingress",
            ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            everything,
        ),
        _rule("read-receive", "egress", ["put", "liveliness_token"], everything),
        # Everyone may learn who subscribes: a declared publisher sends nothing until its
        # router has told it of a matching subscriber (Zenoh's write-side filtering).
        _rule("discover-subscribers", "egress", ["declare_subscriber"], everything),
        _rule("read-query", "ingress", ["query"], world_services),
        _rule("read-answer", "egress", ["reply"], world_services),
        # A robot (and the beacon) asks for the map ...
        _rule("robot-query-info", "ingress", ["query"], [keys.of(keyspace.INFO)]),
        _rule("robot-answer-info", "egress", ["reply"], [keys.of(keyspace.INFO)]),
        # ... and follows the world server's liveliness, to notice a restarted world.
        _rule(
            "follow-world",
            "ingress",
            ["declare_liveliness_subscriber", "liveliness_query"],
            [keys.token(Role.WORLD, "*")],
        ),
        _rule("follow-world-token", "egress", ["liveliness_token"], [keys.token(Role.WORLD, "*")]),
        # Every process hears how the run ended, and exits.
        _rule("hear-ending", "ingress", ["declare_subscriber"], [keys.of(keyspace.ENDING)]),
        _rule("hear-ending-put", "egress", ["put"], [keys.of(keyspace.ENDING)]),
        # The world server: the robots' bodies, the radio medium, the clock.
        _rule("world-speak", "ingress", ["put"], keyspace.keys_for(keys, WORLD_SPEAKS)),
        _rule("world-alive", "ingress", ["liveliness_token"], [keys.token(Role.WORLD, "*")]),
        _rule("world-serve", "ingress", ["declare_queryable", "reply"], world_services),
        _rule("world-asked", "egress", ["query"], world_services),
        # The launcher relays process logs and asks the recorder and the page to finish.
        _rule("launcher-log", "ingress", ["put"], keyspace.keys_for(keys, LAUNCHER_SPEAKS)),
        _rule("launcher-finish", "ingress", ["query"], finishes),
        _rule("launcher-finished", "egress", ["reply"], finishes),
        # The recorder answers the finish query once its file is complete.
        _rule(
            "recorder-serve",
            "ingress",
            ["declare_queryable", "reply"],
            [keys.of(keyspace.RECORDER_FINISH)],
        ),
        _rule("recorder-alive", "ingress", ["liveliness_token"], [keys.token(Role.RECORDER, "*")]),
        _rule("recorder-asked", "egress", ["query"], [keys.of(keyspace.RECORDER_FINISH)]),
        # The page answers its finish query once every page was sent how the run ended.
        _rule(
            "viewer-serve",
            "ingress",
            ["declare_queryable", "reply"],
            [keys.of(keyspace.VIEWER_FINISH)],
        ),
        _rule("viewer-alive", "ingress", ["liveliness_token"], [keys.token(Role.VIEWER, 0)]),
        # ... and says the page's pause, play and speed to the world.
        _rule("viewer-speak", "ingress", ["put"], keyspace.keys_for(keys, VIEWER_SPEAKS)),
        _rule("viewer-asked", "egress", ["query"], [keys.of(keyspace.VIEWER_FINISH)]),
        # Foxglove live only listens, and says it serves.
        _rule("foxglove-alive", "ingress", ["liveliness_token"], [keys.token(Role.FOXGLOVE, 0)]),
        # The bridge publishes its links' figures and says it serves.
        _rule("bridge-speak", "ingress", ["put"], keyspace.keys_for(keys, BRIDGE_SPEAKS)),
        _rule("bridge-alive", "ingress", ["liveliness_token"], [keys.token(Role.BRIDGE, 0)]),
        # Routers of the other hosts relay everyone's traffic; each checks its own clients.
        _rule("router-relay-in", "ingress", ALL_MESSAGES, everything),
        _rule("router-relay-out", "egress", ALL_MESSAGES, everything),
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def grant(subject: str, rule_ids: Sequence[str], common_names: Sequence[str]) -> None:
        subjects.append(
            {
                "id": subject,
                "cert_common_names": list(common_names),
                "link_protocols": ["tls"],
            }
        )
        policies.append({"id": subject, "rules": list(rule_ids), "subjects": [subject]})

    def grant_client(identity: str, rule_ids: Sequence[str]) -> None:
        grant(identity, [*rule_ids, "discover-subscribers"], [identity])

    reading = ["read-subscribe", "read-receive", "read-query", "read-answer"]
    grant_client(WORLD, ["world-speak", "world-alive", "world-serve", "world-asked", *reading])
    for robot in plan.robots:
        identity, name = names.robot_certificate(robot), names.robot_name(robot)
        # A robot may lead a process hosting several: its session then carries their
        # senses and acts as batches (each entry sealed with its own robot's key).
        own_inputs = keyspace.keys_for(keys, ROBOT_HEARS, name)
        rules += [
            _rule(
                f"{identity}-speak", "ingress", ["put"], keyspace.keys_for(keys, ROBOT_SPEAKS, name)
            ),
            _rule(
                f"{identity}-alive",
                "ingress",
                ["liveliness_token"],
                [keys.token(Role.ROBOT, robot)],
            ),
            _rule(f"{identity}-subscribe", "ingress", ["declare_subscriber"], own_inputs),
            _rule(f"{identity}-receive", "egress", ["put"], own_inputs),
        ]
        grant_client(
            identity,
            [
                f"{identity}-speak",
                f"{identity}-alive",
                f"{identity}-subscribe",
                f"{identity}-receive",
                "robot-query-info",
                "robot-answer-info",
                "follow-world",
                "follow-world-token",
                "hear-ending",
                "hear-ending-put",
            ],
        )
    for beacon in plan.beacons:
        identity = names.beacon_certificate(beacon)
        rules += [
            _rule(
                f"{identity}-speak",
                "ingress",
                ["put"],
                keyspace.keys_for(keys, BEACON_SPEAKS, beacon),
            ),
            _rule(
                f"{identity}-alive",
                "ingress",
                ["liveliness_token"],
                [keys.token(Role.BEACON, beacon)],
            ),
            # Each beacon hears its own clock: the ticks it answers.
            _rule(
                f"{identity}-subscribe-clock",
                "ingress",
                ["declare_subscriber"],
                keyspace.keys_for(keys, BEACON_HEARS, beacon),
            ),
            _rule(
                f"{identity}-receive-clock",
                "egress",
                ["put"],
                keyspace.keys_for(keys, BEACON_HEARS, beacon),
            ),
        ]
        grant_client(
            identity,
            [
                f"{identity}-speak",
                f"{identity}-alive",
                f"{identity}-subscribe-clock",
                f"{identity}-receive-clock",
                "robot-query-info",
                "robot-answer-info",
                "follow-world",
                "follow-world-token",
                "hear-ending",
                "hear-ending-put",
            ],
        )
    grant_client(OBSERVER, reading)
    grant_client(LAUNCHER, [*reading, "launcher-log", "launcher-finish", "launcher-finished"])
    grant_client(RECORDER, [*reading, "recorder-serve", "recorder-asked", "recorder-alive"])
    grant_client(VIEWER, [*reading, "viewer-serve", "viewer-asked", "viewer-alive", "viewer-speak"])
    grant_client(FOXGLOVE, [*reading, "foxglove-alive"])
    grant_client(
        BRIDGE,
        [
            "bridge-speak",
            "bridge-alive",
            "follow-world",
            "follow-world-token",
            "hear-ending",
            "hear-ending-put",
        ],
    )
    grant("routers", ["router-relay-in", "router-relay-out"], plan.routers)
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


# --- configurations ------------------------------------------------------------------


def _certificate_paths(cert_dir: PurePath, identity: str) -> tuple[str, str]:
    return str(cert_dir / f"{identity}.key"), str(cert_dir / f"{identity}.pem")


def router_config(plan: SwarmPlan, router: str, cert_dir: PurePath) -> dict[str, Any]:
    """A router that accepts only mutual-TLS clients and enforces ``access_control``."""
    if router not in plan.routers:
        raise ValueError(f"{router!r} is not one of the plan's routers {plan.routers}")
    key, certificate = _certificate_paths(cert_dir, router)
    others = [
        f"tls/{_host_in_endpoint(other)}:{plan.port}" for other in plan.routers if other != router
    ]
    # Its own host's clients come on loopback; only with other routers does it also
    # listen on the address they reach it by (never on every interface).
    listen = [f"tls/127.0.0.1:{plan.port}"]
    if others:
        listen.append(f"tls/{_host_in_endpoint(router)}:{plan.port}")
    return {
        "mode": "router",
        "listen": {"endpoints": listen},
        "connect": {"endpoints": others},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": ["tls"],
                "tls": {
                    "root_ca_certificate": str(cert_dir / "ca.pem"),
                    "listen_private_key": key,
                    "listen_certificate": certificate,
                    "enable_mtls": True,
                    # Its own identity when it connects to the other hosts' routers.
                    "connect_private_key": key,
                    "connect_certificate": certificate,
                    "verify_name_on_connect": True,
                    "close_link_on_expiration": True,
                },
            }
        },
        "access_control": access_control(plan),
    }


def client_config(plan: SwarmPlan, identity: str, cert_dir: PurePath) -> dict[str, Any]:
    """A process's client session: mutual TLS to its host's router, nothing else."""
    if identity not in plan.client_identities():
        raise ValueError(f"{identity!r} is not one of the plan's identities")
    key, certificate = _certificate_paths(cert_dir, identity)
    return {
        "mode": "client",
        "connect": {"endpoints": [f"tls/127.0.0.1:{plan.port}"]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {
                "protocols": ["tls"],
                "tls": {
                    "root_ca_certificate": str(cert_dir / "ca.pem"),
                    "enable_mtls": True,
                    "connect_private_key": key,
                    "connect_certificate": certificate,
                    "verify_name_on_connect": True,
                },
            }
        },
    }


def render(config: dict[str, Any], title: str) -> str:
    """JSON5 text (plain JSON, which is JSON5) with a comment saying where it came from."""
    header = (
        f"// {title}\n"
        "// Written by `python -m deploy.security.zenoh_acl`; see deploy/zenoh/README.md.\n"
    )
    return header + _json(config, 0) + "\n"


def _json(value: Any, depth: int) -> str:
    """Indented JSON that keeps short lists of plain values on one line, to stay readable."""
    inner = "  " * (depth + 1)
    if isinstance(value, dict) and value:
        items = [
            f"{inner}{json.dumps(key)}: {_json(item, depth + 1)}" for key, item in value.items()
        ]
        return "{\n" + ",\n".join(items) + "\n" + "  " * depth + "}"
    if isinstance(value, list) and value:
        one_line = json.dumps(value)
        if len(inner) + len(one_line) <= 90 and not any(
            isinstance(item, dict | list) for item in value
        ):
            return one_line
        return (
            "[\n"
            + ",\n".join(inner + _json(item, depth + 1) for item in value)
            + "\n"
            + "  " * depth
            + "]"
        )
    return json.dumps(value)


def plan_title(plan: SwarmPlan) -> str:
    return (
        f"run {plan.keys.prefix}: {len(plan.robots)} robot(s), "
        f"beacon(s) {', '.join(plan.beacons) or 'none'}"
    )


def write_configs(plan: SwarmPlan, out: Path, cert_dir: PurePath) -> list[Path]:
    """Write ``routers/<router>.json5`` and ``clients/<identity>.json5`` under ``out``."""
    written = []
    for folder, identities, make in (
        ("routers", plan.routers, router_config),
        ("clients", plan.client_identities(), client_config),
    ):
        make_private_folder(out / folder)
        for name in identities:
            path = out / folder / f"{name}.json5"
            write_private(path, render(make(plan, name, cert_dir), f"{name}, {plan_title(plan)}"))
            written.append(path)
    return written


def _host_in_endpoint(host: str) -> str:
    return f"[{host}]" if is_ip(host) and ":" in host else host


# --- command line --------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m deploy.security.zenoh_acl",
        description="Write Zenoh router and client configurations (mutual TLS, access "
        "control) for one swarm run and, given the CA key, issue its certificates.",
    )
    parser.add_argument(
        "--robots",
        type=cliargs.int_range(1, names.MAX_ROBOTS),
        required=True,
        help="number of robots (ids 0 to N-1)",
    )
    parser.add_argument(
        "--run-id", type=cliargs.name, required=True, help="the run id the processes use (--run-id)"
    )
    parser.add_argument(
        "--root",
        type=cliargs.name,
        default=protocol.DEFAULT_ROOT,
        help=f"key expression root (default: {protocol.DEFAULT_ROOT})",
    )
    parser.add_argument(
        "--beacon",
        dest="beacons",
        action="append",
        type=cliargs.name,
        metavar="NAME",
        help=f"a nest beacon's name (repeatable; default: {names.DEFAULT_BEACON})",
    )
    parser.add_argument(
        "--router",
        dest="routers",
        action="append",
        metavar="HOST",
        help="host name or IP address of a host's router; routers connect "
        f"to each other (repeatable; default: one named {DEFAULT_ROUTER})",
    )
    parser.add_argument(
        "--port",
        type=cliargs.int_range(1, 65535),
        default=DEFAULT_PORT,
        help=f"routers' TLS port (default: {DEFAULT_PORT})",
    )
    parser.add_argument(
        "--ca",
        type=Path,
        required=True,
        metavar="FILE",
        help="the certificate authority's certificate (PEM)",
    )
    parser.add_argument(
        "--ca-key",
        type=Path,
        metavar="FILE",
        help="the CA's private key: issue a key and certificate for every identity into OUT/certs",
    )
    parser.add_argument(
        "--new-ca",
        action="store_true",
        help="first create the CA at --ca and --ca-key (never overwrites)",
    )
    parser.add_argument(
        "--days",
        type=cliargs.int_range(1, 36500),
        default=365,
        help="validity of new certificates in days (default: 365)",
    )
    parser.add_argument(
        "--cert-dir",
        type=PurePath,
        metavar="DIR",
        help="where the certificates are on the hosts that run the processes, "
        "as the configurations name them (default: OUT/certs)",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.new_ca and args.ca_key is None:
        parser.error("--new-ca needs --ca-key")
    try:
        plan = SwarmPlan(
            keys=keyspace.Keys(args.run_id, args.root),
            robots=tuple(range(args.robots)),
            beacons=tuple(args.beacons or [names.DEFAULT_BEACON]),
            routers=tuple(args.routers or [DEFAULT_ROUTER]),
            port=args.port,
        )
    except ValueError as error:
        parser.error(str(error))
    out: Path = args.out
    local_certs = out / "certs"
    try:
        if args.new_ca:
            create_ca(args.ca, args.ca_key, days=args.days)
        if args.ca_key is not None:
            issue_all(
                plan.routers,
                plan.client_identities(),
                args.ca,
                args.ca_key,
                local_certs,
                days=args.days,
            )
        elif not args.ca.is_file():
            parser.error(f"no CA certificate at {args.ca} (create one with --new-ca)")
        else:
            make_private_folder(local_certs)
            write_private(local_certs / "ca.pem", read_bounded(args.ca, CERTIFICATE_BYTES))
        cert_dir = args.cert_dir or PurePath(os.path.abspath(local_certs))
        written = write_configs(plan, out, cert_dir)
    except ValueError as error:  # a CA file that cannot be read, or is no CA
        print(f"zenoh_acl: error: {error}", file=sys.stderr)
        return 2
    except (OSError, RuntimeError) as error:
        print(f"zenoh_acl: error: {error}", file=sys.stderr)
        return 1
    issued = "certificates in " + str(local_certs) if args.ca_key else "no certificates issued"
    print(f"wrote {len(written)} configurations under {out} ({issued})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
