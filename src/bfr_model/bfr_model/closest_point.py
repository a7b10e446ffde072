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

Sharp bumps (``track.asperity_*``) are kept in a table sorted by contour angle and padded
with their copies at ``+-2 pi``: an evaluation at ``phi`` finds the asperities within
``12`` widths of ``phi mod 2 pi`` by a binary search (:func:`rho012`), so a rough track
with hundreds of asperities costs no more than the two or three near the point. Each plate
edge has its own table (``track.asperity_edge``; :func:`contour_data` with ``edge``).

:func:`local_minima` finds every local minimum of the distance within a reach (the contact
model's event-based search): the smooth contour's closest point by Newton, the window where
the smooth contour minus the highest asperity is within reach, and in it the sign changes
of ``f`` sampled at a quarter of the narrowest asperity width, each refined by a bracketed
Newton iteration (bisection where Newton leaves the bracket).
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
TWO_PI = 2.0 * math.pi

__all__ = [
    "ContourData",
    "closest_point",
    "contour_data",
    "contour_point_terms",
    "local_minima",
    "newton_closest",
    "newton_inline",
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
        ``track.asperity_*`` of this edge sorted by centre, centres wrapped to [0, 2 pi).
    tphi, th, tw : ndarray
        The asperity table: ``aphi - 2 pi, aphi, aphi + 2 pi`` (sorted) with their heights
        and widths; one ``inf`` entry without asperities.
    span : float
        ``12`` times the widest asperity [rad] (the evaluation window); -1 without any.
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
    tphi: FloatArray
    th: FloatArray
    tw: FloatArray
    span: float

    def as_args(self) -> tuple:
        """Positional arguments of :func:`rho012` after ``phi``."""
        return (self.rho0, self.orders, self.ccos, self.csin, self.bphi, self.bh, self.bw,
                self.tphi, self.th, self.tw, self.span)

    def smooth_args(self) -> tuple:
        """As :meth:`as_args` with the asperities left out (``span = -1``)."""
        return (*self.as_args()[:-1], -1.0)

    @property
    def min_width(self) -> float:
        """Narrowest bump or asperity [rad] (inf without any)."""
        w = np.concatenate([self.bw, self.aw])
        return float(np.min(w)) if w.size else math.inf

    @property
    def asperity_height(self) -> float:
        """Highest asperity [m] (0 without any, or when all are pits)."""
        return float(max(0.0, np.max(self.ah))) if self.ah.size else 0.0

    @property
    def asperity_min_width(self) -> float:
        """Narrowest asperity [rad] (inf without any)."""
        return float(np.min(self.aw)) if self.aw.size else math.inf


def asperity_table(aphi: FloatArray, ah: FloatArray, aw: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """``(tphi, th, tw, span)`` of :class:`ContourData` from sorted, wrapped asperities."""
    if aphi.size == 0:
        return np.array([np.inf]), np.zeros(1), np.ones(1), -1.0
    tphi = np.concatenate([aphi - 2.0 * np.pi, aphi, aphi + 2.0 * np.pi])
    order = np.argsort(tphi, kind="stable")
    return (tphi[order], np.tile(ah, 3)[order], np.tile(aw, 3)[order],
            float(12.0 * np.max(aw)))


def contour_data(params: RigParams, edge: int | None = None) -> ContourData:
    """Build :class:`ContourData` from parameters.

    Parameters
    ----------
    params : RigParams
        The rig; bumps and asperities both included.
    edge : int, optional
        1 (front plate) or 2 (back plate): only the asperities on that edge (and those on
        both, ``track.asperity_edge`` 0). Default: every asperity.
    """
    c = params.frame.contour
    t = params.track
    sel = np.ones(len(t.asperity_phi), bool)
    if edge is not None:
        if edge not in (1, 2):
            raise ValueError(f"edge must be 1 or 2, got {edge!r}")
        sel = np.isin(np.asarray(t.asperity_edges(), int), (0, edge))
    aphi = np.mod(np.asarray(t.asperity_phi, float)[sel], 2.0 * np.pi)
    order = np.argsort(aphi, kind="stable")
    aphi = aphi[order]
    ah = np.asarray(t.asperity_height, float)[sel][order]
    aw = np.asarray(t.asperity_width, float)[sel][order]
    tphi, th, tw, span = asperity_table(aphi, ah, aw)
    return ContourData(
        rho0=float(c.a),
        orders=np.array([2.0, *[float(k) for k in c.harmonic_orders]]),
        ccos=np.array([-c.b, *c.harmonic_cos], dtype=float),
        csin=np.array([0.0, *c.harmonic_sin], dtype=float),
        bphi=np.asarray(t.bump_phi, float),
        bh=np.asarray(t.bump_height, float),
        bw=np.asarray(t.bump_width, float),
        aphi=aphi, ah=ah, aw=aw, tphi=tphi, th=th, tw=tw, span=span,
    )


@njit_inline
def rho012(phi, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span):  # noqa: ANN001, ANN201
    """rho, rho', rho'' at a scalar phi: harmonics, every bump, the asperities near phi.

    A bump of height h and width w at phi_i adds ``h exp(-x^2 / 2)``, ``x = d / w`` with d
    the wrapped angle ``phi - phi_i`` (as :func:`bfr_model.geometry.contour_kernel`); an
    asperity of the table ``tphi, th, tw`` the same for ``|x| < 12``, found by a binary
    search for ``phi mod 2 pi +- span`` (module docstring; ``span < 0``: none). Also
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
    if span > 0.0:
        pw = phi - TWO_PI * math.floor(phi / TWO_PI)
        n = tphi.shape[0]
        i = np.searchsorted(tphi, pw - span)
        top = pw + span
        while i < n and tphi[i] <= top:
            w = tw[i]
            x = (pw - tphi[i]) / w
            if abs(x) < 12.0:
                g = th[i] * math.exp(-0.5 * x * x)
                r0 += g
                r1 -= g * x / w
                r2 += g * (x * x - 1.0) / (w * w)
            i += 1
    return r0, r1, r2, s1, c1


@njit_inline
def contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span):  # noqa: ANN001, ANN201
    """delta, delta', delta'' at phi (frame coordinates), as six floats."""
    r0, r1, r2, s, c = rho012(phi, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span)
    return (r0 * s, r0 * c, r1 * s + r0 * c, r1 * c - r0 * s,
            (r2 - r0) * s + 2.0 * r1 * c, (r2 - r0) * c - 2.0 * r1 * s)


@njit
def newton_closest(cx, cy, phi0, maxit, tol, max_step, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN201
                   bw, tphi, th, tw, span):  # noqa: ANN001
    """Local minimiser of ``|delta(phi) - c|`` near phi0 (:func:`newton_inline`, compiled)."""
    return newton_inline(cx, cy, phi0, maxit, tol, max_step, rho0, orders, ccos, csin, bphi,
                         bh, bw, tphi, th, tw, span)


@njit_inline
def newton_inline(cx, cy, phi0, maxit, tol, max_step, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN201
                  bw, tphi, th, tw, span):  # noqa: ANN001
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
    rho0, ..., span
        The contour (:meth:`ContourData.as_args`).

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
                                                         bh, bw, tphi, th, tw, span)
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
                                                     bw, tphi, th, tw, span)
    ex = dx - cx
    ey = dy - cy
    f = ex * d1x + ey * d1y
    fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
    return phi, math.sqrt(ex * ex + ey * ey), f, fp, it


@njit
def _f_fp(phi, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span):  # noqa: ANN001, ANN202
    """``(f, f', d)`` at phi: the distance's derivative, its own derivative, the distance."""
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh,
                                                     bw, tphi, th, tw, span)
    ex = dx - cx
    ey = dy - cy
    return (ex * d1x + ey * d1y, d1x * d1x + d1y * d1y + ex * d2x + ey * d2y,
            math.sqrt(ex * ex + ey * ey))


