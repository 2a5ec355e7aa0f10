"""The world's camera renderer and the robot's quality estimator, tested together.

A robot at a site's viewpoint must read that site's quality closely enough that every
pairwise comparison of qualities is right; with nothing (or something else) in view it
must read nothing, never a wrong value.
"""

from __future__ import annotations

import itertools
import math
import struct
import zlib
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.rng import Stream
from robot_agent.core.vision import decode_frame, estimate_quality
from world_server.core.camera import (
    FLOOR_BGR,
    WALL_BGR,
    CameraNoise,
    CameraRenderer,
    site_colour_bgr,
)
from world_server.core.layout import Layout, make_layout

SPEC = protocol.CameraSpec(width=64, height=48, fov=0.84)
ROBOT_RADIUS = 0.037
VIEW_DISTANCE = 0.15
SITE_COUNTS = (2, 5, 10, 50, 100)
SIDEWAYS_ERRORS = (-0.03, 0.0, 0.03)
HEADING_ERRORS = (math.radians(-10), 0.0, math.radians(10))
DISTANCE_ERRORS = (-0.02, 0.0, 0.02)

pytestmark = pytest.mark.timeout(60)


def tolerance(num_sites: int) -> float:
    return 0.5 / (num_sites - 1)


def layout_for(num_sites: int, seed: int = 7) -> Layout:
    return make_layout(num_sites, 10, seed=seed)


# --- colour rule ---------------------------------------------------------------------


def test_site_colour_is_red_share_quality_in_bgr() -> None:
    assert site_colour_bgr(1.0) == (0, 0, 255)
    assert site_colour_bgr(0.0) == (255, 0, 0)
    assert site_colour_bgr(0.5) == (128, 0, 128)
    blue, green, red = site_colour_bgr(0.25)
    assert (blue, green, red) == (191, 0, 64)


@pytest.mark.parametrize("quality", [-0.01, 1.01, math.nan, math.inf])
def test_site_colour_rejects_qualities_outside_unit_interval(quality: float) -> None:
    with pytest.raises(ValueError, match="quality"):
        site_colour_bgr(quality)


@pytest.mark.parametrize("quality", [0.0, 0.1, 1 / 3, 0.5, 0.9, 1.0])
def test_estimate_of_a_full_frame_of_site_colour_is_its_quality(quality: float) -> None:
    frame = np.empty((48, 64, 3), np.uint8)
    frame[:] = site_colour_bgr(quality)
    estimate = estimate_quality(frame)
    assert estimate is not None
    assert estimate == pytest.approx(quality, abs=1 / 255)


def test_estimate_of_neutral_frames_is_none() -> None:
    for grey in (0, 35, 95, 150, 205, 255):
        assert estimate_quality(np.full((48, 64, 3), grey, np.uint8)) is None


# --- the robot facing a site reads its quality ---------------------------------------


@pytest.mark.parametrize("num_sites", SITE_COUNTS)
def test_every_site_is_read_within_half_a_quality_step_from_perturbed_viewpoints(
    num_sites: int,
) -> None:
    layout = layout_for(num_sites)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    worst = 0.0
    for site in layout.sites:
        for sideways, heading, distance in itertools.product(
            SIDEWAYS_ERRORS, HEADING_ERRORS, DISTANCE_ERRORS
        ):
            pose = layout.sensing_pose(site.id, VIEW_DISTANCE + distance, sideways, heading)
            estimate = estimate_quality(renderer.render(*pose))
            assert estimate is not None, (site.id, sideways, heading, distance)
            worst = max(worst, abs(estimate - site.quality))
    assert worst < tolerance(num_sites)


@pytest.mark.parametrize("num_sites", SITE_COUNTS)
def test_estimates_order_every_pair_of_sites_like_their_qualities(num_sites: int) -> None:
    layout = layout_for(num_sites, seed=11)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    estimates: dict[int, float] = {}
    for site in layout.sites:
        frame = decode_frame(renderer.encode(renderer.render(*layout.sensing_pose(site.id))))
        estimate = estimate_quality(frame)
        assert estimate is not None
        estimates[site.id] = estimate
    for first, second in itertools.combinations(layout.sites, 2):
        better_by_estimate = estimates[first.id] > estimates[second.id]
        assert better_by_estimate == (first.quality > second.quality)


