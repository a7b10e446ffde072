"""Camera of the independent rig: pinhole + plumb-bob distortion, OpenCV drawing, seeded noise.

Written apart from bfr. The scene: a dark background with a fixed illumination gradient, the
back plate, the bright ball, then the front plate (which hides the part of the ball that lies
inside the contour), a hub and screw heads that turn with the frame, and Gaussian pixel noise.

Camera model
------------
Pose: optical centre ``C`` [m] in the world (origin on the axis, x right, y up, z towards the
camera); optical frame (REP 103 optical: z forward, x right, y down in the image) with
``z_opt`` towards ``look_at``, ``x_opt`` the world's +x made orthogonal to it and turned by
``roll`` about ``z_opt``, ``y_opt = z_opt x x_opt``. World-from-optical rotation
``R_wo = [x_opt y_opt z_opt]``; OpenCV's ``rvec, tvec`` are of ``R_ow = R_wo^T``,
``t = -R_ow C``. Projection: ``cv2.projectPoints`` with ``K`` and ``(k1, k2, p1, p2, k3)``,
which is ROS's plumb_bob model.

Sphere silhouette: the limb of a ball of radius ``R_b`` at centre ``S`` seen from ``C`` is
the circle in the plane normal to ``S - C`` at ``R_b^2 / |S - C|`` from ``S`` towards ``C``,
of radius ``R_b sqrt(1 - R_b^2 / |S - C|^2)``; its projection is drawn as a polygon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from . import physics

#: Sub-pixel bits used by cv2.fillPoly.
_SHIFT = 4
#: Vertices of the ball's projected outline.
_BALL_VERTICES = 40


@dataclass(frozen=True, kw_only=True)
class CameraModel:
    """Intrinsics, distortion, pose and timing of the independent rig's camera.

    Parameters
    ----------
    width, height : int
        Image size [px].
    fx, fy, cx, cy : float
        Pinhole intrinsics [px].
    distortion : tuple of float
        Plumb-bob ``(k1, k2, p1, p2, k3)`` [-].
    position : tuple of float
        Optical centre in the world [m].
    look_at : tuple of float
        Point the optical axis passes through [m].
    roll : float
        Rotation of the image about the optical axis [rad].
    exposure_time : float
        Exposure [s].
    """

    width: int = 640
    height: int = 480
    fx: float = 706.4
    fy: float = 709.1
    cx: float = 327.3
    cy: float = 234.6
    distortion: tuple[float, ...] = (-0.118, 0.094, 0.0007, -0.0005, -0.027)
    position: tuple[float, float, float] = (0.038, -0.027, 0.655)
    look_at: tuple[float, float, float] = (0.004, 0.002, 0.0)
    roll: float = 0.015
    exposure_time: float = 0.002

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if min(self.fx, self.fy) <= 0.0:
            raise ValueError("focal lengths must be > 0 px")
        if len(self.distortion) != 5 or len(self.position) != 3 or len(self.look_at) != 3:
            raise ValueError("distortion needs 5 values, position and look_at 3 [m]")
        if not all(math.isfinite(v) for v in (*self.distortion, *self.position,
                                              *self.look_at, self.roll, self.cx, self.cy)):
            raise ValueError("camera parameters must be finite")
        if self.position[2] <= 0.05:
            raise ValueError("the camera must be in front of the frame (position z > 0.05 m)")

    @property
    def k_matrix(self) -> np.ndarray:
        """3x3 intrinsic matrix ``K`` [px]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def rotation_world_optical(self) -> np.ndarray:
        """``R_wo``: columns are the optical frame's axes in world coordinates."""
        z = np.subtract(self.look_at, self.position)
        z = z / np.linalg.norm(z)
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        c, s = math.cos(self.roll), math.sin(self.roll)
        x, y = c * x + s * y, -s * x + c * y
        return np.stack([x, y, z], axis=1)

    def quaternion_xyzw(self) -> tuple[float, float, float, float]:
        """Orientation of the optical frame in the world, quaternion ``(x, y, z, w)``."""
        m = self.rotation_world_optical
        w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
        x = math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0
        y = math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0
        z = math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0
        x = math.copysign(x, m[2, 1] - m[1, 2])
        y = math.copysign(y, m[0, 2] - m[2, 0])
        z = math.copysign(z, m[1, 0] - m[0, 1])
        return x, y, z, w

    def extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV ``rvec``, ``tvec`` of the world-to-optical transform."""
        r_ow = self.rotation_world_optical.T
        rvec, _ = cv2.Rodrigues(r_ow)
        tvec = -r_ow @ np.asarray(self.position, dtype=float)
        return rvec.reshape(3), tvec

    def project(self, points: np.ndarray) -> np.ndarray:
        """Project world points to distorted pixel coordinates.

        Parameters
        ----------
        points : numpy.ndarray
            (n, 3) world points [m].

        Returns
        -------
        numpy.ndarray
            (n, 2) pixel coordinates ``(u, v)`` [px].
        """
        rvec, tvec = self.extrinsics()
        uv, _ = cv2.projectPoints(np.ascontiguousarray(points, dtype=np.float64), rvec, tvec,
                                  self.k_matrix, np.asarray(self.distortion, dtype=float))
        return uv.reshape(-1, 2)


@dataclass
class Renderer:
    """Draws mono8 frames of the independent rig.

    Parameters
    ----------
    params : physics.RigParams
        The rig (contour, ball radius, plate gap).
    camera : CameraModel
        The camera.
    rng : numpy.random.Generator
        Seeded source of the pixel noise.
    noise_std : float
        Pixel noise standard deviation [DN].
    n_contour : int
        Polygon vertices of a plate's silhouette.
    occlusion : bool
        The (opaque) front plate hides the part of the ball inside the contour (about 6 mm
        of its 33 mm); False draws the whole ball (a transparent front plate).
    """

    params: physics.RigParams
    camera: CameraModel
    rng: np.random.Generator
    noise_std: float = 2.5
    n_contour: int = 360
    occlusion: bool = True
    _contour: np.ndarray = field(init=False, repr=False)
    _background: np.ndarray = field(init=False, repr=False)
    _noise_pos: list[np.ndarray] = field(init=False, repr=False)
    _noise_neg: list[np.ndarray] = field(init=False, repr=False)
    _rvec: np.ndarray = field(init=False, repr=False)
    _tvec: np.ndarray = field(init=False, repr=False)
    _k: np.ndarray = field(init=False, repr=False)
    _d: np.ndarray = field(init=False, repr=False)
    _detail_xy: np.ndarray = field(init=False, repr=False)
    _detail_spans: list[tuple[int, int]] = field(init=False, repr=False)
    _ring: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.noise_std >= 0.0 and math.isfinite(self.noise_std)):
            raise ValueError(f"noise_std must be >= 0 DN, got {self.noise_std}")
        phi = np.linspace(0.0, 2 * np.pi, self.n_contour, endpoint=False)
        rho = physics.contour_radius(self.params, phi)[0]
        self._contour = np.stack([rho * np.sin(phi), rho * np.cos(phi)], axis=1)
        h, w = self.camera.height, self.camera.width
        vv, uu = np.mgrid[0:h, 0:w]
        rr = np.hypot((uu - 0.42 * w) / w, (vv - 0.6 * h) / h)
        self._background = np.clip(30.0 - 22.0 * rr, 6, 40).astype(np.uint8)
        bank = 6
        self._noise_pos, self._noise_neg = [], []
        for _ in range(bank):
            noise = self.rng.normal(0.0, self.noise_std, size=(h, w))
            self._noise_pos.append(np.clip(np.rint(noise), 0, 255).astype(np.uint8))
            self._noise_neg.append(np.clip(np.rint(-noise), 0, 255).astype(np.uint8))
        self._rvec, self._tvec = self.camera.extrinsics()
        self._k = self.camera.k_matrix
        self._d = np.asarray(self.camera.distortion, dtype=float)
        self._detail_xy, self._detail_spans = self._details()
        ring = np.linspace(0.0, 2 * np.pi, _BALL_VERTICES, endpoint=False)
        self._ring = (np.cos(ring), np.sin(ring))

    def _project(self, pts: np.ndarray) -> np.ndarray:
        uv, _ = cv2.projectPoints(pts, self._rvec, self._tvec, self._k, self._d)
        return np.rint(uv.reshape(-1, 1, 2) * (1 << _SHIFT)).astype(np.int32)

    def _ball_outline(self, x: float, y: float) -> np.ndarray:
        """World points of the ball's limb circle (module docstring)."""
        cx, cy, cz = self.camera.position
        ax, ay, az = cx - x, cy - y, cz
        dist = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / dist, ay / dist, az / dist
        rb = self.params.ball_radius
        k = rb * rb / dist
        limb_radius = rb * math.sqrt(max(0.0, 1.0 - (rb / dist) ** 2))
        # u = axis x (0, 1, 0), v = axis x u (both unit: axis is far from +y)
        ux, uy, uz = -az, 0.0, ax
        norm = math.hypot(ux, uz)
        ux, uz = ux / norm, uz / norm
        vx, vy, vz = ay * uz - az * uy, az * ux - ax * uz, ax * uy - ay * ux
        ca, sa = self._ring
        pts = np.empty((len(ca), 3))
        pts[:, 0] = x + ax * k + limb_radius * (ca * ux + sa * vx)
        pts[:, 1] = y + ay * k + limb_radius * (ca * uy + sa * vy)
        pts[:, 2] = az * k + limb_radius * (ca * uz + sa * vz)
        return pts

    @staticmethod
    def _details() -> tuple[np.ndarray, list[tuple[int, int]]]:
        """Hub, screw heads and lightening holes: frame-coordinate outlines and grey levels."""
        items = [((0.0, 0.0), 0.014, 120), ((0.0, 0.0), 0.004, 35)]
        for sign in (1.0, -1.0):
            items.append(((sign * 0.095, 0.0), 0.016, 28))
            items.append(((sign * 0.035, 0.022), 0.003, 150))
            items.append(((sign * 0.035, -0.022), 0.003, 150))
        a = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
        outlines = [np.stack([fx + radius * np.cos(a), fy + radius * np.sin(a)], axis=1)
                    for (fx, fy), radius, _ in items]
        spans, start = [], 0
        for (_, _, value), outline in zip(items, outlines, strict=True):
            spans.append((start + len(outline), value))
            start += len(outline)
        return np.concatenate(outlines), spans

    def render(self, theta: float, ball_xy: tuple[float, float] | None) -> np.ndarray:
        """Draw one frame.

        All world points (both plates' silhouettes at ``z = -+d_f / 2``, the ball's limb,
        the frame's details on the front plate) are projected in one call.

        Parameters
        ----------
        theta : float
            Frame angle [rad].
        ball_xy : tuple of float or None
            Ball centre in the world [m], or None when no ball is on the rig.

        Returns
        -------
        numpy.ndarray
            (height, width) uint8 image [DN].
        """
        half_gap = self.params.plate_gap / 2.0
        c, s = math.cos(theta), math.sin(theta)
        rot = np.array([[c, s], [-s, c]])
        n = len(self._contour)
        nd = len(self._detail_xy)
        ball = ball_xy is not None and all(math.isfinite(v) for v in ball_xy)
        pts = np.empty((2 * n + nd + (_BALL_VERTICES if ball else 0), 3))
        pts[:n, :2] = pts[n:2 * n, :2] = self._contour @ rot
        pts[:n, 2], pts[n:2 * n, 2] = -half_gap, half_gap
        pts[2 * n:2 * n + nd, :2] = self._detail_xy @ rot
        pts[2 * n:2 * n + nd, 2] = half_gap
        if ball:
            pts[2 * n + nd:] = self._ball_outline(*ball_xy)  # type: ignore[misc]
        uv = self._project(pts)
        img = self._background.copy()
        cv2.fillPoly(img, [uv[:n]], 62, cv2.LINE_AA, _SHIFT)
        if ball:
            cv2.fillPoly(img, [uv[2 * n + nd:]], 228, cv2.LINE_AA, _SHIFT)
        front = uv[n:2 * n]
        cv2.fillPoly(img, [front], 84, cv2.LINE_AA, _SHIFT)
        cv2.polylines(img, [front], True, 104, 1, cv2.LINE_AA, _SHIFT)
        begin = 0
        for stop, value in self._detail_spans:
            cv2.fillPoly(img, [uv[2 * n + begin:2 * n + stop]], value, cv2.LINE_AA, _SHIFT)
            begin = stop
        if ball and not self.occlusion:  # a transparent front plate: the whole ball shows
            cv2.fillPoly(img, [uv[2 * n + nd:]], 228, cv2.LINE_AA, _SHIFT)
        if self.noise_std > 0.0:
            k = int(self.rng.integers(len(self._noise_pos)))
            cv2.add(img, self._noise_pos[k], dst=img)
            cv2.subtract(img, self._noise_neg[(k + 1) % len(self._noise_neg)], dst=img)
        return img
