"""The orbital stabilisation controller of the Butterfly robot (pure numpy, no rclpy).

Per control step (``OrbitalController.step``), from the encoder's theta, theta_dot and the
latest camera fix:

1. estimate phi, phi_dot at the present (bfr_control.estimator: Kalman filter with exact
   latency compensation);
2. transverse coordinates ``I = phi_dot^2 - Y(phi)``, ``y = theta - Theta(phi)``,
   ``y_dot = theta_dot - Theta'(phi) phi_dot`` (bfr_control.transverse);
3. ``w = K(phi) [I, y, y_dot]`` with the periodic Riccati gains (bfr_control.riccati);
4. ``u = PFL(w)``, the torque that makes ``y_ddot = w`` on the controller's model (seed
   eq. 4.46), plus an optional friction feed-forward ``c_v theta_dot + T_c tanh(theta_dot /
   v_s)``, clamped to the actuator's +-torque_limit (rig.yaml; the unclamped value is
   reported).

Actuation delay. On hardware a torque acts some time after the encoder sample it answers
(camera processing, transport, the drive's update): ``lead`` [s]. Steps 2-4 are then
computed for the state predicted ``lead`` ahead, ``x(t + lead)``, by integrating the
controller's model (RK4 in steps of at most 1 ms) from the estimate at t under the torque
that acts meanwhile, the previous command (it is held until the new one arrives):

    x(t + lead) = RK4[model, u_prev](x(t), lead),

so the law answers the state the torque will meet, as on a delay-free loop (a Smith
predictor on the model; the node measures ``lead`` per step). ``lead = 0`` is the plain law.

A supervisor (state machine) decides whether to apply it:

- ``WAITING``: no usable ball yet (fewer than ``acquire_frames`` valid fixes, or the ball is
  not rolling forward near the orbit): torque 0;
- ``ROLLING``: the law above;
- ``BALL_LOST`` (latched until :meth:`OrbitalController.reset`): no valid fix for longer than
  ``lost_timeout``, the ball stopped or turned back (phi_dot estimate below
  ``min_phi_dot``), or the state far from the orbit (``|y| > max_abs_y`` or
  ``|z| > max_abs_z``): torque 0, with the reason.

Configuration: ``config/controller.yaml`` (ROS 2 parameter-file format, also the controller
node's parameter file), loaded by :func:`load_controller_config`. The physics comes from the
controller's own :class:`bfr_model.params.RigParams` (its nominal model), separate from the
plant's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel
from bfr_model.param_file import (
    ParameterError,
    config_path,
    integer,
    load_ros_parameters,
    nonnegative,
    positive,
)
from bfr_model.params import RigParams

from bfr_control.constraint import ConstraintSpec, VirtualConstraint
from bfr_control.estimator import BallEstimator, BallObservation, EstimatorConfig
from bfr_control.orbit import OrbitSpec, PeriodicOrbit
from bfr_control.periodic import PeriodicTable
from bfr_control.riccati import GainTable, RiccatiWeights, compute_gains
from bfr_control.transverse import pfl_kernel

__all__ = [
    "BALL_LOST",
    "ROLLING",
    "WAITING",
    "Command",
    "ControlConfig",
    "ControllerConfig",
    "OrbitalController",
    "SupervisorConfig",
    "default_config_path",
    "load_controller_config",
]

WAITING = "WAITING"
ROLLING = "ROLLING"
BALL_LOST = "BALL_LOST"


@dataclass(frozen=True)
class ControlConfig:
    """Control-law settings.

    Attributes
    ----------
    rate : float
        Control rate [Hz] (the closed-loop harness's default).
    friction_viscous : float
        Feed-forward viscous coefficient c_v [N m s/rad].
    friction_coulomb : float
        Feed-forward Coulomb torque T_c [N m].
    friction_smoothing : float
        v_s of ``tanh(theta_dot / v_s)`` [rad/s].
    """

    rate: float = 1000.0
    friction_viscous: float = 0.0
    friction_coulomb: float = 0.0
    friction_smoothing: float = 0.05

    def __post_init__(self) -> None:
        positive("control.rate", self.rate)
        positive("control.friction_smoothing", self.friction_smoothing)
        nonnegative("control.friction_viscous", self.friction_viscous)
        nonnegative("control.friction_coulomb", self.friction_coulomb)


@dataclass(frozen=True)
class SupervisorConfig:
    """State-machine thresholds.

    Attributes
    ----------
    acquire_frames : int
        Valid fixes needed before rolling control starts [-].
    lost_timeout : float
        Longest time without a valid fix while rolling [s].
    min_phi_dot : float
        Smallest phi_dot estimate accepted while rolling [rad/s].
    max_abs_y : float
        Largest |y| = |theta - Theta(phi)| accepted [rad].
    max_abs_z : float
        Largest |phi_dot - phi_dot*(phi)| accepted [rad/s].
    """

    acquire_frames: int = 4
    lost_timeout: float = 0.25
    min_phi_dot: float = 0.3
    max_abs_y: float = 0.6
    max_abs_z: float = 2.0

    def __post_init__(self) -> None:
        integer("supervisor.acquire_frames", self.acquire_frames, minimum=1)
        for name in ("lost_timeout", "min_phi_dot", "max_abs_y", "max_abs_z"):
            positive(f"supervisor.{name}", getattr(self, name))


@dataclass(frozen=True)
class ControllerConfig:
    """Everything in controller.yaml."""

    constraint: ConstraintSpec = field(default_factory=ConstraintSpec)
    orbit: OrbitSpec = field(default_factory=OrbitSpec)
    riccati: RiccatiWeights = field(default_factory=RiccatiWeights)
    control: ControlConfig = field(default_factory=ControlConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    supervisor: SupervisorConfig = field(default_factory=SupervisorConfig)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ControllerConfig:
        """Build from the ``ros__parameters`` mapping of controller.yaml."""
        known = {"constraint", "orbit", "riccati", "control", "estimator", "supervisor"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"controller config: unknown groups {sorted(unknown)}")

        def build(kind: type, name: str) -> Any:
            g = dict(d.get(name, {}) or {})
            names = set(kind.__dataclass_fields__)
            bad = set(g) - names
            if bad:
                raise ValueError(f"controller config: unknown entries {sorted(bad)} in {name}")
            for key, f in kind.__dataclass_fields__.items():
                if key in g and isinstance(f.default, float) and isinstance(g[key], (int, str)):
                    g[key] = float(g[key])  # YAML 1.1 reads 1e4 as a string, 2 as an int
            return kind(**g)

        orbit = dict(d.get("orbit", {}) or {})
        # a ROS parameter cannot be None: a non-positive speed means "not used"
        for key in ("mean_phi_dot", "phi_dot_0"):
            if key in orbit and orbit[key] is not None and float(orbit[key]) <= 0.0:
                orbit[key] = None
        if orbit.get("phi_dot_0") is not None and "mean_phi_dot" not in orbit:
            orbit["mean_phi_dot"] = None
        bad = set(orbit) - set(OrbitSpec.__dataclass_fields__)
        if bad:
            raise ValueError(f"controller config: unknown entries {sorted(bad)} in orbit")
        return cls(constraint=ConstraintSpec.from_dict(dict(d.get("constraint", {}) or {})),
                   orbit=OrbitSpec(**orbit),
                   riccati=build(RiccatiWeights, "riccati"),
                   control=build(ControlConfig, "control"),
                   estimator=build(EstimatorConfig, "estimator"),
                   supervisor=build(SupervisorConfig, "supervisor"))

    def replace(self, **groups: Any) -> ControllerConfig:
        """Copy with some groups changed, e.g. ``replace(control=ControlConfig(rate=200))``."""
        d = {name: getattr(self, name) for name in self.__dataclass_fields__}
        d.update(groups)
        return ControllerConfig(**d)


def default_config_path() -> Path:
    """Path of the shipped controller.yaml (bfr_control's ``config/``)."""
    return config_path("bfr_control", "controller.yaml")


def load_controller_config(path: str | Path | None = None) -> ControllerConfig:
    """Load controller.yaml (ROS 2 parameter-file format; default: the shipped file)."""
    p = Path(path) if path is not None else default_config_path()
    body = load_ros_parameters(p)
    try:
        return ControllerConfig.from_dict(body)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{p}: {exc}") from exc


@dataclass(frozen=True, slots=True, kw_only=True)
class Command:
    """Output of one control step.

    Attributes
    ----------
    t : float
        Time of the step [s].
    mode : str
        WAITING, ROLLING or BALL_LOST.
    reason : str
        Why the supervisor is in this mode (empty while rolling normally).
    torque : float
        Commanded (clamped) torque [N m]; 0 unless ROLLING.
    torque_unsat : float
        Torque before the clamp [N m] (0 when not rolling).
    phi, phi_dot : float
        Estimated contact angle [rad] and rate [rad/s] (NaN before the first fix).
    I, y, y_dot, z : float
        Transverse coordinates from the estimate [rad^2/s^2, rad, rad/s, rad/s] (NaN when
        there is no estimate).
    w : float
        Commanded y_ddot [rad/s^2] (0 when not rolling).
    new_fix : bool
        A valid camera fix was fused in this step.
    lead : float
        Actuation delay the law predicted through [s] (module docstring).
    """

    t: float
    mode: str
    reason: str
    torque: float = 0.0
    torque_unsat: float = 0.0
    phi: float = math.nan
    phi_dot: float = math.nan
    I: float = math.nan  # noqa: E741 (the integral-of-motion deviation of the literature)
    y: float = math.nan
    y_dot: float = math.nan
    z: float = math.nan
    w: float = 0.0
    new_fix: bool = False
    lead: float = 0.0


class OrbitalController:
    """Virtual-constraint orbital stabilisation with a supervisor (module docstring).

    Parameters
    ----------
    params : RigParams
        The controller's model of the rig (nominal; the plant may differ).
    config : ControllerConfig, optional
        Settings (default: the shipped controller.yaml).
    use_cache : bool
        Use the gain cache (bfr_control.riccati).
    gains : GainTable, optional
        Precomputed gains (skips the Riccati solve; must belong to the same orbit).
    """

    def __init__(self, params: RigParams, config: ControllerConfig | None = None,
                 use_cache: bool = True, gains: GainTable | None = None) -> None:
        self.params = params
        #: The actuator's clamp on the command [N m] (``actuator.torque_limit``, rig.yaml).
        self.torque_limit = params.actuator.torque_limit
        self.config = config if config is not None else load_controller_config()
        self.model = RigidModel(params)
        self.constraint = VirtualConstraint(self.model, self.config.constraint)
        self.orbit = PeriodicOrbit(self.model, self.constraint, self.config.orbit)
        self.gains = gains if gains is not None else compute_gains(
            self.orbit, self.config.riccati, use_cache=use_cache)
        self.estimator = BallEstimator(self.model, self.orbit, self.config.estimator)
        self._args = self.model.kernel_args
        # one table for the loop: Theta, Theta', Theta'', Y, k_I, k_y, k_ydot
        o = self.orbit
        nan = np.full((o.phi.size, 3), np.nan)
        self._tab = PeriodicTable(
            o.period, np.column_stack([o.table.values, self.gains.table.values]),
            derivatives=np.column_stack([o.table.derivatives, nan]),
            drift=[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        self.reset()

    def reset(self, keep_lost: bool = False) -> None:
        """Back to WAITING with a fresh estimator.

        ``keep_lost``: a latched BALL_LOST stays (with its reason and time): a node's fault
        recovery must not re-arm what only an operator's reset may.
        """
        lost = (self.reason, self.lost_at) if keep_lost and self.mode == BALL_LOST else None
        self.estimator.reset()
        self.mode = WAITING
        self.reason = "no ball observation yet"
        self.lost_at: float | None = None
        self.last_torque = 0.0  # the command that acts until the next one [N m]
        if lost is not None:
            self.mode, (self.reason, self.lost_at) = BALL_LOST, lost

    def _lose(self, t: float, reason: str) -> None:
        self.mode = BALL_LOST
        self.reason = reason
        self.lost_at = t

    def predict(self, x: np.ndarray, lead: float, u: float) -> np.ndarray:
        """``x(t + lead)`` on the controller's model under the held torque u (module docstring).

        Parameters
        ----------
        x : ndarray, shape (4,)
            ``[theta, phi, theta_dot, phi_dot]`` at t.
        lead : float
            Prediction horizon [s] (<= 0: x itself).
        u : float
            Torque acting meanwhile [N m].

        Returns
        -------
        ndarray, shape (4,)
        """
        if not lead > 0.0:
            return x
        n = max(1, math.ceil(lead / 1e-3))
        return self.model.step(self.model.state(x), u, lead / n, n)[:4]

    def step(self, t: float, theta: float, theta_dot: float,
             ball: BallObservation | Iterable[BallObservation] | None = None,
             lead: float = 0.0) -> Command:
        """One control step.

        Parameters
        ----------
        t : float
            Time of the encoder sample [s].
        theta, theta_dot : float
            Encoder frame angle [rad] and rate [rad/s].
        ball : BallObservation or iterable of them or None
            Camera fixes that arrived since the last step (None: none).
        lead : float
            Time from the encoder sample to the moment the command acts [s]; the law is
            evaluated on the state predicted that far ahead (module docstring).

        Returns
        -------
        Command
        """
        est = self.estimator
        sup = self.config.supervisor
        ctl = self.config.control
        if not (math.isfinite(t) and math.isfinite(theta) and math.isfinite(theta_dot)):
            if self.mode == ROLLING:
                self._lose(t, "non-finite encoder sample")
            return Command(t=t, mode=self.mode, reason=self.reason, phi=est.phi,
                           phi_dot=est.phi_dot)
        est.record(t, theta, theta_dot)
        new_fix = False
        if ball is not None:
            for obs in (ball,) if isinstance(ball, BallObservation) else ball:
                if est.update(obs):
                    new_fix = True
        phi, phi_dot = est.phi, est.phi_dot
        if not est.initialized:
            return Command(t=t, mode=self.mode, reason=self.reason, phi=phi, phi_dot=phi_dot,
                           new_fix=new_fix)
        th0, th1, th2, Y, k_i, k_y, k_yd = self._tab(phi).tolist()
        y = theta - th0
        y_dot = theta_dot - th1 * phi_dot
        I_dev = phi_dot * phi_dot - Y
        z = phi_dot - math.sqrt(Y)
        since_fix = t - est.last_fix_t
        if self.mode == WAITING:
            if since_fix > sup.lost_timeout:
                est.restart("lost")  # the ball went away before we locked on
                self.reason = "ball seen, then lost again before acquisition"
                return Command(t=t, mode=self.mode, reason=self.reason, new_fix=new_fix)
            if est.frames < sup.acquire_frames:
                self.reason = f"acquiring the ball ({est.frames}/{sup.acquire_frames} fixes)"
            elif phi_dot < sup.min_phi_dot or abs(y) > sup.max_abs_y or abs(z) > sup.max_abs_z:
                self.reason = (f"ball seen but not near the orbit (phi_dot {phi_dot:.3g} rad/s, "
                               f"y {y:.3g} rad, z {z:.3g} rad/s)")
            else:
                self.mode = ROLLING
                self.reason = ""
        elif self.mode == ROLLING:
            if since_fix > sup.lost_timeout:
                self._lose(t, f"no valid ball fix for {since_fix:.3f} s "
                              f"(timeout {sup.lost_timeout} s)")
            elif phi_dot < sup.min_phi_dot:
                self._lose(t, f"ball stopped or turned back (phi_dot estimate {phi_dot:.3g} "
                              f"rad/s < {sup.min_phi_dot} rad/s)")
            elif abs(y) > sup.max_abs_y:
                self._lose(t, f"frame {y:.3g} rad off the constraint (max {sup.max_abs_y} rad)")
            elif abs(z) > sup.max_abs_z:
                self._lose(t, f"ball speed {z:.3g} rad/s off the orbit "
                              f"(max {sup.max_abs_z} rad/s)")
        if self.mode != ROLLING:
            self.last_torque = 0.0
            return Command(t=t, mode=self.mode, reason=self.reason, phi=phi, phi_dot=phi_dot,
                           I=I_dev, y=y, y_dot=y_dot, z=z, new_fix=new_fix)
        lead = min(max(float(lead), 0.0), sup.lost_timeout) if math.isfinite(lead) else 0.0
        if lead > 0.0:
            xp = self.predict(np.array([theta, phi, theta_dot, phi_dot]), lead,
                              self.last_torque)
            if bool(np.all(np.isfinite(xp))):
                theta, phi, theta_dot, phi_dot = (float(v) for v in xp)
                th0, th1, th2, Y, k_i, k_y, k_yd = self._tab(phi).tolist()
                y = theta - th0
                y_dot = theta_dot - th1 * phi_dot
                I_dev = phi_dot * phi_dot - Y
                z = phi_dot - math.sqrt(Y)
            else:
                lead = 0.0
        w = k_i * I_dev + k_y * y + k_yd * y_dot
        u = pfl_kernel(theta, phi, theta_dot, phi_dot, th1, th2, w, *self._args)
        if ctl.friction_viscous or ctl.friction_coulomb:
            u += (ctl.friction_viscous * theta_dot
                  + ctl.friction_coulomb * math.tanh(theta_dot / ctl.friction_smoothing))
        lim = self.torque_limit
        u_sat = lim if u > lim else (-lim if u < -lim else u)
        if not math.isfinite(u_sat):
            u_sat = 0.0
        self.last_torque = u_sat
        return Command(t=t, mode=self.mode, reason=self.reason, torque=u_sat, torque_unsat=u,
                       phi=phi, phi_dot=phi_dot, I=I_dev, y=y, y_dot=y_dot, z=z, w=w,
                       new_fix=new_fix, lead=lead)

    def orbit_state(self, phi: float) -> np.ndarray:
        """State ``[theta, phi, theta_dot, phi_dot]`` on the controller's orbit at phi."""
        return self.orbit.state(phi)

    def warm_up(self, steps: int = 12, dt: float = 0.005, lead: float = 0.002) -> int:
        """:meth:`reset`, run the loop on a ball rolling along the orbit, :meth:`reset` again.

        Every path of :meth:`step` a run takes (the estimator, the pick-up, the prediction
        over ``lead`` and the PFL law) calls compiled kernels that load on their first call,
        tens of milliseconds each: a node calls this while it sets up, so that the first
        rolling step of a real run is not the one that pays. The ball is the orbit's own
        (``phi`` advanced at the orbit's rate, camera fixes at its centre every ``dt``
        seconds), so the steps pass the acquisition and roll.

        Returns
        -------
        int
            Steps that ran ROLLING (0 would leave the rolling path cold).
        """
        self.reset()  # the synthetic run starts at t = 0, whatever ran before
        phi, rolled = 0.3, 0
        for k in range(steps):
            t = dt * k
            x = self.orbit_state(phi)
            pos = self.model.ball_position(x)
            cmd = self.step(t, float(x[0]), float(x[2]),
                            BallObservation(t, float(pos[0]), float(pos[1]), True), lead=lead)
            rolled += cmd.mode == ROLLING
            phi += float(x[3]) * dt
        self.reset()
        return rolled

    def summary(self) -> dict:
        """Orbit and gain figures (JSON-ready)."""
        return {"orbit": self.orbit.summary(),
                "gains": {**self.gains.ranges(),
                          "monodromy_spectral_radius":
                              self.gains.info.get("monodromy_spectral_radius"),
                          "riccati_periods": self.gains.info.get("periods"),
                          "cache": self.gains.info.get("cache")}}
