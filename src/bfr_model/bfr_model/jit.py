"""Optional numba compilation of the physics kernels.

The kernels are written once, in array-style numpy that works on floats and arrays alike.
``njit`` compiles them with numba (scalar hot path: one RK4 step in about a microsecond);
with ``BFR_NO_JIT=1`` in the environment, or without numba installed, the very same Python
functions run uncompiled (slower, identical results).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable)

try:  # pragma: no cover - depends on the environment
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

JIT_ENABLED: bool = _numba is not None and os.environ.get("BFR_NO_JIT", "") in ("", "0")


def njit(fn: F) -> F:
    """Compile ``fn`` with ``numba.njit(cache=True)`` when available, else return it."""
    if not JIT_ENABLED:
        return fn
    return _numba.njit(cache=True)(fn)  # type: ignore[union-attr]


def njit_inline(fn: F) -> F:
    """As :func:`njit`, inlined into compiled callers (numba IR inlining).

    The small geometry kernels take a dozen array arguments; a non-inlined call pays the
    reference counting of each (about 80 ns), more than the arithmetic.
    """
    if not JIT_ENABLED:
        return fn
    return _numba.njit(cache=True, inline="always")(fn)  # type: ignore[union-attr]


def njit_parallel(fn: F) -> F:
    """As :func:`njit`, with ``parallel=True``: ``prange`` loops run on numba's threads.

    For loops over independent samples (each iteration writes only its own outputs). The
    thread count is numba's (``NUMBA_NUM_THREADS``, all cores by default; a process pool
    that is itself the parallelism sets it to 1: :func:`use_one_thread`, or the variable in
    the workers' environment). A pool that forks must do so before the parent has run a
    parallel kernel (GNU OpenMP's threads do not survive a fork). Uncompiled, ``prange`` is
    ``range``.
    """
    if not JIT_ENABLED:
        return fn
    return _numba.njit(cache=True, parallel=True)(fn)  # type: ignore[union-attr]


def use_one_thread() -> None:
    """Run this process's :func:`njit_parallel` kernels on one thread.

    For the workers of a process pool, which is itself the parallelism (numba's OpenMP
    threads in every worker would oversubscribe the cores). Nothing without numba.
    """
    if JIT_ENABLED:
        _numba.set_num_threads(1)  # type: ignore[union-attr]


def prange(*args: int) -> range:
    """``numba.prange`` inside :func:`njit_parallel` kernels; ``range`` when uncompiled."""
    return range(*args)


if JIT_ENABLED:  # pragma: no cover - depends on the environment
    prange = _numba.prange  # type: ignore[assignment,union-attr]
