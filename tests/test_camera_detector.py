"""Ball detector: round-trip accuracy on rendered frames (render a known position, detect
it), the not-found and invalid paths, ROI tracking, occlusion, and frames from elsewhere."""

from __future__ import annotations

import math
from collections.abc import Iterator

import cv2
import numpy as np
import pytest
from bfr_camera.calibration import CameraModel
from bfr_camera.detector import (
    BallDetector,
    DetectionStatus,
    DetectorConfig,
    _circle_fit,
    _cone_kernel,
    detector_config_from_dict,
    load_detector_config,
)
from bfr_sim.render import FrameRenderer, Occluder, RenderOptions, rig_scene

CAM = CameraModel()


@pytest.fixture(scope="module")
def scene():  # noqa: ANN201
    return rig_scene()


def _frames(scene, opts: RenderOptions, n: int, seed: int, cam: CameraModel = CAM,  # noqa: ANN001
            moving: bool = False) -> Iterator[tuple[np.ndarray, float, np.ndarray]]:
    """Seeded frames: random theta, the ball on its track at a random phi (plate in front)."""
    rng = np.random.default_rng(seed)
    rend = FrameRenderer(cam, scene.outline, opts)
    for _ in range(n):
        theta, phi = rng.uniform(-math.pi, math.pi, 2)
        td = rng.uniform(1.5, 3.5) * (1 if rng.random() < 0.5 else -1)
        pd = td * rng.uniform(0.7, 1.3)
        centre = scene.ball_centre(theta, phi)
        vel = scene.ball_velocity(theta, phi, td, pd) if moving else None
        img = rend.render(theta, centre, scene.ball_radius, rng=rng,
                          theta_dot=td if moving else 0.0, ball_velocity=vel)
        yield img, theta, centre


def _errors(scene, opts: RenderOptions, n: int, seed: int, cam: CameraModel = CAM,  # noqa: ANN001
            moving: bool = False) -> np.ndarray:
    det = BallDetector(cam, scene.ball_radius)
    out = []
    for img, theta, centre in _frames(scene, opts, n, seed, cam, moving):
        det.reset()
        d = det.detect(img, theta)
        assert d.status == DetectionStatus.FOUND, d.reason
        truth = cam.project(centre)
        out.append(np.hypot(d.u - truth[0], d.v - truth[1]))
        # world position and the rig's phi
        assert np.hypot(d.x - centre[0], d.y - centre[1]) < 2e-3 * d.radius_px / 20 + 5e-4
        assert abs(d.phi - (theta + math.atan2(centre[0], centre[1]))) < 5e-3
        assert 0.0 < d.confidence <= 1.0
    return np.array(out)


def test_round_trip_clean_frames_meet_the_accuracy_targets(scene) -> None:  # noqa: ANN001
    err = _errors(scene, RenderOptions(plate_z=scene.plate_z, exposure_time=0.0), 40, 1)
    assert np.median(err) < 0.1
    assert err.max() < 0.5


def test_round_trip_with_noise_and_blur(scene) -> None:  # noqa: ANN001
    opts = RenderOptions(plate_z=scene.plate_z, noise_sigma=3.0, shot_noise=0.05,
                         defocus_sigma=0.7, exposure_time=4e-3)
    err = _errors(scene, opts, 30, 2, moving=True)
    assert np.median(err) < 0.5
    assert err.max() < 1.0


def test_round_trip_with_lens_distortion_and_a_tilted_camera(scene) -> None:  # noqa: ANN001
    from bfr_camera.calibration import look_at  # noqa: PLC0415

    eye = (0.04, -0.03, 0.5)
    cam = CameraModel(d=(-0.08, 0.02, 0.001, -0.0007, 0.0), position=eye,
                      orientation=look_at(eye, (0.0, 0.0, 0.0)))
    err = _errors(scene, RenderOptions(plate_z=scene.plate_z, exposure_time=0.0), 15, 3, cam)
    assert np.median(err) < 0.1
    assert err.max() < 0.5


