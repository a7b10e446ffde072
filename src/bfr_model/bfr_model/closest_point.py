"""Closest point of the frame contour to the ball centre (seed section 4.2).

The contact model (:mod:`bfr_model.contact`) needs, at every evaluation, the point of the
contour nearest to the ball centre ``c`` (frame coordinates): the contact normal, the
penetration ``w = R - d`` and the lever arms all follow from it. With the contour
``delta(phi) = rho(phi) e(phi)``, ``e = (sin phi, cos phi)``, ``e' = (cos phi, -sin phi)``
(DEVELOPERS.md), the squared distance ``D(phi) = 1/2 |delta(phi) - c|^2`` is stationary where

    f(phi)  = D'(phi)  = (delta - c) . delta' = 0
    f'(phi) = D''(phi) = |delta'|^2 + (delta - c) . delta''       (> 0 at a minimum)

    delta'  = rho' e + rho e',   delta'' = (rho'' - rho) e + 2 rho' e'.

:func:`newton_closest` solves ``f = 0`` by Newton's method from a good initial guess (the
previous solution), with a step limit and a descent step where ``f' <= 0`` so it cannot
jump across a narrow bump; it converges quadratically to ``|dphi| < 1e-14``.
:func:`closest_point` adds a global bracket (a dense sample finer than the narrowest bump)
for a first call.

The seed's estimate (eqs. 4.30-4.37) expands ``D_nl = |delta - c|^2`` to second order in
``phi* = phi - phi_b`` around the ball's own polar angle ``phi_b`` and takes the vertex of
the parabola, ``phi* = -beta / (2 alpha)``. That is exactly one Newton step on ``f`` from
``phi_b``; for the seed's contour ``rho = a + b cos 2 phi`` it reproduces eq. 4.36 term by
term (denominator ``a r_b - 4 b^2 (2 cos^2 2 theta - 1) - 4 a b cos 2 theta
+ 5 b r_b cos 2 theta``) except for the sign: eq. 4.35 writes the vertex as
``beta / (2 alpha)``, dropping the minus (see :func:`seed_eq_4_36`).
:func:`taylor_closest_point` implements it, so its error against
the exact solve can be measured (``bfr analyze bounce`` prints it for a closed-loop run):
the seed attributes the error to the ball centre being R away from the track.

Sharp bumps (``track.asperity_*``) are evaluated from a local index list only (those near
the ball), so a rough track with hundreds of asperities costs no more than a few.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_model.jit import njit, njit_inline
from bfr_model.params import RigParams

F = TypeVar("F", bound=Callable)

__all__ = [
    "ContourData",
    "closest_point",
    "contour_data",
    "contour_point_terms",
    "newton_closest",
    "rho012",
    "seed_eq_4_36",
    "taylor_closest_point",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ContourData:
    """The contact model's contour: harmonics, gentle bumps and sharp asperities.

    Attributes
    ----------
    rho0 : float
        Constant term a [m].
    orders, ccos, csin : ndarray
        Harmonic orders [-] and amplitudes [m] (the seed's ``-b cos 2 phi`` is order 2).
    bphi, bh, bw : ndarray
        ``track.bump_*``: centres [rad], heights [m], widths [rad].
    aphi, ah, aw : ndarray
        ``track.asperity_*`` sorted by centre, centres wrapped to [0, 2 pi).
    """

    rho0: float
    orders: FloatArray
    ccos: FloatArray
    csin: FloatArray
    bphi: FloatArray
    bh: FloatArray
    bw: FloatArray
    aphi: FloatArray
    ah: FloatArray
    aw: FloatArray

    def as_args(self) -> tuple:
        """Positional arguments of :func:`rho012` after ``phi`` (without the index list)."""
        return (self.rho0, self.orders, self.ccos, self.csin, self.bphi, self.bh, self.bw,
                self.aphi, self.ah, self.aw)

    @property
    def all_asperities(self) -> NDArray[np.int64]:
        """Index list selecting every asperity."""
        return np.arange(self.aphi.size, dtype=np.int64)

    @property
    def min_width(self) -> float:
        """Narrowest bump or asperity [rad] (inf without any)."""
        w = np.concatenate([self.bw, self.aw])
        return float(np.min(w)) if w.size else math.inf


def contour_data(params: RigParams) -> ContourData:
    """Build :class:`ContourData` from parameters (bumps and asperities both included)."""
    c = params.frame.contour
    t = params.track
    aphi = np.mod(np.asarray(t.asperity_phi, float), 2.0 * np.pi)
    order = np.argsort(aphi, kind="stable")
    return ContourData(
        rho0=float(c.a),
        orders=np.array([2.0, *[float(k) for k in c.harmonic_orders]]),
        ccos=np.array([-c.b, *c.harmonic_cos], dtype=float),
        csin=np.array([0.0, *c.harmonic_sin], dtype=float),
        bphi=np.asarray(t.bump_phi, float),
        bh=np.asarray(t.bump_height, float),
        bw=np.asarray(t.bump_width, float),
        aphi=aphi[order],
        ah=np.asarray(t.asperity_height, float)[order],
        aw=np.asarray(t.asperity_width, float)[order],
    )


@njit_inline
def rho012(phi, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, na):  # noqa: ANN001, ANN201
    """rho, rho', rho'' at a scalar phi: harmonics, every bump, asperities ``aidx[:na]``.

    A bump of height h and width w at phi_i adds ``h exp(-x^2 / 2)``, ``x = d / w`` with d
    the wrapped angle ``phi - phi_i`` (as :func:`bfr_model.geometry.contour_kernel`). Also
    returns ``sin(phi)``, ``cos(phi)``; integer harmonic orders are evaluated by the
    angle-addition recurrence from them.
    """
    s1 = math.sin(phi)
    c1 = math.cos(phi)
    r0 = rho0
    r1 = 0.0
    r2 = 0.0
    ck = 1.0
    sk = 0.0
    kk = 0
    for i in range(orders.shape[0]):
        k = orders[i]
        ki = int(k)
        if ki == k and ki >= kk:
            while kk < ki:
                ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
                kk += 1
            c = ck
            s = sk
        else:
            c = math.cos(k * phi)
            s = math.sin(k * phi)
        r0 += ccos[i] * c + csin[i] * s
        r1 += k * (-ccos[i] * s + csin[i] * c)
        r2 -= k * k * (ccos[i] * c + csin[i] * s)
    for i in range(bphi.shape[0]):
        w = bw[i]
        d = (phi - bphi[i] + math.pi) % (2.0 * math.pi) - math.pi
        x = d / w
        g = bh[i] * math.exp(-0.5 * x * x)
        r0 += g
        r1 -= g * x / w
        r2 += g * (x * x - 1.0) / (w * w)
    for j in range(na):
        i = aidx[j]
        w = aw[i]
        d = (phi - aphi[i] + math.pi) % (2.0 * math.pi) - math.pi
        x = d / w
        if abs(x) < 12.0:
            g = ah[i] * math.exp(-0.5 * x * x)
            r0 += g
            r1 -= g * x / w
            r2 += g * (x * x - 1.0) / (w * w)
    return r0, r1, r2, s1, c1


@njit_inline
def contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, na):  # noqa: ANN001, ANN201
    """delta, delta', delta'' at phi (frame coordinates), as six floats."""
    r0, r1, r2, s, c = rho012(phi, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx,
                              na)
    return (r0 * s, r0 * c, r1 * s + r0 * c, r1 * c - r0 * s,
            (r2 - r0) * s + 2.0 * r1 * c, (r2 - r0) * c - 2.0 * r1 * s)


@njit
def newton_closest(cx, cy, phi0, maxit, tol, max_step, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN201
                   bw, aphi, ah, aw, aidx, na):  # noqa: ANN001
    """Local minimiser of ``|delta(phi) - c|`` near phi0 by Newton's method (module doc).

    Parameters
    ----------
    cx, cy : float
        Ball centre in frame coordinates [m].
    phi0 : float
        Initial guess [rad].
    maxit : int
        Iteration limit.
    tol : float
        Stop when the Newton step is below tol [rad].
    max_step : float
        Largest step [rad]; where ``f' <= 0`` a descent step of this size is taken.

    Returns
    -------
    tuple
        ``(phi, d, f, fp, it)``: the minimiser [rad], the distance [m], ``f`` [m^2] and
        ``f'`` [m^2] there, and the iterations used.
    """
    phi = phi0
    it = 0
    f = 0.0
    fp = 1.0
    for it in range(1, maxit + 1):  # noqa: B007 (it is returned)
        dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi,
                                                         bh, bw, aphi, ah, aw, aidx, na)
        ex = dx - cx
        ey = dy - cy
        f = ex * d1x + ey * d1y
        fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
        if fp > 0.0:
            step = f / fp
        else:
            step = max_step if f > 0.0 else -max_step
        if step > max_step:
            step = max_step
        elif step < -max_step:
            step = -max_step
        phi -= step
        if abs(step) < tol:
            break
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh,
                                                     bw, aphi, ah, aw, aidx, na)
    ex = dx - cx
    ey = dy - cy
    f = ex * d1x + ey * d1y
    fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
    return phi, math.sqrt(ex * ex + ey * ey), f, fp, it


