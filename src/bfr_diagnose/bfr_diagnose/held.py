"""The ball on a held frame, in closed form: where it rests, how its path curves, its period.

Method
------
With the frame held at theta_0 (``theta_dot = theta_ddot = 0``) the rigid model's ball row
(:mod:`bfr_model.dynamics`, the second row of ``M q'' + C q' + G = B u``) is one
conservative degree of freedom:

    m22(phi) phi'' + (1/2) m22'(phi) phi'^2 + G2(theta_0, phi) = 0                    (1)

(``C`` of :meth:`~bfr_model.dynamics.RigidModel.coriolis_matrix` at ``theta_dot = 0``;
rolling resistance is left out: it damps the swing and hardly moves its period. A creeping
spin is left out too: it is not rolling's, and a swing measures the spin share the ball
shows). Its rest points are the roots of ``G2`` with ``dG2/dphi > 0``; there the ball's
centre is at the lowest point of its path (the potential is ``m_b g y_c``), and small
swings about it have

    omega_0^2 = (dG2/dphi) / m22.                                                       (2)

For the seed's contour ``r = a - b cos 2 phi`` with the frame level and the ball in the
upper waist, (2) is, in closed form (an independent derivation, tested against (1)),

    omega_0^2 = g / ((rho_c - R) (1 + J_b / (m_b R^2))),    rho_c = (a - b)^2 / (5 b - a)  (3)

``rho_c`` the waist's radius of curvature (concave where ``5 b > a``), ``rho_c - R`` that of
the ball centre's path, ``kappa = J_b / (m_b R^2)`` the spin's share of the ball's kinetic
energy (the ball rolls about the line through its two contacts, its centre R from it: its
kinetic energy is ``m_b v_c^2 (1 + kappa) / 2`` on any path).

So on any path a rolling ball swings like a frictionless bead on its centre's path, slowed
by ``sqrt(1 + kappa)`` at every amplitude:

    T_ball(E) = sqrt(1 + kappa) T_bead(E)                                               (4)

(``E`` the swing's height above the rest point). A held frame thus measures, with no torque,
drive, controller or fit in the way: where the ball rests, how its centre's path runs (the
contour less R), and, from each swing's period against the bead's on the measured path, the
spin's share.

**Measured** (:func:`measure_swing`), from the camera's ball centre ``(x, y)`` on the held
part as the camera reports it (world frame, shaft at the origin, y up):

(a) *path*: ``y = p(x)``, a polynomial of degree 2 to :data:`PATH_DEGREE` (by BIC) fitted
    by least squares to every sample; the rest point is its lowest point over the samples'
    range, the path's radius of curvature there ``1 / p''(x_r)``;
(b) *swings*: a swing runs from one upward zero crossing of ``x - x_r`` to the next (the
    crossings linearly interpolated: there the centre moves fastest, so a camera's noise
    moves them least), over one maximum and one minimum; its period the time between the
    crossings, its amplitude half the peak-to-peak excursion of x over it, its height ``E``
    the mean of the path's heights above the rest point at its three extremes;
(c) *spin share* (:func:`closed_form`): per swing ``kappa_i = (T_i / T_bead(E_i))^2 - 1``
    by (4), ``T_bead`` the bead's period at ``E_i`` on ``p`` (integrated, no small-swing
    extrapolation); their mean and a t interval over the swings.

**Predicted** (:func:`model_swing`), the same on the model: its stable rest point (positive
normal force) nearest the measured one; the radius of its centre's path there (the
parametric curve's, exact); each swing released from rest at the turning point right of the rest
point whose swing has the measured amplitude (half peak-to-peak: the turning point left of
rest at the same height), integrated by (1) (``solve_ivp``, DOP853, ``rtol`` 1e-10) out and
back; NaN where the swing would pass a crest of the valley.

What it rests on: the camera's scale (a scale s multiplies the path's lengths, so ``1 +
kappa`` by ``1 / s``); for the rolling radius from the rest point, the camera's offset and the
contour's height at the rest point (:func:`closed_form`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel, mass_terms
from bfr_model.params import RigParams
from numpy.polynomial import Polynomial
from numpy.typing import NDArray
from scipy import stats
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.signal import find_peaks

from bfr_diagnose.preprocess import Prepared, segments_from_mask

__all__ = ["HeldSwing", "bead_period", "closed_form", "held_frame_check", "measure_swing",
           "model_swing", "spin_share", "waist_period"]

FloatArray = NDArray[np.float64]

#: [m] Smallest prominence of a swing's extreme (beside 20 times the camera's noise): a
#: swing smaller than this is not timed.
MIN_PROMINENCE = 2e-4
#: [m] Smallest excursion of the centre (peak to peak in x) whose path is fitted.
MIN_EXCURSION = 2e-3
#: Degree of the polynomial path ``y = p(x)``.
PATH_DEGREE = 6
#: [rad] Largest spread (1st to 99th percentile) of the held frame's angle over the part:
#: one path needs one angle (a held frame whose encoder flickers by a count or two is one).
MAX_THETA_SPREAD = 0.01
#: [m] Largest distance of a model's rest point from the measured one.
MAX_REST_OFFSET = 0.02
#: The most swings timed (spread over their amplitudes): each model integrates each one.
MAX_SWINGS = 12
#: [s] The longest half swing the integrations follow.
MAX_PERIOD = 20.0


@dataclass(frozen=True, kw_only=True)
class HeldSwing:
    """The ball's rest point, path and swings on a held frame (measured or predicted).

    Attributes
    ----------
    theta : float
        [rad] The frame's angle.
    rest_x, rest_y : float
        [m] The ball centre's rest point (the lowest point of its path), world frame.
    path_radius : float
        [m] The radius of curvature of the centre's path at the rest point.
    amplitudes : ndarray
        [m] Each swing's amplitude (half its peak-to-peak horizontal excursion).
    periods : ndarray
        [s] Each swing's period (NaN where the model's ball does not come back).
    heights : ndarray
        [m] Each swing's height above the rest point (measured; empty for a model).
    times : ndarray
        [s] Each swing's start (measured; empty for a model).
    path : Polynomial or None
        ``y(x)`` of the centre's path (world frame).
    """

    theta: float
    rest_x: float
    rest_y: float
    path_radius: float
    amplitudes: FloatArray = field(default_factory=lambda: np.zeros(0))
    periods: FloatArray = field(default_factory=lambda: np.zeros(0))
    heights: FloatArray = field(default_factory=lambda: np.zeros(0))
    times: FloatArray = field(default_factory=lambda: np.zeros(0))
    path: Polynomial | None = None

    @property
    def rest_distance(self) -> float:
        """[m] The rest point's distance from the shaft."""
        return float(math.hypot(self.rest_x, self.rest_y))