def test_round_trip_through_a_fisheye_lens(scene) -> None:  # noqa: ANN001
    """A wide-angle camera close to the frame with a fisheye lens (ROS ``equidistant``): the
    renderer draws through cv2.fisheye, the detector undistorts through it, and the ball's
    position comes back as accurately as through a pinhole."""
    from bfr_camera.calibration import look_at  # noqa: PLC0415

    eye = (0.03, -0.02, 0.3)
    cam = CameraModel(distortion_model="equidistant", d=(-0.02, 0.004, -0.001, 0.0002),
                      k=(330.0, 0.0, 321.0, 0.0, 331.0, 238.0, 0.0, 0.0, 1.0), position=eye,
                      orientation=look_at(eye, (0.0, 0.0, 0.0)))
    err = _errors(scene, RenderOptions(plate_z=scene.plate_z, exposure_time=0.0), 15, 5, cam)
    assert np.median(err) < 0.1
    assert err.max() < 0.5


def test_world_position_and_phi_convention() -> None:
    # a flat disc straight above the axis at theta = 0.3: phi = theta + atan2(x, y) = 0.3
    r_b = 16.6e-3
    det = BallDetector(CAM, r_b)
    for xw, yw, phi_w in ((0.0, 0.12, 0.0), (0.12, 0.0, math.pi / 2),
                          (-0.1, -0.1, -0.75 * math.pi)):
        img = np.full((480, 640), 20, np.uint8)
        u, v = CAM.project(np.array([xw, yw, 0.0]))
        r_px = r_b * CAM.pixels_per_metre(np.array([xw, yw, 0.0]))
        cv2.circle(img, (round(u * 16), round(v * 16)), round((r_px - 0.6) * 16), 230, -1,
                   cv2.LINE_AA, 4)
        d = det.detect(img, 0.3, use_roi=False)
        assert d.valid, d.reason
        assert abs(d.x - xw) < 2e-4 and abs(d.y - yw) < 2e-4
        assert abs(math.remainder(d.phi - (0.3 + phi_w), 2 * math.pi)) < 3e-3


def test_no_ball_in_ball_free_frames(scene) -> None:  # noqa: ANN001
    det = BallDetector(CAM, scene.ball_radius)
    rng = np.random.default_rng(4)
    for opts in (RenderOptions(plate_z=scene.plate_z),
                 RenderOptions(plate_z=scene.plate_z, noise_sigma=4.0, defocus_sigma=0.8),
                 RenderOptions(plate_z=scene.plate_z, background=60.0, frame_level=90.0)):
        rend = FrameRenderer(CAM, scene.outline, opts)
        for _ in range(6):
            theta = rng.uniform(-math.pi, math.pi)
            img = rend.render(theta, None, rng=rng, theta_dot=2.0)
            d = det.detect(img, theta, use_roi=False)
            assert d.status == DetectionStatus.NOT_FOUND, d
            assert d.reason and not d.valid and math.isnan(d.u)
            # a stale fix somewhere on the frame's edge does not conjure a ball either
            edge = CAM.project(np.array([*scene.outline[int(rng.integers(0, 720))], 0.0]))
            d = det.detect(img, theta, hint=(float(edge[0]), float(edge[1])))
            assert d.status == DetectionStatus.NOT_FOUND, d
            assert det.last_fix is None


def test_blank_and_garbage_images_are_not_found() -> None:
    det = BallDetector(CAM, 16.6e-3)
    rng = np.random.default_rng(5)
    images = [np.zeros((480, 640), np.uint8), np.full((480, 640), 255, np.uint8),
              rng.integers(0, 256, (480, 640), dtype=np.uint8),
              cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 3)]
    for img in images:
        d = det.detect(img, 0.0)
        assert d.status == DetectionStatus.NOT_FOUND, d
        assert d.reason


