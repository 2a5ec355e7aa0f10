"""Foxglove messages in a run's recording: the official JSON Schemas and their builders.

The schema texts live in ``world_server/recording/foxglove_schemas/`` as JSON files copied unchanged
from the official Foxglove schemas (npm package ``@foxglove/schemas`` 2.1.0, ``dist/jsonschema``,
generated from ``schemas/jsonschema`` of github.com/foxglove/foxglove-sdk; see the README
there). The builders below return plain dicts that follow those schemas exactly: every
required field present, times as ``{sec, nsec}``, binary data as base64 text.

Pure: no Zenoh, no clocks. The recorder calls these with sim times in nanoseconds.
"""

from __future__ import annotations

import base64
import functools
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from world_server.core.body import EPUCK
from world_server.core.camera import WALL_HEIGHT
from world_server.core.layout import Layout
from world_server.core.palette import PHASE_COLOURS, UNKNOWN_PHASE_COLOUR, Rgba, site_colour

SCHEMA_DIR = Path(__file__).with_name("foxglove_schemas")
SCHEMA_SOURCE = (
    "@foxglove/schemas 2.1.0 (npm, MIT), dist/jsonschema, generated from "
    "github.com/foxglove/foxglove-sdk schemas/jsonschema"
)
SCENE_UPDATE = "foxglove.SceneUpdate"
FRAME_TRANSFORMS = "foxglove.FrameTransforms"
COMPRESSED_IMAGE = "foxglove.CompressedImage"
LOG = "foxglove.Log"
SCHEMA_NAMES = (SCENE_UPDATE, FRAME_TRANSFORMS, COMPRESSED_IMAGE, LOG)

ARENA_FRAME = "arena"  # the fixed frame: metres, origin at the nest, z up

# foxglove.LogLevel
LOG_UNKNOWN, LOG_DEBUG, LOG_INFO, LOG_WARNING, LOG_ERROR, LOG_FATAL = range(6)
_LEVEL_NAMES = {
    "DEBUG": LOG_DEBUG,
    "INFO": LOG_INFO,
    "WARNING": LOG_WARNING,
    "WARN": LOG_WARNING,
    "ERROR": LOG_ERROR,
    "CRITICAL": LOG_ERROR,
    "FATAL": LOG_FATAL,
}
# foxglove.LineType
LINE_STRIP, LINE_LOOP, LINE_LIST = 0, 1, 2

Segment = tuple[tuple[float, float], tuple[float, float]]  # a line from (x, y) to (x, y)

LINK_COLOUR: Rgba = (0.1, 0.8, 0.2, 0.9)
_DIGITS = 5  # 10 micrometres: plenty for a picture, and it keeps the JSON short


@functools.cache
def schema(name: str) -> dict[str, Any]:
    """The official JSON Schema of a Foxglove message type, e.g. ``foxglove.Log``."""
    if name not in SCHEMA_NAMES:
        raise KeyError(f"no Foxglove schema {name!r} here; known: {', '.join(SCHEMA_NAMES)}")
    text = (SCHEMA_DIR / f"{name.removeprefix('foxglove.')}.json").read_text()
    return dict(json.loads(text))


# --- small values ------------------------------------------------------------------------


