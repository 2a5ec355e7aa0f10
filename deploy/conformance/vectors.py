"""The controller vectors (``tests/vectors/controller.json``): what one robot's controller
took and gave at every step of a real run, for a port to check itself against, tick by tick
(docs/controller.md, "The controller vectors").

A *track* is one robot of one run from its first step to a few steps after the transitions
it was chosen for: its map (``WorldInfo``) and settings (``ControllerConfig``), which, with
its id and the map's seed, are all a controller is built from; then each tick's inputs
(``in``: the body's reading, the radio messages in delivery order, the camera frame, if
any) and what the controller must give (``out``: the wheel speeds, the capture request,
the broadcasts, the phase and, when they change, the events it fired, its opinion and its
status). A track starts where its robot started because a controller can only be brought to
a state by the inputs that led there: a port, which only takes inputs, cannot be put in the
middle of a run. Its ``transitions`` say at which tick each phase change happened, so a
reader goes straight to the few lines around one.

This module writes tracks (``track_from_steps``, ``dump``), reads them (``load``), says
where a run of steps first differs from a track (``first_divergence``), and replays a
track through the Python controller (``replay``), as the tests and ``swarm conformance``
do.
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from bestofn_swarm.wire import protocol, settings
from bestofn_swarm.wire.rng import Stream
from deploy.conformance.capture import Step, frame_png
from robot_agent.core import ports, vision
from robot_agent.core.controller import Controller, ControllerConfig
from robot_agent.core.phases import TRANSITIONS

FORMAT = 1

# The order in which a tick's outputs are compared: the first that differs is reported.
COMMAND_FIELDS = ("left", "right", "capture")
STATUS_FIELDS = (
    "phase",
    "trips",
    "opinion",
    "pool_size",
    "poolings",
    "decided_site",
    "decision_time",
    "decision_trips",
    "comparison",
    "rejected",
    "tick",
    "t",
)


# --- reading -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Tick:
    """One step of a track: its inputs and the outputs it must give."""

    tick: int
    inputs: dict[str, Any]  # t, x, y, theta, prox, rx [[sender, payload]], frame (index or None)
    out: dict[str, Any]  # left, right, capture, broadcasts, phase; events, opinion, status

    def sense(self) -> protocol.Sense:
        """The ``Sense`` that brings this tick's reading over a transport."""
        given = self.inputs
        return protocol.Sense(
            v=protocol.VERSION,
            tick=self.tick,
            t=given["t"],
            x=given["x"],
            y=given["y"],
            theta=given["theta"],
            prox=list(given["prox"]),
            rx=len(given["rx"]),
            camera=given["frame"] is not None,
        )

    def radio(self) -> list[tuple[str, bytes]]:
        """The radio messages of this tick, (sender, payload bytes), in delivery order."""
        return [(sender, encode_payload(payload)) for sender, payload in self.inputs["rx"]]


@dataclass(frozen=True)
class Track:
    """One robot of one run, step by step (see the module docstring)."""

    name: str
    about: str
    run: dict[str, Any]
    robot: int
    world: protocol.WorldInfo
    controller: ControllerConfig
    transitions: list[tuple[int, str, str, str]]  # (tick, phase, event, next phase)
    frames: list[bytes]  # PNG
    ticks: list[Tick]

    def frame(self, tick: Tick) -> bytes | None:
        index = tick.inputs["frame"]
        return None if index is None else self.frames[index]

    def window(self, tick: int, before: int = 3) -> list[Tick]:
        """The ticks up to ``tick``, ``before`` of them before it."""
        return [each for each in self.ticks if tick - before <= each.tick <= tick]


def encode_payload(payload: dict[str, Any]) -> bytes:
    """A radio payload given as its JSON value, in the protocol's spelling."""
    return protocol.encode(protocol.decode_radio(json.dumps(payload).encode()))


def load(path: Path) -> list[Track]:
    """The tracks of a controller vector file; ValueError says what is wrong with it."""
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"cannot read the controller vectors {path}: {error}") from None
    try:
        if content.get("format") != FORMAT:
            raise ValueError(f"format {content.get('format')!r}, not {FORMAT}")
        return [track_of(item) for item in content["tracks"]]
    except (KeyError, TypeError, ValueError, msgspec.MsgspecError) as error:
        raise ValueError(f"{path} holds no controller vectors: {error}") from None


