"""Integrators, separate from the models and selectable.

- :func:`rk4_steps` / :func:`rk4_trajectory`: classical fixed-step Runge-Kutta 4, compiled
  together with the model's right-hand side (the live simulator node's integrator: about a
  microsecond per step for the rigid model). Global error O(dt^4).
- :func:`solve_adaptive`: scipy's adaptive/implicit solvers (DOP853 for smooth non-stiff
  problems, Radau/BDF/LSODA for stiff ones such as the contact model), for analysis.

A right-hand side has the signature ``rhs(t, x, args) -> dx`` (numba-compiled for the fixed
step path), with ``args`` a tuple that holds the command and the model constants.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from bfr_model.jit import njit

__all__ = ["IntegrationError", "rk4_steps", "rk4_trajectory", "solve_adaptive"]

FloatArray = NDArray[np.float64]


class IntegrationError(RuntimeError):
    """An integration failed (solver error or a non-finite state)."""


@njit
def rk4_steps(rhs, x0, t0, dt, n, args):  # noqa: ANN001, ANN201
    """Advance ``x0`` by ``n`` RK4 steps of ``dt`` from ``t0``; return the final state."""
    x = x0.copy()
    t = t0
    h2 = 0.5 * dt
    for _ in range(n):
        k1 = rhs(t, x, args)
        k2 = rhs(t + h2, x + h2 * k1, args)
        k3 = rhs(t + h2, x + h2 * k2, args)
        k4 = rhs(t + dt, x + dt * k3, args)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t = t + dt
    return x


@njit
def rk4_trajectory(rhs, x0, t0, dt, n, args):  # noqa: ANN001, ANN201
    """As :func:`rk4_steps`, returning all ``n + 1`` states, shape (n + 1, len(x0))."""
    out = np.empty((n + 1, x0.shape[0]))
    out[0] = x0
    x = x0.copy()
    t = t0
    h2 = 0.5 * dt
    for i in range(n):
        k1 = rhs(t, x, args)
        k2 = rhs(t + h2, x + h2 * k1, args)
        k3 = rhs(t + h2, x + h2 * k2, args)
        k4 = rhs(t + dt, x + dt * k3, args)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t = t + dt
        out[i + 1] = x
    return out


def solve_adaptive(rhs: Callable, x0: FloatArray, t_span: tuple[float, float],
                   args: tuple | Callable[[float], tuple], t_eval: FloatArray | None = None,
                   method: str = "DOP853", rtol: float = 1e-11, atol: float = 1e-12,
                   max_step: float = np.inf) -> tuple[FloatArray, FloatArray]:
    """Integrate with a scipy adaptive (or implicit) method.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, x, args)``.
    x0 : ndarray
        Initial state.
    t_span : tuple of float
        Start and end time [s].
    args : tuple or callable
        Constant ``args``, or ``args(t)`` for a time-varying command.
    t_eval : ndarray, optional
        Output times; default: the solver's own steps.
    method : str
        Any ``scipy.integrate.solve_ivp`` method ("DOP853", "RK45", "Radau", "BDF", "LSODA").
    rtol, atol, max_step : float
        Tolerances and the largest step [s].

    Returns
    -------
    t, x : ndarray
        Times, shape (n,), and states, shape (n, len(x0)).

    Raises
    ------
    IntegrationError
        If the solver fails.
    """
    if callable(args):
        def f(t: float, x: FloatArray) -> FloatArray:
            return rhs(t, x, args(t))
    else:
        def f(t: float, x: FloatArray) -> FloatArray:
            return rhs(t, x, args)
    sol = solve_ivp(f, t_span, np.asarray(x0, float), method=method, t_eval=t_eval,
                    rtol=rtol, atol=atol, max_step=max_step)
    if not sol.success:
        raise IntegrationError(f"{method} failed at t = {sol.t[-1]:.6g} s: {sol.message}")
    return sol.t, sol.y.T