def test_estimate_is_smooth_in_quality_not_a_threshold() -> None:
    qualities = [i / 20 for i in range(21)]
    estimates: list[float] = []
    for quality in qualities:
        frame = np.empty((48, 64, 3), np.uint8)
        frame[:] = WALL_BGR
        frame[:, 16:48] = site_colour_bgr(quality)
        estimate = estimate_quality(frame)
        assert estimate is not None
        estimates.append(estimate)
    assert np.all(np.diff(estimates) > 0)
    assert np.allclose(estimates, qualities, atol=1 / 255)


# --- nothing to read -----------------------------------------------------------------


@pytest.mark.parametrize("num_sites", SITE_COUNTS)
def test_bare_wall_between_sites_gives_none(num_sites: int) -> None:
    layout = layout_for(num_sites)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    spacing = 2 * math.pi / num_sites
    for site in layout.sites:
        gap_angle = site.angle + spacing / 2
        radius = layout.arena_radius - VIEW_DISTANCE
        pose = (radius * math.cos(gap_angle), radius * math.sin(gap_angle), gap_angle)
        assert estimate_quality(renderer.render(*pose)) is None, site.id


@pytest.mark.parametrize("num_sites", SITE_COUNTS)
def test_facing_the_arena_centre_gives_none(num_sites: int) -> None:
    layout = layout_for(num_sites)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    for site in layout.sites:
        x, y, theta = layout.sensing_pose(site.id)
        assert estimate_quality(renderer.render(x, y, theta + math.pi)) is None, site.id
    for heading in np.linspace(0, 2 * math.pi, 16, endpoint=False):
        assert estimate_quality(renderer.render(0.0, 0.0, float(heading))) is None


# --- occlusion -----------------------------------------------------------------------


def occluder_positions(layout: Layout, site_id: int) -> list[tuple[float, float]]:
    """Robot centres between the viewer and the wall, none overlapping the viewer."""
    x, y, theta = layout.sensing_pose(site_id)
    forward = (math.cos(theta), math.sin(theta))
    left = (-forward[1], forward[0])
    positions = []
    for ahead in np.linspace(0.0, VIEW_DISTANCE - ROBOT_RADIUS, 12):
        for across in np.linspace(-0.15, 0.15, 25):
            px = x + ahead * forward[0] + across * left[0]
            py = y + ahead * forward[1] + across * left[1]
            clear_of_viewer = math.hypot(px - x, py - y) >= 2 * ROBOT_RADIUS
            inside_arena = math.hypot(px, py) <= layout.arena_radius - ROBOT_RADIUS
            if clear_of_viewer and inside_arena:
                positions.append((px, py))
    return positions


@pytest.mark.parametrize("num_sites", [2, 10, 100])
def test_an_occluding_robot_gives_none_or_the_right_value(num_sites: int) -> None:
    layout = layout_for(num_sites)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    outcomes = {"none": 0, "right": 0}
    for site in layout.sites[:10]:
        pose = layout.sensing_pose(site.id)
        for occluder in occluder_positions(layout, site.id):
            frame = renderer.render(*pose, others=[occluder])
            estimate = estimate_quality(frame)
            if estimate is None:
                outcomes["none"] += 1
            else:
                assert abs(estimate - site.quality) < tolerance(num_sites), (site.id, occluder)
                outcomes["right"] += 1
    # Both outcomes occur: occluders really hide the panel, and partial ones leave it readable.
    assert outcomes["none"] > 0
    assert outcomes["right"] > 0


def test_two_occluders_from_perturbed_poses_never_give_a_wrong_value() -> None:
    layout = layout_for(100)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    rng = Stream(5)
    for site in layout.sites[:20]:
        pose = layout.sensing_pose(
            site.id, VIEW_DISTANCE, rng.uniform(-0.03, 0.03), rng.uniform(-0.17, 0.17)
        )
        candidates = occluder_positions(layout, site.id)
        for _ in range(10):
            chosen = rng.sample(range(len(candidates)), 2)
            others = [candidates[i] for i in chosen]
            estimate = estimate_quality(renderer.render(*pose, others=others))
            assert estimate is None or abs(estimate - site.quality) < tolerance(100)


def test_a_robot_touching_the_camera_blacks_out_the_view() -> None:
    layout = layout_for(5)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    x, y, theta = layout.sensing_pose(0)
    touching = (x + 2 * ROBOT_RADIUS * math.cos(theta), y + 2 * ROBOT_RADIUS * math.sin(theta))
    frame = renderer.render(x, y, theta, others=[touching])
    assert estimate_quality(frame) is None
    assert frame.max() < max(FLOOR_BGR)  # nothing but the dark body