def closest_point(data: ContourData, c: ArrayLike, phi0: float | None = None,
                  n_grid: int | None = None, tol: float = 1e-14) -> tuple[float, float]:
    """Exact closest contour point to ``c`` (frame coordinates): ``(phi, distance)``.

    Parameters
    ----------
    data : ContourData
        The contour.
    c : array_like
        Point ``(x, y)`` [m], frame coordinates.
    phi0 : float, optional
        Initial guess [rad]; default: a global bracket on a dense sample (spacing at most a
        quarter of the narrowest bump), refined by Newton from the best few samples.
    n_grid : int, optional
        Size of the dense sample (default from the narrowest bump, at least 4096).
    tol : float
        Newton step tolerance [rad].

    Returns
    -------
    phi, d : float
        Contour angle of the closest point [rad] (the global minimiser when phi0 is None)
        and the distance [m].
    """
    cx, cy = (float(v) for v in np.asarray(c, float))
    args = data.as_args()
    idx = data.all_asperities
    na = idx.size
    w_min = min(data.min_width, 0.5)
    max_step = 0.25 * w_min
    if phi0 is not None:
        phi, d, _, _, _ = newton_closest(cx, cy, float(phi0), 200, tol, max_step, *args, idx, na)
        return float(phi), float(d)
    n = n_grid or max(4096, int(4.0 * 2.0 * np.pi / w_min))
    grid = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    dist = np.array([_dist(g, cx, cy, args, idx, na) for g in grid])
    best = (math.inf, 0.0)
    for i in np.argsort(dist)[:4]:
        phi, d, _, fp, _ = newton_closest(cx, cy, float(grid[i]), 200, tol, max_step, *args,
                                          idx, na)
        if fp > 0.0 and d < best[0]:
            best = (float(d), float(phi))
    return float(np.mod(best[1], 2.0 * np.pi)), best[0]