def _path(x: FloatArray, y: FloatArray) -> tuple[Polynomial, float, float, float]:
    """The path ``y = p(x)`` and its rest point and radius: ``(p, x_r, y_r, radius)``.

    The degree (2 to :data:`PATH_DEGREE`) by the Bayesian information criterion: a short
    noisy path is not given the terms only its noise supports.
    """
    best = None
    for deg in range(2, PATH_DEGREE + 1):
        try:
            q = Polynomial.fit(x, y, deg)
        except np.linalg.LinAlgError as exc:  # least squares did not converge
            raise ValueError(f"no path of degree {deg} fits the ball's positions ({exc})") \
                from exc
        rss = float(np.sum((q(x) - y) ** 2))
        bic = x.size * math.log(max(rss, 1e-300) / x.size) + (deg + 1) * math.log(x.size)
        if best is None or bic < best[0]:
            best = (bic, q)
    p = best[1]
    lo, hi = float(np.min(x)), float(np.max(x))
    grid = np.linspace(lo, hi, 2001)
    k = int(np.argmin(p(grid)))
    if k in (0, grid.size - 1):
        raise ValueError("the path has no lowest point inside the samples: no rest point")
    d = p.deriv()
    xr = float(brentq(d, grid[k - 1], grid[k + 1], xtol=1e-12)) if d(grid[k - 1]) * d(
        grid[k + 1]) < 0.0 else float(grid[k])
    curv = float(p.deriv(2)(xr))
    if curv <= 0.0:
        raise ValueError("the path does not curve upwards at its lowest point")
    return p, xr, float(p(xr)), 1.0 / curv


