"""Trajectories for the analyses: any rigid-state time series, or a closed-loop run.

The analyses take a :class:`Trajectory` (``t, theta, phi, theta_dot, phi_dot, u``), so they
work on open-loop runs, recordings or closed-loop runs alike. The closed loops use the
node suite's controller (``bfr_control``):

- :func:`closed_loop_rigid`: ``bfr_sim.closed_loop.run_closed_loop`` (rigid plant);
- :func:`closed_loop_contact`: the same controller, camera model and control rate against the
  contact model (:class:`bfr_model.contact.ContactModel`), which the rigid harness cannot run.
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_control.controller import BALL_LOST, ROLLING, OrbitalController
from bfr_control.estimator import BallObservation
from bfr_model.contact import ISLIP, ITH, ITHD, IX, IY, ContactModel
from bfr_model.params import RigParams
from bfr_model.perturbations import StudySettings
from bfr_sim.closed_loop import (
    SensorConfig,
    orbit_initial_state,
    run_closed_loop,
)
from numpy.typing import NDArray

__all__ = [
    "ContactLoopResult",
    "Trajectory",
    "closed_loop_contact",
    "closed_loop_rigid",
    "progress",
]

FloatArray = NDArray[np.float64]


def progress(msg: str) -> None:
    """A progress line on stderr (long analyses)."""
    print(f"[analyze] {msg}", file=sys.stderr, flush=True)


@dataclass
class Trajectory:
    """A rigid-state trajectory.

    Attributes
    ----------
    t : ndarray
        Times [s], shape (n,), uniformly or not spaced.
    x : ndarray
        ``[theta, phi, theta_dot, phi_dot]`` [rad, rad, rad/s, rad/s], shape (n, 4).
    u : ndarray
        Motor torque command held from t [N m].
    label : str
        Where it comes from.
    info : dict
        Run summary.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    label: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, float)
        self.x = np.asarray(self.x, float)[:, :4]
        self.u = np.asarray(self.u, float)
        if not (self.t.ndim == 1 and self.x.shape == (self.t.size, 4)
                and self.u.shape == self.t.shape):
            raise ValueError("trajectory: t (n,), x (n, 4) and u (n,) must agree")
        if self.t.size < 3 or np.any(np.diff(self.t) <= 0.0):
            raise ValueError("trajectory: need >= 3 samples at increasing times")

    @property
    def theta(self) -> FloatArray:
        """Frame angle [rad]."""
        return self.x[:, 0]

    @property
    def phi(self) -> FloatArray:
        """Contact angle [rad]."""
        return self.x[:, 1]

    @property
    def theta_dot(self) -> FloatArray:
        """Frame rate [rad/s]."""
        return self.x[:, 2]

    @property
    def phi_dot(self) -> FloatArray:
        """Contact-angle rate [rad/s]."""
        return self.x[:, 3]


def _controller(params: RigParams) -> Any:

    return OrbitalController(params)


def closed_loop_rigid(plant: RigParams, study: StudySettings, controller_params: RigParams,
                      duration: float | None = None, controller: Any = None) -> Trajectory:
    """Closed-loop run of the controller (model ``controller_params``) on the rigid plant.

    Starts on the controller's orbit at ``study.run.phase`` with the frame offset
    ``study.run.d_theta``; camera noise ``study.run.camera_noise``, seeded.
    """
    r = study.run
    ctrl = controller if controller is not None else _controller(controller_params)
    x0 = orbit_initial_state(ctrl, r.phase, d_theta=r.d_theta)
    res = run_closed_loop(ctrl, plant, float(duration or r.duration), x0,
                          SensorConfig(camera_noise=r.camera_noise), seed=r.seed)
    s = res.summary()
    info = {k: s[k] for k in ("ball_rolling", "rolling_until", "failure", "mean_phi_dot",
                              "rms_y", "rms_torque", "wall_time", "control_rate") if k in s}
    info["min_normal_force"] = float(np.min(res.normal_force))
    return Trajectory(res.t, res.x[:, :4], res.u, label="closed loop, rigid plant", info=info)


