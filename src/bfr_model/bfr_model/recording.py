"""The project's recording data model: one run of the rig or the simulator.

A :class:`Recording` holds sampled signals as numpy arrays in **our** conventions
(DEVELOPERS.md: SI units, radians, world frame with origin on the frame's axis, x right,
y up, angles counter-clockwise positive, ``theta`` accumulating over turns). Readers and
writers live in :mod:`bfr_model.io` (NTNU rig terminal logs, simulator CSV, ROS 2 bags); they
convert at the edges and write every conversion they applied into ``meta["conversions"]``.

Sampling model
--------------
``t`` is the time base of the frame signals (encoder and torque command, one sample per
control step on the rig). The camera runs at its own rate: ``ball_x``, ``ball_y``,
``ball_valid`` and ``phi`` hold the **latest** camera fix at each sample (zero-order hold),
exactly as a controller sees them; :meth:`Recording.new_fix_mask` marks the samples where a
new distinct fix arrived. When the source stamps each fix (a ROS message's header stamp:
the exposure), ``extra["ball_stamp"]`` holds the held fix's own time [s] on the axis of
``t``, and :meth:`Recording.fix_times` returns those stamps; otherwise a fix's time is that
of the sample where it first appears (its arrival). Simulated recordings without a camera
model have a fix at every sample.

This module is pure numpy (no ``rclpy``).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_model.params import params_to_dict

__all__ = [
    "OPTIONAL_FIELDS",
    "REQUIRED_FIELDS",
    "TRUTH_FIELDS",
    "Recording",
    "RecordingError",
    "ball_centre_angle",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Per-sample arrays every recording has, in order.
REQUIRED_FIELDS = ("t", "theta", "theta_dot", "torque", "ball_x", "ball_y", "ball_valid", "phi")
#: Ground-truth arrays a simulated recording may carry (None when absent).
TRUTH_FIELDS = ("theta_true", "theta_dot_true", "phi_true", "phi_dot_true", "ball_x_true",
                "ball_y_true", "kinetic", "potential", "energy")
#: All optional per-sample arrays (None when absent).
OPTIONAL_FIELDS = ("phi_dot", *TRUTH_FIELDS)
#: Arrays that must be finite at every sample.
_FINITE_FIELDS = ("t", "theta", "theta_dot", "torque")


class RecordingError(ValueError):
    """A recording is empty, inconsistent or malformed; the message names the problem."""


def _as_float(name: str, value: ArrayLike) -> FloatArray:
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise RecordingError(f"field {name!r} is not numeric: {exc}") from exc
    if arr.ndim != 1:
        raise RecordingError(f"field {name!r} must be one-dimensional, got shape {arr.shape}")
    return arr


@dataclass(eq=False)
class Recording:
    """One recorded or simulated run, sampled on the time base ``t``.

    All arrays have the same length ``n``. Construction validates the arrays (see
    :meth:`validate`) and normalises the ball fields: where ``ball_valid`` is false,
    ``ball_x``, ``ball_y`` and ``phi`` are set to NaN.

    Attributes
    ----------
    t : ndarray of float, shape (n,)
        Sample times [s], finite and strictly increasing.
    theta : ndarray of float
        Frame angle [rad], counter-clockwise positive, accumulating over turns.
    theta_dot : ndarray of float
        Frame angular velocity [rad/s] as measured (on the rig: the servo's filtered
        estimate, see ``meta``).
    torque : ndarray of float
        Commanded motor torque [N m], positive accelerating ``theta`` positive.
    ball_x, ball_y : ndarray of float
        Ball centre in the world frame [m] (latest camera fix, held); NaN where invalid.
    ball_valid : ndarray of bool
        True where the held ball fix is a valid, current observation.
    phi : ndarray of float
        Polar angle of the **ball centre** [rad], clockwise from the frame's +y axis,
        ``theta + atan2(ball_x, ball_y)`` with the frame angle at the fix (DEVELOPERS.md);
        NaN where invalid. For a simulation the contact-point angle is ``phi_true``.
    phi_dot : ndarray of float or None
        Estimate of the ball-centre angle rate [rad/s] when the source provides one.
    theta_true, theta_dot_true : ndarray of float or None
        Ground-truth frame angle [rad] and rate [rad/s] (simulation only).
    phi_true, phi_dot_true : ndarray of float or None
        Ground-truth state ``phi`` [rad], i.e. the **contact-point** polar angle of the state
        vector ``[theta, phi, theta_dot, phi_dot]``, and its rate [rad/s] (simulation only).
    ball_x_true, ball_y_true : ndarray of float or None
        Ground-truth ball centre in the world frame [m] (simulation only).
    kinetic, potential, energy : ndarray of float or None
        Kinetic, potential and total mechanical energy [J] (simulation only).
    extra : dict of str to ndarray
        Further per-sample arrays, unit in ``meta["units"][name]`` when known.
    meta : dict
        Provenance: ``source`` (path), ``source_kind`` (``"ntnu_rig_log"``, ``"csv"``,
        ``"bag"``, ``"simulation"``, ...), ``conversions`` (list of strings, every
        conversion applied to reach our conventions), ``sample_rate`` [Hz],
        ``camera_fix_rate`` [Hz], ``notes`` (list of strings) and reader-specific entries.
    """

    t: FloatArray
    theta: FloatArray
    theta_dot: FloatArray
    torque: FloatArray
    ball_x: FloatArray
    ball_y: FloatArray
    ball_valid: BoolArray
    phi: FloatArray
    phi_dot: FloatArray | None = None
    theta_true: FloatArray | None = None
    theta_dot_true: FloatArray | None = None
    phi_true: FloatArray | None = None
    phi_dot_true: FloatArray | None = None
    ball_x_true: FloatArray | None = None
    ball_y_true: FloatArray | None = None
    kinetic: FloatArray | None = None
    potential: FloatArray | None = None
    energy: FloatArray | None = None
    extra: dict[str, FloatArray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    # -- construction and validation ----------------------------------------------------
    def __post_init__(self) -> None:
        for name in REQUIRED_FIELDS:
            value = getattr(self, name)
            if value is None:
                raise RecordingError(f"required field {name!r} is missing (None)")
            if name == "ball_valid":
                try:
                    arr = np.array(value, dtype=bool, copy=True)
                except (TypeError, ValueError) as exc:
                    raise RecordingError(f"field 'ball_valid' is not boolean: {exc}") from exc
                if arr.ndim != 1:
                    raise RecordingError(
                        f"field 'ball_valid' must be one-dimensional, got shape {arr.shape}")
                self.ball_valid = arr
            else:
                setattr(self, name, _as_float(name, value))
        for name in OPTIONAL_FIELDS:
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, _as_float(name, value))
        self.extra = {str(k): _as_float(f"extra[{k!r}]", v) for k, v in self.extra.items()}
        self.meta = dict(self.meta)
        self.meta.setdefault("conversions", [])
        self.meta.setdefault("notes", [])
        self.validate()
        invalid = ~self.ball_valid
        if invalid.any():
            self.ball_x[invalid] = np.nan
            self.ball_y[invalid] = np.nan
            self.phi[invalid] = np.nan

    def arrays(self) -> dict[str, np.ndarray]:
        """All present per-sample arrays by name (required, optional, then ``extra``)."""
        out: dict[str, np.ndarray] = {name: getattr(self, name) for name in REQUIRED_FIELDS}
        for name in OPTIONAL_FIELDS:
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        for name, value in self.extra.items():
            out[f"extra.{name}"] = value
        return out

    def validate(self) -> None:
        """Check the invariants; raise :class:`RecordingError` naming the first problem.

        Raises
        ------
        RecordingError
            If the recording is empty, array lengths differ, ``t``, ``theta``,
            ``theta_dot`` or ``torque`` hold NaN or infinity, ``t`` is not strictly
            increasing, or a sample marked valid has a non-finite ball position or ``phi``.
        """
        n = self.t.shape[0]
        if n == 0:
            raise RecordingError("recording is empty (no samples)")
        for name, arr in self.arrays().items():
            if arr.shape[0] != n:
                raise RecordingError(
                    f"mismatched lengths: {name!r} has {arr.shape[0]} samples, 't' has {n}")
        for name in _FINITE_FIELDS:
            arr = getattr(self, name)
            bad = ~np.isfinite(arr)
            if bad.any():
                i = int(np.argmax(bad))
                kind = "NaN" if np.isnan(arr[i]) else "infinite value"
                raise RecordingError(
                    f"{kind} in {name!r} at sample {i} (t = {self.t[i] if name != 't' else '?'}"
                    f"); {int(bad.sum())} bad sample(s) in total")
        if n > 1:
            dt = np.diff(self.t)
            bad = dt <= 0.0
            if bad.any():
                i = int(np.argmax(bad))
                what = "repeats" if dt[i] == 0.0 else "goes backwards"
                raise RecordingError(
                    f"non-monotonic time: t {what} at sample {i + 1} "
                    f"({self.t[i]!r} -> {self.t[i + 1]!r} s); {int(bad.sum())} such step(s)")
        v = self.ball_valid
        for name in ("ball_x", "ball_y", "phi"):
            arr = getattr(self, name)
            bad = v & ~np.isfinite(arr)
            if bad.any():
                i = int(np.argmax(bad))
                raise RecordingError(
                    f"sample {i} (t = {self.t[i]} s) is marked ball_valid but {name!r} is "
                    f"{arr[i]}")

    def copy(self) -> Recording:
        """Deep copy (arrays and meta)."""
        return copy.deepcopy(self)

    # -- summary quantities -------------------------------------------------------------
    def __len__(self) -> int:
        """Number of samples."""
        return int(self.t.shape[0])

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self)

    @property
    def duration(self) -> float:
        """``t[-1] - t[0]`` [s] (0 for a single sample)."""
        return float(self.t[-1] - self.t[0])

    @property
    def has_truth(self) -> bool:
        """True when the recording carries simulation ground truth (``phi_true``)."""
        return self.phi_true is not None

    def sample_rate(self) -> float:
        """Median sample rate [Hz], ``1 / median(diff(t))``; NaN for fewer than 2 samples."""
        if len(self) < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.t)))

    def new_fix_mask(self) -> BoolArray:
        """True at the valid samples where a new, distinct ball fix arrived.

        A sample counts when it is valid and its fix differs from the previous sample's
        (another ``extra["ball_stamp"]`` when the fixes are stamped, else another
        ``(ball_x, ball_y)``), or the previous sample was invalid.
        """
        v = self.ball_valid
        new = v.copy()
        if len(self) > 1:
            stamp = self.extra.get("ball_stamp")
            if stamp is not None:
                same = stamp[1:] == stamp[:-1]
            else:
                same = ((self.ball_x[1:] == self.ball_x[:-1])
                        & (self.ball_y[1:] == self.ball_y[:-1]))
            new[1:] &= ~(same & v[:-1])
        return new

    def fix_times(self) -> FloatArray:
        """Times [s] of the new distinct ball fixes (see :meth:`new_fix_mask`).

        The fixes' own stamps (``extra["ball_stamp"]``) when the source has them, else the
        times of the samples where they first appear.
        """
        m = self.new_fix_mask()
        stamp = self.extra.get("ball_stamp")
        return stamp[m] if stamp is not None else self.t[m]

    def camera_fix_rate(self, t_from: float | None = None, t_to: float | None = None) -> float:
        """Rate of new distinct ball fixes [Hz] between two times (default: whole run).

        Computed as (number of fixes - 1) / (last fix time - first fix time), so an idle
        start or end of the run does not dilute it. NaN with fewer than two fixes.
        """
        ft = self.fix_times()
        if t_from is not None:
            ft = ft[ft >= t_from]
        if t_to is not None:
            ft = ft[ft <= t_to]
        if ft.size < 2 or ft[-1] <= ft[0]:
            return float("nan")
        return float((ft.size - 1) / (ft[-1] - ft[0]))

    def valid_fraction(self) -> float:
        """Fraction of samples with a valid ball observation [-]."""
        return float(np.mean(self.ball_valid))

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: samples, duration, rates, valid fraction, source."""
        return {
            "samples": len(self),
            "t_start": float(self.t[0]),
            "duration": self.duration,
            "sample_rate": self.sample_rate(),
            "camera_fix_rate": self.camera_fix_rate(),
            "ball_valid_fraction": self.valid_fraction(),
            "has_truth": self.has_truth,
            "source": self.meta.get("source"),
            "source_kind": self.meta.get("source_kind"),
        }

    # -- transformations ----------------------------------------------------------------
    def _take(self, index: NDArray[np.intp] | slice, note: str) -> Recording:
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "extra":
                kwargs["extra"] = {k: v[index] for k, v in value.items()}
            elif f.name == "meta":
                meta = copy.deepcopy(value)
                meta["conversions"] = [*meta.get("conversions", []), note]
                kwargs["meta"] = meta
            elif value is None:
                kwargs[f.name] = None
            else:
                kwargs[f.name] = value[index]
        return Recording(**kwargs)

    def slice_time(self, t_from: float | None = None, t_to: float | None = None) -> Recording:
        """The samples with ``t_from <= t <= t_to`` as a new recording.

        Parameters
        ----------
        t_from, t_to : float, optional
            Window bounds [s]; None means open-ended.

        Raises
        ------
        RecordingError
            If the window holds no sample.
        """
        lo = -np.inf if t_from is None else float(t_from)
        hi = np.inf if t_to is None else float(t_to)
        mask = (self.t >= lo) & (self.t <= hi)
        if not mask.any():
            raise RecordingError(
                f"time window [{lo}, {hi}] s holds no sample (recording spans "
                f"[{self.t[0]}, {self.t[-1]}] s)")
        return self._take(np.nonzero(mask)[0], f"sliced to t in [{lo}, {hi}] s")

    def resample(self, rate: float | None = None, dt: float | None = None,
                 ball: str = "previous") -> Recording:
        """Resample onto a uniform grid ``t[0] + k dt`` within ``[t[0], t[-1]]``.

        Continuous signals (``theta``, ``theta_dot``, ``phi_dot`` and every ground-truth and
        extra array) are interpolated linearly. ``torque`` is a command held between control
        steps, so it is sampled with zero-order hold (value of the latest sample at or
        before the grid time). The ball fields follow ``ball``.

        Parameters
        ----------
        rate : float, optional
            Grid rate [Hz]; give exactly one of ``rate`` and ``dt``.
        dt : float, optional
            Grid step [s].
        ball : {"previous", "linear"}
            ``"previous"`` (default) holds the latest fix, as the camera does; ``"linear"``
            interpolates ``ball_x``, ``ball_y`` and ``phi`` between valid neighbours and marks
            a grid point valid only when both neighbouring samples are valid.

        Returns
        -------
        Recording
            The resampled recording; the grid is recorded in ``meta["conversions"]``.
        """
        if (rate is None) == (dt is None):
            raise RecordingError("resample: give exactly one of rate [Hz] and dt [s]")
        step = float(dt) if dt is not None else 1.0 / float(rate)  # type: ignore[arg-type]
        if not np.isfinite(step) or step <= 0.0:
            raise RecordingError(f"resample: step must be positive and finite, got {step} s")
        if ball not in ("previous", "linear"):
            raise RecordingError(f"resample: ball must be 'previous' or 'linear', got {ball!r}")
        n_new = int(np.floor(self.duration / step + 1e-9)) + 1
        tg = self.t[0] + step * np.arange(n_new)
        prev = np.clip(np.searchsorted(self.t, tg, side="right") - 1, 0, len(self) - 1)

        def lin(y: FloatArray) -> FloatArray:
            return np.interp(tg, self.t, y)

        kwargs: dict[str, Any] = {"t": tg, "theta": lin(self.theta),
                                  "theta_dot": lin(self.theta_dot), "torque": self.torque[prev]}
        if ball == "previous":
            kwargs.update(ball_x=self.ball_x[prev], ball_y=self.ball_y[prev],
                          ball_valid=self.ball_valid[prev], phi=self.phi[prev])
        else:
            nxt = np.clip(prev + 1, 0, len(self) - 1)
            valid = self.ball_valid[prev] & self.ball_valid[nxt]
            for name in ("ball_x", "ball_y", "phi"):
                arr = getattr(self, name)
                y = np.full(n_new, np.nan)
                if valid.any():
                    v = self.ball_valid
                    y[valid] = np.interp(tg[valid], self.t[v], arr[v])
                kwargs[name] = y
            kwargs["ball_valid"] = valid
        for name in OPTIONAL_FIELDS:
            value = getattr(self, name)
            kwargs[name] = None if value is None else lin(value)
        # a fix's stamp is held with the fix, like the ball fields
        kwargs["extra"] = {k: (v[prev] if k == "ball_stamp" and ball == "previous" else lin(v))
                           for k, v in self.extra.items()}
        meta = copy.deepcopy(self.meta)
        meta["conversions"] = [*meta.get("conversions", []),
                               f"resampled onto a uniform grid, dt = {step!r} s "
                               f"(torque zero-order hold, ball '{ball}', others linear)"]
        meta["sample_rate"] = 1.0 / step
        kwargs["meta"] = meta
        return Recording(**kwargs)

    # -- comparison (tests, round trips) ------------------------------------------------
    def allclose(self, other: Recording, rtol: float = 1e-9, atol: float = 1e-12) -> bool:
        """True when both hold the same arrays, equal within tolerance (NaN equals NaN)."""
        return not self.differences(other, rtol=rtol, atol=atol)

    def differences(self, other: Recording, rtol: float = 1e-9,
                    atol: float = 1e-12) -> list[str]:
        """Human-readable list of the arrays that differ from ``other`` (empty if none)."""
        a, b = self.arrays(), other.arrays()
        out = [f"{k}: only in {'self' if k in a else 'other'}" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            x, y = a[k], b[k]
            if x.shape != y.shape:
                out.append(f"{k}: shape {x.shape} != {y.shape}")
            elif x.dtype == bool or y.dtype == bool:
                if not np.array_equal(x, y):
                    out.append(f"{k}: {int(np.sum(x != y))} sample(s) differ")
            elif not np.allclose(x, y, rtol=rtol, atol=atol, equal_nan=True):
                with np.errstate(invalid="ignore"):
                    err = np.nanmax(np.abs(x - y)) if np.isfinite(x - y).any() else np.nan
                out.append(f"{k}: max abs difference {err}")
        return out

    # -- constructors -------------------------------------------------------------------
    @classmethod
    def from_sim(cls, res: Any, model: Any = None, *, source: str | None = None) -> Recording:
        """Build a recording from a :class:`bfr_model.simulate.SimResult`.

        The simulator's state ``phi`` is the contact-point angle; it becomes ``phi_true``
        (rate ``phi_dot_true``). ``phi`` is the ball-centre polar angle
        ``theta + atan2(ball_x, ball_y)``, taken in the turn nearest to the contact angle.
        The ball is valid at every sample (no camera model).

        Parameters
        ----------
        res : SimResult
            Simulated trajectory: ``t``, ``x`` (columns theta, phi, theta_dot, phi_dot,
            ...), ``u``, ``ball`` (n, 2), ``kinetic``, ``potential``.
        model : RigidModel, optional
            The model simulated; its parameters are stored in ``meta["params"]``.
        source : str, optional
            Provenance string for ``meta["source"]``.
        """
        t = np.asarray(res.t, float)
        x = np.asarray(res.x, float)
        ball = np.asarray(res.ball, float)
        theta, phi_c, theta_dot, phi_dot = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
        phi_ball = ball_centre_angle(theta, ball[:, 0], ball[:, 1], near=phi_c)
        kinetic = np.asarray(res.kinetic, float)
        potential = np.asarray(res.potential, float)
        meta: dict[str, Any] = {
            "source": source or "bfr_model.simulate",
            "source_kind": "simulation",
            "conversions": [],
            "notes": ["phi is the ball-centre angle theta + atan2(ball_x, ball_y); the "
                      "state's contact-point angle is phi_true"],
            "sim_info": {k: v for k, v in dict(getattr(res, "info", {}) or {}).items()
                         if isinstance(v, (str, int, float, bool))},
        }
        if model is not None and getattr(model, "params", None) is not None:
            meta["params"] = params_to_dict(model.params)
        rec = cls(t=t, theta=theta, theta_dot=theta_dot, torque=np.asarray(res.u, float),
                  ball_x=ball[:, 0], ball_y=ball[:, 1], ball_valid=np.ones(t.shape, bool),
                  phi=phi_ball, phi_dot=None, theta_true=theta.copy(),
                  theta_dot_true=theta_dot.copy(), phi_true=phi_c, phi_dot_true=phi_dot,
                  ball_x_true=ball[:, 0].copy(), ball_y_true=ball[:, 1].copy(),
                  kinetic=kinetic, potential=potential, energy=kinetic + potential, meta=meta)
        rec.meta["sample_rate"] = rec.sample_rate()
        return rec


def ball_centre_angle(theta: ArrayLike, ball_x: ArrayLike, ball_y: ArrayLike,
                      near: ArrayLike | None = None) -> FloatArray:
    """Ball-centre polar angle ``theta + atan2(x, y)`` [rad], in a chosen turn.

    Parameters
    ----------
    theta : array_like
        Frame angle [rad] at the fix.
    ball_x, ball_y : array_like
        Ball centre in the world frame [m].
    near : array_like, optional
        Reference angle [rad] (e.g. the contact-point angle); the result is shifted by a
        multiple of 2 pi to lie within pi of it. Without it the raw sum is returned.

    Returns
    -------
    ndarray
        The angle [rad]; NaN where the inputs are NaN.
    """
    phi = np.asarray(theta, float) + np.arctan2(np.asarray(ball_x, float),
                                                np.asarray(ball_y, float))
    if near is not None:
        ref = np.asarray(near, float)
        phi = phi - 2.0 * np.pi * np.round((phi - ref) / (2.0 * np.pi))
    return phi