def _up_crossing(t: FloatArray, v: FloatArray, i: int, j: int) -> float | None:
    """The time ``v`` last rises through zero in ``[i, j]`` (linear interpolation)."""
    k = np.nonzero((v[i:j] < 0.0) & (v[i + 1:j + 1] >= 0.0))[0]
    if k.size == 0:
        return None
    k = i + int(k[-1])
    return float(t[k] - v[k] * (t[k + 1] - t[k]) / (v[k + 1] - v[k]))


def _swings(t: FloatArray, v: FloatArray, prominence: float) -> list[tuple[float, ...]]:
    """``(start, period, right, left, right')`` of each swing of ``v`` (one segment).

    A swing runs from one upward zero crossing to the next, over one maximum and one minimum
    of at least ``prominence`` (the crossings, where the centre moves fastest, time it far
    better than its turning points do); ``right``, ``left``, ``right'`` its extremes: the
    maxima before and after it and its minimum.
    """
    hi, _ = find_peaks(v, prominence=prominence)
    lo, _ = find_peaks(-v, prominence=prominence)
    ext = sorted([(int(i), 1) for i in hi if v[i] > 0.0] + [(int(i), -1) for i in lo
                                                            if v[i] < 0.0])
    # upward crossings between a minimum and the maximum right after it
    ups: list[tuple[float, int]] = []
    for (i, si), (j, sj) in itertools.pairwise(ext):
        if si < 0 < sj:
            c = _up_crossing(t, v, i, j)
            if c is not None:
                ups.append((c, j))
    out = []
    for (c0, peak0), (c1, peak1) in itertools.pairwise(ups):
        inside = [e for e in ext if peak0 <= e[0] <= peak1]
        if [sg for _, sg in inside] != [1, -1, 1]:
            continue  # not one maximum, one minimum, one maximum
        out.append((c0, c1 - c0, float(v[inside[0][0]]), float(v[inside[1][0]]),
                    float(v[inside[2][0]])))
    return out


def measure_swing(t: FloatArray, x: FloatArray, y: FloatArray, theta: float,
                  noise: float = 0.0) -> HeldSwing:
    """The ball's rest point, path and swings on a held frame, from its centre's positions.

    Parameters
    ----------
    t : ndarray
        [s] Sample times; NaN positions split the samples into segments (a swing is timed
        within one segment).
    x, y : ndarray
        [m] The ball centre, world frame (shaft at the origin, y up).
    theta : float
        [rad] The frame's angle.
    noise : float
        [m] The camera's noise per axis (the swings' prominence is at least 20 times it).

    Raises
    ------
    ValueError
        The centre did not move enough (:data:`MIN_EXCURSION`) or its path has no lowest
        point that curves up.
    """
    ok = np.isfinite(x) & np.isfinite(y)
    if np.count_nonzero(ok) < 20:
        raise ValueError("fewer than 20 ball positions")
    xo, yo = x[ok], y[ok]
    if float(np.ptp(xo)) < MIN_EXCURSION:
        raise ValueError(f"the ball's centre moved {np.ptp(xo) * 1e3:.2f} mm: too little to "
                         "see its path")
    p, rest_x, rest_y, radius = _path(xo, yo)
    prom = max(20.0 * noise, MIN_PROMINENCE)
    swings = []
    for i, j in segments_from_mask(ok):
        swings += _swings(t[i:j], x[i:j] - rest_x, prom)
    s = np.array(swings, float).reshape(-1, 5)
    amps = 0.5 * (0.5 * (s[:, 2] + s[:, 4]) - s[:, 3])
    heights = np.mean(p(rest_x + s[:, 2:5]), axis=1) - rest_y
    keep = _spread(amps, MAX_SWINGS)
    return HeldSwing(theta=float(theta), rest_x=rest_x, rest_y=rest_y, path_radius=radius,
                     amplitudes=amps[keep], periods=s[keep, 1], heights=heights[keep],
                     times=s[keep, 0], path=p)


