"""Synthetic recordings of the stabilised rolling ball, made with the node suite's controller.

``bfr diagnose`` is proven on recordings with known hidden effects (its tests, ``bfr
blindtest``). They are made in two steps:

1. the closed loop: the plant (perturbed parameters: the hidden effects) under the real
   :class:`bfr_control.controller.OrbitalController` on the nominal model, which sees the
   encoder and the camera (rate, latency, noise). The plant is the rigid model
   (:func:`bfr_sim.closed_loop.run_closed_loop`) or, as a truth of another model structure,
   the force-based contact model (:class:`bfr_model.contact.ContactModel`: a free ball held
   by a compliant contact, friction-limited rolling; :func:`contact_recording`). The control
   loop runs at the log's rate: one log line per control step, as a rig logs.
2. :func:`log_recording`: the true trajectory and the camera frames written as a rig's
   logger writes them (:class:`LogConventions`), each convention a fact of one rig that the
   diagnosis must measure, not assume:

   - the encoder angle quantised (and offset by whole turns, so that a rig log's six printed
     digits quantise it further);
   - the logged velocity the rate of the quantised angle through a first-order lag;
   - the torque column off in time from the torque's action (the drive applies the
     logged command ``torque_delay`` later; the column is the applied torque's cell mean
     over ``[t_k + d, t_k+1 + d)``, so any sub-period delay is exact);
   - lines at any rate, a fix held from its delivery ``latency`` after its exposure, so any
     ratio of lines to camera fixes (a fix that a faster camera replaces before the next
     line is never logged);
   - the camera's extrinsics: ``(x, y)_logged = s Rot(alpha) (x, y)_true + c``.

:func:`bfr_model.io.rig_log.write_rig_log` and :func:`bfr_model.io.bag.write_recording_bag`
then write such a recording as real rig-log text or a ROS 2 bag (with ``stamp_fixes`` the
fixes carry their exposure times, as a ROS camera driver stamps them), so that a test reads
it back through the same readers a user's file goes through.

Seeded throughout; the same seed gives the same recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from bfr_control.controller import BALL_LOST, OrbitalController
from bfr_control.estimator import BallObservation
from bfr_model.contact import ITH, ITHD, IX, IY, ContactModel
from bfr_model.dynamics import RigidModel
from bfr_model.param_file import finite, integer, nonnegative, positive
from bfr_model.params import RigParams
from bfr_model.recording import Recording, ball_centre_angle
from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop
from numpy.typing import NDArray

__all__ = ["LogConventions", "SynthConfig", "TrueRun", "contact_recording",
           "held_frame_recording", "log_recording", "stabilised_recording"]

FloatArray = NDArray[np.float64]

#: Largest plant step of the rigid closed loop [s] (the control period is divided evenly).
_PLANT_DT_MAX = 1e-3


@dataclass(frozen=True, kw_only=True)
class LogConventions:
    """How a rig's logger writes its sensors (units in brackets; module docstring).

    Attributes
    ----------
    encoder_counts : int
        Encoder counts per revolution; 0 logs the exact angle [-].
    theta_turns : int
        Whole turns added to the logged angle [-] (a rig's angle accumulates over runs).
    velocity_lag : float
        Time constant of the first-order filter on the logged frame velocity [s] (0: the
        exact rate of the quantised angle, central differences).
    torque_delay : float
        The drive applies a logged torque this long after its line [s] (negative: before).
    log_rate : float or None
        Lines per second [Hz] = the control loop's rate (None: the controller's own).
    camera_offset : tuple of float
        ``c``: camera origin offset added to every logged fix, world x and y [m].
    camera_scale : float
        ``s``: scale of the logged fixes [-].
    camera_rotation : float
        ``alpha``: rotation of the logged fixes about the shaft axis [rad].
    stamp_fixes : bool
        Keep each fix's exposure time as ``extra["ball_stamp"]`` (a ROS camera driver's
        header stamp); otherwise a fix's only time is its line's (a rig log).
    """

    encoder_counts: int = 65536
    theta_turns: int = 0
    velocity_lag: float = 0.0
    torque_delay: float = 0.0
    log_rate: float | None = None
    camera_offset: tuple[float, float] = (0.0, 0.0)
    camera_scale: float = 1.0
    camera_rotation: float = 0.0
    stamp_fixes: bool = False

    def __post_init__(self) -> None:
        integer("log.encoder_counts", self.encoder_counts, minimum=0)
        integer("log.theta_turns", self.theta_turns)
        nonnegative("log.velocity_lag", self.velocity_lag)
        finite("log.torque_delay", self.torque_delay)
        if self.log_rate is not None:
            positive("log.log_rate", self.log_rate)
        positive("log.camera_scale", self.camera_scale)
        finite("log.camera_rotation", self.camera_rotation)
        for v in self.camera_offset:
            finite("log.camera_offset", v)


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


@dataclass(frozen=True, kw_only=True, eq=False)
class TrueRun:
    """What a closed loop really did, at its control steps (one log line each).

    Attributes
    ----------
    t : ndarray
        Control-step times [s].
    x : ndarray
        True rigid(-equivalent) state ``[theta, phi, theta_dot, phi_dot]``, shape (n, 4).
    u : ndarray
        Torque applied from t on [N m] (held over the period).
    cam_t, cam_x, cam_y, cam_valid : ndarray
        Camera frames: exposure time [s], measured ball centre (with noise) [m], validity.
    ball_xy : ndarray
        True ball centre at t [m], shape (n, 2).
    summary : dict
        ``ball_rolling`` and the loop's figures.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    cam_t: FloatArray
    cam_x: FloatArray
    cam_y: FloatArray
    cam_valid: NDArray[np.bool_]
    ball_xy: FloatArray
    summary: dict


