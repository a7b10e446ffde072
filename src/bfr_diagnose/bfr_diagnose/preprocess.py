"""Preprocessing: from a :class:`~bfr_model.recording.Recording` to smooth states on a grid.

Steps (docs/diagnosis.md):

1. Uniform grid of step ``dt`` (default 2 ms) over the recording.
2. Frame angle. If the encoder is fine (resolution below 1e-4 rad) theta is anti-aliased
   (zero-phase Hann of ``antialias`` on a 4x finer grid), smoothed with a Savitzky-Golay
   filter (cubic, window ``sg_theta``) and differentiated. If theta is coarse (the NTNU logs
   print 6 significant digits: 1-10 mrad) the servo's velocity estimate is used:
   ``theta_dot(t) = dtheta(t + d)`` (the logged estimate lags by ``d``), ``theta`` is its
   integral fused with the coarse angle by a slow low-pass of the difference
   (complementary filter, ``fuse_time``).
3. Torque: the held command's cell means (its integral is exact), the same anti-alias and
   Savitzky-Golay filters as theta.
4. Ball. Only the distinct camera fixes are used (the logs hold the last fix between
   fixes). The fix at ``t_f`` shows the ball where it was at ``t_f - L`` (camera latency L):
   its world polar angle ``psi_w = atan2(x - c_x, y - c_y)`` (clockwise from +y, the rig's
   convention; ``c`` a camera origin offset, zero unless fitted) is unwrapped, placed at
   ``t_f - L``, put through the same anti-alias filter as theta and smoothed with a
   Savitzky-Golay filter (window ``sg_ball``). The ball-centre angle in the frame is
   ``psi = theta + psi_w`` (DEVELOPERS.md); the model's contact angle ``phi`` is obtained by
   inverting ``psi = ball_angle(phi)`` of the model's curve (done in
   :mod:`~bfr_diagnose.residual`, since the curve is a fitted quantity). Camera
   corrections (:class:`SensorCorrection`) re-smooth the fixes exactly (offset) or shift
   them in time (latency).
5. Noise: camera noise from the fixes themselves (:func:`fix_noise`), encoder resolution,
   high-frequency scatter of a logged velocity; used by the noise-only null.
6. Segments: runs of valid ball fixes without gaps longer than ``max_gap``; the first and
   last ``edge`` seconds of each segment are dropped. Recordings without usable ball fixes
   (or with ``--ball no``) give one frame-only segment (row 1 with the ball terms off).
   Several runs of one log are preprocessed one by one and stitched (:func:`stitch`).

Every operation is zero-phase.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_model.recording import Recording
from numpy.typing import NDArray
from scipy.signal import savgol_filter

from bfr_diagnose import DiagnoseError

__all__ = ["PrepConfig", "Prepared", "SensorCorrection", "fix_noise", "prepare",
           "prepare_runs", "segments_from_mask", "stitch"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PrepConfig:
    """Preprocessing settings (units in brackets)."""

    dt: float = 2e-3               # [s] grid step
    sg_theta: float = 0.02         # [s] Savitzky-Golay window for theta (fine encoder)
    sg_ball: float = 0.03          # [s] Savitzky-Golay window for the ball's world angle
    sg_order: int = 3              # [-] polynomial order
    dtheta_delay: float | None = None  # [s] lag of a logged velocity (None: from meta/0)
    fuse_time: float = 0.5         # [s] complementary filter time constant (coarse theta)
    coarse_theta: float = 1e-4     # [rad] resolution above which theta is treated as coarse
    max_gap: float = 0.05          # [s] longest gap between fixes inside a segment
    edge: float = 0.15             # [s] dropped at both ends of each segment
    min_segment: float = 1.0       # [s] shortest usable segment
    ball: str = "auto"             # "auto", "yes" or "no"
    antialias: float = 0.01        # [s] width of the Hann anti-alias filter (angle, torque)


@dataclass(frozen=True)
class SensorCorrection:
    """Camera extrinsics and timing fitted on top of the nominal sensor model.

    Attributes
    ----------
    latency : float
        [s] camera delay beyond the nominal ``latency0``: a fix shows the ball where it was
        ``latency0 + latency`` before it arrived.
    offset_x, offset_y : float
        [m] camera origin off the shaft axis: the camera reports ``(x, y) = true + (offset_x,
        offset_y)`` (world frame), i.e. the shaft axis appears at ``(offset_x, offset_y)``.
        Preprocessing subtracts it before taking the ball's world angle.
    """

    latency: float = 0.0
    offset_x: float = 0.0
    offset_y: float = 0.0

    def __add__(self, other: SensorCorrection) -> SensorCorrection:
        return SensorCorrection(self.latency + other.latency, self.offset_x + other.offset_x,
                                self.offset_y + other.offset_y)

    @property
    def has_offset(self) -> bool:
        """Whether a camera offset is applied."""
        return self.offset_x != 0.0 or self.offset_y != 0.0


@dataclass
class _Fixes:
    """Raw camera fixes of the ball segments (for re-smoothing under a camera offset)."""

    tf: FloatArray                       # [s] fix times minus latency0
    x: FloatArray                        # [m]
    y: FloatArray                        # [m]
    segs: list[tuple[int, int, int, int]]  # fix range [a, b) -> grid range [i0, i1)
    sgw: int
    order: int
    antialias: float = 0.0               # [s] the Hann anti-alias width (as theta, torque)


def _smooth_ball(fx: _Fixes, tg: FloatArray, ox: float, oy: float
                 ) -> tuple[FloatArray, FloatArray]:
    """Smoothed world angle ``atan2(x - ox, y - oy)`` of the ball and its rate on the grid.

    The same zero-phase Hann anti-alias filter as the frame angle and the torque, then the
    Savitzky-Golay smoothing: ``psi = theta + psi_w`` adds two signals that must have been
    filtered alike (with the anti-alias on theta only, the ball row of a noise-free
    simulation kept a residual ten times its processing floor).
    """
    dt = float(tg[1] - tg[0])
    psi_w = np.full(tg.size, np.nan)
    psi_wd = np.full(tg.size, np.nan)
    ang = np.unwrap(np.arctan2(fx.x - ox, fx.y - oy))
    for a, b, i0, i1 in fx.segs:
        if fx.antialias > 0.0:
            y = _antialiased(fx.tf[a:b], ang[a:b], tg[i0:i1], fx.antialias, hold=False)
        else:
            y = np.interp(tg[i0:i1], fx.tf[a:b], ang[a:b])
        psi_w[i0:i1] = savgol_filter(y, fx.sgw, fx.order)
        psi_wd[i0:i1] = savgol_filter(y, fx.sgw, fx.order, deriv=1, delta=dt)
    return psi_w, psi_wd


@dataclass
class Prepared:
    """Smoothed signals on a uniform grid (all arrays shape (n,)).

    Attributes
    ----------
    t : ndarray
        Grid times [s].
    theta, theta_dot, theta_ddot : ndarray
        Frame angle [rad], rate [rad/s], acceleration [rad/s^2].
    u : ndarray
        Commanded torque on the grid (zero-order hold) [N m].
    psi_w, psi_w_dot : ndarray
        Smoothed world polar angle of the ball centre [rad] and rate [rad/s], at nominal
        latency; NaN outside ball segments.
    ball_ok : ndarray of bool
        Grid samples inside a usable ball segment (edges dropped).
    frame_ok : ndarray of bool
        Grid samples usable for the frame-only row (edges of the run dropped).
    has_ball : bool
        Whether the ball rows apply.
    latency0 : float
        Camera latency assumed when placing the fixes [s].
    noise : dict
        Estimated raw noise levels: ``camera`` [m], ``theta`` [rad].
    info : dict
        What was done (for the report).
    """

    t: FloatArray
    theta: FloatArray
    theta_dot: FloatArray
    theta_ddot: FloatArray
    u: FloatArray
    psi_w: FloatArray
    psi_w_dot: FloatArray
    ball_ok: NDArray[np.bool_]
    frame_ok: NDArray[np.bool_]
    has_ball: bool
    latency0: float
    noise: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    fixes: _Fixes | None = None
    _offset_cache: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        """Number of grid samples."""
        return int(self.t.size)

    def psi_for(self, sensor: SensorCorrection | None = None
                ) -> tuple[FloatArray, FloatArray]:
        """World ball angle and rate [rad, rad/s] under a camera correction.

        Offset: the fixes' angle ``atan2(x - c_x, y - c_y)`` is re-interpolated and
        re-smoothed exactly (the last offset is cached). Latency: a fix that is ``dL`` later
        than assumed shows the ball at ``t - dL``; the corrected angle at t is the smoothed
        angle at ``t + dL`` (linear interpolation of a smooth signal).
        """
        sensor = sensor or SensorCorrection()
        psi, psid = self.psi_w, self.psi_w_dot
        if sensor.has_offset and self.fixes is not None:
            key = (sensor.offset_x, sensor.offset_y)
            hit = self._offset_cache.get(key)
            if hit is None:
                hit = _smooth_ball(self.fixes, self.t, *key)
                self._offset_cache.clear()
                self._offset_cache[key] = hit
            psi, psid = hit
        if sensor.latency == 0.0:
            return psi, psid
        ts = self.t + sensor.latency
        return np.interp(ts, self.t, psi), np.interp(ts, self.t, psid)

    def psi_shifted(self, extra_latency: float) -> tuple[FloatArray, FloatArray]:
        """World ball angle and rate with the camera ``extra_latency`` [s] more than latency0."""
        return self.psi_for(SensorCorrection(latency=extra_latency))


def _odd(n: float) -> int:
    k = max(round(n), 5)
    return k if k % 2 else k + 1


def segments_from_mask(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Half-open index ranges ``[i, j)`` of the runs of True in ``mask``."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts = np.nonzero(d == 1)[0]
    ends = np.nonzero(d == -1)[0]
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def fix_noise(tf: FloatArray, x: FloatArray, y: FloatArray, max_gap: float) -> float:
    """Standard deviation [m] of the camera noise per axis, from the fixes themselves.

    Each fix is predicted by the cubic through its four neighbours (two before, two after,
    Lagrange weights ``w`` at the actual fix times); for white noise of standard deviation
    sigma the prediction error has variance ``sigma^2 (1 + sum w^2)``, while the motion
    leaks in only at fourth order (``~ x^(4) h^4``, far below the noise at 165-200 Hz).
    Robust (median absolute deviation) over both axes and all fixes with no gap nearby.
    """
    m = tf.size
    if m < 12:
        return float("nan")
    k = np.arange(2, m - 2)
    nb = np.stack([k - 2, k - 1, k + 1, k + 2], axis=1)
    tn = tf[nb]
    tk = tf[k]
    w = np.ones_like(tn)
    for j in range(4):
        for i in range(4):
            if i != j:
                w[:, j] *= (tk - tn[:, i]) / (tn[:, j] - tn[:, i])
    win = np.stack([k - 2, k - 1, k, k + 1, k + 2], axis=1)
    ok = np.all(np.diff(tf[win], axis=1) < max_gap, axis=1)
    if ok.sum() < 10:
        return float("nan")
    scale = np.sqrt(1.0 + np.sum(w ** 2, axis=1))[ok]
    e = np.concatenate([(v[k] - np.sum(w * v[nb], axis=1))[ok] / scale for v in (x, y)])
    return float(1.4826 * np.median(np.abs(e - np.median(e))))


def _cell_average_zoh(t: FloatArray, u: FloatArray, tg: FloatArray) -> FloatArray:
    """Mean of the zero-order-hold signal ``u`` over each grid cell ``tg +- dt/2``.

    The command changes at every control step (faster than the grid): sampling it would
    alias, while the convolution in the equation error needs its integral, which the cell
    means preserve exactly for a piecewise-constant kernel weight.
    """
    cum = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(t))])
    dt = float(tg[1] - tg[0])
    edges = np.clip(np.concatenate([tg - 0.5 * dt, [tg[-1] + 0.5 * dt]]), t[0], t[-1])
    # the integral of a ZOH signal is piecewise linear: interpolate it at the cell edges
    U = np.interp(edges, t, cum)
    width = np.maximum(np.diff(edges), 1e-12)
    out = np.diff(U) / width
    return out


def _antialiased(t: FloatArray, y: FloatArray, tg: FloatArray, width: float,
                 hold: bool) -> FloatArray:
    """``y`` on the grid ``tg`` after a zero-phase Hann low-pass of ``width`` [s].

    The signal is first put on a grid 4x finer than ``tg`` (linear interpolation, or cell
    means for a held command), filtered there and decimated. Both the angle and the torque
    go through this same filter, so the quadrature of the equation error on the coarse grid
    sees no content above its resolution (the command of a fast loop changes every step).
    """
    dt = float(tg[1] - tg[0])
    sub = 4
    tf = tg[0] + (dt / sub) * np.arange((tg.size - 1) * sub + 1)
    yf = _cell_average_zoh(t, y, tf) if hold else np.interp(tf, t, y)
    k = max(round(width / (dt / sub) / 2.0), 1)
    w = np.hanning(2 * k + 3)[1:-1]
    w /= w.sum()
    pad = np.pad(yf, k, mode="edge")
    return np.convolve(pad, w, mode="valid")[::sub]


def _coarse_theta(rec: Recording, tg: FloatArray, cfg: PrepConfig,
                  delay: float) -> tuple[FloatArray, FloatArray]:
    """Fuse a coarse theta with the logged velocity (complementary filter)."""
    thd = np.interp(tg + delay, rec.t, rec.theta_dot)
    th_q = np.interp(tg, rec.t, rec.theta)
    integ = np.concatenate([[0.0], np.cumsum(0.5 * (thd[1:] + thd[:-1]) * np.diff(tg))])
    diff = th_q - integ
    k = max(round(cfg.fuse_time / (tg[1] - tg[0])), 1)
    w = np.hanning(2 * k + 1)
    w /= w.sum()
    pad = np.pad(diff, k, mode="reflect", reflect_type="odd")
    low = np.convolve(pad, w, mode="valid")
    return integ + low, thd


def prepare(rec: Recording, cfg: PrepConfig | None = None, latency0: float = 0.0) -> Prepared:
    """Smooth and differentiate a recording onto a uniform grid (module docstring).

    Parameters
    ----------
    rec : Recording
        The recording (our conventions).
    cfg : PrepConfig, optional
        Settings.
    latency0 : float
        Nominal camera latency [s]: fixes are placed at ``t_fix - latency0``.

    Raises
    ------
    DiagnoseError
        Too short, or no usable segment.
    """
    cfg = cfg or PrepConfig()
    if rec.n < 50 or rec.duration < 2.0 * cfg.edge + cfg.min_segment:
        raise DiagnoseError(f"recording too short to diagnose: {rec.n} samples, "
                            f"{rec.duration:.3g} s (need at least "
                            f"{2 * cfg.edge + cfg.min_segment:.2g} s)")
    dt = cfg.dt
    tg = rec.t[0] + dt * np.arange(int(np.floor(rec.duration / dt)) + 1)
    info: dict[str, Any] = {"grid_dt": dt}
    noise_thd = _velocity_noise(rec, tg, dt)
    res = _theta_resolution(rec)
    info["theta_resolution"] = float(res)
    info["theta_coarse"] = bool(res > cfg.coarse_theta)
    frame = _frame_angle(rec, tg, cfg, res)
    info["theta_source"] = frame.source
    u = _torque(rec, tg, cfg)
    ball = _ball(rec, tg, cfg, latency0)
    info["ball"] = ball.note
    frame_ok = np.zeros(tg.size, bool)
    n_edge = round(cfg.edge / dt)
    frame_ok[n_edge:tg.size - n_edge] = True
    if ball.has_ball:
        # the frame row with ball terms needs the ball: use ball segments only
        frame_ok &= ball.ok
    if frame_ok.sum() * dt < cfg.min_segment:
        raise DiagnoseError("no usable segment after dropping edges and ball gaps")
    return Prepared(t=tg, theta=frame.theta, theta_dot=frame.theta_dot,
                    theta_ddot=frame.theta_ddot, u=u, psi_w=ball.psi_w,
                    psi_w_dot=ball.psi_w_dot, ball_ok=ball.ok, frame_ok=frame_ok,
                    has_ball=ball.has_ball, latency0=latency0,
                    noise={"camera": ball.noise, "theta": frame.noise,
                           "theta_dot": noise_thd}, info=info, fixes=ball.fixes)


def _velocity_noise(rec: Recording, tg: FloatArray, dt: float) -> float:
    """High-frequency scatter [rad/s] of the logged velocity (about a 50 ms quadratic fit)."""
    thd_raw = np.interp(tg, rec.t, rec.theta_dot)
    return float(np.std(thd_raw - savgol_filter(thd_raw, _odd(0.05 / dt), 2)))


def _theta_resolution(rec: Recording) -> float:
    """Encoder resolution [rad]: ``meta["theta_resolution"]``, else theta's smallest step."""
    res = rec.meta.get("theta_resolution")
    if res is None:
        d = np.abs(np.diff(rec.theta))
        d = d[d > 0]
        res = float(np.min(d)) if d.size else 0.0
    return res