def _spread(amps: FloatArray, n: int) -> NDArray[np.intp]:
    """Indices of at most ``n`` swings spread evenly over their amplitudes, in time order."""
    if amps.size <= n:
        return np.arange(amps.size)
    order = np.argsort(amps)
    return np.sort(order[np.round(np.linspace(0, amps.size - 1, n)).astype(int)])


def _turn(direction: float, sign: float = 1.0) -> Any:
    """A terminal event: ``sign`` times the rate crossing zero in ``direction``."""
    def ev(_t: float, s: FloatArray) -> float:
        return sign * float(s[1])

    ev.terminal = True  # type: ignore[attr-defined]
    ev.direction = direction  # type: ignore[attr-defined]
    return ev


def _out_and_back(rhs: Any, start: FloatArray, sign: float) -> float:
    """The period of a swing released from rest at ``start``; NaN if it does not come back.

    Out to the other turning point and back (``sign``: +1 when the coordinate first
    decreases), each half at most :data:`MAX_PERIOD`.
    """
    t = 0.0
    state = start
    for direction in (1.0, -1.0):
        sol = solve_ivp(rhs, (0.0, MAX_PERIOD), state, method="DOP853", rtol=1e-10,
                        atol=1e-12, events=_turn(direction, sign))
        if not sol.t_events[0].size:
            return math.nan
        t += float(sol.t_events[0][0])
        state = sol.y_events[0][0]
    return t


def _other_side(f: Any, h: float, start: float, step: float, limit: float) -> float | None:
    """Where the height ``f`` first rises to ``h``, walking from ``start`` by ``step``.

    None if it turns down first (a crest) or the walk would pass ``limit``.
    """
    prev_v, prev_u = start, f(start)
    u = start
    while abs(u + step - start) <= limit:
        u = prev_v + step
        fu = f(u)
        if fu >= h:
            return float(brentq(lambda z: f(z) - h, prev_v, u, xtol=1e-13))
        if fu < prev_u:
            return None
        prev_v, prev_u = u, fu
    return None


def bead_period(path: Polynomial, x_r: float, height: float, gravity: float) -> float:
    """[s] The period of a frictionless bead on ``y = path(x)``, ``height`` above ``x_r``.

    ``x'' (1 + y'^2) + y' y'' x'^2 + g y' = 0``, released from rest at the turning point
    right of the lowest point ``x_r``. NaN where the path, within its samples' range, holds
    no swing that high on both sides.
    """
    d1, d2 = path.deriv(), path.deriv(2)
    y_r = float(path(x_r))
    lo, hi = (float(v) for v in path.domain)  # the samples' range: no extrapolation
    x2 = _other_side(lambda z: float(path(z)) - y_r, height, x_r, 1e-4, hi - x_r)
    x1 = _other_side(lambda z: float(path(z)) - y_r, height, x_r, -1e-4, x_r - lo)
    if x1 is None or x2 is None:
        return math.nan

    def rhs(_t: float, s: FloatArray) -> FloatArray:
        a, b = float(d1(s[0])), float(d2(s[0]))
        return np.array([s[1], -(gravity * a + a * b * s[1] ** 2) / (1.0 + a * a)])

    return _out_and_back(rhs, np.array([x2, 0.0]), 1.0)


