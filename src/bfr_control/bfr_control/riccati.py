"""Gains K(phi) from the periodic Riccati equation of the transverse linearisation.

The transverse linearisation (bfr_control.transverse) along the orbit,
``x_dot = A(t) x + B(t) w`` with ``x = [I, y, y_dot]``, is T-periodic. The gains minimise
``int (x^T Q x + Gamma w^2) dt`` over an infinite horizon: ``w = K x``, ``K = -Gamma^-1 B^T X``,
with X the periodic, stabilising solution of the differential Riccati equation
(Shiriaev, Freidovich, Gusev, IEEE TAC 2010, section IV; Bittanti, Colaneri, De Nicolao)

    -dX/dt = A^T X + X A + Q - X B Gamma^-1 B^T X.                                       (1)

Along the orbit ``dt = dphi / phi_dot*(phi)``, so in the contact angle

    dX/dphi = -(A^T X + X A + Q - X B Gamma^-1 B^T X) / phi_dot*(phi).                     (2)

(2) is integrated backwards in phi (classical RK4 on the orbit's grid, A and B evaluated
exactly at the nodes and half-nodes) period after period, starting from the algebraic
Riccati solution of the period-averaged system, until X(0) repeats to a relative tolerance:
the backward iteration converges to the stabilising periodic solution. Stability is then
checked directly: the monodromy matrix of ``x_dot = (A + B K) x`` over one period must have
spectral radius < 1.

Weights. w = y_ddot acts on a double integrator in (y, y_dot); on its own, LQR with
``Q = diag(q_I, q_y, q_ydot)`` gives ``k_y = -sqrt(q_y / Gamma)``,
``k_ydot = -sqrt(q_ydot / Gamma + 2 sqrt(q_y / Gamma))``, so ``Gamma = 1, q_y = 1e4,
q_ydot = 89`` aims at the rig's ``k_y ~ -100, k_ydot ~ -17`` (natural frequency 10 rad/s,
damping 0.85); q_I sets how fast the ball's speed returns to the orbit. The coupling through
I shifts them by a few percent (see the gain ranges printed by ``bfr control-eval``).

Gains are cached in ``$BFR_CACHE_DIR`` (default ``~/.cache/bfr``) as ``.npz`` files keyed by
a hash of every input (model parameters, constraint, orbit, weights, grid, algorithm
version); the file stores those inputs and is recomputed whenever they differ.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from bfr_model.param_file import integer, positive
from bfr_model.params import params_to_dict
from numpy.typing import NDArray
from scipy.linalg import solve_continuous_are

from bfr_control.orbit import PeriodicOrbit
from bfr_control.periodic import PeriodicTable
from bfr_control.transverse import transverse_linearization

__all__ = ["GainTable", "RiccatiWeights", "cache_dir", "compute_gains", "monodromy",
           "solve_periodic_riccati"]

FloatArray = NDArray[np.float64]

ALGORITHM_VERSION = 1  # bump when the computation changes: invalidates cached gains


@dataclass(frozen=True)
class RiccatiWeights:
    """Weights of the transverse LQR cost ``int (x^T Q x + Gamma w^2) dt``.

    Attributes
    ----------
    q_I : float
        Weight on I [(s/rad)^4].
    q_y : float
        Weight on y [1/rad^2].
    q_y_dot : float
        Weight on y_dot [s^2/rad^2].
    gamma : float
        Weight on w = y_ddot [s^4/rad^2].
    tol : float
        Relative periodicity tolerance of X.
    max_periods : int
        Most backward periods before giving up.
    """

    q_I: float = 0.3  # noqa: N815 (the literature's I)
    q_y: float = 1.0e4
    q_y_dot: float = 89.0
    gamma: float = 1.0
    tol: float = 1e-10
    max_periods: int = 400

    def __post_init__(self) -> None:
        for name in ("q_I", "q_y", "q_y_dot", "gamma", "tol"):
            positive(f"riccati.{name}", getattr(self, name))
        integer("riccati.max_periods", self.max_periods, minimum=1)

    @property
    def q_matrix(self) -> FloatArray:
        """diag(q_I, q_y, q_y_dot)."""
        return np.diag([self.q_I, self.q_y, self.q_y_dot])

    def to_json(self) -> str:
        """Canonical JSON (cache keys)."""
        return json.dumps(asdict(self), sort_keys=True)


def _rk4_backward(X: FloatArray, A: FloatArray, B: FloatArray, s: FloatArray, Q: FloatArray,
                  gamma: float, h: float, store: FloatArray | None) -> FloatArray:
    """One period of (2) backwards from phi = P to 0.

    A, B, s (= 1/phi_dot*) are given on the half-grid ``phi_k = k h / 2``, k = 0..2N.
    """
    n = (A.shape[0] - 1) // 2
    ig = 1.0 / gamma

    def f(X: FloatArray, k: int) -> FloatArray:
        XB = X @ B[k]
        AX = A[k].T @ X
        return -(AX + AX.T + Q - ig * np.outer(XB, XB)) * s[k]

    for j in range(n, 0, -1):
        k1 = f(X, 2 * j)
        k2 = f(X - 0.5 * h * k1, 2 * j - 1)
        k3 = f(X - 0.5 * h * k2, 2 * j - 1)
        k4 = f(X - h * k3, 2 * j - 2)
        X = X - (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        X = 0.5 * (X + X.T)
        if store is not None:
            store[j - 1] = X
    return X


def solve_periodic_riccati(orbit: PeriodicOrbit, weights: RiccatiWeights
                           ) -> tuple[FloatArray, FloatArray, dict]:
    """Periodic stabilising solution of (2) on the orbit's grid.

    Returns
    -------
    X : ndarray
        Riccati solution at the grid points, shape (N, 3, 3).
    K : ndarray
        Gains ``-Gamma^-1 B^T X`` at the grid points, shape (N, 3).
    info : dict
        ``periods`` iterated, ``periodicity`` (relative change of X(0) over the last period).
    """
    P = orbit.period
    n = orbit.phi.shape[0]
    h = P / n
    half = np.arange(2 * n + 1) * (h / 2.0)
    A, B = transverse_linearization(orbit, half)
    s = 1.0 / orbit.phi_dot(half)
    Q = weights.q_matrix
    # start: algebraic Riccati solution of the time-averaged system (dt = s dphi)
    Abar = np.sum(A[:-1] * s[:-1, None, None], axis=0) / np.sum(s[:-1])
    Bbar = np.sum(B[:-1] * s[:-1, None], axis=0) / np.sum(s[:-1])
    try:
        X = solve_continuous_are(Abar, Bbar[:, None], Q, np.array([[weights.gamma]]))
    except (np.linalg.LinAlgError, ValueError):
        X = np.eye(3) * float(np.max(np.diag(Q)))
    change = math.inf
    periods = 0
    while periods < weights.max_periods:
        X0 = _rk4_backward(X, A, B, s, Q, weights.gamma, h, None)
        periods += 1
        change = float(np.max(np.abs(X0 - X)) / np.max(np.abs(X0)))
        X = X0
        if not np.all(np.isfinite(X)):
            raise ArithmeticError("periodic Riccati equation diverged")
        if change < weights.tol:
            break
    else:
        raise ArithmeticError(f"periodic Riccati equation did not converge in "
                              f"{weights.max_periods} periods (last change {change:.3g})")
    store = np.empty((n, 3, 3))
    XP = _rk4_backward(X, A, B, s, Q, weights.gamma, h, store)
    store[0] = XP
    Bg = B[0:2 * n:2]
    K = -np.einsum("ni,nij->nj", Bg, store) / weights.gamma
    return store, K, {"periods": periods, "periodicity": change}


def monodromy(orbit: PeriodicOrbit, gains: PeriodicTable, open_loop: bool = False
              ) -> FloatArray:
    """Monodromy matrix of ``x_dot = (A + B K) x`` over one period (RK4 on the half-grid)."""
    P = orbit.period
    n = orbit.phi.shape[0]
    h = P / n
    half = np.arange(2 * n + 1) * (h / 2.0)
    A, B = transverse_linearization(orbit, half)
    s = 1.0 / orbit.phi_dot(half)
    if not open_loop:
        K = gains.evaluate(half)
        A = A + B[:, :, None] * K[:, None, :]
    F = A * s[:, None, None]
    X = np.eye(3)
    for j in range(n):
        k1 = F[2 * j] @ X
        k2 = F[2 * j + 1] @ (X + 0.5 * h * k1)
        k3 = F[2 * j + 1] @ (X + 0.5 * h * k2)
        k4 = F[2 * j + 2] @ (X + h * k3)
        X = X + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return X


def cache_dir() -> Path:
    """Gain cache folder: ``$BFR_CACHE_DIR`` or ``~/.cache/bfr``."""
    env = os.environ.get("BFR_CACHE_DIR", "")
    return Path(env) if env else Path.home() / ".cache" / "bfr"


class GainTable:
    """Tabulated gains ``K(phi) = [k_I, k_y, k_ydot]`` with periodic interpolation.

    Attributes
    ----------
    phi : ndarray
        Grid [rad].
    K : ndarray
        Gains on the grid, shape (N, 3) ([s^2/rad^2 ... ] so that ``w = K [I, y, y_dot]``
        is in rad/s^2).
    X : ndarray
        Riccati solution on the grid, shape (N, 3, 3).
    table : PeriodicTable
        Interpolant of K.
    info : dict
        How they were obtained (periods, periodicity, monodromy, cache hit or miss, file).
    """

    def __init__(self, period: float, phi: FloatArray, K: FloatArray, X: FloatArray,
                 info: dict) -> None:
        self.period = period
        self.phi = phi
        self.K = K
        self.X = X
        self.info = info
        self.table = PeriodicTable(period, K, names=("k_I", "k_y", "k_y_dot"))

    def __call__(self, phi: float) -> FloatArray:
        """K at one scalar phi, shape (3,)."""
        return self.table(phi)

    def ranges(self) -> dict:
        """Min and max of each gain over the period."""
        return {name: [float(self.K[:, i].min()), float(self.K[:, i].max())]
                for i, name in enumerate(("k_I", "k_y", "k_y_dot"))}


def _cache_inputs(orbit: PeriodicOrbit, weights: RiccatiWeights) -> str:
    return json.dumps({
        "algorithm_version": ALGORITHM_VERSION,
        "params": params_to_dict(orbit.model.params),
        "constraint": json.loads(orbit.constraint.spec.to_json()),
        "orbit": json.loads(orbit.spec.to_json()),
        "weights": json.loads(weights.to_json()),
    }, sort_keys=True)


def compute_gains(orbit: PeriodicOrbit, weights: RiccatiWeights | None = None,
                  use_cache: bool = True, directory: Path | None = None) -> GainTable:
    """Gains for an orbit, from the cache when its inputs match, else solved and cached.

    Parameters
    ----------
    orbit : PeriodicOrbit
        The orbit (carries the model, constraint and orbit spec).
    weights : RiccatiWeights, optional
        LQR weights (defaults: module docstring).
    use_cache : bool
        Read and write the cache.
    directory : Path, optional
        Cache folder (default :func:`cache_dir`).
    """
    weights = weights or RiccatiWeights()
    inputs = _cache_inputs(orbit, weights)
    key = hashlib.sha256(inputs.encode()).hexdigest()[:20]
    folder = directory if directory is not None else cache_dir()
    path = folder / f"gains_{key}.npz"
    if use_cache and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as d:
                if str(d["inputs"]) == inputs:
                    info = json.loads(str(d["info"]))
                    info.update(cache="hit", cache_file=str(path))
                    return GainTable(orbit.period, d["phi"], d["K"], d["X"], info)
        except (OSError, ValueError, KeyError):
            pass  # unreadable or foreign file: recompute and overwrite
    X, K, info = solve_periodic_riccati(orbit, weights)
    table = GainTable(orbit.period, orbit.phi.copy(), K, X, info)
    mono = monodromy(orbit, table.table)
    mono_open = monodromy(orbit, table.table, open_loop=True)
    info["monodromy_spectral_radius"] = float(np.max(np.abs(np.linalg.eigvals(mono))))
    info["open_loop_spectral_radius"] = float(np.max(np.abs(np.linalg.eigvals(mono_open))))
    info["ranges"] = table.ranges()
    info["cache"] = "miss"
    if use_cache:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
            np.savez(tmp, phi=orbit.phi, K=K, X=X, inputs=np.array(inputs),
                     info=np.array(json.dumps(info)))
            tmp.replace(path)
            info["cache_file"] = str(path)
        except OSError as exc:
            info["cache_error"] = str(exc)
    return table
