"""Reduced dynamics on the virtual constraint and the periodic orbit phi_dot*(phi).

The rigid model (bfr_model.dynamics) reads ``M(phi) q_ddot + c(q, q_dot) + G(q) = [u, 0]`` with
``c = [M11' th' ph' + M12' ph'^2, -1/2 M11' th'^2 + 1/2 M22' ph'^2]``. On the constraint
``theta = Theta(phi)``: ``theta_dot = Theta' phi_dot``, ``theta_ddot = Theta' phi_ddot +
Theta'' phi_dot^2``, and the passive (second) row becomes the reduced dynamics
(Shiriaev, Perram, Canudas-de-Wit, IEEE TAC 2005, eq. 9; seed section 4.3):

    alpha(phi) phi_ddot + beta(phi) phi_dot^2 + gamma(phi) = 0,
    alpha = M21 Theta' + M22,
    beta  = M21 Theta'' - 1/2 M11' Theta'^2 + 1/2 M22',
    gamma = G2(Theta(phi), phi).

With ``Y(phi) = phi_dot^2`` and ``d/dt = phi_dot d/dphi`` this is linear in Y,

    dY/dphi = -2 (beta/alpha) Y - 2 gamma/alpha,                                      (1)

solved in closed form: with ``b(phi) = int_0^phi 2 beta/alpha`` and ``Phi = exp(-b)``,

    Y(phi) = Phi(phi) [Y(0) + J(phi)],   J(phi) = int_0^phi exp(b) (-2 gamma/alpha) ds.     (2)

A periodic orbit needs ``Y(P) = Y(0)``, ``Y(0) (1 - Phi(P)) = Phi(P) J(P)``:

- ``b(P) != 0``: one isolated periodic orbit, ``Y(0) = Phi(P) J(P) / (1 - Phi(P))``;
- ``b(P) = 0`` and ``J(P) = 0``: a one-parameter family (the integral of motion closes over a
  period); the member is picked by its speed. The rig's constraint is of this kind: the
  frame is symmetric and Theta odd (``Theta(-phi) = -Theta(phi)``), so alpha is even and beta,
  gamma are odd and both integrals vanish over a period (reversibility);
- ``b(P) = 0`` and ``J(P) != 0``: the ball gains or loses the same energy every period, no
  periodic orbit.

A valid orbit has ``alpha != 0`` (the reduced dynamics are regular) and ``Y > 0`` (the ball
never stops or turns back) everywhere. Integrals are spectral (bfr_control.periodic).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np
from bfr_model.dynamics import RigidModel, mass_terms, rigid_terms
from bfr_model.param_file import check, integer, positive
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from bfr_control.constraint import VirtualConstraint
from bfr_control.periodic import PeriodicTable, periodic_integral, spectral_derivative

__all__ = ["OrbitError", "OrbitSpec", "PeriodicOrbit", "reduced_dynamics"]

FloatArray = NDArray[np.float64]


class OrbitError(ValueError):
    """The constraint has no usable periodic orbit; the message names the reason."""


@dataclass(frozen=True)
class OrbitSpec:
    """Which member of the orbit family, and the grid it is tabulated on.

    Attributes
    ----------
    mean_phi_dot : float or None
        Mean contact-angle rate ``P / T`` [rad/s] (T: time of one period P in phi).
    phi_dot_0 : float or None
        Or: phi_dot at phi = 0 [rad/s]. Exactly one of the two is set.
    grid : int
        Samples per period (even).
    """

    mean_phi_dot: float | None = 2.4
    phi_dot_0: float | None = None
    grid: int = 2048

    def __post_init__(self) -> None:
        check((self.mean_phi_dot is None) != (self.phi_dot_0 is None),
              "orbit.mean_phi_dot/phi_dot_0", "set exactly one of the two")
        if self.mean_phi_dot is not None:
            positive("orbit.mean_phi_dot", self.mean_phi_dot)
        else:
            positive("orbit.phi_dot_0", self.phi_dot_0)
        integer("orbit.grid", self.grid, minimum=64)
        check(self.grid % 2 == 0, "orbit.grid", f"must be even, got {self.grid!r}")

    def to_json(self) -> str:
        """Canonical JSON (cache keys)."""
        return json.dumps(asdict(self), sort_keys=True)


def reduced_dynamics(model: RigidModel, constraint: VirtualConstraint, phi: ArrayLike
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(alpha, beta, gamma)`` of the reduced dynamics at phi (module docstring).

    Units: alpha [kg m^2], beta [kg m^2 / rad], gamma [N m]; from the model's own M, M', G.
    """
    phi = np.asarray(phi, float)
    th0, th1, th2 = constraint.evaluate(phi)
    _, m12, m22, dm11, _, dm22 = mass_terms(phi, *model.kernel_args)
    alpha = m12 * th1 + m22
    beta = m12 * th2 - 0.5 * dm11 * th1 * th1 + 0.5 * dm22
    gamma = model.gravity_vector(th0, phi)[..., 1]
    return alpha, beta, gamma


