"""Camera model: pinhole projection against hand computation, pixel <-> world round trips,
CameraInfo and calibration-file loading, validation."""

from __future__ import annotations

import math
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from bfr_camera.calibration import (
    CameraModel,
    CameraModelError,
    camera_to_ros_yaml,
    load_camera,
    load_ros_calibration_yaml,
    look_at,
    matrix_to_quaternion,
    quaternion_to_matrix,
)

DISTORTED = dict(d=(-0.08, 0.02, 0.001, -0.0007, 0.0))


def test_shipped_camera_views_the_frame_from_the_front() -> None:
    cam = load_camera()
    assert (cam.width, cam.height) == (640, 480)
    assert (cam.cx, cam.cy) == (319.5, 239.5)  # principal point at the image centre
    assert cam.frame_id == "camera_optical_frame"
    # the frame's axis is seen at the principal point, 0.5 m away along the optical axis
    np.testing.assert_allclose(cam.project(np.zeros(3)), [319.5, 239.5], atol=1e-12)
    np.testing.assert_allclose(cam.camera_from_world(np.zeros(3)), [0.0, 0.0, 0.5])
    # the whole frame with the ball (0.18 m from the axis) fits into the image
    a = np.linspace(0.0, 2.0 * np.pi, 64)
    ring = np.stack([0.18 * np.cos(a), 0.18 * np.sin(a), np.zeros_like(a)], axis=1)
    uv = cam.project(ring)
    assert uv[:, 0].min() > 0 and uv[:, 0].max() < 639
    assert uv[:, 1].min() > 0 and uv[:, 1].max() < 479


def test_projection_matches_hand_computed_pinhole() -> None:
    cam = CameraModel()  # fx = fy = 600 px, c = (319.5, 239.5), 0.5 m in front, looking at -z
    # X_c = (x, -y, 0.5 - z): image x right = world x, image y down = world -y
    pts = np.array([[0.1, 0.05, 0.0], [-0.05, -0.1, 0.02], [0.0, 0.0, 0.25]])
    expected = np.array([
        [319.5 + 600 * 0.1 / 0.5, 239.5 - 600 * 0.05 / 0.5],  # (439.5, 179.5)
        [319.5 - 600 * 0.05 / 0.48, 239.5 + 600 * 0.1 / 0.48],  # (257.0, 364.5)
        [319.5, 239.5],
    ])
    np.testing.assert_allclose(cam.project(pts), expected, atol=1e-9)
    # behind the camera: no projection
    assert np.all(np.isnan(cam.project(np.array([0.0, 0.0, 0.7]))))


def test_tilted_distorted_camera_matches_opencv_and_hand_computed() -> None:
    eye = (0.12, -0.08, 0.45)
    cam = CameraModel(position=eye, orientation=look_at(eye, (0.01, 0.02, 0.0)),
                      k=(610.0, 0.0, 322.0, 0.0, 605.0, 236.0, 0.0, 0.0, 1.0))
    # the target is on the optical axis
    np.testing.assert_allclose(cam.project(np.array([0.01, 0.02, 0.0])), [322.0, 236.0],
                               atol=1e-9)
    pts = np.random.default_rng(0).uniform(-0.15, 0.15, (20, 3)) * [1, 1, 0.1]
    # hand: X_c = R_cw (X - c), u = fx x / z + cx, v = fy y / z + cy
    xc = (cam.R_cw @ (pts - np.array(eye)).T).T
    hand = np.stack([610 * xc[:, 0] / xc[:, 2] + 322, 605 * xc[:, 1] / xc[:, 2] + 236], 1)
    np.testing.assert_allclose(cam.project(pts), hand, atol=1e-9)
    # with distortion, the same as OpenCV's projectPoints
    dist = cam.replace(**DISTORTED)
    ref, _ = cv2.projectPoints(pts, dist.rvec, dist.tvec, dist.K, dist.D)
    np.testing.assert_allclose(dist.project(pts), ref.reshape(-1, 2), atol=1e-9)
    assert np.abs(dist.project(pts) - cam.project(pts)).max() > 1.0  # distortion matters