@dataclass(frozen=True, kw_only=True, eq=False)
class _FrameAngle:
    """The frame's smoothed angle and derivatives on the grid, and how they were obtained."""

    theta: FloatArray         # [rad]
    theta_dot: FloatArray     # [rad/s]
    theta_ddot: FloatArray    # [rad/s^2]
    noise: float              # [rad] noise of the raw angle
    source: str               # what was done (for the report)


def _frame_angle(rec: Recording, tg: FloatArray, cfg: PrepConfig, res: float) -> _FrameAngle:
    """Frame angle, rate and acceleration on the grid ``tg`` (module docstring, step 2).

    A coarse encoder (resolution ``res`` above ``cfg.coarse_theta``): the logged velocity,
    advanced by its lag, integrated and fused with the angle (:func:`_coarse_theta`), then
    Savitzky-Golay smoothed and differentiated. A fine one: the anti-aliased angle,
    Savitzky-Golay smoothed and differentiated twice.
    """
    dt = cfg.dt
    win = _odd(cfg.sg_theta / dt)
    if res > cfg.coarse_theta:
        delay = cfg.dtheta_delay
        if delay is None:
            delay = float(rec.meta.get("rig_conventions", {}).get("dtheta_delay_s", 0.0))
        theta, thd = _coarse_theta(rec, tg, cfg, delay)
        return _FrameAngle(
            theta=theta, theta_dot=savgol_filter(thd, win, cfg.sg_order),
            theta_ddot=savgol_filter(thd, win, cfg.sg_order, deriv=1, delta=dt),
            noise=float(res) / np.sqrt(12.0),
            source=(f"logged velocity advanced by {delay * 1e3:.1f} ms, integrated "
                    f"and fused with the coarse angle (resolution {res:.2g} rad)"))
    th = _antialiased(rec.t, rec.theta, tg, cfg.antialias, hold=False)
    theta = savgol_filter(th, win, cfg.sg_order)
    return _FrameAngle(
        theta=theta, theta_dot=savgol_filter(th, win, cfg.sg_order, deriv=1, delta=dt),
        theta_ddot=savgol_filter(th, win, cfg.sg_order, deriv=2, delta=dt),
        noise=float(np.std(th - theta)),
        source=f"encoder angle (resolution {res:.2g} rad), Savitzky-Golay")


