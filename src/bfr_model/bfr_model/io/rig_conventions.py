"""Inference of the NTNU rig logs' conventions from the data (issue 7/8 groundwork).

Every number in docs/ntnu-rig-conventions.md is printed by::

    python -m bfr_model.io.rig_conventions [DATA_DIR]

(default ``DATA_DIR``: ``../shared/data/ntnu-rig`` beside the repository). The functions
are also used by the tests that check the inference on the real files. They work on raw
runs (:class:`bfr_model.io.rig_log.RigRun`, rig conventions) or on recordings.

Pure numpy/scipy; the nominal geometry comes from ``bfr_model.params`` / ``bfr_model.geometry``.
"""

from __future__ import annotations

import argparse
import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from bfr_model.geometry import OffsetCurve
from bfr_model.io.rig_log import RigRun, _camera_backlog_end, parse_rig_log
from bfr_model.params import load_params

__all__ = [
    "BallRadiusFit",
    "NoBallFit",
    "ball_radius_fit",
    "default_data_dir",
    "derivative_delay",
    "fix_statistics",
    "frame_fit_no_ball",
    "phi_theta_lag",
    "rolling_direction",
]

FloatArray = NDArray[np.float64]


def default_data_dir() -> Path:
    """``<repo>/../shared/data/ntnu-rig`` (the repository root found from this file)."""
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / "DEVELOPERS.md").exists() or (parent / ".git").exists():
            return parent.parent / "shared" / "data" / "ntnu-rig"
    return here.parents[5] / "shared" / "data" / "ntnu-rig"  # pragma: no cover


def _new_fix(run: RigRun) -> NDArray[np.bool_]:
    x, y = run.column("x"), run.column("y")
    seen = ~((x == 0) & (y == 0))
    changed = np.ones(len(run), bool)
    changed[1:] = (x[1:] != x[:-1]) | (y[1:] != y[:-1]) | ~seen[:-1]
    return seen & changed


def fix_statistics(run: RigRun) -> dict[str, Any]:
    """Loop and camera timing of a run.

    Returns
    -------
    dict
        ``loop_rate_mean`` [Hz] (samples / duration), ``loop_dt_median`` [s] (quantised
        by the 0.1 ms print resolution), ``fixes`` (new distinct fixes), ``backlog_fixes``
        (fixes on consecutive samples at start-up), ``camera_rate`` [Hz] after the backlog,
        ``fix_interval_median`` / ``p10`` / ``p90`` / ``max`` [s], ``samples_per_fix``
        histogram (list, index = samples between fixes).
    """
    t = run.column("t")
    out: dict[str, Any] = {
        "samples": len(run),
        "duration": float(t[-1] - t[0]),
        "loop_rate_mean": float((len(run) - 1) / (t[-1] - t[0])),
        "loop_dt_median": float(np.median(np.diff(t))),
        "loop_dt_max": float(np.max(np.diff(t))),
    }
    fi = np.nonzero(_new_fix(run))[0]
    out["fixes"] = int(fi.size)
    if fi.size < 3:
        return out
    end = _camera_backlog_end(fi, run.column("t"))
    steady = fi[fi >= end]
    out["backlog_fixes"] = int(np.count_nonzero(fi < end))
    out["backlog_end_t"] = float(t[end]) if end else None
    d = np.diff(t[steady])
    out["camera_rate"] = float((steady.size - 1) / (t[steady[-1]] - t[steady[0]]))
    out["fix_interval_median"] = float(np.median(d))
    out["fix_interval_p10"], out["fix_interval_p90"] = (float(v) for v in
                                                        np.percentile(d, [10, 90]))
    out["fix_interval_max"] = float(np.max(d))
    out["samples_per_fix"] = np.bincount(np.diff(steady)).tolist()
    # Excess fixes over a steady camera since program start (t = 0) -> backlog origin.
    out["backlog_start_estimate_t"] = float(t[0] - out["backlog_fixes"] / out["camera_rate"]
                                            + (t[end] - t[0] if end else 0.0))
    return out


