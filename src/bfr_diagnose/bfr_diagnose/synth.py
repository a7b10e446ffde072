"""Synthetic recordings of the stabilised rolling ball, made with the node suite's controller.

``bfr diagnose`` is proven on recordings with known hidden effects (its tests, ``bfr
blindtest``). They are made in two steps:

1. the closed loop of :mod:`bfr_sim.closed_loop`: the plant (perturbed parameters: the hidden
   effects) under the real :class:`bfr_control.controller.OrbitalController` on the nominal
   model, which sees the encoder and the camera through :class:`bfr_sim.closed_loop.
   SensorConfig` (rate, latency, noise);
2. :func:`log_recording`: the true trajectory and the camera frames written as a rig's logger
   writes them (:class:`LogConventions`): the encoder angle quantised, the logged velocity a
   derivative lagging the angle by a first-order filter, the camera fix held from its
   delivery, a camera origin offset, a log line per control step.

Seeded throughout; the same seed gives the same recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from bfr_control.controller import OrbitalController
from bfr_model.dynamics import RigidModel
from bfr_model.param_file import integer, nonnegative
from bfr_model.params import RigParams
from bfr_model.recording import Recording, ball_centre_angle
from bfr_sim.closed_loop import LoopResult, SensorConfig, orbit_initial_state, run_closed_loop

__all__ = ["LogConventions", "SynthConfig", "log_recording", "stabilised_recording"]


@dataclass(frozen=True, kw_only=True)
class LogConventions:
    """How a rig's logger writes its sensors (units in brackets).

    Attributes
    ----------
    encoder_counts : int
        Encoder counts per revolution; 0 logs the exact angle [-].
    velocity_lag : float
        Time constant of the first-order filter on the logged frame velocity [s] (0: the
        exact derivative of the quantised angle, central differences).
    camera_offset : tuple of float
        Camera origin offset added to every logged fix, world x and y [m].
    """

    encoder_counts: int = 65536
    velocity_lag: float = 0.0
    camera_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        integer("log.encoder_counts", self.encoder_counts, minimum=0)
        nonnegative("log.velocity_lag", self.velocity_lag)


@dataclass(frozen=True, kw_only=True)
class SynthConfig:
    """Settings of a synthetic closed-loop recording (units in brackets).

    Attributes
    ----------
    duration : float
        Recorded time [s].
    phase : float or None
        Contact angle at the start, on the controller's orbit [rad]; None draws it.
    camera_rate, camera_noise, camera_latency : float
        The camera the controller sees and the log records: rate [Hz], noise per axis [m],
        delay from exposure to delivery [s].
    log : LogConventions
        How the rig's logger writes the sensors.
    """

    duration: float = 20.0
    phase: float | None = None
    camera_rate: float = 200.0
    camera_noise: float = 1e-4
    camera_latency: float = 0.0
    log: LogConventions = LogConventions()


def _lagged(v: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order low-pass ``tau y' + y = v`` (exact discretisation, started at ``v[0]``)."""
    if tau <= 0.0:
        return v.copy()
    a = 1.0 - math.exp(-dt / tau)
    out = np.empty_like(v)
    acc = float(v[0])
    for i, vi in enumerate(v):
        acc += a * (float(vi) - acc)
        out[i] = acc
    return out


def log_recording(res: LoopResult, plant: RigidModel, latency: float, log: LogConventions,
                  source: str) -> Recording:
    """Write a closed-loop run as the rig's logger would (module docstring, step 2).

    Parameters
    ----------
    res : LoopResult
        The closed-loop run (true state on the control grid, camera frames).
    plant : RigidModel
        The plant of the run (the true ball position).
    latency : float
        Delay from a frame's exposure to its delivery [s]: a fix is logged from then on.
    log : LogConventions
        Encoder, velocity filter and camera offset of the logger.
    source : str
        ``meta["source"]``.

    Returns
    -------
    Recording
        The logged signals, with the truth (``*_true``) beside them.
    """
    t = res.t
    dt = float(np.median(np.diff(t)))
    if log.encoder_counts:
        q = 2.0 * math.pi / log.encoder_counts
        theta = np.round(res.x[:, 0] / q) * q
    else:
        q, theta = 0.0, res.x[:, 0].copy()
    theta_dot = _lagged(np.gradient(theta, t), dt, log.velocity_lag)
    recv = res.cam_t + latency
    k = np.searchsorted(t, recv - 1e-9, side="left")
    ok = (k < t.size) & res.cam_valid
    hold = np.full(t.size, -1)
    hold[k[ok]] = np.nonzero(ok)[0]
    hold = np.maximum.accumulate(hold)
    valid = hold >= 0
    hi = np.maximum(hold, 0)
    bx = np.where(valid, res.cam_x[hi] + log.camera_offset[0], np.nan)
    by = np.where(valid, res.cam_y[hi] + log.camera_offset[1], np.nan)
    phi_b = ball_centre_angle(theta, bx, by, near=res.x[:, 1])
    truth_ball = plant.ball_position(res.x[:, :4])
    return Recording(
        t=t, theta=theta, theta_dot=theta_dot, torque=res.u, ball_x=bx, ball_y=by,
        ball_valid=valid, phi=np.where(valid, phi_b, np.nan),
        theta_true=res.x[:, 0], theta_dot_true=res.x[:, 2], phi_true=res.x[:, 1],
        phi_dot_true=res.x[:, 3],
        ball_x_true=truth_ball[:, 0], ball_y_true=truth_ball[:, 1],
        meta={"source": source, "source_kind": "simulation", "sample_rate": 1.0 / dt,
              "theta_resolution": q, "camera_latency": latency,
              "notes": ["bfr_diagnose.synth: the node suite's controller in closed loop"]})


def stabilised_recording(plant: RigParams, controller_params: RigParams, cfg: SynthConfig,
                         rng: np.random.Generator, source: str = "synthetic") -> Recording:
    """Simulate the stabilised rolling ball and log it as the rig would.

    Parameters
    ----------
    plant : RigParams
        The simulated physics (possibly perturbed: the hidden effects).
    controller_params : RigParams
        The controller's model (the nominal parameters).
    cfg : SynthConfig
        Duration, camera, logger.
    rng : numpy.random.Generator
        Seeded source of the start phase and of the seed of every sensor noise.
    source : str
        ``meta["source"]``.

    Returns
    -------
    Recording
        With ground truth; ``meta["ball_rolled"]`` tells whether the ball kept rolling on
        the orbit throughout, ``meta["loop"]`` is the closed loop's summary.
    """
    ctrl = OrbitalController(controller_params)
    phase = float(rng.uniform(0.0, math.pi)) if cfg.phase is None else cfg.phase
    sensors = SensorConfig(camera_rate=cfg.camera_rate, camera_noise=cfg.camera_noise,
                           camera_latency=cfg.camera_latency,
                           encoder_counts=cfg.log.encoder_counts)
    res = run_closed_loop(ctrl, plant, cfg.duration, orbit_initial_state(ctrl, phase),
                          sensors, seed=int(rng.integers(2**31)))
    summary = res.summary()
    rec = log_recording(res, RigidModel(plant), cfg.camera_latency, cfg.log, source)
    rec.meta.update(ball_rolled=bool(summary["ball_rolling"]), loop=summary,
                    min_normal_force=float(np.min(res.normal_force)))
    return rec
