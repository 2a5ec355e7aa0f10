"""What a robot's forward camera sees: a small colour image of the arena, rendered on request.

Pure numpy/OpenCV, no Zenoh. The scene (see ``docs/camera.md``):

* the arena wall is a vertical cylinder of radius ``layout.arena_radius`` and height
  ``WALL_HEIGHT``, neutral grey; each site is a coloured panel covering the wall's full
  height over ``site.angle +- site.half_width``, coloured by ``site_colour_bgr(quality)``;
* the floor is a darker neutral grey, above the wall is a light neutral background;
* other robots are dark vertical cylinders (radius ``robot_radius``, ``ROBOT_HEIGHT`` tall)
  that hide whatever is behind them;
* the camera is a pinhole with square pixels at ``CAMERA_HEIGHT`` above the floor, looking
  level along the robot's heading, mounted ``camera_forward`` ahead of the robot's centre
  (its front edge, as on an e-puck).

Rendering casts one ray per image column (a 2-D ray cast is exact here because every
object is a vertical extrusion), then fills each column's rows from the hit's depth with
perspective. The image is built as a small label map and coloured with one palette lookup.
All geometry is plain arithmetic on the heading's sine and cosine from the portable kernel
(``bestofn_swarm.wire.numeric``), and the noise comes from the run's generator
(``bestofn_swarm.wire.rng``), so a frame is the same on every CPU.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, ClassVar

import cv2
import numpy as np
from msgspec import Meta

from bestofn_swarm.wire import numeric, protocol, settings
from bestofn_swarm.wire.rng import Stream
from bestofn_swarm.wire.settings import Flag
from world_server.core.body import EPUCK
from world_server.core.layout import Layout

WALL_HEIGHT = 0.10  # metres; panels cover the wall's full height
ROBOT_HEIGHT = 0.05  # an e-puck is about 5 cm tall
CAMERA_HEIGHT = 0.03  # lens height above the floor
NEAR_CLIP = 1e-3  # metres; nothing is drawn closer than this (avoids dividing by zero)
INSIDE_MARGIN = 1e-4  # a camera pushed onto or through the wall is moved this far inside

# Neutral colours (BGR): equal channels, so they carry no red-versus-blue signal at all.
BACKGROUND_BGR = (205, 205, 205)
FLOOR_BGR = (95, 95, 95)
WALL_BGR = (150, 150, 150)
ROBOT_BGR = (35, 35, 35)

# Label values of the intermediate label map; sites are SITE_LABEL0 + index in the layout.
_BACKGROUND, _FLOOR, _WALL, _ROBOT = 0, 1, 2, 3
SITE_LABEL0 = 4

# Fast zlib level with run-length matching: frames are flat colour runs (about 160 bytes).
_PNG_PARAMS = [
    cv2.IMWRITE_PNG_COMPRESSION,
    1,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_RLE,
]


def site_colour_bgr(quality: float) -> tuple[int, int, int]:
    """The panel colour of a site of quality rho: red = 255 rho, blue = 255 (1 - rho), no green.

    Returned in OpenCV's BGR order. Raises ValueError for a quality outside [0, 1] or NaN.
    """
    if not 0.0 <= quality <= 1.0:  # also false for NaN
        raise ValueError(f"site quality must be in [0, 1], got {quality!r}")
    return (round(255 * (1.0 - quality)), 0, round(255 * quality))


@dataclass(frozen=True)
class CameraNoise:
    """Imperfections of the camera and the scene's lighting; all off by default.

    pixel_sigma
        Standard deviation, on the 0..255 scale, of independent Gaussian noise added to
        every pixel channel of every frame (then rounded and clipped to 0..255). Fresh for
        each frame, drawn from the ``rng`` passed to ``CameraRenderer.render``.
    lighting
        Amplitude ``a`` of a per-site lighting variation, fixed for the whole run (drawn
        once from the renderer's ``seed``). Site ``s`` gets two draws ``u_s, w_s`` from
        U(-1, 1); its panel's red channel is multiplied by ``(1 + a u_s)(1 + a w_s)`` and its
        blue channel by ``(1 + a u_s)(1 - a w_s)`` (then rounded and clipped). ``u_s`` changes
        the panel's brightness by up to +-a; ``w_s`` tilts its colour balance, which biases
        a red-share estimate by up to about ``a / 2`` at rho = 0.5 and less towards 0 or 1.
        Walls, floor and robots are not affected. Must be in [0, 1).
    """

    FLAG_GROUP: ClassVar[str] = "camera"

    pixel_sigma: Annotated[
        float,
        Meta(ge=0.0, le=255.0, description="Gaussian pixel noise, std-dev on the 0..255 scale"),
        Flag(name="camera-noise", metavar="SIGMA"),
    ] = 0.0
    lighting: Annotated[
        float,
        Meta(
            ge=0.0,
            lt=1.0,
            description="per-site lighting variation amplitude in [0, 1): biases each "
            "site's colour for the whole run",
        ),
        Flag(),
    ] = 0.0

    def __post_init__(self) -> None:
        settings.check(self)


def _lit_panel_colours(qualities: np.ndarray, lighting: float, rng: Stream) -> np.ndarray:
    """Each site's panel colour (BGR, uint8) after its fixed lighting variation: every
    site's brightness draw, then every site's balance draw, each uniform on (-1, 1)."""
    brightness, balance = (-1.0 + 2.0 * rng.random_array(2 * len(qualities))).reshape(2, -1)
    gain = 1.0 + lighting * brightness
    red = 255.0 * qualities * gain * (1.0 + lighting * balance)
    blue = 255.0 * (1.0 - qualities) * gain * (1.0 - lighting * balance)
    colours = np.zeros((len(qualities), 3))
    colours[:, 0] = blue
    colours[:, 2] = red
    return np.clip(np.rint(colours), 0, 255).astype(np.uint8)


class CameraRenderer:
    """Renders the forward camera image of a robot at a given pose in one run's arena."""

    def __init__(
        self,
        layout: Layout,
        spec: protocol.CameraSpec,
        robot_radius: float = EPUCK.radius,
        noise: CameraNoise = CameraNoise(),
        seed: int = 0,
        *,
        camera_forward: float | None = None,
    ) -> None:
        """``camera_forward``: lens distance ahead of the robot's centre (default: its radius)."""
        if robot_radius <= 0.0:
            raise ValueError(f"robot_radius must be positive, got {robot_radius!r}")
        self.layout = layout
        self.spec = spec
        self.robot_radius = robot_radius
        self.noise = noise
        self.camera_forward = robot_radius if camera_forward is None else camera_forward
        self._arena_radius = layout.arena_radius
        width, height = spec.width, spec.height
        self._sin_half_fov, self._cos_half_fov = numeric.sincos(spec.fov / 2)
        self._focal = (width / 2) * self._cos_half_fov / self._sin_half_fov  # pixels
        # Column c's ray in the camera's frame (x ahead, y to the left): (focal, offset)
        # made a unit vector, so no angle is ever taken.
        column_offsets = width / 2 - (np.arange(width) + 0.5)
        length = np.sqrt(self._focal * self._focal + column_offsets * column_offsets)
        self._column_cos = self._focal / length
        self._column_sin = column_offsets / length
        self._row_centres = (np.arange(height) + 0.5)[:, None]

        # Each site's direction from the centre and the cosine of its panel's half width:
        # a wall point is on the panel when the cosine of its angle to the site is larger.
        sites = layout.sites
        directions = [numeric.sincos(site.angle) for site in sites]
        self._site_cos = np.array([cos for _, cos in directions])
        self._site_sin = np.array([sin for sin, _ in directions])
        self._site_min_cos = np.array([numeric.cos(site.half_width) for site in sites])
        self._site_labels = SITE_LABEL0 + np.arange(len(sites))
        qualities = np.array([site.quality for site in sites])
        for quality in qualities:
            site_colour_bgr(float(quality))  # validates every quality once
        lighting_rng = Stream.named(seed, "camera", "lighting")
        panels = _lit_panel_colours(qualities, noise.lighting, lighting_rng)
        fixed = np.array([BACKGROUND_BGR, FLOOR_BGR, WALL_BGR, ROBOT_BGR], dtype=np.uint8)
        self._palette = np.concatenate([fixed, panels])
        # Pixel noise when render() gets no rng: a deterministic stream of this renderer's own.
        self._default_rng = Stream.named(seed, "camera", "pixels")

    def panel_colour_bgr(self, site_id: int) -> tuple[int, int, int]:
        """The colour site ``site_id``'s panel is drawn with, lighting variation included."""
        blue, green, red = self._palette[SITE_LABEL0 + site_id]
        return (int(blue), int(green), int(red))

    def render(
        self,
        x: float,
        y: float,
        theta: float,
        others: Sequence[tuple[float, float]] = (),
        rng: Stream | None = None,
    ) -> np.ndarray:
        """The H x W x 3 uint8 BGR frame seen by a robot at (x, y) heading ``theta``.

        ``others`` are the centres of the other robots (a disc centred exactly on this
        robot is ignored, so passing every robot is harmless). ``rng`` supplies this
        frame's pixel noise; without one the renderer's own seeded stream is used.
        Raises ValueError for a non-finite pose.
        """
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(theta)):
            raise ValueError(f"camera pose must be finite, got ({x}, {y}, {theta})")
        heading = numeric.sincos(theta)
        sin_theta, cos_theta = heading
        cam_x, cam_y = self._camera_position(x, y, heading)
        dir_x = cos_theta * self._column_cos - sin_theta * self._column_sin
        dir_y = sin_theta * self._column_cos + cos_theta * self._column_sin

        # Wall: the camera is inside the circle, so each ray leaves it at the far root.
        along = cam_x * dir_x + cam_y * dir_y
        inside = cam_x * cam_x + cam_y * cam_y - self._arena_radius * self._arena_radius
        wall_distance = -along + np.sqrt(np.maximum(along * along - inside, 0.0))
        wall_labels = self._wall_labels(
            cam_x + wall_distance * dir_x, cam_y + wall_distance * dir_y
        )
        wall_depth = np.maximum(wall_distance * self._column_cos, NEAR_CLIP)

        rows = self._row_centres
        horizon = self.spec.height / 2
        wall_top = horizon - self._focal * (WALL_HEIGHT - CAMERA_HEIGHT) / wall_depth
        wall_bottom = horizon + self._focal * CAMERA_HEIGHT / wall_depth
        labels = np.where(
            rows < wall_top, _BACKGROUND, np.where(rows < wall_bottom, wall_labels, _FLOOR)
        )

        robot_depth = self._nearest_robot_depth(
            others, own=(x, y), camera=(cam_x, cam_y), heading=heading, directions=(dir_x, dir_y)
        )
        if robot_depth is not None:
            robot_top = horizon - self._focal * (ROBOT_HEIGHT - CAMERA_HEIGHT) / robot_depth
            robot_bottom = horizon + self._focal * CAMERA_HEIGHT / robot_depth
            labels = np.where((rows >= robot_top) & (rows < robot_bottom), _ROBOT, labels)

        image = np.take(self._palette, labels, axis=0)  # much faster than fancy indexing
        if self.noise.pixel_sigma > 0.0:
            image = self._add_pixel_noise(image, rng if rng is not None else self._default_rng)
        return image

    def encode(self, image: np.ndarray) -> bytes:
        """The frame as PNG bytes (lossless, so the robot sees exactly what was rendered)."""
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"expected an HxWx3 uint8 image, got {image.shape} {image.dtype}")
        ok, buffer = cv2.imencode(".png", image, _PNG_PARAMS)
        if not ok:
            raise ValueError("OpenCV could not encode the frame as PNG")
        return buffer.tobytes()

    # --- helpers ---------------------------------------------------------------------

    def _camera_position(
        self, x: float, y: float, heading: tuple[float, float]
    ) -> tuple[float, float]:
        """The lens position, kept strictly inside the arena so every ray meets the wall
        (``heading``: the sine and cosine of the robot's heading)."""
        sin_theta, cos_theta = heading
        cam_x = x + self.camera_forward * cos_theta
        cam_y = y + self.camera_forward * sin_theta
        distance = numeric.hypot(cam_x, cam_y)
        limit = self._arena_radius - INSIDE_MARGIN
        if distance > limit:
            cam_x, cam_y = cam_x * limit / distance, cam_y * limit / distance
        return cam_x, cam_y

    def _wall_labels(self, hit_x: np.ndarray, hit_y: np.ndarray) -> np.ndarray:
        """Per column: the label of the site panel the wall point (hit_x, hit_y) is on, or
        plain wall. The nearest site is the one whose direction has the largest cosine to
        the point's (the first of equals)."""
        length = np.sqrt(hit_x * hit_x + hit_y * hit_y)
        unit_x, unit_y = (hit_x / length)[:, None], (hit_y / length)[:, None]
        cosines = unit_x * self._site_cos + unit_y * self._site_sin  # columns x sites
        nearest = np.argmax(cosines, axis=1)
        on_panel = cosines[np.arange(len(nearest)), nearest] >= self._site_min_cos[nearest]
        return np.where(on_panel, self._site_labels[nearest], _WALL)

    def _nearest_robot_depth(
        self,
        others: Sequence[tuple[float, float]],
        *,
        own: tuple[float, float],
        camera: tuple[float, float],
        heading: tuple[float, float],
        directions: tuple[np.ndarray, np.ndarray],
    ) -> np.ndarray | None:
        """Per column: depth of the nearest robot body hit (inf where none), or None."""
        if len(others) == 0:
            return None
        (x, y), (cam_x, cam_y), (dir_x, dir_y) = own, camera, directions
        centres = np.asarray(others, dtype=float).reshape(-1, 2)
        offset_x, offset_y = centres[:, 0] - x, centres[:, 1] - y
        not_self = offset_x * offset_x + offset_y * offset_y > 1e-18
        # Cull to bodies that may reach into the field of view: in front of the lens and
        # no farther than a radius outside the view cone's edges (a cheap superset; the
        # exact ray test follows).
        rel_x, rel_y = centres[:, 0] - cam_x, centres[:, 1] - cam_y
        sin_theta, cos_theta = heading
        ahead = rel_x * cos_theta + rel_y * sin_theta
        across = np.abs(rel_y * cos_theta - rel_x * sin_theta)
        beyond_edge = across * self._cos_half_fov - ahead * self._sin_half_fov
        visible = (ahead > -self.robot_radius) & (beyond_edge <= self.robot_radius)
        centres = centres[not_self & visible]
        if len(centres) == 0:
            return None
        lens_x = (cam_x - centres[:, 0])[:, None]
        lens_y = (cam_y - centres[:, 1])[:, None]
        along = lens_x * dir_x + lens_y * dir_y  # bodies x columns
        outside = lens_x * lens_x + lens_y * lens_y - self.robot_radius * self.robot_radius
        discriminant = along * along - outside
        entry = -along - np.sqrt(np.maximum(discriminant, 0.0))
        hit = (discriminant >= 0.0) & (entry > 0.0)
        # A lens inside another body (robots pressed together) sees only that body.
        hit_distance = np.where(outside < 0.0, NEAR_CLIP, np.where(hit, entry, np.inf))
        nearest = hit_distance.min(axis=0)
        if not np.isfinite(nearest).any():
            return None
        depths: np.ndarray = np.maximum(nearest * self._column_cos, NEAR_CLIP)
        return depths

    def _add_pixel_noise(self, image: np.ndarray, rng: Stream) -> np.ndarray:
        """Every channel of every pixel, in row-major order, plus sigma times one normal
        draw; rounded half to even and clipped to 0..255."""
        noise = rng.normal_array(image.size).reshape(image.shape)
        noisy = image.astype(np.float64) + self.noise.pixel_sigma * noise
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
