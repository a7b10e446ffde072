"""Geometry of the frame contour and of the ball-centre (offset) curve.

Conventions (DEVELOPERS.md): frame coordinates rotate with the frame; the contour is

    delta(phi) = rho(phi) * e(phi),   e = [sin phi, cos phi],   e' = [cos phi, -sin phi],

so phi is the polar angle of the contact point measured clockwise from the frame's +y axis
(the seed's eqs. 2.2, 4.31). Increasing phi runs clockwise round the frame; the outward unit
normal is ``n = J t`` with ``t = delta' / |delta'|`` and ``J = [[0, -1], [1, 0]]``.

The radius is a Fourier series plus Gaussian bumps (any smooth closed star-shaped frame is a
Fourier series, so this is the pluggable shape):

    rho(phi) = a + sum_k (c_k cos k phi + s_k sin k phi) + sum_i h_i exp(-d_i^2 / (2 w_i^2)),

with the seed's ``a - b cos 2 phi`` as the k = 2 cosine term ``c_2 = -b`` and d_i the wrapped
angle from bump i.

The ball centre lies on the offset curve ``p(phi) = delta(phi) + R n(phi)`` (R: rolling radius).
With ``L = |delta'|``, ``X = delta' x delta''`` (2-D cross product) the contour's signed
curvature (convex > 0) is ``kappa = -X / L^3``; Frenet for this orientation gives
``t' = -K n``, ``n' = K t`` with ``K = kappa L = -X / L^2``. Hence, exactly,

    p'   = lam t,                        lam = L (1 + R kappa) = L - R X / L^2   (= |p'|)
    p''  = lam' t - lam K n
    p''' = (lam'' - lam K^2) t - (2 lam' K + lam K') n

lam is the ball-centre arc-length rate ds/dphi; it must stay positive (no cusp: the ball fits
into every concave part of the track).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_model.jit import njit, njit_inline

__all__ = ["ContourArrays", "OffsetCurve", "contour_kernel", "offset_kernel"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ContourArrays:
    """The contour as flat float arrays, the form the compiled kernels take.

    Attributes
    ----------
    rho0 : float
        Constant term a [m].
    orders, ccos, csin : ndarray
        Harmonic orders k [-] and their cosine/sine amplitudes [m].
    bump_phi, bump_h, bump_w : ndarray
        Gaussian bump centres [rad], heights [m] and widths [rad].
    rolling_radius : float
        R [m].
    """

    rho0: float
    orders: FloatArray
    ccos: FloatArray
    csin: FloatArray
    bump_phi: FloatArray
    bump_h: FloatArray
    bump_w: FloatArray
    rolling_radius: float

    def as_args(self) -> tuple:
        """Positional arguments of :func:`offset_kernel` after ``phi``."""
        return (self.rolling_radius, self.rho0, self.orders, self.ccos, self.csin,
                self.bump_phi, self.bump_h, self.bump_w)


@njit_inline
def _harmonic(r0, r1, r2, r3, r4, k, c, s, a, b):  # noqa: ANN001, ANN202
    """Add ``a cos k phi + b sin k phi`` and its first four derivatives to ``r0..r4``.

    ``c`` and ``s`` are the cosine and sine of ``k phi``.
    """
    return (r0 + a * c + b * s,
            r1 + k * (-a * s + b * c),
            r2 - k * k * (a * c + b * s),
            r3 + k * k * k * (a * s - b * c),
            r4 + k * k * k * k * (a * c + b * s))


#: Integer orders up to this one take cos/sin k phi from the angle-addition recurrence.
MAX_RECURRENCE_ORDER = 64


@njit
def contour_kernel(phi, rho0, orders, ccos, csin, bump_phi, bump_h, bump_w):  # noqa: ANN001, ANN201
    """Rho and its first four derivatives with respect to phi.

    Works on a float or an array ``phi``. When every order is an integer from 1 to
    :data:`MAX_RECURRENCE_ORDER`, ``cos k phi`` and ``sin k phi`` come from ``cos phi`` and
    ``sin phi`` by the angle-addition recurrence (two trigonometric calls instead of two per
    order; the rounding grows as ``k eps``, 1e-14 at k = 64); other orders call them
    directly. Bump derivatives use the Hermite polynomials:
    ``d^n/dd^n exp(-x^2/2) = (-1)^n He_n(x) exp(-x^2/2) / w^n``, ``x = d / w``.
    """
    z = 0.0 * phi
    r0 = rho0 + z
    r1 = z
    r2 = z
    r3 = z
    r4 = z
    kmax = 0
    integer = True
    for i in range(orders.shape[0]):
        k = orders[i]
        if k < 1.0 or k > MAX_RECURRENCE_ORDER or k != np.floor(k):
            integer = False
        else:
            kmax = max(kmax, int(k))
    if integer:
        c1 = np.cos(phi)
        s1 = np.sin(phi)
        ck = c1
        sk = s1
        for k in range(1, kmax + 1):
            for i in range(orders.shape[0]):
                if orders[i] == k:
                    r0, r1, r2, r3, r4 = _harmonic(r0, r1, r2, r3, r4, orders[i], ck, sk,
                                                   ccos[i], csin[i])
            ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
    else:
        for i in range(orders.shape[0]):
            k = orders[i]
            r0, r1, r2, r3, r4 = _harmonic(r0, r1, r2, r3, r4, k, np.cos(k * phi),
                                           np.sin(k * phi), ccos[i], csin[i])
    for i in range(bump_phi.shape[0]):
        w = bump_w[i]
        d = np.mod(phi - bump_phi[i] + np.pi, 2.0 * np.pi) - np.pi
        x = d / w
        g = bump_h[i] * np.exp(-0.5 * x * x)
        r0 = r0 + g
        r1 = r1 - g * x / w
        r2 = r2 + g * (x * x - 1.0) / (w * w)
        r3 = r3 - g * (x * x * x - 3.0 * x) / (w * w * w)
        r4 = r4 + g * (x * x * x * x - 6.0 * x * x + 3.0) / (w * w * w * w)
    return r0, r1, r2, r3, r4


@njit
def offset_kernel(phi, R, rho0, orders, ccos, csin, bump_phi, bump_h, bump_w):  # noqa: ANN001, ANN201
    """Ball-centre curve p(phi) and its derivatives, exactly (module docstring).

    Returns
    -------
    tuple
        ``(px, py, p1x, p1y, p2x, p2y, p3x, p3y, nx, ny, lam, lam1, K)``: the point, its first
        three derivatives [m, m/rad, ...], the outward normal, ``lam = |p'|``, ``lam'`` and
        ``K = kappa |delta'|``.
    """
    r0, r1, r2, r3, r4 = contour_kernel(phi, rho0, orders, ccos, csin, bump_phi, bump_h, bump_w)
    s = np.sin(phi)
    c = np.cos(phi)
    # delta^(n) = A_n e + B_n e',  e = (s, c), e' = (c, -s)
    a1, b1 = r1, r0
    a2, b2 = r2 - r0, 2.0 * r1
    a3, b3 = r3 - 3.0 * r1, 3.0 * r2 - r0
    a4, b4 = r4 - 6.0 * r2 + r0, 4.0 * r3 - 4.0 * r1
    # In the orthonormal basis (e, e'): dot = A A + B B, cross(u, v) = A_u B_v... with
    # cross(e, e') = s(-s) - c c = -1, so cross(u, v) = -(A_u B_v - B_u A_v).
    L2 = a1 * a1 + b1 * b1
    L = np.sqrt(L2)
    d12 = a1 * a2 + b1 * b2
    d22 = a2 * a2 + b2 * b2
    d13 = a1 * a3 + b1 * b3
    X = -(a1 * b2 - b1 * a2)
    X1 = -(a1 * b3 - b1 * a3)
    X2 = -(a2 * b3 - b2 * a3) - (a1 * b4 - b1 * a4)
    L1 = d12 / L
    L_2 = (d22 + d13) / L - d12 * d12 / (L2 * L)
    K = -X / L2
    K1 = -X1 / L2 + 2.0 * X * L1 / (L2 * L)
    lam = L + R * K
    lam1 = L1 + R * K1
    K2 = (-X2 / L2 + 2.0 * X1 * L1 / (L2 * L) + 2.0 * X1 * L1 / (L2 * L)
          + 2.0 * X * L_2 / (L2 * L) - 6.0 * X * L1 * L1 / (L2 * L2))
    lam2 = L_2 + R * K2
    # unit tangent and outward normal n = J t in world-of-frame components
    dx = a1 * s + b1 * c
    dy = a1 * c - b1 * s
    tx = dx / L
    ty = dy / L
    nx = -ty
    ny = tx
    px = r0 * s + R * nx
    py = r0 * c + R * ny
    p1x = lam * tx
    p1y = lam * ty
    p2x = lam1 * tx - lam * K * nx
    p2y = lam1 * ty - lam * K * ny
    ct = lam2 - lam * K * K
    cn = -(2.0 * lam1 * K + lam * K1)
    p3x = ct * tx + cn * nx
    p3y = ct * ty + cn * ny
    return px, py, p1x, p1y, p2x, p2y, p3x, p3y, nx, ny, lam, lam1, K


@njit
def _speed_extremes(n, R, rho0, orders, ccos, csin, bump_phi, bump_h, bump_w):  # noqa: ANN001, ANN202
    """``(min lam, max |lam'|)`` over ``n`` equally spaced nodes of ``[0, 2 pi)``.

    :func:`offset_kernel` node by node (no temporary arrays: the fits check every candidate
    curve, :meth:`OffsetCurve.speed_floor`).
    """
    lam_min = np.inf
    slope = 0.0
    for j in range(n):
        g = offset_kernel(2.0 * np.pi * j / n, R, rho0, orders, ccos, csin, bump_phi, bump_h,
                          bump_w)
        lam_min = min(lam_min, g[10])
        slope = max(slope, abs(g[11]))
    return lam_min, slope


class OffsetCurve:
    """The frame contour and the ball-centre curve of one parameter set (vectorised helpers).

    Parameters
    ----------
    arrays : ContourArrays
        Contour coefficients and rolling radius.
    """

    def __init__(self, arrays: ContourArrays) -> None:
        self.arrays = arrays
        self._args = arrays.as_args()
        self._s_table: tuple[FloatArray, FloatArray] | None = None

    @classmethod
    def from_params(cls, params) -> OffsetCurve:  # noqa: ANN001 (RigParams; avoids a cycle)
        """Build from :class:`bfr_model.params.RigParams`."""
        c = params.frame.contour
        t = params.track
        orders = [2.0, *[float(k) for k in c.harmonic_orders]]
        ccos = [-c.b, *c.harmonic_cos]
        csin = [0.0, *c.harmonic_sin]
        arrays = ContourArrays(
            rho0=float(c.a),
            orders=np.array(orders, dtype=float),
            ccos=np.array(ccos, dtype=float),
            csin=np.array(csin, dtype=float),
            bump_phi=np.array(t.bump_phi, dtype=float),
            bump_h=np.array(t.bump_height, dtype=float),
            bump_w=np.array(t.bump_width, dtype=float),
            rolling_radius=float(params.ball.rolling_radius),
        )
        return cls(arrays)

    # -- contour ---------------------------------------------------------------------------
    def rho(self, phi: ArrayLike) -> FloatArray:
        """Contour radius rho(phi) [m]."""
        a = self.arrays
        return contour_kernel(np.asarray(phi, float), a.rho0, a.orders, a.ccos, a.csin,
                              a.bump_phi, a.bump_h, a.bump_w)[0]

    def contour_point(self, phi: ArrayLike) -> FloatArray:
        """Contour point delta(phi) in frame coordinates, shape (..., 2) [m]."""
        phi = np.asarray(phi, float)
        r = self.rho(phi)
        return np.stack([r * np.sin(phi), r * np.cos(phi)], axis=-1)

    def contour_curvature(self, phi: ArrayLike) -> FloatArray:
        """Signed curvature of the contour, convex > 0 [1/m]."""
        k = self._eval(phi)[12]
        a = self.arrays
        r0, r1 = contour_kernel(np.asarray(phi, float), a.rho0, a.orders, a.ccos, a.csin,
                                a.bump_phi, a.bump_h, a.bump_w)[:2]
        return k / np.sqrt(r0 * r0 + r1 * r1)

    def frame_outline(self, n: int = 720) -> FloatArray:
        """Closed polygon of the contour in frame coordinates, shape (n, 2) [m]."""
        return self.contour_point(np.linspace(0.0, 2.0 * np.pi, n, endpoint=False))

    # -- offset curve ----------------------------------------------------------------------
    def _eval(self, phi: ArrayLike) -> tuple:
        return offset_kernel(np.asarray(phi, float), *self._args)

    def point(self, phi: ArrayLike) -> FloatArray:
        """Ball centre p(phi) in frame coordinates, shape (..., 2) [m]."""
        g = self._eval(phi)
        return np.stack([g[0], g[1]], axis=-1)

    def derivatives(self, phi: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """p, p', p'', p''' in frame coordinates, each shape (..., 2)."""
        g = self._eval(phi)
        return tuple(np.stack([g[2 * i], g[2 * i + 1]], axis=-1) for i in range(4))  # type: ignore[return-value]

    def normal(self, phi: ArrayLike) -> FloatArray:
        """Outward unit normal n(phi) of the contour (and of the offset curve), (..., 2)."""
        g = self._eval(phi)
        return np.stack([g[8], g[9]], axis=-1)

    def tangent(self, phi: ArrayLike) -> FloatArray:
        """Unit tangent t(phi) in the direction of increasing phi, (..., 2)."""
        n = self.normal(phi)
        return np.stack([n[..., 1], -n[..., 0]], axis=-1)

    def speed(self, phi: ArrayLike) -> FloatArray:
        """lam(phi) = |p'(phi)| = ds/dphi of the ball-centre curve [m/rad]."""
        return self._eval(phi)[10]

    def curvature(self, phi: ArrayLike) -> FloatArray:
        """Signed curvature of the ball-centre curve, convex > 0 [1/m]: K / lam."""
        g = self._eval(phi)
        return g[12] / g[10]

    def min_speed(self, n: int = 8192) -> float:
        """Smallest |p'| on a dense grid; <= 0 means the ball-centre curve has a cusp."""
        return float(np.min(self.speed(np.linspace(0.0, 2.0 * np.pi, n, endpoint=False))))

    def speed_floor(self, n_max: int = 8192) -> float:
        """A lower bound of ``lam = |p'|`` over the curve; <= 0: it may have a cusp.

        Between two nodes of a grid of step ``h``, ``lam`` falls below the smaller of its
        two node values by at most ``h/2 max|lam'|`` (``lam'`` exact from the kernel). On a
        grid that resolves every feature (16 nodes per period of the highest harmonic and
        per width of the narrowest bump, at least 512), twice the largest ``|lam'|`` at the
        nodes stands in for its supremum, so

            lam >= min_j lam_j - h max_j |lam'_j|.

        When that bound is positive it is returned (a few hundred evaluations instead of
        :meth:`min_speed`'s 8192: the fits check every candidate curve); otherwise the
        dense grid's minimum, ``min_speed(n_max)``.
        """
        a = self.arrays
        k_max = float(np.max(np.abs(a.orders))) if a.orders.size else 0.0
        w_min = float(np.min(np.abs(a.bump_w))) if a.bump_w.size else np.inf
        need = max(512.0, 16.0 * k_max, 16.0 * 2.0 * np.pi / w_min)
        n = int(min(n_max, 2 ** math.ceil(math.log2(need))))
        lam_min, slope = _speed_extremes(n, *self._args)
        floor = lam_min - (2.0 * np.pi / n) * slope
        if floor > 0.0 or n >= n_max:
            return floor if floor > 0.0 else lam_min
        return self.min_speed(n_max)

    def ball_angle(self, phi: ArrayLike) -> FloatArray:
        """Polar angle of the ball centre, clockwise from the frame's +y axis [rad].

        Continuous in phi (unwrapped relative to phi), so that ``ball_angle(phi) - phi`` is
        small. This is the real rig's logged ``phi - theta`` up to the rig's offsets.
        """
        phi = np.asarray(phi, float)
        g = self._eval(phi)
        psi = np.arctan2(g[0], g[1])
        return phi + np.mod(psi - phi + np.pi, 2.0 * np.pi) - np.pi

    def phi_from_ball_angle(self, psi: ArrayLike, tol: float = 1e-13) -> FloatArray:
        """Invert :meth:`ball_angle` by Newton's method: the contact angle of a ball angle."""
        psi = np.asarray(psi, float)
        phi = psi.copy()
        for _ in range(50):
            g = self._eval(phi)
            px, py, p1x, p1y = g[0], g[1], g[2], g[3]
            f = self.ball_angle(phi) - psi
            dpsi = (py * p1x - px * p1y) / (px * px + py * py)
            step = f / dpsi
            phi = phi - step
            if np.all(np.abs(step) < tol):
                break
        return phi

    def _arc_table(self, n: int = 4096) -> tuple[FloatArray, FloatArray]:
        if self._s_table is None:
            # Gauss-Legendre (8 nodes) on n panels over one turn: spectrally accurate.
            xg, wg = np.polynomial.legendre.leggauss(8)
            edges = np.linspace(0.0, 2.0 * np.pi, n + 1)
            h = np.diff(edges)
            nodes = edges[:-1, None] + 0.5 * h[:, None] * (xg[None, :] + 1.0)
            panel = (0.5 * h[:, None] * wg[None, :] * self.speed(nodes)).sum(axis=1)
            self._s_table = (edges, np.concatenate([[0.0], np.cumsum(panel)]))
        return self._s_table

    def perimeter(self) -> float:
        """Length of the ball-centre curve over one turn [m]."""
        return float(self._arc_table()[1][-1])

    def arc_length(self, phi: ArrayLike) -> FloatArray:
        """Arc length s(phi) of the ball-centre curve from phi = 0 [m] (any real phi)."""
        phi = np.asarray(phi, float)
        edges, s = self._arc_table()
        turns = np.floor(phi / (2.0 * np.pi))
        rem = phi - turns * 2.0 * np.pi
        i = np.clip(np.searchsorted(edges, rem, side="right") - 1, 0, len(edges) - 2)
        # integrate the remainder of the panel with 8-point Gauss-Legendre
        xg, wg = np.polynomial.legendre.leggauss(8)
        a = edges[i]
        h = rem - a
        nodes = a[..., None] + 0.5 * h[..., None] * (xg + 1.0)
        part = (0.5 * h[..., None] * wg * self.speed(nodes)).sum(axis=-1)
        return turns * s[-1] + s[i] + part


def wrap_angle(x: ArrayLike) -> FloatArray:
    """Wrap angles to [-pi, pi)."""
    return np.mod(np.asarray(x, float) + math.pi, 2.0 * math.pi) - math.pi
