"""Ball-state estimator: contact angle phi and its rate from late, noisy camera fixes.

What the rig gives the controller: the frame angle theta and rate theta_dot from the encoder
at every control step, and now and then a camera fix of the ball centre, world ``(x, y)``
[m], stamped with its exposure time and a validity flag, some milliseconds late.

Measurement. The ball-centre angle, clockwise from the frame's +y axis (the rig's logged
``phi``), is ``psi = theta(t_exp) + atan2(x, y)`` (world = Rot(theta) frame, DEVELOPERS.md), with
theta at the exposure time interpolated from the encoder history (cubic Hermite in theta,
theta_dot). The contact angle is ``phi = phi_of_psi(psi)``, the inverse of
``bfr_model.geometry.OffsetCurve.ball_angle``, tabulated once. Its noise, for a camera noise
sigma [m] per axis, is ``sigma / |p(phi)| * dphi/dpsi`` [rad].

Process model. The passive row of the model, ``M21 theta_ddot + M22 phi_ddot + c2 + G2 = Q2``,
gives ``phi_ddot`` from the *measured* frame motion (theta, theta_dot, and theta_ddot as the
encoder rate's difference over the control step), so the prediction does not depend on the
frame inertia, the motor gain or the joint friction:

    phi_ddot = (Q2 - M21 theta_ddot - c2 - G2) / M22,
    c2 = -1/2 M11' theta_dot^2 + 1/2 M22' phi_dot^2,
    Q2 = -mu_rol lam tanh(phi_dot / v_r) F_n(theta_ddot)          (0 in the nominal model).

It is integrated per control step with one evaluation at the step's midpoint
(``phi += phi_dot h + a h^2 / 2``, ``phi_dot += a h``).

Filter. A Kalman filter on ``[phi, phi_dot]`` (constant-acceleration noise of density q
around the model's phi_ddot; measurement ``H = [1, 0]``). Latency is handled exactly rather
than by a delay model: the filter's estimate is kept at the time of the last fix; a new fix
with exposure time t_e is fused after propagating that estimate to t_e through the recorded
encoder history, and the result is propagated on to the present. Missing, invalid (NaN,
``valid = False``), stale (not newer than the last fix) or future-stamped fixes are
ignored: the estimate then simply runs on the model.

Gaps. Between fixes the estimate is the model's prediction driven by the measured frame
motion; its variance grows as ``P11 + 2 dt P12 + dt^2 P22 + q dt^3 / 3``. With the shipped
``accel_noise`` (q = 0.25 rad^2/s^3) the filter's own bound on the error of phi after a gap
of 0.15 s is 17 mrad (one standard deviation) and after 0.25 s 36 mrad, while the ball moves
0.36 and 0.6 rad at the orbit's 2.4 rad/s; measured in closed loop on the nominal plant the
largest error over such gaps is 6 and 15 mrad (tests/test_control_estimator.py). The
controller's supervisor rides through gaps up to ``supervisor.lost_timeout`` (0.25 s) on
this prediction.

Gate. A fix is *absurd*, and is rejected, when the ball centre it reports is further than
``radial_gate`` [m] from the ball-centre curve in the radial direction (``| |r| - |p(phi)| |``,
the camera's fix cannot be a ball on this frame), or when its innovation is larger than
``gate_sigma`` standard deviations of the predicted innovation (``|nu| > gate_sigma
sqrt(P11 + R)``). ``reinit_after`` rejected fixes in a row restart the filter from the
newest fix (the filter, not the camera, is then the one that is wrong); a fix that arrives
after a gap longer than ``max_gap`` is likewise used to restart it rather than fused.

Stamp timing. A fix stamped ``delta`` away from its true exposure puts the frame's angle at
the wrong time, ``psi_m = psi(t) + theta_dot delta``, and is compared with the prediction at
the wrong time, ``phi(t) + phi_dot delta``: the innovation is off by ``delta (dphi/dpsi
theta_dot - phi_dot)``, i.e. ``dphi/dpsi`` times the ball's *world* angular rate. A camera whose
stamps jitter (a software stamp at arrival, a driver's queue) therefore adds
``R_t = sigma_t^2 (dphi/dpsi theta_dot - phi_dot)^2`` to the measurement variance, where
``sigma_t`` is the stamps' jitter. It is not assumed: it is estimated from the stamps
themselves. Consecutive stamps differ by ``d_i = k_i T + e_i - e_(i-1)`` (``T`` the median
interval, ``k_i`` the whole frames between them: dropped frames are whole periods), so with
independent stamp errors ``sigma_t = 1.4826 MAD(d_i - k_i T) / sqrt 2`` over the last
:data:`STAMP_INTERVALS` intervals (none before :data:`STAMP_MIN_INTERVALS`). A camera whose
stamps are its exposure times gives ``sigma_t`` of rounding only and the filter is the one
above; one whose stamps jitter by milliseconds no longer has its fixes rejected by the gate
as the ball speeds up (``stamp_jitter``, reported by the controller node).

Robustness. Every path copes with an empty, one-sample or stale encoder history: a fix
whose exposure the history does not cover is not used; an encoder sample that follows the
previous one by more than ``max_gap`` restarts the filter (the ball cannot be propagated
through an encoder gap); a non-finite or absurd estimate (|phi_dot| > ``max_phi_dot``)
resets it.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from bfr_model.dynamics import RigidModel, rigid_terms
from bfr_model.geometry import offset_kernel
from bfr_model.io.timing import robust_sd
from bfr_model.jit import njit
from bfr_model.param_file import integer, positive

from bfr_control.orbit import PeriodicOrbit
from bfr_control.periodic import PeriodicTable

__all__ = ["BallEstimator", "BallObservation", "EstimatorConfig", "passive_phi_ddot"]

#: Camera stamp intervals the stamps' jitter is estimated from (module docstring).
STAMP_INTERVALS = 64
#: Intervals needed before the jitter is estimated at all.
STAMP_MIN_INTERVALS = 16


@dataclass(frozen=True, slots=True)
class BallObservation:
    """One camera fix of the ball centre.

    Attributes
    ----------
    t : float
        Exposure time [s] (the controller's clock).
    x, y : float
        Ball centre in the world frame [m] (rig: 0, 0 when no ball is seen).
    valid : bool
        The detector found the ball.
    """

    t: float
    x: float
    y: float
    valid: bool = True


@dataclass(frozen=True)
class EstimatorConfig:
    """Estimator settings.

    Attributes
    ----------
    camera_noise : float
        Standard deviation of the camera's ball position, per axis [m].
    accel_noise : float
        Density q of the white acceleration noise around the model's phi_ddot
        [rad/s^2/sqrt(Hz)] (covers model errors and the encoder rate's noise).
    phi_dot_sigma0 : float
        Standard deviation of the initial phi_dot guess [rad/s].
    history : float
        Encoder history kept for latency compensation [s].
    gate_sigma : float
        Innovation gate: a fix whose innovation exceeds this many predicted standard
        deviations is rejected [-].
    radial_gate : float
        Largest radial distance of a fix from the model's ball-centre curve [m].
    reinit_after : int
        Rejected fixes in a row after which the filter restarts from the newest one [-].
    max_gap : float
        Longest encoder or camera gap the estimate is propagated through; a longer one
        restarts the filter [s].
    max_phi_dot : float
        Largest plausible |phi_dot| [rad/s]; a larger estimate resets the filter.
    """

    camera_noise: float = 1.0e-4
    accel_noise: float = 0.5
    phi_dot_sigma0: float = 1.0
    history: float = 0.5
    gate_sigma: float = 6.0
    radial_gate: float = 0.02
    reinit_after: int = 4
    max_gap: float = 0.5
    max_phi_dot: float = 50.0

    def __post_init__(self) -> None:
        for name in ("camera_noise", "accel_noise", "phi_dot_sigma0", "history", "gate_sigma",
                     "radial_gate", "max_gap", "max_phi_dot"):
            positive(f"estimator.{name}", getattr(self, name))
        integer("estimator.reinit_after", self.reinit_after, minimum=1)


@njit
def passive_phi_ddot(theta: float, phi: float, theta_dot: float, phi_dot: float,
                     theta_ddot: float, P: np.ndarray, R: float, rho0: float,
                     orders: np.ndarray, ccos: np.ndarray, csin: np.ndarray, bphi: np.ndarray,
                     bh: np.ndarray, bw: np.ndarray) -> float:
    """phi_ddot from the passive row given the frame's acceleration (module docstring).

    Every ``(theta_ddot, phi_ddot)`` the model produces at one state, whatever the torque,
    lies on the line of the passive row; the model's accelerations at u = 0 and u = 1 give
    two points of it, so the row is used exactly as the model writes it (friction, rolling
    resistance and any perturbation included) without repeating its equations here.

    The line's slope needs ``d theta_ddot / d u`` (``k_u M22 / det M`` > 0) to be resolved
    in floating point: at an absurd state (|phi_dot| ~ 1e8 rad/s, where adding a unit
    torque no longer changes theta_ddot) or with no motor gain there is no such line, and
    NaN is returned instead of dividing by zero; the estimator resets on a NaN.
    """
    a0 = rigid_terms(theta, phi, theta_dot, phi_dot, 0.0, P, R, rho0, orders, ccos, csin,
                     bphi, bh, bw)
    a1 = rigid_terms(theta, phi, theta_dot, phi_dot, 1.0, P, R, rho0, orders, ccos, csin,
                     bphi, bh, bw)
    den = a1[0] - a0[0]
    if not abs(den) > 1e-9 * (1.0 + abs(a0[0])):  # also False for NaN
        return np.nan
    return a0[1] + (theta_ddot - a0[0]) * (a1[1] - a0[1]) / den


class BallEstimator:
    """Kalman filter on ``[phi, phi_dot]`` with exact latency compensation (module docstring).

    Parameters
    ----------
    model : RigidModel
        The controller's model (geometry and ball parameters).
    orbit : PeriodicOrbit
        The orbit: its speed is the initial phi_dot guess.
    config : EstimatorConfig
        Settings.
    """

    def __init__(self, model: RigidModel, orbit: PeriodicOrbit, config: EstimatorConfig
                 ) -> None:
        self.model = model
        self.orbit = orbit
        self.config = config
        self._args = model.kernel_args
        # psi -> phi table: phi - psi as a function of psi (period of the track)
        period = orbit.period
        n = 2048
        psi = np.arange(n) * (period / n)
        phi = model.curve.phi_from_ball_angle(psi)
        g = offset_kernel(phi, *model.geom_args)
        px, py, p1x, p1y = g[0], g[1], g[2], g[3]
        dpsi_dphi = (py * p1x - px * p1y) / (px * px + py * py)
        dphi_dpsi = 1.0 / dpsi_dphi
        # measurement noise of phi per unit camera noise: dphi/dpsi / |p|
        radius = np.hypot(px, py)
        gain = dphi_dpsi / radius
        self._inv = PeriodicTable(period, np.column_stack([phi - psi, gain, radius]),
                                  derivatives=None,
                                  names=("phi_minus_psi", "noise_gain", "radius"))
        self.q = config.accel_noise ** 2
        self.reset()

    def reset(self) -> None:
        """Forget everything (no fix yet); the counters of rejected fixes are kept."""
        self.initialized = False
        self.frames = 0  # valid fixes fused since initialisation
        self.last_fix_t = -math.inf  # exposure time of the last valid fix
        self.last_seen_t = -math.inf  # exposure time of the last fix of any kind
        self._ts: list[float] = []
        self._th: list[float] = []
        self._thd: list[float] = []
        # estimate at the present (last recorded time)
        self.phi = math.nan
        self.phi_dot = math.nan
        self._a = 0.0
        # estimate and covariance at the last fix
        self._m = (math.nan, math.nan, 0.0)
        self._cov = (0.0, 0.0, 0.0)
        self._t_m = -math.inf
        self.last_innovation = math.nan
        self.rejected_in_row = 0
        # the camera's stamps (a restart of the filter keeps them: the camera is the same)
        self._intervals: deque[float] = deque(maxlen=STAMP_INTERVALS)
        self._last_stamp = -math.inf
        self._stamp_sigma = 0.0
        self._stamps_seen = 0
        if not hasattr(self, "rejected"):
            #: Fixes rejected by the gate, by reason (``radial``, ``innovation``), since start.
            self.rejected = {"radial": 0, "innovation": 0}
            #: Filter restarts: ``gate`` (fixes rejected in a row), ``gap``, ``diverged``,
            #: ``lost`` (the supervisor gave the ball up before acquiring it).
            self.restarts = {"gate": 0, "gap": 0, "diverged": 0, "lost": 0}
        self.last_rejection = ""

    def restart(self, why: str) -> None:
        """Drop the estimate, keep the encoder history: the next valid fix starts anew.

        Parameters
        ----------
        why : str
            ``gate``, ``gap``, ``diverged`` or ``lost`` (counted in :attr:`restarts`).
        """
        self.restarts[why] += 1
        kept = (self._ts, self._th, self._thd, self.last_rejection, self._intervals,
                self._last_stamp, self._stamp_sigma, self._stamps_seen)
        self.reset()
        (self._ts, self._th, self._thd, self.last_rejection, self._intervals,
         self._last_stamp, self._stamp_sigma, self._stamps_seen) = kept

    # -- helpers ---------------------------------------------------------------------------
    def phi_of_psi(self, psi: float) -> float:
        """Contact angle of a ball-centre angle [rad] (table inverse of ball_angle)."""
        return psi + float(self._inv(psi)[0])

    def _theta_at(self, t: float) -> float | None:
        """Encoder theta at time t by cubic Hermite interpolation, or None if not covered."""
        ts = self._ts
        if not ts or t < ts[0] or t > ts[-1]:
            return None
        i = bisect.bisect_right(ts, t) - 1
        if i >= len(ts) - 1:
            return self._th[-1]
        h = ts[i + 1] - ts[i]
        s = (t - ts[i]) / h
        s2 = s * s
        s3 = s2 * s
        return ((2 * s3 - 3 * s2 + 1) * self._th[i] + (s3 - 2 * s2 + s) * h * self._thd[i]
                + (-2 * s3 + 3 * s2) * self._th[i + 1] + (s3 - s2) * h * self._thd[i + 1])

    def _accel(self, theta: float, phi: float, theta_dot: float, phi_dot: float,
               theta_ddot: float) -> float:
        return passive_phi_ddot(theta, phi, theta_dot, phi_dot, theta_ddot, *self._args)

    def _propagate(self, phi: float, phi_dot: float, a: float, t0: float, t1: float
                   ) -> tuple[float, float, float]:
        """Propagate ``(phi, phi_dot)`` from t0 to t1 through the encoder history.

        Over each encoder interval ``[t_i, t_i+1]`` (clipped to ``[t0, t1]``) the frame's
        acceleration is the interval's constant ``(theta_dot_i+1 - theta_dot_i) / h``; the
        ball's is evaluated once at the midpoint. Outside the history the estimate is left
        where it is (nothing to propagate with); NaN in gives NaN out.
        """
        ts, th, thd = self._ts, self._th, self._thd
        if t1 <= t0 or len(ts) < 2:
            return phi, phi_dot, a
        i = max(bisect.bisect_right(ts, t0) - 1, 0)
        t = max(t0, ts[0])
        while t < t1 - 1e-12 and i < len(ts) - 1:
            ta, tb = ts[i], ts[i + 1]
            if tb <= t:
                i += 1
                continue
            seg_end = min(tb, t1)
            h = seg_end - t
            acc = (thd[i + 1] - thd[i]) / (tb - ta)
            tm = t + 0.5 * h - ta
            th_m = th[i] + thd[i] * tm + 0.5 * acc * tm * tm
            thd_m = thd[i] + acc * tm
            a = self._accel(th_m, phi + 0.5 * h * phi_dot, thd_m, phi_dot + 0.5 * h * a, acc)
            phi = phi + h * phi_dot + 0.5 * h * h * a
            phi_dot = phi_dot + h * a
            t = seg_end
            i += 1
        return phi, phi_dot, a

    def _sane(self, phi: float, phi_dot: float) -> bool:
        return math.isfinite(phi) and math.isfinite(phi_dot) and \
            abs(phi_dot) <= self.config.max_phi_dot

    # -- interface -------------------------------------------------------------------------
    def record(self, t: float, theta: float, theta_dot: float) -> None:
        """Add an encoder sample and advance the present estimate to t.

        Repeated, out-of-order and non-finite samples are ignored. A sample more than
        ``max_gap`` after the previous one restarts the filter (module docstring).
        """
        if not (math.isfinite(t) and math.isfinite(theta) and math.isfinite(theta_dot)):
            return
        ts = self._ts
        if ts and t <= ts[-1]:
            return  # repeated or out-of-order sample: ignore
        if ts and t - ts[-1] > self.config.max_gap:
            # nothing links the history to the present: start it again
            if self.initialized:
                self.restart("gap")
            ts.clear()
            self._th.clear()
            self._thd.clear()
        prev = (ts[-1], self._th[-1], self._thd[-1]) if ts else None
        ts.append(t)
        self._th.append(theta)
        self._thd.append(theta_dot)
        if len(ts) > 64 and t - ts[0] > 2.0 * self.config.history:
            k = min(bisect.bisect_left(ts, t - self.config.history), len(ts) - 2)
            del ts[:k]
            del self._th[:k]
            del self._thd[:k]
        if self.initialized and prev is not None:
            # one step of the propagation of _propagate, over [t_prev, t]
            t_prev, th_p, thd_p = prev
            h = t - t_prev
            acc = (theta_dot - thd_p) / h
            tm = 0.5 * h
            phi, phi_dot = self.phi, self.phi_dot
            a = passive_phi_ddot(th_p + thd_p * tm + 0.5 * acc * tm * tm, phi + tm * phi_dot,
                                 thd_p + acc * tm, phi_dot + tm * self._a, acc, *self._args)
            phi = phi + h * phi_dot + 0.5 * h * h * a
            phi_dot = phi_dot + h * a
            if not self._sane(phi, phi_dot):
                self.restart("diverged")
                return
            self.phi, self.phi_dot, self._a = phi, phi_dot, a

    def _reject(self, kind: str, why: str) -> bool:
        self.rejected[kind] += 1
        self.rejected_in_row += 1
        self.last_rejection = why
        if self.rejected_in_row >= self.config.reinit_after:
            self.restart("gate")  # the next valid fix starts the filter again
        return False

    def _initialise(self, psi: float, t_e: float, r: float) -> bool:
        """First fix: phi from the measurement, phi_dot from the orbit's speed there."""
        phi_m = self.phi_of_psi(psi)
        pd = float(math.sqrt(max(float(self.orbit.table(phi_m)[3]), 0.0)))
        t_now = self._ts[-1]
        phi, phi_dot, a = self._propagate(phi_m, pd, 0.0, t_e, t_now)
        if not self._sane(phi, phi_dot):
            return False
        self._m = (phi_m, pd, 0.0)
        self._cov = (r, 0.0, self.config.phi_dot_sigma0 ** 2)
        self._t_m = t_e
        self.initialized = True
        self.frames = 1
        self.last_fix_t = t_e
        self.rejected_in_row = 0
        self.phi, self.phi_dot, self._a = phi, phi_dot, a
        return True

    def update(self, obs: BallObservation) -> bool:
        """Fuse one camera fix; returns True when it was valid and used.

        Not used: a fix that is invalid, non-finite, at the origin (the rig's "no ball"),
        not newer than the last one, outside the encoder history, or rejected by the gate
        (module docstring; ``last_rejection`` says why).
        """
        t_e = float(obs.t)
        if not math.isfinite(t_e) or t_e <= self.last_seen_t:
            return False  # stale or repeated frame
        self._note_stamp(t_e)
        x, y = float(obs.x), float(obs.y)
        if not (obs.valid and math.isfinite(x) and math.isfinite(y)) or (x == 0.0 and y == 0.0):
            self.last_seen_t = t_e
            return False
        theta_e = self._theta_at(t_e)
        if theta_e is None:
            return False  # exposure outside the encoder history (future or too old)
        self.last_seen_t = t_e
        psi = theta_e + math.atan2(x, y)
        cfg = self.config
        inv = self._inv(psi)
        dr = math.hypot(x, y) - float(inv[2])
        if abs(dr) > cfg.radial_gate:
            return self._reject("radial", f"fix {1e3 * dr:+.1f} mm off the ball's track "
                                          f"(gate {1e3 * cfg.radial_gate:g} mm)")
        r = (cfg.camera_noise * float(inv[1])) ** 2
        if self.initialized and t_e - self._t_m > cfg.max_gap:
            self.restart("gap")
        if not self.initialized:
            return self._initialise(psi, t_e, r)
        # propagate the estimate at the last fix to this exposure
        phi_p, pd_p, a_p = self._propagate(*self._m, self._t_m, t_e)
        dt = t_e - self._t_m
        p11, p12, p22 = self._cov
        q = self.q
        p11 = p11 + 2.0 * dt * p12 + dt * dt * p22 + q * dt ** 3 / 3.0
        p12 = p12 + dt * p22 + q * dt * dt / 2.0
        p22 = p22 + q * dt
        # measurement, unwrapped next to the prediction
        psi_pred = phi_p - float(self._inv(phi_p)[0])  # approx. ball angle of phi_p
        psi = psi_pred + (psi - psi_pred + math.pi) % (2.0 * math.pi) - math.pi
        phi_meas = self.phi_of_psi(psi)
        nu = phi_meas - phi_p
        # the stamps' jitter times the rate the innovation moves at (module docstring)
        dphi_dpsi = float(inv[1]) * float(inv[2])
        r = r + (self._stamp_sigma * (dphi_dpsi * self._thd[-1] - pd_p)) ** 2
        s = p11 + r
        if not abs(nu) <= cfg.gate_sigma * math.sqrt(s):  # also catches NaN
            return self._reject("innovation", f"innovation {nu:+.3g} rad is more than "
                                              f"{cfg.gate_sigma:g} sigma "
                                              f"({math.sqrt(s):.2g} rad)")
        k1 = p11 / s
        k2 = p12 / s
        phi_u = phi_p + k1 * nu
        pd_u = pd_p + k2 * nu
        phi, phi_dot, a = self._propagate(phi_u, pd_u, a_p, t_e, self._ts[-1])
        if not (self._sane(phi_u, pd_u) and self._sane(phi, phi_dot)):
            self.restart("diverged")
            return False
        self._cov = ((1.0 - k1) * p11, (1.0 - k1) * p12, p22 - k2 * p12)
        self._m = (phi_u, pd_u, a_p)
        self._t_m = t_e
        self.frames += 1
        self.last_fix_t = t_e
        self.last_innovation = nu
        self.rejected_in_row = 0
        self.phi, self.phi_dot, self._a = phi, phi_dot, a
        return True

    @property
    def stamp_jitter(self) -> float:
        """[s] The camera stamps' jitter ``sigma_t``, estimated from their intervals.

        Module docstring, "Stamp timing"; 0 until :data:`STAMP_MIN_INTERVALS` were seen.
        """
        return self._stamp_sigma

    def _note_stamp(self, t_e: float) -> None:
        """Keep a new fix's stamp interval; re-estimate the jitter every eighth one."""
        if t_e <= self._last_stamp:
            return  # a fix handed in again (its exposure was not yet covered): one interval
        if math.isfinite(self._last_stamp):
            self._intervals.append(t_e - self._last_stamp)
            self._stamps_seen += 1
        self._last_stamp = t_e
        n = len(self._intervals)
        if n < STAMP_MIN_INTERVALS or self._stamps_seen % 8:
            return
        d = np.fromiter(self._intervals, float, n)
        period = float(np.median(d))
        if not period > 0.0:
            return
        dev = d - np.maximum(np.rint(d / period), 1.0) * period
        self._stamp_sigma = robust_sd(dev) / math.sqrt(2.0)

    @property
    def covariance(self) -> tuple[float, float, float]:
        """``(P_phiphi, P_phiphidot, P_phidotphidot)`` at the last fix."""
        return self._cov