def _lagged(v: FloatArray, dt: float, tau: float) -> FloatArray:
    """First-order low-pass ``tau y' + y = v``, started at ``v[0]``.

    Exact for ``v`` linear between its samples (first-order hold)::

        y_i = e y_{i-1} + (1 - e) v_{i-1} + (1 - tau (1 - e) / dt) (v_i - v_{i-1}),
        e = exp(-dt / tau),

    so that a ramp comes out exactly ``tau`` late: the lag the diagnosis measures
    (:func:`bfr_model.io.timing.velocity_lag`) is the drawn ``tau``. (The zero-order-hold
    form ``y_i = y_{i-1} + (1 - e)(v_i - y_{i-1})`` treats ``v_i`` as held over the
    interval before it and is only ``tau - dt / 2`` late: at a 300 Hz log 1.7 ms less.)
    """
    if tau <= 0.0:
        return v.copy()
    e = math.exp(-dt / tau)
    b = 1.0 - tau * (1.0 - e) / dt
    out = np.empty_like(v)
    acc = float(v[0])
    prev = float(v[0])
    for i, x in enumerate(v):
        vi = float(x)
        acc = e * acc + (1.0 - e) * prev + b * (vi - prev)
        prev = vi
        out[i] = acc
    return out


def _shifted_torque(t: FloatArray, u: FloatArray, delay: float) -> FloatArray:
    """The torque column of a log whose drive applies each line ``delay`` later.

    Line k logs the command the drive applies over ``[t_k + d, t_k+1 + d)``: the mean of
    the applied (held) torque ``u`` over that interval, exact for any sub-period ``d``
    (the integral of a held signal is piecewise linear).
    """
    if delay == 0.0:
        return u.copy()
    cum = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(t))])
    period = float(np.median(np.diff(t)))
    edges = np.concatenate([t, [t[-1] + period]]) + delay
    # the held torque continues with its last (first) value beyond the run
    ext_t = np.concatenate([[t[0] - 10.0], t, [t[-1] + 10.0]])
    ext_c = np.concatenate([[cum[0] - 10.0 * u[0]], cum, [cum[-1] + 10.0 * u[-1]]])
    integ = np.interp(edges, ext_t, ext_c)
    return np.diff(integ) / np.diff(edges)