@pytest.mark.parametrize(("image", "reason"), [
    (np.zeros((240, 320), np.uint8), "320x240"),
    (np.zeros(640 * 480, np.uint8), "(H, W)"),
    (np.zeros((0, 640), np.uint8), "empty"),
    (np.zeros((480, 640), np.complex64), "pixel type"),
    (np.full((480, 640), np.nan, np.float32), "NaN"),
    (np.zeros((480, 640, 2), np.uint8), "(H, W)"),
    ("not an image", "pixel type"),
    (None, "pixel type"),
])
def test_invalid_input_is_reported_not_raised(image: object, reason: str) -> None:
    d = BallDetector(CAM, 16.6e-3).detect(image, 0.0)  # type: ignore[arg-type]
    assert d.status == DetectionStatus.INVALID_INPUT
    assert reason in d.reason


def test_other_pixel_formats_give_the_same_fix(scene) -> None:  # noqa: ANN001
    img, theta, _ = next(_frames(scene, RenderOptions(plate_z=scene.plate_z), 1, 6))
    det = BallDetector(CAM, scene.ball_radius)
    ref = det.detect(img, theta, use_roi=False)
    assert ref.valid
    variants = [img.astype(np.uint16) * 257, img.astype(np.float32),
                img.astype(np.float64) / 255.0, cv2.cvtColor(img, cv2.COLOR_GRAY2BGR),
                img[:, :, None], img.astype(np.int32)]
    for other in variants:
        d = det.detect(other, theta, use_roi=False)
        assert d.valid, (other.dtype, other.shape, d.reason)
        assert abs(d.u - ref.u) < 0.02 and abs(d.v - ref.v) < 0.02
    with pytest.raises(ValueError):
        BallDetector(CAM, -1.0)


def test_roi_tracking_follows_the_ball_and_recovers_when_lost(scene) -> None:  # noqa: ANN001
    det = BallDetector(CAM, scene.ball_radius)
    rend = FrameRenderer(CAM, scene.outline, RenderOptions(plate_z=scene.plate_z))
    theta, phi = 0.2, 0.5
    first = det.detect(rend.render(theta, scene.ball_centre(theta, phi), scene.ball_radius),
                       theta)
    assert first.valid and first.search == "full"
    for _ in range(5):  # rolling: 5 ms per frame
        theta += 2.5 * 0.005
        phi += 2.5 * 0.005
        centre = scene.ball_centre(theta, phi)
        d = det.detect(rend.render(theta, centre, scene.ball_radius), theta)
        truth = CAM.project(centre)
        assert d.valid and d.search == "roi"
        x0, y0, x1, y1 = d.roi
        assert x0 <= truth[0] < x1 and y0 <= truth[1] < y1 and (x1 - x0) < 200
        assert math.hypot(d.u - truth[0], d.v - truth[1]) < 0.2
    # the ball is gone: not found, and the next search is a full one
    assert det.detect(rend.render(theta), theta).status == DetectionStatus.NOT_FOUND
    assert det.last_fix is None
    theta, phi = theta + 2.0, phi + 2.0  # it comes back elsewhere
    d = det.detect(rend.render(theta, scene.ball_centre(theta, phi), scene.ball_radius), theta)
    assert d.valid and d.search == "full"


def test_two_balls_are_ambiguous_unless_tracking_tells_which(scene) -> None:  # noqa: ANN001
    theta, phi = -0.4, 2.3
    centre = scene.ball_centre(theta, phi)
    rend = FrameRenderer(CAM, scene.outline, RenderOptions(plate_z=scene.plate_z))
    # a second ball on the track, elsewhere (a reflection, a spare ball)
    img = np.maximum(rend.render(theta, centre, scene.ball_radius),
                     rend.render(theta, scene.ball_centre(theta, phi + 2.0), scene.ball_radius))
    det = BallDetector(CAM, scene.ball_radius)
    d = det.detect(img, theta)
    assert d.status == DetectionStatus.AMBIGUOUS, d
    assert len(d.candidates) == 2 and not d.valid and math.isnan(d.u)
    assert det.last_fix is None
    truth = CAM.project(centre)
    d = det.detect(img, theta, hint=(truth[0] + 3.0, truth[1] - 2.0))
    assert d.valid and d.search == "roi"
    assert math.hypot(d.u - truth[0], d.v - truth[1]) < 0.2
    # a flat disc of the ball's size far off-axis is not a sphere's image (an ellipse there)
    where = np.array([-0.15, -0.15, 0.0])
    r_px = scene.ball_radius * CAM.pixels_per_metre(where)
    disc = Occluder.disc(CAM.project(where), r_px - 0.6, level=225.0, n=96)
    img = rend.render(theta, centre, scene.ball_radius, occluders=(disc,))
    d = det.detect(img, theta, use_roi=False)
    assert d.valid and math.hypot(d.u - truth[0], d.v - truth[1]) < 0.2


