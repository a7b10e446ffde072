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
  frame arrives as ``valid = False, x = y = 0`` (as on the rig);
- actuation: the torque computed at a control step acts ``actuation_delay`` later (on the
  plant grid; the previous torque acts meanwhile), as on hardware, where camera
  processing, transport and the drive's update separate the sample from the torque. The
  controller is told the delay (``lead``, as the controller node measures it) unless
  ``predict_delay`` is off.

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
from bfr_control.controller import BALL_LOST, ROLLING, WAITING, Command, OrbitalController
from bfr_control.estimator import BallObservation
from bfr_control.transverse import transverse_coordinates
from bfr_model.dynamics import RigidModel, rigid_rk4_steps, rigid_terms
from bfr_model.param_file import in_range, integer, nonnegative, positive
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
    camera_stamp_jitter : float
        Standard deviation of the error of a frame's exposure stamp [s] (a software stamp's
        jitter; 0: the stamp is the exposure time).
    encoder_counts : int
        Encoder counts per revolution (0: exact theta) [-].
    encoder_rate_noise : float
        Standard deviation of the theta_dot noise [rad/s].
    actuation_delay : float
        From the control step's encoder sample to the moment its torque acts [s].
    """

    camera_rate: float = 200.0
    camera_latency: float = 0.005
    camera_noise: float = 1.0e-4
    camera_dropout: float = 0.0
    camera_blackouts: tuple[tuple[float, float], ...] = ()
    camera_stamp_jitter: float = 0.0
    encoder_counts: int = 0
    encoder_rate_noise: float = 0.0
    actuation_delay: float = 0.0

    def __post_init__(self) -> None:
        positive("sensors.camera_rate", self.camera_rate)
        for name in ("camera_latency", "camera_noise", "camera_stamp_jitter",
                     "encoder_rate_noise", "actuation_delay"):
            nonnegative(f"sensors.{name}", getattr(self, name))
        in_range("sensors.camera_dropout", self.camera_dropout, 0.0, 1.0)
        integer("sensors.encoder_counts", self.encoder_counts, minimum=0)


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


#: Tolerance of time comparisons on the plant grid [s].
_EPS = 1e-9


# -- the pieces of a run -----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class _ControlGrid:
    """The control steps of a run, a whole number of plant steps apart.

    Attributes
    ----------
    plant_dt : float
        Plant RK4 step [s].
    n_sub : int
        Plant steps per control period [-].
    n_steps : int
        Control steps of the run, both ends included [-].
    """

    plant_dt: float
    n_sub: int
    n_steps: int

    @classmethod
    def of(cls, duration: float, rate: float, plant_dt: float) -> _ControlGrid:
        """The grid of ``duration`` [s] at about ``rate`` [Hz] on steps of ``plant_dt`` [s]."""
        n_sub = max(1, round(1.0 / (rate * plant_dt)))
        return cls(plant_dt=plant_dt, n_sub=n_sub,
                   n_steps=round(duration / (n_sub * plant_dt)) + 1)

    @property
    def period(self) -> float:
        """Control period [s]."""
        return self.n_sub * self.plant_dt


@dataclass(frozen=True, kw_only=True)
class _Encoder:
    """The frame encoder as the controller reads it.

    Attributes
    ----------
    quantum : float
        Angle of one count [rad] (0: exact theta).
    rate_noise : float
        Standard deviation of the theta_dot noise [rad/s].
    rng : numpy.random.Generator
        The run's noise source.
    """

    quantum: float
    rate_noise: float
    rng: np.random.Generator

    @classmethod
    def of(cls, sensors: SensorConfig, rng: np.random.Generator) -> _Encoder:
        """The encoder of ``sensors``."""
        counts = sensors.encoder_counts
        return cls(quantum=2.0 * math.pi / counts if counts else 0.0,
                   rate_noise=sensors.encoder_rate_noise, rng=rng)

    def read(self, x: FloatArray) -> tuple[float, float]:
        """Measured ``(theta, theta_dot)`` of the true state ``x`` (draws the rate noise)."""
        q = self.quantum
        theta = x[0] if not q else q * math.floor(x[0] / q)
        theta_dot = x[2] if not self.rate_noise else (
            x[2] + self.rate_noise * self.rng.standard_normal())
        return theta, theta_dot


class _Camera:
    """The camera: exposures on the plant grid, noise, dropouts, blackouts, latency.

    A frame exposed at ``tp`` is delivered at ``tp + camera_latency`` with the exposure's time
    stamp (off by ``camera_stamp_jitter``, Gaussian, when there is one); every frame is also
    recorded (``t`` its true exposure, ``x``, ``y``, ``valid``) for the result.

    Parameters
    ----------
    sensors : SensorConfig
        Rate, latency, noise, dropout and blackouts.
    plant : RigidModel
        The plant (the true ball position).
    rng : numpy.random.Generator
        The run's noise source.
    """

    def __init__(self, sensors: SensorConfig, plant: RigidModel,
                 rng: np.random.Generator) -> None:
        self.period = 1.0 / sensors.camera_rate
        self.latency = sensors.camera_latency
        self.noise = sensors.camera_noise
        self.dropout = sensors.camera_dropout
        self.blackouts = tuple(sensors.camera_blackouts)
        self.stamp_jitter = sensors.camera_stamp_jitter
        self.plant = plant
        self.rng = rng
        self.pending: deque[tuple[float, BallObservation]] = deque()
        self.next_exposure = 0.0
        self.t: list[float] = []
        self.x: list[float] = []
        self.y: list[float] = []
        self.valid: list[bool] = []

    def delivered(self, t: float) -> list[BallObservation]:
        """The frames delivered by time ``t`` [s] and not yet handed out, oldest first."""
        obs = []
        while self.pending and self.pending[0][0] <= t + _EPS:
            obs.append(self.pending.popleft()[1])
        return obs

    def expose_if_due(self, tp: float, x: FloatArray) -> None:
        """Take a frame of state ``x`` at plant time ``tp`` [s] if an exposure is due."""
        if tp < self.next_exposure - _EPS:
            return
        valid = self.rng.random() >= self.dropout
        if valid and self.blackouts:
            valid = not any(a <= tp < b for a, b in self.blackouts)
        if valid:
            bx, by = self.plant.ball_position(x[:4]).tolist()
            bx += self.noise * self.rng.standard_normal()
            by += self.noise * self.rng.standard_normal()
        else:
            bx = by = 0.0
        # the stamp: the exposure time, off by the stamp's jitter (drawn only when there is
        # one, so that a run without it draws the same numbers as before)
        stamp = tp + self.stamp_jitter * self.rng.standard_normal() if self.stamp_jitter else tp
        self.pending.append((tp + self.latency, BallObservation(stamp, bx, by, valid)))
        self.t.append(tp)
        self.x.append(bx)
        self.y.append(by)
        self.valid.append(valid)
        self.next_exposure += self.period

    def steps_to_exposure(self, tp: float, plant_dt: float) -> int:
        """Plant steps of ``plant_dt`` [s] from ``tp`` [s] to the next exposure."""
        return math.ceil((self.next_exposure - _EPS - tp) / plant_dt)


class _Trace:
    """What is recorded at each control step (preallocated for ``n`` steps)."""

    def __init__(self, n: int) -> None:
        self.t = np.empty(n)
        self.x = np.empty((n, 6))
        self.u = np.zeros(n)
        self.u_unsat = np.zeros(n)
        self.mode = np.zeros(n, np.int8)
        self.phi_hat = np.full(n, np.nan)
        self.phi_dot_hat = np.full(n, np.nan)

    def record(self, k: int, t: float, x: FloatArray, cmd: Command) -> None:
        """Store step ``k``: time, true state and the controller's command."""
        self.t[k] = t
        self.x[k] = x[:6]  # a creeping spin's seventh state is not kept
        self.u[k] = cmd.torque
        self.u_unsat[k] = cmd.torque_unsat
        self.mode[k] = MODE_CODES[cmd.mode]
        self.phi_hat[k] = cmd.phi
        self.phi_dot_hat[k] = cmd.phi_dot


