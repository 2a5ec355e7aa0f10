"""``swarm conformance PROGRAM [ARGS]``: does a port decide as the controller does?

PROGRAM is any program that speaks the link (docs/protocol.md, "The link to a robot outside
the emulator") and takes the link program's command line: it is started as
``PROGRAM ARGS --link ADDRESS --id ID --key-file FILE``, as ``robot-agent --link`` and
``c_robot/build/c-robot`` are. Two parts, each on UDP (loopback) or, with ``--serial``, on a
serial line made of two pseudo-terminals (socat):

1. the controller vectors (``tests/vectors/controller.json``): for each track a fresh start
   of the program, driven tick by tick by this process as its bridge and world
   (``link_driver.py``); every act, transmission and status is compared with the track's;
2. a lockstep swarm (``--robots``, ``--sites``, ``--seed``) with robot ``--robot`` the
   program, against the same swarm all emulated (``swarm.py``); skipped when the vectors
   failed, or with ``--no-swarm``.

The first divergence of each part is printed as its tick, field, expected and received
values, with the inputs of the ticks that led there. The last line is the verdict; the exit
code is 0 when the program conforms, 1 when it does not, 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import tempfile
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing.cliargs import UsageError
from deploy.conformance import link_driver, swarm, vectors

VECTORS = Path(__file__).resolve().parents[2] / "tests" / "vectors" / "controller.json"
WINDOW = 3  # ticks shown before the one that differs


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "check a program that speaks the link against the controller vectors, then in a "
        "lockstep swarm beside emulated robots (docs/porting.md)"
    )
    parser.epilog = "exit codes: 0 the program conforms, 1 it does not, 2 bad arguments"
    parser.add_argument(
        "--serial",
        action="store_true",
        help="a serial line (two pseudo-terminals joined by socat) instead of UDP on loopback",
    )
    parser.add_argument(
        "--baud", type=int, default=921600, help="the serial line's rate (default: 921600)"
    )
    parser.add_argument(
        "--vectors",
        type=Path,
        default=VECTORS,
        help="the controller vectors (default: %(default)s)",
    )
    parser.add_argument(
        "--track",
        action="append",
        default=[],
        metavar="NAME",
        help="run only this track (again for more); default: every track",
    )
    parser.add_argument(
        "--no-swarm", action="store_true", help="the controller vectors only, no swarm"
    )
    parser.add_argument("--robots", type=int, default=10, help="the swarm's robots (default: 10)")
    parser.add_argument("--sites", type=int, default=10, help="the swarm's sites (default: 10)")
    parser.add_argument("--seed", type=int, default=0, help="the swarm's seed (default: 0)")
    parser.add_argument(
        "--robot",
        type=int,
        default=None,
        help="the swarm's robot that the program is (default: the last)",
    )
    parser.add_argument(
        "--answer-timeout",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="how long the program may take to answer a tick (default: 10)",
    )
    parser.add_argument(
        "--keep",
        type=Path,
        default=None,
        metavar="DIR",
        help="keep the key files, the program's output and the swarm's recording there",
    )
    parser.add_argument("program", metavar="PROGRAM", help="the program that speaks the link")
    parser.add_argument(
        "args",
        nargs=argparse.REMAINDER,
        metavar="ARGS",
        help="its own arguments, before the link's",
    )


def _checked(args: argparse.Namespace) -> tuple[list[str], list[vectors.Track], int]:
    """The program's command, the tracks and the swarm's robot; UsageError otherwise."""
    program = args.program
    found = shutil.which(program) if "/" not in program else program
    if found is None or not Path(found).is_file():
        raise UsageError(f"no program {program!r}")
    try:
        tracks = vectors.load(args.vectors)
    except ValueError as error:
        raise UsageError(str(error)) from None
    names = [track.name for track in tracks]
    unknown = [name for name in args.track if name not in names]
    if unknown:
        raise UsageError(f"no track {', '.join(unknown)}; the tracks are {', '.join(names)}")
    if args.track:
        tracks = [track for track in tracks if track.name in args.track]
    if args.serial and shutil.which("socat") is None:
        raise UsageError("--serial needs socat (apt-get install socat)")
    if not 50 <= args.baud <= 10_000_000:
        raise UsageError(f"--baud {args.baud}: a line rate is 50 to 10000000")
    if not 1 <= args.robots <= 1000 or not 2 <= args.sites <= 1000:
        raise UsageError("--robots is 1 to 1000 and --sites 2 to 1000")
    robot = args.robots - 1 if args.robot is None else args.robot
    if not 0 <= robot < args.robots:
        raise UsageError(f"--robot {robot}: there is no such robot in a swarm of {args.robots}")
    if not args.answer_timeout > 0:
        raise UsageError("--answer-timeout must be positive")
    return [program, *args.args], tracks, robot


def run(args: argparse.Namespace) -> int:
    command, tracks, robot = _checked(args)
    # The link's ends log every session they close; the verdict says what matters.
    for name in ("bridge", "link.hub", "link.transport"):
        logging.getLogger(name).setLevel(logging.ERROR)
    transport = f"a serial line at {args.baud} baud" if args.serial else "UDP"
    baud = args.baud if args.serial else None
    print(f"swarm conformance: {' '.join(command)}, over {transport}", flush=True)
    with tempfile.TemporaryDirectory(prefix="conformance-") as scratch:
        folder = args.keep if args.keep is not None else Path(scratch)
        failed = _vectors_part(command, tracks, folder / "vectors", baud, args.answer_timeout)
        ticks = sum(len(track.ticks) for track in tracks)
        if failed is not None:
            print(f"FAIL: {failed}")
            return 1
        if args.no_swarm:
            print(f"PASS: every tick of {_tracks(tracks)} ({ticks} ticks) over {transport}")
            return 0
        failed = _swarm_part(command, args, robot, folder / "swarm", baud)
        if failed is not None:
            print(f"FAIL: {failed}")
            return 1
    print(
        f"PASS: every tick of {_tracks(tracks)} ({ticks} ticks) over {transport}, and "
        f"robot {robot} of a lockstep swarm ({args.robots} robots, {args.sites} sites, seed "
        f"{args.seed}) gives the all-emulated run"
    )
    return 0


def _vectors_part(
    command: list[str],
    tracks: list[vectors.Track],
    folder: Path,
    baud: int | None,
    answer_timeout: float,
) -> str | None:
    """Every track; what failed first, or None."""
    first: str | None = None

    def report(track: vectors.Track, found: vectors.Divergence | None, program: Any) -> None:
        nonlocal first
        if found is None:
            print(f"  track {track.name}: {len(track.ticks)} ticks, every output as expected")
            return
        print(f"  track {track.name}: differs at {found.where}")
        print(f"    {_difference(found)}")
        if found.tick >= 0:
            _print_inputs(track, found.tick)
        tail = program.log_tail()
        if tail:
            print("    the program's last lines:")
            print("\n".join(f"      {line}" for line in tail))
        if first is None:
            first = f"{found.describe()} (robot {track.robot}, seed {track.world.seed})"

    print(f"the controller vectors ({_tracks(tracks)}):", flush=True)
    link_driver.run_tracks(
        command, tracks, folder, serial_baud=baud, answer_timeout=answer_timeout, on_track=report
    )
    return first


def _swarm_part(
    command: list[str], args: argparse.Namespace, robot: int, folder: Path, baud: int | None
) -> str | None:
    print(
        f"a lockstep swarm: {args.robots} robots, {args.sites} sites, seed {args.seed}, robot "
        f"{robot} the program",
        flush=True,
    )
    result = swarm.check_swarm(
        command,
        robots=args.robots,
        sites=args.sites,
        seed=args.seed,
        robot=robot,
        folder=folder,
        serial_baud=baud,
    )
    reference = result.reference
    if result.same:
        print(
            f"  the all-emulated run (digest {reference['digest']}), and robot {robot} "
            f"answered as the emulated robot did at each of the {result.compared} ticks that "
            "robot ran (where it ends depends on when the launcher notices the ending)"
        )
        return None
    summary = result.summary
    if summary is None:
        print(f"  no run: {'; '.join(result.notes)}")
        return f"the swarm with the program gave no result ({'; '.join(result.notes)})"
    if summary["digest"] != reference["digest"]:
        print(f"  another run: digest {summary['digest']}, all emulated {reference['digest']}")
    else:
        print(f"  the same results (digest {summary['digest']}), but not the same answers")
    for got, want in zip(swarm.results(summary), swarm.results(reference), strict=False):
        if got != want:
            print(f"    robot {got[0]}: {_robot(got)}; all emulated: {_robot(want)}")
    found = result.divergence
    if found is not None and result.reference_track is not None:
        print(f"  robot {robot} first answered otherwise at tick {found.tick}")
        print(f"    {_difference(found)}")
        _print_inputs(result.reference_track, found.tick)
        return f"in the swarm, tick {found.tick}: {_difference(found)}"
    for note in result.notes:
        print(f"  {note}")
    return "the swarm with the program is not the all-emulated run"


def _tracks(tracks: list[vectors.Track]) -> str:
    return f"{len(tracks)} track{'s' if len(tracks) != 1 else ''}"


def _difference(found: vectors.Divergence) -> str:
    return f"{found.field}: expected {_value(found.expected)}, received {_value(found.received)}"


def _robot(result: tuple[Any, ...]) -> str:
    _, site, steps, time, pools = result
    return f"site {site}, {steps} steps, decided at {time} s, pools {pools}"


def _value(value: Any) -> str:
    if isinstance(value, str):
        return value
    return json.dumps(value, separators=(",", ":"))


def _print_inputs(track: vectors.Track, tick: int) -> None:
    """The inputs of the ticks that led to ``tick``, and what each had to give."""
    earlier = [each for each in track.transitions if each[0] <= tick]
    if earlier:
        at, phase, event, entered = earlier[-1]
        print(f"    the last transition up to it: tick {at}, {phase} --{event}--> {entered}")
    print("    the inputs that led there (and what each tick had to give):")
    for each in track.window(tick, WINDOW):
        given, out = each.inputs, each.out
        heard = (
            ", ".join(f"{sender}: {_value(payload)}" for sender, payload in given["rx"]) or "none"
        )
        frame = "none" if given["frame"] is None else "a PNG frame"
        print(
            f"      tick {each.tick}: t {given['t']!r}, x {given['x']!r}, y {given['y']!r}, "
            f"theta {given['theta']!r}, prox {_value(given['prox'])}; radio: {heard}; "
            f"frame: {frame}"
        )
        expected = f"left {out['left']!r}, right {out['right']!r}, capture {_value(out['capture'])}"
        if out["broadcasts"]:
            expected += f", broadcasts {_value(out['broadcasts'])}"
        expected += f", phase {out['phase']}"
        if "events" in out:
            expected += f", events {_value(out['events'])}"
        if "status" in out:
            expected += ", a status"
        print(f"        gives {expected}")


__all__ = ["add_arguments", "run"]