def test_robots_behind_or_the_robot_itself_do_not_change_the_view() -> None:
    layout = layout_for(10)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    x, y, theta = layout.sensing_pose(3)
    behind = (x - 0.1 * math.cos(theta), y - 0.1 * math.sin(theta))
    clear = renderer.render(x, y, theta)
    assert np.array_equal(renderer.render(x, y, theta, others=[(x, y), behind]), clear)


def test_neighbouring_panel_at_the_edge_does_not_steal_the_estimate() -> None:
    frame = np.empty((48, 64, 3), np.uint8)
    frame[:] = WALL_BGR
    frame[:, 20:50] = site_colour_bgr(0.3)  # the faced panel
    frame[:, 58:] = site_colour_bgr(1.0)  # a neighbour at the right edge
    assert estimate_quality(frame) == pytest.approx(0.3, abs=1 / 255)
    frame[:, 20:50] = WALL_BGR  # the faced panel hidden: the neighbour alone is not read
    assert estimate_quality(frame) is None


def test_robot_pressed_against_the_wall_still_renders() -> None:
    layout = layout_for(5)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    with np.errstate(all="raise"):
        frame = renderer.render(*layout.sensing_pose(2, distance=ROBOT_RADIUS))
        beyond = renderer.render(*layout.sensing_pose(2, distance=0.0))
    estimate = estimate_quality(frame)
    assert estimate == pytest.approx(layout.site(2).quality, abs=tolerance(5))
    assert beyond.shape == (48, 64, 3)


# --- determinism and noise -----------------------------------------------------------


def test_noise_off_frames_are_deterministic_and_survive_png() -> None:
    layout = layout_for(10)
    first = CameraRenderer(layout, SPEC, ROBOT_RADIUS, seed=1)
    second = CameraRenderer(layout, SPEC, ROBOT_RADIUS, seed=2)
    pose = layout.sensing_pose(4, sideways=0.01, heading_error=0.05)
    frame = first.render(*pose, rng=Stream(1))
    assert frame.shape == (48, 64, 3)
    assert frame.dtype == np.uint8
    assert np.array_equal(frame, first.render(*pose, rng=Stream(2)))
    assert np.array_equal(frame, second.render(*pose))
    assert np.array_equal(decode_frame(first.encode(frame), expected_size=(64, 48)), frame)


def test_camera_spec_sets_the_frame_size() -> None:
    layout = layout_for(5)
    spec = protocol.CameraSpec(width=160, height=120, fov=0.84)
    renderer = CameraRenderer(layout, spec, ROBOT_RADIUS)
    frame = renderer.render(*layout.sensing_pose(1))
    assert frame.shape == (120, 160, 3)
    assert estimate_quality(frame) == pytest.approx(layout.site(1).quality, abs=1 / 255)


def test_pixel_noise_is_fresh_per_frame_and_reproducible_from_the_rng() -> None:
    layout = layout_for(5)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS, CameraNoise(pixel_sigma=10.0))
    pose = layout.sensing_pose(0)
    a = renderer.render(*pose, rng=Stream(3))
    b = renderer.render(*pose, rng=Stream(3))
    c = renderer.render(*pose, rng=Stream(4))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    again = CameraRenderer(layout, SPEC, ROBOT_RADIUS, CameraNoise(pixel_sigma=10.0))
    assert np.array_equal(renderer.render(*pose), again.render(*pose))  # own seeded stream


def estimate_errors(layout: Layout, noise: CameraNoise, frames: int) -> np.ndarray:
    """Signed estimate errors over every site and ``frames`` noisy frames of each."""
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS, noise, seed=3)
    rng = Stream(17)
    errors = []
    for site in layout.sites:
        for _ in range(frames):
            estimate = estimate_quality(renderer.render(*layout.sensing_pose(site.id), rng=rng))
            assert estimate is not None
            errors.append(estimate - site.quality)
    return np.array(errors)