@njit
def _bracketed_minimum(cx, cy, a, b, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,  # noqa: ANN001, ANN202
                       span):  # noqa: ANN001
    """The local minimum of the distance in [a, b], given ``f(a) < 0 <= f(b)``.

    Newton's iteration kept inside the bracket (bisection where it would leave it or where
    ``f' <= 0``). Returns ``(phi, d, f')``.
    """
    phi = 0.5 * (a + b)
    fp = 0.0
    d = 0.0
    for _ in range(100):
        f, fp, d = _f_fp(phi, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,
                         span)
        if f < 0.0:
            a = phi
        else:
            b = phi
        new = phi - f / fp if fp > 0.0 else 0.5 * (a + b)
        if not a < new < b:
            new = 0.5 * (a + b)
        if abs(new - phi) < 1e-14 or b - a < 1e-15:
            phi = new
            break
        phi = new
    f, fp, d = _f_fp(phi, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span)
    return phi, d, fp


@njit
def local_minima(cx, cy, phi_base, reach, rise, spacing, max_step, rho0, orders, ccos, csin,  # noqa: ANN001, ANN201
                 bphi, bh, bw, tphi, th, tw, span, out_phi, out_d):  # noqa: ANN001
    """Every local minimum of the distance from ``c`` to the contour closer than ``reach``.

    Parameters
    ----------
    cx, cy : float
        Ball centre in frame coordinates [m].
    phi_base : float
        Guess of the smooth contour's closest point (the previous one) [rad].
    reach : float
        Distance within which minima are wanted [m].
    rise : float
        Highest asperity [m] (how much closer than the smooth contour the track can come).
    spacing : float
        Sample spacing where asperities are [rad] (a quarter of the narrowest).
    max_step : float
        Newton's step limit [rad].
    rho0, ..., span
        The contour (:meth:`ContourData.as_args`).
    out_phi, out_d : ndarray
        Filled with the minima's angles [rad] and distances [m], nearest first.

    Returns
    -------
    tuple
        ``(n, phi_s)``: the number of minima written (at most ``out_phi.size``) and the smooth
        contour's closest point (the next call's ``phi_base``). With none within reach, the
        nearest minimum from ``phi_s`` is written (n = 1).
    """
    # the smooth contour's closest point
    phi_s, d_s, _, _, _ = newton_closest(cx, cy, phi_base, 60, 1e-14, max_step, rho0, orders,
                                         ccos, csin, bphi, bh, bw, tphi, th, tw, -1.0)
    cap = out_phi.shape[0]
    n = 0
    lim = reach + rise
    if span > 0.0 and d_s < lim:
        # the window where the smooth contour (less the highest asperity) is within reach
        step = 4e-3
        lo = phi_s
        for _ in range(2000):
            lo -= step
            if _f_fp(lo, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,
                     -1.0)[2] >= lim:
                break
        hi = phi_s
        for _ in range(2000):
            hi += step
            if _f_fp(hi, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,
                     -1.0)[2] >= lim:
                break
        # any asperity within reach of the window?
        lw = lo - TWO_PI * math.floor(lo / TWO_PI)
        i = np.searchsorted(tphi, lw - span)
        if i < tphi.shape[0] and tphi[i] <= lw + (hi - lo) + span:
            ns = math.ceil((hi - lo) / spacing)
            sp = (hi - lo) / ns
            p_prev = lo
            f_prev = _f_fp(lo, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,
                           span)[0]
            for k in range(1, ns + 1):
                p = lo + k * sp
                f = _f_fp(p, cx, cy, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,
                          span)[0]
                if f_prev < 0.0 <= f:
                    pm, dm, fpm = _bracketed_minimum(cx, cy, p_prev, p, rho0, orders, ccos,
                                                     csin, bphi, bh, bw, tphi, th, tw, span)
                    if fpm > 0.0 and dm < reach:
                        n = _insert_sorted(out_phi, out_d, n, cap, pm, dm)
                p_prev = p
                f_prev = f
        elif d_s < reach:
            out_phi[0] = phi_s
            out_d[0] = d_s
            n = 1
    elif span <= 0.0 and d_s < reach:
        out_phi[0] = phi_s
        out_d[0] = d_s
        n = 1
    if n == 0:
        phi, d, _, _, _ = newton_closest(cx, cy, phi_s, 200, 1e-14, max_step, rho0, orders,
                                         ccos, csin, bphi, bh, bw, tphi, th, tw, span)
        out_phi[0] = phi
        out_d[0] = d
        n = 1
    return n, phi_s