class _Ball:
    """The ball row (1) of one model on a frame held at theta."""

    def __init__(self, params: RigParams, theta: float) -> None:
        self.model = RigidModel(params)
        self.theta = float(theta)

    def g2(self, phi: float | FloatArray) -> FloatArray:
        """``G2(theta, phi)`` [N m]."""
        return self.model.gravity_vector(self.theta, phi)[..., 1]

    def rhs(self, _t: float, s: FloatArray) -> FloatArray:
        m = mass_terms(np.asarray(s[0], float), *self.model.kernel_args)
        m22, d22 = float(m[2]), float(m[5])
        return np.array([s[1], -(0.5 * d22 * s[1] ** 2 + float(self.g2(s[0]))) / m22])

    def centre(self, phi: float | FloatArray) -> FloatArray:
        """The ball centre (x, y) [m] at contact angle(s) phi."""
        phi = np.asarray(phi, float)
        x = np.stack([np.full_like(phi, self.theta), phi, 0.0 * phi, 0.0 * phi], -1)
        return self.model.ball_position(x)

    def rest(self, near_x: float, near_y: float) -> float:
        """The stable rest angle nearest ``(near_x, near_y)`` [m].

        Among the roots of G2 with dG2/dphi > 0 whose normal force is positive (the ball on
        the edge, not under it), the one whose centre is nearest; within
        :data:`MAX_REST_OFFSET`.
        """
        ph = np.linspace(-math.pi, math.pi, 4097)
        g = np.asarray(self.g2(ph), float)
        up = np.nonzero((g[:-1] < 0.0) & (g[1:] >= 0.0))[0]
        roots = np.array([brentq(lambda p: float(self.g2(p)), ph[k], ph[k + 1], xtol=1e-13)
                          for k in up])
        if roots.size:
            fn = self.model.normal_force(np.stack([np.full_like(roots, self.theta), roots,
                                                   0.0 * roots, 0.0 * roots], -1))
            roots = roots[np.asarray(fn) > 0.0]
        if roots.size == 0:
            raise ValueError("the model has no rest point on this held frame")
        c = self.centre(roots)
        dist = np.hypot(c[:, 0] - near_x, c[:, 1] - near_y)
        k = int(np.argmin(dist))
        if dist[k] > MAX_REST_OFFSET:
            raise ValueError(f"the model's nearest rest point is {dist[k] * 1e3:.0f} mm from "
                             "the measured one")
        return float(roots[k])

    def path_radius(self, phi: float) -> float:
        """[m] The centre path's radius of curvature at phi (the offset curve's)."""
        return float(1.0 / abs(self.model.curve.curvature(phi)))


def model_swing(params: RigParams, theta: float, amplitudes: FloatArray,
                near_x: float, near_y: float, x_range: tuple[float, float]) -> HeldSwing:
    """The model's rest point, path and swing periods on a frame held at ``theta``.

    Parameters
    ----------
    params : RigParams
        The model.
    theta : float
        [rad] The frame's angle.
    amplitudes : ndarray
        [m] The swings' amplitudes (half peak-to-peak horizontal excursion of the centre).
    near_x, near_y : float
        [m] The measured rest point: the model's stable rest point nearest it is taken.
    x_range : tuple of float
        [m] The measured centre's x range relative to its rest point: the model's path is
        fitted over the same range about its own.

    Raises
    ------
    ValueError
        The model has no stable rest point with the ball on the edge within
        :data:`MAX_REST_OFFSET` of the measured one.
    """
    ball = _Ball(params, theta)
    phi_r = ball.rest(near_x, near_y)
    xr = float(ball.centre(phi_r)[0])
    dph = np.linspace(-0.8, 0.8, 3201)
    c = ball.centre(phi_r + dph)
    inside = (c[:, 0] - xr >= x_range[0]) & (c[:, 0] - xr <= x_range[1])
    # the connected piece of the path through the rest point
    mid = dph.size // 2
    lo = mid - np.argmin(inside[mid::-1]) + 1 if not inside[mid::-1].all() else 0
    hi = mid + np.argmin(inside[mid:]) if not inside[mid:].all() else dph.size
    p = Polynomial.fit(c[lo:hi, 0], c[lo:hi, 1], PATH_DEGREE)  # drawn beside the measured
    rest_x, rest_y = (float(v) for v in ball.centre(phi_r))
    radius = ball.path_radius(phi_r)
    # phi moving the centre right
    right = 1.0 if float(ball.centre(phi_r + 1e-4)[0]) > xr else -1.0
    valley = _valley(ball, phi_r, right)
    periods = np.array([_model_period(ball, valley, phi_r, right, float(a))
                        for a in amplitudes])
    return HeldSwing(theta=float(theta), rest_x=rest_x, rest_y=rest_y, path_radius=radius,
                     amplitudes=np.asarray(amplitudes, float), periods=periods, path=p)


