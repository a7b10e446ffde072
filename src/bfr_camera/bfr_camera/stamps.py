"""A camera driver's frame period from the stamps of the images that reached a node.

Problem. A node sees only the images that arrive: a busy subscriber keeping the newest drops
some, images over Fast DDS's shared-memory segment go in UDP fragments a loaded machine
loses. How many the driver sent is the stamps' span over its period, and the period has to
come from the received stamps themselves, ``t_i = a + n_i T + e_i``: ``n_i`` increasing
integers with gaps where images were missed, ``e_i`` the stamps' jitter (a driver that
stamps at arrival: milliseconds).

Method. Gaps alone cannot do it: a gap is ``k T + e_i - e_(i-1)``, and with a jitter of a
fifth of the period their 10th percentile is already near ``T / 2`` (a probe written apart
had 1 ms of jitter at 200 Hz read as a 3.10 ms period, 60 % received where 94 % were). The
stamps' phase is the better statistic (the Rayleigh test of circular statistics; Mardia &
Jupp 2000, 6.3): the mean resultant ``R(T) = |mean_i exp(2 pi i t_i / T)|`` is
``exp(-2 pi^2 sigma^2 / T^2)`` at the driver's period whatever images are missed (``sigma``
the stamps' jitter), near 0 at a period the stamps do not repeat with (a multiple of T where
every ``n_i`` occurs, or any other), and ``exp(-2 pi^2 m^2 sigma^2 / T^2)`` at a divisor
``T / m``: the jitter itself picks the longest period. It is searched between half the 10th
percentile gap and 1.2 median gaps (a missed image only lengthens gaps; jitter shortens
some): a peak is ``T^2 / span`` wide, so the search runs on the newest 64 stamps with a grid
step of ``T_min^2 / (8 span)``, and each of its five highest peaks is refined on four times
as many stamps within four of the last grid steps, up to :data:`MAX_STAMPS`; of the refined
peaks at least half the highest, the longest period is the driver's (without jitter ``T``
and its divisors tie). A peak is taken only if ``R`` exceeds ``sqrt(20 / N)`` for ``N`` stamps (a
chance peak of uniform phases reaches it with probability ``exp(-20)`` per period tried);
else the stamps jitter too much to tell and none is given.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["MAX_STAMPS", "driver_period"]

#: The newest stamps used (the grid grows with their span).
MAX_STAMPS = 2000


def _resultant(x: NDArray[np.float64], periods: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(T)`` of the times ``x`` [s] for each period [s], in blocks (memory)."""
    out = np.empty(periods.size)
    for a in range(0, periods.size, 512):
        ph = np.outer(2.0 * np.pi / periods[a:a + 512], x)
        out[a:a + 512] = np.hypot(np.cos(ph).mean(axis=1), np.sin(ph).mean(axis=1))
    return out


def _peaks(r: NDArray[np.float64], k: int) -> NDArray[np.intp]:
    """Indices of the ``k`` highest local maxima of ``r`` (its ends count)."""
    inner = np.r_[True, r[1:] >= r[:-1]] & np.r_[r[:-1] >= r[1:], True]
    idx = np.nonzero(inner)[0]
    return idx[np.argsort(r[idx])[::-1][:k]]


def _search(x: NDArray[np.float64], lo: float, hi: float) -> list[tuple[float, float]]:
    """Peaks of ``R`` for periods in ``[lo, hi]`` [s], refined: ``(period, R)`` on all ``x``."""
    m = min(64, x.size)
    starts = [(0.5 * (lo + hi), 0.5 * (hi - lo))]
    while True:
        xs = x[-m:] - x[-m]
        step = lo * lo / (8.0 * max(float(xs[-1]), hi))
        found = []
        for centre, half in starts:
            grid = centre + np.arange(-half, half + step / 2, step)
            grid = grid[grid > 0.0]
            r = _resultant(xs, grid)
            found += [(float(grid[i]), float(r[i])) for i in _peaks(r, 5)]
        found.sort(key=lambda pr: -pr[1])
        if m == x.size:
            return found[:5]
        m = min(4 * m, x.size)
        lo = min(p for p, _ in found[:5])
        starts = [(p, 4.0 * step) for p, _ in found[:5]]


def driver_period(stamps_ns: NDArray[np.int64]) -> float | None:
    """The driver's frame period [s] from received image stamps (module docstring).

    Parameters
    ----------
    stamps_ns : ndarray of int
        Stamps of the received images [ns], any order; repeats are ignored.

    Returns
    -------
    float or None
        The period [s]; None when there are fewer than 10 distinct stamps or their phase
        shows no period (jitter of a third of a period or more).
    """
    t = np.unique(np.asarray(stamps_ns, np.int64))[-MAX_STAMPS:]
    if t.size < 10:
        return None
    x = (t - t[0]).astype(float) * 1e-9
    gaps = np.diff(x)
    lo, hi = 0.5 * float(np.percentile(gaps, 10)), 1.2 * float(np.median(gaps))
    peaks = _search(x, lo, hi)
    floor = math.sqrt(20.0 / t.size)
    best = max(r for _, r in peaks)
    if best < floor:
        return None
    return max(p for p, r in peaks if r >= max(0.5 * best, floor))