@njit_inline
def _insert_sorted(out_phi, out_d, n, cap, phi, d):  # noqa: ANN001, ANN202
    """Insert (phi, d) into the first n entries kept sorted by d (at most cap); new n."""
    if n == cap and d >= out_d[n - 1]:
        return n
    j = min(n, cap - 1)
    while j > 0 and out_d[j - 1] > d:
        out_phi[j] = out_phi[j - 1]
        out_d[j] = out_d[j - 1]
        j -= 1
    out_phi[j] = phi
    out_d[j] = d
    return min(n + 1, cap)


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
    w_min = min(data.min_width, 0.5)
    max_step = 0.25 * w_min
    if phi0 is not None:
        phi, d, _, _, _ = newton_closest(cx, cy, float(phi0), 200, tol, max_step, *args)
        return float(phi), float(d)
    n = n_grid or max(4096, int(4.0 * 2.0 * np.pi / w_min))
    grid = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    dist = np.array([_dist(g, cx, cy, args) for g in grid])
    best = (math.inf, 0.0)
    for i in np.argsort(dist)[:4]:
        phi, d, _, fp, _ = newton_closest(cx, cy, float(grid[i]), 200, tol, max_step, *args)
        if fp > 0.0 and d < best[0]:
            best = (float(d), float(phi))
    return float(np.mod(best[1], 2.0 * np.pi)), best[0]


def _dist(phi: float, cx: float, cy: float, args: tuple) -> float:
    r0 = rho012(phi, *args)[0]
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
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi_b, *data.as_args())
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