def test_estimates_spread_and_errors_grow_with_pixel_sigma() -> None:
    layout = layout_for(10)
    mean_abs_errors = []
    for sigma in (2.0, 10.0, 25.0, 50.0):
        errors = estimate_errors(layout, CameraNoise(pixel_sigma=sigma), frames=8)
        assert errors.std() > 0.0
        mean_abs_errors.append(float(np.abs(errors).mean()))
    assert np.all(np.diff(mean_abs_errors) > 0), mean_abs_errors
    assert mean_abs_errors[0] < tolerance(10)  # light noise keeps every comparison right


def test_lighting_is_a_fixed_property_of_each_site_for_the_run() -> None:
    layout = layout_for(10)
    noise = CameraNoise(lighting=0.2)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS, noise, seed=9)
    same_seed = CameraRenderer(layout, SPEC, ROBOT_RADIUS, noise, seed=9)
    other_seed = CameraRenderer(layout, SPEC, ROBOT_RADIUS, noise, seed=10)
    colours = [renderer.panel_colour_bgr(site.id) for site in layout.sites]
    assert colours == [same_seed.panel_colour_bgr(site.id) for site in layout.sites]
    assert colours != [other_seed.panel_colour_bgr(site.id) for site in layout.sites]
    assert colours != [site_colour_bgr(site.quality) for site in layout.sites]
    for site in layout.sites:
        pose = layout.sensing_pose(site.id)
        first = estimate_quality(renderer.render(*pose))
        assert first == estimate_quality(renderer.render(*pose))  # no frame-to-frame change
        assert first is not None
        assert abs(first - site.quality) <= 0.2 / 2 + 1 / 255


def test_lighting_errors_grow_with_amplitude() -> None:
    layout = layout_for(50)
    mean_abs_errors = [
        float(np.abs(estimate_errors(layout, CameraNoise(lighting=a), frames=1)).mean())
        for a in (0.0, 0.05, 0.2)
    ]
    assert mean_abs_errors[0] < 1 / 255
    assert mean_abs_errors[0] < mean_abs_errors[1] < mean_abs_errors[2]


def test_render_rejects_a_non_finite_pose() -> None:
    renderer = CameraRenderer(layout_for(5), SPEC, ROBOT_RADIUS)
    for pose in [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, -math.inf)]:
        with pytest.raises(ValueError, match="finite"):
            renderer.render(*pose)


@pytest.mark.parametrize(
    "fields", [{"pixel_sigma": -1.0}, {"pixel_sigma": math.nan}, {"lighting": 1.0}]
)
def test_camera_noise_rejects_bad_values(fields: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        CameraNoise(**fields)


# --- decoding frames safely ----------------------------------------------------------


def sample_png() -> bytes:
    layout = layout_for(5)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS, CameraNoise(pixel_sigma=20.0))
    return renderer.encode(renderer.render(*layout.sensing_pose(0)))


def sample_jpeg() -> bytes:
    frame = np.full((48, 64, 3), site_colour_bgr(0.7), np.uint8)
    ok, buffer = cv2.imencode(".jpg", frame)
    assert ok
    return buffer.tobytes()


