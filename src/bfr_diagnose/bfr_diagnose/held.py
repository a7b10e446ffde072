"""The ball on a held frame, in closed form: where it rests, how its path curves, its period.

Method
------
With the frame held at theta_0 (``theta_dot = theta_ddot = 0``) the rigid model's ball row
(:mod:`bfr_model.dynamics`, the second row of ``M q'' + C q' + G = B u``) is one
conservative degree of freedom:

    m22(phi) phi'' + (1/2) m22'(phi) phi'^2 + G2(theta_0, phi) = 0                    (1)

(``C`` of :meth:`~bfr_model.dynamics.RigidModel.coriolis_matrix` at ``theta_dot = 0``;
rolling resistance and creep are left out: they damp the swing and hardly move its
period). Its rest points are the roots of ``G2`` with ``dG2/dphi > 0``; there the ball's
centre is at the lowest point of its path (the potential is ``m_b g y_c``), and small
swings about it have

    omega_0^2 = (dG2/dphi) / m22.                                                       (2)

For the seed's contour ``r = a - b cos 2 phi`` with the frame level and the ball in the
upper waist, (2) is, in closed form (an independent derivation, tested against (1)),

    omega_0^2 = g / ((rho_c - R) (1 + J_b / (m_b R^2))),    rho_c = (a - b)^2 / (5 b - a)  (3)

``rho_c`` the waist's radius of curvature (concave where ``5 b > a``), ``rho_c - R`` that of
the ball centre's path, ``J_b / (m_b R^2)`` the spin's share of the ball's kinetic energy
(the ball rolls about the line through its two contacts, its centre R from it).

So a held frame measures, with no torque, drive or controller in the way, three things the
closed-loop runs see only mixed: where the ball rests (the contour's height there and R),
how its path curves there (the contour's curvature, less R) and its period (that curvature
and the spin's share together).

**Measured** (:func:`measure_swing`), from the camera's ball centre ``(x, y)`` on the held
part as the camera reports it (world frame, shaft at the origin, y up):

(a) *path*: ``y = p0 + p1 x + p2 x^2`` by least squares over the samples whose ``|x - x_m|``
    is within half the 95th percentile of the excursion (``x_m`` the median x;
    :func:`path_half_width`): the rest point is its lowest point (``x_r = -p1 / (2 p2)``)
    and its radius of curvature there ``1 / (2 p2)`` (a mean curvature over that width: a
    path that is not a circle has no one radius);
(b) *swings*: a swing runs from one upward zero crossing of ``x - x_r`` to the next (the
    crossings linearly interpolated: there the centre moves fastest, so a camera's noise
    moves them least), over one maximum and one minimum; its period the time between the
    crossings, its amplitude half the peak-to-peak excursion of x over it. (A camera offset
    moves ``x_r``, and with it the up and down crossings in opposite directions: the
    up-to-up time is unchanged to first order.)

**Predicted** (:func:`model_swing`), by the same two steps on the model: (a) the same fit on
the model's centre path over the same x range about its own rest point; (b) (1) integrated
(``solve_ivp``, DOP853, ``rtol`` 1e-10) from rest at the turning point whose centre is the
swing's amplitude right of the model's rest point, the period the time to the second
turning point (the swing out and back, exact for a potential that is not symmetric).
Amplitudes are compared as horizontal excursions of the centre from each one's own rest
point (a camera offset does not enter; a camera scale enters the amplitude, to which the
period is only weakly sensitive).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel, curve_terms, gravity_from_curve, mass_terms
from bfr_model.params import RigParams
from numpy.typing import NDArray
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.signal import find_peaks

from bfr_diagnose.preprocess import Prepared, segments_from_mask

__all__ = ["HeldSwing", "closed_form", "held_frame_check", "measure_swing", "model_swing",
           "path_half_width", "spin_share", "waist_period"]

FloatArray = NDArray[np.float64]

#: [m] Smallest prominence of a swing's extreme (beside 20 times the camera's noise): a
#: swing smaller than this is not timed.
MIN_PROMINENCE = 2e-4
#: [m] Smallest excursion of the centre (peak to peak in x) whose path is fitted.
MIN_EXCURSION = 2e-3
#: The most swings timed (spread over their amplitudes): each model integrates each one.
MAX_SWINGS = 12
#: [s] The longest swing the model's integration follows (twice: out and back).
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
        [m] Each swing's amplitude (horizontal excursion of the centre from the rest point).
    periods : ndarray
        [s] Each swing's period (NaN where the model's ball does not come back).
    times : ndarray
        [s] Each swing's start (measured; empty for a model).
    path_x, path_y : ndarray
        [m] The centre's path relative to the rest point (a model's, over the measured
        excursion; empty for a measurement, whose samples are the path).
    """

    theta: float
    rest_x: float
    rest_y: float
    path_radius: float
    amplitudes: FloatArray = field(default_factory=lambda: np.zeros(0))
    periods: FloatArray = field(default_factory=lambda: np.zeros(0))
    times: FloatArray = field(default_factory=lambda: np.zeros(0))
    path_x: FloatArray = field(default_factory=lambda: np.zeros(0))
    path_y: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def rest_distance(self) -> float:
        """[m] The rest point's distance from the shaft."""
        return float(math.hypot(self.rest_x, self.rest_y))