@dataclass(frozen=True, kw_only=True)
class _LoopEnd:
    """How the control loop ended.

    Attributes
    ----------
    steps : int
        Control steps recorded [-].
    plant_steps : int
        RK4 steps of the plant [-].
    lost_reason : str
        The controller's first BALL_LOST reason, or why the run stopped (empty if neither).
    """

    steps: int
    plant_steps: int
    lost_reason: str


def _ball_failed(x: FloatArray, cmd: Command, pargs: tuple) -> bool:
    """The ball stopped, turned back, lifted off, or the controller declared it lost.

    The lift-off test is rolling's normal force (a creeping spin's differs by its friction's
    share of the accelerations).
    """
    return bool(x[3] <= 0.0 or cmd.mode == BALL_LOST
                or rigid_terms(x[0], x[1], x[2], x[3], cmd.torque, *pargs)[4] <= 0.0)


class _Actuator:
    """Torques in flight: each acts from its time on (zero-order hold), the newest wins."""

    def __init__(self, delay: float, plant_dt: float) -> None:
        self.delay_steps = round(delay / plant_dt)
        self.queue: deque[tuple[int, float]] = deque()  # (plant step it acts from, torque)
        self.u = 0.0

    def command(self, k: int, u: float) -> None:
        """The torque ``u`` computed at plant step ``k`` [N m]."""
        self.queue.append((k + self.delay_steps, u))

    def at(self, k: int) -> tuple[float, int]:
        """Torque acting at plant step k, and the steps until the next change (or a lot)."""
        while self.queue and self.queue[0][0] <= k:
            self.u = self.queue.popleft()[1]
        return self.u, (self.queue[0][0] - k) if self.queue else 1 << 30