def _torque(rec: Recording, tg: FloatArray, cfg: PrepConfig) -> FloatArray:
    """The held command on the grid [N m], filtered like theta (one filter on both sides).

    Cell means on a fine grid, the same anti-alias filter as theta, and the same
    Savitzky-Golay smoothing as theta's derivative.
    """
    return savgol_filter(_antialiased(rec.t, rec.torque, tg, cfg.antialias, hold=True),
                         _odd(cfg.sg_theta / cfg.dt), cfg.sg_order)


@dataclass(frozen=True, kw_only=True, eq=False)
class _Ball:
    """The ball's smoothed world angle on the grid and what is usable of it."""

    has_ball: bool                 # whether the ball rows apply
    psi_w: FloatArray              # [rad] (NaN outside the fixes' segments)
    psi_w_dot: FloatArray          # [rad/s]
    ok: NDArray[np.bool_]          # grid samples inside a usable segment (edges dropped)
    noise: float                   # [m] camera noise per axis (NaN if not estimated)
    fixes: _Fixes | None           # the raw fixes (only when the ball rows apply)
    note: str                      # what was found (for the report)


def _ball(rec: Recording, tg: FloatArray, cfg: PrepConfig, latency0: float) -> _Ball:
    """The ball from the distinct camera fixes (module docstring, steps 4 to 6).

    Raises
    ------
    DiagnoseError
        ``cfg.ball == "yes"`` but there are no (usable) fixes.
    """
    nfix = rec.new_fix_mask()
    has_ball = bool(nfix.sum() > 20) and cfg.ball != "no"
    if cfg.ball == "yes" and not has_ball:
        raise DiagnoseError("--ball yes given but the recording holds no valid ball fixes")
    if not has_ball:
        if int(nfix.sum()) > 0:
            note = (f"no usable ball data: only {int(nfix.sum())} valid camera fix(es) in "
                    f"{rec.duration:.1f} s; frame-only analysis (row 1, ball terms off)")
        else:
            note = "no ball in the recording: frame-only analysis (row 1, ball terms off)"
        return _Ball(has_ball=False, psi_w=np.full(tg.size, np.nan),
                     psi_w_dot=np.full(tg.size, np.nan), ok=np.zeros(tg.size, bool),
                     noise=float("nan"), fixes=None, note=note)
    fixes, ball_ok = _ball_fixes(rec, nfix, tg, cfg, latency0)
    psi_w, psi_wd = _smooth_ball(fixes, tg, 0.0, 0.0)
    noise_cam = fix_noise(fixes.tf, fixes.x, fixes.y, cfg.max_gap)
    if not ball_ok.any():
        if cfg.ball == "yes":
            raise DiagnoseError("no usable ball segment (need "
                                f"{cfg.min_segment + 2 * cfg.edge:.2g} s of fixes with "
                                f"gaps under {cfg.max_gap * 1e3:.0f} ms)")
        return _Ball(has_ball=False, psi_w=psi_w, psi_w_dot=psi_wd, ok=ball_ok,
                     noise=noise_cam, fixes=None,
                     note="no usable ball segment: frame-only analysis")
    return _Ball(has_ball=True, psi_w=psi_w, psi_w_dot=psi_wd, ok=ball_ok, noise=noise_cam,
                 fixes=fixes, note=(f"{len(segments_from_mask(ball_ok))} ball segment(s), "
                                    f"{ball_ok.mean() * 100:.0f} % of the run"))


