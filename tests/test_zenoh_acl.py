"""Who may speak: a TLS router with the generated access control, and clients against it.

Certificates are made in a temporary directory (the cryptography package); the router is a
Python Zenoh session in router mode in a subprocess on a free loopback TLS port, killed
by pid; every client opens through ``bestofn_swarm.plumbing.zenoh_session`` with
``--zenoh-config``'s code path (multicast scouting off).
"""

from __future__ import annotations

import json
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePath

import pytest
import zenoh

from bestofn_swarm.plumbing import run_keys, zenoh_session
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.names import Role
from deploy.launcher.processes import python_module
from deploy.security import certificates, zenoh_acl
from world_server.core.layout import make_layout

REPO = Path(__file__).resolve().parent.parent
TEMPLATES = REPO / "deploy" / "zenoh"
RUN = "acl-test"
KEYS = keyspace.Keys(RUN)
ROBOTS = 3  # ids 0, 1, 2
WAIT = 5.0  # seconds: the hard limit on any expected delivery
SETTLE = 0.3  # seconds given to a forbidden message to show up after its sentinel

ROUTER_SCRIPT = """
import sys
from bestofn_swarm.plumbing import zenoh_session
session = zenoh_session.open_session("router", listen=[sys.argv[2]], config_file=sys.argv[1])
print("ready", flush=True)
sys.stdin.read()  # serve until the test closes stdin (or kills this process)
session.close()
"""


@dataclass(frozen=True)
class Swarm:
    out: Path
    endpoint: str
    rogue_certs: Path  # robot-1's key and certificate from another CA

    def client_config(self, identity: str) -> Path:
        return self.out / "clients" / f"{identity}.json5"

    def open(self, identity: str) -> zenoh.Session:
        return self.open_with(self.client_config(identity))

    def open_with(self, config_file: Path) -> zenoh.Session:
        return zenoh_session.open_session(
            "client", connect=[self.endpoint], config_file=str(config_file)
        )