def test_pixel_to_world_plane_round_trip_with_distortion() -> None:
    cam = CameraModel(**DISTORTED)
    u, v = np.meshgrid(np.linspace(0, 639, 17), np.linspace(0, 479, 13))
    px = np.stack([u, v], axis=-1)
    world = cam.pixel_to_plane(px, z=0.0)
    np.testing.assert_allclose(world[..., 2], 0.0, atol=1e-15)
    np.testing.assert_allclose(cam.project(world), px, atol=1e-6)
    # and world -> pixel -> world, on another plane
    pts = np.random.default_rng(1).uniform(-0.17, 0.17, (50, 3))
    pts[:, 2] = 0.0127
    back = cam.pixel_to_plane(cam.project(pts), z=0.0127)
    np.testing.assert_allclose(back, pts, atol=1e-9)


FISHEYE = dict(distortion_model="equidistant", d=(-0.02, 0.004, -0.001, 0.0002),
               k=(300.0, 0.0, 321.0, 0.0, 302.0, 238.0, 0.0, 0.0, 1.0))


def test_fisheye_camera_matches_the_equidistant_closed_form_and_round_trips() -> None:
    """ROS's ``equidistant`` (OpenCV's cv2.fisheye): theta = atan r, theta_d = theta (1 + k1
    theta^2 + ... + k4 theta^8), pixel = K (theta_d / r) (x, y), written out here by hand; and
    pixel -> plane -> pixel round trips over the whole image, wide angles included."""
    eye = (0.05, -0.04, 0.25)  # close: the frame fills a wide angle
    cam = CameraModel(position=eye, orientation=look_at(eye, (0.0, 0.0, 0.0)), **FISHEYE)
    assert cam.has_distortion and cam.fisheye
    pts = np.random.default_rng(2).uniform(-0.18, 0.18, (30, 3)) * [1, 1, 0.05]
    xc = (cam.R_cw @ (pts - np.array(eye)).T).T
    x, y = xc[:, 0] / xc[:, 2], xc[:, 1] / xc[:, 2]
    r = np.hypot(x, y)
    th = np.arctan(r)
    k1, k2, k3, k4 = FISHEYE["d"]
    thd = th * (1 + k1 * th**2 + k2 * th**4 + k3 * th**6 + k4 * th**8)
    hand = np.stack([300.0 * thd / r * x + 321.0, 302.0 * thd / r * y + 238.0], axis=1)
    assert th.max() > 0.6  # rays 35 deg and more off the axis
    np.testing.assert_allclose(cam.project(pts), hand, atol=1e-9)
    u, v = np.meshgrid(np.linspace(0, 639, 17), np.linspace(0, 479, 13))
    px = np.stack([u, v], axis=-1)
    world = cam.pixel_to_plane(px, z=0.0)
    ok = np.isfinite(world[..., 0])
    assert ok.mean() > 0.9
    np.testing.assert_allclose(cam.project(world[ok]), px[ok], atol=1e-6)
    # all coefficients zero is still a fisheye (r_d = theta), not the pinhole (r_d = tan theta)
    plain = cam.replace(d=(0.0, 0.0, 0.0, 0.0))
    assert plain.has_distortion
    pin = CameraModel(position=eye, orientation=cam.orientation, k=FISHEYE["k"])
    assert np.abs(plain.project(pts) - pin.project(pts)).max() > 10.0
    # from and back to a CameraInfo as a ROS driver publishes it
    back = CameraModel.from_camera_info(cam.to_camera_info(), position=eye,
                                        orientation=cam.orientation)
    assert back.distortion_model == "equidistant" and back.d == cam.d
    np.testing.assert_allclose(back.project(pts), hand, atol=1e-9)