@dataclass
class ContactLoopResult:
    """A closed-loop run with the contact plant, sampled at the control steps.

    Attributes
    ----------
    t : ndarray
        Times [s].
    x : ndarray
        Contact states (:mod:`bfr_model.contact`), shape (n, NX).
    u : ndarray
        Torque command held from t [N m].
    rigid : ndarray
        Rigid-equivalent states (closest point), shape (n, 4).
    normal_force, penetration, slip_velocity, energy : ndarray
        Diagnostics at t ([N], [m], [m/s], [J]).
    mode : ndarray
        Controller mode codes (0 waiting, 1 rolling, 2 lost).
    wall_time : float
        Wall time of the plant integration [s] (the controller excluded).
    wall_total : float
        Wall time of the whole loop [s].
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    rigid: FloatArray
    normal_force: FloatArray
    penetration: FloatArray
    slip_velocity: FloatArray
    energy: FloatArray
    mode: NDArray[np.int8]
    wall_time: float
    wall_total: float

    @property
    def slip(self) -> FloatArray:
        """Accumulated slip angle: integral of ``v_slip / R`` [rad]."""
        return self.x[:, ISLIP]

    def trajectory(self) -> Trajectory:
        """The rigid-equivalent :class:`Trajectory`."""
        return Trajectory(self.t, self.rigid, self.u, label="closed loop, contact plant")

    @property
    def rolling_until(self) -> float:
        """Time the ball stopped rolling forward or the controller lost it [s] (end if never)."""
        bad = np.nonzero((self.rigid[:, 3] <= 0.0) | (self.mode == 2))[0]
        return float(self.t[bad[0]]) if bad.size else float(self.t[-1])


def closed_loop_contact(model: ContactModel, controller_params: RigParams, study: StudySettings,
                        duration: float, camera_rate: float = 200.0,
                        camera_latency: float = 0.005, seed: int = 0,
                        report_every: float = 2.0, controller: Any = None,
                        stop_after_lost: float | None = None) -> ContactLoopResult:
    """The controller (model ``controller_params``) against the contact plant ``model``.

    Same structure as ``bfr_sim.closed_loop.run_closed_loop``: control at the
    controller's rate with the torque held, exact encoder, camera exposures of the ball
    centre at ``camera_rate`` [Hz] delivered ``camera_latency`` [s] later with Gaussian noise
    ``study.run.camera_noise`` [m] (seeded). Starts on the orbit like
    :func:`closed_loop_rigid`, the ball pressed onto the track in equilibrium. With
    ``stop_after_lost`` [s] the run ends that long after the controller declared the ball
    lost.
    """
    r = study.run
    ctrl = controller if controller is not None else _controller(controller_params)
    ctrl.reset()
    rate = float(ctrl.config.control.rate)
    Tc = 1.0 / rate
    n = round(duration / Tc) + 1
    rng = np.random.default_rng(seed)
    x0r = orbit_initial_state(ctrl, r.phase, d_theta=r.d_theta)
    x = model.state_from_rigid(x0r)
    T = np.arange(n) * Tc
    X = np.empty((n, x.size))
    U = np.zeros(n)
    REC = np.empty((n, 4))
    MODE = np.zeros(n, np.int8)
    pending: deque = deque()
    next_cam = 0.0
    wall = 0.0
    start = time.perf_counter()
    next_report = report_every
    lost_at = None
    for k in range(n):
        t = T[k]
        if t >= next_cam - 1e-9:
            bx = x[IX] + r.camera_noise * rng.standard_normal()
            by = x[IY] + r.camera_noise * rng.standard_normal()
            pending.append((t + camera_latency, BallObservation(t, bx, by, True)))
            next_cam += 1.0 / camera_rate
        obs = []
        while pending and pending[0][0] <= t + 1e-9:
            obs.append(pending.popleft()[1])
        cmd = ctrl.step(t, x[ITH], x[ITHD], obs or None)
        U[k] = cmd.torque
        MODE[k] = 1 if cmd.mode == ROLLING else (2 if cmd.mode == BALL_LOST else 0)
        X[k] = x
        REC[k] = model.record(x, cmd.torque)
        if k == n - 1:
            break
        if stop_after_lost is not None and MODE[k] == 2:
            lost_at = lost_at if lost_at is not None else t
            if t - lost_at >= stop_after_lost:
                n = k + 1
                break
        t0 = time.perf_counter()
        x = model.step(x, cmd.torque, Tc)
        wall += time.perf_counter() - t0
        if not np.all(np.isfinite(x)):
            n = k + 1
            break
        if report_every and t >= next_report:
            progress(f"contact closed loop: t = {t:.1f} / {duration:.1f} s "
                     f"({time.perf_counter() - start:.1f} s wall)")
            next_report += report_every
    sl = slice(0, n)
    rigid = model.rigid_state(X[sl], phi0=float(x0r[1]))
    return ContactLoopResult(t=T[sl], x=X[sl], u=U[sl], rigid=rigid, normal_force=REC[sl, 0],
                             penetration=REC[sl, 1], slip_velocity=REC[sl, 2],
                             energy=REC[sl, 3], mode=MODE[sl], wall_time=wall,
                             wall_total=time.perf_counter() - start)


def unwrap_near(phi: FloatArray, ref: FloatArray) -> FloatArray:
    """Phi shifted by whole turns to lie within pi of ref."""
    return ref + np.mod(phi - ref + math.pi, 2.0 * math.pi) - math.pi