def _plant_period(x: FloatArray, t: float, k0: int, actuator: _Actuator, grid: _ControlGrid,
                  camera: _Camera, pargs: tuple) -> tuple[FloatArray, int]:
    """The plant over one control period from ``t`` [s] (plant step ``k0``).

    The RK4 runs in stretches that end at the camera's exposures, which are taken on the
    plant grid, and where the actuator's torque changes. Returns the state at the period's
    end and the RK4 steps taken.
    """
    j = 0
    while j < grid.n_sub:
        tp = t + j * grid.plant_dt
        camera.expose_if_due(tp, x)
        u, until = actuator.at(k0 + j)
        m = max(1, min(grid.n_sub - j, camera.steps_to_exposure(tp, grid.plant_dt), until))
        x = rigid_rk4_steps(x, tp, grid.plant_dt, m, (u, *pargs))
        j += m
    return x, j


def _control_loop(controller: OrbitalController, x: FloatArray, grid: _ControlGrid,
                  camera: _Camera, encoder: _Encoder, trace: _Trace, pargs: tuple,
                  stop_on_failure: bool, actuator: _Actuator, lead: float) -> _LoopEnd:
    """Run the control steps of ``grid`` from the true state ``x``, recording into ``trace``.

    Each step hands the controller the encoder reading and the camera frames delivered by
    then, records its command, and (but after the last) advances the plant one period.
    """
    lost_reason = ""
    plant_steps = 0
    for k in range(grid.n_steps):
        t = k * grid.period
        obs = camera.delivered(t)
        theta_m, theta_dot_m = encoder.read(x)
        cmd = controller.step(t, theta_m, theta_dot_m, obs or None, lead=lead)
        actuator.command(k * grid.n_sub, cmd.torque)
        trace.record(k, t, x, cmd)
        if cmd.mode == BALL_LOST and not lost_reason:
            lost_reason = cmd.reason
        if stop_on_failure and _ball_failed(x, cmd, pargs):
            return _LoopEnd(steps=k + 1, plant_steps=plant_steps, lost_reason=lost_reason)
        if k == grid.n_steps - 1:
            break
        x, m = _plant_period(x, t, k * grid.n_sub, actuator, grid, camera, pargs)
        plant_steps += m
        if not all(math.isfinite(v) for v in x[:4]):
            return _LoopEnd(steps=k + 1, plant_steps=plant_steps,
                            lost_reason=lost_reason or "plant state became non-finite")
    return _LoopEnd(steps=grid.n_steps, plant_steps=plant_steps, lost_reason=lost_reason)


def _loop_result(controller: OrbitalController, trace: _Trace, camera: _Camera,
                 end: _LoopEnd, pargs: tuple, wall_time: float, info: dict) -> LoopResult:
    """The :class:`LoopResult` of the first ``end.steps`` recorded steps."""
    sl = slice(0, end.steps)
    xs = trace.x[sl]
    fn = rigid_terms(xs[:, 0], xs[:, 1], xs[:, 2], xs[:, 3], trace.u[sl], *pargs)[4]
    return LoopResult(t=trace.t[sl], x=xs, u=trace.u[sl], u_unsat=trace.u_unsat[sl],
                      mode=trace.mode[sl], phi_hat=trace.phi_hat[sl],
                      phi_dot_hat=trace.phi_dot_hat[sl],
                      transverse=transverse_coordinates(controller.orbit, xs[:, :4]),
                      normal_force=fn, cam_t=np.array(camera.t), cam_x=np.array(camera.x),
                      cam_y=np.array(camera.y), cam_valid=np.array(camera.valid, bool),
                      wall_time=wall_time, info=info)


def run_closed_loop(controller: OrbitalController, plant_params: RigParams, duration: float,
                    x0: FloatArray | None = None, sensors: SensorConfig | None = None,
                    seed: int = 0, plant_dt: float = 1e-3, control_rate: float | None = None,
                    stop_on_failure: bool = False, predict_delay: bool = True) -> LoopResult:
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
    predict_delay : bool
        Tell the controller the actuation delay (``lead``), as the controller node does.
    """
    sensors = sensors or SensorConfig()
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    grid = _ControlGrid.of(duration, float(control_rate or controller.config.control.rate),
                           plant_dt)
    rng = np.random.default_rng(seed)
    plant = RigidModel(plant_params)
    x = plant.state(controller.orbit.state(0.0) if x0 is None else x0)
    controller.reset()
    camera = _Camera(sensors, plant, rng)
    trace = _Trace(grid.n_steps)
    start = time.perf_counter()
    actuator = _Actuator(sensors.actuation_delay, plant_dt)
    lead = actuator.delay_steps * plant_dt if predict_delay else 0.0
    end = _control_loop(controller, x, grid, camera, _Encoder.of(sensors, rng), trace,
                        plant.kernel_args, stop_on_failure, actuator, lead)
    wall = time.perf_counter() - start
    info = {
        "seed": seed,
        "plant_dt": plant_dt,
        "control_rate": 1.0 / grid.period,
        "torque_limit": controller.torque_limit,
        "plant_steps": end.plant_steps,
        "sensors": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in asdict(sensors).items()},
        "x0": [float(v) for v in trace.x[0, :4]],
        "lost_reason": end.lost_reason,
    }
    return _loop_result(controller, trace, camera, end, plant.kernel_args, wall, info)