def _path_fit(x: FloatArray, y: FloatArray, half_width: float, x_m: float
              ) -> tuple[float, float, float]:
    """(rest_x, rest_y, path_radius) of ``y = p0 + p1 x + p2 x^2`` within ``half_width``."""
    sel = np.abs(x - x_m) <= half_width
    if np.count_nonzero(sel) < 5:
        raise ValueError("too few samples about the rest point")
    xs = x[sel] - x_m
    p2, p1, p0 = np.polyfit(xs, y[sel], 2)
    if p2 <= 0.0:
        raise ValueError("the path does not curve upwards: no rest point")
    xr = -p1 / (2.0 * p2)
    return float(x_m + xr), float(p0 + p1 * xr + p2 * xr ** 2), float(1.0 / (2.0 * p2))


def _up_crossing(t: FloatArray, v: FloatArray, i: int, j: int) -> float | None:
    """The time ``v`` last rises through zero in ``[i, j]`` (linear interpolation)."""
    k = np.nonzero((v[i:j] < 0.0) & (v[i + 1:j + 1] >= 0.0))[0]
    if k.size == 0:
        return None
    k = i + int(k[-1])
    return float(t[k] - v[k] * (t[k + 1] - t[k]) / (v[k + 1] - v[k]))


def _swings(t: FloatArray, v: FloatArray, prominence: float
            ) -> tuple[list[float], list[float], list[float]]:
    """(start times, amplitudes, periods) of the swings of ``v`` (one segment).

    A swing runs from one upward zero crossing to the next, over one minimum and one maximum
    of at least ``prominence`` (the crossings, where the centre moves fastest, time it far
    better than its turning points do).
    """
    hi, _ = find_peaks(v, prominence=prominence)
    lo, _ = find_peaks(-v, prominence=prominence)
    ext = sorted([(int(i), 1) for i in hi if v[i] > 0.0] + [(int(i), -1) for i in lo
                                                            if v[i] < 0.0])
    # upward crossings between a minimum and the maximum right after it
    ups: list[tuple[float, int, int]] = []
    for (i, si), (j, sj) in itertools.pairwise(ext):
        if si < 0 < sj:
            c = _up_crossing(t, v, i, j)
            if c is not None:
                ups.append((c, i, j))
    starts, amps, pers = [], [], []
    for (c0, _, x0), (c1, m1, _) in itertools.pairwise(ups):
        inside = [e for e in ext if x0 <= e[0] <= m1]
        if [sg for _, sg in inside] != [1, -1]:
            continue  # not one maximum and one minimum between the two crossings
        starts.append(c0)
        amps.append(0.5 * (float(v[inside[0][0]]) - float(v[inside[1][0]])))
        pers.append(c1 - c0)
    return starts, amps, pers


