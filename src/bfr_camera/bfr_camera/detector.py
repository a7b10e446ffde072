"""Ball detection in camera frames: sub-pixel ball centre, its world position and phi.

Pure numpy/OpenCV (no ``rclpy``). The camera node converts ``sensor_msgs/Image`` to an array,
calls :meth:`BallDetector.detect` and fills ``bfr_interfaces/BallObservation`` from the
returned :class:`Detection`.

Method
------
1. **Search region.** With a last fix (or a caller's hint), the ball is first refined
   straight from there (steps 3-6: the ball moves a few pixels between frames; its edges are
   searched 0.5 to 1.5 radii from the fix); failing that, candidates are searched in a square
   region of interest (ROI) of half-size ``roi_radius_factor * r_px + roi_margin`` around it;
   failing that, or without a fix, in the whole frame (the ball was lost).
2. **Candidates.** The region is reduced by an integer factor ``s`` (about 5 px of ball radius
   remain) and correlated with a disc template of the expected radius (zero-mean normalised
   cross-correlation, :func:`cv2.matchTemplate` ``TM_CCOEFF_NORMED``: insensitive to
   brightness and contrast). Local maxima above ``candidate_threshold`` are candidates.
3. **Sub-pixel edges.** From the candidate centre, ``n_rays`` rays sample the image (bilinear
   interpolation, 0.5 px steps). On each ray the strongest falling edge (ball -> outside)
   is located, the levels ``I_in``, ``I_out`` are averaged 1.5-3.5 px inside and outside it,
   and the edge point is where the profile crosses ``(I_in + I_out) / 2`` (linear
   interpolation between samples): the half-level contour, unbiased under symmetric blur.
   Rays are kept if their contrast ``I_in - I_out`` exceeds ``min_contrast`` and
   ``min_cnr`` noise standard deviations, and if their outside level is the common one (the
   largest cluster of ``I_out``): an edge against the frame's plate, an occluder or the
   ball's own shadowed side is dropped there.
4. **Cone fit.** The silhouette of a sphere is the cone of viewing rays tangent to it: every
   edge ray ``v_i`` (undistorted, unit) makes the same angle ``beta`` with the direction
   ``c`` of the sphere centre, ``v_i . c = cos(beta)``. With ``w = c / cos(beta)`` this is the
   linear least-squares problem

       minimise  sum_i  rho_i (v_i . w - 1)^2 ,

   whose residual ``v_i . w - 1 ~ tan(beta) (beta - gamma_i)`` is, to first order, the
   angular distance of the edge ray from the cone (a geometric, not merely algebraic, fit).
   Tukey biweights ``rho_i`` (iteratively re-weighted, scale from the median absolute
   residual) drop the remaining outliers. Then ``c = w / |w|``, ``cos(beta) = 1 / |w|``.
   Unlike a circle fit in the image this is exact under perspective, where the ball's image
   is an ellipse whose centre is not the image of the ball centre (0.2 px apart at the
   frame's tips with the default camera), and it is exact under lens distortion (the edge
   points are undistorted first). The fit is repeated once on rays cast from the fitted
   centre with a narrow window around the fitted radius.
5. **World position.** The ball centre lies in the plane ``z = ball_plane_z`` (the frame's
   plane): ``X = o + lambda R_wc c`` with ``lambda = (z_b - o_z) / (R_wc c)_z``, ``o`` the
   optical centre; the fitted ball radius is ``lambda sin(beta)``. The pixel position is the
   projection of ``X``. Then ``phi = theta + atan2(x, y)`` (the rig's convention).
6. **Verification and confidence.** A candidate is a ball only if at least
   ``min_inlier_fraction`` of the rays agree, they span an arc of ``min_arc`` or more (the
   fit is well conditioned), their RMS distance to the cone is at most ``max_rms_px`` and the
   fitted radius is within ``radius_tolerance`` of the calibrated ``R_b``. The confidence
   in [0, 1] is the product of the inlier fraction, arc, fit, radius and contrast-to-noise
   terms (each 1 when comfortably good). Two verified candidates of similar confidence make
   the result AMBIGUOUS.

Partial occlusion (the frame's front plate hides about a third of the ball's outline, or a
foreign object hides more) costs rays, not accuracy: hidden rays fail the outside-level and
cone tests and the fit uses the visible arc.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from bfr_model.jit import njit
from bfr_model.param_file import finite, integer, nonnegative, one_of, positive
from numpy.typing import ArrayLike, NDArray

from bfr_camera.calibration import CameraModel, CameraModelError, read_ros_parameters

__all__ = [
    "BallDetector",
    "Detection",
    "DetectionStatus",
    "DetectorConfig",
    "detector_config_from_dict",
    "load_detector_config",
]

F32 = NDArray[np.float32]

_GRID = 32  # [px] spacing of the expected-radius table
_N_TRIPLES = 48  # RANSAC hypotheses of the coarse circle
_HALF = 12  # samples (0.5 px steps) either side of a ray's steepest point: longest half-ramp
_WIN_OFF = np.arange(-_HALF, _HALF + 1)
_SEG_OFF = np.arange(-3, 4)  # samples around the ramp's middle searched for the crossing
_SEG_DIST = np.abs(np.arange(6) - 2.5)[None, :]
_LEVEL_OFF = np.arange(5)  # a level window: 5 samples = 2 px


class DetectionStatus(IntEnum):
    """Outcome of a detection (same values as ``bfr_interfaces/BallObservation``)."""

    FOUND = 0
    NOT_FOUND = 1
    AMBIGUOUS = 2
    INVALID_INPUT = 3


@dataclass(frozen=True)
class Detection:
    """Result of :meth:`BallDetector.detect`.

    Attributes
    ----------
    status : DetectionStatus
        FOUND, NOT_FOUND, AMBIGUOUS or INVALID_INPUT.
    reason : str
        Human-readable explanation (why not found, what was ambiguous or invalid).
    confidence : float
        Detection confidence in [0, 1] (0 unless a ball was verified).
    u, v : float
        Sub-pixel image position of the ball centre [px] (NaN unless FOUND).
    radius_px : float
        Apparent ball radius [px].
    x, y : float
        Ball centre in the world frame [m], in the frame's plane.
    radius_m : float
        Fitted ball radius [m] (a check of the calibration: close to R_b).
    phi : float
        ``theta + atan2(x, y)`` [rad].
    theta_used : float
        The theta given to the detector [rad].
    rms_px : float
        RMS distance of the edge points to the fitted silhouette [px].
    n_edges : int
        Edge points used by the fit.
    search : str
        ``"roi"``, ``"full"`` or ``"none"``: where the ball was found (or last searched).
    roi : tuple of 4 int or None
        Last searched region ``(x0, y0, x1, y1)`` [px], end-exclusive.
    candidates : tuple of (u, v)
        Verified candidate positions [px] (two or more when AMBIGUOUS).
    processing_time : float
        Wall time of the call [s].
    """

    status: DetectionStatus
    reason: str
    confidence: float = 0.0
    u: float = math.nan
    v: float = math.nan
    radius_px: float = math.nan
    x: float = math.nan
    y: float = math.nan
    radius_m: float = math.nan
    phi: float = math.nan
    theta_used: float = math.nan
    rms_px: float = math.nan
    n_edges: int = 0
    search: str = "none"
    roi: tuple[int, int, int, int] | None = None
    candidates: tuple[tuple[float, float], ...] = ()
    processing_time: float = 0.0

    @property
    def valid(self) -> bool:
        """True iff a single ball was found and the position fields may be used."""
        return self.status == DetectionStatus.FOUND

    @property
    def pixel(self) -> NDArray[np.float64]:
        """``[u, v]`` [px]."""
        return np.array([self.u, self.v])

    @property
    def world(self) -> NDArray[np.float64]:
        """``[x, y]`` [m]."""
        return np.array([self.x, self.y])

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (status as its name), e.g. for JSON."""
        d = dataclasses.asdict(self)
        d["status"] = self.status.name
        d["valid"] = self.valid
        return d