def phi_theta_lag(run: RigRun, lags: range = range(0, 13), t_min: float | None = None,
                  min_speed: float = 2.0) -> dict[str, Any]:
    """Which logged ``theta`` the rig pairs with each image in its ``phi``.

    For each lag L, the residual ``phi - (theta[k - L] + atan2(x, y))`` is evaluated at the
    new fixes k (after the start-up backlog, where ``|dtheta| > min_speed`` so that a wrong
    lag shows) and compared with the print resolution of theta.

    Returns
    -------
    dict
        ``best_lag`` [samples], ``best_lag_s`` [s] (mean sample period times lag),
        ``resolution`` [rad], and per lag ``median_abs`` [rad] and ``frac_within``
        (fraction of fixes with ``|residual| <= resolution``).
    """
    t, th, ph = run.column("t"), run.column("theta"), run.column("phi")
    x, y, dth = run.column("x"), run.column("y"), run.column("dtheta")
    fi = np.nonzero(_new_fix(run))[0]
    if t_min is None:
        t_min = float(t[_camera_backlog_end(fi, run.column("t"))]) + 0.1
    m = fi[(t[fi] > t_min) & (np.abs(dth[fi]) > min_speed) & (fi >= max(lags))]
    res = 10.0 ** (math.floor(math.log10(np.max(np.abs(th)))) - 5)
    psi = np.arctan2(x[m], y[m])
    table = {}
    for L in lags:
        r = ph[m] - (th[m - L] + psi)
        r = (r + np.pi) % (2 * np.pi) - np.pi
        table[L] = {"median_abs": float(np.median(np.abs(r))),
                    "frac_within": float(np.mean(np.abs(r) <= res * 1.01))}
    best = min(table, key=lambda k: table[k]["median_abs"])
    period = float((t[-1] - t[0]) / (len(run) - 1))
    return {"best_lag": int(best), "best_lag_s": best * period, "resolution": res,
            "fixes_used": int(m.size), "table": table}


def rolling_direction(run: RigRun) -> dict[str, float]:
    """Mean rates of ``theta`` and of the rig's ``phi`` over the valid rolling part.

    Returns ``theta_rate`` and ``phi_rate`` [rad/s] (least-squares slopes) and
    ``increment_correlation`` of their 0.5-s increments.
    """
    t, th, ph = run.column("t"), run.column("theta"), run.column("phi")
    fi = np.nonzero(_new_fix(run))[0]

    start = _camera_backlog_end(fi, run.column("t"))
    s = slice(start + 100, None)
    init = np.abs(ph[s] - th[s]) < 2.0  # the rig's phi estimator initialised
    tt, a, b = t[s][init], th[s][init], ph[s][init]
    grid = np.arange(tt[0], tt[-1], 0.5)
    da, db = np.diff(np.interp(grid, tt, a)), np.diff(np.interp(grid, tt, b))
    return {"theta_rate": float(np.polyfit(tt, a, 1)[0]),
            "phi_rate": float(np.polyfit(tt, b, 1)[0]),
            "increment_correlation": float(np.corrcoef(da, db)[0, 1])}


@dataclass
class BallRadiusFit:
    """Camera ball radius against the nominal ball-centre curve.

    Attributes
    ----------
    rms_nominal : float
        RMS of ``sqrt(x^2 + y^2) - |p|`` with no camera offset [m].
    mean_nominal : float
        Mean of that residual [m].
    theta_offset : float
        Best zero offset of theta (mod pi) without camera offset [rad].
    cx, cy : float
        Best camera-origin offset [m] (x, y measured = true + offset).
    theta_offset_with_camera : float
        Best zero offset of theta with the camera offset fitted [rad].
    rms_with_offset : float
        RMS residual after fitting (cx, cy, theta offset) [m].
    scale, cx_s, cy_s, rms_with_scale : float
        Fit with an extra camera scale factor [-] and its offsets and RMS [m].
    n : int
        Fixes used.
    binned : list of (float, float, float, int)
        ``(frame angle bin centre [rad], mean camera radius [m], nominal |p| [m], count)``.
    """

    rms_nominal: float
    mean_nominal: float
    theta_offset: float
    cx: float
    cy: float
    theta_offset_with_camera: float
    rms_with_offset: float
    scale: float
    cx_s: float
    cy_s: float
    rms_with_scale: float
    n: int
    binned: list[tuple[float, float, float, int]]


