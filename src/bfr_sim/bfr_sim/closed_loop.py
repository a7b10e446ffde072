"""Closed-loop simulation: the controller against the rigid plant, through the rig's sensors.

The plant is :class:`bfr_model.dynamics.RigidModel` with its own parameters (the *true* physics,
possibly different from the controller's nominal model), stepped by the compiled RK4 at
``plant_dt`` (default 1 ms) with the torque held between control steps. The controller sees
only what the rig gives it:

- encoder: theta (optionally quantised to ``encoder_counts`` per revolution) and theta_dot
  (optionally with Gaussian noise), sampled at each control step;
- camera: the ball centre's world position ``(x, y)`` [m] at ``camera_rate``, exposures on the
  plant's time grid, Gaussian noise ``camera_noise`` per axis, delivered ``camera_latency``
  after the exposure with the exposure time stamp; frames can be dropped at random
  (``camera_dropout``) or blacked out over time intervals (``camera_blackouts``); a dropped
  frame arrives as ``valid = False, x = y = 0`` (as on the rig).

All noise comes from one seeded ``numpy.random.Generator``. The run records the true state,
the torque, the camera frames, the controller's estimates and mode, and the transverse
coordinates of the true state; :meth:`LoopResult.summary` says whether the ball kept rolling
(true ``phi_dot > 0`` and normal force > 0, and the controller never declared it lost), until
when, its mean phi_dot, and the RMS of the transverse coordinates over the last part of the
run.

Example::

    from bfr_model.params import load_params
    from bfr_control.controller import OrbitalController
    from bfr_sim.closed_loop import run_closed_loop, orbit_initial_state
    ctrl = OrbitalController(load_params())
    res = run_closed_loop(ctrl, load_params(), 60.0, orbit_initial_state(ctrl, 0.3, d_theta=0.05))
    print(res.summary())
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np
from bfr_control.controller import BALL_LOST, ROLLING, WAITING, OrbitalController
from bfr_control.estimator import BallObservation
from bfr_control.transverse import transverse_coordinates
from bfr_model.dynamics import RigidModel, rigid_rk4_steps, rigid_terms
from bfr_model.params import RigParams
from bfr_model.simulate import SimResult
from numpy.typing import NDArray

__all__ = ["LoopResult", "SensorConfig", "orbit_initial_state", "run_closed_loop"]

FloatArray = NDArray[np.float64]

MODE_CODES = {WAITING: 0, ROLLING: 1, BALL_LOST: 2}


@dataclass(frozen=True)
class SensorConfig:
    """What the rig's sensors give the controller in simulation.

    Attributes
    ----------
    camera_rate : float
        Camera frame rate [Hz].
    camera_latency : float
        Delay from exposure to delivery [s].
    camera_noise : float
        Standard deviation of the ball position per axis [m].
    camera_dropout : float
        Probability that a frame has no valid ball [-].
    camera_blackouts : tuple of (float, float)
        Time intervals [s] in which every frame is invalid (ball hidden).
    encoder_counts : int
        Encoder counts per revolution (0: exact theta) [-].
    encoder_rate_noise : float
        Standard deviation of the theta_dot noise [rad/s].
    """

    camera_rate: float = 200.0
    camera_latency: float = 0.005
    camera_noise: float = 1.0e-4
    camera_dropout: float = 0.0
    camera_blackouts: tuple[tuple[float, float], ...] = ()
    encoder_counts: int = 0
    encoder_rate_noise: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.camera_rate) and self.camera_rate > 0.0):
            raise ValueError(f"camera_rate must be > 0 Hz, got {self.camera_rate}")
        for name in ("camera_latency", "camera_noise", "encoder_rate_noise"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be >= 0, got {v}")
        if not 0.0 <= self.camera_dropout <= 1.0:
            raise ValueError("camera_dropout must be within [0, 1]")
        if self.encoder_counts < 0:
            raise ValueError("encoder_counts must be >= 0")


@dataclass
class LoopResult:
    """A closed-loop run, sampled at the control steps.

    Attributes
    ----------
    t : ndarray
        Control-step times [s], shape (n,).
    x : ndarray
        True state ``[theta, phi, theta_dot, phi_dot, W_in, W_diss]`` at t, shape (n, 6).
    u : ndarray
        Applied (clamped) torque command held from t on [N m].
    u_unsat : ndarray
        Torque before the clamp [N m].
    mode : ndarray
        Controller mode codes (:data:`MODE_CODES`: 0 WAITING, 1 ROLLING, 2 BALL_LOST).
    phi_hat, phi_dot_hat : ndarray
        Controller's estimates [rad, rad/s].
    transverse : ndarray
        ``[I, y, y_dot, z]`` of the true state w.r.t. the controller's orbit, shape (n, 4).
    normal_force : ndarray
        Normal force of the frame on the ball [N].
    cam_t, cam_x, cam_y, cam_valid : ndarray
        Camera frames: exposure time [s], ball position [m], validity.
    wall_time : float
        Wall-clock time of the run [s].
    info : dict
        Settings of the run (seed, rates, sensors, reasons).
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    u_unsat: FloatArray
    mode: NDArray[np.int8]
    phi_hat: FloatArray
    phi_dot_hat: FloatArray
    transverse: FloatArray
    normal_force: FloatArray
    cam_t: FloatArray
    cam_x: FloatArray
    cam_y: FloatArray
    cam_valid: NDArray[np.bool_]
    wall_time: float
    info: dict = field(default_factory=dict)

    @property
    def failure_time(self) -> float | None:
        """First time the ball stopped rolling (true phi_dot <= 0, lift-off, or declared lost)."""
        bad = (self.x[:, 3] <= 0.0) | (self.normal_force <= 0.0) | (self.mode == 2)
        idx = np.nonzero(bad)[0]
        return float(self.t[idx[0]]) if idx.size else None

    def summary(self, last_fraction: float = 0.5) -> dict:
        """JSON-ready figures; RMS values over the last ``last_fraction`` of the rolling time."""
        fail = self.failure_time
        t_end = float(self.t[-1])
        until = fail if fail is not None else t_end
        rolling = self.t <= until
        t0 = until - last_fraction * (until - float(self.t[0]))
        tail = rolling & (self.t >= t0)
        tr = self.transverse[tail]
        ctrl = self.mode == 1
        roll_ctrl = ctrl & rolling
        sat = np.abs(self.u_unsat) > self.info.get("torque_limit", np.inf)
        phi_t = self.x[rolling, 1]
        tt = self.t[rolling]
        mean_pd = float((phi_t[-1] - phi_t[0]) / (tt[-1] - tt[0])) if tt.size > 1 else math.nan
        est_tail = tail & ctrl
        err_phi = self.phi_hat[est_tail] - self.x[est_tail, 1]
        err_pd = self.phi_dot_hat[est_tail] - self.x[est_tail, 3]

        def rms(a: FloatArray) -> float:
            return float(np.sqrt(np.mean(a * a))) if a.size else math.nan

        def mx(a: FloatArray) -> float:
            return float(np.max(np.abs(a))) if a.size else math.nan

        lost_reason = self.info.get("lost_reason", "")
        return {
            "ball_rolling": fail is None,
            "rolling_until": until,
            "failure": None if fail is None else self._failure_kind(),
            "duration": t_end - float(self.t[0]),
            "mean_phi_dot": mean_pd,
            "rms_I": rms(tr[:, 0]),
            "rms_y": rms(tr[:, 1]),
            "rms_y_dot": rms(tr[:, 2]),
            "rms_z": rms(tr[:, 3]),
            "max_abs_y_tail": mx(tr[:, 1]),
            "max_abs_z_tail": mx(tr[:, 3]),
            "tail_from": t0,
            "saturation_fraction": float(np.mean(sat[roll_ctrl])) if roll_ctrl.any() else 0.0,
            "rms_torque": rms(self.u[roll_ctrl]),
            "rms_phi_error": rms(err_phi),
            "rms_phi_dot_error": rms(err_pd),
            "rolling_from": float(self.t[np.argmax(ctrl)]) if ctrl.any() else None,
            "final_mode": {0: WAITING, 1: ROLLING, 2: BALL_LOST}[int(self.mode[-1])],
            "lost_reason": lost_reason,
            "camera_frames": int(self.cam_t.size),
            "camera_valid_fraction": float(np.mean(self.cam_valid)) if self.cam_t.size else 0.0,
            "wall_time": self.wall_time,
            "real_time_factor": (t_end - float(self.t[0])) / max(self.wall_time, 1e-9),
            **{k: v for k, v in self.info.items() if k not in ("lost_reason",)},
        }

    def _failure_kind(self) -> str:
        fail = self.failure_time
        i = int(np.searchsorted(self.t, fail))
        if self.x[i, 3] <= 0.0:
            return "ball stopped or turned back"
        if self.normal_force[i] <= 0.0:
            return "ball lifted off the frame"
        return "controller declared the ball lost"

    def to_sim_result(self, model: RigidModel):  # noqa: ANN201 (bfr_model.simulate.SimResult)
        """The true trajectory as a :class:`bfr_model.simulate.SimResult` (CSV / bag writers)."""
        kin, pot = model.energy(self.x)
        return SimResult(t=self.t, x=self.x, u=self.u, kinetic=kin, potential=pot,
                         ball=model.ball_position(self.x), normal_force=self.normal_force,
                         wall_time=self.wall_time, steps=int(self.info.get("plant_steps", 0)),
                         info={"integrator": "rk4", "dt": self.info.get("plant_dt")})


