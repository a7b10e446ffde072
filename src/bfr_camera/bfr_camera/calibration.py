"""Camera model of the rig: intrinsics, lens distortion, pose, and the pixel <-> world mapping.

Pure numpy/OpenCV (no ``rclpy``). A real camera's calibration drops in either as a
``sensor_msgs/CameraInfo``-shaped mapping (:meth:`CameraModel.from_camera_info`, which also
takes the message object itself), as a ``camera_calibration_parsers`` YAML file
(:func:`load_ros_calibration_yaml`, the ``ost.yaml`` that ``camera_calibration`` writes), or
through ``config/camera.yaml`` (:func:`load_camera`), the camera node's parameter file.

Frames
------
World (DEVELOPERS.md): origin on the frame's rotation axis, x right, y up, z towards the
camera. Camera optical frame (REP 103 ``*_optical_frame``): x right, y down, z forward along
the optical axis. The pose is the optical frame's position ``c`` [m] and orientation (unit
quaternion ``q = (x, y, z, w)``, ``R_wc = R(q)``) in the world, so a world point ``X_w`` has
camera coordinates

    X_c = R_cw (X_w - c),        R_cw = R_wc^T.

Lens models (OpenCV / ROS ``plumb_bob``, ``rational_polynomial``, ``equidistant``)
----------------------------------------------------------------------------------------
Normalised coordinates ``x = X_c / Z_c``, ``y = Y_c / Z_c``, ``r^2 = x^2 + y^2``,

    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
          + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (...) / (...) + p1 (r^2 + 2 y^2) + 2 p2 x y
    u = fx x_d + s y_d + cx,   v = fy y_d + cy,        K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]

with ``D = (k1, k2, p1, p2, k3[, k4, k5, k6])``. A fisheye lens (ROS ``equidistant``,
OpenCV's :mod:`cv2.fisheye`, ``D = (k1, k2, k3, k4)``) maps the ray's angle from the
optical axis ``theta = atan r`` instead:

    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),
    (x_d, y_d) = (theta_d / r) (x, y),   u = fx x_d + s y_d + cx,   v = fy y_d + cy.

Pixel centres sit at integer coordinates (OpenCV and ROS convention): the image centre of a
W x H image is ((W-1)/2, (H-1)/2).

Pixel -> world (the ball centre lies in a known plane ``z = z0``): undistort the pixel to
``(x, y)`` (iteratively, :func:`cv2.undistortPoints` or its fisheye twin), form the viewing ray
``d_w = R_wc [x, y, 1]^T`` from the optical centre ``c``, and intersect it with the plane:

    X_w = c + lambda d_w,       lambda = (z0 - c_z) / d_{w,z}   (> 0, else no intersection).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from bfr_model.param_file import (
    ParameterError,
    check,
    config_path,
    finite,
    load_ros_parameters,
    positive,
)
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DISTORTION_MODELS",
    "CameraModel",
    "CameraModelError",
    "camera_from_dict",
    "camera_to_dict",
    "camera_to_ros_yaml",
    "default_camera_path",
    "load_camera",
    "load_ros_calibration_yaml",
    "look_at",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "read_ros_parameters",
]

FloatArray = NDArray[np.float64]

#: Distortion models understood (ROS names) and the coefficient counts OpenCV accepts for them.
DISTORTION_MODELS: dict[str, tuple[int, ...]] = {
    "plumb_bob": (0, 4, 5),
    "rational_polynomial": (8, 12, 14),
    # a fisheye lens (ROS camera_calibration --fisheye, OpenCV's cv2.fisheye): k1..k4 of
    # theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), theta the
    # angle of the ray from the optical axis, r_d = theta_d in normalised units
    "equidistant": (4,),
}

#: Termination of the iterative undistortion: enough iterations for 1e-9 px round trips.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-14)


class CameraModelError(ParameterError):
    """A camera model, calibration file or parameter is invalid; the message says which.

    A :class:`bfr_model.param_file.ParameterError` (so a ``ValueError``): a failed check of a
    field is re-raised as this type.
    """


# --------------------------------------------------------------------------------------------
# Rotations
# --------------------------------------------------------------------------------------------
def quaternion_to_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrix of a unit quaternion ``(x, y, z, w)`` (ROS order).

    Parameters
    ----------
    q : array_like, shape (4,)
        Quaternion; it is normalised first (its norm must be positive and finite).

    Returns
    -------
    ndarray, shape (3, 3)
        ``R`` such that ``v' = R v`` rotates a vector by ``q``.
    """
    x, y, z, w = np.asarray(q, dtype=float).reshape(4)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or n == 0.0:
        raise CameraModelError(f"quaternion {tuple(q)} has no direction")  # type: ignore[arg-type]
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quaternion(r: ArrayLike) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix (Shepperd's method, w >= 0).

    Parameters
    ----------
    r : array_like, shape (3, 3)
        Proper rotation matrix.
    """
    m = np.asarray(r, dtype=float).reshape(3, 3)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s)
    qa = np.array(q)
    if qa[3] < 0:
        qa = -qa
    qa /= np.linalg.norm(qa)
    return (float(qa[0]), float(qa[1]), float(qa[2]), float(qa[3]))


def look_at(eye: ArrayLike, target: ArrayLike = (0.0, 0.0, 0.0),
            up: ArrayLike = (0.0, 1.0, 0.0)) -> tuple[float, float, float, float]:
    """Orientation of an optical frame at ``eye`` looking at ``target`` with ``up`` up.

    The optical axis is ``z_c = (target - eye) / |target - eye|``, the image's x axis
    ``x_c = z_c x up / |z_c x up|`` (right), and its y axis ``y_c = z_c x x_c`` (down).

    Returns
    -------
    tuple of 4 float
        Quaternion ``(x, y, z, w)`` of ``R_wc = [x_c y_c z_c]``.
    """
    e = np.asarray(eye, dtype=float).reshape(3)
    z = np.asarray(target, dtype=float).reshape(3) - e
    if np.linalg.norm(z) == 0.0:
        raise CameraModelError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float).reshape(3))
    if np.linalg.norm(x) < 1e-12:
        raise CameraModelError("look_at: 'up' is parallel to the viewing direction")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return matrix_to_quaternion(np.column_stack([x, y, z]))


# --------------------------------------------------------------------------------------------
# The camera model
# --------------------------------------------------------------------------------------------
def _finite_seq(name: str, values: Any, length: int | None = None) -> tuple[float, ...]:
    """``values`` as a tuple of finite floats (``length`` of them when given).

    Raises
    ------
    ParameterError
        Naming ``camera.<name>``, if a value is not a finite number or the count is wrong.
    """
    try:
        t, numeric = tuple(float(v) for v in np.asarray(values, dtype=float).reshape(-1)), True
    except (TypeError, ValueError):
        t, numeric = (), False
    check(numeric, f"camera.{name}", f"expected numbers, got {values!r}")
    check(length is None or len(t) == length, f"camera.{name}",
          f"expected {length} numbers, got {len(t)}")
    check(all(math.isfinite(v) for v in t), f"camera.{name}", f"values must be finite, got {t}")
    return t


def _positive_int(name: str, value: Any) -> int:
    """``value`` as an int if it is a positive integer (``640.0`` counts, a bool does not)."""
    ok = (isinstance(value, (int, np.integer, float)) and not isinstance(value, bool)
          and float(value).is_integer() and value > 0)
    check(ok, f"camera.{name}", f"expected a positive integer, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class CameraModel:
    """A calibrated pinhole camera with lens distortion and a pose in the world frame.

    Attributes
    ----------
    width, height : int
        Image size [px].
    k : tuple of 9 float
        Camera matrix K, row-major [px] (``fx, s, cx, 0, fy, cy, 0, 0, 1``).
    d : tuple of float
        Distortion coefficients D [-] in OpenCV/ROS order (0, 4, 5, 8, 12 or 14 of them).
    distortion_model : str
        ``"plumb_bob"`` (up to 5 coefficients), ``"rational_polynomial"`` or
        ``"equidistant"`` (a fisheye lens: 4 coefficients).
    position : tuple of 3 float
        Optical centre ``c`` in the world frame [m].
    orientation : tuple of 4 float
        Unit quaternion ``(x, y, z, w)`` of the optical frame in the world frame (``R_wc``).
        The default ``(1, 0, 0, 0)`` (half a turn about x) looks along -z with image-up = +y.
    exposure_time : float
        Exposure (shutter) time [s]; frames are stamped at mid-exposure.
    frame_rate : float
        Frame rate [Hz].
    frame_id : str
        Name of the optical frame (ROS ``header.frame_id`` of the camera's images).
    """

    width: int = 640
    height: int = 480
    k: tuple[float, ...] = (600.0, 0.0, 319.5, 0.0, 600.0, 239.5, 0.0, 0.0, 1.0)
    d: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    distortion_model: str = "plumb_bob"
    position: tuple[float, ...] = (0.0, 0.0, 0.5)
    orientation: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)
    exposure_time: float = 2.0e-3
    frame_rate: float = 200.0
    frame_id: str = "camera_optical_frame"

    def __post_init__(self) -> None:
        try:
            self._validate()
        except CameraModelError:
            raise
        except ParameterError as exc:  # a failed check: the camera's own error type
            raise CameraModelError(str(exc)) from exc

    def _validate(self) -> None:
        """Check every field with the checks of :mod:`bfr_model.param_file`; normalise types.

        Sizes become ints, sequences tuples of floats, the quaternion is normalised.
        """
        set_ = object.__setattr__
        for name in ("width", "height"):
            set_(self, name, _positive_int(name, getattr(self, name)))
        k = _finite_seq("k", self.k, 9)
        check(k[0] > 0 and k[4] > 0 and k[3] == 0 and k[6] == 0 and k[7] == 0 and k[8] == 1,
              "camera.k", f"expected [fx, s, cx, 0, fy, cy, 0, 0, 1] with fx, fy > 0, got {k}")
        set_(self, "k", k)
        d = _finite_seq("d", self.d)
        model = str(self.distortion_model)
        check(model in DISTORTION_MODELS, "camera.distortion_model",
              f"{model!r} is not supported (use one of {sorted(DISTORTION_MODELS)})")
        check(len(d) in DISTORTION_MODELS[model], "camera.d",
              f"{model} takes {DISTORTION_MODELS[model]} coefficients, got {len(d)}")
        set_(self, "d", d)
        set_(self, "position", _finite_seq("position", self.position, 3))
        q = _finite_seq("orientation", self.orientation, 4)
        n = math.sqrt(sum(v * v for v in q))
        check(abs(n - 1.0) <= 1e-3, "camera.orientation",
              f"quaternion (x, y, z, w) must have unit norm, got |q| = {n}")
        set_(self, "orientation", tuple(v / n for v in q))
        finite("camera.exposure_time", self.exposure_time)
        positive("camera.frame_rate", self.frame_rate)
        set_(self, "exposure_time", float(self.exposure_time))
        set_(self, "frame_rate", float(self.frame_rate))
        check(0.0 <= self.exposure_time <= 1.0 / self.frame_rate, "camera.exposure_time",
              f"must be in [0, 1/frame_rate = {1 / self.frame_rate} s], got {self.exposure_time}")
        check(self.camera_from_world(np.zeros((1, 3)))[0, 2] > 0, "camera.position/orientation",
              "the world origin (the frame's axis) is behind the camera")

    # -- derived arrays (read-only, cached) ------------------------------------------------
    @staticmethod
    def _ro(a: np.ndarray) -> np.ndarray:
        a.setflags(write=False)
        return a

    @cached_property
    def K(self) -> FloatArray:  # noqa: N802 (the matrix's usual name)
        """Camera matrix K, shape (3, 3) [px]."""
        return self._ro(np.array(self.k, dtype=float).reshape(3, 3))

    @cached_property
    def D(self) -> FloatArray:  # noqa: N802
        """Distortion coefficients, shape (n,) [-]."""
        return self._ro(np.array(self.d, dtype=float))

    @cached_property
    def has_distortion(self) -> bool:
        """True unless the camera is a plain pinhole (no non-zero coefficient).

        A fisheye (``equidistant``) lens is never one: with every coefficient zero it still
        maps the ray's angle theta to ``r_d = theta``, not ``tan theta``.
        """
        return self.distortion_model == "equidistant" or bool(np.any(self.D != 0.0))

    @property
    def fisheye(self) -> bool:
        """Whether the lens is the ``equidistant`` (fisheye) model (:mod:`cv2.fisheye`)."""
        return self.distortion_model == "equidistant"

    @cached_property
    def R_wc(self) -> FloatArray:  # noqa: N802
        """Orientation of the optical frame in the world: ``X_w = R_wc X_c + c``."""
        return self._ro(quaternion_to_matrix(self.orientation))

    @cached_property
    def R_cw(self) -> FloatArray:  # noqa: N802
        """World-to-camera rotation ``R_wc^T``."""
        return self._ro(self.R_wc.T.copy())

    @cached_property
    def c(self) -> FloatArray:
        """Optical centre in the world frame, shape (3,) [m]."""
        return self._ro(np.array(self.position, dtype=float))

    @cached_property
    def rvec(self) -> FloatArray:
        """OpenCV rotation vector (Rodrigues) of ``R_cw``."""
        return self._ro(cv2.Rodrigues(self.R_cw)[0].reshape(3))

    @cached_property
    def tvec(self) -> FloatArray:
        """OpenCV translation ``t = -R_cw c`` [m] (``X_c = R_cw X_w + t``)."""
        return self._ro(-self.R_cw @ self.c)

    @property
    def fx(self) -> float:
        """Focal length along x [px]."""
        return self.k[0]

    @property
    def fy(self) -> float:
        """Focal length along y [px]."""
        return self.k[4]

    @property
    def cx(self) -> float:
        """Principal point column [px]."""
        return self.k[2]

    @property
    def cy(self) -> float:
        """Principal point row [px]."""
        return self.k[5]

    def replace(self, **changes: Any) -> CameraModel:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    # -- world <-> camera ------------------------------------------------------------------
    def camera_from_world(self, points_w: ArrayLike) -> FloatArray:
        """``X_c = R_cw (X_w - c)``; points shape (..., 3) [m]."""
        p = np.asarray(points_w, dtype=float)
        return (p - self.c) @ self.R_wc  # row vectors: (R_cw v)^T = v^T R_wc

    def world_from_camera(self, points_c: ArrayLike) -> FloatArray:
        """``X_w = R_wc X_c + c``; points shape (..., 3) [m]."""
        return np.asarray(points_c, dtype=float) @ self.R_cw + self.c

    # -- projection ------------------------------------------------------------------------
    def distort_normalized(self, xy: ArrayLike) -> FloatArray:
        """Pixel coordinates of ideal normalised coordinates ``(x, y) = (X/Z, Y/Z)``.

        Applies the distortion polynomial and K (module docstring). Shape (..., 2) -> (..., 2).
        """
        xy = np.asarray(xy, dtype=float)
        shp = xy.shape
        pts = np.concatenate([xy.reshape(-1, 2), np.ones((xy.size // 2, 1))], axis=1)
        if pts.shape[0] == 0:
            return np.zeros(shp)
        if self.fisheye:  # OpenCV's skew: u = fx (x_d + alpha y_d) + cx, alpha = s / fx
            uv = cv2.fisheye.distortPoints(np.ascontiguousarray(pts[:, :2]).reshape(-1, 1, 2),
                                           self.K, self.D, alpha=self.k[1] / self.k[0])
            return uv.reshape(shp)
        uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K,
                                  self.D if self.has_distortion else None)
        return uv.reshape(shp)

    def project_camera(self, points_c: ArrayLike) -> FloatArray:
        """Pixel coordinates of points in the optical frame, (..., 3) -> (..., 2) [px].

        Points at or behind the optical centre (``Z_c <= 0``) give NaN.
        """
        p = np.asarray(points_c, dtype=float)
        shp = p.shape[:-1]
        p = p.reshape(-1, 3)
        out = np.full((p.shape[0], 2), np.nan)
        ok = p[:, 2] > 1e-12
        if np.any(ok):
            xy = p[ok, :2] / p[ok, 2:3]
            if self.has_distortion:
                out[ok] = self.distort_normalized(xy)
            else:
                k = self.k
                out[ok, 0] = k[0] * xy[:, 0] + k[1] * xy[:, 1] + k[2]
                out[ok, 1] = k[4] * xy[:, 1] + k[5]
        return out.reshape(*shp, 2)

    def project(self, points_w: ArrayLike) -> FloatArray:
        """Pixel coordinates of world points, (..., 3) -> (..., 2) [px] (NaN behind the camera).

        Equivalent to ``cv2.projectPoints(X_w, rvec, tvec, K, D)`` (its fisheye twin for an
        ``equidistant`` lens).
        """
        return self.project_camera(self.camera_from_world(points_w))

    def pixel_to_normalized(self, pixels: ArrayLike) -> FloatArray:
        """Undistorted normalised coordinates ``(X/Z, Y/Z)`` of pixels, (..., 2) -> (..., 2).

        Inverts the distortion iteratively (:func:`cv2.undistortPoints` with a tight
        termination criterion); exact when there is no distortion.
        """
        px = np.asarray(pixels, dtype=float)
        shp = px.shape
        flat = px.reshape(-1, 2)
        if not self.has_distortion:
            k = self.k
            y = (flat[:, 1] - k[5]) / k[4]
            x = (flat[:, 0] - k[2] - k[1] * y) / k[0]
            return np.stack([x, y], axis=1).reshape(shp)
        if flat.shape[0] == 0:
            return np.zeros(shp)
        if self.fisheye:
            # cv2.fisheye.undistortPoints ignores K's skew: the distorted normalised point by
            # hand (y_d first), then undistorted with the identity for K; a point it cannot
            # invert (no convergence, beyond the lens's field) comes back as -1e6: NaN
            k = self.k
            yd = (flat[:, 1] - k[5]) / k[4]
            xd = (flat[:, 0] - k[2] - k[1] * yd) / k[0]
            out = cv2.fisheye.undistortPoints(np.stack([xd, yd], axis=1).reshape(-1, 1, 2),
                                              np.eye(3), self.D, criteria=_UNDISTORT_CRITERIA)
            out = out.reshape(-1, 2)
            out[np.any(out <= -1e5, axis=1)] = np.nan
            return out.reshape(shp)
        out = cv2.undistortPoints(flat.reshape(-1, 1, 2), self.K, self.D,
                                  criteria=_UNDISTORT_CRITERIA)
        return out.reshape(shp)

    def pixel_to_ray(self, pixels: ArrayLike) -> FloatArray:
        """Unit viewing directions in the world frame of pixels, (..., 2) -> (..., 3).

        The ray of pixel ``(u, v)`` is ``c + lambda d``, ``lambda > 0``, with
        ``d = R_wc [x, y, 1]^T / |[x, y, 1]|`` and ``(x, y)`` the undistorted normalised
        coordinates.
        """
        xy = self.pixel_to_normalized(pixels)
        m = np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], axis=-1)
        m /= np.linalg.norm(m, axis=-1, keepdims=True)
        return m @ self.R_cw

    def pixel_to_plane(self, pixels: ArrayLike, z: float = 0.0) -> FloatArray:
        """World points where the viewing rays of pixels meet the plane ``z_w = z``.

        Parameters
        ----------
        pixels : array_like, shape (..., 2)
            Pixel coordinates (u, v) [px], distorted (as they appear in the image).
        z : float
            Height of the plane along the world z axis [m]; 0 is the frame's plane, where the
            ball centre lies.

        Returns
        -------
        ndarray, shape (..., 3)
            ``X_w = c + lambda d`` with ``lambda = (z - c_z) / d_z`` [m]; NaN where the ray is
            parallel to the plane or meets it behind the camera.
        """
        d = self.pixel_to_ray(pixels)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (z - self.c[2]) / d[..., 2]
        lam = np.where(np.isfinite(lam) & (lam > 0), lam, np.nan)
        return self.c + lam[..., None] * d

    def pixels_per_metre(self, point_w: ArrayLike = (0.0, 0.0, 0.0)) -> float:
        """Approximate image scale [px/m] for lengths in the plane facing the camera at a point.

        ``sqrt(fx fy) / Z_c`` at the point's depth (distortion ignored); used for priors such as
        the ball's expected radius in pixels and for reporting errors in millimetres.
        """
        zc = float(self.camera_from_world(np.asarray(point_w, dtype=float).reshape(3))[2])
        if zc <= 0:
            raise CameraModelError("pixels_per_metre: the point is behind the camera")
        return math.sqrt(self.fx * self.fy) / zc

    # -- CameraInfo ------------------------------------------------------------------------
    def to_camera_info(self) -> dict[str, Any]:
        """A ``sensor_msgs/CameraInfo``-shaped dict (no header): the node fills the message.

        ``r`` is the identity (monocular camera) and ``p = [K | 0]``.
        """
        k = self.k
        return {
            "width": self.width,
            "height": self.height,
            "distortion_model": self.distortion_model,
            "d": list(self.d),
            "k": list(k),
            "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "p": [k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0],
            "binning_x": 0,
            "binning_y": 0,
            "frame_id": self.frame_id,
        }

    @classmethod
    def from_camera_info(cls, info: Any, **pose_and_timing: Any) -> CameraModel:
        """Build a model from a CameraInfo message or a mapping with its fields.

        Parameters
        ----------
        info : Mapping or object
            Has ``width``, ``height``, ``k``, ``d``, ``distortion_model`` (keys or attributes;
            upper-case ``K``/``D`` of ROS 1 are accepted too), and may have ``binning_x/y``
            and ``roi``. A camera that bins or crops (REP 104) keeps the calibration of the
            full sensor in ``k`` and ``d`` and sends images of the region ``roi`` (all zero:
            the full sensor), ``binning`` times smaller (0 and 1: none). The model is that of
            the images, as ``image_geometry`` builds it: ``fx' = fx / b_x``, ``cx' = (cx -
            x_offset) / b_x``, size ``roi.width // b_x``; the distortion, in normalised
            coordinates, is unchanged. Two choices of ours: the skew is divided by ``b_x``
            too (``image_geometry`` leaves it, which is wrong unless it is zero), and, like
            ``image_geometry``, a binned pixel's centre is taken at ``b`` times its index
            (an averaging sensor's is ``(b - 1) / 2`` further: 0.25 px at 2x2).
        **pose_and_timing
            ``position``, ``orientation``, ``exposure_time``, ``frame_rate``, ``frame_id``: what
            CameraInfo does not carry (defaults: those of :class:`CameraModel`).
        """
        def get(name: str, default: Any = None) -> Any:
            for key in (name, name.upper()):
                if isinstance(info, Mapping) and key in info:
                    return info[key]
                if not isinstance(info, Mapping) and hasattr(info, key):
                    return getattr(info, key)
            return default

        def field(obj: Any, name: str) -> int:
            v = obj.get(name, 0) if isinstance(obj, Mapping) else getattr(obj, name, 0)
            return int(v or 0)

        bx, by = (max(1, int(get(b, 0) or 0)) for b in ("binning_x", "binning_y"))
        width, height = int(get("width") or 0), int(get("height") or 0)
        roi = get("roi")
        x0, y0, rw, rh = ((field(roi, "x_offset"), field(roi, "y_offset"),
                           field(roi, "width"), field(roi, "height"))
                          if roi is not None else (0, 0, 0, 0))
        if rw == 0 and rh == 0 and x0 == 0 and y0 == 0:
            rw, rh = width, height
        if rw <= 0 or rh <= 0:
            raise CameraModelError(f"CameraInfo roi is empty ({rw}x{rh} at x {x0}, y {y0}; "
                                   f"calibrated size {width}x{height})")
        if x0 < 0 or y0 < 0 or (width and height and (x0 + rw > width or y0 + rh > height)):
            raise CameraModelError(f"CameraInfo roi (x {x0}, y {y0}, {rw}x{rh}) is not within "
                                   f"the calibrated {width}x{height} sensor")
        k = [float(v) for v in get("k", ())]
        if len(k) == 9 and (bx, by, x0, y0) != (1, 1, 0, 0):
            k[0], k[1], k[2] = k[0] / bx, k[1] / bx, (k[2] - x0) / bx
            k[4], k[5] = k[4] / by, (k[5] - y0) / by
            width, height = rw // bx, rh // by
        elif len(k) == 9:
            width, height = rw, rh
        d = get("d", ())
        model = get("distortion_model", "") or "plumb_bob"
        if not len(d) and model == "plumb_bob":
            d = (0.0, 0.0, 0.0, 0.0, 0.0)
        kwargs: dict[str, Any] = {
            "width": width,
            "height": height,
            "k": tuple(k),
            "d": tuple(d),
            "distortion_model": model,
        }
        header = get("header")
        if header is not None and getattr(header, "frame_id", ""):
            kwargs["frame_id"] = header.frame_id
        kwargs.update(pose_and_timing)
        return cls(**kwargs)


# --------------------------------------------------------------------------------------------
# Parameter files
# --------------------------------------------------------------------------------------------
def default_camera_path() -> Path:
    """Path of the shipped ``camera.yaml`` (bfr_camera's ``config/``)."""
    return config_path("bfr_camera", "camera.yaml")


def read_ros_parameters(path: str | Path | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` mapping of a ROS 2 parameter file (default: camera.yaml)."""
    p = Path(path) if path is not None else default_camera_path()
    return load_ros_parameters(p, CameraModelError)


def camera_from_dict(d: Mapping[str, Any]) -> CameraModel:
    """Build a :class:`CameraModel` from the ``camera`` parameter group (unknown keys fail)."""
    names = {f.name for f in dataclasses.fields(CameraModel)}
    unknown = set(d) - names
    if unknown:
        raise CameraModelError(f"camera: unknown entries {sorted(unknown)} "
                               f"(known: {sorted(names)})")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()}
    try:
        return CameraModel(**kwargs)
    except TypeError as exc:
        raise CameraModelError(f"camera: {exc}") from exc


def camera_to_dict(camera: CameraModel) -> dict[str, Any]:
    """The ``camera`` parameter group of a model (tuples as lists)."""
    return {f.name: (list(v) if isinstance(v := getattr(camera, f.name), tuple) else v)
            for f in dataclasses.fields(camera)}


def camera_to_ros_yaml(camera: CameraModel) -> str:
    """Serialise a model as a ROS 2 parameter file loadable by :func:`load_camera`."""
    return yaml.safe_dump({"/**": {"ros__parameters": {"camera": camera_to_dict(camera)}}},
                          sort_keys=False)


def load_camera(path: str | Path | None = None) -> CameraModel:
    """Load the camera model from the ``camera`` group of a parameter file.

    Parameters
    ----------
    path : str or Path, optional
        ROS 2 parameter file; default the shipped ``config/camera.yaml``.

    Raises
    ------
    CameraModelError
        If the file is missing, malformed, or a value is invalid.
    """
    params = read_ros_parameters(path)
    group = params.get("camera")
    if not isinstance(group, Mapping):
        raise CameraModelError(f"{path or default_camera_path()}: no 'camera' parameter group")
    try:
        return camera_from_dict(group)
    except CameraModelError as exc:
        raise CameraModelError(f"{path or default_camera_path()}: {exc}") from exc


def load_ros_calibration_yaml(path: str | Path, **pose_and_timing: Any) -> CameraModel:
    """Load a ``camera_calibration_parsers`` YAML file (what ``camera_calibration`` saves).

    The file has ``image_width``, ``image_height``, ``camera_matrix: {rows, cols, data}``,
    ``distortion_model`` and ``distortion_coefficients: {data}``; the pose and timing, which a
    calibration file does not carry, are keyword arguments as in
    :meth:`CameraModel.from_camera_info`.
    """
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise CameraModelError(f"cannot read calibration {p}: {exc}") from exc
    try:
        info = {
            "width": doc["image_width"],
            "height": doc["image_height"],
            "k": doc["camera_matrix"]["data"],
            "d": doc.get("distortion_coefficients", {}).get("data", []),
            "distortion_model": doc.get("distortion_model", "plumb_bob"),
        }
    except (KeyError, TypeError) as exc:
        raise CameraModelError(f"{p}: not a camera calibration file (missing {exc})") from exc
    return CameraModel.from_camera_info(info, **pose_and_timing)

