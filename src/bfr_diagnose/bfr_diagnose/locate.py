"""Locate the mismatch in time and state, and measure fit quality.

Significance against the noise-only null: under the null each equation row is noise whose
expected square at each sample, ``msq``, comes from the noise injections of
:mod:`~bfr_diagnose.null` (the noise is not stationary: it grows where the ball moves
fast), with integrated autocorrelation time ``tau`` samples; over a set of n residual
samples ``Q = (n / tau) sum r^2 / sum msq`` is approximately chi-square with ``n / tau``
degrees of freedom. Windows (default 0.5 s) and
state regions (frame speed and its sign, the ball's place on the frame ``phi mod 2 pi``,
torque level, normal force i.e. contact phase) are flagged where the p-value is below
``alpha`` divided by the number of tests (Bonferroni).

Short-horizon prediction: the model is integrated open loop (RK4 on the grid, the recorded
torque) for ``horizon`` seconds from the start of each held-out window; the prediction error
of theta, theta_dot and the ball's world angle is the fit measure a person can picture. Two
starts: the smoothed state (:func:`prediction_errors`; its error, chiefly the smoothed
phi_dot's, is common to every model) and the state the model itself fits to the
``horizon`` before the window (:func:`causal_prediction_errors`: Ljung's k-step prediction,
causal and model-based). Residual whiteness: Ljung-Box statistic of the residual taken once
per kernel width (near-independent samples).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel, frame_gravity, joint_torque, rigid_rk4_steps
from bfr_model.jit import njit
from bfr_model.params import RigParams
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.stats import chi2

from bfr_diagnose.grip import STATE_SCALE, SlipLaw
from bfr_diagnose.preprocess import Prepared, SensorCorrection
from bfr_diagnose.residual import ROW_NAMES, Residual

__all__ = ["causal_prediction_errors", "ljung_box", "locate", "phi_dot_misfit_by_place",
           "prediction_errors", "rms_by_block"]

FloatArray = NDArray[np.float64]


def _test(r: FloatArray, msq: FloatArray, tau: float) -> tuple[float, float]:
    """(RMS ratio to the noise, p-value) of residual samples r under the null.

    ``msq`` is the expected square of the noise residual at each sample; the sum
    ``S = sum r^2`` is compared with its null mean ``mu = sum msq``:
    ``Q = dof S / mu ~ chi2(dof)``, ``dof = n / tau``.
    """
    ok = np.isfinite(r) & np.isfinite(msq)
    r = r[ok]
    mu = float(np.sum(msq[ok]))
    if r.size < 3 or mu <= 0:
        return float("nan"), 1.0
    ratio = float(np.sum(r ** 2)) / mu
    dof = max(r.size / tau, 1.0)
    return float(np.sqrt(ratio)), float(chi2.sf(ratio * dof, dof))


def locate(prep: Prepared, res: Residual, sigma: Any, tau: float,
           window: float = 0.5, alpha: float = 0.01,
           msq: Any = None, rows: tuple[int, ...] | None = None) -> dict[str, Any]:
    """Windows and state regions where the nominal residual exceeds the noise.

    Parameters
    ----------
    prep : Prepared
        Preprocessed recording.
    res : Residual
        Equation error of the nominal model.
    sigma : sequence of float
        Noise scales of rows 1-3 [N m, N m, m] (used when ``msq`` is not given).
    tau : float
        Autocorrelation time of the residual under the null [samples].
    window : float
        Window length [s].
    alpha : float
        Family-wise significance level.
    msq : sequence of ndarray, optional
        Expected square of the noise residual at each kept sample, rows 1-3 (from the
        noise-injection null; the noise is not stationary).
    rows : tuple of int, optional
        The rows to test (default: 1, and 2 and 3 with a ball).

    Returns
    -------
    dict
        ``global`` (per-row RMS ratio and p-value), ``windows`` (flagged, worst first),
        ``n_windows``, ``regions`` (flagged state bins, worst first), ``all_regions``.
    """
    if rows is None:
        rows = (1, 2, 3) if prep.has_ball else (1,)
    rows = _rows_under_null(res, sigma, msq, rows)
    glob = {}
    for name, row in rows.items():
        ratio, p = _test(row.r, row.msq, tau)
        glob[name] = {"rms_over_noise": ratio, "p_value": p, "significant": bool(p < alpha)}
    windows, n_windows = _windows(prep.t[res.idx], rows, tau, window, alpha)
    regs = _regions(_region_bins(prep, res), rows, tau, alpha)
    # the regions where the mismatch concentrates: significant, largest excess first
    sig = [e for e in regs if e["significant"]]
    sig.sort(key=lambda e: -max(e[k]["rms_over_noise"] for k in rows))
    return {"global": glob, "windows": windows, "regions": sig[:8], "all_regions": regs,
            "n_windows": n_windows, "flagged_fraction": len(windows) / max(n_windows, 1)}


@dataclass(frozen=True, kw_only=True, eq=False)
class _Row:
    """One equation row's residual and its expected square under the null, per sample."""

    r: FloatArray       # [N m]
    msq: FloatArray     # [N^2 m^2]




