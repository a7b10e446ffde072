"""Open-loop simulation of the rigid model (the core of ``bfr simulate``, bfr_sim.simulate_cli).

From an initial state under a torque command that is constant or read from a CSV of
``(t, u)`` rows (zero-order hold, as a digital controller applies it): :func:`simulate`
returns a :class:`SimResult`; :func:`write_csv` writes it in the documented columns.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bfr_model.dynamics import RigidModel, rigid_rhs
from bfr_model.integrators import IntegrationError, solve_adaptive

__all__ = ["CSV_COLUMNS", "SimResult", "simulate", "torque_from_csv", "write_csv"]

FloatArray = NDArray[np.float64]

CSV_COLUMNS = ("t", "theta", "theta_dot", "phi", "phi_dot", "ball_x", "ball_y", "torque",
               "kinetic", "potential", "energy")


@dataclass
class SimResult:
    """A simulated trajectory.

    Attributes
    ----------
    t : ndarray
        Times [s], shape (n,).
    x : ndarray
        States ``[theta, phi, theta_dot, phi_dot, W_in, W_diss]``, shape (n, 6)
        ([rad, rad, rad/s, rad/s, J, J]).
    u : ndarray
        Commanded torque held over the step that starts at t [N m].
    kinetic, potential : ndarray
        Energies [J].
    ball : ndarray
        Ball centre in the world frame, shape (n, 2) [m].
    normal_force : ndarray
        Normal force of the frame on the ball [N]; < 0 means the ball would leave the frame.
    wall_time : float
        Integration wall time [s].
    steps : int
        Integrator steps taken.
    info : dict
        Method, step size, notes.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    kinetic: FloatArray
    potential: FloatArray
    ball: FloatArray
    normal_force: FloatArray
    wall_time: float
    steps: int
    info: dict = field(default_factory=dict)

    @property
    def energy(self) -> FloatArray:
        """Total mechanical energy T + V [J]."""
        return self.kinetic + self.potential

    @property
    def energy_drift_rel(self) -> float:
        """Largest violation of the energy balance ``E(t) - E(0) = W_in - W_diss``, relative.

        Divided by ``max(|E(0)|, max T)`` so that it measures the integration error whatever
        the motor and the losses did (for u = 0 and no losses it is the relative drift of E).
        """
        e = self.energy
        balance = e - e[0] - (self.x[:, 4] - self.x[:, 5])
        scale = max(abs(float(e[0])), float(np.max(self.kinetic)), 1e-300)
        return float(np.max(np.abs(balance)) / scale)

    @property
    def left_frame_at(self) -> float | None:
        """First time the normal force turned negative [s], or None if the ball stayed on."""
        bad = np.nonzero(self.normal_force < 0.0)[0]
        return float(self.t[bad[0]]) if bad.size else None

    def summary(self) -> dict:
        """JSON-ready summary of the run."""
        left = self.left_frame_at
        return {
            "duration": float(self.t[-1] - self.t[0]),
            "steps": int(self.steps),
            "energy_drift_rel": self.energy_drift_rel,
            "ball_on_frame": left is None,
            "left_frame_at": left,
            "min_normal_force": float(np.min(self.normal_force)),
            "wall_time": self.wall_time,
            "real_time_factor": float((self.t[-1] - self.t[0]) / max(self.wall_time, 1e-12)),
            "final_state": {k: float(v) for k, v in
                            zip(("theta", "phi", "theta_dot", "phi_dot"), self.x[-1, :4],
                                strict=True)},
            **self.info,
        }


