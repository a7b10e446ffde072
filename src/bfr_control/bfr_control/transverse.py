"""Transverse coordinates, partial feedback linearisation and the transverse linearisation.

Transverse coordinates of a state ``x = [theta, phi, theta_dot, phi_dot]`` with respect to the
orbit ``theta = Theta(phi)``, ``phi_dot^2 = Y(phi)`` (Shiriaev, Freidovich, Gusev, IEEE TAC 2010;
seed eq. 4.44 with the integral-of-motion deviation in place of z):

    I     = phi_dot^2 - Y(phi)                  [rad^2/s^2]   distance to the orbit
    y     = theta - Theta(phi)                  [rad]         constraint violation
    y_dot = theta_dot - Theta'(phi) phi_dot     [rad/s]
    z     = phi_dot - sqrt(Y(phi))              [rad/s]       (reported; I ~ 2 sqrt(Y) z)

Partial feedback linearisation (PFL). ``y_ddot = theta_ddot - Theta' phi_ddot - Theta''
phi_dot^2 = [1, -Theta'] q_ddot - Theta'' phi_dot^2`` with ``q_ddot = M^-1 (B u - c - G - F)``,
``B = [k_u, 0]`` and F the model's friction forces, so the torque that gives ``y_ddot = w`` is

    u = (w + Theta'' phi_dot^2 + [1, -Theta'] M^-1 (c + G + F)) / ([1, -Theta'] M^-1 B),   (1)

the seed's eq. 4.46 written with ``L^-1 = [[1, -Theta'], [0, 1]]``. The denominator equals
``k_u alpha / det M`` with alpha of the reduced dynamics, so (1) is regular wherever the orbit
is. :func:`pfl_torque` evaluates (1) through the model's own accelerations, which are affine in
u (also with the rolling resistance, whose normal force depends on the accelerations; not
with a load-dependent bearing friction, which a controller's model should not carry):
``y_ddot(u) = y_ddot(0) + u (y_ddot(1) - y_ddot(0))``; :func:`pfl_torque_explicit` writes (1)
out with M, c, G for the frictionless model (a test checks that they agree).

Transverse linearisation. With PFL, ``y_ddot = w`` exactly, and the passive row
``M21 theta_ddot + M22 phi_ddot + c2 + G2 = 0`` gives
``alpha phi_ddot = -M21 (w + Theta'' phi_dot^2) - c2(theta_dot, phi_dot) - G2(Theta + y, phi)``.
Differentiating ``I_dot = 2 phi_dot phi_ddot - Y'(phi) phi_dot`` at ``I = y = y_dot = w = 0``
(where ``phi_ddot = Y'/2``) gives, along the orbit ``phi_dot = sqrt(Y)``,

    d/dt [I, y, y_dot] = A(phi) [I, y, y_dot] + B(phi) w,

    A = [[-2 beta phi_dot / alpha, -2 phi_dot dG2/dtheta / alpha,
          2 M11' Theta' phi_dot^2 / alpha],
         [0, 0, 1],
         [0, 0, 0]],
    B = [-2 M21 phi_dot / alpha, 0, 1],

with beta of the reduced dynamics and ``dG2/dtheta = G2(theta + pi/2)`` (gravity enters as
``a(phi) sin theta + b(phi) cos theta``; for the round ball
``dG2/dtheta = m g (cos theta p'_x - sin theta p'_y)``).
The rolling resistance is left out of the linearisation (zero in the nominal model; the PFL
still cancels it exactly when the controller's model has it).
"""

from __future__ import annotations

import numpy as np
from bfr_model.dynamics import RigidModel, mass_terms, rigid_terms
from bfr_model.jit import njit
from bfr_model.layout import I_CV, I_KU, I_TC, I_VC
from numpy.typing import ArrayLike, NDArray

from bfr_control.orbit import PeriodicOrbit

__all__ = [
    "pfl_kernel",
    "pfl_torque",
    "pfl_torque_explicit",
    "transverse_coordinates",
    "transverse_linearization",
    "y_ddot",
]

FloatArray = NDArray[np.float64]


def transverse_coordinates(orbit: PeriodicOrbit, x: ArrayLike) -> FloatArray:
    """``[I, y, y_dot, z]`` of state(s) x (module docstring), shape (..., 4)."""
    x = np.asarray(x, float)
    theta, phi, theta_dot, phi_dot = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    tab = orbit.table.evaluate(phi)
    th0, th1, Y = tab[..., 0], tab[..., 1], tab[..., 3]
    I_dev = phi_dot * phi_dot - Y
    y = theta - th0
    y_dot = theta_dot - th1 * phi_dot
    z = phi_dot - np.sqrt(Y)
    return np.stack([I_dev, y, y_dot, z], axis=-1)