def path_half_width(x: FloatArray) -> float:
    """[m] The half width of the path fit: half the 95th percentile of ``|x - median(x)|``.

    Set by the swings, not by the samples at rest (a ball that settles puts most of its
    samples at the rest point, where the path's curvature is not seen); at least half of
    :data:`MIN_EXCURSION`.
    """
    return max(0.5 * float(np.percentile(np.abs(x - np.median(x)), 95.0)),
               0.5 * MIN_EXCURSION)


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
        The centre did not move enough (:data:`MIN_EXCURSION`) or its path does not curve up.
    """
    ok = np.isfinite(x) & np.isfinite(y)
    if np.count_nonzero(ok) < 20:
        raise ValueError("fewer than 20 ball positions")
    xo, yo = x[ok], y[ok]
    x_m = float(np.median(xo))
    if float(np.ptp(xo)) < MIN_EXCURSION:
        raise ValueError(f"the ball's centre moved {np.ptp(xo) * 1e3:.2f} mm: too little to "
                         "see its path")
    rest_x, rest_y, radius = _path_fit(xo, yo, path_half_width(xo), x_m)
    prom = max(20.0 * noise, MIN_PROMINENCE)
    starts, amps, pers = [], [], []
    for i, j in segments_from_mask(ok):
        s, a, p = _swings(t[i:j], x[i:j] - rest_x, prom)
        starts += s
        amps += a
        pers += p
    keep = _spread(np.asarray(amps, float), MAX_SWINGS)
    return HeldSwing(theta=float(theta), rest_x=rest_x, rest_y=rest_y, path_radius=radius,
                     amplitudes=np.asarray(amps, float)[keep],
                     periods=np.asarray(pers, float)[keep], times=np.asarray(starts, float)[keep])


def _spread(amps: FloatArray, n: int) -> NDArray[np.intp]:
    """Indices of at most ``n`` swings spread evenly over their amplitudes, in time order."""
    if amps.size <= n:
        return np.arange(amps.size)
    order = np.argsort(amps)
    return np.sort(order[np.round(np.linspace(0, amps.size - 1, n)).astype(int)])


class _Ball:
    """The ball row (1) of one model on a frame held at theta."""

    def __init__(self, params: RigParams, theta: float) -> None:
        self.model = RigidModel(params)
        self.theta = float(theta)
        self.st, self.ct = math.sin(theta), math.cos(theta)

    def g2(self, phi: float | FloatArray) -> FloatArray:
        """``G2(theta, phi)`` [N m]."""
        g = curve_terms(np.asarray(phi, float), *self.model.kernel_args)
        return gravity_from_curve(self.st, self.ct, g[0], g[1], g[2], g[3], self.model.P)[1]

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

        Among the roots of G2 with dG2/dphi > 0, the one whose centre is nearest.
        """
        ph = np.linspace(-math.pi, math.pi, 4097)
        g = np.asarray(self.g2(ph), float)
        up = np.nonzero((g[:-1] < 0.0) & (g[1:] >= 0.0))[0]
        if up.size == 0:
            raise ValueError("the model has no rest point on this held frame")
        roots = np.array([brentq(lambda p: float(self.g2(p)), ph[k], ph[k + 1], xtol=1e-13)
                          for k in up])
        c = self.centre(roots)
        return float(roots[np.argmin(np.hypot(c[:, 0] - near_x, c[:, 1] - near_y))])


def model_swing(params: RigParams, theta: float, amplitudes: FloatArray,
                near_x: float, near_y: float, half_width: float) -> HeldSwing:
    """The model's rest point, path and swing periods on a frame held at ``theta``.

    Parameters
    ----------
    params : RigParams
        The model.
    theta : float
        [rad] The frame's angle.
    amplitudes : ndarray
        [m] The swings' amplitudes (horizontal excursion of the centre from rest).
    near_x, near_y : float
        [m] The measured rest point: the model's stable rest point nearest it is taken.
    half_width : float
        [m] The path is fitted within this of the rest point (as measured).
    """
    ball = _Ball(params, theta)
    phi_r = ball.rest(near_x, near_y)
    xr = float(ball.centre(phi_r)[0])
    # the path about the rest point, as it is measured
    dph = np.linspace(-0.6, 0.6, 1201)
    c = ball.centre(phi_r + dph)
    rest_x, rest_y, radius = _path_fit(c[:, 0], c[:, 1], half_width, xr)
    # the direction of phi in which the centre moves right
    right = 1.0 if c[-1, 0] > c[0, 0] else -1.0
    periods = np.array([_period(ball, phi_r, right, xr, float(a)) for a in amplitudes])
    yr = float(ball.centre(phi_r)[1])
    reach = 1.2 * max(float(np.max(amplitudes, initial=0.0)), half_width)
    near = np.abs(c[:, 0] - xr) <= reach
    return HeldSwing(theta=float(theta), rest_x=rest_x, rest_y=rest_y, path_radius=radius,
                     amplitudes=np.asarray(amplitudes, float), periods=periods,
                     path_x=c[near, 0][::4] - xr, path_y=c[near, 1][::4] - yr)