def log_recording(run: TrueRun, latency: float, log: LogConventions, source: str,
                  truth_phi: FloatArray | None = None) -> Recording:
    """Write a closed-loop run as the rig's logger would (module docstring, step 2).

    Parameters
    ----------
    run : TrueRun
        The closed-loop run (true state on the control grid, camera frames).
    latency : float
        Delay from a frame's exposure to its delivery [s]: a fix is logged from then on.
    log : LogConventions
        The logger's conventions.
    source : str
        ``meta["source"]``.
    truth_phi : ndarray, optional
        Contact angle of the truth (default: ``run.x[:, 1]``).

    Returns
    -------
    Recording
        The logged signals, with the truth (``*_true``) beside them and the conventions
        used in ``meta["log_conventions"]`` (never read by the diagnosis).
    """
    t = run.t
    dt = float(np.median(np.diff(t)))
    turns = 2.0 * math.pi * log.theta_turns
    if log.encoder_counts:
        q = 2.0 * math.pi / log.encoder_counts
        theta = np.round((run.x[:, 0] + turns) / q) * q
    else:
        q, theta = 0.0, run.x[:, 0] + turns
    theta_dot = _lagged(np.gradient(theta, t), dt, log.velocity_lag)
    recv = run.cam_t + latency
    k = np.searchsorted(t, recv - 1e-9, side="left")
    ok = (k < t.size) & run.cam_valid
    hold = np.full(t.size, -1)
    hold[k[ok]] = np.nonzero(ok)[0]
    hold = np.maximum.accumulate(hold)
    valid = hold >= 0
    hi = np.maximum(hold, 0)
    ca, sa = math.cos(log.camera_rotation), math.sin(log.camera_rotation)
    s = log.camera_scale
    cx, cy = run.cam_x[hi], run.cam_y[hi]
    bx = np.where(valid, s * (ca * cx - sa * cy) + log.camera_offset[0], np.nan)
    by = np.where(valid, s * (sa * cx + ca * cy) + log.camera_offset[1], np.nan)
    phi_t = run.x[:, 1] if truth_phi is None else truth_phi
    phi_b = ball_centre_angle(theta, bx, by, near=phi_t + turns)
    extra = {}
    if log.stamp_fixes:
        extra["ball_stamp"] = np.where(valid, run.cam_t[hi], np.nan)
    conv = {k: (list(v) if isinstance(v, tuple) else v) for k, v in log.__dict__.items()}
    return Recording(
        t=t, theta=theta, theta_dot=theta_dot, torque=_shifted_torque(t, run.u,
                                                                        log.torque_delay),
        ball_x=bx, ball_y=by, ball_valid=valid, phi=np.where(valid, phi_b, np.nan),
        theta_true=run.x[:, 0] + turns, theta_dot_true=run.x[:, 2], phi_true=phi_t + turns,
        phi_dot_true=run.x[:, 3], ball_x_true=run.ball_xy[:, 0], ball_y_true=run.ball_xy[:, 1],
        extra=extra,
        meta={"source": source, "source_kind": "simulation", "sample_rate": 1.0 / dt,
              "theta_resolution": q, "camera_latency": latency,
              "log_conventions": {**conv, "camera_latency": latency},
              "notes": ["bfr_diagnose.synth: the node suite's controller in closed loop"]})


def _loop_grid(ctrl: OrbitalController, log: LogConventions) -> tuple[float, float]:
    """(control rate [Hz], plant step [s]): the log's rate, the period divided evenly."""
    rate = float(log.log_rate or ctrl.config.control.rate)
    period = 1.0 / rate
    return rate, period / math.ceil(period / _PLANT_DT_MAX - 1e-9)


