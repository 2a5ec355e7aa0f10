"""Camera frame -> site quality estimate. Runs on the robot; numpy and OpenCV only.

A site panel is coloured red = 255 rho, blue = 255 (1 - rho), green = 0; walls, floor and
robots are neutral greys. So a pixel belongs to a site when it is far more red-or-blue
than green, whatever rho is, and the site's quality is the red share of its light:
``mean red / (mean red + mean blue)`` over the panel's pixels. That is smooth in rho
(a red threshold would be a step), unaffected by the panel's brightness, and averaging
channels before dividing keeps dark, noisy pixels from dominating.

Of the coloured regions in view, only the one the robot faces counts: the region
containing the image centre, or failing that the nearest one that reaches the central
half of the image. A region must also be tall, as a panel seen from sensing distance is;
far-away panels across the arena and slivers above an occluding robot give ``None``.

Every step is integer arithmetic on the pixels until the one division at the end, so the
estimate is the same bits on every CPU and in a port (docs/camera.md states each step;
OpenCV finds the connected regions, which is exact).
"""

from __future__ import annotations

import struct

import cv2
import numpy as np

from bestofn_swarm.wire import protocol

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SOI = b"\xff\xd8"
# JPEG start-of-frame markers carry the image size; C4, C8 and CC are other segments.
_JPEG_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# JPEG markers with no length field.
_JPEG_STANDALONE = frozenset(range(0xD0, 0xD8)) | {0x01}

# (R + B) / 2 - G on 0..255, averaged over a pixel's 3x3 neighbourhood: greys give 0, a
# panel's inside 127.5 (dimmed by lighting to 80 or so), a grey pixel beside a panel edge
# at most a third of that.
SITE_CHROMA_THRESHOLD = 60.0
MIN_REGION_HEIGHT_FRACTION = 0.3  # of the image height; a sensed panel spans most of it
MIN_REGION_PIXELS = 12


def decode_frame(
    data: bytes,
    max_pixels: int = 1_000_000,
    *,
    expected_size: tuple[int, int] | None = None,
    max_bytes: int = protocol.MAX_CAMERA_FRAME_BYTES,
) -> np.ndarray:
    """Decode a PNG or JPEG camera frame into an H x W x 3 uint8 BGR array.

    The image size is read from the header and checked against ``max_pixels`` (and
    ``expected_size`` = (width, height), e.g. from the frame's CameraMeta) before any
    pixel is decoded, so a small file cannot claim a huge image. Every failure is a
    ValueError saying what was wrong; no OpenCV exception or None leaks out.
    """
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ValueError(f"frame must be bytes, got {type(data).__name__}")
    data = bytes(data)
    if not data:
        raise ValueError("empty camera frame")
    if len(data) > max_bytes:
        raise ValueError(f"camera frame is {len(data)} bytes, more than the limit {max_bytes}")
    width, height = _header_size(data)
    if width * height > max_pixels:
        raise ValueError(
            f"camera frame is {width}x{height} = {width * height} pixels, "
            f"more than the limit {max_pixels}"
        )
    if expected_size is not None and (width, height) != tuple(expected_size):
        raise ValueError(
            f"camera frame is {width}x{height}, expected {expected_size[0]}x{expected_size[1]}"
        )
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    except cv2.error as error:
        raise ValueError(f"camera frame could not be decoded: {error}") from None
    if image is None:
        raise ValueError("camera frame could not be decoded (corrupt or truncated image)")
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"camera frame decoded to an unexpected {image.shape} {image.dtype}")
    if image.shape[:2] != (height, width):
        raise ValueError(
            f"camera frame decoded to {image.shape[1]}x{image.shape[0]}, "
            f"its header says {width}x{height}"
        )
    return image


def estimate_quality(
    frame: np.ndarray,
    *,
    chroma_threshold: float = SITE_CHROMA_THRESHOLD,
    min_height_fraction: float = MIN_REGION_HEIGHT_FRACTION,
) -> float | None:
    """The quality in [0, 1] of the site the camera faces, or None if no site is in view.

    ``frame`` is an H x W x 3 uint8 BGR image (as from ``decode_frame``).
    """
    if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8:
        raise ValueError("frame must be a uint8 numpy array")
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.shape[0] < 3 or frame.shape[1] < 3:
        raise ValueError(f"frame must be H x W x 3 with H, W >= 3, got shape {frame.shape}")
    height, width = frame.shape[:2]

    # Classify on 3x3 neighbourhood sums so pixel noise does not speckle the mask, then
    # erode (the image border counting as outside) so the pixels kept are inside a panel,
    # one pixel clear of its edges, where the neighbourhood mixes in the grey around it.
    sums = neighbourhood_sums(frame)
    blue, green, red = sums[..., 0], sums[..., 1], sums[..., 2]
    # The neighbourhood's mean (R + B) / 2 - G above the threshold, times 18 on both sides.
    mask = (red + blue - 2 * green) > 18.0 * chroma_threshold
    mask = _eroded(mask).view(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        mask, 4, cv2.CV_32S, cv2.CCL_DEFAULT
    )
    # Each region's first pixel in row-major order: the tie-break between equally near ones.
    values, first_pixels = np.unique(labels, return_index=True)
    first = np.zeros(count, dtype=np.int64)
    first[values] = first_pixels

    region = _facing_region(stats, first, width, height, min_height_fraction)
    if region is None:
        return None
    inside = labels == region
    red_sum = int(frame[..., 2][inside].sum(dtype=np.int64))
    blue_sum = int(frame[..., 0][inside].sum(dtype=np.int64))
    if red_sum + blue_sum == 0:
        return None
    return red_sum / (red_sum + blue_sum)