def _valley(ball: _Ball, phi_r: float, right: float) -> tuple[FloatArray, ...]:
    """Both sides of the valley, tabulated out to their crests (5e-4 rad apart).

    ``(d, release_x, release_h, left_h, left_x)``: the release points right of rest at
    ``phi_r + right d`` (their x and height above rest, up to the right crest and no higher
    than the left one) and the left side's rising heights and their x.
    """
    d = np.linspace(0.0, 1.5, 3001)
    cr, cl = ball.centre(phi_r + right * d), ball.centre(phi_r - right * d)
    y_r = float(cr[0, 1])
    hr, hl = cr[:, 1] - y_r, cl[:, 1] - y_r
    kr, kl = _crest(hr), _crest(hl)
    i = np.arange(1, kr + 1)
    i = i[hr[i] <= hl[kl]]  # a release above the left crest goes over it
    return d[i], cr[i, 0], hr[i], hl[:kl + 1], cl[:kl + 1, 0]


def _model_period(ball: _Ball, valley: tuple[FloatArray, ...], phi_r: float, right: float,
                  amp: float) -> float:
    """The period of (1) for the swing of half peak-to-peak ``amp``; NaN past a crest.

    The release point right of rest is the one whose turning point left of rest, at the same
    height (energy is conserved), is ``2 amp`` from it in x (:func:`_valley`; the heights rise
    monotonically to the crests), interpolated between table points.
    """
    d, x_rel, h_rel, h_left, x_left_side = valley
    if d.size == 0:
        return math.nan
    half = 0.5 * (x_rel - np.interp(h_rel, h_left, x_left_side))
    if amp > half.max() or amp < half.min():
        return math.nan
    j = int(np.argmax(half >= amp))
    dr = float(d[0]) if j == 0 else float(np.interp(amp, half[j - 1:j + 1], d[j - 1:j + 1]))
    return _out_and_back(ball.rhs, np.array([phi_r + right * dr, 0.0]), right)


def _crest(h: FloatArray) -> int:
    """Index of the last point of the heights' first monotonic rise (a crest or the end)."""
    down = np.nonzero(np.diff(h) <= 0.0)[0]
    return int(down[0]) if down.size else h.size - 1


def spin_share(params: RigParams) -> float:
    """[-] The spin's share of a rolling ball's kinetic energy, ``J_b / (m_b R^2)``."""
    b = params.ball
    return b.inertia / (b.mass * b.rolling_radius ** 2)


def waist_period(params: RigParams) -> float:
    """[s] The small-swing period (3) in the upper waist of the seed's contour, frame level.

    ``2 pi sqrt((rho_c - R) (1 + J_b / (m_b R^2)) / g)``, ``rho_c = (a - b)^2 / (5 b - a)``:
    the closed form of (2) for ``r = a - b cos 2 phi`` (no harmonics, no bump; g in the
    frame's plane).
    """
    a, b = params.frame.contour.a, params.frame.contour.b
    rr = params.ball.rolling_radius
    rho_c = (a - b) ** 2 / (5.0 * b - a)
    return 2.0 * math.pi * math.sqrt((rho_c - rr) * (1.0 + spin_share(params))
                                     / params.environment.in_plane_gravity)