def track_of(item: dict[str, Any]) -> Track:
    """A track from its JSON value (``track_from_steps``'s)."""
    world = protocol.decode(json.dumps(item["world"]).encode(), protocol.WorldInfo)
    controller = settings.decode(json.dumps(item["controller"]).encode(), ControllerConfig)
    return Track(
        name=item["name"],
        about=item["about"],
        run=item["run"],
        robot=int(item["robot"]),
        world=world,
        controller=controller,
        transitions=[tuple(each) for each in item["transitions"]],
        frames=[base64.b64decode(frame, validate=True) for frame in item["frames"]],
        ticks=[Tick(tick["tick"], tick["in"], tick["out"]) for tick in item["ticks"]],
    )


# --- writing -----------------------------------------------------------------------------


def track_from_steps(
    *,
    name: str,
    about: str,
    run: dict[str, Any],
    robot: int,
    world: protocol.WorldInfo,
    controller: ControllerConfig,
    steps: Sequence[Step],
) -> dict[str, Any]:
    """A track (as its JSON value) of ``robot``'s ``steps``, from its first."""
    frames: list[str] = []
    ticks: list[dict[str, Any]] = []
    transitions: list[list[Any]] = []
    opinion: list[float] | None = None
    for step in steps:
        reading = step.reading
        frame = None
        if reading.frame is not None:
            frame = len(frames)
            frames.append(base64.b64encode(frame_png(reading.frame)).decode())
        inputs = {
            "t": reading.t,
            "x": reading.x,
            "y": reading.y,
            "theta": reading.theta,
            "prox": list(reading.proximity),
            "rx": [[sender, json.loads(payload)] for sender, payload in step.received],
            "frame": frame,
        }
        command = step.command
        out: dict[str, Any] = {
            "left": command.left,
            "right": command.right,
            "capture": command.capture,
            "broadcasts": [json.loads(protocol.encode(each)) for each in command.broadcasts],
            "phase": step.phase,
        }
        if step.events:
            out["events"] = [list(event) for event in step.events]
            for phase, event in step.events:
                transitions.append([step.tick, phase, event, TRANSITIONS[phase][event]])
        if step.opinion != opinion:
            out["opinion"] = step.opinion
            opinion = step.opinion
        if step.status is not None:
            out["status"] = json.loads(protocol.encode(step.status))
        ticks.append({"tick": step.tick, "in": inputs, "out": out})
    return {
        "name": name,
        "about": about,
        "run": run,
        "robot": robot,
        "world": json.loads(protocol.encode(world)),
        "controller": json.loads(settings.encode(controller)),
        "transitions": transitions,
        "frames": frames,
        "ticks": ticks,
    }


def dump(about: Sequence[str], tracks: Sequence[dict[str, Any]]) -> str:
    """The file's text: one tick, and one frame, a line, so that a window of ticks reads
    as a few lines."""

    def compact(value: Any) -> str:
        return json.dumps(value, separators=(",", ":"), ensure_ascii=False)

    lines = ["{", f' "about": {compact(list(about))},', f' "format": {FORMAT},', ' "tracks": [']
    for number, track in enumerate(tracks):
        lines.append("  {")
        for key in ("name", "about", "run", "robot", "world", "controller"):
            lines.append(f"   {compact(key)}: {compact(track[key])},")
        for key in ("transitions", "frames", "ticks"):
            items = track[key]
            lines.append(f"   {compact(key)}: [")
            lines += [f"    {compact(item)}," for item in items[:-1]]
            lines += [f"    {compact(item)}" for item in items[-1:]]
            lines.append("   ]" + ("," if key != "ticks" else ""))
        lines.append("  }" + ("," if number < len(tracks) - 1 else ""))
    lines += [" ]", "}", ""]
    return "\n".join(lines)


# --- comparing ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Divergence:
    """The first output that differs from a track: where, and the two values."""

    track: str
    tick: int  # -1: before the first tick (the program did not start, connect or ask)
    field: str
    expected: Any
    received: Any

    @property
    def where(self) -> str:
        return f"tick {self.tick}" if self.tick >= 0 else "its start"

    def describe(self) -> str:
        return (
            f"track {self.track!r}, {self.where}: {self.field}: expected "
            f"{_shown(self.expected)}, received {_shown(self.received)}"
        )


def _shown(value: Any) -> str:
    if value is _MISSING:
        return "nothing"
    return json.dumps(value, separators=(",", ":")) if not isinstance(value, str) else value


_MISSING = object()