@dataclass(frozen=True)
class DetectorConfig:
    """Detector parameters (the ``detector`` group of ``config/camera.yaml``).

    Attributes
    ----------
    polarity : str
        ``"bright"``: the ball is brighter than what surrounds it; ``"dark"``: darker.
    use_roi : bool
        Search a region of interest around the last fix first.
    roi_radius_factor : float
        ROI half-size in expected ball radii [-].
    roi_margin : float
        Added to the ROI half-size [px].
    n_rays : int
        Rays cast for sub-pixel edges [-].
    candidate_threshold : float
        Minimum normalised cross-correlation of a candidate [-].
    max_candidates : int
        Candidates verified per search at most [-].
    ambiguity_score : float
        Other candidates are verified (for ambiguity) if their correlation is at least this
        fraction of the best one's [-].
    ambiguity_ratio : float
        A second verified candidate with at least this fraction of the best confidence
        makes the result AMBIGUOUS [-].
    min_contrast : float
        Minimum edge contrast ``I_in - I_out`` [DN, 8-bit scale].
    min_cnr : float
        Minimum edge contrast in noise standard deviations [-].
    min_inlier_fraction : float
        Minimum fraction of rays on the fitted silhouette [-].
    min_arc : float
        Minimum angular span of those rays around the centre [rad].
    max_rms_px : float
        Maximum RMS distance of the edge points to the silhouette [px].
    radius_tolerance : float
        Maximum relative deviation of the fitted ball radius from R_b [-].
    radius_prior_sigma : float
        Relative standard deviation of the soft prior tying the fitted radius to R_b [-].
    min_confidence : float
        Minimum confidence of a FOUND result [-].
    ball_plane_z : float
        World z of the plane the ball centre moves in [m] (0: the frame's plane).
    track_gate : float
        Track gate [m]: when the detector knows the track (:meth:`BallDetector.set_track`)
        and the frame angle, a ball-like object whose centre lies further than this from
        the ball's track (radially) is not the ball (a hole, the hub, a bolt head of the
        frame); 0 turns the gate off.
    """

    polarity: str = "bright"
    use_roi: bool = True
    roi_radius_factor: float = 2.5
    roi_margin: float = 10.0
    n_rays: int = 64
    candidate_threshold: float = 0.5
    max_candidates: int = 3
    ambiguity_score: float = 0.6
    ambiguity_ratio: float = 0.5
    min_contrast: float = 8.0
    min_cnr: float = 5.0
    min_inlier_fraction: float = 0.3
    min_arc: float = 2.1
    max_rms_px: float = 0.5
    radius_tolerance: float = 0.10
    radius_prior_sigma: float = 0.05
    min_confidence: float = 0.2
    ball_plane_z: float = 0.0
    track_gate: float = 0.02

    def __post_init__(self) -> None:
        one_of("detector.polarity", self.polarity, ("bright", "dark"))
        for name in ("roi_radius_factor", "candidate_threshold", "min_cnr", "max_rms_px",
                     "radius_tolerance", "radius_prior_sigma", "min_arc"):
            positive(f"detector.{name}", getattr(self, name))
        for name in ("roi_margin", "min_contrast", "min_confidence", "min_inlier_fraction",
                     "ambiguity_score", "ambiguity_ratio"):
            nonnegative(f"detector.{name}", getattr(self, name))
        integer("detector.n_rays", self.n_rays, minimum=16)
        integer("detector.max_candidates", self.max_candidates, minimum=1)
        finite("detector.ball_plane_z", self.ball_plane_z)
        nonnegative("detector.track_gate", self.track_gate)
        # counts are used as such (array sizes): 64.0 passes the check and becomes 64
        object.__setattr__(self, "n_rays", int(self.n_rays))
        object.__setattr__(self, "max_candidates", int(self.max_candidates))


def detector_config_from_dict(d: Mapping[str, Any]) -> DetectorConfig:
    """Build a :class:`DetectorConfig` from the ``detector`` parameter group."""
    names = {f.name for f in dataclasses.fields(DetectorConfig)}
    unknown = set(d) - names
    if unknown:
        raise ValueError(f"detector: unknown entries {sorted(unknown)}")
    return DetectorConfig(**dict(d))


def load_detector_config(path: str | Path | None = None) -> DetectorConfig:
    """Load the ``detector`` group of a parameter file (default: the shipped camera.yaml)."""
    params = read_ros_parameters(path)
    group = params.get("detector", {})
    if not isinstance(group, Mapping):
        raise CameraModelError("parameter group 'detector' must be a mapping")
    return detector_config_from_dict(group)


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------
@dataclass
class _Fit:
    """One verified or rejected candidate."""

    ok: bool
    reason: str
    confidence: float = 0.0
    u: float = math.nan
    v: float = math.nan
    radius_px: float = math.nan
    world: NDArray[np.float64] | None = None
    radius_m: float = math.nan
    rms_px: float = math.nan
    n_edges: int = 0
    box: tuple[int, int, int, int] = (0, 0, 0, 0)


def _sample(img: F32, xs: F32, ys: F32) -> F32:
    """Bilinear samples of ``img`` at (xs, ys) (float32 maps); NaN outside the image.

    :func:`cv2.remap` interpolates with weights quantised to 1/32 px: an edge moves by at
    most 1/64 px per sample, at random across rays.
    """
    return cv2.remap(img, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=np.nan)


def _median(x: np.ndarray) -> float:
    """Median (lower middle for even sizes) by partial sort: cheaper than np.median."""
    k = (x.size - 1) // 2
    return float(np.partition(x.reshape(-1), k)[k])