def closed_form(meas: HeldSwing, nominal: RigParams, pred: HeldSwing) -> dict[str, Any] | None:
    """What the swing says of the ball in closed form: its spin's share and rolling radius.

    By (4), each swing's ``kappa_i = (T_i / T_bead(E_i))^2 - 1`` on the measured path
    (:func:`bead_period`); ``kappa`` their mean, with a t interval over the swings (the
    swings' scatter; the camera's scale is taken as calibrated: ``1 + kappa`` scales with its
    inverse). Then ``R_spin = sqrt((J_b / m_b) / kappa)`` with the nominal ball's ``J_b /
    m_b`` (a weighed ball and its shell). Beside it, from the rest point, ``R_rest =
    R_nominal + (d_rest - d_rest,nominal)`` (the ball's centre rides R above the edge): it
    rests on the camera's offset and on the contour's height at the rest point being the
    nominal model's, so it is a second reading, not an independent one. With both,
    ``J_b / m_b = kappa R_rest^2`` (a thin shell's is ``2 R_b^2 / 3``). None with fewer than
    three swings the bead can swing.
    """
    if meas.path is None:
        return None
    g = nominal.environment.in_plane_gravity
    bead = np.array([bead_period(meas.path, meas.rest_x, float(h), g) for h in meas.heights])
    kap = (meas.periods / bead) ** 2 - 1.0
    kap = kap[np.isfinite(kap)]
    if kap.size < 3:
        return None
    k = float(np.mean(kap))
    half = float(stats.t.ppf(0.975, kap.size - 1) * np.std(kap, ddof=1) / math.sqrt(kap.size))
    ball = nominal.ball
    r_nom = ball.rolling_radius
    jm = ball.inertia / ball.mass
    r_rest = r_nom + meas.rest_distance - pred.rest_distance

    def radius(kv: float) -> float | None:
        return math.sqrt(jm / kv) if kv > 0.0 else None

    return {
        "spin_share": k, "spin_share_ci95": [k - half, k + half],
        "spin_share_per_swing": [float(v) for v in kap],
        "spin_share_nominal": spin_share(nominal), "rolling_radius_nominal": r_nom,
        "rolling_radius_from_rest": r_rest,
        "rolling_radius_from_spin_share": radius(k),
        "rolling_radius_from_spin_share_ci95": [radius(k + half), radius(k - half)],
        "inertia_per_mass_from_both": k * r_rest ** 2, "inertia_per_mass_nominal": jm,
    }


def held_frame_check(prep: Prepared, models: dict[str, RigParams]) -> dict[str, Any]:
    """The held frame's measured rest point, path and swings beside each model's (JSON).

    Parameters
    ----------
    prep : Prepared
        A frame-held part (the camera's centre as it reports it, ``ball_xy``).
    models : dict
        Label -> parameters (``nominal``, ``corrected``, ...).

    Returns
    -------
    dict
        ``measured`` and per model ``rest_x``, ``rest_y``, ``rest_distance``,
        ``path_radius`` [m], ``amplitudes`` [m] and ``periods`` [s] (per swing),
        ``period_ratio`` (median of measured over predicted) and ``spin_share``;
        ``closed_form`` (:func:`closed_form`, against ``nominal``); ``meaning``; or
        ``{"measured": None, "why": ...}`` when the swing cannot be measured.
    """
    ok = prep.ball_ok & np.isfinite(prep.ball_xy[0])
    if not ok.any():
        return {"measured": None, "why": "no ball positions on the held frame"}
    spread = float(np.subtract(*np.percentile(prep.theta[ok], [99.0, 1.0])))
    if spread > MAX_THETA_SPREAD:
        return {"measured": None, "why": f"the frame was held at several angles (spread "
                f"{spread:.3g} rad): one path needs one angle"}
    theta = float(np.median(prep.theta[ok]))
    x = np.where(ok, prep.ball_xy[0], np.nan)
    y = np.where(ok, prep.ball_xy[1], np.nan)
    try:
        meas = measure_swing(prep.t, x, y, theta, float(prep.noise.get("camera", 0.0)))
    except ValueError as exc:
        return {"measured": None, "why": str(exc)}
    xs = x[ok] - meas.rest_x
    x_range = (float(np.min(xs)), float(np.max(xs)))
    out: dict[str, Any] = {"theta": theta, "measured": _json(meas, x_range), "models": {}}
    for label, params in models.items():
        try:
            pred = model_swing(params, theta, meas.amplitudes, meas.rest_x, meas.rest_y,
                               x_range)
        except ValueError as exc:
            out["models"][label] = {"why": str(exc)}
            continue
        d = _json(pred, x_range)
        d["spin_share"] = spin_share(params)
        ratio = meas.periods / pred.periods
        good = np.isfinite(ratio)
        d["period_ratio"] = float(np.median(ratio[good])) if good.any() else None
        out["models"][label] = d
        if label == "nominal":
            try:
                out["closed_form"] = closed_form(meas, params, pred)
            except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
                out["closed_form"] = None
                out["closed_form_why"] = str(exc)
    out["meaning"] = _meaning(out)
    return out