def _radius_table(params: Any = None) -> tuple[FloatArray, FloatArray]:

    curve = OffsetCurve.from_params(params if params is not None else load_params())
    ph = np.linspace(0.0, 2.0 * np.pi, 8193)
    pc = np.mod(curve.ball_angle(ph), 2.0 * np.pi)
    pr = np.linalg.norm(curve.point(ph), axis=-1)
    o = np.argsort(pc)
    return pc[o], pr[o]


def ball_radius_fit(run: RigRun, lag: int = 8, params: Any = None) -> BallRadiusFit:
    """Compare the camera radius with the nominal offset curve ``|p|`` (see class doc)."""
    th = run.column("theta")
    x, y = run.column("x"), run.column("y")
    fi = np.nonzero(_new_fix(run))[0]
    fi = fi[(fi >= _camera_backlog_end(fi, run.column("t"))) & (fi >= lag)]
    X, Y, T = x[fi], y[fi], th[fi - lag]
    pc, pr = _radius_table(params)

    def model_r(ang: FloatArray) -> FloatArray:
        return np.interp(np.mod(ang, 2.0 * np.pi), pc, pr, period=2.0 * np.pi)

    def resid(q: FloatArray, scale: bool) -> FloatArray:
        cx, cy, c = q[0], q[1], q[2]
        s = q[3] if scale else 1.0
        xx, yy = (X - cx) / s, (Y - cy) / s
        return np.hypot(xx, yy) - model_r(T - c + np.arctan2(xx, yy))

    grid = np.linspace(-np.pi / 2, np.pi / 2, 91)
    rms = [float(np.sqrt(np.mean(resid(np.array([0.0, 0.0, c]), False) ** 2))) for c in grid]
    c0 = float(grid[int(np.argmin(rms))])
    r0 = resid(np.array([0.0, 0.0, 0.0]), False)
    f1 = least_squares(resid, np.array([0.0, 0.0, c0]), args=(False,))
    f2 = least_squares(resid, np.array([f1.x[0], f1.x[1], f1.x[2], 1.0]), args=(True,))
    ang = np.mod(T + np.arctan2(X, Y), np.pi)
    edges = np.linspace(0.0, np.pi, 13)
    binned = []
    for lo, hi in itertools.pairwise(edges):
        sel = (ang >= lo) & (ang < hi)
        if sel.any():
            mid = 0.5 * (lo + hi)
            binned.append((float(mid), float(np.mean(np.hypot(X, Y)[sel])),
                           float(model_r(np.array([mid]))[0]), int(sel.sum())))
    return BallRadiusFit(
        rms_nominal=float(np.sqrt(np.mean(r0 ** 2))), mean_nominal=float(np.mean(r0)),
        theta_offset=c0, cx=float(f1.x[0]), cy=float(f1.x[1]),
        theta_offset_with_camera=float(f1.x[2]),
        rms_with_offset=float(np.sqrt(np.mean(f1.fun ** 2))), scale=float(f2.x[3]),
        cx_s=float(f2.x[0]), cy_s=float(f2.x[1]),
        rms_with_scale=float(np.sqrt(np.mean(f2.fun ** 2))), n=int(fi.size), binned=binned)


