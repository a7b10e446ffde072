"""Sensors of the independent rig: encoder and servo velocity (numpy only, written apart from bfr).

The servo reports the frame angle from a quantised encoder and a velocity that is a
difference of quantised angles over a window of samples (a delay of half the window),
optionally low-passed by a first-order filter. Each rig of the design may time these
differently; every convention is a parameter and goes into the truth sidecar.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


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