def test_fisheye_camera_with_skew_and_beyond_its_field() -> None:
    """A fisheye calibration with skew (the calibrator fits it unless told not to): the
    closed form with ``u = fx x_d + s y_d + cx`` and the round trip; a pixel whose ray the
    lens model cannot invert is NaN, never OpenCV's -1e6 placeholder; three coefficients are
    refused."""
    cam = CameraModel(**{**FISHEYE, "k": (300.0, 0.8, 321.0, 0.0, 302.0, 238.0, 0, 0, 1)})
    rng = np.random.default_rng(3)
    xy = rng.uniform(-0.8, 0.8, (40, 2))
    r = np.hypot(xy[:, 0], xy[:, 1])
    th = np.arctan(r)
    k1, k2, k3, k4 = FISHEYE["d"]
    s = th * (1 + k1 * th**2 + k2 * th**4 + k3 * th**6 + k4 * th**8) / r
    xd, yd = s * xy[:, 0], s * xy[:, 1]
    hand = np.stack([300.0 * xd + 0.8 * yd + 321.0, 302.0 * yd + 238.0], axis=1)
    np.testing.assert_allclose(cam.distort_normalized(xy), hand, atol=1e-9)
    np.testing.assert_allclose(cam.pixel_to_normalized(hand), xy, atol=1e-7)
    # a lens whose theta_d turns back (k1 < 0, large): beyond its turning point no ray
    bent = cam.replace(d=(-0.6, 0.0, 0.0, 0.0))
    far = bent.pixel_to_normalized(np.array([[321.0 + 300.0 * 2.0, 238.0]]))
    assert np.all(np.isnan(far)) or np.all(np.abs(far) < 1e5), far
    with pytest.raises(CameraModelError, match="equidistant takes \\(4,\\) coefficients"):
        CameraModel(**{**FISHEYE, "d": (0.1, 0.0, 0.0)})


def test_pixel_to_plane_without_intersection_is_nan() -> None:
    cam = CameraModel()
    assert np.all(np.isnan(cam.pixel_to_plane(np.array([100.0, 100.0]), z=1.0)))  # behind
    # a camera looking far up the plane: its top rows see above the horizon
    grazing = CameraModel(orientation=look_at((0.0, 0.0, 0.5), (0.0, 3.0, 0.0)))
    assert np.all(np.isfinite(grazing.pixel_to_plane(np.array([319.5, 479.0]))))
    assert np.all(np.isnan(grazing.pixel_to_plane(np.array([319.5, 0.0]))))