def neighbourhood_sums(frame: np.ndarray) -> np.ndarray:
    """Per pixel and channel, the sum of the 3x3 neighbourhood (int32), the image mirrored
    at its border without repeating the edge row or column (OpenCV's BORDER_REFLECT_101)."""
    height, width = frame.shape[:2]
    padded = np.pad(frame.astype(np.int32), ((1, 1), (1, 1), (0, 0)), mode="reflect")
    sums = np.zeros((height, width, frame.shape[2]), dtype=np.int32)
    for dy in range(3):
        for dx in range(3):
            sums += padded[dy : dy + height, dx : dx + width]
    return sums


def _eroded(mask: np.ndarray) -> np.ndarray:
    """A pixel stays set when its whole 3x3 neighbourhood is set; outside the image is unset."""
    height, width = mask.shape
    padded = np.pad(mask, 1, mode="constant", constant_values=False)
    kept = np.ones((height, width), dtype=bool)
    for dy in range(3):
        for dx in range(3):
            kept &= padded[dy : dy + height, dx : dx + width]
    return kept


def _facing_region(
    stats: np.ndarray, first: np.ndarray, width: int, height: int, min_height_fraction: float
) -> int | None:
    """Label of the coloured region the robot faces, from connectedComponentsWithStats
    (``first``: each label's first pixel in row-major order, which breaks ties)."""
    centre_x, centre_y = width / 2, height / 2
    band_left, band_right = width / 4, 3 * width / 4
    best: tuple[float, float, int, int] | None = None
    for label in range(1, len(stats)):
        left, top, region_width, region_height, area = (int(v) for v in stats[label])
        right, bottom = left + region_width, top + region_height
        if area < MIN_REGION_PIXELS or region_height < min_height_fraction * height:
            continue
        if right <= band_left or left >= band_right:
            continue  # at the image edge: a neighbouring site, not the one faced
        dx = max(left - centre_x, centre_x - right, 0.0)
        dy = max(top - centre_y, centre_y - bottom, 0.0)
        candidate = (dx, dy, int(first[label]), label)
        if best is None or candidate < best:
            best = candidate
    return None if best is None else best[3]


def _header_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a PNG or JPEG header; ValueError for anything else."""
    if data.startswith(PNG_SIGNATURE):
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise ValueError("truncated or malformed PNG header")
        width, height = struct.unpack(">II", data[16:24])
    elif data.startswith(JPEG_SOI):
        width, height = _jpeg_size(data)
    else:
        raise ValueError("camera frame is neither PNG nor JPEG")
    if width == 0 or height == 0:
        raise ValueError(f"camera frame header gives an empty {width}x{height} image")
    return width, height


def _jpeg_size(data: bytes) -> tuple[int, int]:
    position = 2
    while True:
        # Each marker is 0xFF, optional 0xFF fill bytes, then the marker code.
        if position >= len(data) or data[position] != 0xFF:
            raise ValueError("malformed JPEG: no frame header before the data ends")
        while position < len(data) and data[position] == 0xFF:
            position += 1
        if position >= len(data):
            raise ValueError("truncated JPEG header")
        marker = data[position]
        position += 1
        if marker in _JPEG_STANDALONE:
            continue
        if marker in (0xD8, 0xD9, 0xDA):
            raise ValueError("malformed JPEG: no frame header before the image data")
        if position + 2 > len(data):
            raise ValueError("truncated JPEG header")
        (length,) = struct.unpack(">H", data[position : position + 2])
        if length < 2:
            raise ValueError("malformed JPEG: bad segment length")
        if marker in _JPEG_SOF_MARKERS:
            if length < 7 or position + 7 > len(data):
                raise ValueError("truncated JPEG frame header")
            height, width = struct.unpack(">HH", data[position + 3 : position + 7])
            return width, height
        position += length