def _ball_fixes(rec: Recording, nfix: NDArray[np.bool_], tg: FloatArray, cfg: PrepConfig,
                latency0: float) -> tuple[_Fixes, NDArray[np.bool_]]:
    """The distinct fixes, placed at ``t_fix - latency0`` and cut into segments at gaps.

    A segment needs 10 fixes, ``min_segment + 2 edge`` seconds and more grid samples than
    the Savitzky-Golay window; its first and last ``edge`` seconds are not usable.

    Returns
    -------
    fixes : _Fixes
        The fixes and their segments.
    ball_ok : ndarray of bool
        Grid samples inside a segment, edges dropped.
    """
    dt = cfg.dt
    n_edge = round(cfg.edge / dt)
    tf = rec.t[nfix] - latency0
    # segments between gaps
    gaps = np.nonzero(np.diff(tf) > cfg.max_gap)[0]
    bounds = np.concatenate([[0], gaps + 1, [tf.size]])
    sgw = _odd(cfg.sg_ball / dt)
    ball_ok = np.zeros(tg.size, bool)
    segs = []
    for a, b in itertools.pairwise(bounds):
        if b - a < 10:
            continue
        i0 = int(np.searchsorted(tg, tf[a], side="left"))
        i1 = int(np.searchsorted(tg, tf[b - 1], side="right"))
        if (i1 - i0) * dt < cfg.min_segment + 2 * cfg.edge or i1 - i0 <= sgw:
            continue
        segs.append((int(a), int(b), i0, i1))
        ball_ok[i0 + n_edge:i1 - n_edge] = True
    fixes = _Fixes(tf=tf, x=rec.ball_x[nfix].astype(float), y=rec.ball_y[nfix].astype(float),
                   segs=segs, sgw=sgw, order=cfg.sg_order, antialias=cfg.antialias)
    return fixes, ball_ok


