"""One robot on a UDP radio: the main loop of a port, with a stub body in place of hardware.

This is the whole of what a port to a real robot looks like (docs/porting.md): build the
map (a ``WorldInfo``), a ``Body`` (here ``StubBody``: dead reckoning and a painted camera;
on a robot, its motor, IR and camera drivers), a ``Radio`` (``UdpRadio``), the controller
with its seeded RNG, then call ``ports.control_step`` once per control period with the
clock's time until the robot has decided and parked.

    python examples/udp_robot.py --id 0 --qualities 0.25,1,0.5,0 --interface wlan0

Every robot of the swarm, and the nest beacon, must use the same group, port and map.
``--speed`` runs the clock faster than the wall clock (for tests and demos: the stub body
moves that much faster too). ``--start-at`` gives robots launched one by one a common
start. On exit it prints one JSON line: the decision, trips, pool sizes and radio counts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

# Run as a script (python examples/udp_robot.py), the repository root is not on the path.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.stop_signals import on_stop_signals
from bestofn_swarm.wire import names, protocol
from examples.udp_radio import DEFAULT_GROUP, DEFAULT_PORT, UdpRadio
from robot_agent.core import builder, ports
from robot_agent.core.controller import Controller, ControllerConfig

PANEL_FRACTION = 0.7  # of each site's share of the wall that its coloured panel covers
CAMERA_REACH = 0.3  # metres: a panel further away is too small to judge
NEUTRAL_GREY = 128


class ScaledClock:
    """Seconds since the start, running ``speed`` times as fast as the wall clock."""

    def __init__(self, speed: float = 1.0, start_at: float | None = None) -> None:
        offset = 0.0 if start_at is None else start_at - time.time()
        self._origin = time.monotonic() + offset
        self._speed = speed

    def now(self) -> float:
        return max(time.monotonic() - self._origin, 0.0) * self._speed

    def sleep_until(self, t: float) -> None:
        delay = (t - self.now()) / self._speed
        if delay > 0:
            time.sleep(delay)


class StubBody:
    """A ``ports.Body`` without hardware: unicycle dead reckoning on the clock's time, no
    obstacles (proximity all zero), and a camera that paints the faced site's colour
    (red = 255 quality, blue = 255 (1 - quality)) as the world server renders it."""

    def __init__(
        self,
        clock: ScaledClock,
        world: protocol.WorldInfo,
        qualities: Sequence[float],
        pose: tuple[float, float, float],
    ) -> None:
        self.clock = clock
        self.world = world
        self.qualities = list(qualities)
        self.x, self.y, self.theta = pose
        self._left = self._right = 0.0
        self._t = clock.now()
        self._frame_requested = False

    def read(self) -> ports.BodyReading:
        t = self.clock.now()
        self._move(t - self._t)
        self._t = t
        frame = None
        if self._frame_requested:
            self._frame_requested = False
            frame = self._render()
        return ports.BodyReading(
            t=t, x=self.x, y=self.y, theta=self.theta, proximity=(0.0,) * 8, frame=frame
        )

    def drive(self, left: float, right: float) -> None:
        limit = self.world.max_wheel_speed
        self._left = min(max(left, -limit), limit)
        self._right = min(max(right, -limit), limit)

    def request_frame(self) -> None:
        self._frame_requested = True

    def _move(self, elapsed: float) -> None:
        """The exact arc that constant wheel speeds drive in ``elapsed`` seconds."""
        speed = (self._left + self._right) / 2
        rate = (self._right - self._left) / self.world.wheel_base
        if abs(rate) < 1e-12:
            self.x += speed * elapsed * math.cos(self.theta)
            self.y += speed * elapsed * math.sin(self.theta)
            return
        theta = self.theta + rate * elapsed
        self.x += speed / rate * (math.sin(theta) - math.sin(self.theta))
        self.y -= speed / rate * (math.cos(theta) - math.cos(self.theta))
        self.theta = math.atan2(math.sin(theta), math.cos(theta))

    def _render(self) -> np.ndarray:
        camera = self.world.camera
        frame = np.full((camera.height, camera.width, 3), NEUTRAL_GREY, dtype=np.uint8)
        # Where the camera's central ray meets the arena wall (a circle round the origin).
        ux, uy = math.cos(self.theta), math.sin(self.theta)
        along = self.x * ux + self.y * uy
        radius = self.world.arena_radius
        inside = along * along + radius**2 - self.x**2 - self.y**2
        to_wall = -along + math.sqrt(max(inside, 0.0))
        if to_wall > CAMERA_REACH:
            return frame
        hit = math.atan2(self.y + to_wall * uy, self.x + to_wall * ux)
        half_width = PANEL_FRACTION * math.pi / len(self.world.sites)
        for site in self.world.sites:
            offset = hit - math.atan2(site.y, site.x)
            if abs(math.atan2(math.sin(offset), math.cos(offset))) <= half_width:
                quality = self.qualities[site.id]
                frame[...] = (round(255 * (1 - quality)), 0, round(255 * quality))
        return frame


class NestRange:
    """The robot's ``ports.Radio``: a UdpRadio that passes the nest beacon's messages on
    only while the body is within the nest's radius.

    On a shared Wi-Fi every robot hears the beacon wherever it is; a real nest beacon is a
    short-range transmitter (infrared, BLE), and with one this wrapper is not needed.
    """

    def __init__(self, radio: UdpRadio, body: StubBody, nest: protocol.Nest) -> None:
        self.radio = radio
        self.body = body
        self.nest = nest

    def send(self, payload: bytes) -> None:
        self.radio.send(payload)

    def poll(self) -> list[tuple[str, bytes]]:
        messages = self.radio.poll()
        if math.hypot(self.body.x - self.nest.x, self.body.y - self.nest.y) <= self.nest.radius:
            return messages
        return [(sender, payload) for sender, payload in messages if not _is_beacon(payload)]


def _is_beacon(payload: bytes) -> bool:
    try:
        return isinstance(protocol.decode_radio(payload), protocol.BeaconPayload)
    except protocol.ProtocolError:
        return False  # left for ports.decode_received to count


def circular_world(num_sites: int, arena_radius: float = 0.75, seed: int = 0) -> protocol.WorldInfo:
    """The Section 5 arena of run seed ``seed``: an e-puck's geometry, n sites evenly spaced
    on the wall, the nest at the centre. A port may load its own map instead (``--world``)."""
    sites = [
        protocol.Site(
            index,
            arena_radius * math.cos(2 * math.pi * index / num_sites),
            arena_radius * math.sin(2 * math.pi * index / num_sites),
        )
        for index in range(num_sites)
    ]
    return protocol.WorldInfo(
        v=protocol.VERSION,
        run="udp",
        seed=seed,
        dt=0.1,
        arena_radius=arena_radius,
        nest=protocol.Nest(0.0, 0.0, 0.2),
        sites=sites,
        robot_radius=0.037,
        wheel_base=0.053,
        max_wheel_speed=0.13,
        camera=protocol.CameraSpec(width=64, height=48, fov=0.84),
        clock="realtime",
    )


STOP = threading.Event()  # set by SIGINT/SIGTERM: leave the loop, report, exit


def run(args: argparse.Namespace) -> dict[str, object]:
    world = load_world(args)
    if len(args.qualities) != len(world.sites):
        raise ValueError(f"{len(args.qualities)} qualities for {len(world.sites)} sites")
    clock = ScaledClock(args.speed, args.start_at)
    # Start on a ring just outside the nest, facing out, spread by id.
    ring = world.nest.radius + 2 * world.robot_radius
    angle = 2 * math.pi * args.id / args.robots
    pose = (world.nest.x + ring * math.cos(angle), world.nest.y + ring * math.sin(angle), angle)
    body = StubBody(clock, world, args.qualities, pose)
    config = ControllerConfig(dwell=args.dwell)
    # The determinism rule: every random draw comes from the world's seed's stream for this
    # robot, as every robot of the project is built (robot_agent/core/builder.py).
    controller = builder.build_controller(args.id, world, config, factory=Controller)
    assert isinstance(controller, Controller)
    rejects = ports.RejectCounter()
    with UdpRadio(
        names.robot_name(args.id),
        address=args.address,
        port=args.port,
        interface=args.interface,
    ) as udp:
        radio = NestRange(udp, body, world.nest)
        clock.sleep_until(0.0)
        next_step = 0.0
        while controller.phase != "stopped" and clock.now() < args.max_seconds:
            if STOP.is_set():
                break
            ports.control_step(controller, body, radio, rejects)
            next_step += world.dt
            clock.sleep_until(next_step)
        return {
            "id": args.id,
            "phase": controller.phase,
            "decided_site": controller.decided_site,
            "decision_time": controller.decision_time,
            "trips": controller.trips,
            "pool_sizes": controller.pool_sizes,
            "rejected_payloads": rejects.count,
            "radio": asdict(udp.stats),
        }


def load_world(args: argparse.Namespace) -> protocol.WorldInfo:
    if args.world is None:
        return circular_world(len(args.qualities), seed=args.seed or 0)
    with open(args.world, "rb") as file:
        world = protocol.decode(file.read(), protocol.WorldInfo)
    builder.run_seed(world, args.seed)  # a --seed must be the world's
    return world


def qualities(text: str) -> list[float]:
    parse = cliargs.probability
    values = [parse(part) for part in text.split(",")]
    if len(values) < 2:
        raise argparse.ArgumentTypeError("give at least two qualities")
    return values


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="udp_robot", description="One robot of the swarm on a UDP radio, with a stub body."
    )
    parser.add_argument("--id", type=cliargs.int_range(0, names.MAX_ROBOTS - 1), required=True)
    parser.add_argument(
        "--robots",
        type=cliargs.positive_int,
        default=10,
        help="swarm size, to spread start poses round the nest (default: 10)",
    )
    parser.add_argument(
        "--seed",
        type=cliargs.seed,
        default=None,
        help="run seed of the Section 5 arena (default: 0), or, with --world, the world's "
        "seed again (checked); the robot's RNG derives from the world's seed and its id",
    )
    parser.add_argument(
        "--qualities",
        type=qualities,
        required=True,
        help="comma-separated site qualities the stub camera shows, site 0 first",
    )
    parser.add_argument(
        "--world", default=None, help="a WorldInfo JSON file (default: the Section 5 arena)"
    )
    parser.add_argument(
        "--dwell",
        type=cliargs.positive_float,
        default=3.0,
        help="seconds at the nest broadcasting and listening (default: 3)",
    )
    parser.add_argument(
        "--address",
        default=DEFAULT_GROUP,
        help=f"multicast group or broadcast address (default: {DEFAULT_GROUP})",
    )
    parser.add_argument("--port", type=cliargs.int_range(1, 65535), default=DEFAULT_PORT)
    parser.add_argument(
        "--interface",
        default=None,
        help="network interface: IPv4 address, or name (Linux, multicast)",
    )
    parser.add_argument(
        "--speed",
        type=cliargs.positive_float,
        default=1.0,
        help="clock seconds per wall second (default: 1, real time)",
    )
    parser.add_argument(
        "--start-at",
        type=float,
        default=None,
        help="wall time (seconds since the epoch) of the common start",
    )
    parser.add_argument(
        "--max-seconds",
        type=cliargs.positive_float,
        default=600.0,
        help="give up after this many clock seconds (default: 600)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    # Not STOP.set() in a handler: it takes a lock the interrupted code may hold.
    on_stop_signals(lambda _: STOP.set())
    try:
        summary = run(args)
    except (ValueError, OSError) as error:
        parser.exit(2, f"udp_robot: error: {error}\n")
    print(json.dumps(summary), flush=True)
    return 0 if summary["phase"] == "stopped" else 1


if __name__ == "__main__":
    sys.exit(main())
