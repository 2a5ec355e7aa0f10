"""Writes c_robot/tests/png_cases.json: camera frames as the world encodes them, and PNGs
with every filter type and block kind, each with what OpenCV decodes (a hash of the BGR
pixels) and what robot_agent/core/vision.py estimates (run with the project's venv:
.venv/bin/python c_robot/tests/make_png_cases.py)."""

import hashlib
import json
import random
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core import vision
from world_server.core.camera import CameraNoise, CameraRenderer
from world_server.core.layout import make_layout


def estimate(image):
    try:
        quality = vision.estimate_quality(image)
    except ValueError:
        return None
    if quality is None:
        return None
    return struct.pack(">d", quality).hex()


def case(name, data, expect_ok=True):
    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR) if data else None
    entry = {"name": name, "hex": data.hex()}
    if image is None or not expect_ok:
        entry["decodes"] = False
        return entry
    entry["decodes"] = True
    entry["width"], entry["height"] = int(image.shape[1]), int(image.shape[0])
    entry["sha256"] = hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()
    entry["quality"] = estimate(image)
    return entry


def chunk(kind, body):
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def png(image_rgb, colour_type, filters, level=6, strategy=zlib.Z_DEFAULT_STRATEGY, *, split=0):
    height, width = image_rgb.shape[:2]
    channels = {0: 1, 2: 3, 6: 4}[colour_type]
    rows = image_rgb.reshape(height, width * channels).astype(np.int32)
    raw = bytearray()
    for r in range(height):
        f = filters[r % len(filters)]
        cur = rows[r]
        prev = rows[r - 1] if r else np.zeros_like(cur)
        out = []
        for i in range(width * channels):
            a = int(cur[i - channels]) if i >= channels else 0
            b = int(prev[i])
            c = int(prev[i - channels]) if i >= channels else 0
            x = int(cur[i])
            if f == 0:
                p = 0
            elif f == 1:
                p = a
            elif f == 2:
                p = b
            elif f == 3:
                p = (a + b) >> 1
            else:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                p = a if pa <= pb and pa <= pc else b if pb <= pc else c
            out.append((x - p) & 255)
        raw.append(f)
        raw.extend(out)
    compressor = zlib.compressobj(level, zlib.DEFLATED, 15, 9, strategy)
    data = compressor.compress(bytes(raw)) + compressor.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    idats = [data] if not split else [data[i : i + split] for i in range(0, len(data), split)]
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"tEXt", b"Comment\x00c_robot test")
        + b"".join(chunk(b"IDAT", part) for part in idats)
        + chunk(b"IEND", b"")
    )


cases = []
spec = protocol.CameraSpec(width=64, height=48, fov=0.84)
rng = random.Random(7)
for sites in (5, 10, 100):
    layout = make_layout(sites, 10, seed=sites)
    for noise in (CameraNoise(), CameraNoise(pixel_sigma=10.0), CameraNoise(lighting=0.2)):
        renderer = CameraRenderer(layout, spec, noise=noise, seed=3)
        for site in range(min(sites, 6)):
            for sideways, heading in ((0.0, 0.0), (0.03, 0.17), (-0.02, -0.3), (0.0, 0.6)):
                x, y, theta = layout.sensing_pose(site, sideways=sideways, heading_error=heading)
                others = []
                if rng.random() < 0.3:  # someone between the robot and the panel
                    others = [(x * 1.08, y * 1.08)]
                image = renderer.render(x, y, theta, others, rng=Stream(rng.getrandbits(64)))
                name = f"world n={sites} noise={noise} site={site} off=({sideways},{heading})"
                cases.append(case(name, renderer.encode(image)))
        # a frame from the middle of the arena: far panels, no site in view
        image = renderer.render(0.0, 0.0, 0.3, [], rng=Stream(1))
        cases.append(case(f"world n={sites} from the nest", renderer.encode(image)))

random_rgb = np.array(
    [[[rng.randrange(256) for _ in range(3)] for _ in range(17)] for _ in range(11)], dtype=np.uint8
)
panel = np.zeros((48, 64, 3), dtype=np.uint8)
panel[:] = (95, 95, 95)
panel[6:42, 10:54] = (200, 0, 55)  # RGB: a panel of quality 200/255
for filters in ([0], [1], [2], [3], [4], [0, 1, 2, 3, 4]):
    cases.append(case(f"rgb filters {filters}", png(random_rgb, 2, filters)))
    cases.append(case(f"panel filters {filters}", png(panel, 2, filters)))
for level, strategy, label in (
    (0, zlib.Z_DEFAULT_STRATEGY, "stored"),
    (9, zlib.Z_FIXED, "fixed"),
    (9, zlib.Z_DEFAULT_STRATEGY, "dynamic"),
    (1, zlib.Z_RLE, "rle"),
):
    cases.append(case(f"rgb {label} blocks", png(random_rgb, 2, [4], level, strategy)))
    cases.append(case(f"panel {label} blocks", png(panel, 2, [1], level, strategy)))
cases.append(case("rgb split over IDAT chunks", png(random_rgb, 2, [0, 4], split=7)))
grey = np.array([[rng.randrange(256) for _ in range(9)] for _ in range(5)], dtype=np.uint8)
cases.append(case("greyscale", png(grey[..., None].reshape(5, 9, 1), 0, [0, 2, 4])))
rgba = np.array(
    [[[rng.randrange(256) for _ in range(4)] for _ in range(6)] for _ in range(7)], dtype=np.uint8
)
cases.append(case("rgba: alpha dropped", png(rgba, 6, [1, 3])))
for level in range(10):  # OpenCV's own encoder at every level
    ok, buf = cv2.imencode(
        ".png", cv2.cvtColor(panel, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, level]
    )
    cases.append(case(f"opencv level {level}", buf.tobytes()))
tiny = np.zeros((2, 2, 3), dtype=np.uint8)
cases.append(case("2x2: too small to estimate", png(tiny, 2, [0])))

good = png(panel, 2, [1])
cases.append(case("truncated", good[: len(good) // 2], expect_ok=False))
bad_crc = bytearray(good)
bad_crc[-20] ^= 1
cases.append(case("a changed byte", bytes(bad_crc), expect_ok=False))
cases.append(case("not a png", b"GIF89a" + bytes(40), expect_ok=False))
cases.append(case("empty", b"", expect_ok=False))
bad_filter = bytearray(png(random_rgb, 2, [0], level=0))
cases.append(
    case(
        "zero-size header",
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 0, 5, 8, 2, 0, 0, 0))
        + chunk(b"IEND", b""),
        expect_ok=False,
    )
)

Path(__file__).with_name("png_cases.json").write_text(json.dumps(cases, indent=0) + "\n")
print(len(cases), "cases;", sum(1 for c in cases if c.get("quality")), "with a quality")
