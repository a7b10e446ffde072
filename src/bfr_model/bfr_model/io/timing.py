"""Sensor timing of a recording, measured on the recording itself (no rig's constants).

A rig's logger may report the frame's velocity with a lag, log at any rate, and replay a
camera's queued frames at start-up. What one rig shows (the NTNU rig: a 6.4 ms velocity lag,
~920 lines per second, a fix every ~6 ms) is a fact about that rig, so each quantity here is
estimated on every recording and reported with how well the recording determines it.

Velocity lag (:func:`velocity_lag`). A logged velocity ``v`` that lags the true rate of the
logged angle ``theta`` by ``d`` integrates to ``theta`` only when advanced by ``d``:

    theta(t) - theta(t0) = int_t0^t v(s + d) ds                                         (1)

A velocity estimator is a filter, not only a delay: a first-order lag of time constant tau
is, to second order, the delay tau with ``v_true = v(t + d) + c2 v''(t + d)``, ``c2 =
-tau^2 / 2``; a moving average over a window L is the delay L / 2 with ``c2 = +L^2 / 24``.
Both terms are measured: after d, the remaining error of (1) is ``c2 v'(t + d)`` plus a
constant (the integral of ``c2 v''``), and c2 is its least-squares coefficient on the
smoothed ``v'(t + d)`` (same blocks). :func:`corrected_velocity` applies both.

To first order in d, ``int v(s + d) ds = int v(s) ds + d (v(t) - v(t0))``, so the error of
the unshifted integral ``e(t) = theta(t) - theta(t0) - int_t0^t v ds`` is ``d v(t)`` plus a
constant. An offset of v makes the integral drift, so in each block of ``window`` seconds a
straight line ``c0 + c1 t`` is projected out of both e and v (P the projection), and d is
their least-squares ratio ``<P e, P v> / <P v, P v>``, refined at the shift found (the
first-order step is exact only to first order). Its standard error comes from the residual
of (1), inflated by the residual's correlation time. A recording whose velocity hardly
varies (a frame at constant speed) determines nothing: ``identified`` is False, and the lag
is then irrelevant to any use of v (a shift of a constant changes nothing).

Camera backlog (:func:`camera_backlog_end`). A camera that queued frames since program start
delivers them at the logger's rate when the loop starts: fixes arrive faster than the camera
can take them. The steady interval between fixes is the median interval over the second half
of the run; the backlog is the initial burst of intervals shorter than half of it. A log
written at under twice the camera's rate (every third line of the NTNU rig's 920 Hz: the
replay's fixes one per 3.3 ms line, the camera's one per 1.86 lines) has no interval under
half of the median: there the burst is the run's first fixes arriving one per line at 1.5
times the camera's mean rate or more, and it ends where the fixes' median interval over
``steady`` of them comes within 15 % of the camera's mean (the first fixes of that window that
still came one per line counted to the burst). A log at the camera's rate or slower (a new
fix on every line whether replayed or not) shows no burst in its times: no backlog is found
there, and none is assumed.

Camera clock (:func:`camera_clock`). A log without the fixes' own stamps places each fix
at the line where it first appears: ``t_k = t_e,k + L + q_k``, the exposure ``t_e,k``,
a latency L and the wait ``q_k`` in [0, dl) for the next line (dl the line interval).
Where the camera and the logger run at nearly commensurate rates (182.4 fixes against
725.9 lines per second: 3.98 lines a fix) q_k is not white: it drifts through [0, dl) as a
sawtooth of a fraction of a second, a slowly varying latency that no smoothing removes,
worth ``|v| dl / sqrt(12)`` of position (0.1 mm at 0.25 m/s and 1.4 ms, as much as a
camera's noise). A camera that exposes on its own steady clock, ``t_e,k = a + T n_k``
(``n_k`` the frame count, dropped frames included), is recovered by a straight line
through the arrival times against ``n_k`` per run of fixes without a gap of more than
``max_gap`` (the period from spans of 20 fixes, the counts by rounding on it, the line
refitted without late deliveries); its residual is then the wait, of standard deviation
``dl / sqrt(12)``, plus whatever jitter the camera or its delivery adds. The clock is used
when the residual's standard deviation (late deliveries left out) is at most ``sqrt(2)``
times the wait (then the clock
cannot be the worse timing, :func:`camera_clock`) and no two fixes fall on one frame;
otherwise the arrival times stay, and the report says which and why. The NTNU logs: a
steady 164.98 Hz camera (no frame dropped in 30 s), arrivals scattered 0.46 ms about it
against a wait of 0.32 ms (1.45x: kept, a near thing). The line's mean wait ``dl / 2``
stays in the times (part of the latency the sensor model fits).

Pure numpy; no ``rclpy``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter

__all__ = ["CameraClock", "VelocityLag", "camera_backlog_end", "camera_clock",
           "corrected_velocity", "line_rate", "robust_sd", "velocity_lag"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class VelocityLag:
    """The lag of a logged velocity behind the rate of the logged angle (module docstring).

    Attributes
    ----------
    lag : float
        ``d`` of eq. (1) [s] (positive: the velocity is late); 0 when not identified.
    std : float
        Its standard error [s] (inf when not identified).
    identified : bool
        The velocity varies enough for the lag to matter and be measured: std < 1 ms, and
        the shift removes a tenth of the error or is within two standard errors of zero.
    rms_unshifted, rms_shifted : float
        RMS of the detrended error of eq. (1) without and with the correction [rad].
    note : str
        What was found, for reports.
    c2 : float
        The second-order term [s^2] (module docstring; 0 when not measured).
    c2_std : float
        Its standard error [s^2].
    """

    lag: float
    std: float
    identified: bool
    rms_unshifted: float
    rms_shifted: float
    note: str
    c2: float = 0.0
    c2_std: float = math.inf

    def to_json(self) -> dict[str, float | bool | str | None]:
        """JSON-ready dict (inf as None)."""
        return {"lag_s": self.lag, "std_s": self.std if math.isfinite(self.std) else None,
                "c2_s2": self.c2,
                "c2_std_s2": self.c2_std if math.isfinite(self.c2_std) else None,
                "identified": self.identified, "rms_unshifted_rad": self.rms_unshifted,
                "rms_shifted_rad": self.rms_shifted, "note": self.note}


def _detrend_blocks(y: FloatArray, k: int) -> FloatArray:
    """``y`` with a straight line fitted out of each block of ``k`` samples (last block longer).

    The projection P of the module docstring: per block, the residual of ``y`` on
    ``[1, i]``.
    """
    out = np.empty_like(y)
    nb = max(y.size // k, 1)
    edges = np.linspace(0, y.size, nb + 1).astype(int)
    for a, b in itertools.pairwise(edges):
        x = np.arange(b - a, dtype=float)
        x -= x.mean()
        seg = y[a:b] - y[a:b].mean()
        den = float(np.dot(x, x))
        out[a:b] = seg - (x * float(np.dot(x, seg)) / den if den > 0 else 0.0)
    return out


def velocity_lag(t: FloatArray, theta: FloatArray, theta_dot: FloatArray, *,
                 window: float = 4.0, dt: float | None = None,
                 max_lag: float = 0.05) -> VelocityLag:
    """Measure how late a logged velocity is (module docstring, eq. 1).

    Parameters
    ----------
    t : ndarray
        Sample times [s], increasing.
    theta : ndarray
        Logged angle [rad] (any resolution).
    theta_dot : ndarray
        Logged velocity [rad/s].
    window : float
        Length of the blocks in which a drift line is removed [s].
    dt : float, optional
        Grid step of the test [s] (default: the median sample interval, at most 2 ms).
    max_lag : float
        Largest lag believed [s]; a fit beyond it is reported as not identified.

    Returns
    -------
    VelocityLag
    """
    t = np.asarray(t, float)
    n = t.size
    nothing = VelocityLag(lag=0.0, std=math.inf, identified=False, rms_unshifted=float("nan"),
                          rms_shifted=float("nan"), note="too few samples to measure a lag")
    if n < 50 or t[-1] - t[0] < 0.3:
        return nothing
    step = float(dt or min(np.median(np.diff(t)), 2e-3))
    tg = t[0] + step * np.arange(int((t[-1] - t[0]) / step))
    # cubic splines through the samples, the velocity integrated exactly: a trapezoid sum
    # (or a linear interpolant) is off by -h^2/12 v' (h^2/8 of theta''), which the fit of
    # c2 below took for a filter's term (-0.28 ms^2 at 545 lines per second, a velocity
    # scale error of 1e-4 at the orbit's frequencies)
    th = CubicSpline(t, theta)(tg)
    v = np.interp(tg, t, theta_dot)
    v_int = CubicSpline(t, theta_dot).antiderivative()
    k = max(round(window / step), 10)
    edge = max(round(max_lag / step), 1)  # shifted samples beyond the ends are not used

    def error(d: float) -> FloatArray:
        e = th - th[0] - (v_int(tg + d) - v_int(tg[0] + d))
        return _detrend_blocks(e[edge:-edge], k)

    hv = _detrend_blocks(v[edge:-edge], k)
    e0 = error(0.0)
    den = float(np.dot(hv, hv))
    if hv.size < 20 or den <= 0.0:
        return VelocityLag(lag=0.0, std=math.inf, identified=False, rms_unshifted=float("nan"),
                           rms_shifted=float("nan"),
                           note="the velocity is constant: no lag to measure, none applied")
    d = float(np.dot(e0, hv) / den)
    for _ in range(2):  # refine: the first-order step is exact only for small lags
        if not abs(d) <= max_lag:
            break
        e = error(d)
        d = d + float(np.dot(e, hv) / den)
    rms0 = float(np.sqrt(np.mean(e0 ** 2)))
    if not abs(d) <= max_lag:
        return VelocityLag(lag=0.0, std=math.inf, identified=False, rms_unshifted=rms0,
                           rms_shifted=rms0, note=f"fitted lag {d * 1e3:.1f} ms beyond "
                           f"{max_lag * 1e3:.0f} ms: not identified, none applied")
    e = error(d)
    rms1 = float(np.sqrt(np.mean(e ** 2)))
    std = _coefficient_std(e, den, hv.size)
    # measured: a small standard error, and a shift that explains the error (a lag
    # indistinguishable from zero needs no explaining)
    identified = bool(std < 1e-3 and (rms1 < 0.9 * rms0 or abs(d) < 2.0 * std))
    c2, c2_std = 0.0, math.inf
    if identified:  # the second-order term: e on the smoothed v'(t + d)
        vs = np.interp(tg + d, t, theta_dot)
        win = max(int(0.03 / step) | 1, 5)
        X = _detrend_blocks(savgol_filter(vs, win, 3, deriv=1, delta=step)[edge:-edge], k)
        dx = float(np.dot(X, X))
        if dx > 0.0:
            c = float(np.dot(e, X) / dx)
            c_std = _coefficient_std(e - c * X, dx, X.size)
            if abs(c) > 3.0 * c_std:
                c2, c2_std = c, c_std
                e = e - c * X
                rms1 = float(np.sqrt(np.mean(e ** 2)))
    if identified:
        note = (f"logged velocity lags the angle's rate by {d * 1e3:.2f} ms "
                f"(+- {std * 1e3:.2f})" + (
                    f", second-order term {c2 * 1e6:+.2f} ms^2 (as a first-order lag of "
                    f"{math.sqrt(-2 * c2) * 1e3:.1f} ms)" if c2 < 0 else
                    f", second-order term {c2 * 1e6:+.2f} ms^2 (as a moving average of "
                    f"{math.sqrt(24 * c2) * 1e3:.1f} ms)" if c2 > 0 else "")
                + "; corrected by that")
    elif std >= 1e-3:
        note = (f"velocity lag not identified ({d * 1e3:.2f} +- {std * 1e3:.2f} ms; the "
                "velocity hardly varies): none applied")
    else:  # well measured, but the shift explains nothing (the velocity already on time)
        note = (f"velocity lag {d * 1e3:.2f} +- {std * 1e3:.2f} ms explains little of the "
                f"angle's error (RMS x{rms1 / rms0:.2f} shifted, under the encoder's steps): "
                f"none applied")
    return VelocityLag(lag=d if identified else 0.0, std=std if identified else math.inf,
                       identified=identified, rms_unshifted=rms0, rms_shifted=rms1, note=note,
                       c2=c2, c2_std=c2_std)


def _coefficient_std(resid: FloatArray, den: float, n: int) -> float:
    """Standard error of a least-squares coefficient ``<e, x> / den`` from its residual.

    Inflated by the residual's correlation time (samples to the first autocorrelation
    below 1/e, at least one).
    """
    ec = resid - resid.mean()
    var = float(np.dot(ec, ec))
    if var <= 0.0 or den <= 0.0:
        return 0.0
    tau = 1
    for lag in range(1, min(ec.size // 4, 2000)):
        if float(np.dot(ec[:-lag], ec[lag:])) / var < math.exp(-1.0):
            break
        tau = lag + 1
    return math.sqrt(var / max(n - 1, 1) * tau / den)


def corrected_velocity(t: FloatArray, theta_dot: FloatArray, tg: FloatArray, lag: float,
                       c2: float = 0.0) -> FloatArray:
    """The true rate on the grid ``tg`` from a logged velocity (module docstring).

    ``v(t + d) + c2 v''(t + d)`` (v by a cubic spline through its samples, ``v''`` by a cubic
    Savitzky-Golay filter of 30 ms).
    """
    v = (CubicSpline(t, theta_dot)(np.clip(tg + lag, t[0], t[-1])) if t.size > 3
         else np.interp(tg + lag, t, theta_dot))
    if c2 == 0.0 or tg.size < 7:
        return v
    step = float(tg[1] - tg[0])
    win = max(int(0.03 / step) | 1, 5)
    return v + c2 * savgol_filter(v, win, 3, deriv=2, delta=step)


def camera_backlog_end(fix_t: FloatArray, steady: int = 10, min_burst: int = 10,
                       line_period: float | None = None) -> int:
    """Index (into ``fix_t``) of the first fix after a start-up backlog; 0 when there is none.

    Parameters
    ----------
    fix_t : ndarray
        Times of the distinct fixes [s], increasing.
    steady : int
        Intervals in a row at the steady pace that end the burst.
    min_burst : int
        Fewest fast intervals that make a burst.
    line_period : float, optional
        The log's line interval [s]: with it, a burst of one fix per line at 1.5-2 times the
        camera's rate is found too (module docstring).

    Returns
    -------
    int
        The backlog is ``fix_t[:end]`` (module docstring).
    """
    fix_t = np.asarray(fix_t, float)
    if fix_t.size < 2 * (min_burst + steady):
        return 0
    gaps = np.diff(fix_t)
    typical = float(np.median(gaps[gaps.size // 2:]))
    if typical <= 0.0:
        return 0
    fast = gaps < 0.5 * typical
    if np.count_nonzero(fast[:4 * min_burst]) < min_burst:
        return _burst_at_line_rate(gaps, steady, min_burst, line_period)
    ok = (~fast).astype(np.int64)
    run = np.convolve(ok, np.ones(steady, np.int64), mode="valid")
    j = np.nonzero(run == steady)[0]
    if j.size == 0:
        return 0  # never settles: not a backlog, the camera is simply irregular
    return int(j[0] + 1)


def _burst_at_line_rate(gaps: FloatArray, steady: int, min_burst: int,
                        line_period: float | None) -> int:
    """:func:`camera_backlog_end` for a log at 1.5-2 times the camera's rate (module docstring).

    The first ``min_burst`` intervals one line each (their median within 25 % of
    ``line_period``, a line's jitter allowed) and their median under 2/3 of the camera's mean
    interval (the second half's); the end where the median of ``steady`` intervals reaches
    85 % of it, the window's leading intervals of one line (under 1.5 lines) counted to the
    burst, and that within the first quarter of the fixes. 0 without ``line_period`` or
    such a start.
    """
    if line_period is None or not line_period > 0.0 or gaps.size < 2 * (min_burst + steady):
        return 0
    camera = float(np.mean(gaps[gaps.size // 2:]))
    head = float(np.median(gaps[:min_burst]))
    if head > 1.25 * line_period or not camera > 0.0 or head > camera / 1.5:
        return 0
    # the median over gaps[i:i+steady] (one long pause, a log's lone first line, is no pace)
    pace = np.median(np.lib.stride_tricks.sliding_window_view(gaps, steady), axis=1)
    j = np.nonzero(pace >= 0.85 * camera)[0]
    if j.size == 0:
        return 0
    i = int(j[0])
    while i < j[0] + steady and gaps[i] < 1.5 * line_period:
        i += 1
    # a start-up replay is the run's beginning: a "burst" over a quarter of the fixes is a
    # log at the camera's rate whose camera later slowed (or lost the ball), not a replay
    return i + 1 if i < gaps.size // 4 else 0


def line_rate(t: FloatArray) -> float:
    """Mean line (sample) rate [Hz]: ``(n - 1) / (t[-1] - t[0])``; NaN below two samples."""
    t = np.asarray(t, float)
    if t.size < 2 or t[-1] <= t[0]:
        return float("nan")
    return float((t.size - 1) / (t[-1] - t[0]))


@dataclass(frozen=True, kw_only=True)
class CameraClock:
    """The fixes' times after :func:`camera_clock` (module docstring), and why.

    Attributes
    ----------
    times : ndarray
        Fix times [s]: on the fitted clock when ``used``, else the arrival times.
    used : bool
        Whether the fixes were placed on a steady camera clock.
    period : float
        The clock's frame period [s] (median over the runs fitted; NaN if none).
    residual_std : float
        Standard deviation [s] of the arrival times about the fitted clock (NaN if none).
    wait_std : float
        That of the wait for the next line, ``dl / sqrt(12)`` [s]: what a steady camera
        leaves.
    reason : str
        One line for the report.
    """

    times: FloatArray
    used: bool
    period: float
    residual_std: float
    wait_std: float
    reason: str

    def to_json(self) -> dict[str, object]:
        """The figures (not the times) for a report."""
        return {"used": self.used, "period_s": self.period,
                "residual_std_s": self.residual_std, "line_wait_std_s": self.wait_std,
                "reason": self.reason}


HEAD = 256  # fixes of the periodogram and of the clock's first prefix (_clock_line)


def _first_period(seg: FloatArray, head: int = HEAD) -> float:
    """A camera's frame period from its arrivals, to a few 1e-4 (:func:`_clock_line`).

    The median span over 20 fixes is only good to a line interval over 20 frames: where a
    frame lasts 1.3-2.3 lines the spans take two values, and the median is off by 1-3 %
    (264.6 lines and a 201 Hz camera: 203.5 Hz), so that even 16 frames slip one. Arrivals
    are exposures plus a wait in ``[0, dl)``: at the camera's frequency their phases spread
    over ``dl / T`` of a cycle and still add up (to ``sin(pi dl/T) / (pi dl/T)`` of the
    count, 0.28 at 1.3 lines a frame), while a wrong frequency makes them wind round.
    """
    m = min(20, seg.size - 1)
    p0 = float(np.median((seg[m:] - seg[:-m]) / m))
    x = seg[:min(seg.size, head)] - seg[0]
    span = float(x[-1]) if x.size > 1 else 0.0
    if not (p0 > 0.0 and span > 0.0):
        return p0
    f = np.arange(0.9 / p0, 1.1 / p0, 0.1 / span)
    power = np.abs(np.exp(2j * np.pi * np.outer(f, x)).sum(axis=1))
    return float(1.0 / f[int(np.argmax(power))])


def _clock_line(seg: FloatArray) -> tuple[FloatArray, FloatArray, float, float]:
    """Frame counts, residuals, period and origin of one run's arrivals on a steady clock.

    The period starts at the strongest peak of the arrivals' Rayleigh periodogram
    ``|sum_k exp(2 pi i f t_k)|`` over the first 256 fixes, searched within 10 % of the
    median span over m = 20 fixes divided by m (:func:`_first_period`). The clock is then
    fitted on a growing prefix of the run (those 256 fixes, doubled until the whole run):
    each fix's frame count is its time since the origin over the period, rounded, and a straight
    line through (count, time), refitted without the arrivals beyond 4 robust sd (late
    deliveries), gives the next period and origin. Counting on the whole run at once with
    the first period would slip a frame wherever its error times the count passes half a
    period (0.1 % over 500 frames); the prefix keeps that error far below it. (A line
    through W arrivals has a slope good to ``dl / W^1.5``; from a prefix of 16, the next
    one of 32 frames slipped at 1.5 lines a frame. From 256 the doubled prefix is off by
    ``dl / 8`` at most.)
    """
    period = _first_period(seg, HEAD)
    origin = float(seg[0])
    end = min(seg.size, HEAD)
    while True:
        part = seg[:end]
        keep = np.ones(end, bool)
        for _ in range(2):
            n = np.round((part - origin) / period)
            design = np.column_stack([np.ones_like(n), n])
            coef, *_ = np.linalg.lstsq(design[keep], part[keep], rcond=None)
            origin, period = float(coef[0]), float(coef[1])
            r = part - (origin + period * n)
            keep = np.abs(r - np.median(r)) <= 4.0 * robust_sd(r) + 1e-9
        if end == seg.size:
            break
        end = min(seg.size, 2 * end)
    n = np.round((seg - origin) / period)
    return n, seg - (origin + period * n), period, origin


def robust_sd(x: FloatArray) -> float:
    """Robust standard deviation: 1.4826 times the median absolute deviation."""
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def camera_clock(arrivals: FloatArray, line_interval: float, max_gap: float = 0.05,
                 tolerance: float = math.sqrt(2.0), min_fixes: int = 20) -> CameraClock:
    """Place fixes that arrive on log lines on the camera's own steady clock, if it has one.

    Parameters
    ----------
    arrivals : ndarray
        Times [s] of the lines where each distinct fix first appears (increasing).
    line_interval : float
        The log's median line interval dl [s].
    max_gap : float
        A run of fixes ends at a longer gap [s]; each run gets its own clock line.
    tolerance : float
        The clock is used when the arrivals' scatter about it (their standard deviation,
        late deliveries beyond 4 robust sd left out) is at most this times
        the wait ``w = dl / sqrt(12)``. With ``sqrt(2)`` the clock is never the worse
        timing: the scatter ``s`` is the wait and the camera's own (exposure) jitter ``e``
        or a delivery jitter together, ``s^2 >= w^2 + e^2``, so the clock's error e is at
        most ``sqrt(s^2 - w^2) <= w``, while the arrival's is at least w.
    min_fixes : int
        Runs with fewer fixes keep their arrival times.

    Returns
    -------
    CameraClock
        The times and the figures that decided (module docstring).
    """
    t = np.asarray(arrivals, float)
    wait = float(line_interval) / math.sqrt(12.0) if math.isfinite(line_interval) else \
        float("nan")
    if t.size < min_fixes or not math.isfinite(wait) or wait <= 0.0:
        return CameraClock(times=t, used=False, period=float("nan"),
                           residual_std=float("nan"), wait_std=wait,
                           reason="too few fixes or no line interval: arrival times kept")
    gaps = np.nonzero(np.diff(t) > max_gap)[0]
    bounds = np.concatenate([[0], gaps + 1, [t.size]])
    fitted = t.copy()
    resid, periods, doubled = [], [], 0
    for a, b in itertools.pairwise(bounds):
        if b - a < min_fixes:
            continue
        n, r, period, origin = _clock_line(t[a:b])
        doubled += int(np.sum(np.diff(n) < 1))
        fitted[a:b] = origin + period * n
        resid.append(r)
        periods.append(period)
    if not resid:
        return CameraClock(times=t, used=False, period=float("nan"),
                           residual_std=float("nan"), wait_std=wait,
                           reason=f"no run of {min_fixes} fixes without a gap: arrival "
                                  "times kept")
    r_all = np.concatenate(resid)
    inside = np.abs(r_all - np.median(r_all)) <= 4.0 * robust_sd(r_all) + 1e-9
    scatter = float(np.std(r_all[inside]))  # late deliveries beyond 4 robust sd left out
    period = float(np.median(periods))
    if doubled == 0 and scatter <= tolerance * wait:
        return CameraClock(times=fitted, used=True, period=period, residual_std=scatter,
                           wait_std=wait,
                           reason=(f"steady camera clock of {1.0 / period:.2f} Hz: the "
                                   f"arrivals scatter {scatter * 1e3:.3f} ms about it, the "
                                   f"wait for a line {wait * 1e3:.3f} ms; fixes placed on "
                                   "the clock"))
    why = (f"the arrivals scatter {scatter * 1e3:.3f} ms about a steady clock of "
           f"{1.0 / period:.2f} Hz, "
           + (f"{doubled} fix(es) on one frame of it" if doubled else
              f"more than {tolerance:.3g} x the wait for a line ({wait * 1e3:.3f} ms): the "
              "clock might be the worse timing"))
    return CameraClock(times=t, used=False, period=period, residual_std=scatter,
                       wait_std=wait,
                       reason=f"no steady camera clock ({why}): fixes at their lines' times")