def free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.fixture(scope="module")
def swarm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Swarm]:
    base = tmp_path_factory.mktemp("zenoh-acl")
    out, ca = base / "out", base / "ca"
    assert (
        zenoh_acl.main(
            [
                "--robots",
                str(ROBOTS),
                "--run-id",
                RUN,
                "--ca",
                str(ca / "ca.pem"),
                "--ca-key",
                str(ca / "ca.key"),
                "--new-ca",
                "--days",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rogue = base / "rogue"
    certificates.create_ca(rogue / "ca.pem", rogue / "ca.key", days=2)
    certificates.issue_certificate(rogue / "ca.pem", rogue / "ca.key", "robot-1", rogue, days=2)

    endpoint = f"tls/127.0.0.1:{free_loopback_port()}"
    router = subprocess.Popen(
        [sys.executable, "-c", ROUTER_SCRIPT, str(out / "routers" / "router.json5"), endpoint],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        assert router.stdout is not None
        ready, _, _ = select.select([router.stdout], [], [], 20.0)
        if not ready or router.stdout.readline().strip() != b"ready":
            router.kill()
            _, errors = router.communicate(timeout=5)
            pytest.fail(f"the router did not start: {errors.decode(errors='replace')[-2000:]}")
        yield Swarm(out, endpoint, rogue)
    finally:
        router.kill()
        router.wait(timeout=5)


class Inbox:
    """What a session received, by key, with a wait for one key."""

    def __init__(self) -> None:
        self.received: list[tuple[str, bytes]] = []
        self._changed = threading.Condition()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self._changed:
            self.received.append((str(sample.key_expr), sample.payload.to_bytes()))
            self._changed.notify_all()

    def heard_keys(self) -> set[str]:
        with self._changed:
            return {key for key, _ in self.received}

    def wait_for(self, key: str) -> None:
        with self._changed:
            if not self._changed.wait_for(lambda: key in {k for k, _ in self.received}, WAIT):
                pytest.fail(f"{key} did not arrive within {WAIT} s; got {self.heard_keys()}")


def until(condition: Callable[[], bool]) -> bool:
    """Poll ``condition`` for up to WAIT seconds (a subscription takes a moment to spread)."""
    deadline = time.monotonic() + WAIT
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def put_until_heard(speaker: zenoh.Session | zenoh.Publisher, key: str, inbox: Inbox) -> None:
    """Repeat an allowed put until it arrives: the subscriber's declaration has then spread."""

    def probe() -> bool:
        if isinstance(speaker, zenoh.Publisher):
            speaker.put(b"probe")
        else:
            speaker.put(key, b"probe")
        return key in inbox.heard_keys()

    assert until(probe), key


# --- who may connect -----------------------------------------------------------------


@pytest.mark.timeout(30)
def test_a_client_needs_a_certificate_from_the_swarm_ca(swarm: Swarm, tmp_path: Path) -> None:
    with swarm.open("world") as session:  # the same endpoint accepts a proper identity
        assert str(session.info.zid())

    plan = zenoh_acl.SwarmPlan(KEYS, tuple(range(ROBOTS)))
    anonymous = zenoh_acl.client_config(plan, "world", PurePath(swarm.out / "certs"))
    tls = anonymous["transport"]["link"]["tls"]
    del tls["connect_private_key"], tls["connect_certificate"]
    (tmp_path / "anonymous.json5").write_text(json.dumps(anonymous))
    with pytest.raises(zenoh.ZError):
        swarm.open_with(tmp_path / "anonymous.json5")

    impostor = zenoh_acl.client_config(plan, "robot-1", PurePath(swarm.out / "certs"))
    impostor["transport"]["link"]["tls"].update(
        connect_private_key=str(swarm.rogue_certs / "robot-1.key"),
        connect_certificate=str(swarm.rogue_certs / "robot-1.pem"),
    )
    (tmp_path / "impostor.json5").write_text(json.dumps(impostor))
    with pytest.raises(zenoh.ZError):
        swarm.open_with(tmp_path / "impostor.json5")


# --- who may speak -------------------------------------------------------------------


@pytest.mark.timeout(30)
def test_a_robot_speaks_on_its_own_keys_and_asks_for_the_map(swarm: Swarm) -> None:
    heard, alive = Inbox(), Inbox()
    with swarm.open("world") as world, swarm.open("robot-1") as robot:
        world.declare_subscriber(KEYS.all, heard)
        world.liveliness().declare_subscriber(f"{KEYS.prefix}/alive/**", alive, history=True)
        world.declare_queryable(
            KEYS.of(keyspace.INFO), lambda query: query.reply(KEYS.of(keyspace.INFO), b"map")
        )
        # Declared publishers, as the robot process has: each sends only once its router
        # has told it of a matching subscriber, which the access control must allow.
        own = {
            KEYS.of(keyspace.ACT, 1): b"act",
            KEYS.of(keyspace.STATUS, 1): b"status",
            KEYS.of(keyspace.RADIO_TX, 1): b"tx",
        }
        publishers = {key: zenoh_session.reliable_publisher(robot, key) for key in own}
        put_until_heard(publishers[KEYS.of(keyspace.ACT, 1)], KEYS.of(keyspace.ACT, 1), heard)
        for key, payload in own.items():
            publishers[key].put(payload)
        token = robot.liveliness().declare_token(KEYS.token(Role.ROBOT, 1))
        for key in own:
            heard.wait_for(key)
        alive.wait_for(KEYS.token(Role.ROBOT, 1))
        assert {key: payload for key, payload in heard.received if key in own} == own

        replies = list(robot.get(KEYS.of(keyspace.INFO), timeout=WAIT))
        assert [reply.ok.payload.to_bytes() for reply in replies if reply.ok] == [b"map"]
        token.undeclare()


@pytest.mark.timeout(30)
def test_a_robot_cannot_speak_for_another_robot_or_the_world(swarm: Swarm) -> None:
    heard, alive = Inbox(), Inbox()
    with swarm.open("world") as world, swarm.open("robot-1") as robot:
        world.declare_subscriber(KEYS.all, heard)
        world.liveliness().declare_subscriber(f"{KEYS.prefix}/alive/**", alive, history=True)
        put_until_heard(robot, KEYS.of(keyspace.STATUS, 1), heard)

        forbidden = [
            KEYS.of(keyspace.ACT, 2),
            KEYS.of(keyspace.STATUS, 2),
            KEYS.of(keyspace.RADIO_TX, 2),  # another robot's
            KEYS.of(keyspace.HOST_ACT, 2),  # the batch of another robot's process
            KEYS.of(keyspace.SENSE, 1),
            KEYS.of(keyspace.HOST_SENSE, 1),
            KEYS.of(keyspace.CAMERA, 1),
            KEYS.of(keyspace.RADIO_RX, 1),
            KEYS.of(keyspace.CLOCK),  # the world's
            KEYS.of(keyspace.ACK, "nest"),
            KEYS.of(keyspace.LOG, "robot-1"),
        ]
        for key in forbidden:  # session puts: they reach the router whoever subscribes
            robot.put(key, b"spoofed")
        spoofed_token = robot.liveliness().declare_token(KEYS.token(Role.ROBOT, 2))
        own_token = robot.liveliness().declare_token(KEYS.token(Role.ROBOT, 1))
        robot.put(KEYS.of(keyspace.HOST_ACT, 1), b"batch")  # the acts of the process it leads
        robot.put(
            KEYS.of(keyspace.ACT, 1), b"sentinel"
        )  # sent after the forbidden ones, on the same link
        heard.wait_for(KEYS.of(keyspace.ACT, 1))
        alive.wait_for(KEYS.token(Role.ROBOT, 1))
        time.sleep(SETTLE)
        assert heard.heard_keys() == {
            KEYS.of(keyspace.STATUS, 1),
            KEYS.of(keyspace.HOST_ACT, 1),
            KEYS.of(keyspace.ACT, 1),
        }
        assert alive.heard_keys() == {KEYS.token(Role.ROBOT, 1)}
        spoofed_token.undeclare()
        own_token.undeclare()


@pytest.mark.timeout(30)
def test_an_observer_only_listens(swarm: Swarm) -> None:
    heard, watched = Inbox(), Inbox()
    with swarm.open("world") as world, swarm.open("observer") as observer:
        world.declare_subscriber(KEYS.all, heard)
        observer.declare_subscriber(KEYS.all, watched)
        put_until_heard(world, KEYS.of(keyspace.CLOCK), watched)
        for key in (
            KEYS.of(keyspace.ACT, 0),
            KEYS.of(keyspace.STATUS, 0),
            KEYS.of(keyspace.CLOCK),
            KEYS.of(keyspace.LOG, "observer"),
        ):
            observer.put(key, b"spoofed")
        world.put(KEYS.of(keyspace.STATE), b"sentinel")
        watched.wait_for(KEYS.of(keyspace.STATE))
        time.sleep(SETTLE)
        assert not [key for key, payload in heard.received if payload == b"spoofed"]


@pytest.mark.timeout(30)
def test_the_page_and_foxglove_live_declare_their_own_tokens_and_the_page_answers_the_launcher(
    swarm: Swarm,
) -> None:
    """What ``swarm run --secure --view --foxglove`` needs, and no more: each observer its
    token, the page its finish queryable, asked by the launcher alone."""
    alive = Inbox()
    with (
        swarm.open("launcher") as launcher,
        swarm.open("viewer") as viewer,
        swarm.open("foxglove") as foxglove,
        swarm.open("robot-0") as robot,
    ):
        launcher.liveliness().declare_subscriber(f"{KEYS.prefix}/alive/**", alive, history=True)
        spoofed = [
            foxglove.liveliness().declare_token(KEYS.token(Role.VIEWER, 0)),
            foxglove.liveliness().declare_token(KEYS.token(Role.RECORDER, 0)),
            viewer.liveliness().declare_token(KEYS.token(Role.VIEWER, 1)),
        ]
        tokens = [
            foxglove.liveliness().declare_token(KEYS.token(Role.FOXGLOVE, 0)),
            viewer.liveliness().declare_token(KEYS.token(Role.VIEWER, 0)),
        ]
        alive.wait_for(KEYS.token(Role.FOXGLOVE, 0))
        alive.wait_for(KEYS.token(Role.VIEWER, 0))
        impostor = foxglove.declare_queryable(  # only the page may answer
            KEYS.of(keyspace.VIEWER_FINISH),
            lambda query: query.reply(KEYS.of(keyspace.VIEWER_FINISH), b"spoofed"),
        )
        queryable = viewer.declare_queryable(
            KEYS.of(keyspace.VIEWER_FINISH),
            lambda query: query.reply(KEYS.of(keyspace.VIEWER_FINISH), b"ended"),
        )

        def answers(asker: zenoh.Session) -> list[bytes]:
            replies = asker.get(KEYS.of(keyspace.VIEWER_FINISH), timeout=1.0)
            return [reply.ok.payload.to_bytes() for reply in replies if reply.ok]

        assert until(lambda: answers(launcher) == [b"ended"])
        assert answers(robot) == []  # a robot may not end the page
        time.sleep(SETTLE)
        assert alive.heard_keys() == {KEYS.token(Role.FOXGLOVE, 0), KEYS.token(Role.VIEWER, 0)}
        queryable.undeclare()
        impostor.undeclare()
        for token in [*spoofed, *tokens]:
            token.undeclare()


# --- the world's keys ----------------------------------------------------------------


@pytest.mark.timeout(30)
def test_the_world_senses_for_each_robot_and_only_that_robot_hears_it(swarm: Swarm) -> None:
    robot_1_hears, robot_2_hears = Inbox(), Inbox()
    with (
        swarm.open("world") as world,
        swarm.open("robot-1") as robot_1,
        swarm.open("robot-2") as robot_2,
    ):
        robot_1.declare_subscriber(KEYS.of(keyspace.SENSE, 1), robot_1_hears)
        robot_2.declare_subscriber(
            KEYS.of(keyspace.SENSE, 1), robot_2_hears
        )  # not its own: refused
        robot_2.declare_subscriber(KEYS.of(keyspace.SENSE, 2), robot_2_hears)
        robot_1.declare_subscriber(
            KEYS.of(keyspace.HOST_SENSE, 1), robot_1_hears
        )  # its process's batch
        robot_2.declare_subscriber(
            KEYS.of(keyspace.HOST_SENSE, 1), robot_2_hears
        )  # another's: refused
        senses = {
            robot: zenoh_session.reliable_publisher(world, KEYS.of(keyspace.SENSE, robot))
            for robot in (1, 2)
        }
        batched = zenoh_session.reliable_publisher(world, KEYS.of(keyspace.HOST_SENSE, 1))
        put_until_heard(senses[1], KEYS.of(keyspace.SENSE, 1), robot_1_hears)
        put_until_heard(senses[2], KEYS.of(keyspace.SENSE, 2), robot_2_hears)
        put_until_heard(batched, KEYS.of(keyspace.HOST_SENSE, 1), robot_1_hears)
        senses[1].put(b"sense 1")
        senses[2].put(b"sense 2")
        batched.put(b"batch 1")
        assert until(lambda: (KEYS.of(keyspace.SENSE, 1), b"sense 1") in robot_1_hears.received)
        assert until(lambda: (KEYS.of(keyspace.SENSE, 2), b"sense 2") in robot_2_hears.received)
        assert until(
            lambda: (KEYS.of(keyspace.HOST_SENSE, 1), b"batch 1") in robot_1_hears.received
        )
        time.sleep(SETTLE)
        assert robot_2_hears.heard_keys() == {KEYS.of(keyspace.SENSE, 2)}


# --- the generator -------------------------------------------------------------------


def example_plan() -> zenoh_acl.SwarmPlan:
    """The plan the files in deploy/zenoh were written for (see its README)."""
    return zenoh_acl.SwarmPlan(keyspace.Keys("run"), robots=(0, 1))


@pytest.mark.parametrize(
    ("template", "folder", "identity"),
    [
        ("router.json5", "routers", "router"),
        ("client-robot.json5", "clients", "robot-0"),
        ("client-world.json5", "clients", "world"),
        ("client-beacon.json5", "clients", "beacon-nest"),
        ("client-observer.json5", "clients", "observer"),
    ],
)
def test_the_templates_are_what_the_generator_writes(
    tmp_path: Path, template: str, folder: str, identity: str
) -> None:
    zenoh_acl.write_configs(example_plan(), tmp_path, PurePath("certs"))
    written = (tmp_path / folder / f"{identity}.json5").read_text()
    assert (TEMPLATES / template).read_text() == written
    zenoh.Config.from_file(str(TEMPLATES / template))  # Zenoh 1.10 accepts every field


def test_every_policy_names_existing_rules_and_one_subject_per_identity() -> None:
    plan = zenoh_acl.SwarmPlan(
        KEYS, robots=(0, 1, 2, 7), beacons=("nest", "b2"), routers=("host-a", "10.0.0.2")
    )
    acl = zenoh_acl.access_control(plan)
    rule_ids = [rule["id"] for rule in acl["rules"]]
    assert len(rule_ids) == len(set(rule_ids))
    assert all(set(policy["rules"]) <= set(rule_ids) for policy in acl["policies"])
    names = {subject["id"]: subject["cert_common_names"] for subject in acl["subjects"]}
    assert names["robot-7"] == ["robot-7"] and names["beacon-b2"] == ["beacon-b2"]
    assert names["routers"] == ["host-a", "10.0.0.2"]
    assert set(names) == {*plan.client_identities(), "routers"}
    assert acl["default_permission"] == "deny"
    assert all(rule["permission"] == "allow" for rule in acl["rules"])


@pytest.mark.parametrize(
    ("beacons", "routers", "reason"),
    [
        (("3",), ("router",), "number"),  # would be robot 3's radio name
        (("a/b",), ("router",), "invalid beacon name"),
        (("nest",), ("bad name",), "not a host name"),
        (("nest",), ("world",), "also a client identity"),  # would give the world every right
        (("nest", "nest"), ("router",), "once"),
    ],
)
def test_a_plan_refuses_names_that_would_clash_or_break_keys(
    beacons: tuple[str, ...], routers: tuple[str, ...], reason: str
) -> None:
    with pytest.raises(ValueError, match=reason):
        zenoh_acl.SwarmPlan(KEYS, robots=(0,), beacons=beacons, routers=routers)


def test_routers_connect_to_each_other_by_name() -> None:
    plan = zenoh_acl.SwarmPlan(KEYS, robots=(0,), routers=("host-a", "10.0.0.2"), port=7450)
    config = zenoh_acl.router_config(plan, "host-a", PurePath("certs"))
    assert config["connect"]["endpoints"] == ["tls/10.0.0.2:7450"]
    assert config["listen"]["endpoints"] == ["tls/127.0.0.1:7450", "tls/host-a:7450"]


# --- a swarm under the access control ------------------------------------------------


@pytest.mark.timeout(180)
def test_a_swarm_started_by_hand_takes_its_id_from_its_certificate_and_follows_a_new_world(
    swarm: Swarm, tmp_path: Path
) -> None:
    """World, beacon and two robots, each with its own certificate and run keys: robot 1
    is started with ``--id auto`` and takes its id from its certificate (the world would
    hand out ids the access control then refuses), and both robots follow a restarted
    world server, whose liveliness the access control must let them see."""
    assert run_keys.main(["--run-id", RUN, "--robots", "2", "--out", str(tmp_path)]) == 0
    seed, sites, robots = 4, 4, 2
    connect = ["--mode", "client", "--connect", swarm.endpoint, "--run-id", RUN]

    def command(module: str, identity: str, key_file: str, *options: str) -> list[str]:
        config = str(swarm.client_config(identity))
        keys_file = str(tmp_path / key_file)
        options = (*options, "--seed", str(seed), "--key-file", keys_file)
        return python_module(module, *connect, "--zenoh-config", config, *options)

    world_command = command(
        "world_server.server", "world", "secret.json", "--robots", str(robots), "--sites", "4"
    )
    statuses: dict[int, protocol.Status] = {}

    def on_status(sample: zenoh.Sample) -> None:
        status = protocol.decode(sample.payload.to_bytes(), protocol.Status)
        statuses[status.id] = status

    started: list[subprocess.Popen[bytes]] = []

    def start(argv: list[str]) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(argv, cwd=REPO, stderr=subprocess.PIPE)
        started.append(process)
        return process

    with swarm.open("observer") as observer:
        observer.declare_subscriber(KEYS.of(keyspace.STATUS, "*"), on_status)
        try:
            world = start(world_command)
            start(command("nest_beacon", "beacon-nest", "secret.json"))
            start(command("robot_agent.node", "robot-0", "robot-0.json", "--id", "0"))
            robot_1 = start(command("robot_agent.node", "robot-1", "robot-1.json", "--id", "auto"))
            assert until_within(60, lambda: any(s.trips >= 1 for s in statuses.values()))
            world.kill()
            world.wait()
            time.sleep(2.0)
            assert robot_1.poll() is None, "robot 1 exited"
            start(world_command)
            assert until_within(
                120,
                lambda: (
                    len(statuses) == robots
                    and all(status.decided_site is not None for status in statuses.values())
                ),
            )
        finally:
            for process in started:
                if process.poll() is None:
                    process.kill()
                process.wait()
    errors = b"".join(process.stderr.read() for process in started if process.stderr)
    best = make_layout(sites, robots, seed).best_site
    assert {status.decided_site for status in statuses.values()} == {best}
    assert sorted(statuses) == [0, 1]
    assert errors.count(b"a new world server appeared; resuming") == robots, errors.decode()[-3000:]
    assert b"Traceback" not in errors


def until_within(seconds: float, condition: Callable[[], bool]) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True