def test_partly_hidden_ball(scene) -> None:  # noqa: ANN001
    theta, phi = 0.9, 1.6
    centre = scene.ball_centre(theta, phi)
    truth = CAM.project(centre)
    r_px = scene.ball_radius * CAM.pixels_per_metre(centre)
    out = truth - CAM.project(np.zeros(3))
    out /= np.linalg.norm(out)
    side = np.array([-out[1], out[0]])
    det = BallDetector(CAM, scene.ball_radius)
    for level in (20.0, 70.0, 140.0):  # as dark as the background, grey, as bright as plate
        # a bar across the outer side of the ball, hiding about a quarter of its outline
        c = truth + out * 0.95 * r_px
        bar = [c + a * 0.2 * r_px * out + b * 2 * r_px * side for a, b in
               ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        img = FrameRenderer(CAM, scene.outline, RenderOptions(
            plate_z=scene.plate_z, noise_sigma=2.0)).render(
            theta, centre, scene.ball_radius, rng=np.random.default_rng(9),
            occluders=(Occluder(tuple(map(tuple, bar)), level),))
        det.reset()
        d = det.detect(img, theta)
        assert d.valid, (level, d.reason)
        assert math.hypot(d.u - truth[0], d.v - truth[1]) < 0.3, level


def test_frames_from_another_source(scene) -> None:  # noqa: ANN001
    """Not rendered by bfr: OpenCV drawing, gradient light, JPEG artefacts, blur, noise."""
    rng = np.random.default_rng(10)
    det = BallDetector(CAM, scene.ball_radius)
    for k in range(6):
        yy, xx = np.mgrid[0:480, 0:640]
        img = (40 + 50 * xx / 640 + 20 * yy / 480).astype(np.float32)  # uneven light
        frame = CAM.project(np.c_[scene.outline * 1.02, np.zeros(720)])
        cv2.fillPoly(img, [np.round(frame).astype(np.int32)], 120.0)
        xw, yw = rng.uniform(-0.1, 0.1, 2)
        u, v = CAM.project(np.array([xw, yw, 0.0]))
        r_px = scene.ball_radius * CAM.pixels_per_metre(np.array([xw, yw, 0.0]))
        ball = np.zeros((480, 640), np.uint8)
        cv2.circle(ball, (round(u * 16), round(v * 16)), round((r_px - 0.6) * 16), 255, -1,
                   cv2.LINE_AA, 4)
        level = 150.0 + 20 * k  # contrast from weak to strong
        img = img + (level - img) * (ball / 255.0)
        img = cv2.GaussianBlur(img, (0, 0), 1.2) + rng.normal(0, 2.5, img.shape)
        img = np.clip(img, 0, 255).astype(np.uint8)
        _, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 75])
        img = cv2.imdecode(jpg, cv2.IMREAD_GRAYSCALE)
        d = det.detect(img, 0.0, use_roi=False)
        assert d.valid, (k, d.reason)
        assert math.hypot(d.u - u, d.v - v) < 0.3, k
    # a dark ball on a bright background, with polarity "dark"
    img = np.full((480, 640), 200, np.uint8)
    cv2.circle(img, (320 * 16, 200 * 16), round((r_px - 0.6) * 16), 40, -1, cv2.LINE_AA, 4)
    dark = BallDetector(CAM, scene.ball_radius, DetectorConfig(polarity="dark"))
    d = dark.detect(img, 0.0)
    assert d.valid and math.hypot(d.u - 320, d.v - 200) < 0.2
    assert not det.detect(img, 0.0).valid  # "bright" finds no ball there