def stabilised_recording(plant: RigParams, controller_params: RigParams, cfg: SynthConfig,
                         rng: np.random.Generator, source: str = "synthetic") -> Recording:
    """Simulate the stabilised rolling ball on the rigid plant and log it as the rig would.

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
    rate, plant_dt = _loop_grid(ctrl, cfg.log)
    res = run_closed_loop(ctrl, plant, cfg.duration, orbit_initial_state(ctrl, phase),
                          sensors, seed=int(rng.integers(2**31)), plant_dt=plant_dt,
                          control_rate=rate)
    summary = res.summary()
    model = RigidModel(plant)
    run = TrueRun(t=res.t, x=res.x[:, :4], u=res.u, cam_t=res.cam_t, cam_x=res.cam_x,
                  cam_y=res.cam_y, cam_valid=res.cam_valid,
                  ball_xy=model.ball_position(res.x[:, :4]), summary=summary)
    rec = log_recording(run, cfg.camera_latency, cfg.log, source)
    rec.meta.update(ball_rolled=bool(summary["ball_rolling"]), loop=summary,
                    min_normal_force=float(np.min(res.normal_force)), plant_model="rigid")
    return rec


def _contact_loop(ctrl: OrbitalController, plant: RigParams, cfg: SynthConfig, phase: float,
                  rng: np.random.Generator) -> tuple[TrueRun, ContactModel]:
    """The closed loop with the contact model as the plant (see :func:`contact_recording`).

    Control steps at the log's rate; the contact model is stepped between them and stopped
    exactly at each camera exposure (its own step is ``contact.time_step``); the camera
    delivers a frame ``camera_latency`` after its exposure, with the exposure's time.
    """
    cm = ContactModel(plant)
    rate, _ = _loop_grid(ctrl, cfg.log)
    period = 1.0 / rate
    n = round(cfg.duration * rate) + 1
    x = cm.state_from_rigid(orbit_initial_state(ctrl, phase))
    q = 2.0 * math.pi / cfg.log.encoder_counts if cfg.log.encoder_counts else 0.0
    ctrl.reset()
    cam_period = 1.0 / cfg.camera_rate
    next_exp = 0.0
    pending: list[tuple[float, BallObservation]] = []
    ts, xs, us, cam = np.arange(n) * period, np.empty((n, x.size)), np.zeros(n), []
    lost = False
    for k in range(n):
        t = ts[k]
        obs = [o for due, o in pending if due <= t + 1e-9]
        pending = [(due, o) for due, o in pending if due > t + 1e-9]
        th_m = x[ITH] if not q else q * math.floor(x[ITH] / q)
        cmd = ctrl.step(t, th_m, x[ITHD], obs or None)
        lost |= cmd.mode == BALL_LOST
        xs[k], us[k] = x, cmd.torque
        if k == n - 1:
            break
        tc = t
        while tc < t + period - 1e-12:
            if next_exp <= tc + 1e-12:  # a frame now
                bx = x[IX] + cfg.camera_noise * rng.standard_normal()
                by = x[IY] + cfg.camera_noise * rng.standard_normal()
                cam.append((tc, bx, by))
                pending.append((tc + cfg.camera_latency, BallObservation(tc, bx, by, True)))
                next_exp += cam_period
            h = min(t + period, next_exp) - tc
            x = cm.step(x, cmd.torque, h)
            tc += h
    rigid = cm.rigid_state(xs, phi0=float(orbit_initial_state(ctrl, phase)[1]))
    fn_ok = True
    for i in range(0, n, max(n // 200, 1)):  # in contact along the run (sampled)
        cm.reset(xs[i], phi_guess=float(rigid[i, 1]))
        fn_ok &= cm.diagnostics(xs[i], us[i])["normal_force"] > 0.0
    cam_a = np.array(cam, float).reshape(-1, 3)
    rolled = bool(not lost and fn_ok and np.all(rigid[:, 3] > 0.0))
    summary = {"ball_rolling": rolled,
               "rms_torque": float(np.sqrt(np.mean(us ** 2))),
               "mean_phi_dot": float((rigid[-1, 1] - rigid[0, 1]) / (ts[-1] - ts[0])),
               "plant": "contact model", "control_rate": rate}
    run = TrueRun(t=ts, x=rigid, u=us, cam_t=cam_a[:, 0], cam_x=cam_a[:, 1],
                  cam_y=cam_a[:, 2], cam_valid=np.ones(cam_a.shape[0], bool),
                  ball_xy=xs[:, [IX, IY]].copy(), summary=summary)
    return run, cm


def contact_recording(plant: RigParams, controller_params: RigParams, cfg: SynthConfig,
                      rng: np.random.Generator, source: str = "synthetic (contact model)"
                      ) -> Recording:
    """A recording whose truth is the force-based contact model (another model structure).

    The ball is a free planar body held to the frame by a compliant Hunt-Crossley contact
    with friction-limited rolling (:mod:`bfr_model.contact`); the controller is the same as
    in :func:`stabilised_recording` and the log the same (:func:`log_recording`). The
    diagnosis's rigid model is then not the truth's structure: what it may find are the
    effects present in the plant, and it must not invent others from the difference.

    Parameters
    ----------
    plant : RigParams
        The simulated physics (``contact.*`` included).
    controller_params : RigParams
        The controller's model.
    cfg : SynthConfig
        Duration, camera, logger.
    rng : numpy.random.Generator
        Seeded source of the phase and the camera noise.
    source : str
        ``meta["source"]``.

    Returns
    -------
    Recording
        ``meta["ball_rolled"]`` tells whether the ball kept rolling in contact.
    """
    ctrl = OrbitalController(controller_params)
    phase = float(rng.uniform(0.0, math.pi)) if cfg.phase is None else cfg.phase
    run, _ = _contact_loop(ctrl, plant, cfg, phase, rng)
    rec = log_recording(run, cfg.camera_latency, cfg.log, source)
    rec.meta.update(ball_rolled=bool(run.summary["ball_rolling"]), loop=run.summary,
                    plant_model="contact")
    return rec


def held_frame_recording(plant: RigParams, cfg: SynthConfig, rng: np.random.Generator, *,
                         theta: float = 0.0, phi0: float = 0.35, phi_dot0: float = 0.0,
                         source: str = "synthetic (frame held)") -> Recording:
    """The frame held still, the ball rolling freely on it and settling.

    A rig's frame-held run, like the NTNU ``rolling_data``.

    The rigid plant with the frame's inertia made enormous (the frame does not move; the
    ball's torque on it turns it by nanoradians), no torque, the ball started at ``phi0``
    with ``phi_dot0``; the camera (rate, latency, noise of ``cfg``) and the logger
    (:class:`LogConventions`) as in :func:`stabilised_recording`, one log line per
    millisecond unless ``cfg.log.log_rate`` says otherwise.

    Returns
    -------
    Recording
        With ground truth; the frame's angle is exactly ``theta`` in the truth.
    """
    held = plant.replace(**{"frame.inertia": 1e6})
    model = RigidModel(held)
    rate = float(cfg.log.log_rate or 1000.0)
    dt = 1.0 / rate / math.ceil(1.0 / rate / _PLANT_DT_MAX - 1e-9)
    n_sub = round(1.0 / rate / dt)
    n = round(cfg.duration * rate) + 1
    x = np.array([theta, phi0, 0.0, phi_dot0, 0.0, 0.0])
    xs = np.empty((n, 4))
    fine = [x[:4].copy()]
    for k in range(n):
        xs[k] = x[:4]
        if k < n - 1:
            for _ in range(n_sub):
                x = model.step(x, 0.0, dt, 1)
                fine.append(x[:4].copy())
    t = np.arange(n) / rate
    tf = np.arange(len(fine)) * dt
    xf = np.array(fine)
    cam_t = np.arange(0.0, t[-1], 1.0 / cfg.camera_rate)
    pos = model.ball_position(np.column_stack([np.interp(cam_t, tf, xf[:, i])
                                               for i in range(4)]))
    noise = cfg.camera_noise * rng.standard_normal(pos.shape)
    run = TrueRun(t=t, x=xs, u=np.zeros(n), cam_t=cam_t, cam_x=pos[:, 0] + noise[:, 0],
                  cam_y=pos[:, 1] + noise[:, 1], cam_valid=np.ones(cam_t.size, bool),
                  ball_xy=model.ball_position(xs), summary={"ball_rolling": True})
    rec = log_recording(run, cfg.camera_latency, cfg.log, source)
    rec.meta.update(ball_rolled=True, loop={"ball_rolling": True}, plant_model="rigid",
                    frame_held=True)
    return rec