def timestamp(ns: int) -> dict[str, int]:
    """A ``time`` value: seconds and nanoseconds, both non-negative."""
    ns = max(0, int(ns))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def duration(ns: int) -> dict[str, int]:
    """A ``duration`` value (nanoseconds in [0, 1e9), seconds may be negative)."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def colour(rgba: Rgba) -> dict[str, float]:
    r, g, b, a = rgba
    return {"r": r, "g": g, "b": b, "a": a}


def vector(x: float, y: float, z: float = 0.0) -> dict[str, float]:
    return {"x": round(x, _DIGITS), "y": round(y, _DIGITS), "z": round(z, _DIGITS)}


def yaw_quaternion(theta: float) -> dict[str, float]:
    """A rotation of ``theta`` radians about +z."""
    half = 0.5 * theta
    return {"x": 0.0, "y": 0.0, "z": round(math.sin(half), 6), "w": round(math.cos(half), 6)}


def pose(x: float, y: float, z: float = 0.0, theta: float = 0.0) -> dict[str, Any]:
    return {"position": vector(x, y, z), "orientation": yaw_quaternion(theta)}


def robot_frame(robot: int) -> str:
    return f"robot-{robot}"


# --- messages ----------------------------------------------------------------------------


def frame_transforms(
    ns: int, poses: Iterable[tuple[int, float, float, float]], parent: str = ARENA_FRAME
) -> dict[str, Any]:
    """``foxglove.FrameTransforms``: one ``robot-<id>`` frame per ``(id, x, y, theta)``."""
    stamp = timestamp(ns)
    return {
        "transforms": [
            {
                "timestamp": stamp,
                "parent_frame_id": parent,
                "child_frame_id": robot_frame(robot),
                "translation": vector(x, y),
                "rotation": yaw_quaternion(theta),
            }
            for robot, x, y, theta in poses
        ]
    }


def compressed_image(ns: int, frame_id: str, data: bytes, image_format: str) -> dict[str, Any]:
    """``foxglove.CompressedImage`` with the encoded image as base64 text."""
    return {
        "timestamp": timestamp(ns),
        "frame_id": frame_id,
        "data": base64.b64encode(data).decode("ascii"),
        "format": image_format,
    }


def log_level(line: str) -> int:
    """The level of a process log line (``<date> <time> <name> LEVEL message``), if it says."""
    for word in line.split(maxsplit=5)[:5]:
        level = _LEVEL_NAMES.get(word)
        if level is not None:
            return level
    return LOG_UNKNOWN


def log_message(ns: int, process: str, line: str) -> dict[str, Any]:
    """``foxglove.Log`` for one line a process wrote (no source file or line is known)."""
    return {
        "timestamp": timestamp(ns),
        "level": log_level(line),
        "message": line,
        "name": process,
        "file": "",
        "line": 0,
    }


# --- the 3D scene ------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneRobot:
    """What the scene shows of one robot."""

    phase: str | None = None
    decided_site: int | None = None
    trips: int = 0
    poolings: int = 0


def _entity(
    ns: int,
    frame_id: str,
    entity_id: str,
    *,
    frame_locked: bool = False,
    metadata: Mapping[str, str] | None = None,
    **primitives: list[Any],
) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` with every primitive list present (empty unless given)."""
    entity: dict[str, Any] = {
        "timestamp": timestamp(ns),
        "frame_id": frame_id,
        "id": entity_id,
        "lifetime": duration(0),
        "frame_locked": frame_locked,
        "metadata": [{"key": key, "value": value} for key, value in (metadata or {}).items()],
    }
    for kind in (
        "arrows",
        "cubes",
        "spheres",
        "cylinders",
        "lines",
        "triangles",
        "texts",
        "models",
    ):
        entity[kind] = primitives.pop(kind, [])
    if primitives:
        raise TypeError(f"unknown primitive lists: {sorted(primitives)}")
    return entity


Point = tuple[float, float, float]


def _cylinder(centre: Point, diameter: float, height: float, rgba: Rgba) -> dict[str, Any]:
    return {
        "pose": pose(*centre),
        "size": vector(diameter, diameter, height),
        "bottom_scale": 1.0,
        "top_scale": 1.0,
        "color": colour(rgba),
    }


def _text(
    position: Point, text: str, size: float, rgba: Rgba = (0.05, 0.05, 0.05, 1.0)
) -> dict[str, Any]:
    return {
        "pose": pose(*position),
        "billboard": True,
        "font_size": size,
        "scale_invariant": False,
        "color": colour(rgba),
        "text": text,
    }


def _lines(line_type: int, points: Sequence[Point], thickness: float, rgba: Rgba) -> dict[str, Any]:
    return {
        "type": line_type,
        "pose": pose(0.0, 0.0),
        "thickness": thickness,
        "scale_invariant": False,
        "points": [vector(*point) for point in points],
        "color": colour(rgba),
        "colors": [],
        "indices": [],
    }