@njit
def _edge_kernel(prof, pad, half, start, cu, cv, cos, sin):  # noqa: ANN001, ANN202
    """Compiled core of :meth:`BallDetector._edges` on the sampled profiles ``prof`` (n, m).

    The same arithmetic as the array form it replaces, in loops over rays and samples, in
    the same precision (float32 profiles, float64 positions): the steepest falling sample
    (the first NaN, as ``np.argmax``, when the ray leaves the image), the ramp's extent
    ``nl``, ``nr`` (samples either side with ``g >= g_max / 2``), the level windows, the
    crossing of the mid level nearest the ramp's middle and its linear interpolation.
    Returns the edge points (n, 2), contrasts, outside levels, whether a crossing was
    found, and the ramp extents.
    """
    n, m = prof.shape
    f32 = np.float32
    pts = np.empty((n, 2))
    contrast = np.empty(n, dtype=np.float32)
    outer_l = np.empty(n, dtype=np.float32)
    has = np.zeros(n, dtype=np.bool_)
    nls = np.zeros(n, dtype=np.int64)
    nrs = np.zeros(n, dtype=np.int64)
    for r in range(n):
        # steepest point: argmax of g[i] = prof[i] - prof[i + 2] over i in [pad-1, m-pad-1)
        j = -1
        gmax = f32(0.0)
        for i in range(pad - 1, m - pad - 1):
            gi = prof[r, i] - prof[r, i + 2]
            if gi != gi:  # NaN: np.argmax returns the first one
                j = i
                break
            if j < 0 or gi > gmax:
                j = i
                gmax = gi
        j += 1  # sample index of the steepest point
        g0 = prof[r, j - 1] - prof[r, j + 1]
        h = f32(0.5) * g0
        nl = 0
        for q in range(1, half + 1):
            gq = prof[r, j - 1 - q] - prof[r, j + 1 - q]
            if not gq >= h:
                break
            nl += 1
        nr = 0
        for q in range(1, half + 1):
            gq = prof[r, j - 1 + q] - prof[r, j + 1 + q]
            if not gq >= h:
                break
            nr += 1
        inner = f32(0.0)
        outer = f32(0.0)
        for q in range(5):
            inner += prof[r, j - nl - 2 - q]
            outer += prof[r, j + nr + 2 + q]
        inner = inner * f32(0.2)
        outer = outer * f32(0.2)
        mid = f32(0.5) * (inner + outer)
        jc = j + (nr - nl) // 2
        best = -1
        best_d = np.inf
        for k in range(6):
            if prof[r, jc - 3 + k] >= mid and not prof[r, jc - 2 + k] >= mid:
                d = abs(k - 2.5)
                if d < best_d:
                    best_d = d
                    best = k
        kk = best if best >= 0 else 0
        a = prof[r, jc - 3 + kk]
        den = a - prof[r, jc - 2 + kk] if best >= 0 else f32(1.0)
        frac = (a - mid) / den
        se = np.float64(f32(start)) + 0.5 * (np.float64(jc + kk - 3) + np.float64(frac))
        pts[r, 0] = cu + np.float64(cos[r]) * se
        pts[r, 1] = cv + np.float64(sin[r]) * se
        contrast[r] = inner - outer
        outer_l[r] = outer
        has[r] = best >= 0
        nls[r] = nl
        nrs[r] = nr
    return pts, contrast, outer_l, has, nls, nrs



@njit
def _ransac_circle(x, t, r_lo, r_hi):  # noqa: ANN001, ANN202
    """Inliers (within 1 px) of the best circumcircle of the triples ``t`` (see below).

    Compiled (numba) form of the RANSAC step of :func:`_circle_fit`, the same arithmetic in
    loops: for each triple the circumcircle of its points (skipped when the points are
    collinear or its radius is outside ``(r_lo, r_hi)``), the number of points within 1 px
    of it; the first circle with the most wins. Returns the inlier mask of the winner and
    whether there was any circle at all.
    """
    n = x.shape[0]
    best_count = -1
    best_ux = 0.0
    best_uy = 0.0
    best_rr = 0.0
    for i in range(t.shape[0]):
        a0 = x[t[i, 0], 0]
        a1 = x[t[i, 0], 1]
        b0 = x[t[i, 1], 0]
        b1 = x[t[i, 1], 1]
        c0 = x[t[i, 2], 0]
        c1 = x[t[i, 2], 1]
        aa = -x[t[i, 0], 3]
        bb = -x[t[i, 1], 3]
        cc = -x[t[i, 2], 3]
        d = 2.0 * (a0 * (b1 - c1) + b0 * (c1 - a1) + c0 * (a1 - b1))
        if d == 0.0:
            continue
        ux = (aa * (b1 - c1) + bb * (c1 - a1) + cc * (a1 - b1)) / d
        uy = (aa * (c0 - b0) + bb * (a0 - c0) + cc * (b0 - a0)) / d
        rr = np.hypot(a0 - ux, a1 - uy)
        if not (np.isfinite(rr) and rr > r_lo and rr < r_hi):
            continue
        count = 0
        for k in range(n):
            if abs(np.hypot(x[k, 0] - ux, x[k, 1] - uy) - rr) <= 1.0:
                count += 1
        if count > best_count:
            best_count = count
            best_ux = ux
            best_uy = uy
            best_rr = rr
    mask = np.zeros(n, dtype=np.bool_)
    if best_count < 0:
        return mask, False
    for k in range(n):
        mask[k] = abs(np.hypot(x[k, 0] - best_ux, x[k, 1] - best_uy) - best_rr) <= 1.0
    return mask, True