def test_detector_parameters() -> None:
    assert load_detector_config() == DetectorConfig()  # camera.yaml holds the defaults
    with pytest.raises(ValueError, match="unknown"):
        detector_config_from_dict({"n_ray": 64})
    with pytest.raises(ValueError, match="polarity"):
        DetectorConfig(polarity="grey")
    with pytest.raises(ValueError, match="n_rays"):
        DetectorConfig(n_rays=4)


def test_perspective_the_ball_image_is_an_ellipse_not_centred_on_the_ball() -> None:
    # off-axis, the sphere's outline is an ellipse whose centre is not the image of the ball
    # centre; the cone fit reports the latter, a 2-D circle or blob centroid would not
    tiny = np.array([[-1e-3, -1e-3], [1e-3, -1e-3], [1e-3, 1e-3], [-1e-3, 1e-3]])
    from bfr_sim.render import Lighting  # noqa: PLC0415

    opts = RenderOptions(lighting=Lighting(ambient=1.0), plate_in_front=False)
    rend = FrameRenderer(CAM, tiny, opts)
    det = BallDetector(CAM, 16.6e-3)
    for where in ((0.16, 0.0, 0.0), (-0.11, 0.11, 0.0)):
        centre = np.array(where)
        img = rend.render(0.0, centre, 16.6e-3)
        truth = CAM.project(centre)
        cov = (img.astype(float) - opts.background) / (opts.ball_level - opts.background)
        yy, xx = np.mgrid[0:480, 0:640]
        blob = np.array([(cov * xx).sum(), (cov * yy).sum()]) / cov.sum()
        assert np.hypot(*(blob - truth)) > 0.15  # the effect is real here ...
        d = det.detect(img, 0.0, use_roi=False)
        assert d.valid
        assert math.hypot(d.u - truth[0], d.v - truth[1]) < 0.05  # ... and accounted for
        assert abs(d.radius_m - 16.6e-3) < 1e-4