def _rows_under_null(res: Residual, sigma: Any, msq: Any,
                     rows: tuple[int, ...]) -> dict[str, _Row]:
    """The rows to test, by name: the null's ``msq`` where given, else ``sigma^2``."""
    idx = res.idx

    def expected(i: int) -> FloatArray:
        if msq is not None and msq[i] is not None and np.size(msq[i]) == idx.size:
            return np.asarray(msq[i], float)
        return np.full(idx.size, float(sigma[i]) ** 2)

    return {ROW_NAMES[r]: _Row(r=res.rows[r - 1], msq=expected(r - 1)) for r in rows}


def _tested(rows: dict[str, _Row], m: NDArray[np.bool_], tau: float) -> dict[str, Any]:
    """Each row's RMS ratio to the noise and p-value on the samples ``m``, and the least p.

    Returns
    -------
    dict
        ``{row: {"rms_over_noise", "p_value"}}`` and ``p_min``.
    """
    entry: dict[str, Any] = {}
    worst = 1.0
    for name, row in rows.items():
        ratio, p = _test(row.r[m], row.msq[m], tau)
        entry[name] = {"rms_over_noise": ratio, "p_value": p}
        worst = min(worst, p)
    entry["p_min"] = worst
    return entry


def _windows(t: FloatArray, rows: dict[str, _Row], tau: float, window: float,
             alpha: float) -> tuple[list[dict[str, Any]], int]:
    """Windows of ``window`` seconds where a row exceeds the noise (Bonferroni).

    Parameters
    ----------
    t : ndarray
        Times of the residual samples [s].
    rows : dict
        The rows to test (:func:`_rows_under_null`).
    tau : float
        Autocorrelation time under the null [samples].
    window, alpha : float
        Window length [s] and family-wise significance level.

    Returns
    -------
    flagged : list of dict
        ``t0``, ``t1``, per row ``rms_over_noise`` and ``p_value``, ``p_min`` and
        ``signals`` (the rows that exceed), most significant first.
    n_windows : int
        Windows tested (those with at least 5 samples).
    """
    edges = np.arange(t[0], t[-1] + window, window)
    wins = []
    for a, b in itertools.pairwise(edges):
        m = (t >= a) & (t < b)
        if m.sum() < 5:
            continue
        wins.append({"t0": float(a), "t1": float(b), **_tested(rows, m, tau)})
    n_w = max(len(wins), 1)
    flagged = [w for w in wins if w["p_min"] < alpha / n_w]
    for w in flagged:
        w["signals"] = [k for k in rows if w[k]["p_value"] < alpha / n_w]
    flagged.sort(key=lambda w: w["p_min"])
    return flagged, len(wins)