def y_ddot(model: RigidModel, theta1: ArrayLike, theta2: ArrayLike, x: ArrayLike,
           u: ArrayLike) -> FloatArray:
    """``y_ddot = theta_ddot - Theta' phi_ddot - Theta'' phi_dot^2`` under torque u [rad/s^2]."""
    x = np.asarray(x, float)
    u = np.asarray(u, float) + 0.0 * x[..., 0]
    r = rigid_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], u, *model.kernel_args)
    return r[0] - np.asarray(theta1) * r[1] - np.asarray(theta2) * x[..., 3] ** 2


@njit
def pfl_kernel(theta: float, phi: float, theta_dot: float, phi_dot: float, theta1: float,
               theta2: float, w: float, P: np.ndarray, R: float, rho0: float,
               orders: np.ndarray, ccos: np.ndarray, csin: np.ndarray, bphi: np.ndarray,
               bh: np.ndarray, bw: np.ndarray) -> float:
    """Compiled eq. (1) through the model's affine accelerations (see :func:`pfl_torque`)."""
    a0 = rigid_terms(theta, phi, theta_dot, phi_dot, 0.0, P, R, rho0, orders, ccos, csin,
                     bphi, bh, bw)
    a1 = rigid_terms(theta, phi, theta_dot, phi_dot, 1.0, P, R, rho0, orders, ccos, csin,
                     bphi, bh, bw)
    c = theta2 * phi_dot * phi_dot
    yd0 = a0[0] - theta1 * a0[1] - c
    yd1 = a1[0] - theta1 * a1[1] - c
    return (w - yd0) / (yd1 - yd0)


def pfl_torque(model: RigidModel, theta1: float, theta2: float, x: ArrayLike, w: float
               ) -> float:
    """Torque u [N m] that gives ``y_ddot = w`` on the model (eq. 1, via affine accelerations).

    Parameters
    ----------
    model : RigidModel
        The controller's model (with whatever friction it has).
    theta1, theta2 : float
        Theta'(phi), Theta''(phi) at the state's phi.
    x : array_like
        ``[theta, phi, theta_dot, phi_dot]``.
    w : float
        Commanded y_ddot [rad/s^2].
    """
    return float(pfl_kernel(float(x[0]), float(x[1]), float(x[2]), float(x[3]), float(theta1),
                            float(theta2), float(w), *model.kernel_args))


def pfl_torque_explicit(model: RigidModel, theta1: ArrayLike, theta2: ArrayLike, x: ArrayLike,
                        w: ArrayLike) -> FloatArray:
    """Eq. (1) written out with M, c, G and the joint friction (no rolling resistance)."""
    x = np.asarray(x, float)
    theta, phi, thd, phd = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    P = model.P
    m11, m12, m22, d11, d12, d22 = mass_terms(phi, *model.kernel_args)
    det = m11 * m22 - m12 * m12
    # [1, -Theta'] M^-1 = [m22 + Theta' m12, -m12 - Theta' m11] / det
    r1 = (m22 + theta1 * m12) / det
    r2 = (-m12 - theta1 * m11) / det
    c1 = d11 * thd * phd + d12 * phd * phd
    c2 = -0.5 * d11 * thd * thd + 0.5 * d22 * phd * phd
    G = model.gravity_vector(theta, phi)
    f1 = P[I_CV] * thd + P[I_TC] * np.tanh(thd / P[I_VC])  # joint friction torque
    num = np.asarray(w) + theta2 * phd * phd + r1 * (c1 + G[..., 0] + f1) + r2 * (c2 + G[..., 1])
    return num / (r1 * P[I_KU])


def transverse_linearization(orbit: PeriodicOrbit, phi: ArrayLike | None = None
                             ) -> tuple[FloatArray, FloatArray]:
    """``A(phi)`` (..., 3, 3) and ``B(phi)`` (..., 3) of the transverse linearisation.

    State ``[I, y, y_dot]``, input ``w = y_ddot``, time t (module docstring); phi defaults to
    the orbit's grid.
    """
    model = orbit.model
    phi = orbit.phi if phi is None else np.asarray(phi, float)
    th0, th1, th2 = orbit.constraint.evaluate(phi)
    Y = orbit.phi_dot_sq(phi)
    pd = np.sqrt(Y)
    _, m12, m22, d11, _, d22 = mass_terms(phi, *model.kernel_args)
    alpha = m12 * th1 + m22
    beta = m12 * th2 - 0.5 * d11 * th1 * th1 + 0.5 * d22
    # G2 = a(phi) sin(theta) + b(phi) cos(theta), so dG2/dtheta = G2(theta + pi/2)
    dG2 = model.gravity_vector(th0 + 0.5 * np.pi, phi)[..., 1]
    A = np.zeros((*phi.shape, 3, 3))
    A[..., 0, 0] = -2.0 * beta * pd / alpha
    A[..., 0, 1] = -2.0 * pd * dG2 / alpha
    A[..., 0, 2] = 2.0 * d11 * th1 * Y / alpha
    A[..., 1, 2] = 1.0
    B = np.zeros((*phi.shape, 3))
    B[..., 0] = -2.0 * m12 * pd / alpha
    B[..., 2] = 1.0
    return A, B
