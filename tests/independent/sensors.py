"""Sensors of the independent rig: servo, encoder, camera fixes (numpy only; apart from bfr).

The servo reports the frame angle from a quantised encoder and a velocity that is a
difference of quantised angles over a window of samples (a delay of half the window),
optionally low-passed by a first-order filter. Each rig of the design may time these
differently; every convention is a parameter and goes into the truth sidecar.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, kw_only=True)
class EncoderConfig:
    """Encoder and servo-velocity conventions.

    Parameters
    ----------
    counts_per_rev : int
        Encoder counts per turn [-]; 0 disables quantisation.
    velocity_window : int
        The velocity is ``(theta_k - theta_{k-w}) / (w dt)`` over ``w`` samples [-]
        (its delay is ``w dt / 2``).
    velocity_filter : float
        Time constant of a first-order low-pass on that difference [s] (0: none).
    """

    counts_per_rev: int = 16384
    velocity_window: int = 2
    velocity_filter: float = 0.0

    def __post_init__(self) -> None:
        if self.counts_per_rev < 0:
            raise ValueError(f"counts_per_rev must be >= 0, got {self.counts_per_rev}")
        if self.velocity_window < 1:
            raise ValueError(f"velocity_window must be >= 1 sample, got {self.velocity_window}")
        if not (self.velocity_filter >= 0.0 and math.isfinite(self.velocity_filter)):
            raise ValueError(f"velocity_filter must be >= 0 s, got {self.velocity_filter}")

    def lag(self, dt: float) -> float:
        """Low-frequency delay of the reported velocity at sample period ``dt`` [s]."""
        return self.velocity_window * dt / 2.0 + self.velocity_filter


class Encoder:
    """Quantised angle and windowed, filtered velocity at a fixed sample period.

    Parameters
    ----------
    config : EncoderConfig
        The conventions.
    dt : float
        Sample period [s].
    """

    def __init__(self, config: EncoderConfig, dt: float) -> None:
        if not dt > 0.0:
            raise ValueError(f"sample period must be > 0 s, got {dt}")
        self.config = config
        self.dt = dt
        self._history: deque[float] = deque(maxlen=config.velocity_window + 1)
        self._velocity = 0.0
        self._step = 2 * math.pi / config.counts_per_rev if config.counts_per_rev else 0.0
        tau = config.velocity_filter
        self._alpha = dt / (tau + dt)

    def quantise(self, theta: float) -> float:
        """Angle as the encoder counts it [rad]."""
        if not self._step:
            return theta
        return round(theta / self._step) * self._step

    def sample(self, theta: float) -> tuple[float, float]:
        """Take one sample of the true angle.

        Parameters
        ----------
        theta : float
            True frame angle [rad].

        Returns
        -------
        tuple of float
            Reported angle [rad] and velocity [rad/s] (0 until the window has filled).
        """
        q = self.quantise(theta)
        self._history.append(q)
        if len(self._history) > self.config.velocity_window:
            raw = (q - self._history[0]) / (self.config.velocity_window * self.dt)
            self._velocity += self._alpha * (raw - self._velocity)
        return q, self._velocity


VELOCITY_MODES = ("difference", "filter", "true")
LOST_FILL = ("zero", "hold")


@dataclass(frozen=True, kw_only=True)
class SensorConventions:
    """Everything about how one rig's servo, camera and logger see the truth.

    Parameters
    ----------
    line_rate : float
        Log lines (control steps) per second [Hz], 150-1000.
    line_jitter : float
        Standard deviation of a line period relative to its mean [-].
    servo_rate : float
        Servo sample rate [Hz]; a log line reads the servo's latest sample.
    counts_per_rev : int
        Encoder counts per turn [-] (0: none).
    velocity_mode : str
        ``difference`` (over a window of servo samples), ``filter`` (first-order low-pass
        of the one-sample difference) or ``true`` (the exact rate, no lag).
    velocity_lag : float
        Delay of the reported velocity [s], 0-10 ms (``difference``: the window is
        ``2 lag servo_rate`` samples; ``filter``: the time constant).
    torque_shift : float
        The torque printed on a line acts at ``t_line + torque_shift`` [s], -2..+2 ms.
    actuation_delay : float
        From a command's computation to its action [s] (>= ``torque_shift``).
    camera_rate : float
        Camera frames per second [Hz], 150-250.
    camera_jitter : float
        Standard deviation of a frame period [s].
    camera_latency : float
        From exposure to the fix being available to the rig software [s].
    camera_noise : float
        Standard deviation of each fix coordinate [m].
    camera_offset : tuple of float
        Origin offset of the fixes ``(dx, dy)`` [m].
    camera_scale : float
        Scale error: fixes are ``(1 + camera_scale)`` times the truth [-].
    camera_rotation : float
        Rotation of the fixes about the axis, counter-clockwise [rad].
    lost_fill : str
        Fix columns while no ball is seen after one was: ``zero`` or ``hold`` the last.
    phi_lead_in : float
        For this long after a closed-loop run starts, the rig software logs
        ``phi = atan2(x, y)`` without ``theta`` [s] (a quirk of the NTNU logs; 0: none).
    digits : int
        Significant digits of the logged numbers (C++ ostream default: 6).
    t_start : float
        Logger time of a run's first line [s] (randomised per run around this).
    """

    line_rate: float = 909.0
    line_jitter: float = 0.08
    servo_rate: float = 2000.0
    counts_per_rev: int = 4096 * 4
    velocity_mode: str = "difference"
    velocity_lag: float = 0.004
    torque_shift: float = 0.0
    actuation_delay: float = 0.0005
    camera_rate: float = 190.0
    camera_jitter: float = 2e-4
    camera_latency: float = 0.005
    camera_noise: float = 1.5e-4
    camera_offset: tuple[float, float] = (0.0, 0.0)
    camera_scale: float = 0.0
    camera_rotation: float = 0.0
    lost_fill: str = "zero"
    phi_lead_in: float = 0.0
    digits: int = 6
    t_start: float = 4.1

    def __post_init__(self) -> None:
        checks = (
            ("line_rate", 150.0 <= self.line_rate <= 1000.0),
            ("line_jitter", 0.0 <= self.line_jitter <= 0.3),
            ("servo_rate", self.line_rate <= self.servo_rate <= 20000.0),
            ("counts_per_rev", self.counts_per_rev >= 0),
            ("velocity_mode", self.velocity_mode in VELOCITY_MODES),
            ("velocity_lag", 0.0 <= self.velocity_lag <= 0.02),
            ("torque_shift", abs(self.torque_shift) <= 0.005),
            ("actuation_delay", self.torque_shift <= self.actuation_delay <= 0.02
             and self.actuation_delay >= 0.0),
            ("camera_rate", 100.0 <= self.camera_rate <= 300.0),
            ("camera_jitter", 0.0 <= self.camera_jitter <= 0.1 / self.camera_rate),
            ("camera_latency", 0.0 <= self.camera_latency <= 0.05),
            ("camera_noise", 0.0 <= self.camera_noise <= 0.005),
            ("camera_scale", abs(self.camera_scale) <= 0.1),
            ("camera_rotation", abs(self.camera_rotation) <= 0.1),
            ("lost_fill", self.lost_fill in LOST_FILL),
            ("phi_lead_in", self.phi_lead_in >= 0.0),
            ("digits", 4 <= self.digits <= 17),
            ("t_start", self.t_start >= 0.0),
        )
        for name, ok in checks:
            if not ok:
                raise ValueError(f"sensor convention {name} out of range: "
                                 f"{getattr(self, name)!r}")

    @property
    def velocity_window(self) -> int:
        """Servo samples in the velocity difference (``difference`` mode) [-]."""
        if self.velocity_mode != "difference":
            return 1
        return max(1, round(2.0 * self.velocity_lag * self.servo_rate))

    @property
    def effective_velocity_lag(self) -> float:
        """Low-frequency delay of the logged velocity behind the truth [s] (servo only)."""
        if self.velocity_mode == "true":
            return 0.0
        if self.velocity_mode == "difference":
            return self.velocity_window / (2.0 * self.servo_rate)
        return self.velocity_lag + 0.5 / self.servo_rate

    def encoder(self) -> EncoderConfig:
        """The servo's encoder conventions (``true`` mode: no velocity filter)."""
        return EncoderConfig(counts_per_rev=self.counts_per_rev,
                             velocity_window=self.velocity_window,
                             velocity_filter=self.velocity_lag
                             if self.velocity_mode == "filter" else 0.0)