def derivative_delay(t: FloatArray, value: FloatArray, rate: FloatArray,
                     shifts: FloatArray | None = None) -> dict[str, float]:
    """Delay and gain of a logged rate against the derivative of its logged value.

    Integrates ``rate`` (trapezoid) and finds the shift ``d`` and gain ``g`` minimising the
    RMS of ``value(t) - g * integral(t + d) - c``: a rate that lags the true derivative by
    ``d`` seconds matches at a positive ``d``.

    Returns
    -------
    dict
        ``delay`` [s], ``gain`` [-], ``rms`` [rad] at the optimum and ``rms_at_zero``.
    """
    keep = np.r_[True, np.diff(t) > 0]
    t, value, rate = t[keep], value[keep], rate[keep]
    integral = cumulative_trapezoid(rate, t, initial=0.0)
    if shifts is None:
        shifts = np.arange(-0.004, 0.020, 0.0001)
    best: tuple[float, float, float] | None = None
    at_zero = float("nan")
    for d in shifts:
        m = (t + d > t[0]) & (t + d < t[-1])
        a = np.c_[np.interp(t[m] + d, t, integral), np.ones(int(m.sum()))]
        sol = np.linalg.lstsq(a, value[m], rcond=None)[0]
        r = float(np.sqrt(np.mean((value[m] - a @ sol) ** 2)))
        if abs(d) < 1e-12:
            at_zero = r
        if best is None or r < best[0]:
            best = (r, float(d), float(sol[0]))
    assert best is not None
    return {"delay": best[1], "gain": best[2], "rms": best[0], "rms_at_zero": at_zero}


@dataclass
class NoBallFit:
    """Frame-only parameters from the no-ball runs (torque gain k not separable).

    Model: ``J theta_ddot = k u - T_c sign(theta_dot) - c_v theta_dot (+ imbalance)``.
    Only ratios to ``k`` are identifiable; the values below assume ``k = 1``.

    Attributes
    ----------
    accel0 : float
        Step runs: acceleration at zero speed [rad/s^2] = (k u - T_c) / J (mean of runs).
    accel0_std : float
        Run-to-run standard deviation of ``accel0`` [rad/s^2].
    decay : float
        Step runs: ``c_v / J`` [1/s] (mean of runs).
    decay_std : float
        Run-to-run standard deviation of ``decay`` [1/s].
    step_torque : float
        Commanded torque of the step runs [N m].
    hold_torque : float
        Friction run: mean torque at the tracked speed [N m] = T_c + c_v w.
    hold_speed : float
        Friction run: mean speed [rad/s].
    hold_harmonics : dict of str to float
        Friction run: torque ripple ``u - mean`` fitted as ``a1 sin(theta) + b1 cos(theta)
        + a2 sin(2 theta) + b2 cos(2 theta)`` [N m].
    inertia : float
        ``J / k`` [kg m^2].
    coulomb : float
        ``T_c / k`` [N m].
    viscous : float
        ``c_v / k`` [N m s/rad].
    torque_sign : int
        +1 when a positive command accelerates theta positive.
    runs : int
        Step runs used.
    """

    accel0: float
    accel0_std: float
    decay: float
    decay_std: float
    step_torque: float
    hold_torque: float
    hold_speed: float
    hold_harmonics: dict[str, float]
    inertia: float
    coulomb: float
    viscous: float
    torque_sign: int
    runs: int


def _uniform(t: FloatArray, *ys: FloatArray, dt: float = 1e-3) -> tuple[FloatArray, ...]:
    keep = np.r_[True, np.diff(t) > 0]
    tg = np.arange(t[keep][0], t[keep][-1], dt)
    return (tg, *(np.interp(tg, t[keep], y[keep]) for y in ys))