class ArenaScene:
    """Builds ``foxglove.SceneUpdate`` messages of one run: arena, robots, radio links."""

    def __init__(self, layout: Layout, robot_radius: float = EPUCK.radius) -> None:
        self.layout = layout
        self.robot_radius = robot_radius

    def arena(self, ns: int) -> dict[str, Any]:
        """The wall, the floor, the nest, and each site in its colour (the run's palette,
        ``world_server.core.palette``) with a label naming its quality."""
        layout = self.layout
        radius = layout.arena_radius
        wall = [
            (radius * math.cos(a), radius * math.sin(a), 0.0)
            for a in (2 * math.pi * i / 96 for i in range(96))
        ]
        panels, labels = [], []
        for site in layout.sites:
            width = 2 * radius * math.sin(site.half_width)
            panels.append(
                {
                    "pose": pose(site.x, site.y, WALL_HEIGHT / 2, site.angle),
                    "size": vector(0.01, width, WALL_HEIGHT),
                    "color": colour(site_colour(site.id, len(layout.sites))),
                }
            )
            inside = radius - 0.12
            labels.append(
                _text(
                    (inside * math.cos(site.angle), inside * math.sin(site.angle), 0.12),
                    f"site {site.id}\nrho = {site.quality:.2f}",
                    0.04,
                )
            )
        labels.append(_text((0.0, 0.0, 0.1), "nest", 0.04))
        return _entity(
            ns,
            ARENA_FRAME,
            "arena",
            metadata={"best_site": str(layout.best_site), "sites": str(len(layout.sites))},
            cylinders=[
                _cylinder((0.0, 0.0, -0.002), 2 * radius, 0.002, (0.92, 0.92, 0.9, 1.0)),
                _cylinder((0.0, 0.0, 0.0005), 2 * layout.nest_radius, 0.001, (1.0, 0.85, 0.3, 0.6)),
            ],
            lines=[_lines(LINE_LOOP, wall, 0.01, (0.45, 0.45, 0.45, 1.0))],
            cubes=panels,
            texts=labels,
        )

    def robot_colour(self, view: SceneRobot) -> Rgba:
        if view.decided_site is not None and 0 <= view.decided_site < len(self.layout.sites):
            return site_colour(view.decided_site, len(self.layout.sites))
        if view.phase is None:
            return UNKNOWN_PHASE_COLOUR
        return PHASE_COLOURS.get(view.phase, UNKNOWN_PHASE_COLOUR)

    def robot(self, ns: int, robot: int, view: SceneRobot) -> dict[str, Any]:
        """A robot's body, heading and label in its own frame (it follows its transform)."""
        height = 0.05
        decided = "-" if view.decided_site is None else str(view.decided_site)
        return _entity(
            ns,
            robot_frame(robot),
            f"robot-{robot}",
            frame_locked=True,
            metadata={
                "phase": view.phase or "unknown",
                "trips": str(view.trips),
                "poolings": str(view.poolings),
                "decided_site": decided,
            },
            cylinders=[
                _cylinder(
                    (0.0, 0.0, height / 2), 2 * self.robot_radius, height, self.robot_colour(view)
                ),
            ],
            arrows=[
                {
                    "pose": pose(0.0, 0.0, height + 0.002),
                    "shaft_length": self.robot_radius,
                    "shaft_diameter": 0.008,
                    "head_length": 0.02,
                    "head_diameter": 0.02,
                    "color": colour((0.05, 0.05, 0.05, 1.0)),
                }
            ],
            texts=[_text((0.0, 0.0, height + 0.04), str(robot), 0.035)],
        )

    def links(self, ns: int, segments: Iterable[Segment]) -> dict[str, Any]:
        """Radio links of recent poolings, as line segments in the arena frame."""
        points: list[Point] = []
        for (x1, y1), (x2, y2) in segments:
            points += [(x1, y1, 0.06), (x2, y2, 0.06)]
        lines = [_lines(LINE_LIST, points, 0.006, LINK_COLOUR)] if points else []
        return _entity(ns, ARENA_FRAME, "radio-links", lines=lines)

    def update(
        self,
        ns: int,
        robots: Mapping[int, SceneRobot],
        segments: Iterable[Segment] = (),
    ) -> dict[str, Any]:
        """A whole ``foxglove.SceneUpdate``: arena, every robot, and the pooling links."""
        entities = [self.arena(ns), self.links(ns, segments)]
        entities += [self.robot(ns, robot, view) for robot, view in sorted(robots.items())]
        return {"deletions": [], "entities": entities}

    def robot_update(self, ns: int, robot: int, view: SceneRobot) -> dict[str, Any]:
        """A ``foxglove.SceneUpdate`` that replaces one robot's entity (its state changed)."""
        return {"deletions": [], "entities": [self.robot(ns, robot, view)]}