def png_header_only(width: int, height: int) -> bytes:
    """A PNG signature and IHDR chunk claiming a size, with no pixel data at all."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return (
        b"\x89PNG\r\n\x1a\n"
        + struct.pack(">I", len(ihdr))
        + chunk
        + struct.pack(">I", zlib.crc32(chunk))
    )


def test_jpeg_frames_decode_and_estimate() -> None:
    frame = decode_frame(sample_jpeg(), expected_size=(64, 48))
    assert frame.shape == (48, 64, 3)
    assert estimate_quality(frame) == pytest.approx(0.7, abs=0.02)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "empty"),
        (b"hello, world", "neither PNG nor JPEG"),
        (bytes(range(256)) * 4, "neither PNG nor JPEG"),
        (b"\x89PNG\r\n\x1a\n", "PNG header"),
        (png_header_only(64, 48), "could not be decoded"),
        (png_header_only(100_000, 100_000), "more than the limit"),
        (png_header_only(0, 48), "empty"),
        (b"\xff\xd8\xff", "JPEG"),
        (b"\xff\xd8\xff\xda\x00\x02", "JPEG"),
    ],
)
def test_decode_rejects_garbage_with_value_error(data: bytes, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        decode_frame(data)


@pytest.mark.parametrize("make", [sample_png, sample_jpeg])
def test_decode_rejects_every_truncation(make: Callable[[], bytes]) -> None:
    data = make()
    for cut in range(0, len(data) - 1):
        with pytest.raises(ValueError):
            decode_frame(data[:cut])


def test_decode_rejects_huge_and_wrong_sized_images() -> None:
    big = np.zeros((1001, 1000, 3), np.uint8)  # compresses to a few kB
    ok, buffer = cv2.imencode(".png", big)
    assert ok
    with pytest.raises(ValueError, match="more than the limit"):
        decode_frame(buffer.tobytes())
    assert decode_frame(buffer.tobytes(), max_pixels=2_000_000).shape == (1001, 1000, 3)
    with pytest.raises(ValueError, match="expected 32x48"):
        decode_frame(sample_png(), expected_size=(32, 48))
    with pytest.raises(ValueError, match="bytes"):
        decode_frame(sample_png(), max_bytes=10)


def test_decode_rejects_other_image_formats_and_types() -> None:
    ok, bmp = cv2.imencode(".bmp", np.zeros((48, 64, 3), np.uint8))
    assert ok
    with pytest.raises(ValueError, match="neither PNG nor JPEG"):
        decode_frame(bmp.tobytes())
    with pytest.raises(ValueError, match="bytes"):
        not_bytes: Any = "not bytes"
        decode_frame(not_bytes)


def test_estimate_rejects_frames_of_the_wrong_shape_or_type() -> None:
    for bad in (
        np.zeros((48, 64), np.uint8),
        np.zeros((48, 64, 4), np.uint8),
        np.zeros((48, 64, 3), np.float32),
        np.zeros((2, 64, 3), np.uint8),
    ):
        with pytest.raises(ValueError):
            estimate_quality(bad)


def check_decodes_or_value_error(data: bytes) -> None:
    try:
        frame = decode_frame(data)
    except ValueError:
        return
    assert frame.dtype == np.uint8
    assert frame.ndim == 3
    assert frame.shape[2] == 3
    estimate = estimate_quality(frame) if min(frame.shape[:2]) >= 3 else None
    assert estimate is None or 0.0 <= estimate <= 1.0


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=2048))
def test_any_bytes_give_a_frame_or_value_error(data: bytes) -> None:
    check_decodes_or_value_error(data)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.sampled_from(["png", "jpeg"]),
    st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=8),
    st.integers(0, 10_000),
)
def test_corrupted_real_frames_give_a_frame_or_value_error(
    kind: str, flips: list[tuple[int, int]], cut: int
) -> None:
    data = bytearray(SAMPLES[kind])
    for position, value in flips:
        data[position % len(data)] = value
    check_decodes_or_value_error(bytes(data[: max(cut, 1)]))


SAMPLES = {"png": sample_png(), "jpeg": sample_jpeg()}


def column_rays_hit_disc(
    renderer: CameraRenderer, pose: tuple[float, float, float], centre: tuple[float, float]
) -> bool:
    """Reference in plain math: does any column's ray from the lens meet the robot disc?"""
    x, y, theta = pose
    lens = (x + ROBOT_RADIUS * math.cos(theta), y + ROBOT_RADIUS * math.sin(theta))
    width = SPEC.width
    focal = (width / 2) / math.tan(SPEC.fov / 2)
    for column in range(width):
        angle = theta + math.atan((width / 2 - column - 0.5) / focal)
        dx, dy = math.cos(angle), math.sin(angle)
        mx, my = lens[0] - centre[0], lens[1] - centre[1]
        along = mx * dx + my * dy
        discriminant = along * along - (mx * mx + my * my - ROBOT_RADIUS**2)
        if discriminant >= 0 and -along - math.sqrt(discriminant) > 0:
            return True
    return False


def test_robots_appear_exactly_when_a_column_ray_meets_them() -> None:
    layout = layout_for(10)
    renderer = CameraRenderer(layout, SPEC, ROBOT_RADIUS)
    rng = Stream(23)
    pose = (0.1, -0.2, 0.7)
    clear = renderer.render(*pose)
    seen = 0
    for _ in range(400):
        distance = rng.uniform(2 * ROBOT_RADIUS, 0.6)
        bearing = pose[2] + rng.uniform(-1.2, 1.2)
        centre = (pose[0] + distance * math.cos(bearing), pose[1] + distance * math.sin(bearing))
        frame = renderer.render(*pose, others=[centre])
        expected = column_rays_hit_disc(renderer, pose, centre)
        assert (not np.array_equal(frame, clear)) == expected, centre
        seen += expected
    assert 50 < seen < 350  # both visible and culled robots were exercised
