"""Synthetic recordings of a stabilised rolling ball: the noise-only null and test data.

``bfr diagnose`` needs recordings of the *nominal* model under the same kind of excitation
as the recording it explains (the null distribution of its fit statistics), and its tests
need recordings with known hidden effects. The controller of the node suite lives in
``bfr_control`` (later in the dependency order than ``bfr_sim``), so this module carries a
small stabilising controller of its own, enough to keep the ball rolling:

- virtual holonomic constraint ``theta = Theta(phi)`` chosen so that the track's tangent at
  the contact point has the world inclination ``atan(c sin 2 phi) + delta``
  (rig-brief.md): ``Theta(phi) = phi - A(phi) + atan(c sin 2 phi) + delta``, with
  ``A(phi) = ang(t(phi)) + phi`` the periodic part of the tangent's angle in the frame;
- partial feedback linearisation of ``y = theta - Theta(phi)`` on the controller's model:
  ``y_ddot = w = -k_p y - k_d y_dot``; from row 2,
  ``phi_ddot = -(c2 + G2 + M12 theta_ddot) / M22``, so
  ``theta_ddot (1 + Theta' M12 / M22) = w + Theta'' phi_dot^2 - Theta' (c2 + G2) / M22`` and
  ``u = M11 theta_ddot + M12 phi_ddot + c1 + G1`` (clamped to the torque limit);
- a slow pump ``delta = clip(-k_e (phidot_ref - phidot_avg), +-delta_max)`` keeps the mean
  rolling speed near ``phidot_ref`` (tilting the track forward accelerates the ball);
- the first ``warmup`` seconds (the start-up transient from the initial state) are simulated
  and dropped: in that transient the ball came close to lifting off at the wings.

The camera model: a fix every 5-6 ms holding the world ball centre at ``t_fix - latency``
plus an origin offset and Gaussian noise [m]; the encoder quantises theta; theta_dot is a
first-order filtered difference. Seeded :class:`numpy.random.Generator` throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bfr_sim.dynamics import RigidModel, mass_terms
from bfr_sim.geometry import offset_kernel
from bfr_sim.params import RigParams
from bfr_sim.recording import Recording, ball_centre_angle

__all__ = ["SynthConfig", "VhcController", "stabilised_recording"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SynthConfig:
    """Settings of a synthetic closed-loop recording (units in brackets)."""

    duration: float = 20.0          # [s]
    control_dt: float = 1e-3        # [s] control period (torque held)
    substeps: int = 2               # RK4 steps per control period
    camera_noise: float = 1e-4      # [m] std of each camera coordinate
    camera_latency: float = 0.0     # [s] age of the image at the fix
    camera_offset: tuple[float, float] = (0.0, 0.0)  # [m] added to every fix (origin offset)
    fix_intervals: tuple[int, ...] = (5, 6)  # [control periods] between fixes, cycled
    encoder_counts: int = 65536     # [counts/rev] theta quantisation
    phidot_ref: float = 2.4         # [rad/s] target mean rolling speed
    tilt_c: float = 0.03            # [-] constraint's tilt amplitude c
    kp: float = 400.0               # [1/s^2]
    kd: float = 40.0                # [1/s]
    pump_gain: float = 0.05         # [rad s/rad]
    pump_max: float = 0.04          # [rad]
    excitation: float = 0.0         # [N m] amplitude of a multisine added to the command
    warmup: float = 1.0             # [s] simulated first and dropped (start-up transient)


class VhcController:
    """Virtual-constraint PFL controller on a (nominal) model (module docstring)."""

    def __init__(self, params: RigParams, cfg: SynthConfig, n_grid: int = 4096) -> None:
        self.model = RigidModel(params)
        self.cfg = cfg
        self.limit = params.actuator.torque_limit
        phi = np.linspace(0.0, 2.0 * np.pi, n_grid, endpoint=False)
        tang = self.model.curve.tangent(phi)
        ang = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
        a = ang + phi
        a -= 2.0 * np.pi * np.round(a[0] / (2.0 * np.pi))
        k = np.fft.rfftfreq(n_grid, d=1.0 / n_grid)
        fa = np.fft.rfft(a)
        self._grid = phi
        self._a = a
        self._a1 = np.fft.irfft(1j * k * fa, n_grid)
        self._a2 = np.fft.irfft(-(k**2) * fa, n_grid)
        self.delta = 0.0
        self._phidot_avg = cfg.phidot_ref

    def constraint(self, phi: float) -> tuple[float, float, float]:
        """Theta(phi), Theta'(phi), Theta''(phi) [rad, -, 1/rad]."""
        c = self.cfg.tilt_c
        pm = phi % (2.0 * np.pi)
        gx = np.append(self._grid, 2.0 * np.pi)
        a = np.interp(pm, gx, np.append(self._a, self._a[0]))
        a1 = np.interp(pm, gx, np.append(self._a1, self._a1[0]))
        a2 = np.interp(pm, gx, np.append(self._a2, self._a2[0]))
        s2, c2 = math.sin(2 * phi), math.cos(2 * phi)
        den = 1.0 + (c * s2) ** 2
        tilt = math.atan(c * s2)
        tilt1 = 2.0 * c * c2 / den
        tilt2 = (-4.0 * c * s2 * den - 2.0 * c * c2 * 2.0 * c * c * s2 * 2.0 * c2) / den**2
        return (phi - a + tilt + self.delta, 1.0 - a1 + tilt1, -a2 + tilt2)

    def __call__(self, x: FloatArray, dt: float) -> float:
        """Command [N m] for the state ``x = [theta, phi, theta_dot, phi_dot]``."""
        cfg = self.cfg
        th, ph, thd, phd = x[:4]
        alpha = dt / 2.0
        self._phidot_avg += alpha * (phd - self._phidot_avg)
        self.delta = float(np.clip(-cfg.pump_gain * (cfg.phidot_ref - self._phidot_avg),
                                   -cfg.pump_max, cfg.pump_max))
        big_t, t1, t2 = self.constraint(ph)
        y = th - big_t
        yd = thd - t1 * phd
        w = -cfg.kp * y - cfg.kd * yd
        P, *g = self.model.kernel_args
        m11, m12, m22, d11, d12, d22 = mass_terms(ph, P, *g)
        px, py, p1x, p1y = offset_kernel(ph, *g)[:4]
        mg = P[0] * P[4]
        st, ct = math.sin(th), math.cos(th)
        g1 = mg * (ct * px - st * py)
        g2 = mg * (st * p1x + ct * p1y)
        c1 = d11 * thd * phd + d12 * phd * phd
        c2 = -0.5 * d11 * thd * thd + 0.5 * d22 * phd * phd
        thdd = (w + t2 * phd * phd - t1 * (c2 + g2) / m22) / (1.0 + t1 * m12 / m22)
        phdd = -(c2 + g2 + m12 * thdd) / m22
        u = m11 * thdd + m12 * phdd + c1 + g1
        return float(np.clip(u, -self.limit, self.limit))