def frame_fit_no_ball(step_runs: list[RigRun], friction_run: RigRun,
                      window: int = 201) -> NoBallFit:
    """Fit the frame's inertia and friction from the step and speed-tracking runs.

    The step runs (constant torque from rest) give ``theta_ddot = A - B theta_dot``
    (Savitzky-Golay derivatives of theta on a 1 ms grid, edges dropped); the friction run
    gives the holding torque ``T_c + c_v w`` at its tracked speed ``w``. Then
    ``J = (u_step - T_c) / A``, ``c_v = B J`` and ``T_c = u_hold - c_v w`` solved jointly.
    """
    a0s, decays, u_steps, signs = [], [], [], []
    for run in step_runs:
        _, u, th = _uniform(run.column("t"), run.column("torque"), run.column("theta"))
        w = savgol_filter(th, window, 3, deriv=1, delta=1e-3)
        acc = savgol_filter(th, window, 3, deriv=2, delta=1e-3)
        s = slice(window, -window)
        slope, icpt = np.polyfit(w[s], acc[s], 1)
        a0s.append(icpt)
        decays.append(-slope)
        u_steps.append(float(np.median(u)))
        signs.append(np.sign(np.median(acc[s])) * np.sign(np.median(u)))
    _, u, th = _uniform(friction_run.column("t"), friction_run.column("torque"),
                         friction_run.column("theta"))
    w = savgol_filter(th, window, 3, deriv=1, delta=1e-3)
    s = slice(int(3.0 / 1e-3), -window)  # skip the speed controller's transient
    hold_u, hold_w = float(np.mean(u[s])), float(np.mean(w[s]))
    basis = np.c_[np.sin(th[s]), np.cos(th[s]), np.sin(2 * th[s]), np.cos(2 * th[s])]
    coef = np.linalg.lstsq(basis, u[s] - hold_u, rcond=None)[0]
    a0, decay, u_step = float(np.mean(a0s)), float(np.mean(decays)), float(np.mean(u_steps))
    # hold_u = Tc + cv w, cv = decay J, J = (u_step - Tc) / a0  ->  solve for Tc.
    r = decay * hold_w / a0
    coulomb = (hold_u - r * u_step) / (1.0 - r)
    inertia = (u_step - coulomb) / a0
    return NoBallFit(
        accel0=a0, accel0_std=float(np.std(a0s)), decay=decay, decay_std=float(np.std(decays)),
        step_torque=u_step, hold_torque=hold_u, hold_speed=hold_w,
        hold_harmonics={"a1_sin": float(coef[0]), "b1_cos": float(coef[1]),
                        "a2_sin2": float(coef[2]), "b2_cos2": float(coef[3])},
        inertia=float(inertia), coulomb=float(coulomb), viscous=float(decay * inertia),
        torque_sign=int(np.sign(np.mean(signs))), runs=len(step_runs))


def camera_delay_smoothness(run: RigRun, taus: FloatArray | None = None,
                            window: int = 11) -> dict[str, Any]:
    """Kinematic test of the camera delay: smoothness of ``atan2(x, y) + theta(t - tau)``.

    If the image of a fix arriving at ``t`` was taken at ``t - tau``, the ball's frame
    angle ``atan2(x, y) + theta(t - tau)`` should be smoothest at the true ``tau`` (the
    frame's fast, torque-driven motion cancels). Returns the high-pass RMS per ``tau``
    (Savitzky-Golay residual, ``window`` fixes). On these logs the curve is flat within
    ~15 % and its minimum is set by theta's print quantisation: inconclusive.
    """
    if taus is None:
        taus = np.arange(-0.005, 0.0301, 0.0005)
    t, th = run.column("t"), run.column("theta")
    x, y = run.column("x"), run.column("y")
    keep = np.r_[True, np.diff(t) > 0]
    fi = np.nonzero(_new_fix(run) & keep)[0]
    fi = fi[fi >= _camera_backlog_end(fi, run.column("t"))]
    tf, psi = t[fi], np.arctan2(x[fi], y[fi])
    hp = []
    for tau in taus:
        pe = psi + np.interp(tf - tau, t[keep], th[keep])
        hp.append(float(np.sqrt(np.mean((pe - savgol_filter(pe, window, 3)) ** 2))))
    i = int(np.argmin(hp))
    return {"taus": [float(v) for v in taus], "hp_rms": hp, "best_tau": float(taus[i]),
            "spread": float((max(hp) - min(hp)) / min(hp))}