@njit
def _lower_median(x):  # noqa: ANN001, ANN202
    """Compiled :func:`_median`: the lower middle of a 1-D array (by a sort)."""
    s = np.sort(x)
    return s[(s.size - 1) // 2]


@njit
def _solve3_k(g):  # noqa: ANN001, ANN202
    """Compiled :func:`_solve3` of ``g[:, :3] w = g[:, 3]``: ``(ok, w_x, w_y, w_z)``."""
    a0, a1, a2 = g[0, 0], g[0, 1], g[0, 2]
    b0, b1, b2 = g[1, 0], g[1, 1], g[1, 2]
    c0, c1, c2 = g[2, 0], g[2, 1], g[2, 2]
    r0, r1, r2 = g[0, 3], g[1, 3], g[2, 3]
    det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    if not np.isfinite(det) or abs(det) < 1e-300:
        return False, 0.0, 0.0, 0.0
    x = (r0 * (b1 * c2 - b2 * c1) - a1 * (r1 * c2 - b2 * r2) + a2 * (r1 * c1 - b1 * r2)) / det
    y = (a0 * (r1 * c2 - b2 * r2) - r0 * (b0 * c2 - b2 * c0) + a2 * (b0 * r2 - r1 * c0)) / det
    z = (a0 * (b1 * r2 - r1 * c1) - a1 * (b0 * r2 - r1 * c0) + r0 * (b0 * c1 - b1 * c0)) / det
    return True, x, y, z


@njit
def _circle_kernel(pts, r_lo, r_hi, t):  # noqa: ANN001, ANN202
    """Compiled body of :func:`_circle_fit`: ``(ok, u_c, v_c, r)`` [px].

    The same steps as its docstring says, in loops: centred points, the RANSAC winner's
    1 px inliers (:func:`_ransac_circle`), the algebraic fit on them (normal equations of
    ``x^2 + y^2 + D x + E y + F = 0``, Cramer's rule), once more on its own 1 px inliers.
    """
    n = pts.shape[0]
    m0 = 0.0
    m1 = 0.0
    for k in range(n):
        m0 += pts[k, 0]
        m1 += pts[k, 1]
    m0 *= 1.0 / n
    m1 *= 1.0 / n
    x = np.empty((n, 4))
    for k in range(n):
        x[k, 0] = pts[k, 0] - m0
        x[k, 1] = pts[k, 1] - m1
        x[k, 2] = 1.0
        x[k, 3] = -(x[k, 0] ** 2 + x[k, 1] ** 2)
    keep, found = _ransac_circle(x, t, r_lo, r_hi)
    if not found:
        return False, 0.0, 0.0, 0.0
    cx = cy = r = 0.0
    for it in range(2):
        g = np.zeros((3, 4))
        count = 0
        for k in range(n):
            if keep[k]:
                count += 1
                for a in range(3):
                    for b in range(4):
                        g[a, b] += x[k, a] * x[k, b]
        if count < 5:
            return False, 0.0, 0.0, 0.0
        ok, d, e, f = _solve3_k(g)
        if not ok:
            return False, 0.0, 0.0, 0.0
        cx, cy = -0.5 * d, -0.5 * e
        r2 = cx * cx + cy * cy - f
        if not r2 > 0:
            return False, 0.0, 0.0, 0.0
        r = math.sqrt(r2)
        if it == 0:
            for k in range(n):
                keep[k] = abs(np.hypot(x[k, 0] - cx, x[k, 1] - cy) - r) <= 1.0
    return True, cx + m0, cy + m1, r


def _circle_fit(pts: np.ndarray, r_lo: float, r_hi: float,
                triples: np.ndarray) -> tuple[float, float, float] | None:
    """Coarse image-plane circle through edge points, robust to many foreign points.

    A third or more of the points may lie on something else (an occluder's straight edge,
    the frame's plate).

    RANSAC over the given index triples (circumcircles, kept if their radius is within
    ``[r_lo, r_hi]``): the circle with the most points within 1 px wins; then the algebraic
    fit ``min sum (x^2 + y^2 + D x + E y + F)^2`` on those points (centre ``(-D/2, -E/2)``,
    radius ``sqrt(D^2/4 + E^2/4 - F)``), repeated once on its own 1 px inliers. Coordinates
    are centred on the points' mean first (conditioning). Compiled: :func:`_circle_kernel`.
    """
    ok, uc, vc, r = _circle_kernel(np.ascontiguousarray(pts, dtype=float), float(r_lo),
                                   float(r_hi), triples)
    return (float(uc), float(vc), float(r)) if ok else None


@njit
def _cone_kernel(v, wts, iters, focal, rz0, rz1, rz2, cz, zb, rb,  # noqa: ANN001, ANN202
                 prior_sigma):  # noqa: ANN001
    """Compiled iterations of :meth:`BallDetector._cone_fit` (its docstring has the method).

    ``v`` (n, 4) holds the unit edge rays and a column of ones; ``wts`` the initial weights;
    ``rz*`` the third row of ``R_wc``; ``cz`` the optical centre's height, ``zb`` the ball
    plane's, ``rb`` the ball radius [m]. Per round: the weighted normal equations
    ``sum rho_i v_i v_i^T w = sum rho_i v_i`` (plus the radius prior's row from the second
    round on), Cramer's rule, residuals in pixels ``(v_i . w - 1) f / tan(beta)``, the robust
    scale from the median absolute residual (first two rounds), Tukey biweights. Returns
    ``(ok, w, residuals, weights)``.
    """
    n = v.shape[0]
    wts = wts.copy()
    res = np.zeros(n)
    w = np.zeros(3)
    scale = 1.0
    sig = 1.0
    has_prior = False
    h = np.zeros(3)
    wexp = rho = 0.0
    for it in range(iters):
        g = np.zeros((3, 4))
        for i in range(n):
            wi = wts[i]
            for a in range(3):
                va = v[i, a] * wi
                for b in range(4):
                    g[a, b] += va * v[i, b]
        if has_prior:  # rho h h^T and rho W h, h the unit axis of the last round
            for a in range(3):
                for b in range(3):
                    g[a, b] += rho * h[a] * h[b]
                g[a, 3] += rho * wexp * h[a]
        ok, wx, wy, wz = _solve3_k(g)
        if not ok:
            return False, w, res, wts
        nw2 = wx * wx + wy * wy + wz * wz
        if nw2 <= 1.0:
            return False, w, res, wts
        w[0] = wx
        w[1] = wy
        w[2] = wz
        f = focal / math.sqrt(nw2 - 1.0)  # focal / tan(beta)
        for i in range(n):
            res[i] = (v[i, 0] * wx + v[i, 1] * wy + v[i, 2] * wz - 1.0) * f
        if it < 2:  # robust scale from the median absolute residual
            a_res = np.empty(n)
            m = 0
            for i in range(n):
                if wts[i] > 0:
                    a_res[m] = abs(res[i])
                    m += 1
            sig = max(1.4826 * _lower_median(a_res[:m]), 0.08) if m else 0.08
            scale = 4.685 * sig
        nz = 0
        for i in range(n):
            u = max(1.0 - (res[i] * (1.0 / scale)) ** 2, 0.0)
            wts[i] = u * u
            if wts[i] != 0.0:
                nz += 1
        if it == iters - 1:
            break
        if nz < 3:
            return False, w, res, wts
        # radius prior for the next round, linearised at this solution
        nw = math.sqrt(nw2)
        ux, uy, uz = wx / nw, wy / nw, wz / nw
        dz = rz0 * ux + rz1 * uy + rz2 * uz
        lam = (zb - cz) / dz if abs(dz) > 1e-12 else -1.0
        if lam > rb:
            h[0], h[1], h[2] = ux, uy, uz
            sb = rb / lam
            sig_r = max(prior_sigma * focal * sb, 1e-3)
            # data rows: residual ~ tan(beta) e_px / f; prior row: ~ tan(beta) dr_px / f
            has_prior = True
            wexp = 1.0 / math.sqrt(1.0 - sb * sb)
            rho = (sig / sig_r) ** 2
    return True, w, res, wts


def _disc_template(radius: float) -> F32:
    """A bright anti-aliased disc of ``radius`` [px] on a dark square of side ~3.4 radius."""
    h = math.ceil(1.7 * radius)
    yy, xx = np.mgrid[-h:h + 1, -h:h + 1].astype(np.float32)
    return np.clip(radius + 0.5 - np.sqrt(xx * xx + yy * yy), 0.0, 1.0).astype(np.float32)


# --------------------------------------------------------------------------------------------
# Detector
# --------------------------------------------------------------------------------------------
class BallDetector:
    """Finds the ball in camera frames; keeps the last fix for a region of interest.

    Parameters
    ----------
    camera : CameraModel
        Calibration (intrinsics, distortion, pose).
    ball_radius : float
        R_b [m], from the rig parameters (``ball.radius`` in rig.yaml).
    config : DetectorConfig, optional
        Detector parameters; default :class:`DetectorConfig`.
    """

    def __init__(self, camera: CameraModel, ball_radius: float,
                 config: DetectorConfig | None = None) -> None:
        positive("ball.radius", ball_radius)
        self.camera = camera
        self.ball_radius = float(ball_radius)
        self.config = config if config is not None else DetectorConfig()
        cfg = self.config
        self._z = cfg.ball_plane_z
        centre = camera.pixel_to_plane(np.array([camera.cx, camera.cy]), self._z)
        if not np.all(np.isfinite(centre)):
            raise CameraModelError("the camera's optical axis does not meet the ball's plane")
        self._r_px = self.ball_radius * camera.pixels_per_metre(centre)
        if self._r_px < 3.0:
            raise ValueError(f"the ball is {self._r_px:.1f} px in radius: too small to detect")
        # expected ball radius [px] on a coarse grid over the image (perspective varies it)
        gv, gu = np.mgrid[0:camera.height + _GRID:_GRID, 0:camera.width + _GRID:_GRID]
        plane = camera.pixel_to_plane(np.stack([gu, gv], axis=-1).astype(float), self._z)
        depth = camera.camera_from_world(plane)[..., 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            grid = self.ball_radius * math.sqrt(camera.fx * camera.fy) / depth
        self._r_grid = np.where(np.isfinite(grid) & (grid > 0), grid, self._r_px)
        self._scale_factor = int(min(8, max(1, round(self._r_px / 5.0))))
        self._tmpl = _disc_template(self._r_px / self._scale_factor)
        self._tmpl_half = self._tmpl.shape[0] // 2
        self._n_coarse = max(16, (3 * cfg.n_rays) // 8)
        self._grids: dict[tuple[int, int], tuple[F32, F32, F32]] = {}
        self._rays: dict[int, tuple[F32, F32, np.ndarray]] = {}
        for n in (cfg.n_rays, self._n_coarse):
            a = (np.arange(n) + 0.5) * (2.0 * np.pi / n)
            self._rays[n] = (np.cos(a).astype(np.float32), np.sin(a).astype(np.float32), a)
        self._focal = math.sqrt(camera.fx * camera.fy)
        self._rwc = camera.R_wc.tolist()
        self._triples: dict[int, np.ndarray] = {}
        self._last: tuple[float, float] | None = None
        self._track: tuple[np.ndarray, np.ndarray] | None = None
        self._gate_theta: float | None = None

    def set_track(self, ball_angle: ArrayLike, centre_radius: ArrayLike) -> None:
        """The ball's track: distance of the ball centre from the axis [m] by its angle.

        Parameters
        ----------
        ball_angle : array_like
            Polar angles of the ball centre in frame coordinates, clockwise from the
            frame's +y axis (``psi = theta + atan2(x, y)``), increasing over one turn [rad].
        centre_radius : array_like
            ``|p|`` at those angles [m] (the offset curve of the contour).
        """
        a = np.asarray(ball_angle, float)
        r = np.asarray(centre_radius, float)
        if a.ndim != 1 or a.shape != r.shape or a.size < 8 or np.any(np.diff(a) <= 0):
            raise ValueError("track: increasing ball angles and radii of the same length")
        # the periodic table np.interp(..., period=2 pi) builds on every call, built once:
        # angles reduced to [0, 2 pi), sorted, one point wrapped onto either end
        two_pi = 2.0 * math.pi
        red = a % two_pi
        order = np.argsort(red, kind="stable")
        red, rr = red[order], r[order]
        self._track = (np.concatenate((red[-1:] - two_pi, red, red[:1] + two_pi)),
                       np.concatenate((rr[-1:], rr, rr[:1])))

    def _off_track(self, fit: _Fit) -> str:
        """Why a fit is not the ball on its track (empty: it may be)."""
        if self._track is None or self._gate_theta is None or not self.config.track_gate:
            return ""
        x, y = float(fit.world[0]), float(fit.world[1])
        a, r = self._track
        psi = self._gate_theta + math.atan2(x, y)
        expect = float(np.interp(psi % (2.0 * math.pi), a, r))
        dr = math.hypot(x, y) - expect
        if abs(dr) > self.config.track_gate:
            return (f"object {1e3 * dr:+.0f} mm off the ball's track (gate "
                    f"{1e3 * self.config.track_gate:g} mm): part of the frame")
        return ""

    # -- state -----------------------------------------------------------------------------
    @property
    def last_fix(self) -> tuple[float, float] | None:
        """Pixel position (u, v) of the last FOUND ball, or None (lost / never found)."""
        return self._last

    @property
    def expected_radius_px(self) -> float:
        """Ball radius in pixels at the image centre, from the calibration [px]."""
        return self._r_px

    def _triples_for(self, n: int) -> np.ndarray:
        """Fixed pseudo-random index triples into n points (deterministic RANSAC)."""
        t = self._triples.get(n)
        if t is None:
            r = np.random.default_rng(n).random((_N_TRIPLES, n)).argsort(axis=1)[:, :3]
            t = self._triples[n] = np.sort(r, axis=1)
        return t

    def reset(self) -> None:
        """Forget the last fix: the next frame is searched in full."""
        self._last = None

    def warm_up(self) -> float:
        """Run every compiled step once on a synthetic frame; return the time it took [s].

        The compiled kernels (edges, RANSAC circle, algebraic circle, cone fit) are loaded
        from numba's cache on their first call: some 30 ms on a quiet machine and several
        times that on a busy one, which would otherwise delay the first fix of a run (the
        ball rolls unseen meanwhile). A bright disc of the expected radius on a dark frame
        of the calibrated size, found once by a full search and once by tracking; the
        detector then forgets it (:meth:`reset`).
        """
        t0 = time.perf_counter()
        cam = self.camera
        img = np.full((cam.height, cam.width), 30, np.uint8)
        centre = (cam.width // 2, cam.height // 2)
        cv2.circle(img, centre, max(3, round(self._r_px)), 200, -1, cv2.LINE_AA)
        img = cv2.GaussianBlur(img, (5, 5), 0.8)
        try:
            for _ in range(2):  # the disc is on no track: no gate
                self.detect(img, 0.0, gate=False)
        finally:
            self.reset()
        return time.perf_counter() - t0

    # -- main entry ------------------------------------------------------------------------
    def detect(self, image: ArrayLike, theta: float = 0.0, *,
               hint: tuple[float, float] | None = None,
               use_roi: bool | None = None, gate: bool = True) -> Detection:
        """Find the ball in one frame.

        Parameters
        ----------
        image : ndarray
            Grey image (H, W) of the camera's size, uint8, uint16 (scaled by 1/257) or
            float (8-bit DN scale; values within [0, 1] are scaled by 255); (H, W, 1) and
            BGR (H, W, 3) are accepted too.
        theta : float
            Frame angle [rad] at the frame's mid-exposure, for ``phi = theta + atan2(x, y)``.
        hint : (u, v), optional
            Where to look first [px] (default: the last fix).
        use_roi : bool, optional
            Override ``config.use_roi`` for this call.
        gate : bool
            Apply the track gate (needs the track and a true theta; pass False when theta
            is a stand-in value).

        Returns
        -------
        Detection
            FOUND (one ball, position fields valid), NOT_FOUND, AMBIGUOUS or INVALID_INPUT;
            never raises on bad image data.
        """
        t0 = time.perf_counter()
        try:
            theta = float(theta)
        except (TypeError, ValueError):
            theta = math.nan
        gray, scale, err = self._prepare(image)
        if err:
            return Detection(DetectionStatus.INVALID_INPUT, err, theta_used=theta,
                             processing_time=time.perf_counter() - t0)
        if not math.isfinite(theta):
            return Detection(DetectionStatus.INVALID_INPUT, f"theta must be finite, got {theta}",
                             processing_time=time.perf_counter() - t0)
        roi_on = self.config.use_roi if use_roi is None else bool(use_roi)
        self._gate_theta = theta if gate else None
        where = hint if hint is not None else self._last
        result: Detection | None = None
        u = v = math.nan
        if roi_on and where is not None:
            u, v = float(where[0]), float(where[1])
        if math.isfinite(u) and math.isfinite(v):
            # tracking: refine straight from the last fix (the ball moved a few pixels) ...
            fit = self._refine(gray, scale, u, v)
            if fit.ok and fit.confidence >= self.config.min_confidence \
                    and not self._off_track(fit):
                result = self._found(fit, theta, "roi", fit.box)
            else:  # ... else look for candidates in the region of interest
                result = self._search(gray, scale, theta, self._roi((u, v)), "roi")
                if result.status != DetectionStatus.FOUND:
                    result = None
        if result is None:
            h, w = gray.shape[:2]
            result = self._search(gray, scale, theta, (0, 0, w, h), "full")
        self._last = (result.u, result.v) if result.valid else None
        # the result is new and not shared yet: stamp it in place (cheaper than replace())
        object.__setattr__(result, "processing_time", time.perf_counter() - t0)
        return result

    # -- steps -----------------------------------------------------------------------------
    def _prepare(self, image: Any) -> tuple[np.ndarray, float, str]:
        """Validate; return a 2-D grey view, its scale to 8-bit DN, and an error or ''."""
        if not isinstance(image, np.ndarray):
            try:
                image = np.asarray(image)
            except Exception as exc:  # noqa: BLE001 (any garbage input)
                return np.zeros((0, 0)), 1.0, f"not an image array: {exc}"
        if image.dtype == object or image.dtype.kind not in "uif":
            return image, 1.0, f"unsupported pixel type {image.dtype}"
        if image.size == 0:
            return image, 1.0, f"empty image {image.shape}"
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[:, :, 0]
        elif image.ndim == 3 and image.shape[2] in (3, 4):
            src = image if image.dtype in (np.uint8, np.uint16, np.float32) else \
                image.astype(np.float32)
            code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
            image = cv2.cvtColor(np.ascontiguousarray(src), code)
        if image.ndim != 2:
            return image, 1.0, f"expected a (H, W) grey image, got shape {image.shape}"
        h, w = image.shape
        if (w, h) != (self.camera.width, self.camera.height):
            return image, 1.0, (f"image is {w}x{h} but the camera calibration is "
                                f"{self.camera.width}x{self.camera.height}")
        if image.dtype == np.uint8:
            return image, 1.0, ""
        if image.dtype == np.uint16:
            return image, 1.0 / 257.0, ""
        if image.dtype.kind == "f":
            if not np.all(np.isfinite(image)):
                return image, 1.0, "image contains NaN or infinite values"
            top = float(np.max(image))
            return image, (255.0 if top <= 1.0 else 1.0), ""
        return image.astype(np.float32), 1.0, ""  # other integer types: taken as 8-bit DN

    def _roi(self, where: tuple[float, float]) -> tuple[int, int, int, int]:
        half = self.config.roi_radius_factor * self._r_px + self.config.roi_margin
        u, v = float(where[0]), float(where[1])
        w, h = self.camera.width, self.camera.height
        x0 = int(max(0, math.floor(u - half)))
        y0 = int(max(0, math.floor(v - half)))
        x1 = int(min(w, math.ceil(u + half) + 1))
        y1 = int(min(h, math.ceil(v + half) + 1))
        return x0, y0, max(x1, x0), max(y1, y0)

    def _crop(self, gray: np.ndarray, scale: float, x0: int, y0: int, x1: int,
              y1: int) -> F32:
        """Region as float32 on the 8-bit DN scale, polarity applied (ball bright)."""
        c = gray[y0:y1, x0:x1]
        if c.dtype == np.uint8 and self.config.polarity == "bright":
            return c.astype(np.float32)
        f = c.astype(np.float32)
        if scale != 1.0:
            f *= np.float32(scale)
        if self.config.polarity == "dark":
            f = np.float32(255.0) - f
        return f

    def _search(self, gray: np.ndarray, scale: float, theta: float,
                box: tuple[int, int, int, int], kind: str) -> Detection:
        """Candidates in a region, verified one by one."""
        cfg = self.config
        s = self._scale_factor
        x0, y0, x1, y1 = box
        w = ((x1 - x0) // s) * s
        h = ((y1 - y0) // s) * s
        th = self._tmpl.shape[0]
        if w // s < th or h // s < th:
            return Detection(DetectionStatus.NOT_FOUND, f"search region {box} is too small",
                             theta_used=theta, search=kind, roi=box)
        region = gray[y0:y0 + h, x0:x0 + w]
        small = cv2.resize(region, (w // s, h // s), interpolation=cv2.INTER_AREA)
        small = small.astype(np.float32)
        if cfg.polarity == "dark":
            small = -small
        lo, hi = float(small.min()), float(small.max())
        if (hi - lo) * (scale if gray.dtype != np.uint8 else 1.0) < cfg.min_contrast * 0.5:
            return Detection(DetectionStatus.NOT_FOUND, "no contrast in the search region",
                             theta_used=theta, search=kind, roi=box)
        ncc = cv2.matchTemplate(small, self._tmpl, cv2.TM_CCOEFF_NORMED)
        cv2.patchNaNs(ncc, 0.0)
        k = max(3, 2 * round(self._r_px / s) + 1)
        dil = cv2.dilate(ncc, np.ones((k, k), np.uint8))
        ys, xs = np.nonzero((ncc >= dil) & (ncc >= cfg.candidate_threshold))
        if ys.size == 0:
            best = float(ncc.max()) if ncc.size else 0.0
            return Detection(DetectionStatus.NOT_FOUND,
                             f"no ball-like blob (best correlation {best:.2f} < "
                             f"{cfg.candidate_threshold})", theta_used=theta, search=kind,
                             roi=box)
        scores = ncc[ys, xs]
        order = np.argsort(-scores)
        cands: list[tuple[float, float, float]] = []
        half = self._tmpl_half
        for i in order:
            py, px = int(ys[i]), int(xs[i])
            dx = dy = 0.0
            if 0 < px < ncc.shape[1] - 1 and 0 < py < ncc.shape[0] - 1:  # parabolic peak
                nb = ncc[py - 1:py + 2, px - 1:px + 2].tolist()
                c_ = nb[1][1]
                den = nb[1][0] - 2 * c_ + nb[1][2]
                dx = min(0.5, max(-0.5, 0.5 * (nb[1][0] - nb[1][2]) / den)) if den < 0 else 0.0
                den = nb[0][1] - 2 * c_ + nb[2][1]
                dy = min(0.5, max(-0.5, 0.5 * (nb[0][1] - nb[2][1]) / den)) if den < 0 else 0.0
            u = x0 + (px + half + dx) * s + 0.5 * (s - 1)
            v = y0 + (py + half + dy) * s + 0.5 * (s - 1)
            if all(math.hypot(u - cu, v - cv) > self._r_px for cu, cv, _ in cands):
                cands.append((u, v, float(scores[i])))
            if len(cands) >= cfg.max_candidates:
                break
        found: list[_Fit] = []
        reasons: list[str] = []
        top_score = cands[0][2]
        for u, v, score in cands:
            if found and score < cfg.ambiguity_score * top_score:
                break
            fit = self._refine(gray, scale, u, v)
            off = self._off_track(fit) if fit.ok else ""
            if fit.ok and not off:
                if not any(math.hypot(fit.u - f.u, fit.v - f.v) < self._r_px for f in found):
                    found.append(fit)
            else:
                reasons.append(off or fit.reason)
        if not found:
            why = reasons[0] if reasons else "no candidate"
            return Detection(DetectionStatus.NOT_FOUND,
                             f"{len(cands)} candidate(s) rejected: {why}", theta_used=theta,
                             search=kind, roi=box)
        found.sort(key=lambda f: -f.confidence)
        best = found[0]
        if len(found) > 1 and found[1].confidence >= cfg.ambiguity_ratio * best.confidence:
            return Detection(DetectionStatus.AMBIGUOUS,
                             f"{len(found)} ball-like objects (confidences "
                             + ", ".join(f"{f.confidence:.2f}" for f in found) + ")",
                             theta_used=theta, search=kind, roi=box,
                             candidates=tuple((f.u, f.v) for f in found))
        if best.confidence < cfg.min_confidence:
            return Detection(DetectionStatus.NOT_FOUND,
                             f"best candidate's confidence {best.confidence:.2f} < "
                             f"{cfg.min_confidence}", theta_used=theta, search=kind, roi=box)
        return self._found(best, theta, kind, box)

    @staticmethod
    def _found(fit: _Fit, theta: float, kind: str, box: tuple[int, int, int, int]
               ) -> Detection:
        """The FOUND result of a verified fit; ``phi = theta + atan2(x, y)``."""
        assert fit.world is not None
        x, y = float(fit.world[0]), float(fit.world[1])
        return Detection(DetectionStatus.FOUND, "ok", confidence=fit.confidence, u=fit.u,
                         v=fit.v, radius_px=fit.radius_px, x=x, y=y, radius_m=fit.radius_m,
                         phi=theta + math.atan2(x, y), theta_used=theta, rms_px=fit.rms_px,
                         n_edges=fit.n_edges, search=kind, roi=box,
                         candidates=((fit.u, fit.v),))

    # -- sub-pixel refinement --------------------------------------------------------------
    def _ray_grid(self, n_rays: int, count: int) -> tuple[F32, F32, F32]:
        """Cached sample offsets along the rays: s (count,), cos * s and sin * s (n, count)."""
        key = (n_rays, count)
        grid = self._grids.get(key)
        if grid is None:
            cos, sin, _ = self._rays[n_rays]
            base = (0.5 * np.arange(count)).astype(np.float32)
            grid = self._grids[key] = (base, cos[:, None] * base, sin[:, None] * base)
        return grid

    def _edges(self, patch: F32, cu: float, cv: float, r_lo: float, r_hi: float,
               sigma: float, n_rays: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                   np.ndarray, np.ndarray]:
        """Sub-pixel falling edges on ``n_rays`` rays from (cu, cv) (patch coordinates).

        On each ray the profile ``I(s)`` is sampled every 0.5 px and ``g = -dI/ds`` (central
        difference over 1 px). Around the steepest point in ``[r_lo, r_hi]``, the run where
        ``g >= g_max / 2`` is the edge's ramp (about 1 px for a sharp edge, longer under
        blur); the levels ``I_in`` and ``I_out`` are averaged over 2 px starting 1 px beyond
        either end of the ramp, and the edge is where the profile crosses
        ``(I_in + I_out) / 2`` nearest the ramp's middle (linear interpolation between
        samples). With the level windows outside the ramp, the estimate is the half-level
        point for any blur symmetric about the edge.

        Returns the ray angles, edge points (n, 2), contrasts ``I_in - I_out``, outside
        levels and a validity mask.
        """
        cu, cv = float(cu), float(cv)
        pad = _HALF + 8  # samples beyond the search window: ramp, gap and level window
        start = float(r_lo) - 0.5 * pad
        count = math.ceil((r_hi - r_lo) / 0.5) + 2 * pad + 1
        _, cs, sn = self._ray_grid(n_rays, count)
        cos, sin, ang = self._rays[n_rays]
        xs = cs + (cu + cos * np.float32(start))[:, None]
        ys = sn + (cv + sin * np.float32(start))[:, None]
        prof = _sample(patch, xs, ys)
        pts, contrast, outer, has, nl, nr = _edge_kernel(prof, pad, _HALF, float(start), cu, cv,
                                                         cos, sin)
        ok = has & (contrast >= max(self.config.min_contrast, self.config.min_cnr * sigma))
        ok &= (nl < _HALF) & (nr < _HALF)  # a ramp longer than the window is not an edge
        return ang, pts, contrast, outer, ok  # NaN samples (off the image) fail the tests

    @staticmethod
    def _on_outline(dr: np.ndarray, contrast: np.ndarray, outer: np.ndarray, ok: np.ndarray,
                    sigma: float) -> np.ndarray:
        """Rays whose edge is the ball's outline against its usual surroundings.

        ``dr`` is each edge's distance to the coarse circle [px]. The reference outside level
        and contrast are those of the rays on that circle (within 1 px); rays whose outside
        level differs by more than ``max(0.2 contrast, 3 sigma)`` (an edge against the frame's
        plate or an occluder) or whose contrast is under half the reference are dropped.
        """
        core = ok & (np.abs(dr) <= 1.0)
        if np.count_nonzero(core) < 3:
            core = ok
        if not core.any():
            return ok
        ref_c = _median(contrast[core])
        ref_o = _median(outer[core])
        tol = max(0.2 * ref_c, 3.0 * sigma)
        return ok & (np.abs(outer - ref_o) <= tol) & (contrast >= 0.5 * ref_c)

    def _cone_fit(self, pts_px: np.ndarray, wts: np.ndarray, iters: int = 4
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Robust fit of the tangent cone to edge pixels (see the module docstring).

        ``wts`` are the initial weights (from the points' distances to the coarse circle).
        From the second round on, a soft prior ties the ball radius to R_b: the row
        ``c . w = W(c)`` with ``W = 1 / sqrt(1 - (R_b / lambda(c))^2)`` (the ``|w|`` a sphere
        of radius R_b at the plane point in direction c would have), weighted as
        ``(sigma_edge / sigma_r)^2`` with ``sigma_r = radius_prior_sigma`` times the radius
        in pixels: negligible on a long arc, decisive on a short one.
        Returns ``w`` (3,) (``c = w/|w|``, ``cos beta = 1/|w|``), the residuals [px] and the
        final Tukey weights; None if degenerate.
        """
        cam = self.camera
        if cam.has_distortion:
            xy = cam.pixel_to_normalized(pts_px)
        else:
            xy = np.empty_like(pts_px)
            xy[:, 1] = (pts_px[:, 1] - cam.cy) * (1.0 / cam.fy)
            xy[:, 0] = (pts_px[:, 0] - cam.cx - cam.k[1] * xy[:, 1]) * (1.0 / cam.fx)
        n = xy.shape[0]
        v = np.empty((n, 4))  # [v_x, v_y, v_z, 1]: one product gives the normal equations
        v[:, :2] = xy
        v[:, 2] = 1.0
        v[:, :3] *= (1.0 / np.sqrt(xy[:, 0] ** 2 + xy[:, 1] ** 2 + 1.0))[:, None]
        v[:, 3] = 1.0
        rz = self._rwc[2]
        ok, w, res, wts = _cone_kernel(v, np.asarray(wts, dtype=float), int(iters),
                                       self._focal, rz[0], rz[1], rz[2], float(cam.c[2]),
                                       self._z, self.ball_radius,
                                       float(self.config.radius_prior_sigma))
        return (w, res, wts) if ok else None

    def _refine(self, gray: np.ndarray, scale: float, u0: float, v0: float) -> _Fit:
        """Sub-pixel centre of the candidate at (u0, v0), with verification."""
        cfg = self.config
        cam = self.camera
        gi = min(max(round(v0 / _GRID), 0), self._r_grid.shape[0] - 1)
        gj = min(max(round(u0 / _GRID), 0), self._r_grid.shape[1] - 1)
        r0 = float(self._r_grid[gi, gj])
        reach = 1.6 * r0 + 8.0
        x0 = int(max(0, math.floor(u0 - reach)))
        y0 = int(max(0, math.floor(v0 - reach)))
        x1 = int(min(cam.width, math.ceil(u0 + reach) + 1))
        y1 = int(min(cam.height, math.ceil(v0 + reach) + 1))
        patch = self._crop(gray, scale, x0, y0, x1, y1)
        if patch.shape[0] < 4 or patch.shape[1] < 4:
            return _Fit(False, "candidate at the image border")
        d = np.abs(patch[::4, 1::2] - patch[::4, :-1:2])
        sigma = max(1.4826 * _median(d) / math.sqrt(2.0), 0.3)
        # pass 1: wide window from the coarse centre, half the rays; a RANSAC circle
        _, pts, con, out, ok = self._edges(patch, u0 - x0, v0 - y0, 0.5 * r0, 1.5 * r0, sigma,
                                           self._n_coarse)
        n_ok = int(ok.sum())
        if n_ok < max(6, cfg.min_inlier_fraction * self._n_coarse):
            return _Fit(False, f"only {n_ok} ball edge points found")
        circ = _circle_fit(pts[ok], 0.8 * r0, 1.2 * r0, self._triples_for(n_ok))
        if circ is None:
            return _Fit(False, "no ball-sized circle among the edges")
        uc, vc, rpx = circ[0] + x0, circ[1] + y0, circ[2]
        if not (x0 <= uc < x1 and y0 <= vc < y1):
            return _Fit(False, "coarse circle outside the candidate's region")
        # pass 2: narrow window around the coarse circle, rays from its centre
        ang, pts, con, out, ok = self._edges(patch, uc - x0, vc - y0, rpx - 3.0, rpx + 3.0,
                                             sigma, cfg.n_rays)
        dr = np.hypot(pts[:, 0] - (uc - x0), pts[:, 1] - (vc - y0)) - rpx
        ok = self._on_outline(dr, con, out, ok, sigma)
        n_ok = int(ok.sum())
        if n_ok < 6:
            return _Fit(False, f"only {n_ok} ball edge points found")
        # initial weights: Tukey on the distance to the coarse circle, so that a foreign edge
        # cannot drag the first least-squares solution
        pk = pts[ok]
        dk = dr[ok] - _median(dr[ok])
        u = dk * (1.0 / (4.685 * max(1.4826 * _median(np.abs(dk)), 0.15)))
        w0 = np.maximum(1.0 - u * u, 0.0) ** 2
        fit = self._cone_fit(pk + np.array([x0, y0], dtype=float), w0, iters=3)
        sol = None if fit is None else self._solution(fit[0])
        if fit is None or sol is None:
            return _Fit(False, "no consistent outline")
        _, res, wts = fit
        uc, vc, rpx, world, rm = sol
        inl = (wts > 0) & (np.abs(res) <= 3.0 * cfg.max_rms_px)
        n_in = int(inl.sum())
        frac = n_in / cfg.n_rays
        rms = math.sqrt(float(res[inl] @ res[inl]) / n_in) if n_in else math.inf
        a_in = ang[np.nonzero(ok)[0][inl]]  # increasing: rays are cast in angle order
        if a_in.size >= 2:
            gap = max(float(np.diff(a_in).max()), 2.0 * math.pi + a_in[0] - a_in[-1])
            arc = 2.0 * math.pi - gap
        else:
            arc = 0.0
        rel = rm / self.ball_radius - 1.0
        cnr = _median(con[ok]) / sigma
        base = dict(u=uc, v=vc, radius_px=rpx, world=world, radius_m=rm, rms_px=rms,
                    n_edges=n_in, box=(x0, y0, x1, y1))
        if frac < cfg.min_inlier_fraction:
            return _Fit(False, f"only {n_in}/{cfg.n_rays} rays on a ball outline", **base)
        if arc < cfg.min_arc:
            return _Fit(False, f"visible outline spans {math.degrees(arc):.0f} deg "
                               f"< {math.degrees(cfg.min_arc):.0f} deg", **base)
        if rms > cfg.max_rms_px:
            return _Fit(False, f"outline fit RMS {rms:.2f} px > {cfg.max_rms_px} px", **base)
        if abs(rel) > cfg.radius_tolerance:
            return _Fit(False, f"fitted radius {1e3 * rm:.1f} mm differs from the ball's "
                               f"{1e3 * self.ball_radius:.1f} mm by {100 * abs(rel):.0f} %",
                        **base)
        conf = (min(1.0, frac / 0.5)
                * min(1.0, (arc - cfg.min_arc) / max(math.pi - cfg.min_arc, 1e-9) + 0.5)
                * math.exp(-((rms / max(cfg.max_rms_px, 1e-9)) ** 2))
                * math.exp(-0.5 * (rel / (0.5 * cfg.radius_tolerance)) ** 2)
                * min(1.0, cnr / (2.0 * cfg.min_cnr)))
        return _Fit(True, "ok", confidence=float(min(1.0, max(0.0, conf))), **base)

    def _solution(self, w: np.ndarray) -> tuple[float, float, float, np.ndarray, float] | None:
        """Centre pixel, radius [px], world centre and radius [m] of a cone ``w``."""
        nw = math.sqrt(float(w @ w))
        if not math.isfinite(nw) or nw <= 1.0:
            return None
        c_cam = w / nw
        if c_cam[2] <= 0:
            return None
        cam = self.camera
        d = cam.R_wc @ c_cam
        if abs(d[2]) < 1e-12:
            return None
        lam = (self._z - cam.c[2]) / d[2]
        if lam <= 0:
            return None
        world = cam.c + lam * d
        rm = lam * math.sqrt(max(1.0 - 1.0 / (nw * nw), 0.0))
        # image of the centre: the cone's axis c_cam (== projection of the world centre)
        if cam.has_distortion:
            uv = cam.distort_normalized(c_cam[:2] / c_cam[2])
            u, v = float(uv[0]), float(uv[1])
        else:
            k = cam.k
            xn, yn = c_cam[0] / c_cam[2], c_cam[1] / c_cam[2]
            u, v = k[0] * xn + k[1] * yn + k[2], k[4] * yn + k[5]
        rpx = rm * self._focal / (lam * float(c_cam[2]))
        return float(u), float(v), float(rpx), world, float(rm)