def _json(s: HeldSwing, x_range: tuple[float, float]) -> dict[str, Any]:
    per = s.periods[np.isfinite(s.periods)]
    d: dict[str, Any] = {
        "rest_x": s.rest_x, "rest_y": s.rest_y, "rest_distance": s.rest_distance,
        "path_radius": s.path_radius, "n_swings": int(s.periods.size),
        "amplitudes": [float(a) for a in s.amplitudes],
        "periods": [float(p) if math.isfinite(p) else None for p in s.periods],
        "times": [float(v) for v in s.times], "heights": [float(v) for v in s.heights],
        "period_median": float(np.median(per)) if per.size else None}
    if s.path is not None:
        xs = np.linspace(x_range[0], x_range[1], 81)
        d["path"] = {"x": [float(v) for v in xs],
                     "y": [float(v) for v in s.path(s.rest_x + xs) - s.rest_y]}
    return d


def _meaning(out: dict[str, Any]) -> str:
    m = out["measured"]
    amp = np.median(m["amplitudes"]) * 1e3 if m["amplitudes"] else None
    head = (f"the ball rests {m['rest_distance'] * 1e3:.1f} mm from the shaft, its path curving "
            f"with radius {m['path_radius'] * 1e3:.0f} mm there")
    if m["period_median"] is not None:
        head += (f", and swings with a period of {m['period_median']:.3g} s (median of "
                 f"{m['n_swings']} swings, amplitude {amp:.1f} mm)")
    parts = []
    for label, d in out["models"].items():
        if "why" in d:
            parts.append(f"the {label} model: {d['why']}")
            continue
        txt = (f"the {label} model {d['rest_distance'] * 1e3:.1f} mm, radius "
               f"{d['path_radius'] * 1e3:.0f} mm")
        if d.get("period_median") is not None:
            txt += f", period {d['period_median']:.3g} s"
            if d.get("period_ratio") is not None:
                txt += f" (measured / model {d['period_ratio']:.2f})"
        parts.append(txt)
    text = head + ("; " + "; ".join(parts) if parts else "")
    cf = out.get("closed_form")
    if cf and cf["rolling_radius_from_spin_share"] is not None:
        lo, hi = cf["spin_share_ci95"]
        text += (f". Each swing against a bead's on the measured path gives the spin's share "
                 f"J_b / (m_b R^2) = {cf['spin_share']:.2f} [{lo:.2f}, {hi:.2f}] (nominal "
                 f"{cf['spin_share_nominal']:.2f}; the camera's scale taken as calibrated): "
                 "with the nominal ball a rolling radius of "
                 f"{cf['rolling_radius_from_spin_share'] * 1e3:.1f} mm (nominal "
                 f"{cf['rolling_radius_nominal'] * 1e3:.1f} mm)")
    return text