# -- the compiled kernels against array forms written apart from them -------------------------
def _cone_irls_reference(v: np.ndarray, wts: np.ndarray, iters: int, focal: float,
                         rz: tuple[float, float, float], cz: float, zb: float, rb: float,
                         prior_sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The cone fit's rounds in numpy (the detector's module docstring, step 4)."""
    v3 = v[:, :3]
    w = np.zeros(3)
    res = np.zeros(len(v))
    prior = None
    scale = sig = 1.0
    for it in range(iters):
        a = (v3 * wts[:, None]).T @ v3
        b = (v3 * wts[:, None]).sum(axis=0)
        if prior is not None:
            h, wexp, rho = prior
            a = a + rho * np.outer(h, h)
            b = b + rho * wexp * h
        w = np.linalg.solve(a, b)
        nw2 = float(w @ w)
        if nw2 <= 1.0:
            return None
        res = (v3 @ w - 1.0) * focal / math.sqrt(nw2 - 1.0)
        if it < 2:
            sig = max(1.4826 * float(np.sort(np.abs(res[wts > 0]))[(np.sum(wts > 0) - 1) // 2]),
                      0.08)
            scale = 4.685 * sig
        wts = np.maximum(1.0 - (res / scale) ** 2, 0.0) ** 2
        if it == iters - 1:
            break
        h = w / math.sqrt(nw2)
        lam = (zb - cz) / float(np.dot(rz, h))
        if lam > rb:
            sb = rb / lam
            prior = (h, 1.0 / math.sqrt(1.0 - sb * sb),
                     (sig / max(prior_sigma * focal * sb, 1e-3)) ** 2)
    return w, res, wts


def test_compiled_cone_and_circle_kernels_match_array_forms() -> None:
    rng = np.random.default_rng(7)
    for trial in range(40):
        # rays on a cone about a random axis, with noise and a few outliers
        axis = np.array([rng.normal(0, 0.2), rng.normal(0, 0.2), 1.0])
        axis /= np.linalg.norm(axis)
        beta = rng.uniform(0.01, 0.05)
        e1 = np.cross(axis, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        n = int(rng.integers(12, 64))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        rays = (math.cos(beta) * axis[None, :]
                + math.sin(beta) * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2))
        rays += rng.normal(0, 2e-5, rays.shape)
        rays[: n // 8] += rng.normal(0, 2e-3, (n // 8, 3))  # outliers
        rays /= np.linalg.norm(rays, axis=1)[:, None]
        v = np.hstack([rays, np.ones((n, 1))])
        w0 = rng.uniform(0.2, 1.0, n)
        args = (600.0, (0.0, 0.0, -1.0), 1.2, 0.0, 0.0166, 0.05)
        ref = _cone_irls_reference(v, w0.copy(), 3, *args)
        ok, w, res, wts = _cone_kernel(v, w0.copy(), 3, args[0], *args[1], *args[2:])
        assert ok == (ref is not None), trial
        if ref is not None:
            np.testing.assert_allclose(w, ref[0], rtol=1e-7)  # narrow cone: cond ~1e7
            # residuals [px] are v.w - 1 (a cancellation) times f / tan(beta) ~ 2e4: Cramer's
            # rule against LAPACK's solve differ there by ~1e-8 px
            np.testing.assert_allclose(res, ref[1], atol=1e-6)
            np.testing.assert_allclose(wts, ref[2], atol=1e-6)
        # circle: points on a circle plus foreign points on a line
        cx, cy, r = rng.uniform(20, 60), rng.uniform(20, 60), rng.uniform(8, 20)
        a = rng.uniform(0, 2 * np.pi, 40)
        pts = np.c_[cx + r * np.cos(a), cy + r * np.sin(a)] + rng.normal(0, 0.05, (40, 2))
        pts = np.vstack([pts, np.c_[np.linspace(0, 80, 12), np.full(12, cy + 0.5 * r)]])
        triples = np.sort(rng.random((48, len(pts))).argsort(axis=1)[:, :3], axis=1)
        got = _circle_fit(pts, 0.8 * r, 1.2 * r, triples)
        assert got is not None
        # the algebraic fit on its 1 px inliers, in numpy
        inl = np.abs(np.hypot(pts[:, 0] - got[0], pts[:, 1] - got[1]) - got[2]) <= 1.0
        p = pts[inl] - pts.mean(axis=0)
        a_mat = np.c_[p, np.ones(len(p))]
        d, e, f = np.linalg.lstsq(a_mat, -(p ** 2).sum(axis=1), rcond=None)[0]
        ref_c = (-d / 2 + pts[:, 0].mean(), -e / 2 + pts[:, 1].mean(),
                 math.sqrt(d * d / 4 + e * e / 4 - f))
        np.testing.assert_allclose(got, ref_c, rtol=1e-9, atol=1e-9)
        assert abs(got[0] - cx) < 0.1 and abs(got[1] - cy) < 0.1 and abs(got[2] - r) < 0.1


def test_track_gate_table_is_numpy_periodic_interp() -> None:
    det = BallDetector(CAM, 0.0166)
    rng = np.random.default_rng(3)
    a = np.sort(rng.uniform(-1.0, 2 * np.pi - 1.0, 200))
    r = rng.uniform(0.1, 0.2, 200)
    det.set_track(a, r)
    ta, tr = det._track
    for psi in rng.uniform(-30, 30, 2000):
        assert np.interp(psi % (2 * np.pi), ta, tr) == pytest.approx(
            np.interp(psi, a, r, period=2 * np.pi), abs=1e-15)


def test_warm_up_runs_the_detector_and_forgets_its_disc(scene) -> None:  # noqa: ANN001
    det = BallDetector(CAM, scene.ball_radius)
    assert det.warm_up() > 0.0
    assert det.last_fix is None  # the synthetic disc is not a fix of the run
    img, theta, centre = next(_frames(scene, RenderOptions(), 1, seed=5))
    d = det.detect(img, theta)
    assert d.status == DetectionStatus.FOUND and d.search == "full"
    truth = CAM.project(centre)
    assert math.hypot(d.u - truth[0], d.v - truth[1]) < 0.2