def _period(ball: _Ball, phi_r: float, right: float, xr: float, amp: float) -> float:
    """The period of (1) swinging ``amp`` right of the rest point.

    From rest at that turning point, the time out to the other turning point and back (NaN
    if the ball does not come back within :data:`MAX_PERIOD` each way).
    """
    def dx(d: float) -> float:
        return float(ball.centre(phi_r + right * d)[0]) - xr - amp

    try:
        d = brentq(dx, 0.0, 1.5, xtol=1e-12)
    except ValueError:
        return math.nan

    def half(state: FloatArray, direction: float) -> tuple[float, FloatArray] | None:
        """Time and state at the next turning point of (1), or None if it does not come.

        A turning point: the centre's x velocity crossing zero in ``direction``.
        """
        def turn(_t: float, s: FloatArray) -> float:
            return right * float(s[1])

        turn.terminal = True  # type: ignore[attr-defined]
        turn.direction = direction  # type: ignore[attr-defined]
        sol = solve_ivp(ball.rhs, (0.0, MAX_PERIOD), state, method="DOP853", rtol=1e-10,
                        atol=1e-12, events=turn)
        if not sol.t_events[0].size:
            return None
        return float(sol.t_events[0][0]), sol.y_events[0][0]

    out = half(np.array([phi_r + right * d, 0.0]), 1.0)  # out to the left turning point
    back = None if out is None else half(out[1], -1.0)  # and back to the right one
    return math.nan if out is None or back is None else out[0] + back[0]


def spin_share(params: RigParams) -> float:
    """[-] The spin's share of a rolling ball's kinetic energy, ``J_b / (m_b R^2)``."""
    b = params.ball
    return b.inertia / (b.mass * b.rolling_radius ** 2)


