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


def _is_wrap(before: float, after: float) -> int:
    """The turns to add at a step from ``before`` to ``after`` [rad]: -1, 0 or +1.

    A wrap is a step of nearly a whole turn (within a quarter turn of +-2 pi) between two
    angles within one turn of zero (an encoder that reports its angle modulo a turn); any
    other step is left to the gates.
    """
    d = after - before
    k = round(d / (2.0 * math.pi))
    if abs(k) != 1 or abs(d - 2.0 * math.pi * k) >= math.pi / 2:
        return 0
    return -k if max(abs(before), abs(after)) <= _ONE_TURN else 0


def unwrap_turns(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
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
    turns = np.zeros(d.size)
    for i in np.nonzero(near)[0]:
        turns[i] = _is_wrap(float(th[i]), float(th[i + 1]))
    if not turns.any():
        return theta, none
    out = np.array(theta, dtype=np.float64)
    out[idx[1:]] += 2.0 * math.pi * np.cumsum(turns)
    return out, idx[1:][turns != 0]


class TurnUnwrapper:
    """:func:`unwrap_turns` one sample at a time (a node's encoder stream).

    ``unwrapper(theta)`` returns the accumulating angle; :attr:`wraps` counts the wraps
    undone so far; ``on_first_wrap()`` is called at the first (a node says it once).
    """

    def __init__(self, on_first_wrap: Callable[[], None] | None = None) -> None:
        self.last: float | None = None  # the last angle as reported [rad]
        self.offset = 0.0               # whole turns added [rad]
        self.wraps = 0
        self.on_first_wrap = on_first_wrap

    def __call__(self, theta: float) -> float:
        """The accumulating angle [rad] of the next reported ``theta`` [rad]."""
        if self.last is not None and math.isfinite(theta):
            k = _is_wrap(self.last, theta)
            if k:
                self.offset += 2.0 * math.pi * k
                self.wraps += 1
                if self.wraps == 1 and self.on_first_wrap is not None:
                    self.on_first_wrap()
        if math.isfinite(theta):
            self.last = theta
        return theta + self.offset
