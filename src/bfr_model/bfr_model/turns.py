"""A frame angle reported within one turn, made the accumulating angle the formats mean.

The rig logs, the CSV, the bags and the hardware contract (docs/hardware.md) carry theta
accumulating over turns. A driver that reports it modulo a turn (``[-pi, pi)`` or
``[0, 2 pi)``) jumps by nearly 2 pi at each wrap: the readers' angle gate
(:mod:`bfr_model.io.account`) would take that for a jump no hardware makes, and a controller
for a frame that leapt a turn between two samples. A step is a wrap when it is within a
quarter turn of +-2 pi and both angles lie within one turn of zero; each adds its turn to
every later sample. Pure Python and numpy (the nodes import it).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["TurnUnwrapper", "unwrap_turns"]

#: Largest |angle| [rad] a wrapped encoder reports: one turn (``[0, 2 pi)``), and a margin.
_ONE_TURN = 2.0 * math.pi + 0.1
#: Largest motion [rad] between two samples a wrap may hide when no rate is known.
_STEP_WITHOUT_RATE = 0.5
#: With a rate: the motion must match ``theta_dot dt`` within this [rad] plus half of it.
_STEP_TOLERANCE = 0.1


def _is_wrap(before: float, after: float, expected: float = math.nan) -> int:
    """The turns to add at a step from ``before`` to ``after`` [rad]: -1, 0 or +1.

    A wrap is a step of nearly a whole turn between two angles within one turn of zero (an
    encoder that reports its angle modulo a turn), the rest of the step the frame's own
    motion: ``expected`` [rad] (the rate times the interval) within
    ``_STEP_TOLERANCE + |expected| / 2`` where known, else at most ``_STEP_WITHOUT_RATE``.
    Any other step (a glitch of a sample, a gap) is left to the gates.
    """
    d = after - before
    k = round(d / (2.0 * math.pi))
    if abs(k) != 1 or max(abs(before), abs(after)) > _ONE_TURN:
        return 0
    motion = d - 2.0 * math.pi * k
    if math.isfinite(expected):
        ok = abs(motion - expected) <= _STEP_TOLERANCE + 0.5 * abs(expected)
    else:
        ok = abs(motion) <= _STEP_WITHOUT_RATE
    return -k if ok else 0


def unwrap_turns(theta: NDArray[np.float64], t: NDArray[np.float64] | None = None,
                 theta_dot: NDArray[np.float64] | None = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """The accumulating frame angle of one reported within a turn, and the wraps undone.

    The formats and the hardware contract carry theta accumulating over turns
    (docs/hardware.md); a driver that reports it modulo a turn jumps by nearly 2 pi at each
    wrap, which the angle gate (step 3) would take for a jump no hardware makes and keep
    only the longest stretch between two. Each step between finite samples that
    :func:`_is_wrap` calls a wrap adds its turn to every later sample.

    Parameters
    ----------
    theta : ndarray, shape (n,)
        Frame angle as read [rad] (NaN where missing: skipped).
    t, theta_dot : ndarray, shape (n,), optional
        Time [s] and rate [rad/s]: a step is a wrap only if what is left of it is the motion
        the mean rate over the interval makes (NaN rates: at most ``_STEP_WITHOUT_RATE``).

    Returns
    -------
    (ndarray, ndarray of int)
        The angle with the wraps undone (the input itself when there are none), and the
        index of the first sample after each wrap.
    """
    none = np.zeros(0, np.intp)
    idx = np.nonzero(np.isfinite(theta))[0]
    if idx.size < 2:
        return theta, none
    th = theta[idx]
    d = np.diff(th)
    near = np.abs(np.abs(d) - 2.0 * math.pi) < math.pi / 2
    if not near.any():
        return theta, none
    expected = np.full(d.size, np.nan)
    if t is not None and theta_dot is not None:
        with np.errstate(invalid="ignore"):
            expected = 0.5 * (theta_dot[idx][1:] + theta_dot[idx][:-1]) * np.diff(t[idx])
    turns = np.zeros(d.size)
    for i in np.nonzero(near)[0]:
        turns[i] = _is_wrap(float(th[i]), float(th[i + 1]), float(expected[i]))
    if not turns.any():
        return theta, none
    out = np.array(theta, dtype=np.float64)
    out[idx[1:]] += 2.0 * math.pi * np.cumsum(turns)
    return out, idx[1:][turns != 0]


class TurnUnwrapper:
    """:func:`unwrap_turns` one sample at a time (a node's encoder stream).

    ``unwrapper(theta, t, theta_dot)`` returns the accumulating angle; :attr:`wraps` counts
    the wraps undone so far; ``on_first_wrap()`` is called at the first (a node says it
    once).
    """

    def __init__(self, on_first_wrap: Callable[[], None] | None = None) -> None:
        self.last: tuple[float, float, float] | None = None  # (theta, t, rate) as reported
        self.offset = 0.0               # whole turns added [rad]
        self.wraps = 0
        self.on_first_wrap = on_first_wrap

    def __call__(self, theta: float, t: float = math.nan,
                 theta_dot: float = math.nan) -> float:
        """The accumulating angle [rad] of the next reported ``theta`` [rad].

        ``t`` [s] and ``theta_dot`` [rad/s], where known, make the step's rest the frame's
        motion (:func:`_is_wrap`).
        """
        if not math.isfinite(theta):
            return theta + self.offset
        # a step under half a turn is no wrap (_is_wrap's rounding): the per-sample path
        if self.last is not None and abs(theta - self.last[0]) > math.pi:
            th0, t0, w0 = self.last
            k = _is_wrap(th0, theta, 0.5 * (w0 + theta_dot) * (t - t0))
            if k:
                self.offset += 2.0 * math.pi * k
                self.wraps += 1
                if self.wraps == 1 and self.on_first_wrap is not None:
                    self.on_first_wrap()
        self.last = (theta, t, theta_dot)
        return theta + self.offset