def _fmt(v: float, unit: str = "", digits: int = 4) -> str:
    return f"{v:.{digits}g}{(' ' + unit) if unit else ''}"


def report(data_dir: Path, params: Any = None) -> str:
    """The full conventions report for the logs in ``data_dir`` (plain text).

    ``params`` (a ``RigParams``) sets the nominal geometry; default ``load_params()``.
    """
    out: list[str] = []
    logs = {p.stem: parse_rig_log(p, warn=False) for p in sorted(data_dir.glob("*.txt"))}
    out.append("== parse summary and timing")
    for name, log in logs.items():
        runs = log.runs
        st = fix_statistics(max(runs, key=len))
        out.append(f"{name}: lines {log.n_lines}, data {log.n_data}, runs {len(runs)}, "
                   f"skipped {log.skipped}")
        line = (f"   loop: {st['loop_rate_mean']:.1f} Hz mean (median dt "
                f"{st['loop_dt_median'] * 1e3:.2f} ms, max {st['loop_dt_max'] * 1e3:.2f} ms)")
        if "camera_rate" in st:
            line += (f"; camera: {st['camera_rate']:.2f} Hz, fix interval median "
                     f"{st['fix_interval_median'] * 1e3:.2f} ms (p10 "
                     f"{st['fix_interval_p10'] * 1e3:.2f}, p90 "
                     f"{st['fix_interval_p90'] * 1e3:.2f}, max "
                     f"{st['fix_interval_max'] * 1e3:.2f}); samples per fix "
                     f"{st['samples_per_fix']}; start-up backlog {st['backlog_fixes']} fixes "
                     f"until t = {st['backlog_end_t']}")
        else:
            line += f"; camera: {st['fixes']} distinct fix(es) in the run"
        out.append(line)
    for name in ("Actually_worked", "fin"):
        if name not in logs:
            continue
        run = max(logs[name].runs, key=len)
        out.append(f"== {name}: phi vs theta[k - L] + atan2(x, y) at new fixes")
        lag = phi_theta_lag(run)
        for L, v in lag["table"].items():
            out.append(f"   L = {L:2d}: median |res| {v['median_abs']:.4f} rad, within "
                       f"resolution {lag['resolution']:g}: {v['frac_within']:.3f}")
        out.append(f"   best L = {lag['best_lag']} samples = {lag['best_lag_s'] * 1e3:.2f} ms "
                   f"({lag['fixes_used']} fixes with |dtheta| > 2 rad/s)")
        rd = rolling_direction(run)
        out.append(f"   rolling: theta rate {rd['theta_rate']:.3f} rad/s, phi rate "
                   f"{rd['phi_rate']:.3f} rad/s, 0.5-s increment correlation "
                   f"{rd['increment_correlation']:.3f}")
        fit = ball_radius_fit(run, params=params)
        out.append(f"   camera radius - nominal |p|: mean {fit.mean_nominal * 1e3:.2f} mm, rms "
                   f"{fit.rms_nominal * 1e3:.2f} mm; best theta zero offset (no camera "
                   f"offset) {fit.theta_offset:.4f} rad")
        out.append(f"   with camera offset: cx {fit.cx * 1e3:.2f} mm, cy {fit.cy * 1e3:.2f} mm, "
                   f"theta offset {fit.theta_offset_with_camera:.4f} rad, rms "
                   f"{fit.rms_with_offset * 1e3:.2f} mm")
        out.append(f"   + scale: s {fit.scale:.4f}, cx {fit.cx_s * 1e3:.2f} mm, cy "
                   f"{fit.cy_s * 1e3:.2f} mm, rms {fit.rms_with_scale * 1e3:.2f} mm "
                   f"({fit.n} fixes)")
        out.append("   frame angle bin [rad] | mean camera radius [m] | nominal |p| [m] | n")
        for b in fit.binned:
            out.append(f"     {b[0]:.2f} | {b[1]:.4f} | {b[2]:.4f} | {b[3]}")
        t = run.column("t")
        fi = np.nonzero(_new_fix(run))[0]

        start = _camera_backlog_end(fi, run.column("t"))
        ph = run.column("phi")
        sel = fi[(fi > start + 20)]
        dd = derivative_delay(t[sel], ph[sel] - 0.0, run.column("dphi")[sel],
                              shifts=np.arange(-0.01, 0.03, 0.0005))
        out.append(f"   dphi vs derivative of phi (at fixes): delay {dd['delay'] * 1e3:.1f} ms, "
                   f"gain {dd['gain']:.3f}")
        cam = camera_delay_smoothness(run)
        hp = dict(zip(cam["taus"], cam["hp_rms"], strict=True))
        pick = [0.0, 0.005, 0.0085, 0.012, 0.02]
        def near(k: float, hp: dict[float, float] = hp) -> float:
            return min(hp.items(), key=lambda kv: abs(kv[0] - k))[1]

        vals = ", ".join(f"{k * 1e3:.1f} ms: {near(k) * 1e3:.3f}" for k in pick)
        out.append(f"   camera-delay smoothness test: HP rms [mrad] {vals}; min at "
                   f"{cam['best_tau'] * 1e3:.1f} ms, spread {cam['spread'] * 100:.0f} % "
                   f"(inconclusive)")
    out.append("== dtheta vs derivative of theta (integral method)")
    for name, log in logs.items():
        run = log.runs[0]
        dd = derivative_delay(run.column("t"), run.column("theta"), run.column("dtheta"))
        out.append(f"   {name}: delay {dd['delay'] * 1e3:.1f} ms, gain {dd['gain']:.4f}, rms "
                   f"{dd['rms'] * 1e3:.2f} mrad (at 0 delay {dd['rms_at_zero'] * 1e3:.2f})")
    if "step_response_tau_001" in logs and "friction_v_ref_1" in logs:
        nb = frame_fit_no_ball(logs["step_response_tau_001"].runs,
                               logs["friction_v_ref_1"].runs[0])
        out.append("== no-ball frame fit (torque gain k = 1 assumed)")
        out.append(f"   step runs: {nb.runs}, u = {nb.step_torque:g} N m, theta_ddot = "
                   f"{nb.accel0:.3f} (+-{nb.accel0_std:.3f}) - {nb.decay:.4f} "
                   f"(+-{nb.decay_std:.4f}) theta_dot")
        out.append(f"   friction run: hold torque {nb.hold_torque * 1e3:.3f} mN m at "
                   f"{nb.hold_speed:.4f} rad/s; ripple "
                   + ", ".join(f"{k} {v * 1e3:.3f} mN m" for k, v in nb.hold_harmonics.items()))
        out.append(f"   J/k = {nb.inertia:.4e} kg m^2, T_c/k = {nb.coulomb:.4e} N m, c_v/k = "
                   f"{nb.viscous:.4e} N m s/rad, J/c_v = {nb.inertia / nb.viscous:.1f} s, "
                   f"torque sign {nb.torque_sign:+d}")
    return "\n".join(out)


def _main(argv: list[str] | None = None) -> int:

    ap = argparse.ArgumentParser(prog="python -m bfr_model.io.rig_conventions",
                                 description="Print the inferred conventions of the NTNU logs.")
    ap.add_argument("data_dir", nargs="?", type=Path, default=None)
    ap.add_argument("--params", type=Path, default=None,
                    help="parameter YAML for the nominal geometry (default: rig.yaml)")
    args = ap.parse_args(argv)
    data_dir = args.data_dir or default_data_dir()
    if not data_dir.is_dir():
        print(f"no data directory {data_dir}")
        return 2
    params = None
    if args.params is not None:
        params = load_params(args.params)
    print(report(data_dir, params))
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