def waist_period(params: RigParams) -> float:
    """[s] The small-swing period (3) in the upper waist of the seed's contour, frame level.

    ``2 pi sqrt((rho_c - R) (1 + J_b / (m_b R^2)) / g)``, ``rho_c = (a - b)^2 / (5 b - a)``:
    the closed form of (2) for ``r = a - b cos 2 phi`` (no harmonics, no bump).
    """
    a, b = params.frame.contour.a, params.frame.contour.b
    rr = params.ball.rolling_radius
    rho_c = (a - b) ** 2 / (5.0 * b - a)
    return 2.0 * math.pi * math.sqrt((rho_c - rr) * (1.0 + spin_share(params))
                                     / params.environment.gravity)


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
        ``path_radius`` [m], ``amplitudes`` [m] and ``periods`` [s] (per swing), and per
        model ``period_ratio`` (median of measured over predicted), ``meaning``; or
        ``{"measured": None, "why": ...}`` when the swing cannot be measured.
    """
    ok = prep.ball_ok & np.isfinite(prep.ball_xy[0])
    theta = float(np.median(prep.theta[ok])) if ok.any() else float(np.median(prep.theta))
    x = np.where(ok, prep.ball_xy[0], np.nan)
    y = np.where(ok, prep.ball_xy[1], np.nan)
    try:
        meas = measure_swing(prep.t, x, y, theta, float(prep.noise.get("camera", 0.0)))
    except ValueError as exc:
        return {"measured": None, "why": str(exc)}
    half = path_half_width(x[ok])
    out: dict[str, Any] = {"theta": theta, "measured": _json(meas), "models": {}}
    for label, params in models.items():
        try:
            pred = model_swing(params, theta, meas.amplitudes, meas.rest_x, meas.rest_y,
                               half)
        except ValueError as exc:
            out["models"][label] = {"why": str(exc)}
            continue
        d = _json(pred)
        d["spin_share"] = spin_share(params)
        ratio = meas.periods / pred.periods
        good = np.isfinite(ratio)
        d["period_ratio"] = float(np.median(ratio[good])) if good.any() else None
        out["models"][label] = d
        if label == "nominal":
            out["closed_form"] = closed_form(meas, params, pred)
    out["meaning"] = _meaning(out)
    return out


def closed_form(meas: HeldSwing, nominal: RigParams, pred: HeldSwing) -> dict[str, Any] | None:
    """What the swing says of the ball in closed form: its spin's share and rolling radius.

    (2) holds for any path: the ball rolls about the line of its contacts, so its kinetic
    energy is ``m_b v_c^2 (1 + kappa) / 2``, ``kappa = J_b / (m_b R^2)``, and its potential
    ``m_b g s^2 / (2 rho)`` along a path of radius rho. The small swing's period ``T0``
    (``T = T0 + c A^2`` fitted over the swings) and the measured path radius give

        kappa = g T0^2 / (4 pi^2 rho) - 1,        R_spin = sqrt((J_b / m_b) / kappa)

    with the nominal ball's ``J_b / m_b`` (a weighed ball and its shell; the camera's scale
    taken as calibrated: ``1 + kappa`` scales with its inverse). Beside it, from the rest
    point alone, ``R_rest = R_nominal + (d_rest - d_rest,nominal)`` (the ball's centre rides R
    above the edge; the contour's height at the rest point and the camera's offset taken as
    nominal). Two estimates resting on different assumptions: where they agree, the rolling
    radius is measured twice. Taken together (R from the rest point, kappa from the swing)
    they give the ball's own ``J_b / m_b = kappa R_rest^2`` (a thin shell's is
    ``2 R_b^2 / 3``). None with fewer than three swings.
    """
    ok = np.isfinite(meas.periods)
    if np.count_nonzero(ok) < 3:
        return None
    a2 = meas.amplitudes[ok] ** 2
    X = np.column_stack([np.ones(a2.size), a2])
    coef, res, *_ = np.linalg.lstsq(X, meas.periods[ok], rcond=None)
    t0 = float(coef[0])
    dof = max(a2.size - 2, 1)
    s2 = float(res[0]) / dof if res.size else 0.0
    se_t0 = float(math.sqrt(s2 * np.linalg.inv(X.T @ X)[0, 0]))
    g = nominal.environment.gravity
    ball = nominal.ball
    r_nom = ball.rolling_radius
    jm = ball.inertia / ball.mass
    # the ball that fits both: R from the rest point, J_b / m_b = kappa R^2 from the swing
    r_rest = r_nom + meas.rest_distance - pred.rest_distance

    def kappa(t: float) -> float:
        return g * t ** 2 / (4.0 * math.pi ** 2 * meas.path_radius) - 1.0

    k = kappa(t0)
    k_lo, k_hi = kappa(t0 - 1.96 * se_t0), kappa(t0 + 1.96 * se_t0)
    out: dict[str, Any] = {
        "small_swing_period": t0, "small_swing_period_se": se_t0,
        "spin_share": k, "spin_share_ci95": [k_lo, k_hi],
        "spin_share_nominal": spin_share(nominal), "rolling_radius_nominal": r_nom,
        "rolling_radius_from_rest": r_rest,
        "inertia_per_mass_from_both": k * r_rest ** 2,
        "inertia_per_mass_nominal": jm,
        "rolling_radius_from_spin_share": math.sqrt(jm / k) if k > 0.0 else None,
        "rolling_radius_from_spin_share_ci95": ([math.sqrt(jm / k_hi) if k_hi > 0 else None,
                                                 math.sqrt(jm / k_lo) if k_lo > 0 else None]),
    }
    return out


def _json(s: HeldSwing) -> dict[str, Any]:
    per = s.periods[np.isfinite(s.periods)]
    return {"rest_x": s.rest_x, "rest_y": s.rest_y, "rest_distance": s.rest_distance,
            "path_radius": s.path_radius, "n_swings": int(s.periods.size),
            "amplitudes": [float(a) for a in s.amplitudes],
            "periods": [float(p) if math.isfinite(p) else None for p in s.periods],
            "times": [float(v) for v in s.times],
            **({"path": {"x": [float(v) for v in s.path_x], "y": [float(v) for v in s.path_y]}}
               if s.path_x.size else {}),
            "period_median": float(np.median(per)) if per.size else None}


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
        text += (f". In closed form its small swing ({cf['small_swing_period']:.3g} s) and path "
                 f"give the spin's share J_b / (m_b R^2) = {cf['spin_share']:.2f} (nominal "
                 f"{cf['spin_share_nominal']:.2f}): with the nominal ball a rolling radius of "
                 f"{cf['rolling_radius_from_spin_share'] * 1e3:.1f} mm; its rest point says "
                 f"{cf['rolling_radius_from_rest'] * 1e3:.1f} mm (nominal "
                 f"{cf['rolling_radius_nominal'] * 1e3:.1f} mm)")
    return text
