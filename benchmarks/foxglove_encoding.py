"""The recorder's Foxglove messages as JSON (today) against foxglove-sdk's typed messages
(protobuf): bytes per message, and CPU time to build and encode one.

    .venv/bin/python benchmarks/foxglove_encoding.py [--robots 100]

Measures the two messages that dominate a recording's Foxglove topics: the whole-scene
``foxglove.SceneUpdate`` written at every ``world/state``, and a camera frame as
``foxglove.CompressedImage`` (a PNG as base64 in JSON, against raw bytes in protobuf).
Both are also compressed with zstd, as MCAP chunks are. Figures are ratios of one run on
one machine; absolute times vary with its load.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any

import msgspec
import zstandard
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CompressedImage,
    CylinderPrimitive,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from bestofn_swarm.wire import protocol
from world_server.core.camera import CameraRenderer
from world_server.core.layout import make_layout
from world_server.recording import foxglove


def per_call(function: Callable[[], Any], seconds: float = 0.5) -> float:
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        function()
        calls += 1
    return (time.perf_counter() - start) / calls


def typed_robot(ns: int, robot: int, view: foxglove.SceneRobot, scene: foxglove.ArenaScene) -> Any:
    r, g, b, a = scene.robot_colour(view)
    return SceneEntity(
        timestamp=Timestamp.from_epoch_secs(ns / 1e9),
        frame_id=foxglove.robot_frame(robot),
        id=f"robot-{robot}",
        frame_locked=True,
        cylinders=[
            CylinderPrimitive(
                pose=Pose(position=Vector3(x=0, y=0, z=0.025), orientation=Quaternion(w=1)),
                size=Vector3(x=0.074, y=0.074, z=0.05),
                bottom_scale=1.0,
                top_scale=1.0,
                color=Color(r=r, g=g, b=b, a=a),
            )
        ],
        arrows=[
            ArrowPrimitive(
                pose=Pose(position=Vector3(x=0, y=0, z=0.052), orientation=Quaternion(w=1)),
                shaft_length=0.037,
                shaft_diameter=0.008,
                head_length=0.02,
                head_diameter=0.02,
                color=Color(r=0.05, g=0.05, b=0.05, a=1),
            )
        ],
        texts=[
            TextPrimitive(
                pose=Pose(position=Vector3(x=0, y=0, z=0.09), orientation=Quaternion(w=1)),
                billboard=True,
                font_size=0.035,
                color=Color(r=0.05, g=0.05, b=0.05, a=1),
                text=str(robot),
            )
        ],
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, default=100)
    args = parser.parse_args()
    layout = make_layout(10, args.robots, 0)
    scene = foxglove.ArenaScene(layout)
    views = {robot: foxglove.SceneRobot("to_site", None, 3, 2) for robot in range(args.robots)}
    encoder = msgspec.json.Encoder()
    zstd = zstandard.ZstdCompressor()

    def json_scene() -> bytes:
        return encoder.encode(scene.update(10**9, views))

    def typed_scene() -> bytes:
        entities = [typed_robot(10**9, robot, view, scene) for robot, view in views.items()]
        return bytes(SceneUpdate(entities=entities).encode())

    camera = CameraRenderer(layout, protocol.CameraSpec(64, 48, math.radians(60)))
    png = camera.encode(camera.render(*layout.sensing_pose(0)))

    def json_image() -> bytes:
        return encoder.encode(foxglove.compressed_image(10**9, "robot-0/camera", png, "png"))

    def typed_image() -> bytes:
        image = CompressedImage(
            timestamp=Timestamp.from_epoch_secs(1.0),
            frame_id="robot-0/camera",
            data=png,
            format="png",
        )
        return bytes(image.encode())

    print(f"{args.robots} robots; PNG frame of {len(png)} bytes")
    print(f"{'message':32} {'bytes':>8} {'zstd':>8} {'us/encode':>10}")
    for name, function in (
        (
            "SceneUpdate, JSON (robots only)",
            lambda: encoder.encode(
                {"deletions": [], "entities": [scene.robot(10**9, r, v) for r, v in views.items()]}
            ),
        ),
        ("SceneUpdate, JSON (with arena)", json_scene),
        ("SceneUpdate, SDK protobuf (robots)", typed_scene),
        ("CompressedImage, JSON base64", json_image),
        ("CompressedImage, SDK protobuf", typed_image),
    ):
        data = function()
        print(
            f"{name:32} {len(data):8d} {len(zstd.compress(data)):8d} "
            f"{per_call(function) * 1e6:10.1f}"
        )


if __name__ == "__main__":
    main()
