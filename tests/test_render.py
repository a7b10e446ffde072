"""Renderer: what the camera sees (levels, occlusion by the front plate), exact anti-aliasing
(area and centroid against supersampling), motion blur, seeded noise, encodings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_camera.calibration import CameraModel
from bfr_sim.render import (
    FrameRenderer,
    Lighting,
    Occluder,
    RenderOptions,
    render_frame,
    rig_scene,
)

CAM = CameraModel()
R_B = 16.6e-3
# a 2 mm square "frame" at the axis: keeps the ball's surroundings pure background
TINY = np.array([[-1e-3, -1e-3], [1e-3, -1e-3], [1e-3, 1e-3], [-1e-3, 1e-3]])
FLAT = RenderOptions(lighting=Lighting(ambient=1.0), plate_in_front=False)


@pytest.fixture(scope="module")
def scene():  # noqa: ANN201
    return rig_scene()


def _coverage(img: np.ndarray, opts: RenderOptions) -> np.ndarray:
    return (img.astype(float) - opts.background) / (opts.ball_level - opts.background)


def _supersampled_disc(cam: CameraModel, centre: np.ndarray, r: float, box: tuple,
                       k: int = 16) -> np.ndarray:
    """Ball coverage of each pixel by k x k point samples of the exact silhouette cone."""
    x0, y0, x1, y1 = box
    sub = (np.arange(k) + 0.5) / k - 0.5
    us = (np.arange(x0, x1)[:, None] + sub[None, :]).reshape(-1)
    vs = (np.arange(y0, y1)[:, None] + sub[None, :]).reshape(-1)
    uu, vv = np.meshgrid(us, vs)
    xy = cam.pixel_to_normalized(np.stack([uu, vv], axis=-1))
    m = np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], axis=-1)
    c = cam.camera_from_world(centre)
    inside = (m @ c) ** 2 - (c @ c - r * r) * (m * m).sum(-1) > 0
    return inside.reshape(y1 - y0, k, x1 - x0, k).mean(axis=(1, 3))


def test_frame_shows_background_plate_and_ball(scene) -> None:  # noqa: ANN001
    opts = RenderOptions(plate_z=scene.plate_z)
    img = FrameRenderer(CAM, scene.outline, opts).render(0.3, scene.ball_centre(0.3, 1.2),
                                                         scene.ball_radius)
    assert img.dtype == np.uint8 and img.shape == (480, 640)
    assert img[5, 5] == opts.background  # a corner: background
    assert abs(int(img[240, 320]) - 115 * (0.55 + 0.45 * 0.94)) <= 2  # the plate, lit
    u, v = CAM.project(scene.ball_centre(0.3, 1.2))
    assert img[round(v), round(u)] > 200  # the ball is bright


def test_ball_area_and_centroid_match_supersampled_silhouette() -> None:
    centre = np.array([0.11, 0.09, 0.0])  # off-axis: the silhouette is an ellipse
    img = render_frame(CAM, TINY, 0.0, centre, R_B, FLAT)
    u, v = CAM.project(centre)
    box = (int(u) - 26, int(v) - 26, int(u) + 27, int(v) + 27)
    cov = _coverage(img[box[1]:box[3], box[0]:box[2]], FLAT)
    ref = _supersampled_disc(CAM, centre, R_B, box)
    assert abs(cov.sum() - ref.sum()) / ref.sum() < 1e-3
    yy, xx = np.mgrid[box[1]:box[3], box[0]:box[2]]
    for w in (xx, yy):
        assert abs((cov * w).sum() / cov.sum() - (ref * w).sum() / ref.sum()) < 0.01
    # pixels straddling the edge carry fractional coverage (anti-aliasing)
    assert np.count_nonzero((cov > 0.05) & (cov < 0.95)) > 100


def test_frame_silhouette_has_the_outline_area(scene) -> None:  # noqa: ANN001
    opts = RenderOptions(plate_z=scene.plate_z, background=20.0, frame_level=200.0,
                         lighting=Lighting(ambient=1.0))
    rend = FrameRenderer(CAM, scene.outline, opts)
    img = rend.render(0.7)
    cov = (img.astype(float) - 20.0) / 180.0
    uv = rend._project_outline(0.7)
    x, y = uv[:, 0], uv[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    perimeter = np.sum(np.hypot(np.diff(x, append=x[0]), np.diff(y, append=y[0])))
    # within 0.1 px along the whole edge (OpenCV's own anti-aliasing alone is 0.6 px off)
    assert abs(cov.sum() - area) < 0.1 * perimeter


def test_front_plate_hides_the_inner_part_of_the_ball(scene) -> None:  # noqa: ANN001
    theta, phi = 0.0, 0.0  # the ball on top of the frame's waist
    centre = scene.ball_centre(theta, phi)
    contact = np.array([0.0, scene.curve.rho(np.array([0.0]))[0], 0.0])
    probe = CAM.project(contact - [0.0, 0.002, 0.0])  # 2 mm inside the contour
    pu, pv = round(probe[0]), round(probe[1])
    front = RenderOptions(plate_z=scene.plate_z)
    behind = RenderOptions(plate_z=scene.plate_z, plate_in_front=False)
    a = FrameRenderer(CAM, scene.outline, front).render(theta, centre, scene.ball_radius)
    b = FrameRenderer(CAM, scene.outline, behind).render(theta, centre, scene.ball_radius)
    assert abs(int(a[pv, pu]) - int(a[240, 320])) <= 1  # plate level: the ball is hidden
    assert b[pv, pu] > a[pv, pu] + 30  # the ball (shaded near its limb) is in front there


def test_noise_is_seeded_and_has_the_requested_sigma() -> None:
    opts = RenderOptions(noise_sigma=4.0)
    rend = FrameRenderer(CAM, TINY, opts)
    a = rend.render(0.0, rng=np.random.default_rng(7))
    b = rend.render(0.0, rng=np.random.default_rng(7))
    c = rend.render(0.0, rng=np.random.default_rng(8))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    flat = a[:200, :200].astype(float)  # background only
    assert abs(flat.mean() - opts.background) < 0.1
    assert abs(flat.std() - 4.0) < 0.15
    with pytest.raises(ValueError, match="Generator"):
        rend.render(0.0)  # noise without a generator


def test_motion_blur_spreads_along_the_motion_and_keeps_the_mid_exposure_centre() -> None:
    centre = np.array([0.05, -0.04, 0.0])
    opts = RenderOptions(lighting=Lighting(ambient=1.0), plate_in_front=False,
                         exposure_time=4e-3)
    rend = FrameRenderer(CAM, TINY, opts)
    still = _coverage(rend.render(0.0, centre, R_B), opts)
    moving = _coverage(rend.render(0.0, centre, R_B, ball_velocity=(0.5, 0.0, 0.0)), opts)
    yy, xx = np.mgrid[0:480, 0:640]
    for w in (xx, yy):
        assert abs((still * w).sum() / still.sum() - (moving * w).sum() / moving.sum()) < 0.02
    blur_px = 0.5 * 4e-3 * CAM.pixels_per_metre(centre)  # 2.4 px
    # the support grows by the blur along the motion only ...
    width = [(c > 0.01).any(axis=0).sum() for c in (still, moving)]
    height = [(c > 0.01).any(axis=1).sum() for c in (still, moving)]
    assert abs(width[1] - width[0] - blur_px) <= 1.0
    assert abs(height[1] - height[0]) <= 1
    # ... while the half-level outline stays where the ball is at mid-exposure
    assert abs((moving > 0.5).any(axis=0).sum() - (still > 0.5).any(axis=0).sum()) <= 1
    assert abs(moving.sum() - still.sum()) / still.sum() < 2e-3  # blur keeps the light


def test_occluders_and_encodings(scene) -> None:  # noqa: ANN001
    centre = scene.ball_centre(1.0, 2.0)
    u, v = CAM.project(centre)
    occ = Occluder.disc((u, v), 6.0, level=0.0)
    opts = RenderOptions(plate_z=scene.plate_z)
    rend = FrameRenderer(CAM, scene.outline, opts)
    img = rend.render(1.0, centre, scene.ball_radius, occluders=(occ,))
    assert img[round(v), round(u)] == 0
    plain = rend.render(1.0, centre, scene.ball_radius)
    for enc, dtype in (("mono16", np.uint16), ("32FC1", np.float32)):
        other = FrameRenderer(CAM, scene.outline, RenderOptions(plate_z=scene.plate_z,
                                                                encoding=enc))
        out = other.render(1.0, centre, scene.ball_radius)
        assert out.dtype == dtype
        scale = 257 if enc == "mono16" else 1
        np.testing.assert_array_equal(out, plain.astype(dtype) * scale)


def test_invalid_inputs_are_rejected() -> None:
    rend = FrameRenderer(CAM, TINY)
    with pytest.raises(ValueError, match="ball_radius"):
        rend.render(0.0, (0.1, 0.1, 0.0))
    with pytest.raises(ValueError, match="ball_centre"):
        rend.render(0.0, (0.1, float("nan"), 0.0), R_B)
    with pytest.raises(ValueError, match="outline"):
        FrameRenderer(CAM, np.zeros((5, 3)))
    with pytest.raises(ValueError, match="encoding"):
        RenderOptions(encoding="rgb8")
    with pytest.raises(ValueError, match="noise_sigma"):
        RenderOptions(noise_sigma=-1.0)


def test_rig_scene_ball_kinematics(scene) -> None:  # noqa: ANN001
    theta, phi, td, pd = 0.4, 1.1, 2.0, 2.5
    c = scene.ball_centre(theta, phi)
    # the ball centre is R outside the contour and the rig's phi is near the contact angle
    assert math.isclose(c[2], 0.0)
    h = 1e-6
    fd = (scene.ball_centre(theta + td * h, phi + pd * h)
          - scene.ball_centre(theta - td * h, phi - pd * h)) / (2 * h)
    np.testing.assert_allclose(scene.ball_velocity(theta, phi, td, pd), fd, atol=1e-7)
    assert abs(theta + math.atan2(c[0], c[1]) - phi) < 0.1
