"""Controllers of the independent rig (written apart from bfr; numpy only).

* :class:`BallStabiliser`: keeps the ball rolling. A virtual constraint
  ``theta = Theta(psi) + delta`` turns the frame so that the world tangent of the
  ball-centre curve at the ball has inclination ``-atan(c sin 2 psi)`` (``c`` about -0.04 in
  this rig's sign convention: a tilt under 2.5 degrees); partial feedback linearisation on
  ``y = theta - Theta(psi) - delta`` with a PD law ``y'' = -k_p y - k_d y'`` computed on the
  controller's own nominal model (physics.Plant, lossless); a slow speed pump (PI) sets the
  frame offset ``delta`` from the mean speed over the last half-lap time (a frame turned
  ahead, ``delta < 0``, speeds the ball up: about +60 rad/s per rad of ``-delta`` per half
  lap on the nominal rig, measured with this controller).
* :class:`BallEstimator`: the ball angle and rate between camera fixes (least-squares line
  through the last fixes, latency compensated).
* :class:`SpeedPI`: frame speed tracking (friction runs, no ball).
* :class:`TorqueProgram`: open-loop torque (step, sine, zero).

Derivation of the PFL law: on the model ``M q'' = b(q, q') + [u, 0]`` the accelerations are
affine in ``u``: ``theta'' = a0 + a1 u``, ``psi'' = b0 + b1 u`` (two evaluations, ``u = 0, 1``).
With ``Theta = psi + g(psi)``: ``y'' = theta'' - Theta' psi'' - Theta'' psi'^2``, so
``u = (w - a0 + Theta' b0 + Theta'' psi'^2) / (a1 - Theta' b1)`` gives ``y'' = w``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from . import physics


class Constraint:
    """The virtual constraint ``Theta(psi) = psi + g(psi)`` of the stabiliser.

    ``g = -atan2(r', r) - atan(c sin 2 psi)``: the clockwise tangent ``p'`` has frame angle
    ``alpha = -psi + atan2(r', r)`` (physics.Track.tangent_angle), so in the world it is
    inclined by ``Theta + alpha = -atan(c sin 2 psi)``. ``g`` is tabulated
    (physics.PeriodicTable), giving ``Theta' = 1 + g'`` and ``Theta'' = g''``.

    Parameters
    ----------
    track : physics.Track
        The controller's model of the ball-centre curve.
    c : float
        Tilt amplitude [-].
    """

    def __init__(self, track: physics.Track, c: float) -> None:
        n = track.table.n
        psi = 2 * np.pi * np.arange(n) / n
        r, r1, _ = track.eval_array(psi)
        self.c = c
        self.table = physics.PeriodicTable.from_samples(
            -np.arctan2(r1, r) - np.arctan(c * np.sin(2 * psi)))

    def eval(self, psi: float) -> tuple[float, float, float]:
        """``Theta`` [rad], ``Theta'`` [-], ``Theta''`` [1/rad] at ``psi`` [rad]."""
        g, g1, g2 = self.table.eval(psi)
        return psi + g, 1.0 + g1, g2


@dataclass(frozen=True, kw_only=True)
class StabiliserGains:
    """Gains of :class:`BallStabiliser`.

    Parameters
    ----------
    c : float
        Constraint tilt amplitude [-].
    kp : float
        ``k_p`` [1/s^2].
    kd : float
        ``k_d`` [1/s].
    speed_ref : float
        Target half-lap mean ball speed [rad/s].
    pump_p : float
        Frame offset per speed error [rad s/rad].
    pump_i : float
        Frame offset per integrated speed error [rad/rad].
    delta_max : float
        Bound of the frame offset [rad].
    friction_ff : float
        Joint friction feed-forward ``friction_ff sign(theta_dot)`` [N m].
    torque_limit : float
        Clamp [N m].
    lost_timeout : float
        No camera fix for this long: ball lost, zero torque [s].
    y_max : float
        ``|y|`` beyond this: ball lost [rad].
    """

    c: float = -0.04
    kp: float = 400.0
    kd: float = 40.0
    speed_ref: float = 2.35
    pump_p: float = 0.012
    pump_i: float = 0.004
    delta_max: float = 0.02
    friction_ff: float = 0.0
    torque_limit: float = 0.1
    lost_timeout: float = 0.1
    y_max: float = 0.35

    def __post_init__(self) -> None:
        for name in ("kp", "kd", "speed_ref", "torque_limit", "lost_timeout", "y_max"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"stabiliser gain {name} must be > 0")


class BallStabiliser:
    """Keeps the ball rolling (module docstring).

    Parameters
    ----------
    model : physics.RigParams
        The controller's nominal model (its losses are ignored).
    gains : StabiliserGains
        Gains.
    """

    def __init__(self, model: physics.RigParams, gains: StabiliserGains) -> None:
        self.gains = gains
        self.model = physics.Plant(model.lossless(), ball=True)
        self.constraint = Constraint(self.model.track, gains.c)
        self.delta = 0.0
        self._delta_i = 0.0
        self._lap_psi = -math.inf
        self._history: deque[tuple[float, float]] = deque()
        self._t_pump: float | None = None
        self.lost = False
        self.half_lap_speeds: list[float] = []

    def command(self, t: float, theta: float, theta_dot: float, psi: float, psi_dot: float,
                fix_age: float) -> float:
        """Torque for one control step.

        Parameters
        ----------
        t : float
            Time [s].
        theta, theta_dot : float
            Frame angle [rad] and rate [rad/s] (as the servo reports them).
        psi, psi_dot : float
            Estimated ball-centre angle [rad] and rate [rad/s].
        fix_age : float
            Time since the last camera fix arrived [s].

        Returns
        -------
        float
            Commanded torque [N m] (0 once the ball is lost).
        """
        g = self.gains
        if self.lost:
            return 0.0
        self._pump(t, psi)
        Th, Th1, Th2 = self.constraint.eval(psi)
        y = theta - Th - self.delta
        yd = theta_dot - Th1 * psi_dot
        if fix_age > g.lost_timeout or abs(y) > g.y_max or not math.isfinite(y + yd):
            self.lost = True
            return 0.0
        acc0 = self.model.rolling_accelerations(theta, psi, theta_dot, psi_dot, 0.0)
        acc1 = self.model.rolling_accelerations(theta, psi, theta_dot, psi_dot, 1.0)
        a1, b1 = acc1[0] - acc0[0], acc1[1] - acc0[1]
        w = -g.kp * y - g.kd * yd
        u = (w - acc0[0] + Th1 * acc0[1] + Th2 * psi_dot * psi_dot) / (a1 - Th1 * b1)
        u += g.friction_ff * (1.0 if theta_dot > 0 else -1.0 if theta_dot < 0 else 0.0)
        return max(-g.torque_limit, min(g.torque_limit, u))

    def _pump(self, t: float, psi: float) -> None:
        """Set the frame offset from the mean ball speed over the last half-lap time.

        ``v = (psi(t) - psi(t - T)) / T`` with ``T = pi / speed_ref`` (on the orbit: the
        half-lap mean, free of the speed's ripple along the lap); ``e = speed_ref - v``;
        ``delta = -pump_p e - pump_i integral(e)``, both bounded by ``delta_max``.
        """
        g = self.gains
        window = math.pi / g.speed_ref
        hist = self._history
        hist.append((t, psi))
        while len(hist) > 2 and hist[1][0] <= t - window:
            hist.popleft()
        t0, psi0 = hist[0]
        if t - t0 < 0.1:
            return
        speed = (psi - psi0) / (t - t0)
        dt = t - self._t_pump if self._t_pump is not None else 0.0
        self._t_pump = t
        error = g.speed_ref - speed
        self._delta_i = max(-g.delta_max, min(g.delta_max, self._delta_i - g.pump_i * error * dt))
        self.delta = max(-g.delta_max, min(g.delta_max, self._delta_i - g.pump_p * error))
        if speed < 0.6 * g.speed_ref:  # stalling or turning back: full push forward
            self.delta = -g.delta_max
        if not math.isfinite(self._lap_psi):
            self._lap_psi = math.pi * math.floor(psi / math.pi)
        elif psi - self._lap_psi >= math.pi:
            self._lap_psi += math.pi * math.floor((psi - self._lap_psi) / math.pi)
            self.half_lap_speeds.append(speed)


class BallEstimator:
    """Ball angle and rate between camera fixes.

    At each fix the rig software's ball-centre angle ``theta(t_e) + atan2(x, y)`` is formed
    with the frame angle interpolated at the estimated exposure time
    ``t_e = t_arrival - latency``; a least-squares line through the last ``window`` fixes
    gives the rate; between fixes the angle is extrapolated along that line.

    Parameters
    ----------
    latency : float
        Assumed camera latency [s].
    window : int
        Fixes in the line fit.
    """

    def __init__(self, latency: float, window: int = 5) -> None:
        if window < 2:
            raise ValueError("the estimator needs a window of >= 2 fixes")
        self.latency = latency
        self._fixes: deque[tuple[float, float]] = deque(maxlen=window)
        self._theta: deque[tuple[float, float]] = deque(maxlen=64)
        self.last_arrival = -math.inf
        self._line = (0.0, 0.0, 0.0)

    def frame_sample(self, t: float, theta: float) -> None:
        """Record the servo's frame angle at ``t`` (for the exposure-time interpolation)."""
        self._theta.append((t, theta))

    def _theta_at(self, t: float) -> float:
        pts = self._theta
        if not pts:
            return 0.0
        for (t0, th0), (t1, th1) in zip(reversed(list(pts)[:-1]), reversed(list(pts)[1:]),
                                        strict=True):
            if t0 <= t <= t1:
                return th0 + (th1 - th0) * (t - t0) / (t1 - t0) if t1 > t0 else th1
        return pts[0][1] if t < pts[0][0] else pts[-1][1]

    def prime(self, t: float, psi: float, psi_dot: float) -> None:
        """Start from a known ball angle [rad] and rate [rad/s] at ``t`` [s]."""
        self._fixes.clear()
        for k in range(self._fixes.maxlen or 2):
            dt = -0.005 * k
            self._fixes.appendleft((t + dt, psi + psi_dot * dt))
        self._line = (t, psi, psi_dot)
        self.last_arrival = t

    def fix(self, t_arrival: float, x: float, y: float) -> None:
        """A new camera fix ``(x, y)`` [m] arrived at ``t_arrival`` [s]."""
        t_e = t_arrival - self.latency
        psi = self._theta_at(t_e) + math.atan2(x, y)
        if self._fixes:
            last = self._fixes[-1][1]
            psi += 2 * math.pi * round((last - psi) / (2 * math.pi))
        self._fixes.append((t_e, psi))
        self.last_arrival = t_arrival
        if len(self._fixes) >= 2:
            ts = np.array([f[0] for f in self._fixes])
            ps = np.array([f[1] for f in self._fixes])
            rate, offset = np.polyfit(ts - ts[-1], ps, 1)
            self._line = (float(ts[-1]), float(offset), float(rate))
        else:
            self._line = (t_e, psi, 0.0)

    def estimate(self, t: float) -> tuple[float, float]:
        """Angle [rad] and rate [rad/s] at ``t`` [s]."""
        t0, p0, rate = self._line
        return p0 + rate * (t - t0), rate


@dataclass
class SpeedPI:
    """Frame speed tracking: ``u = kp e + ki integral(e)``, ``e = v_ref(t) - theta_dot``.

    Parameters
    ----------
    speed_ref : float
        Target frame speed [rad/s].
    kp : float
        [N m s/rad].
    ki : float
        [N m/rad].
    ramp : float
        The reference ramps up over this time [s].
    torque_limit : float
        Clamp [N m] (the integrator stops while clamped).
    """

    speed_ref: float
    kp: float = 0.01
    ki: float = 0.05
    ramp: float = 0.5
    torque_limit: float = 0.1
    _integral: float = 0.0
    _t_last: float | None = None

    def command(self, t: float, theta_dot: float) -> float:
        """Torque [N m] at time ``t`` [s] for the measured speed [rad/s]."""
        dt = 0.0 if self._t_last is None else t - self._t_last
        self._t_last = t
        ref = self.speed_ref * min(1.0, t / self.ramp) if self.ramp > 0 else self.speed_ref
        e = ref - theta_dot
        u = self.kp * e + self.ki * (self._integral + e * dt)
        if abs(u) < self.torque_limit:
            self._integral += e * dt
        return max(-self.torque_limit, min(self.torque_limit, u))


@dataclass(frozen=True, kw_only=True)
class TorqueProgram:
    """Open-loop torque: ``u = level`` from ``t_on``, plus ``amplitude sin(2 pi f t)``.

    Parameters
    ----------
    level : float
        Step level [N m].
    t_on : float
        Step time [s].
    amplitude : float
        Sine amplitude [N m].
    frequency : float
        Sine frequency [Hz].
    """

    level: float = 0.0
    t_on: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0

    def command(self, t: float) -> float:
        """Torque [N m] at time ``t`` [s]."""
        u = self.level if t >= self.t_on else 0.0
        return u + self.amplitude * math.sin(2 * math.pi * self.frequency * t)