class PeriodicOrbit:
    """The periodic solution ``Y(phi) = phi_dot*(phi)^2`` of the reduced dynamics.

    Parameters
    ----------
    model : RigidModel
        The controller's model.
    constraint : VirtualConstraint
        The virtual constraint.
    spec : OrbitSpec
        Member and grid.

    Attributes
    ----------
    period : float
        P [rad], the period in phi.
    phi : ndarray
        Grid ``phi_j = j P / N`` [rad].
    Y, dY : ndarray
        ``phi_dot*^2`` [rad^2/s^2] and its phi-derivative on the grid.
    alpha, beta, gamma : ndarray
        Reduced dynamics on the grid.
    theta, theta1, theta2 : ndarray
        Theta, Theta', Theta'' on the grid.
    tau : ndarray
        Time along the orbit from phi = 0 [s], ``tau(phi) = int_0^phi ds / sqrt(Y)``.
    time_period : float
        T [s], time to advance P in phi.
    kind : str
        ``"family"`` (one-parameter family, member chosen by speed) or ``"isolated"``.
    table : PeriodicTable
        Channels ``Theta, Theta1, Theta2, Y`` for the control loop.
    """

    def __init__(self, model: RigidModel, constraint: VirtualConstraint,
                 spec: OrbitSpec | None = None) -> None:
        spec = spec or OrbitSpec()
        self.model = model
        self.constraint = constraint
        self.spec = spec
        P = constraint.period
        n = spec.grid
        self.period = P
        phi = np.arange(n) * (P / n)
        self.phi = phi
        alpha, beta, gamma = reduced_dynamics(model, constraint, phi)
        self.alpha, self.beta, self.gamma = alpha, beta, gamma
        if not (np.all(alpha > 0.0) or np.all(alpha < 0.0)):
            j = int(np.argmin(np.abs(alpha)))
            raise OrbitError(f"alpha(phi) = M21 Theta' + M22 changes sign near phi = "
                             f"{phi[j]:.4f} rad: the reduced dynamics are singular there; "
                             f"choose a smaller |c| or other constraint terms")
        f1 = 2.0 * beta / alpha
        b, bP = periodic_integral(f1, P)
        scale = float(np.sum(np.abs(f1)) * P / n)
        m = bP / P
        bper = b - m * phi
        J, JP = periodic_integral(np.exp(bper) * (-2.0 * gamma / alpha), P, growth=m)
        Phi = np.exp(-b)
        PhiP = math.exp(-bP)
        if abs(bP) <= 1e-9 * max(scale, 1.0):
            jscale = float(np.max(np.abs(J)))
            if abs(JP) > 1e-7 * max(jscale, 1e-300):
                raise OrbitError(
                    "no periodic orbit: over one period the reduced dynamics are conservative "
                    f"in the speed term (int 2 beta/alpha = {bP:.3g}) but gravity does net "
                    f"work (J(P) = {JP:.4g} rad^2/s^2), so phi_dot^2 changes by the same "
                    "amount every period")
            self.kind = "family"
            y0min = float(np.max(-J))
            self._Phi, self._J = Phi, J
            y0 = self._pick_member(y0min)
        else:
            self.kind = "isolated"
            y0 = PhiP * JP / (1.0 - PhiP)
        Y = Phi * (y0 + J)
        if not np.all(Y > 0.0):
            j = int(np.argmin(Y))
            raise OrbitError(f"the orbit has phi_dot^2 = {Y[j]:.4g} <= 0 at phi = {phi[j]:.4f} "
                             "rad: the ball would stop and turn back (ask for a faster orbit or "
                             "another constraint)")
        self.Y0 = float(y0)
        self.Y = Y
        self.dY = -f1 * Y - 2.0 * gamma / alpha  # eq. (1), exact on the grid
        tau, T = periodic_integral(1.0 / np.sqrt(Y), P)
        self.tau = tau
        self.time_period = T
        th0, th1, th2 = constraint.evaluate(phi)
        self.theta, self.theta1, self.theta2 = th0, th1, th2
        th3 = spectral_derivative(th2, P)
        self.table = PeriodicTable(
            P, np.column_stack([th0, th1, th2, Y]),
            derivatives=np.column_stack([th1, th2, th3, self.dY]),
            drift=[1.0, 0.0, 0.0, 0.0], names=("Theta", "Theta1", "Theta2", "Y"))

    def _pick_member(self, y0min: float) -> float:
        """Y(0) of the family member with the requested speed (bisection on a monotone map)."""
        spec = self.spec
        if spec.phi_dot_0 is not None:
            y0 = spec.phi_dot_0 ** 2
            if y0 <= y0min:
                raise OrbitError(
                    f"phi_dot(0) = {spec.phi_dot_0} rad/s is too slow for this constraint: the "
                    f"ball would stop (needs phi_dot(0) > {math.sqrt(max(y0min, 0)):.4g} rad/s)")
            return y0
        P = self.period
        target = spec.mean_phi_dot

        def mean_speed(y0: float) -> float:
            Y = self._Phi * (y0 + self._J)
            return P / (np.mean(1.0 / np.sqrt(Y)) * P)

        lo = max(y0min, 0.0) + 1e-12 * max(abs(y0min), 1.0)
        if mean_speed(lo) >= target:
            raise OrbitError(f"mean phi_dot {target} rad/s is below the slowest orbit of this "
                             f"constraint ({mean_speed(lo):.4g} rad/s)")
        hi = max(4.0 * target * target, lo + 1.0)
        while mean_speed(hi) < target:
            hi *= 4.0
        return float(brentq(lambda y: mean_speed(y) - target, lo, hi, xtol=1e-14, rtol=1e-14))

    # -- evaluation ------------------------------------------------------------------------
    @property
    def mean_phi_dot(self) -> float:
        """Mean contact-angle rate P / T [rad/s]."""
        return self.period / self.time_period

    def phi_dot_sq(self, phi: ArrayLike) -> FloatArray:
        """Y(phi) = phi_dot*^2 [rad^2/s^2] at any phi."""
        return self.table.evaluate(phi)[..., 3]

    def phi_dot(self, phi: ArrayLike) -> FloatArray:
        """phi_dot*(phi) [rad/s]."""
        return np.sqrt(self.phi_dot_sq(phi))

    def state(self, phi: ArrayLike) -> FloatArray:
        """The orbit's state ``[theta, phi, theta_dot, phi_dot]`` at contact angle(s) phi."""
        phi = np.asarray(phi, float)
        th0, th1, _, Y = np.moveaxis(self.table.evaluate(phi), -1, 0)
        pd = np.sqrt(Y)
        return np.stack([th0, phi, th1 * pd, pd], axis=-1)

    def nominal_torque(self, phi: ArrayLike | None = None) -> FloatArray:
        """Torque that keeps the model exactly on the orbit, u*(phi) [N m] (default: grid).

        From the model's accelerations, which are affine in u:
        ``y_ddot(u) = theta_ddot - Theta' phi_ddot - Theta'' phi_dot^2 = 0``.
        """
        phi = self.phi if phi is None else np.asarray(phi, float)
        x = self.state(phi)
        th1, th2 = self.table.evaluate(phi)[..., 1], self.table.evaluate(phi)[..., 2]
        args = self.model.kernel_args
        a0 = rigid_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], 0.0 * phi, *args)
        a1 = rigid_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], 1.0 + 0.0 * phi, *args)
        y0 = a0[0] - th1 * a0[1] - th2 * x[..., 3] ** 2
        y1 = a1[0] - th1 * a1[1] - th2 * x[..., 3] ** 2
        return -y0 / (y1 - y0)

    def summary(self) -> dict:
        """Figures of the orbit (JSON-ready)."""
        pd = np.sqrt(self.Y)
        u = self.nominal_torque()
        return {
            "c": self.constraint.spec.c,
            "kind": self.kind,
            "period_phi": self.period,
            "time_period": float(self.time_period),
            "mean_phi_dot": float(self.mean_phi_dot),
            "phi_dot_min": float(pd.min()),
            "phi_dot_max": float(pd.max()),
            "phi_dot_0": float(pd[0]),
            "theta_dot_min": float(np.min(self.theta1 * pd)),
            "theta_dot_max": float(np.max(self.theta1 * pd)),
            "alpha_min": float(np.min(np.abs(self.alpha))),
            "nominal_torque_max": float(np.max(np.abs(u))),
        }