def stitch(preps: list[Prepared], gap: float = 0.6) -> Prepared:
    """Several prepared runs on one time axis, back to back with unusable gaps between.

    Each run is preprocessed on its own (its own filters, edges dropped); here the runs are
    laid end to end on a common grid separated by ``gap`` seconds of samples marked unusable,
    longer than the residual's kernel, so that no filtered sample mixes two runs. The time
    axis is synthetic (the first run's start, then continuous); ``info["runs"]`` keeps each
    run's original start and its offset on the stitched axis.
    """
    if len(preps) == 1:
        return preps[0]
    dt = float(preps[0].t[1] - preps[0].t[0])
    ng = max(round(gap / dt), 1)
    has_ball = all(p.has_ball for p in preps)
    if not has_ball and any(p.has_ball for p in preps):
        raise DiagnoseError("cannot diagnose runs with and without ball data together "
                            "(choose one run with --run)")
    parts: dict[str, list[FloatArray]] = {k: [] for k in (
        "theta", "theta_dot", "theta_ddot", "u", "psi_w", "psi_w_dot", "ball_ok", "frame_ok")}
    fx_t, fx_x, fx_y, segs = [], [], [], []
    n0 = 0
    nf0 = 0
    t0 = float(preps[0].t[0])
    runs = []
    for k, p in enumerate(preps):
        if abs(float(p.t[1] - p.t[0]) - dt) > 1e-12:
            raise DiagnoseError("runs prepared on different grids cannot be stitched")
        if k:
            for name, lst in parts.items():
                if name in ("ball_ok", "frame_ok"):
                    lst.append(np.zeros(ng, bool))
                elif name in ("psi_w", "psi_w_dot"):
                    lst.append(np.full(ng, np.nan))
                else:
                    lst.append(np.full(ng, lst[-1][-1]))
            n0 += ng
        shift = t0 + n0 * dt - float(p.t[0])
        runs.append({"t_start": float(p.t[0]), "offset_s": shift, "samples": p.n})
        parts["theta"].append(p.theta)
        parts["theta_dot"].append(p.theta_dot)
        parts["theta_ddot"].append(p.theta_ddot)
        parts["u"].append(p.u)
        parts["psi_w"].append(p.psi_w)
        parts["psi_w_dot"].append(p.psi_w_dot)
        parts["ball_ok"].append(p.ball_ok & has_ball)
        parts["frame_ok"].append(p.frame_ok if not has_ball else p.frame_ok & p.ball_ok)
        if has_ball and p.fixes is not None:
            fx_t.append(p.fixes.tf + shift)
            fx_x.append(p.fixes.x)
            fx_y.append(p.fixes.y)
            segs += [(a + nf0, b + nf0, i0 + n0, i1 + n0) for a, b, i0, i1 in p.fixes.segs]
            nf0 += p.fixes.tf.size
        n0 += p.n
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    t = t0 + dt * np.arange(n0)
    fixes = None
    if has_ball:
        f0 = preps[0].fixes
        fixes = _Fixes(tf=np.concatenate(fx_t), x=np.concatenate(fx_x), y=np.concatenate(fx_y),
                       segs=segs, sgw=f0.sgw, order=f0.order, antialias=f0.antialias)
    noise = {}
    for k in preps[0].noise:
        v = np.array([p.noise.get(k, np.nan) for p in preps], float)
        noise[k] = float(np.median(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")
    info = dict(preps[0].info)
    info["runs"] = runs
    info["ball"] = (f"{len(preps)} runs stitched ({gap:.1f} s unusable gaps); "
                    + str(preps[0].info.get("ball")))
    if not has_ball:
        cat["ball_ok"][:] = False
    return Prepared(t=t, theta=cat["theta"], theta_dot=cat["theta_dot"],
                    theta_ddot=cat["theta_ddot"], u=cat["u"], psi_w=cat["psi_w"],
                    psi_w_dot=cat["psi_w_dot"], ball_ok=cat["ball_ok"],
                    frame_ok=cat["frame_ok"], has_ball=has_ball, latency0=preps[0].latency0,
                    noise=noise, info=info, fixes=fixes)


def prepare_runs(recs: list[Recording], cfg: PrepConfig | None = None,
                 latency0: float = 0.0) -> Prepared:
    """:func:`prepare` each run, then :func:`stitch` them (one run: just :func:`prepare`)."""
    return stitch([prepare(r, cfg, latency0=latency0) for r in recs])