def _dist(phi: float, cx: float, cy: float, args: tuple, idx: NDArray[np.int64],
          na: int) -> float:
    r0 = rho012(phi, *args, idx, na)[0]
    return math.hypot(r0 * math.sin(phi) - cx, r0 * math.cos(phi) - cy)


def taylor_closest_point(data: ContourData, c: ArrayLike) -> float:
    """The seed's closest-point estimate (eqs. 4.33-4.37): one Newton step from phi_b.

    ``phi_b = atan2(c_x, c_y)`` is the ball centre's own polar angle (clockwise from the
    frame's +y axis, as phi); the second-order Taylor polynomial of
    ``D_nl(phi*) = |delta(phi_b + phi*) - c|^2`` has its vertex at
    ``phi* = -D_nl'(0) / D_nl''(0) = -f(phi_b) / f'(phi_b)``.

    Returns
    -------
    float
        Estimated contact angle [rad] (compare with :func:`closest_point`).
    """
    cx, cy = (float(v) for v in np.asarray(c, float))
    phi_b = math.atan2(cx, cy)
    idx = data.all_asperities
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi_b, *data.as_args(), idx, idx.size)
    f = (dx - cx) * d1x + (dy - cy) * d1y
    fp = d1x * d1x + d1y * d1y + (dx - cx) * d2x + (dy - cy) * d2y
    return phi_b - f / fp


def seed_eq_4_36(a: float, b: float, r_b: float, theta_rel: float) -> float:
    """The seed's printed eq. 4.36 for its contour ``rho = a + b cos 2 t``, verbatim.

    ``phi* = -b (2 a sin 2t - 2 r_b sin 2t + 2 b cos 2t sin 2t)
    / (a r_b - 4 b^2 (2 cos^2 2t - 1) - 4 a b cos 2t + 5 b r_b cos 2t)``.

    In our conventions (``rho = a - b cos 2 phi``) ``seed_eq_4_36(a, -b, r_b, phi_b)`` is
    exactly ``-(phi_T - phi_b)`` of :func:`taylor_closest_point`: the same magnitude, the
    opposite sign. The seed's eq. 4.35 writes the parabola's vertex as ``beta / (2 alpha)``
    instead of ``-beta / (2 alpha)``, and 4.36 inherits the sign; we use the vertex.
    """
    s2 = math.sin(2.0 * theta_rel)
    c2 = math.cos(2.0 * theta_rel)
    num = b * (2.0 * a * s2 - 2.0 * r_b * s2 + 2.0 * b * c2 * s2)
    den = a * r_b - 4.0 * b * b * (2.0 * c2 * c2 - 1.0) - 4.0 * a * b * c2 + 5.0 * b * r_b * c2
    return -num / den