def _region_bins(prep: Prepared, res: Residual) -> list[tuple[str, NDArray[np.bool_]]]:
    """``(label, mask over the residual samples)`` of each state region tested.

    Frame speed and its sign, torque level (terciles), and with a ball its place on the
    frame (``phi mod 2 pi`` in 30-degree bins) and the normal force (contact phase).
    """
    idx = res.idx
    thd = prep.theta_dot[idx]
    u = prep.u[idx]
    bins: list[tuple[str, NDArray[np.bool_]]] = []
    for lo, hi, lab in [(-np.inf, -2.0, "theta_dot < -2 rad/s"),
                        (-2.0, -0.3, "-2 <= theta_dot < -0.3 rad/s"),
                        (-0.3, 0.3, "|theta_dot| < 0.3 rad/s (near rest / reversal)"),
                        (0.3, 2.0, "0.3 <= theta_dot < 2 rad/s"),
                        (2.0, 5.0, "2 <= theta_dot < 5 rad/s"),
                        (5.0, np.inf, "theta_dot >= 5 rad/s")]:
        bins.append((lab, (thd >= lo) & (thd < hi)))
    qs = np.quantile(np.abs(u), [1 / 3, 2 / 3])
    bins.append((f"|torque| < {qs[0]:.3g} N m (low)", np.abs(u) < qs[0]))
    bins.append((f"|torque| in [{qs[0]:.3g}, {qs[1]:.3g}) N m", (np.abs(u) >= qs[0])
                 & (np.abs(u) < qs[1])))
    bins.append((f"|torque| >= {qs[1]:.3g} N m (high)", np.abs(u) >= qs[1]))
    if prep.has_ball:
        ph = np.mod(res.phi[idx], 2.0 * np.pi)
        for k in range(12):
            a, b = k * np.pi / 6, (k + 1) * np.pi / 6
            bins.append((f"phi mod 2pi in [{np.degrees(a):.0f}, {np.degrees(b):.0f}) deg",
                         (ph >= a) & (ph < b)))
        fn = res.fn[idx]
        fq = np.nanquantile(fn, [0.1, 0.5])
        bins.append((f"normal force < {fq[0]:.3g} N (light contact)", fn < fq[0]))
        bins.append((f"normal force in [{fq[0]:.3g}, {fq[1]:.3g}) N", (fn >= fq[0])
                     & (fn < fq[1])))
        bins.append((f"normal force >= {fq[1]:.3g} N", fn >= fq[1]))
    return bins


def _regions(bins: list[tuple[str, NDArray[np.bool_]]], rows: dict[str, _Row], tau: float,
             alpha: float) -> list[dict[str, Any]]:
    """Test every region with at least 10 samples (Bonferroni over the regions tested).

    Returns
    -------
    list of dict
        ``region``, ``fraction`` of the samples, per row ``rms_over_noise`` and
        ``p_value``, ``p_min``, ``significant`` and ``signals`` (the rows that exceed).
    """
    regs = []
    for lab, m in bins:
        if m.sum() < 10:
            continue
        regs.append({"region": lab, "fraction": float(m.mean()), **_tested(rows, m, tau)})
    n_r = max(len(regs), 1)
    for e in regs:
        e["significant"] = bool(e["p_min"] < alpha / n_r)
        e["signals"] = [k for k in rows if e[k]["p_value"] < alpha / n_r]
    return regs


