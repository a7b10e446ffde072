"""The rig as a picture: world-frame geometry of one instant, and marker descriptions.

Pure numpy (no ``rclpy``): the nodes turn the :class:`MarkerSpec` records into
``visualization_msgs`` messages (:mod:`bfr_ros.markers`), and ``bfr video`` draws the same
geometry with OpenCV, so the 3-D view and the video show one picture.

Geometry (DEVELOPERS.md conventions: world x right, y up, z towards the camera, origin on the
frame's axis, ``Rot(theta)`` counter-clockwise)
------------------------------------------------------------------------------------------
The frame is two parallel plates ``d_f`` apart, at ``z = +-d_f / 2``; the edge of each plate
is the contour ``delta(phi) = rho(phi) [sin phi, cos phi]`` (frame coordinates), so in the
world

    c(phi) = Rot(theta) delta(phi),                                  z = +-d_f / 2.

The ball (radius ``R_b``) lies in the groove between the plates with its centre in the plane
``z = 0`` on the offset curve ``p(phi) = delta(phi) + R n(phi)``:

    r = Rot(theta) p(phi),        R = sqrt(R_b^2 - d_f^2 / 4),

and touches each plate's edge at ``c(phi)``: the two contact points are ``(c, +-d_f / 2)``,
at distance ``sqrt(R^2 + d_f^2 / 4) = R_b`` from the centre, i.e. on the ball's surface.

Given a measured ball position instead of ``phi`` (a camera fix, a rig log), the contact angle
follows from the ball-centre angle in frame coordinates,
``psi = theta + atan2(x, y)`` (clockwise from the frame's +y axis), by
:meth:`bfr_model.geometry.OffsetCurve.phi_from_ball_angle`; this uses only theta and (x, y),
never a log's own ``phi`` column, whose conventions differ between rigs.

Markers
-------
:class:`MarkerSpec` mirrors the fields of ``visualization_msgs/Marker`` that the views use
(namespace, id, type, pose, scale, colour, points, text, lifetime) with SI units; the header
(``frame_id``, stamp) is added by the publisher. All markers are in one frame, the world
frame (``bfr_ros.markers.WORLD_FRAME``), so Foxglove and RViz need no transform to show them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_model.geometry import OffsetCurve
from bfr_model.param_file import check, finite, positive

__all__ = [
    "COLORS",
    "MARKER_KINDS",
    "MarkerSpec",
    "RigPicture",
    "fix_markers",
    "rig_markers",
    "rig_picture",
    "rotate",
]

FloatArray = NDArray[np.float64]

#: Marker types used here (``visualization_msgs/Marker`` type names, lower case), and
#: ``delete`` (action DELETE of that namespace and id).
MARKER_KINDS = ("sphere", "cylinder", "line_strip", "sphere_list", "text_view_facing",
                "delete")

#: Colours (r, g, b, a in [0, 1]) of the parts of the picture, shared by the markers and
#: ``bfr video`` (which converts them to BGR).
COLORS: dict[str, tuple[float, float, float, float]] = {
    "front_plate": (0.55, 0.62, 0.72, 1.0),
    "back_plate": (0.35, 0.40, 0.48, 0.6),
    "shaft": (0.25, 0.25, 0.25, 1.0),
    "ball": (0.95, 0.55, 0.10, 1.0),
    "truth": (0.95, 0.95, 0.95, 1.0),
    "contact": (0.85, 0.10, 0.10, 1.0),
    "fix": (0.10, 0.75, 0.95, 0.6),
    "text": (1.0, 1.0, 1.0, 1.0),
}


def rotate(theta: float, xy: ArrayLike) -> FloatArray:
    """``Rot(theta) xy`` for points of shape (..., 2) [m] (counter-clockwise)."""
    xy = np.asarray(xy, dtype=float)
    c, s = math.cos(theta), math.sin(theta)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


@dataclass(frozen=True, kw_only=True)
class RigPicture:
    """World-frame geometry of the rig at one instant (module docstring), SI units.

    Attributes
    ----------
    theta : float
        Frame angle [rad].
    outline : ndarray, shape (n, 2)
        The plates' edge in frame coordinates, ``delta(phi_i)`` on ``n`` contact angles
        ``phi_i = 2 pi i / n`` [m] (open polygon: close it to draw). Shared between pictures
        of one curve (do not modify).
    contour : ndarray, shape (n, 2)
        The same in the world, ``Rot(theta) delta(phi_i)`` [m].
    ball : ndarray, shape (3,) or None
        Ball centre [m] (z: out of the plane; 0 for the rigid model without wobble); None when
        the ball is not known.
    contact : ndarray, shape (2,) or None
        In-plane contact point ``Rot(theta) delta(phi)`` [m]; the two contact points are at
        ``z = +-plate_distance / 2``.
    ball_radius : float
        R_b [m].
    plate_distance : float
        d_f [m].
    """

    theta: float
    outline: FloatArray
    contour: FloatArray
    ball: FloatArray | None
    contact: FloatArray | None
    ball_radius: float
    plate_distance: float

    def __post_init__(self) -> None:
        finite("theta", self.theta)
        positive("ball.radius", self.ball_radius)
        positive("ball.plate_distance", self.plate_distance)
        check(self.plate_distance < 2.0 * self.ball_radius, "ball.plate_distance",
              f"must be < 2 R_b = {2.0 * self.ball_radius} m (the ball must reach the plates)")


_OUTLINES: dict[tuple[int, int], tuple[OffsetCurve, FloatArray]] = {}
_RINGS: dict[tuple[int, float], tuple[FloatArray, FloatArray]] = {}


def _outline(curve: OffsetCurve, n: int) -> FloatArray:
    """``delta(2 pi i / n)``, i < n, in frame coordinates, computed once per curve and n."""
    check(n >= 8, "n_contour", f"must be >= 8, got {n}")
    key = (id(curve), n)
    hit = _OUTLINES.get(key)
    if hit is None or hit[0] is not curve:
        if len(_OUTLINES) > 32:
            _OUTLINES.clear()
        grid = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        out = curve.contour_point(grid)
        out.flags.writeable = False
        hit = _OUTLINES[key] = (curve, out)
    return hit[1]


def _ring(outline: FloatArray, z: float) -> FloatArray:
    """The closed outline lifted to z, shape (n + 1, 3): one array per outline and z."""
    key = (id(outline), z)
    hit = _RINGS.get(key)
    if hit is None or hit[0] is not outline:
        if len(_RINGS) > 64:
            _RINGS.clear()
        ring = np.vstack([outline, outline[:1]])
        out = np.column_stack([ring, np.full(len(ring), z)])
        out.flags.writeable = False
        hit = _RINGS[key] = (outline, out)
    return hit[1]


def rig_picture(curve: OffsetCurve, theta: float, *, phi: float | None = None,
                ball_xy: ArrayLike | None = None, ball_z: float = 0.0, ball_radius: float,
                plate_distance: float, n_contour: int = 64) -> RigPicture:
    """The rig at frame angle ``theta``, the ball given by its contact angle or its position.

    Parameters
    ----------
    curve : OffsetCurve
        The frame contour and the ball-centre curve (:meth:`OffsetCurve.from_params`).
    theta : float
        Frame angle [rad].
    phi : float, optional
        Contact angle [rad] (the state's phi). The ball centre is ``Rot(theta) p(phi)``.
    ball_xy : array_like, shape (2,), optional
        Ball centre in the world [m] (a camera fix or the simulator's truth); used for the
        ball when given, and for the contact angle when ``phi`` is not (module docstring).
    ball_z : float
        Ball centre's z [m] (the simulator's wobble sway).
    ball_radius, plate_distance : float
        R_b and d_f [m].
    n_contour : int
        Points of the contour polygon (64: chords within 0.4 mm of the nominal contour).

    Returns
    -------
    RigPicture
        Without a ball (and contact) when neither ``phi`` nor a finite ``ball_xy`` is given.
    """
    outline = _outline(curve, n_contour)
    contour = rotate(theta, outline)
    ball: FloatArray | None = None
    contact: FloatArray | None = None
    have_xy = ball_xy is not None and bool(np.all(np.isfinite(np.asarray(ball_xy, float))))
    if phi is None and have_xy:
        xy = np.asarray(ball_xy, float)
        psi = theta + math.atan2(float(xy[0]), float(xy[1]))
        phi = float(curve.phi_from_ball_angle(np.array([psi]))[0])
    if phi is not None and math.isfinite(phi):
        contact = rotate(theta, curve.contour_point(np.array([phi]))[0])
        centre = (np.asarray(ball_xy, float) if have_xy
                  else rotate(theta, curve.point(np.array([phi]))[0]))
        ball = np.array([centre[0], centre[1], float(ball_z)])
    return RigPicture(theta=float(theta), outline=outline, contour=contour, ball=ball,
                      contact=contact,
                      ball_radius=float(ball_radius), plate_distance=float(plate_distance))


@dataclass(frozen=True, kw_only=True)
class MarkerSpec:
    """One ``visualization_msgs/Marker`` without its header, SI units.

    Attributes
    ----------
    ns : str
        Namespace; with ``id`` it names the marker (a new one replaces the old).
    id : int
        Id within the namespace.
    kind : str
        One of :data:`MARKER_KINDS`.
    position : tuple of 3 float
        Pose position [m].
    orientation : tuple of 4 float
        Pose orientation quaternion (x, y, z, w) [-], unit norm.
    scale : tuple of 3 float
        Size [m]: diameters of a sphere or cylinder (z: the cylinder's length), the line
        width (x) of a line strip, the sphere diameter of a sphere list, the text height (z).
    color : tuple of 4 float
        r, g, b, a in [0, 1].
    points : ndarray, shape (n, 3), or None
        Vertices [m] of a line strip or sphere list, in the pose's frame.
    text : str
        Text of a text marker.
    lifetime : float
        Seconds after its stamp that the viewer drops it; 0 keeps it until replaced [s].
    """

    ns: str
    id: int
    kind: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    points: FloatArray | None = field(default=None, compare=False)
    text: str = ""
    lifetime: float = 0.0

    def __post_init__(self) -> None:
        check(self.kind in MARKER_KINDS, "marker.kind",
              f"must be one of {MARKER_KINDS}, got {self.kind!r}")
        check(bool(np.all(np.isfinite(self.position))), "marker.position",
              f"must be finite, got {self.position}")
        check(abs(float(np.linalg.norm(self.orientation)) - 1.0) < 1e-9, "marker.orientation",
              f"must be a unit quaternion, got {self.orientation}")
        check(all(0.0 <= c <= 1.0 for c in self.color), "marker.color",
              f"components must lie in [0, 1], got {self.color}")
        if self.points is not None:
            pts = np.asarray(self.points, dtype=float)
            check(pts.ndim == 2 and pts.shape[1] == 3 and bool(np.all(np.isfinite(pts))),
                  "marker.points", f"must be finite, shape (n, 3), got {pts.shape}")
        if self.kind in ("line_strip", "sphere_list"):
            check(self.points is not None and len(self.points) > 0, "marker.points",
                  f"a {self.kind} needs points")
        if self.kind != "delete":
            check(all(s > 0 for s in self.scale), "marker.scale",
                  f"must be > 0, got {self.scale}")
        check(self.lifetime >= 0.0, "marker.lifetime", f"must be >= 0 s, got {self.lifetime}")


def rig_markers(pic: RigPicture, *, label: str = "", line_width: float = 2.0e-3
                ) -> list[MarkerSpec]:
    """The simulator's markers of one instant.

    Namespaces and ids:

    - ``frame`` 0 / 1: the front / back plate's edge (closed line strips at ``z = +-d_f/2``),
      points in frame coordinates, the pose's orientation the frame's: ``theta`` about z
      (so the points are the same array every time: a publisher converts them once);
    - ``shaft`` 0: the axis (a cylinder along z at the origin);
    - ``ball`` 0: the ball (a sphere of diameter ``2 R_b`` at its centre), DELETE when unknown;
    - ``contact`` 0: the two contact points (a sphere list), DELETE when unknown;
    - ``label`` 0: ``label`` as a text above the frame (omitted when empty).

    Parameters
    ----------
    pic : RigPicture
        The geometry.
    label : str
        Text to show (e.g. time and torque).
    line_width : float
        Width of the plate edges [m].
    """
    h = 0.5 * pic.plate_distance
    q = (0.0, 0.0, math.sin(0.5 * pic.theta), math.cos(0.5 * pic.theta))  # Rot(theta) about z
    out = [
        MarkerSpec(ns="frame", id=0, kind="line_strip", orientation=q,
                   scale=(line_width, 1.0, 1.0), color=COLORS["front_plate"],
                   points=_ring(pic.outline, h)),
        MarkerSpec(ns="frame", id=1, kind="line_strip", orientation=q,
                   scale=(line_width, 1.0, 1.0), color=COLORS["back_plate"],
                   points=_ring(pic.outline, -h)),
        MarkerSpec(ns="shaft", id=0, kind="cylinder",
                   scale=(0.008, 0.008, 2.0 * pic.plate_distance), color=COLORS["shaft"]),
    ]
    if pic.ball is None or pic.contact is None:
        out += [MarkerSpec(ns="ball", id=0, kind="delete"),
                MarkerSpec(ns="contact", id=0, kind="delete")]
    else:
        d = 2.0 * pic.ball_radius
        out.append(MarkerSpec(ns="ball", id=0, kind="sphere",
                              position=tuple(float(v) for v in pic.ball),  # type: ignore[arg-type]
                              scale=(d, d, d), color=COLORS["ball"]))
        c = pic.contact
        s = 0.25 * pic.ball_radius
        out.append(MarkerSpec(ns="contact", id=0, kind="sphere_list", scale=(s, s, s),
                              color=COLORS["contact"],
                              points=np.array([[c[0], c[1], h], [c[0], c[1], -h]])))
    if label:
        top = float(np.max(np.hypot(pic.contour[:, 0], pic.contour[:, 1])))
        out.append(MarkerSpec(ns="label", id=0, kind="text_view_facing",
                              position=(0.0, top + 0.03, 0.0), scale=(0.012, 0.012, 0.012),
                              color=COLORS["text"], text=label))
    return out


def fix_markers(x: float, y: float, valid: bool, ball_radius: float, *, ns: str = "camera_fix",
                lifetime: float = 0.0) -> list[MarkerSpec]:
    """The camera's fix: a translucent sphere of the ball's size at (x, y, 0), or DELETE.

    Parameters
    ----------
    x, y : float
        Ball centre in the world [m] (``BallObservation.x, y``).
    valid : bool
        Whether the observation is a valid fix; if not (or not finite), the marker is deleted.
    ball_radius : float
        R_b [m].
    ns : str
        Namespace.
    lifetime : float
        Seconds the viewer keeps it [s] (0: until replaced).
    """
    positive("ball.radius", ball_radius)
    if not (valid and math.isfinite(x) and math.isfinite(y)):
        return [MarkerSpec(ns=ns, id=0, kind="delete")]
    d = 2.0 * ball_radius
    return [MarkerSpec(ns=ns, id=0, kind="sphere", position=(float(x), float(y), 0.0),
                       scale=(d, d, d), color=COLORS["fix"], lifetime=lifetime)]