def stabilised_recording(plant: RigParams, controller_params: RigParams, cfg: SynthConfig,
                         rng: np.random.Generator, source: str = "synthetic") -> Recording:
    """Simulate the stabilised rolling ball and record it as the rig would.

    Parameters
    ----------
    plant : RigParams
        The simulated physics (possibly perturbed: the hidden effects).
    controller_params : RigParams
        The controller's model (the nominal parameters).
    cfg : SynthConfig
        Durations, rates, noise, latency, gains.
    rng : numpy.random.Generator
        Seeded source of the camera noise, fix phase and initial speed jitter.
    source : str
        ``meta["source"]``.

    Returns
    -------
    Recording
        With ground truth; ``meta["ball_rolled"]`` tells whether the ball kept rolling on
        the frame (normal force > 0 and mean speed > 1 rad/s in every second).
    """
    model = RigidModel(plant)
    ctrl = VhcController(controller_params, cfg)
    n_warm = round(cfg.warmup / cfg.control_dt)
    n = round(cfg.duration / cfg.control_dt) + n_warm
    dt = cfg.control_dt
    h = dt / cfg.substeps
    phd0 = cfg.phidot_ref * (1.0 + 0.05 * rng.standard_normal())
    ph0 = float(rng.uniform(0.0, 2.0 * np.pi))
    th0, t1, _ = ctrl.constraint(ph0)
    x = np.array([th0, ph0, t1 * phd0, phd0, 0.0, 0.0])
    xs = np.empty((n + 1, 4))
    us = np.empty(n + 1)
    xs[0] = x[:4]
    freqs = np.array([0.7, 1.9, 3.1, 5.3])
    phases = rng.uniform(0.0, 2.0 * np.pi, freqs.size)
    for i in range(n):
        u = ctrl(x, dt)
        if cfg.excitation:
            u = float(np.clip(u + cfg.excitation * np.mean(
                np.sin(2 * np.pi * freqs * i * dt + phases)), -ctrl.limit, ctrl.limit))
        us[i] = u
        x = model.step(x, u, h, cfg.substeps)
        xs[i + 1] = x[:4]
        if not np.all(np.isfinite(x)):
            xs[i + 1:] = np.nan
            us[i + 1:] = 0.0
            break
    us[n] = us[n - 1]
    # drop the start-up transient (initial state put on the constraint, speed jittered)
    xs = xs[n_warm:]
    us = us[n_warm:]
    n -= n_warm
    t = np.arange(n + 1) * dt
    fn = model.normal_force(xs, us) if np.all(np.isfinite(xs)) else np.array([-1.0])
    ball = model.ball_position(np.nan_to_num(xs))
    per_s = round(1.0 / dt)
    speeds = [np.mean(xs[k:k + per_s, 3]) for k in range(0, n - per_s + 1, per_s)]
    rolled = bool(np.all(np.isfinite(xs)) and np.min(fn) > 0.0 and min(speeds) > 1.0)
    # camera: fixes on the control grid, world position at t - latency, noise
    steps = np.array(cfg.fix_intervals, int)
    first = int(rng.integers(0, int(steps.max())))
    fix_idx = first + np.concatenate([[0], np.cumsum(np.resize(steps, n))])
    fix_idx = fix_idx[fix_idx <= n]
    t_img = t[fix_idx] - cfg.camera_latency
    bx_f = (np.interp(t_img, t, ball[:, 0]) + cfg.camera_offset[0]
            + cfg.camera_noise * rng.standard_normal(fix_idx.size))
    by_f = (np.interp(t_img, t, ball[:, 1]) + cfg.camera_offset[1]
            + cfg.camera_noise * rng.standard_normal(fix_idx.size))
    hold = np.maximum(np.searchsorted(fix_idx, np.arange(n + 1), side="right") - 1, 0)
    valid = np.arange(n + 1) >= fix_idx[0]
    bx = bx_f[hold]
    by = by_f[hold]
    q = 2.0 * np.pi / cfg.encoder_counts
    theta_m = np.round(xs[:, 0] / q) * q
    thd_raw = np.gradient(theta_m, dt)
    a = dt / (dt + 1.0 / (2 * np.pi * 150.0))
    thd_m = np.empty_like(thd_raw)
    acc = thd_raw[0]
    for i in range(n + 1):
        acc += a * (thd_raw[i] - acc)
        thd_m[i] = acc
    phi_ball = ball_centre_angle(theta_m, bx, by, near=xs[:, 1])
    rec = Recording(
        t=t, theta=theta_m, theta_dot=thd_m, torque=us, ball_x=bx, ball_y=by,
        ball_valid=valid, phi=phi_ball, theta_true=xs[:, 0], theta_dot_true=xs[:, 2],
        phi_true=xs[:, 1], phi_dot_true=xs[:, 3], ball_x_true=ball[:, 0],
        ball_y_true=ball[:, 1],
        meta={"source": source, "source_kind": "simulation",
              "sample_rate": 1.0 / dt, "theta_resolution": q,
              "camera_noise": cfg.camera_noise, "camera_latency": cfg.camera_latency,
              "rig_conventions": {"dtheta_delay_s": 1.0 / (2 * np.pi * 150.0)},
              "ball_rolled": rolled, "min_normal_force": float(np.min(fn)),
              "notes": ["bfr_sim.diagnose.synth: VHC + PFL stabilised rolling"]})
    return rec