class Servo:
    """The servo: samples the frame at ``servo_rate``; the log reads its latest sample.

    Parameters
    ----------
    conventions : SensorConventions
        Rates and velocity conventions.
    """

    def __init__(self, conventions: SensorConventions) -> None:
        self.conventions = conventions
        self.encoder = Encoder(conventions.encoder(), 1.0 / conventions.servo_rate)
        self.theta = 0.0
        self.velocity = 0.0

    def sample(self, theta: float, theta_dot: float) -> None:
        """Take a sample of the true angle [rad] and rate [rad/s]."""
        self.theta, velocity = self.encoder.sample(theta)
        self.velocity = theta_dot if self.conventions.velocity_mode == "true" else velocity


class Camera:
    """The rig's ball tracker: fixes of the ball centre in metres, with its own errors.

    A fix of a ball at ``p`` [m] is ``(1 + scale) Rot(rotation) p + offset + n``,
    ``n ~ N(0, noise^2 I)``; none when no ball is in view.

    Parameters
    ----------
    conventions : SensorConventions
        Camera conventions.
    rng : numpy.random.Generator
        Seeded noise source.
    view : float
        Half-size of the field of view [m]; a ball outside gives no fix.
    """

    def __init__(self, conventions: SensorConventions, rng: np.random.Generator,
                 view: float = 0.22) -> None:
        self.c = conventions
        self.rng = rng
        self.view = view
        s = 1.0 + conventions.camera_scale
        self._a = s * math.cos(conventions.camera_rotation)
        self._b = s * math.sin(conventions.camera_rotation)

    def next_period(self) -> float:
        """Time to the next exposure [s]."""
        jitter = self.c.camera_jitter * float(self.rng.standard_normal())
        return max(0.2 / self.c.camera_rate, 1.0 / self.c.camera_rate + jitter)

    def measure(self, x: float, y: float) -> tuple[float, float] | None:
        """The fix of a ball at ``(x, y)`` [m], or None when it is not in view."""
        if not (math.isfinite(x) and math.isfinite(y)) or abs(x) > self.view \
                or abs(y) > self.view:
            return None
        nx, ny = self.rng.normal(0.0, self.c.camera_noise, 2) \
            if self.c.camera_noise > 0 else (0.0, 0.0)
        dx, dy = self.c.camera_offset
        return (self._a * x - self._b * y + dx + nx, self._b * x + self._a * y + dy + ny)
