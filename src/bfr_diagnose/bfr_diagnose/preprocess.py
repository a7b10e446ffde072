"""Preprocessing: from a :class:`~bfr_model.recording.Recording` to smooth states on a grid.

Steps (docs/diagnosis.md):

1. Uniform grid of step ``dt`` (default 2 ms) over the recording.
2. Frame angle. If the encoder is fine (resolution below 1e-4 rad) theta is anti-aliased
   (zero-phase Hann of ``antialias`` on a 4x finer grid), smoothed with a Savitzky-Golay
   filter (cubic, window ``sg_theta``) and differentiated. If theta is coarse (the NTNU logs
   print 6 significant digits: 1-10 mrad) the logged velocity is used:
   ``theta_dot(t) = dtheta(t + d)``, ``d`` the velocity's lag **measured on this
   recording** (:func:`bfr_model.io.timing.velocity_lag`; the NTNU rig: 6.4 ms, another
   rig: anything, 0 included), ``theta`` its integral fused with the coarse angle by a slow
   low-pass of the difference (complementary filter, ``fuse_time``).
3. Torque: the held command's cell means (its integral is exact), the same anti-alias and
   Savitzky-Golay filters as theta. A drive that applies the logged torque ``d_u`` later is
   a sensor correction (:meth:`Prepared.u_for`: ``u(t - d_u)``), fitted per recording.
4. Ball. Only the distinct camera fixes are used (a log holds the last fix between fixes,
   at any ratio of lines to fixes). A fix's time is its own stamp when the source has one
   (a bag's header stamp), else the line where it first appears, moved onto the camera's
   steady clock when the arrivals show one (:func:`bfr_model.io.timing.camera_clock`: the
   wait for the next line is a slowly drifting latency where the camera's and the log's
   rates are nearly commensurate; measured and reported per recording). The fix at ``t_f`` shows
   the ball where it was at ``t_f - L`` (camera latency L): its world polar angle
   ``psi_w = atan2(x - c_x, y - c_y) + alpha`` (clockwise from +y, the rig's convention;
   ``c`` a camera origin offset, ``alpha`` a camera rotation: the camera logs
   ``s Rot(alpha) true + c``) is unwrapped, placed at ``t_f - L``, put through the same
   anti-alias filter as theta and smoothed with a Savitzky-Golay filter (window
   ``sg_ball``); the ball's distance from the shaft ``rho = |(x, y) - c| / s`` (camera
   scale s) likewise. The ball-centre angle in the frame is ``psi = theta + theta_0 +
   psi_w`` (DEVELOPERS.md; ``theta_0`` the encoder's zero against the frame's shape); the
   model's contact angle ``phi`` is obtained by inverting ``psi = ball_angle(phi)`` of the
   model's curve (done in :mod:`~bfr_diagnose.residual`, since the curve is a fitted
   quantity). Camera corrections (:class:`SensorCorrection`) re-smooth the fixes exactly
   (offset) or shift them in time (latency).
5. Noise: camera noise from the fixes themselves (:func:`fix_noise`, and across and along
   the ball's path apart, :func:`fix_noise_path`), encoder resolution, high-frequency scatter
   of a logged velocity; used by the noise-only null.
6. Segments: runs of valid ball fixes without gaps longer than ``max_gap``; the first and
   last ``edge`` seconds of each segment are dropped. Recordings without usable ball fixes
   (or with ``--ball no``) give one frame-only segment (row 1 with the ball terms off).
   A recording whose frame does not turn while the ball moves is **frame-held**: its ball
   rows alone are analysed (the frame's row would need the unknown holding torque).
   A recording is first cut where its samples stop for longer than ``max_line_gap``
   (:func:`split_pieces`); pieces and runs too short to use are dropped and said; the rest
   are preprocessed one by one and stitched by kind (:func:`stitch`).

Every operation is zero-phase.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from bfr_model.io.timing import (
    CameraClock,
    camera_clock,
    corrected_velocity,
    robust_sd,
    velocity_lag,
)
from bfr_model.recording import Recording
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter
from scipy.stats import trim_mean

from bfr_diagnose import DiagnoseError

__all__ = ["HELD_WINDOW", "Piece", "PrepConfig", "Prepared", "SensorCorrection", "fix_noise",
           "fix_noise_path", "frame_held", "held_angle", "held_bound", "held_span",
           "path_steps", "plan_parts", "prepare", "prepare_pieces", "prepare_runs",
           "segments_from_mask", "split_pieces", "stitch"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PrepConfig:
    """Preprocessing settings (units in brackets)."""

    dt: float = 2e-3               # [s] grid step
    sg_theta: float = 0.02         # [s] Savitzky-Golay window for theta (fine encoder)
    sg_ball: float = 0.03          # [s] Savitzky-Golay window for the ball's world angle
    sg_order: int = 3              # [-] polynomial order
    dtheta_delay: float | None = None  # [s] lag of a logged velocity (None: measured)
    dtheta_c2: float = 0.0         # [s^2] its second-order term when the lag is given
    fuse_time: float = 0.5         # [s] complementary filter time constant (coarse theta)
    coarse_theta: float = 1e-4     # [rad] resolution above which theta is treated as coarse
    max_gap: float = 0.05          # [s] longest gap between fixes inside a segment
    max_line_gap: float = 0.05     # [s] a recording is cut where its samples stop longer
    edge: float = 0.05             # [s] dropped at both ends of each segment
    min_segment: float = 0.3       # [s] shortest usable segment
    ball: str = "auto"             # "auto", "yes" or "no"
    antialias: float = 0.01        # [s] width of the Hann anti-alias filter (angle, torque)
    width_factor: float = 1.0      # [-] every filter width times this (the null's x1.4)


@dataclass(frozen=True)
class SensorCorrection:
    """A recording's sensor conventions, fitted on top of the nominal sensor model.

    The camera logs ``(x, y) = scale Rot(rotation) (x, y)_true + (offset_x, offset_y)``.

    Attributes
    ----------
    latency : float
        [s] camera delay beyond the nominal ``latency0``: a fix shows the ball where it was
        ``latency0 + latency`` before it arrived.
    offset_x, offset_y : float
        [m] camera origin off the shaft axis (world frame): the shaft axis appears at
        ``(offset_x, offset_y)``. Preprocessing subtracts it before taking the ball's world
        angle and distance.
    rotation : float
        [rad] camera rotation about the shaft axis (counter-clockwise): the world angle
        ``atan2(x, y)`` (clockwise from +y) reads ``rotation`` too small.
    scale : float
        [-] camera scale: the ball's distance from the shaft reads ``scale`` times its own.
    theta_zero : float
        [rad] the encoder's zero against the frame's shape: the true frame angle is the
        logged one plus ``theta_zero`` (a frame mounted turned on its shaft).
    torque_delay : float
        [s] the drive applies a logged torque this much later (negative: earlier).
    """

    latency: float = 0.0
    offset_x: float = 0.0
    offset_y: float = 0.0
    rotation: float = 0.0
    scale: float = 1.0
    theta_zero: float = 0.0
    torque_delay: float = 0.0

    def __add__(self, other: SensorCorrection) -> SensorCorrection:
        return SensorCorrection(latency=self.latency + other.latency,
                                offset_x=self.offset_x + other.offset_x,
                                offset_y=self.offset_y + other.offset_y,
                                rotation=self.rotation + other.rotation,
                                scale=self.scale * other.scale,
                                theta_zero=self.theta_zero + other.theta_zero,
                                torque_delay=self.torque_delay + other.torque_delay)

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


def _smooth_ball(fx: _Fixes, tg: FloatArray) -> tuple[FloatArray, ...]:
    """The ball's world position and velocity on the grid, smoothed (NaN outside segments).

    Each coordinate of the fixes goes through the same zero-phase Hann anti-alias filter as
    the frame angle and the torque, then the Savitzky-Golay smoothing: ``psi = theta +
    psi_w`` adds two signals that must have been filtered alike (with the anti-alias on
    theta only, the ball row of a noise-free simulation kept a residual ten times its
    processing floor). The filters are linear, so a camera correction (offset, rotation,
    scale) applies exactly to the smoothed position (:meth:`Prepared.ball_for`).

    Returns
    -------
    x, y, x_dot, y_dot : ndarray
        [m], [m/s] on the grid.
    """
    dt = float(tg[1] - tg[0])
    out = [np.full(tg.size, np.nan) for _ in range(4)]
    for a, b, i0, i1 in fx.segs:
        for j, src in enumerate((fx.x, fx.y)):
            if fx.antialias > 0.0:
                y = _antialiased(fx.tf[a:b], src[a:b], tg[i0:i1], fx.antialias, hold=False)
            else:
                y = np.interp(tg[i0:i1], fx.tf[a:b], src[a:b])
            out[j][i0:i1] = savgol_filter(y, fx.sgw, fx.order)
            out[j + 2][i0:i1] = savgol_filter(y, fx.sgw, fx.order, deriv=1, delta=dt)
    return tuple(out)


def _world_angle(x: FloatArray, y: FloatArray) -> FloatArray:
    """``atan2(x, y)`` (clockwise from +y), unwrapped along the finite samples."""
    out = np.full(x.size, np.nan)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.any():
        out[ok] = np.unwrap(np.arctan2(x[ok], y[ok]))
    return out


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
    rho : ndarray
        Smoothed distance of the ball centre from the shaft as the camera reports it [m]
        (NaN outside ball segments).
    ball_xy : ndarray or None
        Smoothed world position and velocity of the ball as the camera reports it, shape
        (4, n): x, y [m], x_dot, y_dot [m/s] (NaN outside ball segments).
    ball_ok : ndarray of bool
        Grid samples inside a usable ball segment (edges dropped).
    frame_ok : ndarray of bool
        Grid samples usable for the frame-only row (edges of the run dropped).
    has_ball : bool
        Whether the ball rows apply.
    frame_held : bool
        The frame did not turn (the ball rows alone are analysed).
    latency0 : float
        Camera latency assumed when placing the fixes [s].
    noise : dict
        Estimated raw noise levels: ``camera`` [m] per axis, ``camera_across`` and
        ``camera_along`` [m] across and along the ball's path (:func:`fix_noise_path`),
        ``theta`` [rad], ``theta_dot`` [rad/s].
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
    rho: FloatArray | None = None
    ball_xy: FloatArray | None = None
    frame_held: bool = False
    noise: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    fixes: _Fixes | None = None
    _u_spline: _HeldSpline | None = field(default=None, init=False, repr=False, compare=False)
    _u_shifted: tuple[float, FloatArray] | None = field(default=None, init=False, repr=False,
                                                        compare=False)
    _offset_view: tuple[tuple[float, float], tuple[FloatArray, FloatArray, FloatArray]] | None = (
        field(default=None, init=False, repr=False, compare=False))

    @property
    def n(self) -> int:
        """Number of grid samples."""
        return int(self.t.size)

    @property
    def usable(self) -> NDArray[np.bool_]:
        """The samples the analysis uses: ``ball_ok`` with a ball, else ``frame_ok``."""
        return self.ball_ok if self.has_ball else self.frame_ok

    def ball_for(self, sensor: SensorCorrection | None = None,
                 at: NDArray[np.intp] | None = None
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """World ball angle, its rate and the ball's distance under a sensor correction.

        The smoothed position minus the offset gives the angle ``atan2(x - c_x, y - c_y)``
        plus the rotation, its rate, and the distance over the scale. Latency: a fix that is
        ``dL`` later than assumed shows the ball at ``t - dL``; the corrected signals at t
        are the smoothed ones at ``t + dL`` (linear interpolation of smooth signals).

        Parameters
        ----------
        sensor : SensorCorrection, optional
            The correction (none by default).
        at : ndarray of int, optional
            Grid indices: the signals there only (default: the whole grid).

        Returns
        -------
        psi_w, psi_w_dot, rho : ndarray
            [rad], [rad/s], [m] on the grid or at ``at`` (NaN outside ball segments).
        """
        sensor = sensor or SensorCorrection()
        psi, psid = self.psi_w, self.psi_w_dot
        rho = self.rho if self.rho is not None else np.full(self.n, np.nan)
        if sensor.has_offset and self.ball_xy is not None:
            key = (sensor.offset_x, sensor.offset_y)
            if self._offset_view is not None and self._offset_view[0] == key:
                psi, psid, rho = self._offset_view[1]  # a fit's columns mostly share it
            else:
                bx, by, bxd, byd = self.ball_xy
                x, y = bx - sensor.offset_x, by - sensor.offset_y
                rho = np.hypot(x, y)
                psi = _world_angle(x, y)
                psid = (y * bxd - x * byd) / (rho * rho)
                for a in (psi, psid, rho):
                    a.flags.writeable = False
                self._offset_view = (key, (psi, psid, rho))
        if sensor.rotation != 0.0:
            psi = psi + sensor.rotation
        if sensor.scale != 1.0:
            rho = rho / sensor.scale
        if sensor.latency == 0.0:
            return (psi, psid, rho) if at is None else (psi[at], psid[at], rho[at])
        ts = self.t + sensor.latency if at is None else self.t[at] + sensor.latency
        return (np.interp(ts, self.t, psi), np.interp(ts, self.t, psid),
                np.interp(ts, self.t, rho))

    def psi_for(self, sensor: SensorCorrection | None = None
                ) -> tuple[FloatArray, FloatArray]:
        """World ball angle and rate [rad, rad/s] under a sensor correction (:meth:`ball_for`)."""
        return self.ball_for(sensor)[:2]

    def psi_shifted(self, extra_latency: float) -> tuple[FloatArray, FloatArray]:
        """World ball angle and rate with the camera ``extra_latency`` [s] more than latency0."""
        return self.psi_for(SensorCorrection(latency=extra_latency))

    def u_for(self, sensor: SensorCorrection | None = None) -> FloatArray:
        """The torque acting at each grid time [N m]: ``u(t - torque_delay)``.

        The filtered torque's cubic spline (:class:`_HeldSpline`, built once per recording)
        between grid samples: a straight line between them bends it by
        ``-s (1 - s) h^2 u'' / 2`` at a fraction s of the step h, a relative error of
        ``(omega h)^2 / 8`` at s = 1/2 (1e-4 at 10 rad/s on the 2 ms grid), which a torque
        gain or a frame inertia of that size then explained. Beyond the ends the torque
        keeps its end values.
        """
        d = 0.0 if sensor is None else sensor.torque_delay
        if d == 0.0:
            return self.u
        if self._u_shifted is not None and self._u_shifted[0] == d:
            return self._u_shifted[1]  # a fit's evaluations mostly share the delay
        if self._u_spline is None:
            self._u_spline = _HeldSpline(self.t, self.u)
        u = self._u_spline(self.t - d)
        u.flags.writeable = False
        self._u_shifted = (d, u)
        return u


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
    return _per_axis(_fix_prediction_errors(tf, x, y, max_gap))


def fix_noise_path(tf: FloatArray, x: FloatArray, y: FloatArray, max_gap: float
                    ) -> tuple[float, float]:
    """The camera noise [m] across and along the ball's path: (across, along).

    The prediction errors of :func:`fix_noise` projected on the normal of the fix's velocity
    (from its neighbours) and on the velocity. An error in a fix's time (a fix logged at the
    next line of a log, not at its exposure) moves it along its path, by its speed times the
    error, and not across it. The null injects each component at its own level
    (:func:`bfr_diagnose.null.noisy_copy`). (NaN, NaN) when not estimated: fewer than 10
    fixes with no gap nearby whose neighbours are apart (a ball at rest has no path).

    One level along the path for the whole recording: where the ball is slow its timing
    error is smaller than that (a resting ball's fixes are apart by noise alone, and the
    null then gives it the along level in every direction); the ball rolls in the
    recordings this is made for.
    """
    return _across_along(_fix_prediction_errors(tf, x, y, max_gap))


_Errors = tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None


def _per_axis(errs: _Errors) -> float:
    """:func:`fix_noise` from the prediction errors (NaN when there are none)."""
    return float("nan") if errs is None else robust_sd(np.concatenate(errs[:2]))


def _across_along(errs: _Errors) -> tuple[float, float]:
    """:func:`fix_noise_path` from the prediction errors ((NaN, NaN) when not estimated)."""
    if errs is None:
        return float("nan"), float("nan")
    ex, ey, vx, vy = errs
    v = np.hypot(vx, vy)
    ok = v > 0
    if ok.sum() < 10:
        return float("nan"), float("nan")
    ux, uy = vx[ok] / v[ok], vy[ok] / v[ok]
    return (robust_sd(ey[ok] * ux - ex[ok] * uy), robust_sd(ex[ok] * ux + ey[ok] * uy))


def _fix_prediction_errors(tf: FloatArray, x: FloatArray, y: FloatArray, max_gap: float
                           ) -> _Errors:
    """Normalised prediction errors of each fix from its neighbours (:func:`fix_noise`).

    ``(ex, ey, dx, dy)`` at the fixes with no gap nearby (the errors over
    ``sqrt(1 + sum w^2)``; the step between the outer neighbours, the path's direction);
    None when fewer than 10.
    """
    m = tf.size
    if m < 12:
        return None
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
        return None
    scale = np.sqrt(1.0 + np.sum(w ** 2, axis=1))[ok]
    ex, ey = ((v[k] - np.sum(w * v[nb], axis=1))[ok] / scale for v in (x, y))
    dx, dy = path_steps(x, y)
    return ex, ey, dx[k][ok], dy[k][ok]


def path_steps(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The ball's path direction at each fix: the step between its outer neighbours [m].

    ``(x[k + 2] - x[k - 2], y[k + 2] - y[k - 2])``, the span clipped to the fixes at the
    ends. The one stencil of the path's direction: the camera-noise estimate
    (:func:`fix_noise_path`) projects on it and the null
    (:func:`bfr_diagnose.null.noisy_copy`) injects along it, so both split a fix's error
    into the same two directions.
    """
    m = x.size
    k = np.arange(m)
    hi = np.minimum(k + 2, m - 1)
    lo = np.maximum(k - 2, 0)
    return x[hi] - x[lo], y[hi] - y[lo]


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


class _HeldSpline:
    """``y(t)`` as a cubic spline (not-a-knot), held constant beyond the ends.

    Fewer than four samples: a straight line. A class, not a closure, so that a
    :class:`Prepared` that caches one still pickles (to a Dask worker).
    """

    def __init__(self, t: FloatArray, y: FloatArray) -> None:
        self._t, self._y = t, y
        self._f = CubicSpline(t, y) if t.size >= 4 else None

    def __call__(self, at: FloatArray) -> FloatArray:
        if self._f is None:
            return np.interp(at, self._t, self._y)
        return self._f(np.clip(at, self._t[0], self._t[-1]))


def _spline(t: FloatArray, y: FloatArray, at: FloatArray) -> FloatArray:
    """``y(t)`` at ``at`` by a cubic spline (not-a-knot), held constant beyond the ends."""
    return _HeldSpline(t, y)(at)


def _antialiased(t: FloatArray, y: FloatArray, tg: FloatArray, width: float,
                 hold: bool) -> FloatArray:
    """``y`` on the grid ``tg`` after a zero-phase Hann low-pass of ``width`` [s].

    The signal is first put on a grid 4x finer than ``tg`` (a cubic spline through the
    samples, or cell means for a held command), filtered there and decimated. A straight
    line between samples would bend the signal by ``-y'' h^2 / 12`` on average over an
    interval h: at 150 samples per second a bias of the frame's acceleration that looked
    like a torque gain; the spline's error is of fourth order. Both the angle and the torque
    go through this same filter, so the quadrature of the equation error on the coarse grid
    sees no content above its resolution (the command of a fast loop changes every step).
    """
    dt = float(tg[1] - tg[0])
    sub = 4
    tf = tg[0] + (dt / sub) * np.arange((tg.size - 1) * sub + 1)
    yf = _cell_average_zoh(t, y, tf) if hold else _spline(t, y, tf)
    k = max(round(width / (dt / sub) / 2.0), 1)
    w = np.hanning(2 * k + 3)[1:-1]
    w /= w.sum()
    pad = np.pad(yf, k, mode="edge")
    return np.convolve(pad, w, mode="valid")[::sub]


def _coarse_theta(rec: Recording, tg: FloatArray, cfg: PrepConfig, delay: float,
                  c2: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """Fuse a coarse theta with the logged velocity (complementary filter).

    The velocity is first corrected for its filter: advanced by its lag, plus its
    second-order term (:func:`bfr_model.io.timing.corrected_velocity`).
    """
    thd = corrected_velocity(rec.t, rec.theta_dot, tg, delay, c2)
    th_q = np.interp(tg, rec.t, rec.theta)
    integ = np.concatenate([[0.0], np.cumsum(0.5 * (thd[1:] + thd[:-1]) * np.diff(tg))])
    diff = th_q - integ
    k = max(round(cfg.fuse_time / (tg[1] - tg[0])), 1)
    w = np.hanning(2 * k + 1)
    w /= w.sum()
    pad = np.pad(diff, k, mode="reflect", reflect_type="odd")
    low = np.convolve(pad, w, mode="valid")
    return integ + low, thd


def _adapted(cfg: PrepConfig, rec: Recording) -> PrepConfig:
    """The filter widths for this recording's sampling, times ``width_factor``.

    A filter must span its samples: the anti-alias filter (one for the angle, the torque
    and the ball) at least two intervals of the lines and of the camera's fixes, the
    Savitzky-Golay windows at least five (a log at 150 lines per second with the widths of a
    1-kHz log fitted cubics through three samples of a linear interpolation, a bias that
    looked like a torque gain).
    """
    line = float(np.median(np.diff(rec.t))) if rec.n > 1 else cfg.dt
    ft = rec.fix_times()
    fix = float(np.median(np.diff(ft))) if ft.size > 2 else line
    f = cfg.width_factor
    return replace(cfg, antialias=f * max(cfg.antialias, 2.0 * line, 2.0 * fix),
                   sg_theta=f * max(cfg.sg_theta, 5.0 * line),
                   sg_ball=f * max(cfg.sg_ball, 5.0 * fix), width_factor=1.0)


def split_pieces(rec: Recording, cfg: PrepConfig | None = None
                 ) -> tuple[list[Recording], list[str]]:
    """Cut a recording where its samples stop for longer than ``max_line_gap``.

    A logger that stalled, a bag with a dropout, a stray first line long before the run
    (the NTNU ``rolling_data`` log opens with a line at t = 0, the next at 4.1 s): each side
    is preprocessed on its own. Pieces shorter than ``2 edge + min_segment`` are dropped.

    Returns
    -------
    pieces : list of Recording
        The usable pieces, in time order.
    notes : list of str
        What was cut and dropped.
    """
    cfg = cfg or PrepConfig()
    notes: list[str] = []
    if rec.n < 2:
        return [], [f"{rec.n} sample(s): nothing to diagnose"]
    dt = np.diff(rec.t)
    limit = max(cfg.max_line_gap, 20.0 * float(np.median(dt)))
    cuts = np.nonzero(dt > limit)[0]
    bounds = np.concatenate([[0], cuts + 1, [rec.n]])
    need = 2.0 * cfg.edge + cfg.min_segment
    pieces = []
    for a, b in itertools.pairwise(bounds):
        part = rec if (a, b) == (0, rec.n) else rec.slice_time(float(rec.t[a]),
                                                               float(rec.t[b - 1]))
        if b - a < 50 or part.duration < need:
            notes.append(f"samples {a}-{b - 1} (t = {rec.t[a]:.3f}-{rec.t[b - 1]:.3f} s, "
                         f"{b - a} sample(s)) dropped: shorter than {need:.2g} s")
            continue
        pieces.append(part)
    if cuts.size:
        notes.append(f"cut at {cuts.size} gap(s) in the samples longer than {limit * 1e3:.0f} "
                     f"ms (longest {dt[cuts].max():.3g} s)")
    return pieces, notes


#: [s] The window over which a held frame's angle is averaged (:func:`frame_held`): five
#: times the fine encoder's Savitzky-Golay window, longer than any filter the frame's rows
#: see, so what it averages away the analysis would not have seen either.
HELD_WINDOW = 0.1


def held_span(rec: Recording) -> float:
    """[rad] The span of the frame's angle averaged over :data:`HELD_WINDOW` windows.

    ``m_i = mean{theta_j : |t_j - t_i| <= W / 2}`` at every sample whose whole window lies in
    the recording (running sums on the recording's own times: any line rate, any gaps), and
    the span ``max m - min m``; the raw angle's span when the recording is shorter than a
    window. An encoder flickering between neighbouring steps on a clamped shaft, or an
    analogue sensor's white noise, averages out; a frame that turns or creeps does not.
    """
    t, th = rec.t, rec.theta
    half = 0.5 * HELD_WINDOW
    full = (t - half >= t[0]) & (t + half <= t[-1])
    if not full.any():
        return float(np.ptp(th))
    c = np.concatenate([[0.0], np.cumsum(th - th[0])])
    lo = np.searchsorted(t, t[full] - half, side="left")
    hi = np.searchsorted(t, t[full] + half, side="right")
    return float(np.ptp((c[hi] - c[lo]) / (hi - lo)))


def held_bound(rec: Recording, resolution: float) -> float:
    """[rad] The largest :func:`held_span` of a held frame: its sensor's noise, averaged.

    Three encoder steps or 2 mrad, or ten times the noise of a window's average,
    ``10 sigma / sqrt(n)``: ``sigma`` the raw angle's noise (``1.4826 MAD`` of its
    successive differences over ``sqrt 2``, which a steady turn does not move), ``n`` the
    median samples per window. The averages of white noise over a run span about ``2
    sqrt(2 ln M) sigma / sqrt(n)`` (``M`` windows: 6-7 for a minute), so ten keeps a noisy
    sensor's clamped frame held at any line rate (a probe written apart: 2 mrad of noise at
    153 lines a second averaged to a 3 mrad span and was taken as rolling; 5 mrad at 920
    lines, 3.7 mrad); a frame that turns spans radians.
    """
    d = np.diff(rec.theta)
    if not d.size:
        return max(3.0 * resolution, 2e-3)
    sigma = robust_sd(d) / math.sqrt(2.0)
    per_window = max(float(HELD_WINDOW / np.median(np.diff(rec.t))), 1.0)
    return max(3.0 * resolution, 2e-3, 10.0 * sigma / math.sqrt(per_window))


def held_angle(rec: Recording) -> float:
    """[rad] Where a held frame is: its angle's mean, the outer 5 % on either side left out.

    Not the median: an encoder flickering between two counts has its median on one of them
    (a probe's two-count flicker of a 256-count encoder read 0.0000 rad for a frame at
    -0.0139 rad, between its counts -0.0245 and 0), and the null's noisy copies jumped
    between them, a whole count of frame angle that the ball's rows then had to explain.
    """
    return float(trim_mean(rec.theta, 0.05))


def frame_held(rec: Recording, resolution: float) -> bool:
    """Whether the frame did not turn: its angle spans no more than its sensor's noise.

    The raw angle's span or the span of its :data:`HELD_WINDOW` averages
    (:func:`held_span`) within :func:`held_bound`: a clamped frame whose encoder flickers
    between a few steps, or whose sensor is noisy, is held too.
    """
    bound = held_bound(rec, resolution)
    return bool(np.ptp(rec.theta) <= max(3.0 * resolution, 2e-3) or held_span(rec) <= bound)


def prepare(rec: Recording, cfg: PrepConfig | None = None, latency0: float = 0.0,
            held: bool | None = None) -> Prepared:
    """Smooth and differentiate a recording onto a uniform grid (module docstring).

    Parameters
    ----------
    rec : Recording
        The recording (our conventions), without long gaps (:func:`split_pieces`).
    cfg : PrepConfig, optional
        Settings.
    latency0 : float
        Nominal camera latency [s]: fixes are placed at ``t_fix - latency0``.
    held : bool, optional
        Whether the frame is held (default: :func:`frame_held`; the null passes the
        original's decision to its noisy copies).

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
    cfg = _adapted(cfg, rec)
    dt = cfg.dt
    tg = rec.t[0] + dt * np.arange(int(np.floor(rec.duration / dt)) + 1)
    info: dict[str, Any] = {"grid_dt": dt, "filters_s": {"antialias": cfg.antialias,
                                                        "sg_theta": cfg.sg_theta,
                                                        "sg_ball": cfg.sg_ball}}
    noise_thd = _velocity_noise(rec, tg, dt)
    res = _theta_resolution(rec)
    info["theta_resolution"] = float(res)
    info["theta_coarse"] = bool(res > cfg.coarse_theta)
    ball = _ball(rec, tg, cfg, latency0)
    info["ball"] = ball.note
    if ball.clock is not None:
        info["camera_clock"] = ball.clock.to_json()
    held = ball.has_ball and (frame_held(rec, res) if held is None else held)
    if held:
        # the frame does not turn: its angle is constant, its rates zero
        th0 = held_angle(rec)
        frame = _FrameAngle(theta=np.full(tg.size, th0), theta_dot=np.zeros(tg.size),
                            theta_ddot=np.zeros(tg.size), noise=float(res) / np.sqrt(12.0),
                            source=f"frame held at theta = {th0:.4f} rad (it spans "
                                   f"{np.ptp(rec.theta):.2g} rad, its {HELD_WINDOW:g} s "
                                   f"averages {held_span(rec):.2g} rad): ball rows only",
                            lag=None)
    else:
        frame = _frame_angle(rec, tg, cfg, res)
    info["theta_source"] = frame.source
    if frame.lag is not None:
        info["velocity_lag"] = frame.lag
    u = _torque(rec, tg, cfg)
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
                    psi_w_dot=ball.psi_w_dot, rho=ball.rho, ball_xy=ball.xy, ball_ok=ball.ok,
                    frame_ok=frame_ok, has_ball=ball.has_ball, frame_held=bool(held),
                    latency0=latency0,
                    noise={"camera": ball.noise, "camera_across": ball.noise_path[0],
                           "camera_along": ball.noise_path[1], "theta": frame.noise,
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
    lag: dict | None          # the logged velocity's measured lag (when it is used)


def _frame_angle(rec: Recording, tg: FloatArray, cfg: PrepConfig, res: float) -> _FrameAngle:
    """Frame angle, rate and acceleration on the grid ``tg`` (module docstring, step 2).

    A coarse encoder (resolution ``res`` above ``cfg.coarse_theta``): the logged velocity,
    advanced by its lag, integrated and fused with the angle (:func:`_coarse_theta`), both
    through the anti-alias filter (as the torque), then Savitzky-Golay smoothed and
    differentiated. A fine one: the anti-aliased angle,
    Savitzky-Golay smoothed and differentiated twice.
    """
    dt = cfg.dt
    win = _odd(cfg.sg_theta / dt)
    if res > cfg.coarse_theta:
        if cfg.dtheta_delay is None:
            vl = velocity_lag(rec.t, rec.theta, rec.theta_dot)
            lag = {**vl.to_json(), "how": "measured on this recording" if vl.identified else
                   vl.note}
            delay, c2 = vl.lag, vl.c2
        else:
            delay, c2 = float(cfg.dtheta_delay), float(cfg.dtheta_c2)
            lag = {"lag_s": delay, "c2_s2": c2,
                   "how": "given (--velocity-lag or the null's copy)"}
        theta, thd = _coarse_theta(rec, tg, cfg, delay, c2)
        # the same anti-alias filter as the torque's: the frame row balances J_f theta''
        # against the command, and a filter on one side only is a relative error of its
        # variance times omega^2 / 2 (a 10 ms Hann: 2.4e-4 at 12 rad/s), which a frame
        # inertia or a ball mass of that size then explained
        theta = _antialiased(tg, theta, tg, cfg.antialias, hold=False)
        thd = _antialiased(tg, thd, tg, cfg.antialias, hold=False)
        return _FrameAngle(
            theta=theta, theta_dot=savgol_filter(thd, win, cfg.sg_order),
            theta_ddot=savgol_filter(thd, win, cfg.sg_order, deriv=1, delta=dt),
            noise=float(res) / np.sqrt(12.0), lag=lag,
            source=(f"logged velocity advanced by {delay * 1e3:.2f} ms (its lag, "
                    f"{lag['how']}), integrated and fused with the coarse angle "
                    f"(resolution {res:.2g} rad)"))
    th = _antialiased(rec.t, rec.theta, tg, cfg.antialias, hold=False)
    theta = savgol_filter(th, win, cfg.sg_order)
    return _FrameAngle(
        theta=theta, theta_dot=savgol_filter(th, win, cfg.sg_order, deriv=1, delta=dt),
        theta_ddot=savgol_filter(th, win, cfg.sg_order, deriv=2, delta=dt),
        noise=float(np.std(th - theta)), lag=None,
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
    rho: FloatArray                # [m] distance from the shaft as the camera reports it
    xy: FloatArray | None          # (4, n): smoothed x, y [m], x_dot, y_dot [m/s]
    ok: NDArray[np.bool_]          # grid samples inside a usable segment (edges dropped)
    noise: float                   # [m] camera noise per axis (NaN if not estimated)
    noise_path: tuple[float, float] = (float("nan"), float("nan"))  # [m] across, along
    fixes: _Fixes | None           # the raw fixes (only when the ball rows apply)
    note: str                      # what was found (for the report)
    clock: CameraClock | None = None  # how the fixes were timed (no stamps: line arrivals)


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
        if cfg.ball == "no":
            note = (f"ball rows switched off (--ball no; the recording holds "
                    f"{int(nfix.sum())} valid camera fix(es)): frame-only analysis (row 1, "
                    f"ball terms off)")
        elif int(nfix.sum()) > 0:
            note = (f"no usable ball data: only {int(nfix.sum())} valid camera fix(es) in "
                    f"{rec.duration:.1f} s; frame-only analysis (row 1, ball terms off)")
        else:
            note = "no ball in the recording: frame-only analysis (row 1, ball terms off)"
        nan = np.full(tg.size, np.nan)
        return _Ball(has_ball=False, psi_w=nan, psi_w_dot=nan.copy(), rho=nan.copy(), xy=None,
                     ok=np.zeros(tg.size, bool), noise=float("nan"), fixes=None, note=note)
    fixes, ball_ok, clock = _ball_fixes(rec, nfix, tg, cfg, latency0)
    bxy = np.vstack(_smooth_ball(fixes, tg))
    psi_w = _world_angle(bxy[0], bxy[1])
    rho = np.hypot(bxy[0], bxy[1])
    psi_wd = (bxy[1] * bxy[2] - bxy[0] * bxy[3]) / (rho * rho)
    errs = _fix_prediction_errors(fixes.tf, fixes.x, fixes.y, cfg.max_gap)  # once, for both
    noise_cam, noise_path = _per_axis(errs), _across_along(errs)
    if not ball_ok.any():
        if cfg.ball == "yes":
            raise DiagnoseError("no usable ball segment (need "
                                f"{cfg.min_segment + 2 * cfg.edge:.2g} s of fixes with "
                                f"gaps under {cfg.max_gap * 1e3:.0f} ms)")
        return _Ball(has_ball=False, psi_w=psi_w, psi_w_dot=psi_wd, rho=rho, xy=None,
                     ok=ball_ok, noise=noise_cam, fixes=None,
                     note="no usable ball segment: frame-only analysis", clock=clock)
    timing = ("fixes at their own stamps" if clock is None else
              f"camera clock {1.0 / clock.period:.2f} Hz, fixes placed on it" if clock.used
              else "fixes at their lines' times (no steady camera clock)")
    return _Ball(has_ball=True, psi_w=psi_w, psi_w_dot=psi_wd, rho=rho, xy=bxy, ok=ball_ok,
                 noise=noise_cam, noise_path=noise_path, fixes=fixes,
                 note=(f"{len(segments_from_mask(ball_ok))} ball segment(s), "
                       f"{ball_ok.mean() * 100:.0f} % of the run; {int(nfix.sum())} fixes "
                       f"({rec.camera_fix_rate():.0f} per second); {timing}"), clock=clock)


def _ball_fixes(rec: Recording, nfix: NDArray[np.bool_], tg: FloatArray, cfg: PrepConfig,
                latency0: float) -> tuple[_Fixes, NDArray[np.bool_], CameraClock | None]:
    """The distinct fixes, placed at ``t_fix - latency0`` and cut into segments at gaps.

    ``t_fix`` is the fix's own stamp when the source has one, else its line's time
    (:meth:`bfr_model.recording.Recording.fix_times`), placed on the camera's steady clock
    when the arrivals show one (:func:`bfr_model.io.timing.camera_clock`: the wait for the
    next line removed; None with stamps). A segment needs 10 fixes,
    ``min_segment + 2 edge`` seconds and more grid samples than the Savitzky-Golay window;
    its first and last ``edge`` seconds are not usable.

    Returns
    -------
    fixes : _Fixes
        The fixes and their segments.
    ball_ok : ndarray of bool
        Grid samples inside a segment, edges dropped.
    clock : CameraClock or None
        How fixes without stamps were timed.
    """
    dt = cfg.dt
    n_edge = round(cfg.edge / dt)
    clock = None
    tf = rec.fix_times()
    if rec.extra.get("ball_stamp") is None and rec.n > 1:
        clock = camera_clock(tf, float(np.median(np.diff(rec.t))), cfg.max_gap)
        tf = clock.times
    tf = tf - latency0
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
    return fixes, ball_ok, clock


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
    held = all(p.frame_held for p in preps)
    if (not has_ball and any(p.has_ball for p in preps)) or (
            not held and any(p.frame_held for p in preps)):
        raise DiagnoseError("cannot stitch runs of different kinds (ball or not, frame held "
                            "or not): prepare them as separate parts")
    parts: dict[str, list[FloatArray]] = {k: [] for k in (
        "theta", "theta_dot", "theta_ddot", "u", "psi_w", "psi_w_dot", "rho", "ball_ok",
        "frame_ok", "bx", "by", "bxd", "byd")}
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
                elif name in ("psi_w", "psi_w_dot", "rho", "bx", "by", "bxd", "byd"):
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
        parts["rho"].append(p.rho if p.rho is not None else np.full(p.n, np.nan))
        xy = p.ball_xy if p.ball_xy is not None else np.full((4, p.n), np.nan)
        for j, key in enumerate(("bx", "by", "bxd", "byd")):
            parts[key].append(xy[j])
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
    info["ball"] = f"{len(preps)} runs stitched ({gap:.1f} s unusable gaps); " + (
        _ball_note_of_runs(preps) if has_ball else str(preps[0].info.get("ball")))
    lags = [p.info["velocity_lag"] for p in preps if "velocity_lag" in p.info]
    if lags:
        info["velocity_lag_runs"] = lags
    if not has_ball:
        cat["ball_ok"][:] = False
    return Prepared(t=t, theta=cat["theta"], theta_dot=cat["theta_dot"],
                    theta_ddot=cat["theta_ddot"], u=cat["u"], psi_w=cat["psi_w"],
                    psi_w_dot=cat["psi_w_dot"], rho=cat["rho"],
                    ball_xy=np.vstack([cat[k] for k in ("bx", "by", "bxd", "byd")]),
                    ball_ok=cat["ball_ok"],
                    frame_ok=cat["frame_ok"], has_ball=has_ball, frame_held=held,
                    latency0=preps[0].latency0, noise=noise, info=info, fixes=fixes)


def _ball_note_of_runs(preps: list[Prepared]) -> str:
    """The ball note of stitched runs: segments, share and fixes counted over every run.

    Each run's own note (its fixes, its camera timing) is in its ``info["ball"]``; the
    stitched part's counts all of them (it had repeated the first run's).
    """
    fixes = sum(p.fixes.tf.size for p in preps if p.fixes is not None)
    segs = sum(len(p.fixes.segs) for p in preps if p.fixes is not None)
    share = sum(int(np.count_nonzero(p.ball_ok)) for p in preps) / sum(p.n for p in preps)
    span = sum(float(p.t[-1] - p.t[0]) for p in preps)
    per_run = ", ".join(str(p.fixes.tf.size if p.fixes is not None else 0) for p in preps)
    return (f"over all {len(preps)} runs: {segs} ball segment(s), {share * 100:.0f} % of "
            f"their time; {fixes} fixes ({fixes / span:.0f} per second; per run {per_run})")


def prepare_runs(recs: list[Recording], cfg: PrepConfig | None = None,
                 latency0: float = 0.0, held: bool | None = None) -> Prepared:
    """:func:`prepare` each run, then :func:`stitch` them (one run: just :func:`prepare`)."""
    return stitch([prepare(r, cfg, latency0=latency0, held=held) for r in recs])


@dataclass(frozen=True, kw_only=True, eq=False)
class Piece:
    """One continuous piece of a recording and the decisions its preprocessing made.

    The noise-only null prepares noisy copies of the same pieces with the same decisions
    (:func:`prepare_pieces`), so that only the noise differs.

    Attributes
    ----------
    rec : Recording
        The piece (:func:`split_pieces`).
    held : bool
        Whether its frame is held.
    lag : float or None
        The logged velocity's lag used [s] (None: a fine encoder, the velocity unused).
    c2 : float
        The logged velocity's second-order term used [s^2].
    """

    rec: Recording
    held: bool
    lag: float | None
    c2: float = 0.0


def prepare_pieces(pieces: list[Piece], cfg: PrepConfig | None = None,
                   latency0: float = 0.0, recs: list[Recording] | None = None) -> Prepared:
    """Prepare pieces with their recorded decisions and stitch them (one kind).

    ``recs`` replaces the pieces' recordings (the null's noisy copies).
    """
    cfg = cfg or PrepConfig()
    out = []
    for pc, rec in zip(pieces, recs or [pc.rec for pc in pieces], strict=True):
        c = cfg if pc.lag is None else replace(cfg, dtheta_delay=pc.lag, dtheta_c2=pc.c2)
        out.append(prepare(rec, c, latency0=latency0, held=pc.held))
    return stitch(out)


def _kind(p: Prepared) -> str:
    if not p.has_ball:
        return "frame only"
    return "frame held" if p.frame_held else "rolling"


def plan_parts(runs: list[Recording], cfg: PrepConfig | None = None, latency0: float = 0.0
               ) -> tuple[list[tuple[str, list[Piece], Prepared]], list[str]]:
    """The runs of one recording, cut into pieces, prepared and stitched by kind.

    Every run is cut at gaps (:func:`split_pieces`); each usable piece is prepared alone;
    pieces of one kind (rolling ball, frame held, frame only) are stitched into one part.
    What was dropped, and why, is in the notes: nothing is lost silently.

    Returns
    -------
    parts : list of (kind, pieces, Prepared)
        One per kind present, in the order rolling, frame held, frame only.
    notes : list of str
        Cuts and dropped runs or pieces.

    Raises
    ------
    DiagnoseError
        No usable piece at all.
    """
    cfg = cfg or PrepConfig()
    notes: list[str] = []
    groups: dict[str, list[tuple[Piece, Prepared]]] = {}
    for k, run in enumerate(runs):
        pieces, why = split_pieces(run, cfg)
        tag = f"run {k}: " if len(runs) > 1 else ""
        notes += [tag + w for w in why]
        for rec in pieces:
            try:
                p = prepare(rec, cfg, latency0=latency0)
            except DiagnoseError as exc:
                notes.append(f"{tag}a piece of {rec.duration:.2f} s dropped: {exc}")
                continue
            vl = p.info.get("velocity_lag", {})
            groups.setdefault(_kind(p), []).append(
                (Piece(rec=rec, held=p.frame_held, lag=vl.get("lag_s"),
                       c2=float(vl.get("c2_s2") or 0.0)), p))
    if not groups:
        raise DiagnoseError("no usable data: " + ("; ".join(notes) or "every run too short"))
    out = []
    for kind in ("rolling", "frame held", "frame only"):
        if kind in groups:
            pieces = [pc for pc, _ in groups[kind]]
            out.append((kind, pieces, stitch([p for _, p in groups[kind]])))
    return out, notes