def simulate(model: RigidModel, x0: FloatArray, duration: float,
             torque: Callable[[float], float] | float = 0.0, dt: float = 1e-3,
             integrator: str = "rk4", rtol: float = 1e-11, atol: float = 1e-12) -> SimResult:
    """Simulate the rigid model open loop.

    Parameters
    ----------
    model : RigidModel
        The model.
    x0 : array_like
        Initial ``[theta, phi, theta_dot, phi_dot]`` [rad, rad, rad/s, rad/s].
    duration : float
        Simulated time [s].
    torque : float or callable
        Commanded torque [N m], constant or ``u(t)``, held over each step of ``dt``.
    dt : float
        Step (rk4) or output/hold interval (adaptive) [s].
    integrator : str
        ``"rk4"`` (fixed step, compiled) or a scipy method name (``"DOP853"``, ``"Radau"``...).
    rtol, atol : float
        Tolerances of the adaptive path.

    Returns
    -------
    SimResult
    """
    if not np.isfinite(duration) or duration <= 0.0:
        raise ValueError(f"duration must be a positive number of seconds, got {duration}")
    if not np.isfinite(dt) or dt <= 0.0:
        raise ValueError(f"dt must be a positive number of seconds, got {dt}")
    x0 = np.asarray(x0, float)
    if x0.shape != (4,) or not np.all(np.isfinite(x0)):
        raise ValueError(f"initial state must be 4 finite numbers, got {x0}")
    u_of_t = torque if callable(torque) else (lambda _t, _u=float(torque): _u)
    n = round(duration / dt)
    t = np.arange(n + 1) * dt
    u = np.array([float(u_of_t(ti)) for ti in t])
    if not np.all(np.isfinite(u)):
        raise ValueError("torque input produced a non-finite value")
    x0 = model.state(x0)  # a creeping spin (ball.creep_time) is a seventh state
    x = np.empty((n + 1, x0.size))
    x[0] = x0
    steps = n
    start = time.perf_counter()
    if integrator == "rk4":
        for i in range(n):
            x[i + 1] = model.step(x[i], u[i], dt, 1, t[i])
    else:
        steps = 0
        for i in range(n):  # the command is piecewise constant: integrate each hold exactly
            _, xs = solve_adaptive(rigid_rhs, x[i], (t[i], t[i + 1]), model.rhs_args(u[i]),
                                   t_eval=np.array([t[i + 1]]), method=integrator, rtol=rtol,
                                   atol=atol)
            x[i + 1] = xs[-1]
            steps += 1
    wall = time.perf_counter() - start
    if not np.all(np.isfinite(x)):
        bad = int(np.argmax(~np.all(np.isfinite(x), axis=1)))
        raise IntegrationError(f"state became non-finite at t = {t[bad]:.6g} s")
    kin, pot = model.energy(x)
    fn = model.normal_force(x, u)
    return SimResult(t=t, x=x, u=u, kinetic=kin, potential=pot, ball=model.ball_position(x),
                     normal_force=fn, wall_time=wall, steps=steps,
                     info={"integrator": integrator, "dt": dt})


def torque_from_csv(path: str | Path) -> Callable[[float], float]:
    """Zero-order-hold torque input from a CSV of ``t, u`` rows ([s], [N m]).

    A header row is allowed; times must increase; before the first row the command is the
    first value, after the last row the last value.
    """
    p = Path(path)
    try:
        rows = np.genfromtxt(p, delimiter=",", comments="#", dtype=float, invalid_raise=True)
    except (OSError, ValueError) as exc:
        raise ValueError(f"torque CSV {p}: {exc}") from exc
    rows = np.atleast_2d(rows)
    if rows.size and np.all(np.isnan(rows[0])):
        rows = rows[1:]  # header
    if rows.ndim != 2 or rows.shape[1] < 2 or rows.shape[0] == 0:
        raise ValueError(f"torque CSV {p}: expected rows 't, u', got shape {rows.shape}")
    tt, uu = rows[:, 0], rows[:, 1]
    if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(uu))):
        raise ValueError(f"torque CSV {p}: non-numeric or non-finite value in row "
                         f"{int(np.argmax(~(np.isfinite(tt) & np.isfinite(uu)))) + 1}")
    if np.any(np.diff(tt) <= 0.0):
        raise ValueError(f"torque CSV {p}: times must strictly increase")

    def u_of_t(ti: float) -> float:
        i = int(np.searchsorted(tt, ti, side="right")) - 1
        return float(uu[max(i, 0)])

    return u_of_t


def write_csv(path: Path, res: SimResult) -> None:
    """Write the trajectory in the documented column order (:data:`CSV_COLUMNS`)."""
    cols = np.column_stack([res.t, res.x[:, 0], res.x[:, 2], res.x[:, 1], res.x[:, 3],
                            res.ball[:, 0], res.ball[:, 1], res.u, res.kinetic,
                            res.potential, res.energy])
    np.savetxt(path, cols, delimiter=",", header=",".join(CSV_COLUMNS), comments="",
               fmt="%.12g")
