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

Short-horizon prediction: from the smoothed state at the start of each window the model is
integrated open loop (RK4 on the grid, the recorded torque) for ``horizon`` seconds; the
prediction error of theta, theta_dot and the ball's world angle is the fit measure a person
can picture. Residual whiteness: Ljung-Box statistic of the residual taken once per kernel
width (near-independent samples).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel, frame_gravity, joint_torque
from bfr_model.params import RigParams
from numpy.typing import NDArray
from scipy.stats import chi2

from bfr_diagnose.preprocess import Prepared, SensorCorrection
from bfr_diagnose.residual import ROW_NAMES, Residual

__all__ = ["ljung_box", "locate", "prediction_errors", "rms_by_block"]

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
    rho = np.array([float(np.dot(x[:-k], x[k:]) / v) for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
    return {"Q": q, "p_value": float(chi2.sf(q, lags)), "rho1": float(rho[0])}


def rms_by_block(r: FloatArray, mask: NDArray[np.bool_]) -> float:
    """RMS of the finite entries of r where mask holds."""
    x = r[mask]
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if x.size else float("nan")


def prediction_errors(prep: Prepared, params: RigParams, phi: FloatArray, phi_dot: FloatArray,
                      sensor: SensorCorrection | None, test_mask_t: NDArray[np.bool_],
                      horizon: float = 0.1, every: float = 0.2,
                      keep_traces: int = 0) -> dict[str, Any]:
    """Short-horizon open-loop prediction errors on the held-out samples.

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

    Returns
    -------
    dict
        ``rmse`` per signal (``theta`` [rad], ``theta_dot`` [rad/s], ``ball_angle`` [rad]),
        ``n_windows`` and optionally ``traces``.
    """
    dt = float(prep.t[1] - prep.t[0])
    nh = max(round(horizon / dt), 1)
    step = max(round(every / dt), 1)
    sensor = sensor or SensorCorrection()
    if prep.frame_held:  # the frame does not move: a frame too heavy to turn
        params = params.replace(**{"frame.inertia": 1e6})
    model = RigidModel(params)
    ok = (prep.ball_ok if prep.has_ball else prep.frame_ok) & test_mask_t
    psi_w, _ = prep.psi_for(sensor)
    u = prep.u_for(sensor)
    theta = prep.theta + sensor.theta_zero
    err: dict[str, list] = {"theta": [], "theta_dot": [], "ball_angle": []}
    traces = []
    n_win = 0
    jf = params.frame.inertia
    for i0 in range(0, prep.n - nh - 1, step):
        if not ok[i0:i0 + nh + 1].all():
            continue
        seg = slice(i0, i0 + nh + 1)
        if prep.has_ball:
            if not (np.isfinite(phi[i0]) and np.isfinite(phi_dot[i0])):
                continue
            x = np.array([theta[i0], phi[i0], prep.theta_dot[i0], phi_dot[i0], 0.0, 0.0])
            xs = np.empty((nh + 1, 4))
            xs[0] = x[:4]
            for k in range(nh):
                x = model.step(x, u[i0 + k], dt, 1)
                xs[k + 1] = x[:4]
            if not np.all(np.isfinite(xs)):
                continue
            ball_w = model.curve.ball_angle(xs[:, 1]) - xs[:, 0]
            err["ball_angle"].append((ball_w - psi_w[seg])[1:])
        else:
            th, v = theta[i0], prep.theta_dot[i0]
            xs = np.empty((nh + 1, 4))
            xs[0] = [th, 0.0, v, 0.0]
            for k in range(nh):
                a = (joint_torque(u[i0 + k], v, model.P)
                     - frame_gravity(np.sin(th), np.cos(th), model.P)) / jf
                th += dt * v + 0.5 * dt * dt * a
                v += dt * a
                xs[k + 1] = [th, 0.0, v, 0.0]
        if not prep.frame_held:
            err["theta"].append((xs[:, 0] - theta[seg])[1:])
            err["theta_dot"].append((xs[:, 2] - prep.theta_dot[seg])[1:])
        n_win += 1
        if len(traces) < keep_traces:
            tr = {"t": prep.t[seg].tolist(), "theta_dot": xs[:, 2].tolist()}
            if prep.has_ball:
                tr["ball_angle"] = (model.curve.ball_angle(xs[:, 1]) - xs[:, 0]).tolist()
            traces.append(tr)
    rmse = {k: (float(np.sqrt(np.mean(np.concatenate(v) ** 2))) if v else float("nan"))
            for k, v in err.items()}
    out: dict[str, Any] = {"rmse": rmse, "n_windows": n_win, "horizon": horizon}
    if keep_traces:
        out["traces"] = traces
    return out
