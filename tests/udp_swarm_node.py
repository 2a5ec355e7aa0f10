"""One robot, the nest beacon, or a plain talker of a swarm whose radio is real UDP.

A test helper: ``tests/test_udp_radio.py`` starts one of these per network namespace
with ``ip netns exec``.

* ``robot``: the real ``Controller`` stepped by ``ports.control_step`` on a kinematic
  fake body from ``tests/fakes.py`` (its camera shows the sites' qualities, the same in
  every process for one seed) and a ``UdpRadio``.
* ``beacon``: the real ``nest_beacon.core.beacon.Beacon`` transmitting on a ``UdpRadio``.
* ``hello``: sends a few beacon payloads under its own name and reports whom it heard
  (a quick check of a transport setting without a whole swarm).

Start-up handshake: a process opens its radio, prints ``ready`` on stdout and reads the
start time (a ``time.time()`` value) from stdin, so that slow start-ups do not skew the
processes' clocks. All share one simulated clock: tick k (sim time k * dt) is due at wall
time ``start + k * dt / speed``; a process that falls behind steps without sleeping until
it has caught up. At the end it prints one JSON summary line on stdout.

On a shared Wi-Fi every robot hears the nest beacon; a real beacon is a short-range
transmitter. So a robot's radio passes the beacon's messages on only while its body is
within the nest's radius (``NestRange``), which is what being in range means in the fakes.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from fakes import ROBOT_RADIUS, FakeBody, FakeWorld, make_world_info, shuffled_qualities

# Run as a script (python tests/udp_swarm_node.py), the repository root is not on the path.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.wire import names, protocol
from bestofn_swarm.wire.rng import Stream
from examples.udp_radio import DEFAULT_GROUP, DEFAULT_PORT, UdpRadio
from nest_beacon.core.beacon import Beacon, BeaconConfig
from robot_agent.core import ports
from robot_agent.core.controller import Controller, ControllerConfig

STOP = threading.Event()  # set by SIGTERM: finish the step, print the summary, exit


class NestRange:
    """A ``ports.Radio`` that drops beacon messages while the body is away from the nest,
    and tallies whose opinions it heard."""

    def __init__(self, radio: UdpRadio, body: FakeBody, nest: protocol.Nest) -> None:
        self.radio = radio
        self.body = body
        self.nest = nest
        self.opinion_senders: Counter[str] = Counter()
        self.beacons_heard = 0
        self.beacons_out_of_range = 0

    def send(self, payload: bytes) -> None:
        self.radio.send(payload)

    def poll(self) -> list[tuple[str, bytes]]:
        x, y, _ = self.body.pose
        at_nest = math.hypot(x - self.nest.x, y - self.nest.y) <= self.nest.radius
        passed = []
        for sender, payload in self.radio.poll():
            try:
                message = protocol.decode_radio(payload)
            except protocol.ProtocolError:
                passed.append((sender, payload))  # for ports.decode_received to count
                continue
            if isinstance(message, protocol.BeaconPayload):
                if not at_nest:
                    self.beacons_out_of_range += 1
                    continue
                self.beacons_heard += 1
            else:
                self.opinion_senders[sender] += 1
            passed.append((sender, payload))
        return passed


class SimClock:
    """Sim time paced against the wall clock from a start time shared by processes."""

    def __init__(self, start_at: float, speed: float, dt: float) -> None:
        self.origin = time.monotonic() + (start_at - time.time())
        self.speed = speed
        self.dt = dt

    def wait_for_tick(self, tick: int) -> None:
        delay = self.origin + tick * self.dt / self.speed - time.monotonic()
        if delay > 0:
            time.sleep(delay)


def open_radio(args: argparse.Namespace, name: str) -> UdpRadio:
    return UdpRadio(name, address=args.address, port=args.port, interface=args.interface)


def await_start(args: argparse.Namespace, dt: float) -> SimClock:
    """The handshake: say ready, read the common start time."""
    print("ready", flush=True)
    line = sys.stdin.readline()
    return SimClock(float(line), args.speed, dt)


def run_robot(args: argparse.Namespace) -> dict[str, object]:
    info = make_world_info(args.sites)
    # The beacon is a process on the network, not the fake world's.
    world = FakeWorld(
        info, shuffled_qualities(args.sites, args.seed), seed=args.seed, beacon_on=False
    )
    ring = info.nest.radius + 2 * ROBOT_RADIUS
    angle = 2 * math.pi * args.id / args.robots
    body, _ = world.add_robot(args.id, (ring * math.cos(angle), ring * math.sin(angle), angle))
    config = ControllerConfig(dwell=args.dwell)
    controller = Controller(args.id, info, config, Stream.named(args.seed, "robot", args.id))
    rejects = ports.RejectCounter()
    best_site = max(range(args.sites), key=world.qualities.__getitem__)
    with open_radio(args, names.robot_name(args.id)) as udp:
        radio = NestRange(udp, body, info.nest)
        clock = await_start(args, info.dt)
        while controller.phase != "stopped" and world.t < args.max_sim and not STOP.is_set():
            clock.wait_for_tick(world.tick)
            ports.control_step(controller, body, radio, rejects)
            if controller.take_status_change():
                # A trace on stderr, for the test to show when something goes wrong.
                print(
                    f"t={world.t:.1f} robot {args.id} {controller.phase} trips="
                    f"{controller.trips} opinion={protocol.wire_opinion(controller.opinion)}",
                    file=sys.stderr,
                )
            world.advance()
        return {
            "role": "robot",
            "id": args.id,
            "phase": controller.phase,
            "decided_site": controller.decided_site,
            "best_site": best_site,
            "decision_time": controller.decision_time,
            "trips": controller.trips,
            "pool_sizes": controller.pool_sizes,
            "sim_time": world.t,
            "opinion_senders": dict(radio.opinion_senders),
            "beacons_heard": radio.beacons_heard,
            "beacons_out_of_range": radio.beacons_out_of_range,
            "rejected_payloads": rejects.count,
            "radio": asdict(udp.stats),
            "local_address": list(udp.local_address),
        }


def run_beacon(args: argparse.Namespace) -> dict[str, object]:
    beacon = Beacon(
        BeaconConfig(name=args.name, period=args.period),
        Stream.named(args.seed, "beacon", args.name),
    )
    with open_radio(args, args.name) as udp:
        clock = await_start(args, args.dt)
        tick = 0
        while tick * args.dt < args.max_sim and not STOP.is_set():
            clock.wait_for_tick(tick)
            for message in beacon.on_tick(tick * args.dt):
                udp.send(protocol.encode(message))
            udp.poll()  # keep the receive buffer drained; the beacon listens to no one
            tick += 1
        return {"role": "beacon", "name": args.name, "radio": asdict(udp.stats)}


def run_hello(args: argparse.Namespace) -> dict[str, object]:
    """Send ``count`` payloads ``dt`` sim seconds apart; listen for ``max_sim`` sim seconds."""
    heard: Counter[str] = Counter()
    with open_radio(args, args.name) as udp:
        clock = await_start(args, args.dt)
        tick = 0
        while tick * args.dt < args.max_sim and not STOP.is_set():
            clock.wait_for_tick(tick)
            if tick < args.count:
                udp.send(protocol.encode(protocol.BeaconPayload(v=1, id=args.name, seq=tick)))
            for sender, payload in udp.poll():
                protocol.decode_radio(payload)  # a broken payload fails the helper, loudly
                heard[sender] += 1
            tick += 1
        return {
            "role": "hello",
            "name": args.name,
            "heard": dict(heard),
            "radio": asdict(udp.stats),
            "local_address": list(udp.local_address),
        }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--address", default=DEFAULT_GROUP)
    parser.add_argument("--port", type=cliargs.int_range(1, 65535), default=DEFAULT_PORT)
    parser.add_argument("--interface", default=None)
    parser.add_argument("--seed", type=cliargs.seed, default=0)
    parser.add_argument(
        "--speed", type=cliargs.positive_float, default=20.0, help="sim seconds per wall second"
    )
    parser.add_argument(
        "--max-sim", type=cliargs.positive_float, default=300.0, help="sim seconds before giving up"
    )
    roles = parser.add_subparsers(dest="role", required=True)
    robot = roles.add_parser("robot")
    robot.add_argument("--id", type=cliargs.int_range(0, names.MAX_ROBOTS - 1), required=True)
    robot.add_argument(
        "--robots", type=cliargs.positive_int, required=True, help="swarm size (for the start ring)"
    )
    robot.add_argument("--sites", type=cliargs.int_range(2, 100), default=4)
    robot.add_argument("--dwell", type=cliargs.positive_float, default=3.0)
    beacon = roles.add_parser("beacon")
    beacon.add_argument("--name", default="nest")
    beacon.add_argument("--period", type=cliargs.positive_float, default=0.5)
    beacon.add_argument("--dt", type=cliargs.positive_float, default=0.1)
    hello = roles.add_parser("hello")
    hello.add_argument("--name", required=True)
    hello.add_argument("--count", type=cliargs.positive_int, default=5)
    hello.add_argument("--dt", type=cliargs.positive_float, default=0.1)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: STOP.set())
    run = {"robot": run_robot, "beacon": run_beacon, "hello": run_hello}[args.role]
    print(json.dumps(run(args)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