def test_camera_info_round_trip_and_message_objects() -> None:
    cam = CameraModel(**DISTORTED)
    info = cam.to_camera_info()
    assert set(info) >= {"width", "height", "k", "d", "r", "p", "distortion_model"}
    assert info["p"] == [600.0, 0.0, 319.5, 0.0, 0.0, 600.0, 239.5, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert info["r"] == [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]
    back = CameraModel.from_camera_info(info, position=cam.position,
                                        orientation=cam.orientation)
    assert back == cam
    # a sensor_msgs/CameraInfo-like object (attributes, arrays, a header)
    msg = SimpleNamespace(width=1280, height=960, distortion_model="plumb_bob",
                          k=np.array([1200.0, 0, 639.5, 0, 1200.0, 479.5, 0, 0, 1]),
                          d=np.array([0.01, -0.02, 0.0, 0.0, 0.0]), binning_x=0, binning_y=0,
                          header=SimpleNamespace(frame_id="rig_camera"))
    real = CameraModel.from_camera_info(msg, position=(0.0, 0.0, 1.0))
    assert (real.width, real.fx, real.frame_id) == (1280, 1200.0, "rig_camera")
    np.testing.assert_allclose(real.project(np.zeros(3)), [639.5, 479.5])


def test_a_binning_or_cropping_camera_is_modelled_as_its_images() -> None:
    """REP 104: binning and roi keep the full sensor's calibration in k and d; the model is
    that of the images (image_geometry's rule). A world point lands where the full-sensor
    model puts it, less the roi's offset, divided by the binning; the size is the roi's
    divided by the binning. A roi outside the sensor is refused (it had been: binning > 1 was
    refused outright, and a probe's 2x2-binned driver got no fix)."""
    full = CameraModel(**{**DISTORTED, "width": 1280, "height": 960,
                          "k": (1200.0, 0.5, 639.5, 0.0, 1190.0, 479.5, 0.0, 0.0, 1.0)})
    info = full.to_camera_info()
    pose = {"position": full.position, "orientation": full.orientation}
    points = np.array([[0.0, 0.0, 0.0], [0.05, -0.03, 0.0], [-0.08, 0.06, 0.01]])
    for bx, by, roi, size in ((2, 2, None, (640, 480)), (0, 0, (100, 60, 800, 600), (800, 600)),
                              (2, 1, (200, 100, 640, 480), (320, 480))):
        msg = {**info, "binning_x": bx, "binning_y": by}
        if roi is not None:
            msg["roi"] = SimpleNamespace(x_offset=roi[0], y_offset=roi[1], width=roi[2],
                                         height=roi[3], do_rectify=False)
        cam = CameraModel.from_camera_info(msg, **pose)
        x0, y0 = (roi[0], roi[1]) if roi is not None else (0, 0)
        expect = (full.project(points) - [x0, y0]) / [max(bx, 1), max(by, 1)]
        np.testing.assert_allclose(cam.project(points), expect, atol=1e-9)
        assert (cam.width, cam.height) == size
        np.testing.assert_allclose(cam.pixel_to_plane(cam.project(points), z=0.0)[0],
                                   points[0], atol=1e-9)
    outside = {**info, "roi": SimpleNamespace(x_offset=700, y_offset=0, width=640, height=480)}
    with pytest.raises(CameraModelError, match=r"roi .* not within the calibrated 1280x960"):
        CameraModel.from_camera_info(outside, **pose)


def test_ros_calibration_file_drops_in(tmp_path) -> None:  # noqa: ANN001
    f = tmp_path / "ost.yaml"
    f.write_text(
        "image_width: 752\nimage_height: 480\ncamera_name: rig\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n"
        "  data: [700.5, 0.0, 370.1, 0.0, 699.8, 241.3, 0.0, 0.0, 1.0]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n"
        "  data: [-0.31, 0.12, 0.0004, -0.0002, 0.0]\n"
        "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
        "projection_matrix:\n  rows: 3\n  cols: 4\n"
        "  data: [650, 0, 370, 0, 0, 650, 241, 0, 0, 0, 1, 0]\n")
    cam = load_ros_calibration_yaml(f, position=(0.0, 0.0, 0.6), exposure_time=1e-3)
    assert (cam.width, cam.height) == (752, 480)
    assert cam.k[0] == 700.5 and cam.d[0] == -0.31 and cam.exposure_time == 1e-3
    with pytest.raises(CameraModelError, match="not a camera calibration"):
        (tmp_path / "bad.yaml").write_text("foo: 1\n")
        load_ros_calibration_yaml(tmp_path / "bad.yaml")


def test_parameter_file_round_trip(tmp_path) -> None:  # noqa: ANN001
    cam = CameraModel(**DISTORTED, position=(0.01, -0.02, 0.55), exposure_time=1e-3)
    f = tmp_path / "camera.yaml"
    f.write_text(camera_to_ros_yaml(cam))
    assert load_camera(f) == cam


@pytest.mark.parametrize(("change", "message"), [
    ({"k": (0.0, 0, 319.5, 0, 600.0, 239.5, 0, 0, 1)}, "fx, fy > 0"),
    ({"k": (600.0, 0, 319.5)}, "expected 9 numbers"),
    ({"d": (0.1, 0.2, 0.3)}, "takes"),
    ({"distortion_model": "kannala_brandt"}, "not supported"),
    ({"orientation": (1.0, 1.0, 0.0, 0.0)}, "unit norm"),
    ({"width": -640}, "positive integer"),
    ({"exposure_time": 0.01}, "exposure_time"),
    ({"position": (0.0, 0.0, -0.5)}, "behind the camera"),
    ({"position": (0.0, float("nan"), 0.5)}, "finite"),
])
def test_invalid_cameras_are_rejected(change: dict, message: str) -> None:
    with pytest.raises(CameraModelError, match=message):
        CameraModel(**change)


def test_unknown_parameter_entries_are_rejected(tmp_path) -> None:  # noqa: ANN001
    f = tmp_path / "camera.yaml"
    f.write_text("/**:\n  ros__parameters:\n    camera:\n      widht: 640\n")
    with pytest.raises(CameraModelError, match="unknown entries"):
        load_camera(f)


def test_rotation_helpers() -> None:
    q = look_at((0.0, 0.0, 0.5))
    np.testing.assert_allclose(q, (1.0, 0.0, 0.0, 0.0), atol=1e-12)  # the default pose
    rng = np.random.default_rng(2)
    for _ in range(20):
        qq = rng.normal(size=4)
        qq /= np.linalg.norm(qq)
        r = quaternion_to_matrix(qq)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert math.isclose(np.linalg.det(r), 1.0, abs_tol=1e-12)
        np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(r)), r,
                                   atol=1e-12)
