"""Equation error of both rows of ``M q_ddot + c + G = Q`` in filtered-momentum form.

Lagrange's equations with ``T = 1/2 q_dot^T M(phi) q_dot`` read (bfr_model.dynamics)

    d/dt (M11 th' + M12 ph')                                          = Q_theta - G1
    d/dt (M12 th' + M22 ph') - 1/2 (M11' th'^2 + 2 M12' th' ph' + M22' ph'^2) = Q_phi - G2

(expanding ``d/dt`` gives ``M q_ddot + c``, the Coriolis vector of the dynamics module). Both
sides are convolved with one smooth kernel ``k`` (``cos^4``, half-width ``T``, unit area,
:func:`kernel_pair`); by parts, ``k * d/dt p = k' * p``, so the equation error

    r1 = k' * p1 - k * (Q_theta - G1)
    r2 = k' * p2 - k * (Q_phi - G2 + dT/dphi)

needs only the states and their first derivatives, evaluated pointwise in the exact model
(including fast terms such as track bumps), and both sides see exactly the same filter.
It never diverges on the unstable system (no integration), and it is linear in the
measurement noise to first order. ``Q_theta = k_u u + tau_0 - c_v th' - T_c tanh(th'/v_c)``;
``Q_phi = -mu_rol lam tanh(ph'/v_r) F_n`` with ``F_n = f0 + f_th th''`` (the dynamics
module's exact normal force; th'' from preprocessing).

The measured ball angle enters through ``psi = theta + theta_0 + psi_w`` (ball-centre angle
in the frame; ``theta_0`` the encoder's zero, a sensor correction like the camera's); the
contact angle is ``phi = ball_angle^{-1}(psi)`` of the candidate's curve (Newton) and
``phi_dot = psi_dot / psi'(phi)``, so contour and radius changes are propagated to the
measurement model too. A third, kinematic row compares where the camera puts the ball with
where the model's curve does:

    r3 = k * (rho - |p(phi)|)                                             [m]

``rho`` the ball's measured distance from the shaft (camera offset and scale corrected).
It sees the contour's radius directly, which the dynamics rows see only through the
forces; its confounds (the contour's mean radius, the rolling radius, the camera's scale
and vertical offset: the camera sees the ball near the top of the frame) are resolved, or
reported, by the joint fit with the dynamics. The frame-only row (no ball) is
``r1 = k' * (J_f th') - k * (Q_theta - G1_f)`` (``G1_f`` the frame's own weight); a
frame-held recording has rows 2 and 3 only (``th' = th'' = 0``).

A creeping ball (:mod:`bfr_diagnose.grip`, 5: its spin relaxes to rolling over tau_s) has
its spin as a coordinate of its own, ``J_b omega_b' = tau_f``, and the generalised forces
``(-tau_f, lam tau_f / R)`` on ``(theta, phi)``; its spin is the first-order lag of the rolling
rate ``w = th' - lam ph' / R`` (:func:`bfr_diagnose.grip.creep_lag`), a function of the
measured states. With ``k * (J_b omega_b') = k' * (J_b omega_b)`` and, for ``g = lam / R``,
``k * (g J_b omega_b') = k' * (g J_b omega_b) - k * (g' J_b omega_b)``, the rows are the
rolling rows with the spin's momentum ``J_b w`` replaced by ``J_b omega_b``; for the relative
spin ``s = omega_b - w``:

    r1 += k' * (J_b s)
    r2 += k' * (-g J_b s) - k * (-g' J_b s),        g' = lam' ph' / R

(rolling's ``dT/dphi`` holds the spin's ``-g' J_b w``, a creeping spin's energy does not
depend on phi). ``tau_s -> 0`` gives back the rolling rows.

Numerics. The kernel is ``cos^4`` with half-width 0.2 s (see :func:`kernel_pair` for why not
Hann; shorter for runs too short to hold four of them, :func:`usable_half_width`); the
model terms are evaluated on every second grid sample (4 ms quadrature nodes, exact to
``O(h^4)`` for the pre-filtered integrand) and the filtered rows kept every 12 ms.
One evaluation of both rows over a 60 s recording takes ~10 ms (compiled loop, one curve
evaluation per Newton step).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.dynamics import (
    RigidModel,
    curve_terms,
    frame_gravity,
    gravity_from_curve,
    joint_torque,
    mass_from_curve,
)
from bfr_model.geometry import offset_kernel
from bfr_model.jit import njit, njit_parallel, prange
from bfr_model.layout import (
    I_CV,
    I_CW,
    I_EL,
    I_G,
    I_JB,
    I_JF,
    I_KU,
    I_M,
    I_MEX,
    I_MEY,
    I_MUR,
    I_R,
    I_SW,
    I_TAU0,
    I_TC,
    I_VC,
    I_VR,
)
from bfr_model.params import RigParams
from numpy.typing import NDArray

from bfr_diagnose.grip import creep_lag
from bfr_diagnose.preprocess import Prepared, SensorCorrection, segments_from_mask

#: The equation rows by number: the frame's torque balance, the ball's, the ball's distance.
ROW_NAMES = {1: "frame_torque_row", 2: "ball_row", 3: "ball_distance_row"}
#: Their units.
ROW_UNITS = {1: "N m", 2: "N m", 3: "m"}

__all__ = ["ROW_NAMES", "ROW_UNITS", "Residual", "ResidualConfig", "ResidualEvaluator",
           "kernel_pair", "pointwise_terms", "usable_half_width"]

FloatArray = NDArray[np.float64]


#: [rad] Largest Newton step after which the curve's terms are moved along by their Taylor
#: series instead of evaluated anew (:func:`_sample_terms`).
TAYLOR_STEP = 1e-6


@njit
def _sample_terms(th, thd, thdd, ps, psd, ph, P, R, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN202
                  bw):  # noqa: ANN001
    """One sample of :func:`pointwise_terms`: its nine outputs, from Newton's start ``ph``.

    A function of its own so that the parallel loop's body has no locals of its own (the
    curve's terms of the last Newton step are used after the iteration's ``break``).

    Newton on ``f(phi) = phi + wrap(atan2(p_x, p_y) - phi) - psi``. For a round ball, once a
    step ``d`` is below :data:`TAYLOR_STEP` the curve's terms at ``phi + d`` are their
    Taylor series from those at phi (:func:`bfr_model.geometry.offset_kernel` gives p to its
    third derivative, ``p3``; ``p4`` is the fourth)::

        p(phi + d)  = p + p1 d + p2 d^2 / 2 + p3 d^3 / 6    (error p4 d^4 / 24)
        p1(phi + d) = p1 + p2 d + p3 d^2 / 2               (error p4 d^3 / 6)
        p2(phi + d) = p2 + p3 d                            (error p4 d^2 / 2)

    with ``lam = |p1|``, ``t = p1 / lam``, ``n = J t`` and ``lam' = p1 . p2 / lam`` from
    them: at ``d = 1e-6`` and ``|p4| ~ 1 m`` (an 8th harmonic of 0.1 mm beside the seed's
    contour) p2 is off by 5e-13 m, a relative 5e-12, below the Newton tolerance's own effect
    (on fin's rows: 2e-11 of the ball row, against 2e-9 with a 1e-5 threshold, at the same
    speed). ``f`` is then evaluated from the moved terms (exact to 1e-20 rad) and decides
    convergence as before; a fit's next evaluation is mostly a step of 1e-10 to 1e-6 rad
    from its last (:meth:`ResidualEvaluator._predicted`), so one curve evaluation per
    sample replaces two.
    """
    m = P[I_M]
    g = P[I_G]
    cw = P[I_CW]
    sw = P[I_SW]
    round_ball = P[I_EL] == 0.0
    # contact angle from the ball-centre angle (Newton on psi = phi + wrap(atan2 - phi))
    for _ in range(8):
        if round_ball:
            px, py, p1x, p1y, p2x, p2y, p3x, p3y, nx, ny, lam, lam1, _k = offset_kernel(
                ph, R, rho0, orders, ccos, csin, bphi, bh, bw)
        else:
            px, py, p1x, p1y, p2x, p2y, nx, ny, lam, lam1 = curve_terms(
                ph, P, R, rho0, orders, ccos, csin, bphi, bh, bw)
            p3x = 0.0
            p3y = 0.0
        r2 = px * px + py * py
        f = ph + (np.mod(np.arctan2(px, py) - ph + np.pi, 2.0 * np.pi) - np.pi) - ps
        dpsi = (py * p1x - px * p1y) / r2
        if abs(f) < 1e-11:
            break
        d = -f / dpsi
        ph = ph + d
        if round_ball and abs(d) < TAYLOR_STEP:
            d2 = 0.5 * d * d
            d3 = d * d2 / 3.0
            px = px + p1x * d + p2x * d2 + p3x * d3
            py = py + p1y * d + p2y * d2 + p3y * d3
            p1x = p1x + p2x * d + p3x * d2
            p1y = p1y + p2y * d + p3y * d2
            p2x = p2x + p3x * d
            p2y = p2y + p3y * d
            lam = np.sqrt(p1x * p1x + p1y * p1y)
            nx = -p1y / lam
            ny = p1x / lam
            lam1 = (p1x * p2x + p1y * p2y) / lam
            r2 = px * px + py * py
            f = ph + (np.mod(np.arctan2(px, py) - ph + np.pi, 2.0 * np.pi) - np.pi) - ps
            dpsi = (py * p1x - px * p1y) / r2
            if abs(f) < 1e-11:
                break
    phd = psd / dpsi
    # mass matrix, its phi-derivative and gravity: the model's own kernels
    m11, m12, m22, dm11, dm12, dm22 = mass_from_curve(px, py, p1x, p1y, p2x, p2y, lam,
                                                      lam1, P, R)
    st = np.sin(th)
    ct = np.cos(th)
    g1, g2 = gravity_from_curve(st, ct, px, py, p1x, p1y, P)
    g1 = g1 - frame_gravity(st, ct, P)  # the ball's weight only (the frame's: outside)
    # normal force n3 . m (r_dd + g y) (bfr_model.dynamics.rigid_terms; the phi_dd term
    # vanishes for a round ball: n . p' = 0)
    thd2 = thd * thd
    phd2 = phd * phd
    cor = 2.0 * thd * phd
    a0x = -thd2 * cw * px - cor * p1y + phd2 * cw * p2x + g * st
    a0y = -thd2 * py + cor * cw * p1x + phd2 * p2y + g * ct
    a0z = phd2 * sw * p2x
    fn = (m * (cw * nx * a0x + ny * a0y + sw * nx * a0z)
          + m * (-cw * nx * py + ny * cw * px) * thdd)
    q2 = -P[I_MUR] * lam * np.tanh(phd / P[I_VR]) * fn
    dtdphi = 0.5 * (dm11 * thd2 + 2.0 * dm12 * thd * phd + dm22 * phd2)
    return ((m11 - P[I_JF]) * thd + m12 * phd, -g1, m12 * thd + m22 * phd,
            q2 - g2 + dtdphi, ph, phd, fn, np.sqrt(px * px + py * py), dpsi)


@njit_parallel
def pointwise_terms(theta: FloatArray, theta_dot: FloatArray, theta_ddot: FloatArray,
                    psi: FloatArray, psi_dot: FloatArray,
                    phi_guess: FloatArray, P: FloatArray, R: float, rho0: float,
                    orders: FloatArray, ccos: FloatArray, csin: FloatArray, bphi: FloatArray,
                    bh: FloatArray, bw: FloatArray) -> tuple:
    """Momenta and force terms at each sample (module docstring), compiled.

    The samples are independent: a parallel loop (``prange``) over :func:`_sample_terms`.
    One evaluation of the ball-centre curve per Newton step (a small last step moves the
    terms by their Taylor series instead): the iteration stops when the angle equation is
    solved to 1e-11 rad and the terms at that point are used directly. The mass matrix, its
    derivative and the normal force are the same expressions as
    :func:`bfr_model.dynamics.mass_terms` and :func:`bfr_model.dynamics.rigid_terms`
    (including the frame's wobble factors), written inline.

    The frame's own terms (its inertia, the drive, the joint, its weight) are left out of
    row 1 here: they do not depend on the ball, and :meth:`ResidualEvaluator.evaluate` adds
    them outside this loop, so that a change of frame parameters alone reuses the ball's
    terms (the fits' Jacobian columns of the frame's effects cost a few vector operations).

    Returns
    -------
    tuple of ndarray
        ``(p1b, f1b, p2, f2, phi, phi_dot, fn, pr, dpsi)``: ``p1b = (M11 - J_f) th' + M12 ph'``
        and ``p2`` the generalised momenta without the frame's inertia [N m s],
        ``f1b = -G1_ball`` (the ball's weight on the frame) and ``f2 = Q_phi - G2 + dT/dphi``
        [N m], the contact angle [rad], its rate [rad/s], the normal force [N], the
        model's distance of the ball centre from the shaft ``|p(phi)|`` [m] and
        ``d psi / d phi`` at the solution [-] (the next evaluation's predictor).
    """
    n = theta.shape[0]
    out = np.empty((9, n))
    for i in prange(n):
        o = _sample_terms(theta[i], theta_dot[i], theta_ddot[i], psi[i], psi_dot[i],
                          phi_guess[i], P, R, rho0, orders, ccos, csin, bphi, bh, bw)
        for j in range(9):
            out[j, i] = o[j]
    return (out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8])


def kernel_pair(J: int, dt: float) -> tuple[FloatArray, FloatArray]:
    """Quadrature weights of the kernel ``k`` and of its derivative ``k'`` (times ``dt``).

    ``k(tau) = cos^4(pi tau / 2T) / (3T/4)`` on ``[-T, T]``, ``T = J dt`` (unit area). The
    fourth power matters: ``k'`` then vanishes at the ends with its first two derivatives, so
    the sum ``sum k'(tau_j) p(t - tau_j) dt`` is exact to ``O(dt^4)`` (Euler-Maclaurin). With a
    Hann kernel (``cos^2``) ``k''(+-T) != 0`` and the derivative side carries a relative bias
    ``~ pi^2 dt^2 / (12 T^2)`` (3e-4 at dt = 2 ms, T = 0.1 s) that the torque side does not:
    on clean data it looked like a 0.03 % torque gain, or a frame-inertia or ball-mass change.
    """
    tau = dt * np.arange(-J, J + 1)
    T = J * dt
    a = np.pi * tau / (2.0 * T)
    c = np.cos(a)
    area = 0.75 * T
    k = c ** 4 / area * dt
    kd = -4.0 * c ** 3 * np.sin(a) * (np.pi / (2.0 * T)) / area * dt
    return k, kd


#: Entries of the kernel vector that the frame's own terms use (not the ball's).
_FRAME_ENTRIES = (I_JF, I_CV, I_TC, I_VC, I_KU, I_MEX, I_MEY, I_TAU0)


#: ... and every entry they read (gravity and the wobble factor are shared with the ball's).
_FRAME_KEY = np.array([*_FRAME_ENTRIES, I_G, I_CW])


def _ball_key(P: FloatArray) -> bytes:
    """The entries of ``P`` the ball's terms depend on (all but the frame's own)."""
    q = np.array(P, float)
    q[list(_FRAME_ENTRIES)] = 0.0
    return q.tobytes()


def usable_half_width(ok: NDArray[np.bool_], dt: float, half_width: float,
                      floor: float = 0.05) -> float:
    """The kernel's half-width [s] for a recording whose usable stretches are ``ok``.

    ``half_width`` when the longest usable stretch holds four of them; shorter runs (a log
    of 0.5-s runs) get a quarter of their longest stretch, but never less than ``floor``,
    so that every run still gives equation-error samples.
    """
    segs = segments_from_mask(ok)
    longest = max((b - a for a, b in segs), default=0) * dt
    return float(min(half_width, max(floor, longest / 4.0)))


@dataclass(frozen=True)
class ResidualConfig:
    """Settings of the equation error (units in brackets)."""

    half_width: float = 0.2     # [s] half-width T of the cos^4 kernel (see kernel_pair)
    stride: int = 6             # [-] keep every stride-th filtered sample of the grid
    quad_step: int = 2          # [-] the model terms are evaluated on every quad_step-th grid
    #                             sample (the kernel's quadrature: exact to O(h^4) for the
    #                             smooth, pre-filtered integrand; halves the cost)


class Residual:
    """Filtered equation error of one evaluation.

    Attributes
    ----------
    r1, r2 : ndarray
        Rows 1 and 2 [N m] at the kept samples ``idx`` (NaN where not defined); r2 is
        all-NaN for frame-only recordings, r1 for frame-held ones.
    r3 : ndarray
        The kinematic row [m]: the filtered difference between the ball's distance from the
        shaft as measured and the model's ``|p(phi)|`` (all-NaN without a ball).
    idx : ndarray of int
        Grid indices of the kept samples.
    phi, phi_dot, fn : ndarray
        Contact angle [rad], rate [rad/s] and normal force [N] on the full grid (computed on
        first access: the fits never need them).
    """

    def __init__(self, r1: FloatArray, r2: FloatArray, idx: NDArray[np.intp],
                 grid: Any = None, nodes: tuple | None = None, n: int = 0,
                 r3: FloatArray | None = None) -> None:
        self.r1 = r1
        self.r2 = r2
        self.r3 = np.full(r1.size, np.nan) if r3 is None else r3
        self.idx = idx
        self._grid = grid
        self._nodes = nodes
        self._n = n
        self._cache: dict[str, FloatArray] = {}

    def _get(self, i: int, name: str) -> FloatArray:
        if name not in self._cache:
            if self._nodes is None:
                self._cache[name] = np.full(self._n, np.nan)
            else:
                self._cache[name] = self._grid(self._nodes[i])
        return self._cache[name]

    @property
    def phi(self) -> FloatArray:
        """Contact angle on the grid [rad]."""
        return self._get(0, "phi")

    @property
    def phi_dot(self) -> FloatArray:
        """Contact angle rate on the grid [rad/s]."""
        return self._get(1, "phi_dot")

    @property
    def fn(self) -> FloatArray:
        """Normal force on the grid [N]."""
        return self._get(2, "fn")

    @property
    def rows(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(r1, r2, r3)``."""
        return self.r1, self.r2, self.r3


class ResidualEvaluator:
    """Evaluate the equation error of a candidate model on prepared data.

    Parameters
    ----------
    prep : Prepared
        Preprocessed recording.
    cfg : ResidualConfig, optional
        Kernel settings.
    """

    def __init__(self, prep: Prepared, cfg: ResidualConfig | None = None) -> None:
        self.prep = prep
        self.cfg = cfg or ResidualConfig()
        dt = float(prep.t[1] - prep.t[0])
        q = max(int(self.cfg.quad_step), 1)
        h = q * dt
        ok = prep.usable
        self.half_width = usable_half_width(ok, dt, self.cfg.half_width)
        J = max(round(self.half_width / h), 2)
        self.k, self.kd = kernel_pair(J, h)
        self.J = J
        n = prep.n
        self.rows_mask = ok
        self._grid = np.arange(0, n, q)             # quadrature nodes (full-grid indices)
        ok_s = ok[self._grid]
        ns = self._grid.size
        step = max(round(self.cfg.stride / q), 1)
        idx_s = np.arange(J, ns - J, step)
        # keep outputs whose whole kernel support is usable
        bad = np.convolve((~ok_s).astype(float), np.ones(2 * J + 1), mode="valid") > 0
        idx_s = idx_s[~bad[idx_s - J]]
        self._idx_s = idx_s
        self._step = step                           # outputs every step-th node (_conv)
        self._n_out = len(range(J, ns - J, step))
        self._kept = (idx_s - J) // step            # the kept ones among them
        self.idx = self._grid[idx_s]
        self._sel_s = np.nonzero(ok_s)[0]           # usable nodes (subgrid positions)
        self._sel = self._grid[self._sel_s]         # ... as full-grid indices
        self._ok_full = np.nonzero(ok)[0]
        # (psi, phi, d psi / d phi) of the last evaluation: Newton's start (_predicted)
        self._last_solution: tuple[FloatArray, FloatArray, FloatArray] | None = None
        self._ball_cache: tuple | None = None  # the ball's terms of the last evaluation
        self._frame_cache: tuple | None = None  # the frame's own terms of the last one
        self._camera_cache: tuple | None = None  # the ball as the camera model reads it
        self._model: RigidModel | None = None   # the last evaluation's model

    def _conv(self, x: FloatArray, kern: FloatArray) -> FloatArray:
        """Kernel sums at the kept outputs; ``x`` is given on the quadrature nodes.

        ``y_m = sum_j k_j x_{m+J-j}`` is wanted only at ``m = J + s i`` (``s`` the outputs'
        step in nodes): split ``j = p + s l`` into its ``s`` phases and each phase is a
        convolution of every ``s``-th node with every ``s``-th weight (polyphase
        decimation), ``1/s`` of the direct sum's work; the same sums, added in another order.
        A step longer than the kernel leaves phases without weights: they add nothing.
        """
        s, J = self._step, self.J
        if s == 1 or self._n_out == 0:
            return np.convolve(x, kern, mode="valid")[self._idx_s - J]
        out = np.zeros(self._n_out)
        for p in range(min(s, kern.size)):
            start = (2 * J - p) % s                 # x_{2J - p + s (i - l)} = xs_{off + i - l}
            off = (2 * J - p - start) // s
            out += np.convolve(x[start::s], kern[p::s], mode="full")[off:off + self._n_out]
        return out[self._kept]

    def _to_grid(self, arr: FloatArray) -> FloatArray:
        """Values at the usable nodes -> full grid (linear between nodes), NaN elsewhere."""
        out = np.full(self.prep.n, np.nan)
        out[self._ok_full] = np.interp(self._ok_full, self._sel, arr)
        return out

    def evaluate(self, params: RigParams,
                 sensor: SensorCorrection | float | None = None,
                 creep: float | None = None) -> Residual:
        """Equation error of ``params`` under a camera correction (see module).

        ``sensor`` is a :class:`SensorCorrection` (a plain float is read as an extra camera
        latency [s]). ``creep``: the ball's spin creeps with this relaxation time tau_s [s]
        (module docstring, a creeping ball); None (default): it rolls.
        """
        if sensor is None or isinstance(sensor, (int, float)):
            sensor = SensorCorrection(latency=float(sensor or 0.0))
        prep = self.prep
        if self._model is None or self._model.params is not params:
            self._model = RigidModel(params)  # the same parameter object: the same model
        model = self._model
        g = self._grid
        u = prep.u_for(sensor)
        if not prep.has_ball:
            P = model.P
            thd = prep.theta_dot[g]
            th = prep.theta[g] + sensor.theta_zero
            q1 = (joint_torque(u[g], thd, P)
                  - frame_gravity(np.sin(th), np.cos(th), P))
            r1 = self._conv(P[I_JF] * thd, self.kd) - self._conv(q1, self.k)
            return Residual(r1, np.full(r1.size, np.nan), self.idx, n=prep.n)
        sel = self._sel
        th = prep.theta[sel] + sensor.theta_zero
        P = model.P
        key = (_ball_key(P), *model.geom_args[:2],
               *(a.tobytes() for a in model.geom_args[2:]), sensor.latency, sensor.offset_x,
               sensor.offset_y, sensor.rotation, sensor.scale, sensor.theta_zero, creep)
        if self._ball_cache is not None and self._ball_cache[0] == key:
            ball = self._ball_cache[1]
        else:
            cam = (sensor.latency, sensor.offset_x, sensor.offset_y, sensor.rotation,
                   sensor.scale)
            if self._camera_cache is not None and self._camera_cache[0] == cam:
                psi_w, psi_wd, rho = self._camera_cache[1]  # a physics column: the same fixes
            else:
                psi_w, psi_wd, rho = prep.ball_for(sensor, at=sel)
                self._camera_cache = (cam, (psi_w, psi_wd, rho))
            psi = th + psi_w
            psid = prep.theta_dot[sel] + psi_wd
            guess = psi if self._last_solution is None else self._predicted(psi)
            p1b, f1b, p2, f2, phi, phid, fn, pr, dpsi = pointwise_terms(
                th, prep.theta_dot[sel], prep.theta_ddot[sel], psi, psid, guess,
                *model.kernel_args)
            if np.all(np.isfinite(phi)):
                self._last_solution = (psi, phi, dpsi)
            if creep is not None:
                p1b, p2, f2 = self._creep_terms(model, creep, phi, phid, p1b, p2, f2)
            r2 = self._conv(self._nodes(p2), self.kd) - self._conv(self._nodes(f2), self.k)
            r3 = self._conv(self._nodes(rho - pr), self.k)
            ball = (self._conv(self._nodes(p1b), self.kd) - self._conv(self._nodes(f1b), self.k),
                    r2, r3, (phi, phid, fn))
            self._ball_cache = (key, ball)
        r1b, r2, r3, grid_nodes = ball
        if prep.frame_held:  # the frame's row needs the unknown holding torque
            r1 = np.full(self._idx_s.size, np.nan)
        else:
            key = (P[_FRAME_KEY].tobytes(), sensor.torque_delay, sensor.theta_zero)
            if self._frame_cache is not None and self._frame_cache[0] == key:
                inertial, applied = self._frame_cache[1]  # a column of the ball's effects
            else:
                thd = prep.theta_dot[sel]
                q1 = joint_torque(u[sel], thd, P) - frame_gravity(np.sin(th), np.cos(th), P)
                inertial = self._conv(self._nodes(P[I_JF] * thd), self.kd)
                applied = self._conv(self._nodes(q1), self.k)
                self._frame_cache = (key, (inertial, applied))
            r1 = r1b + inertial - applied
        return Residual(r1, r2, self.idx, grid=self._to_grid, nodes=grid_nodes, n=prep.n,
                        r3=r3)

    def _creep_terms(self, model: RigidModel, tau_s: float, phi: FloatArray,
                     phid: FloatArray, p1b: FloatArray, p2: FloatArray, f2: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(p1b, p2, f2)`` at the usable nodes with the spin creeping (module docstring).

        The relative spin is the lag of the rolling rate along the quadrature nodes, each
        usable stretch of nodes starting rolling.
        """
        P = model.P
        lam, lam1 = curve_terms(phi, *model.kernel_args)[8:10]
        g = lam / P[I_R]
        w = self.prep.theta_dot[self._sel] - g * phid
        ok = np.zeros(self._grid.size, bool)
        ok[self._sel_s] = np.isfinite(w)
        h = float(self.prep.t[self._grid[1]] - self.prep.t[0]) if self._grid.size > 1 else 1.0
        s = creep_lag(self._nodes(np.nan_to_num(w)), ok, h, float(tau_s))[self._sel_s]
        s = np.nan_to_num(s) * P[I_JB]
        return p1b + s, p2 - g * s, f2 - lam1 * phid / P[I_R] * s

    def _predicted(self, psi: FloatArray) -> FloatArray:
        """Newton's starting contact angles for the ball-centre angles ``psi``.

        The last evaluation's solution moved to first order by the change of ``psi``:
        ``phi_0 = phi_last + (psi - psi_last) / psi'(phi_last)``. A fit's next evaluation is
        a small step from its last (a Jacobian column, a trust-region step): a step of the
        camera's model moves ``psi`` by about 1e-5 rad and leaves the predictor 1e-10 off, a
        step of the contour moves the solution by a few 1e-6 rad; started from the first
        evaluation's solution instead (up to 0.03 rad off once a contour is fitted), Newton
        took three to four curve evaluations per sample, now about two. The tolerance is
        the kernel's (1e-11 rad), so the rows do not depend on the start.
        """
        psi0, phi0, dpsi0 = self._last_solution
        ok = np.isfinite(dpsi0) & (dpsi0 > 0.0)
        return phi0 + np.where(ok, psi - psi0, 0.0) / np.where(ok, dpsi0, 1.0)

    def _nodes(self, arr: FloatArray) -> FloatArray:
        """Values at the usable nodes -> every quadrature node (zero elsewhere)."""
        a = np.zeros(self._grid.size)
        a[self._sel_s] = arr
        return a