def same(expected: Any, received: Any) -> bool:
    """Equal, floats bit for bit (0.0 is not -0.0; lists and objects entry by entry)."""
    if isinstance(expected, float) or isinstance(received, float):
        if not isinstance(expected, (int, float)) or not isinstance(received, (int, float)):
            return False
        if isinstance(expected, bool) or isinstance(received, bool):
            return False
        return struct.pack("<d", float(expected)) == struct.pack("<d", float(received))
    if isinstance(expected, list) and isinstance(received, list):
        return len(expected) == len(received) and all(
            same(a, b) for a, b in zip(expected, received, strict=True)
        )
    if isinstance(expected, dict) and isinstance(received, dict):
        return expected.keys() == received.keys() and all(
            same(expected[key], received[key]) for key in expected
        )
    return type(expected) is type(received) and bool(expected == received)


def first_difference(
    tick: Tick, observed: dict[str, Any], *, fields: Iterable[str] = ("phase", "opinion")
) -> tuple[str, Any, Any] | None:
    """The first of a tick's outputs that ``observed`` gives otherwise: (field, expected,
    received), or None. ``observed`` holds ``left``, ``right``, ``capture``,
    ``broadcasts`` (payloads as JSON values), ``status`` (a JSON value, or None) and those
    of ``fields`` that the observer sees (a port over a link shows neither its phase, but
    in its status, nor its opinion at full precision)."""
    out = tick.out
    for name in COMMAND_FIELDS:
        if not same(out[name], observed[name]):
            return f"act.{name}", out[name], observed[name]
    expected_casts, casts = out["broadcasts"], observed["broadcasts"]
    if len(expected_casts) != len(casts):
        return "broadcasts", len(expected_casts), len(casts)
    for index, (want, got) in enumerate(zip(expected_casts, casts, strict=True)):
        for key in want.keys() | got.keys():
            if not same(want.get(key, _MISSING), got.get(key, _MISSING)):
                return f"broadcasts[{index}].{key}", want.get(key, _MISSING), got.get(key, _MISSING)
    if "phase" in fields and not same(out["phase"], observed["phase"]):
        return "phase", out["phase"], observed["phase"]
    if "opinion" in fields and "opinion" in out and not same(out["opinion"], observed["opinion"]):
        return "opinion", out["opinion"], observed["opinion"]
    want_status, got_status = out.get("status"), observed["status"]
    if want_status is None and got_status is None:
        return None
    if want_status is None or got_status is None:
        return (
            "status",
            _MISSING if want_status is None else want_status,
            _MISSING if got_status is None else got_status,
        )
    for key in (*STATUS_FIELDS, *sorted(want_status.keys() - set(STATUS_FIELDS))):
        want, got = want_status.get(key, _MISSING), got_status.get(key, _MISSING)
        if not same(want, got):
            return f"status.{key}", want, got
    return None


# --- the Python controller on a track ----------------------------------------------------


def build_controller(track: Track) -> Controller:
    """The controller a port builds for this track: its id, map, settings and generator."""
    rng = Stream.named(track.world.seed, "robot", track.robot)
    return Controller(track.robot, track.world, track.controller, rng)


def replay(track: Track, controller: Controller | None = None) -> Divergence | None:
    """Step a fresh controller (or ``controller``) through the track; the first output
    that differs, or None."""
    controller = controller or build_controller(track)
    rejects = ports.RejectCounter()
    for tick in track.ticks:
        given = tick.inputs
        frame = track.frame(tick)
        reading = ports.BodyReading(
            t=given["t"],
            x=given["x"],
            y=given["y"],
            theta=given["theta"],
            proximity=tuple(given["prox"]),
            frame=None if frame is None else vision.decode_frame(frame),
        )
        command = controller.step(reading, ports.decode_received(tick.radio(), rejects))
        status = None
        if controller.take_status_change():
            status = json.loads(protocol.encode(controller.status(tick.tick)))
        observed = {
            "left": command.left,
            "right": command.right,
            "capture": command.capture,
            "broadcasts": [json.loads(protocol.encode(each)) for each in command.broadcasts],
            "phase": controller.phase,
            "opinion": controller.opinion,
            "status": status,
        }
        found = first_difference(tick, observed)
        if found is not None:
            return Divergence(track.name, tick.tick, *found)
    return None


__all__ = [
    "FORMAT",
    "Divergence",
    "Tick",
    "Track",
    "build_controller",
    "dump",
    "first_difference",
    "load",
    "replay",
    "same",
    "track_from_steps",
    "track_of",
]