def ljung_box(r: FloatArray, lag_step: int, lags: int = 10) -> dict[str, float]:
    """Ljung-Box whiteness test of r sampled every ``lag_step`` samples."""
    x = r[np.isfinite(r)][::max(lag_step, 1)]
    n = x.size
    if n < lags + 5:
        return {"Q": float("nan"), "p_value": float("nan"), "rho1": float("nan")}
    x = x - x.mean()
    v = float(np.dot(x, x))
    if not v > 0.0:  # a constant residual (a held frame's zero-torque row): no whiteness
        return {"Q": float("nan"), "p_value": float("nan"), "rho1": float("nan")}
    rho = np.array([float(np.dot(x[:-k], x[k:]) / v) for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
    return {"Q": q, "p_value": float(chi2.sf(q, lags)), "rho1": float(rho[0])}


def rms_by_block(r: FloatArray, mask: NDArray[np.bool_]) -> float:
    """RMS of the finite entries of r where mask holds."""
    x = r[mask]
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if x.size else float("nan")


# -- short-horizon predictions ---------------------------------------------------------------


@njit
def _rigid_rollout(x0, u, dt, P, R, rho0, orders, ccos, csin, bphi, bh, bw):  # noqa: ANN001, ANN202
    """The rigid model's states ``[theta, phi, theta_dot, phi_dot]`` along a torque record.

    One RK4 step of ``dt`` per torque sample (:func:`~bfr_model.dynamics.rigid_rk4_steps`,
    ``u[k]`` held over ``[t_k, t_k + dt)``) from the 6-state ``x0``: the same arithmetic as
    :meth:`~bfr_model.dynamics.RigidModel.step`. Shape (n + 1, 4), row 0 the start.
    """
    n = u.shape[0]
    xs = np.empty((n + 1, 4))
    x = x0.copy()
    xs[0, :] = x[:4]
    for k in range(n):
        x = rigid_rk4_steps(x, 0.0, dt, 1, (u[k], P, R, rho0, orders, ccos, csin, bphi, bh,
                                            bw))
        xs[k + 1, :] = x[:4]
    return xs


@njit
def _frame_rollout(x0, u, dt, P, jf):  # noqa: ANN001, ANN202
    """The frame alone along a torque record (a recording without the ball).

    ``J_f theta_ddot = Q(u, theta_dot) - G_f(theta)`` (:func:`~bfr_model.dynamics.joint_torque`,
    :func:`~bfr_model.dynamics.frame_gravity`), stepped with the acceleration at the start of
    each step: ``theta += dt theta_dot + dt^2 a / 2``, ``theta_dot += dt a`` (exact for a
    constant acceleration). Shape (n + 1, 4) with phi and phi_dot zero.
    """
    n = u.shape[0]
    xs = np.zeros((n + 1, 4))
    th = x0[0]
    v = x0[2]
    xs[0, 0] = th
    xs[0, 2] = v
    for k in range(n):
        a = (joint_torque(u[k], v, P) - frame_gravity(np.sin(th), np.cos(th), P)) / jf
        th += dt * v + 0.5 * dt * dt * a
        v += dt * a
        xs[k + 1, 0] = th
        xs[k + 1, 2] = v
    return xs


@dataclass(frozen=True, kw_only=True, eq=False)
class _Predictor:
    """One model's open-loop rollouts on one recording, and the measured signals to score.

    Attributes
    ----------
    prep : Prepared
        The preprocessed recording.
    model : RigidModel
        The model (frame inertia 1e6 on a held frame: a frame too heavy to turn).
    dt : float
        Grid step [s].
    nh, step : int
        Horizon and spacing of the window starts [samples].
    theta, psi_w, rho : ndarray
        Measured frame angle [rad] (with the encoder zero), ball world angle [rad] and the
        ball's distance from the shaft [m] under the sensor correction.
    u : ndarray
        Torque acting at each grid time [N m].
    usable : ndarray of bool
        Grid samples usable (``ball_ok`` with a ball, else ``frame_ok``).
    slip : SlipLaw or None
        How the ball slips (:class:`bfr_diagnose.grip.SlipLaw`); None: it rolls.
    """

    prep: Prepared
    model: RigidModel
    dt: float
    nh: int
    step: int
    theta: FloatArray
    psi_w: FloatArray
    rho: FloatArray
    u: FloatArray
    usable: NDArray[np.bool_]
    slip: SlipLaw | None = None

    def rollout(self, x0: FloatArray, i: int, n: int) -> FloatArray:
        """States (n + 1, 4) open loop from ``x0`` at grid sample i.

        ``x0 = [theta, phi, theta_dot, phi_dot]``; the recorded torque ``u[i], ...,
        u[i + n - 1]`` acts. With ``slip`` the ball may slip (:meth:`SlipLaw.rollout
        <bfr_diagnose.grip.SlipLaw.rollout>`): rolling at x0, or under creep with the
        relative spin ``x0[4]`` when given.
        """
        u = np.array(self.u[i:i + n], dtype=float)  # writable: one signature of the kernels
        if self.prep.has_ball and self.slip is not None:
            return self.slip.rollout(self.model, x0, u, self.dt)
        if self.prep.has_ball:
            x = np.array([x0[0], x0[1], x0[2], x0[3], 0.0, 0.0])
            return _rigid_rollout(x, u, self.dt, *self.model.kernel_args)
        return _frame_rollout(np.asarray(x0, float), u, self.dt, self.model.P,
                              self.model.params.frame.inertia)

    def ball_angle(self, xs: FloatArray) -> FloatArray:
        """The ball's world angle ``psi_w = psi(phi) - theta`` of states xs [rad]."""
        return self.model.curve.ball_angle(xs[:, 1]) - xs[:, 0]

    def starts(self, test_mask_t: NDArray[np.bool_], lead: int = 0) -> list[int]:
        """Window starts i0 on the grid of ``step`` samples.

        The scored ``[i0, i0 + nh]`` usable and held out, and with ``lead`` > 0 the ``lead``
        samples before i0 usable too.
        """
        ok = self.usable & test_mask_t
        return [i0 for i0 in range(0, self.prep.n - self.nh - 1, self.step)
                if i0 >= lead and ok[i0:i0 + self.nh + 1].all()
                and self.usable[i0 - lead:i0 + 1].all()]


def _predictor(prep: Prepared, params: RigParams, sensor: SensorCorrection | None,
               horizon: float, every: float, slip: SlipLaw | None = None) -> _Predictor:
    """The :class:`_Predictor` of a model on a recording under a sensor correction."""
    dt = float(prep.t[1] - prep.t[0])
    sensor = sensor or SensorCorrection()
    if slip is None and params.ball.creep_time > 0.0:  # the model's own ball creeps
        slip = SlipLaw(kind="creep", value=params.ball.creep_time)
    if prep.frame_held:  # the frame does not move: a frame too heavy to turn
        params = params.replace(**{"frame.inertia": 1e6})
    psi_w, _, rho = prep.ball_for(sensor)
    return _Predictor(prep=prep, model=RigidModel(params), dt=dt,
                      nh=max(round(horizon / dt), 1), step=max(round(every / dt), 1),
                      theta=prep.theta + sensor.theta_zero, psi_w=psi_w, rho=rho,
                      u=prep.u_for(sensor),
                      usable=prep.usable, slip=slip)


class _Scores:
    """The prediction errors of the windows scored so far, and traces for the plot."""

    def __init__(self, pred: _Predictor, keep_traces: int) -> None:
        self.pred = pred
        self.keep = keep_traces
        self.err: dict[str, list[FloatArray]] = {"theta": [], "theta_dot": [],
                                                 "ball_angle": []}
        self.traces: list[dict[str, Any]] = []
        self.n = 0

    def add(self, xs: FloatArray, i0: int) -> None:
        """Score predicted states xs at grid samples ``i0 .. i0 + nh`` against the data.

        Row 0, the start, is not scored.
        """
        p = self.pred
        seg = slice(i0, i0 + p.nh + 1)
        prep = p.prep
        ball_w = p.ball_angle(xs) if prep.has_ball else None
        if ball_w is not None:
            self.err["ball_angle"].append((ball_w - p.psi_w[seg])[1:])
        if not prep.frame_held:
            self.err["theta"].append((xs[:, 0] - p.theta[seg])[1:])
            self.err["theta_dot"].append((xs[:, 2] - prep.theta_dot[seg])[1:])
        self.n += 1
        if len(self.traces) < self.keep:
            tr = {"t": prep.t[seg].tolist(), "theta_dot": xs[:, 2].tolist()}
            if ball_w is not None:
                tr["ball_angle"] = ball_w.tolist()
                tr["phi"] = xs[:, 1].tolist()
                tr["phi_dot"] = xs[:, 3].tolist()
            self.traces.append(tr)

    def result(self, horizon: float, **extra: Any) -> dict[str, Any]:
        """``rmse`` per signal, ``n_windows``, ``horizon``, ``extra`` and the traces."""
        rmse = {k: (float(np.sqrt(np.mean(np.concatenate(v) ** 2))) if v else float("nan"))
                for k, v in self.err.items()}
        out: dict[str, Any] = {"rmse": rmse, "n_windows": self.n, "horizon": horizon,
                               **extra}
        if self.keep:
            out["traces"] = self.traces
        return out


def prediction_errors(prep: Prepared, params: RigParams, phi: FloatArray, phi_dot: FloatArray,
                      sensor: SensorCorrection | None, test_mask_t: NDArray[np.bool_],
                      horizon: float = 0.1, every: float = 0.2,
                      keep_traces: int = 0, slip: SlipLaw | None = None) -> dict[str, Any]:
    """Short-horizon open-loop prediction errors on the held-out samples, smoothed start.

    At each window start i0 (every ``every`` seconds where ``[i0, i0 + horizon]`` is usable
    and held out) the model starts from ``[theta, phi, theta_dot, phi_dot](i0)``: the
    measured frame angle and rate, the kernel-smoothed contact angle and rate of the residual
    evaluator; it runs open loop on the grid under the recorded torque (RK4; the frame alone
    without a ball) and its errors at ``i0 + dt .. i0 + horizon`` are pooled into an RMSE.
    The start state's own error (chiefly the smoothed phi_dot's) is common to every model:
    :func:`causal_prediction_errors` fits each model's start instead.

    Parameters
    ----------
    prep : Prepared
        Preprocessed recording.
    params : RigParams
        Model to predict with.
    phi, phi_dot : ndarray
        Contact angle and rate on the grid under this model (NaN where unknown).
    sensor : SensorCorrection or None
        Camera correction (latency beyond the nominal, origin offset): the measured ball
        angle is compared after undoing it.
    test_mask_t : ndarray of bool
        Grid samples that are held out.
    horizon, every : float
        Prediction horizon and spacing of the start points [s].
    keep_traces : int
        Return this many predicted traces (for the overlay plot).
    slip : SlipLaw or None
        How the ball may slip (:class:`bfr_diagnose.grip.SlipLaw`): Coulomb friction,
        rolling at the start, or creep, with the relative spin its law implies from the
        measured rolling rate before the start (:meth:`SlipLaw.spin
        <bfr_diagnose.grip.SlipLaw.spin>`); None (default): it rolls.

    Returns
    -------
    dict
        ``rmse`` per signal (``theta`` [rad], ``theta_dot`` [rad/s], ``ball_angle`` [rad]),
        ``n_windows``, ``horizon`` [s], ``start`` (``"smoothed"``) and optionally
        ``traces``.
    """
    pred = _predictor(prep, params, sensor, horizon, every, slip)
    scores = _Scores(pred, keep_traces)
    spin = (slip.spin(pred.model, prep.theta_dot, phi, phi_dot, pred.usable, pred.dt)
            if prep.has_ball and slip is not None else None)
    for i0 in pred.starts(test_mask_t):
        if prep.has_ball and not (np.isfinite(phi[i0]) and np.isfinite(phi_dot[i0])):
            continue
        x0 = np.array([pred.theta[i0], phi[i0] if prep.has_ball else 0.0,
                       prep.theta_dot[i0], phi_dot[i0] if prep.has_ball else 0.0])
        if spin is not None and np.isfinite(spin[i0]):
            x0 = np.append(x0, spin[i0])
        xs = pred.rollout(x0, i0, pred.nh)
        if not np.all(np.isfinite(xs)):
            continue
        scores.add(xs, i0)
    return scores.result(horizon, start="smoothed")


#: Scale of each state in the start-state fit (:data:`bfr_diagnose.grip.STATE_SCALE`; the
#: finite-difference steps are 1e-4 of it).
_STATE_SCALE = STATE_SCALE

#: Noise below which a measured angle's noise is taken as this [rad] (an exact encoder, a
#: noise-free simulation): the weights stay finite.
_NOISE_FLOOR = 1e-6

#: Residual of a start state whose rollout is not finite (far above any fit's, in noise units).
_PENALTY = 1e6


def _noise_rad(x: float | None) -> float:
    """A noise level [rad], floored at :data:`_NOISE_FLOOR` (and where not estimated)."""
    return float(x) if x is not None and np.isfinite(x) and x > _NOISE_FLOOR else _NOISE_FLOOR


@dataclass(frozen=True, kw_only=True)
class _StartFit:
    """A start state fitted to the measurements of a fit window.

    Attributes
    ----------
    state : ndarray
        ``[theta, phi, theta_dot, phi_dot]`` at the fit window's first sample, and under
        creep the ball's relative spin [rad/s] fifth.
    rms : float
        RMS of the noise-normalised residual over the fit window [-].
    """

    state: FloatArray
    rms: float


def _fit_start(pred: _Predictor, guess: FloatArray, j: int, nw: int) -> _StartFit | None:
    """The start state at grid sample j that best explains the measurements on ``[j, j + nw]``.

    Unknowns: all four states when the ball rolls on a turning frame, and the ball's relative
    spin where the guess carries one (a fifth state: creep); ``(theta, theta_dot)`` without a
    ball; ``(phi, phi_dot)`` on a held frame (theta and theta_dot stay measured).
    Residuals, each over its noise: the frame angle ``(theta_m(x0; t_k) - theta(t_k)) /
    sigma_theta`` (not on a held frame) and the ball's world angle ``(psi_w,m(x0; t_k) -
    psi_w(t_k)) / (sigma_cam / rho)`` with a ball, ``sigma_cam`` the camera's noise per axis
    [m] over the ball's *measured* distance from the shaft rho (median over the fit window,
    after the sensor's scale; the model's at the guess where none is measured): the same
    weights for every model. Levenberg-Marquardt (``scipy.optimize.least_squares``) on the
    deviation from the guess, forward-difference Jacobian with steps of 1e-4 of
    :data:`_STATE_SCALE`.

    Returns
    -------
    _StartFit or None
        None when the solver fails or the fitted rollout is not finite.
    """
    prep = pred.prep
    free = ([1, 3] if prep.frame_held else [0, 1, 2, 3]) if prep.has_ball else [0, 2]
    if guess.size > 4:  # the relative spin of a ball under creep
        free = [*free, 4]
    seg = slice(j, j + nw + 1)
    th_m = pred.theta[seg]
    sig_th = _noise_rad(prep.noise.get("theta"))
    psi_m = pred.psi_w[seg]
    if prep.has_ball:
        rho = pred.rho[seg]
        rho = rho[np.isfinite(rho)]
        dist = (float(np.median(rho)) if rho.size else
                float(np.hypot(*pred.model.ball_position(guess[:4]))))
        sig_psi = _noise_rad(prep.noise.get("camera", np.nan) / dist)
    m = (0 if prep.frame_held else nw + 1) + (nw + 1 if prep.has_ball else 0)

    def residual(dz: FloatArray) -> FloatArray:
        x0 = guess.copy()
        x0[free] += dz
        xs = pred.rollout(x0, j, nw)
        if not np.all(np.isfinite(xs)):
            return np.full(m, _PENALTY)
        r = []
        if not prep.frame_held:
            r.append((xs[:, 0] - th_m) / sig_th)
        if prep.has_ball:
            r.append((pred.ball_angle(xs) - psi_m) / sig_psi)
        return np.concatenate(r)

    h = 1e-4 * _STATE_SCALE[free]
    last: dict[str, FloatArray] = {}

    def fun(dz: FloatArray) -> FloatArray:
        last["dz"], last["r"] = dz.copy(), residual(dz)
        return last["r"]

    def jac(dz: FloatArray) -> FloatArray:
        r0 = last["r"] if "dz" in last and np.array_equal(last["dz"], dz) else residual(dz)
        cols = []
        for c in range(dz.size):
            e = dz.copy()
            e[c] += h[c]
            cols.append((residual(e) - r0) / h[c])
        return np.column_stack(cols)

    sol = least_squares(fun, np.zeros(len(free)), jac=jac, method="lm",
                        x_scale=_STATE_SCALE[free], max_nfev=50 * len(free))
    x0 = guess.copy()
    x0[free] += sol.x
    if sol.status <= 0 or not np.all(np.isfinite(x0)):
        return None
    r = residual(sol.x)
    if np.any(r == _PENALTY):
        return None
    return _StartFit(state=x0, rms=float(np.sqrt(np.mean(r ** 2))))


def causal_prediction_errors(prep: Prepared, params: RigParams, phi: FloatArray,
                             phi_dot: FloatArray, sensor: SensorCorrection | None,
                             test_mask_t: NDArray[np.bool_], horizon: float = 0.1,
                             every: float = 0.2, fit_window: float | None = None,
                             keep_traces: int = 0, slip: SlipLaw | None = None
                             ) -> dict[str, Any]:
    """Short-horizon prediction errors on the held-out samples, the start fitted before.

    Causal and model-based: Ljung's k-step prediction with the initial state estimated from
    the past data.

    At each window start i0 (the windows of :func:`prediction_errors` whose ``fit_window``
    W before i0 is usable too) the model's state at ``i0 - W`` is fitted to the measured
    frame angle and ball world angle on ``[i0 - W, i0]`` (:func:`_fit_start`, started from
    the smoothed state there); the model then runs open loop from ``i0 - W`` through i0 to
    ``i0 + horizon`` under the recorded torque, and only its errors on ``(i0, i0 +
    horizon]``, data the fit never saw and held out from the identification, are scored.
    Each model estimates its own start (a wrong model's estimate is worse: that is part of
    its prediction), so the figure measures the model, not the smoother. Windows whose fit
    fails or whose rollout diverges are skipped and counted.

    Parameters
    ----------
    prep, params, phi, phi_dot, sensor, test_mask_t, horizon, every, keep_traces, slip
        As :func:`prediction_errors` (phi and phi_dot only give the fit's starting guess).
        Under Coulomb slip the ball rolls at the fit window's start; under creep the
        relative spin there is a fifth unknown of the fit (from 0): a state of that model.
    fit_window : float, optional
        Length W of the fit window before each start [s] (default: the horizon).

    Returns
    -------
    dict
        As :func:`prediction_errors`, with ``start`` = ``"fitted"``, ``fit_window`` [s],
        ``n_skipped`` (windows whose fit failed or diverged) and ``fit_rms_over_noise``
        (the fits' residual RMS over the noise, pooled); each trace also holds the fitted
        start (``fit_t`` [s], ``fit_state``).
    """
    pred = _predictor(prep, params, sensor, horizon, every, slip)
    nw = max(round((horizon if fit_window is None else fit_window) / pred.dt), 1)
    scores = _Scores(pred, keep_traces)
    skipped = 0
    fit_ms: list[float] = []
    for i0 in pred.starts(test_mask_t, lead=nw):
        j = i0 - nw
        guess = np.array([pred.theta[j], phi[j] if prep.has_ball else 0.0,
                          prep.theta_dot[j], phi_dot[j] if prep.has_ball else 0.0, 0.0])
        if not (prep.has_ball and slip is not None and slip.states == 5):
            guess = guess[:4]
        if not np.all(np.isfinite(guess)):
            continue
        fit = _fit_start(pred, guess, j, nw)
        xs = None if fit is None else pred.rollout(fit.state, j, nw + pred.nh)
        if xs is None or not np.all(np.isfinite(xs)):
            skipped += 1
            continue
        fit_ms.append(fit.rms ** 2)
        n_tr = len(scores.traces)
        scores.add(xs[nw:], i0)
        if len(scores.traces) > n_tr:
            scores.traces[-1].update(fit_t=float(prep.t[j]), fit_state=fit.state.tolist())
    return scores.result(horizon, start="fitted", fit_window=round(nw * pred.dt, 9),
                         n_skipped=skipped,
                         fit_rms_over_noise=(float(np.sqrt(np.mean(fit_ms))) if fit_ms
                                             else float("nan")))


def phi_dot_misfit_by_place(pred: dict[str, Any], phi_dot: FloatArray, t: FloatArray,
                            edges: FloatArray) -> FloatArray:
    """Where on the frame a model's predicted ball speed departs from the measured one.

    Over the traces of a prediction (:func:`causal_prediction_errors` or
    :func:`prediction_errors` with ``keep_traces``), at every scored sample (the start
    excluded): ``d = phi_dot_pred - phi_dot_meas``, the measured rate that model's own
    (its residual's smoothed contact rate on the grid ``t``); binned by the predicted
    ``phi mod pi`` on ``edges`` [rad], the RMS of d per bin [rad/s].

    Returns
    -------
    ndarray
        ``len(edges) - 1`` values, NaN where no sample falls (or the traces hold no ball).
    """
    phis, diffs = [], []
    for tr in pred.get("traces", []):
        if "phi_dot" not in tr:
            continue
        idx = np.searchsorted(t, np.asarray(tr["t"][1:]) - 1e-9)
        phis.append(np.asarray(tr["phi"][1:]))
        diffs.append(np.asarray(tr["phi_dot"][1:]) - phi_dot[idx])
    n_bins = edges.size - 1
    if not phis:
        return np.full(n_bins, np.nan)
    phi, dif = np.concatenate(phis), np.concatenate(diffs)
    ok = np.isfinite(phi) & np.isfinite(dif)
    k = np.digitize(np.mod(phi[ok], np.pi), edges) - 1
    v = dif[ok]
    return np.array([float(np.sqrt(np.mean(v[k == i] ** 2))) if np.any(k == i) else np.nan
                     for i in range(n_bins)])
