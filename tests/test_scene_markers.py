"""The rig's picture (bfr_model.scene) and its markers (bfr_ros.markers), without a ROS graph.

Geometry is checked against closed forms and an independent derivation (not the functions
under test): the waist point at theta = 0, the contact points on the ball's surface, the ball
centre against the dynamics' ``RigidModel.ball_position``, the contact angle recovered from a
position alone; then the conversion to ``visualization_msgs`` field by field, a CDR round trip
through the bag typestore, and the rate gate.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import OffsetCurve
from bfr_model.io.bag import make_typestore
from bfr_model.param_file import ParameterError
from bfr_model.params import load_params
from bfr_model.scene import MarkerSpec, fix_markers, rig_markers, rig_picture, rotate
from bfr_ros.markers import WORLD_FRAME, RateGate, image_circle, marker_array
from rclpy.serialization import serialize_message
from visualization_msgs.msg import ImageMarker, Marker

P = load_params()
CURVE = OffsetCurve.from_params(P)
RB, DF = P.ball.radius, P.ball.plate_distance
A, B = P.frame.contour.a, P.frame.contour.b


def picture(theta: float, **kw: object):  # noqa: ANN201
    return rig_picture(CURVE, theta, ball_radius=RB, plate_distance=DF, **kw)  # type: ignore[arg-type]


def test_waist_on_top_at_rest() -> None:
    # theta = 0, phi = 0: contact at the waist (0, a - b), normal +y, ball centre (0, a - b + R)
    pic = picture(0.0, phi=0.0)
    R = math.sqrt(RB**2 - DF**2 / 4)
    assert pic.contact == pytest.approx([0.0, A - B], abs=1e-12)
    assert pic.ball == pytest.approx([0.0, A - B + R, 0.0], abs=1e-12)


@pytest.mark.parametrize(("theta", "phi"), [(0.3, 0.2), (-2.0, 1.3), (7.5, -4.0), (1.0, 2.4)])
def test_ball_contacts_and_contour(theta: float, phi: float) -> None:
    pic = picture(theta, phi=phi)
    # the ball centre is where the dynamics puts it
    assert pic.ball[:2] == pytest.approx(RigidModel(P).ball_position([theta, phi]), abs=1e-12)
    # both contact points (plate edges at z = +-d_f/2) lie on the ball's surface
    for z in (0.5 * DF, -0.5 * DF):
        d = math.dist([*pic.contact, z], pic.ball)
        assert d == pytest.approx(RB, rel=1e-9)
    # every contour vertex is at radius rho(phi_i) = a - b cos(2 phi_i) from the axis, and the
    # polygon is the frame-coordinates contour turned by theta: un-rotate and compare angles
    n = len(pic.contour)
    grid = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    assert np.hypot(*pic.contour.T) == pytest.approx(A - B * np.cos(2 * grid), abs=1e-12)
    back = rotate(-theta, pic.contour)
    assert np.arctan2(back[:, 0], back[:, 1]) == pytest.approx(
        np.angle(np.exp(1j * grid)), abs=1e-12)


def test_contact_from_a_position_alone() -> None:
    # a camera fix carries no phi: the contact angle comes from theta and (x, y) only
    theta, phi = 0.8, 2.1
    truth = picture(theta, phi=phi)
    from_fix = picture(theta, ball_xy=truth.ball[:2])
    assert from_fix.contact == pytest.approx(truth.contact, abs=1e-10)
    assert from_fix.ball == pytest.approx(truth.ball, abs=1e-15)
    # no ball known: no ball, no contact; a NaN fix is no ball either
    assert picture(theta).ball is None
    assert picture(theta, ball_xy=[math.nan, 0.1]).contact is None


def test_rig_markers_parts() -> None:
    pic = picture(0.4, phi=0.9)
    specs = {(s.ns, s.id): s for s in rig_markers(pic, label="t 1.00 s")}
    assert set(specs) == {("frame", 0), ("frame", 1), ("shaft", 0), ("ball", 0),
                          ("contact", 0), ("label", 0)}
    front, back = specs["frame", 0].points, specs["frame", 1].points
    assert front[0] == pytest.approx(front[-1])  # closed
    # the points are the outline in frame coordinates; the pose turns them by theta
    q = specs["frame", 0].orientation
    assert q == pytest.approx((0.0, 0.0, math.sin(0.2), math.cos(0.2)))
    assert rotate(0.4, front[:-1, :2]) == pytest.approx(pic.contour, abs=1e-12)
    assert specs["frame", 0].points is rig_markers(picture(1.3, phi=0.1))[0].points  # shared
    assert front[:, 2] == pytest.approx(0.5 * DF) and back[:, 2] == pytest.approx(-0.5 * DF)
    ball = specs["ball", 0]
    assert ball.kind == "sphere" and ball.position == pytest.approx(pic.ball)
    assert ball.scale == pytest.approx((2 * RB,) * 3)
    assert specs["contact", 0].points[:, :2] == pytest.approx(np.tile(pic.contact, (2, 1)))
    assert specs["label", 0].text == "t 1.00 s"
    gone = {(s.ns, s.kind) for s in rig_markers(picture(0.4))}
    assert ("ball", "delete") in gone and ("contact", "delete") in gone


def test_marker_spec_rejects_bad_fields() -> None:
    with pytest.raises(ParameterError, match=r"marker\.kind"):
        MarkerSpec(ns="a", id=0, kind="mesh")
    with pytest.raises(ParameterError, match=r"marker\.orientation"):
        MarkerSpec(ns="a", id=0, kind="sphere", orientation=(0, 0, 0, 2))
    with pytest.raises(ParameterError, match=r"marker\.points"):
        MarkerSpec(ns="a", id=0, kind="line_strip")
    with pytest.raises(ParameterError, match=r"marker\.color"):
        MarkerSpec(ns="a", id=0, kind="sphere", color=(2, 0, 0, 1))


def test_messages_carry_the_specs() -> None:
    pic = picture(1.1, phi=0.2)
    specs = rig_markers(pic, label="x") + fix_markers(0.01, 0.12, True, RB)
    stamp = 12_345_678_901
    arr = marker_array(specs, stamp)
    assert len(arr.markers) == len(specs)
    again = marker_array(rig_markers(picture(2.0, phi=0.3)), stamp)  # another instant
    assert again.markers[0].points[5] == arr.markers[0].points[5]
    for m, s in zip(arr.markers, specs, strict=True):
        assert m.header.frame_id == WORLD_FRAME == "world"
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (12, 345_678_901)
        assert (m.ns, m.id, m.action) == (s.ns, s.id, Marker.ADD)
        assert [m.pose.position.x, m.pose.position.y, m.pose.position.z] == \
            pytest.approx(s.position)
        assert [m.scale.x, m.scale.y, m.scale.z] == pytest.approx(s.scale)
        assert [m.color.r, m.color.g, m.color.b, m.color.a] == pytest.approx(s.color)
        q = m.pose.orientation
        assert [q.x, q.y, q.z, q.w] == pytest.approx(s.orientation)
        if s.points is not None:
            got = np.array([[p.x, p.y, p.z] for p in m.points])
            assert got == pytest.approx(s.points)
    types = {(m.ns, m.type) for m in arr.markers}
    assert ("ball", Marker.SPHERE) in types and ("frame", Marker.LINE_STRIP) in types
    assert ("contact", Marker.SPHERE_LIST) in types and ("label", Marker.TEXT_VIEW_FACING) in types
    # deletions
    gone = marker_array(fix_markers(math.nan, 0.1, True, RB), stamp).markers[0]
    assert gone.action == Marker.DELETE and gone.ns == "camera_fix"
    # what the recorder writes, the bag reader decodes (the typestore knows MarkerArray)
    store = make_typestore()
    back = store.deserialize_cdr(serialize_message(arr), "visualization_msgs/msg/MarkerArray")
    ball = next(m for m in back.markers if m.ns == "ball")
    assert [ball.pose.position.x, ball.pose.position.y] == pytest.approx(pic.ball[:2])


def test_image_circle() -> None:
    from builtin_interfaces.msg import Time  # noqa: PLC0415 - only this test builds a stamp

    m = image_circle(320.5, 100.25, 9.0, Time(sec=3, nanosec=5), "camera_optical_frame", True)
    assert (m.type, m.action, m.scale) == (ImageMarker.CIRCLE, ImageMarker.ADD, 9.0)
    assert (m.position.x, m.position.y) == (320.5, 100.25)
    assert m.header.frame_id == "camera_optical_frame" and m.header.stamp.nanosec == 5
    assert image_circle(math.nan, 1.0, 9.0, Time(), "c", True).action == ImageMarker.REMOVE
    assert image_circle(1.0, 1.0, 9.0, Time(), "c", False).action == ImageMarker.REMOVE


def test_rate_gate() -> None:
    ms = 1_000_000
    gate = RateGate(30.0)
    passed = [t for t in range(0, 10_000 * ms, 5 * ms) if gate.due(t)]  # 200 Hz for 10 s
    assert len(passed) == pytest.approx(300, abs=1)
    gaps = np.diff(passed) / ms
    assert gaps.min() >= 30.0 and gaps.max() <= 35.0
    assert not any(RateGate(0.0).due(t) for t in range(0, 100 * ms, ms))
    # a time reset (a bag replayed, a restarted simulator) restarts the schedule
    g = RateGate(10.0)
    assert g.due(5_000 * ms) and not g.due(5_050 * ms) and g.due(0)
    with pytest.raises(ParameterError, match=r"markers\.rate"):
        RateGate(-1.0)