def orbit_initial_state(controller: OrbitalController, phase: float = 0.0, d_theta: float = 0.0,
                        d_phi: float = 0.0, d_theta_dot: float = 0.0, d_phi_dot: float = 0.0,
                        d_z: float = 0.0) -> FloatArray:
    """A state on the controller's orbit at contact angle ``phase`` [rad], then perturbed.

    ``d_phi`` displaces the ball along the orbit (frame unchanged, so ``y = -Theta' d_phi``),
    ``d_phi_dot`` changes the ball's speed alone (``z = d_phi_dot`` and
    ``y_dot = -Theta' d_phi_dot``), ``d_z`` moves the state across the orbit in z only (the
    frame follows: ``theta_dot = Theta' phi_dot``, so ``y = y_dot = 0``), ``d_theta`` /
    ``d_theta_dot`` turn the frame (``y``, ``y_dot``).
    """
    x = np.array(controller.orbit.state(float(phase)), float)
    theta1 = float(controller.orbit.table(float(phase))[1])
    x += np.array([d_theta, d_phi, d_theta_dot + theta1 * d_z, d_phi_dot + d_z])
    return x


def run_closed_loop(controller: OrbitalController, plant_params: RigParams, duration: float,
                    x0: FloatArray | None = None, sensors: SensorConfig | None = None,
                    seed: int = 0, plant_dt: float = 1e-3, control_rate: float | None = None,
                    stop_on_failure: bool = False) -> LoopResult:
    """Simulate the closed loop (module docstring).

    Parameters
    ----------
    controller : OrbitalController
        The controller (reset before the run).
    plant_params : RigParams
        The plant's (true) physics.
    duration : float
        Simulated time [s].
    x0 : array_like, optional
        Initial ``[theta, phi, theta_dot, phi_dot]`` (default: the orbit at phi = 0).
    sensors : SensorConfig, optional
        Sensor model.
    seed : int
        Seed of all noise.
    plant_dt : float
        Plant RK4 step [s].
    control_rate : float, optional
        Control rate [Hz] (default: the controller's ``control.rate``); the control period is
        rounded to a whole number of plant steps.
    stop_on_failure : bool
        End the run when the ball stops rolling (faster sweeps).
    """
    sensors = sensors or SensorConfig()
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    rate = float(control_rate or controller.config.control.rate)
    n_sub = max(1, round(1.0 / (rate * plant_dt)))
    Tc = n_sub * plant_dt
    n_ctrl = round(duration / Tc) + 1
    rng = np.random.default_rng(seed)
    plant = RigidModel(plant_params)
    pargs = plant.kernel_args
    x = np.zeros(6)
    x[:4] = controller.orbit.state(0.0) if x0 is None else np.asarray(x0, float)
    controller.reset()
    limit = controller.torque_limit
    cam_dt = 1.0 / sensors.camera_rate
    lat = sensors.camera_latency
    sigma = sensors.camera_noise
    counts = sensors.encoder_counts
    q_enc = 2.0 * math.pi / counts if counts else 0.0
    blackouts = tuple(sensors.camera_blackouts)
    pending: deque = deque()
    next_cam = 0.0
    eps = 1e-9
    T = np.empty(n_ctrl)
    X = np.empty((n_ctrl, 6))
    U = np.zeros(n_ctrl)
    UU = np.zeros(n_ctrl)
    MODE = np.zeros(n_ctrl, np.int8)
    PH = np.full(n_ctrl, np.nan)
    PD = np.full(n_ctrl, np.nan)
    cam_t: list[float] = []
    cam_x: list[float] = []
    cam_y: list[float] = []
    cam_v: list[bool] = []
    lost_reason = ""
    start = time.perf_counter()
    n_done = n_ctrl
    plant_steps = 0
    for k in range(n_ctrl):
        t = k * Tc
        obs = []
        while pending and pending[0][0] <= t + eps:
            obs.append(pending.popleft()[1])
        theta_m = x[0] if not q_enc else q_enc * math.floor(x[0] / q_enc)
        thd_m = x[2] if not sensors.encoder_rate_noise else (
            x[2] + sensors.encoder_rate_noise * rng.standard_normal())
        cmd = controller.step(t, theta_m, thd_m, obs or None)
        u = cmd.torque
        T[k] = t
        X[k] = x
        U[k] = u
        UU[k] = cmd.torque_unsat
        MODE[k] = MODE_CODES[cmd.mode]
        PH[k] = cmd.phi
        PD[k] = cmd.phi_dot
        if cmd.mode == BALL_LOST and not lost_reason:
            lost_reason = cmd.reason
        if stop_on_failure and (x[3] <= 0.0 or cmd.mode == BALL_LOST
                                or rigid_terms(x[0], x[1], x[2], x[3], u, *pargs)[4] <= 0.0):
            n_done = k + 1
            break
        if k == n_ctrl - 1:
            break
        # plant over one control period; camera exposures on the plant grid
        j = 0
        while j < n_sub:
            tp = t + j * plant_dt
            if tp >= next_cam - eps:
                valid = rng.random() >= sensors.camera_dropout
                if valid and blackouts:
                    valid = not any(a <= tp < b for a, b in blackouts)
                if valid:
                    bx, by = plant.ball_position(x[:4]).tolist()
                    bx += sigma * rng.standard_normal()
                    by += sigma * rng.standard_normal()
                else:
                    bx = by = 0.0
                pending.append((tp + lat, BallObservation(tp, bx, by, valid)))
                cam_t.append(tp)
                cam_x.append(bx)
                cam_y.append(by)
                cam_v.append(valid)
                next_cam += cam_dt
            # steps until the next exposure or the end of the control period
            n_free = n_sub - j
            to_cam = math.ceil((next_cam - eps - tp) / plant_dt)
            m = max(1, min(n_free, to_cam))
            x = rigid_rk4_steps(x, tp, plant_dt, m, (u, *pargs))
            plant_steps += m
            j += m
        if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2])
                and math.isfinite(x[3])):
            n_done = k + 1
            lost_reason = lost_reason or "plant state became non-finite"
            break
    wall = time.perf_counter() - start
    sl = slice(0, n_done)
    tr = transverse_coordinates(controller.orbit, X[sl, :4])
    Xs = X[sl]
    FN = rigid_terms(Xs[:, 0], Xs[:, 1], Xs[:, 2], Xs[:, 3], U[sl], *pargs)[4]
    info = {
        "seed": seed,
        "plant_dt": plant_dt,
        "control_rate": 1.0 / Tc,
        "torque_limit": limit,
        "plant_steps": plant_steps,
        "sensors": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in asdict(sensors).items()},
        "x0": [float(v) for v in X[0, :4]],
        "lost_reason": lost_reason,
    }
    return LoopResult(t=T[sl], x=X[sl], u=U[sl], u_unsat=UU[sl], mode=MODE[sl], phi_hat=PH[sl],
                      phi_dot_hat=PD[sl], transverse=tr, normal_force=FN,
                      cam_t=np.array(cam_t), cam_x=np.array(cam_x), cam_y=np.array(cam_y),
                      cam_valid=np.array(cam_v, bool), wall_time=wall, info=info)
