"""Rigid-body dynamics of the Butterfly robot: frame + ball rolling without slipping.

Generalised coordinates ``q = (theta, phi)`` (DEVELOPERS.md): theta the frame angle, phi the
contact point's contour angle. State ``x = [theta, phi, theta_dot, phi_dot]``; the integrators
carry two more entries, ``W_in`` (work done by the motor) and ``W_diss`` (energy dissipated).

Lagrangian (rig-brief.md; seed eq. 2.1 with the spin corrected to the offset curve):

    r        = Rot(theta) p(phi)                            ball centre, world [m]
    |r_dot|^2 = |p|^2 th'^2 + 2 (p x p') th' ph' + lam^2 ph'^2
    omega_b  = th' - lam ph' / R                            rolling without slip
    T = 1/2 m |r_dot|^2 + 1/2 J_b omega_b^2 + 1/2 J_f th'^2
    V = m g_e r_y,  r_y = sin(theta) p_x + cos(theta) p_y,  g_e = g cos(eps)

so ``T = 1/2 q_dot^T M(phi) q_dot`` with

    M11 = m |p|^2 + J_b + J_f,   M12 = m (p x p') - J_b lam / R,   M22 = (m + J_b / R^2) lam^2.

Euler-Lagrange with Christoffel symbols (only d/dphi is non-zero):

    M q_ddot + c(q, q_dot) + G(q) = Q
    c = [M11' th' ph' + M12' ph'^2,  -1/2 M11' th'^2 + 1/2 M22' ph'^2]
    G = [m g_e r_x,  m g_e (sin(theta) p'_x + cos(theta) p'_y)]
    M11' = 2 m p.p',  M12' = m (p x p'') - J_b lam' / R,  M22' = 2 (m + J_b/R^2) lam lam'

Generalised forces Q (perturbations; all zero in the nominal model):

    Q_theta = k_u u - c_v th' - T_c tanh(th' / v_c)                 motor gain, joint friction
    Q_phi   = -mu_rol F_n lam tanh(ph' / v_r)                        rolling resistance (seed 2.4)

with F_n the normal force of the frame on the ball, ``F_n = n_w . m (r_ddot + g_e y_hat)``:

    F_n = m [-(n.p) th'^2 + 2 lam th' ph' + (p x n) th'' - lam K ph'^2] + m g_e n_w,y

It is linear in theta_ddot, so the rolling-resistance term is solved exactly together with
the accelerations (a 2x2 system). ``F_n > 0`` is the condition for the rigid model to hold
(the ball pressed onto the track); a negative value means the ball would lift off.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_sim._jit import njit
from bfr_sim.geometry import OffsetCurve, offset_kernel
from bfr_sim.params import RigParams

__all__ = ["RigidModel", "rigid_rhs", "rigid_rk4_steps", "rigid_terms", "mass_terms", "P_SIZE"]

FloatArray = NDArray[np.float64]

# Layout of the scalar parameter vector P handed to the compiled kernels.
I_M, I_JB, I_JF, I_R, I_G, I_CV, I_TC, I_VC, I_MUR, I_VR, I_KU = range(11)
P_SIZE = 11


@njit
def mass_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw):  # noqa: ANN001, ANN201
    """M11, M12, M22 and their phi-derivatives (module docstring), float or array phi."""
    m = P[I_M]
    jb = P[I_JB]
    jf = P[I_JF]
    px, py, p1x, p1y, p2x, p2y, _, _, _, _, lam, lam1, _ = offset_kernel(
        phi, R, rho0, orders, ccos, csin, bphi, bh, bw)
    mr = m + jb / (R * R)
    m11 = m * (px * px + py * py) + jb + jf
    m12 = m * (px * p1y - py * p1x) - jb * lam / R
    m22 = mr * lam * lam
    dm11 = 2.0 * m * (px * p1x + py * p1y)
    dm12 = m * (px * p2y - py * p2x) - jb * lam1 / R
    dm22 = 2.0 * mr * lam * lam1
    return m11, m12, m22, dm11, dm12, dm22


@njit
def rigid_terms(theta, phi, theta_dot, phi_dot, u, P, R, rho0, orders, ccos, csin, bphi, bh,
                bw):  # noqa: ANN001, ANN201
    """Accelerations, powers and normal force of the rigid model at one state.

    Returns
    -------
    tuple
        ``(theta_ddot, phi_ddot, p_in, p_diss, F_n)``: [rad/s^2], [rad/s^2], motor power
        ``k_u u theta_dot`` [W], dissipated power [W] (>= 0 while F_n >= 0), normal force [N].
    """
    m = P[I_M]
    jb = P[I_JB]
    jf = P[I_JF]
    g = P[I_G]
    px, py, p1x, p1y, p2x, p2y, _, _, nx, ny, lam, lam1, K = offset_kernel(
        phi, R, rho0, orders, ccos, csin, bphi, bh, bw)
    st = np.sin(theta)
    ct = np.cos(theta)
    # mass matrix and its derivative (same lines as mass_terms, kept inline for speed)
    mr = m + jb / (R * R)
    m11 = m * (px * px + py * py) + jb + jf
    m12 = m * (px * p1y - py * p1x) - jb * lam / R
    m22 = mr * lam * lam
    dm11 = 2.0 * m * (px * p1x + py * p1y)
    dm12 = m * (px * p2y - py * p2x) - jb * lam1 / R
    dm22 = 2.0 * mr * lam * lam1
    # Coriolis/centrifugal vector
    c1 = dm11 * theta_dot * phi_dot + dm12 * phi_dot * phi_dot
    c2 = -0.5 * dm11 * theta_dot * theta_dot + 0.5 * dm22 * phi_dot * phi_dot
    # gravity
    rx = ct * px - st * py
    g1 = m * g * rx
    g2 = m * g * (st * p1x + ct * p1y)
    # joint: motor gain, viscous and (smoothed) Coulomb friction
    tau_f = P[I_CV] * theta_dot + P[I_TC] * np.tanh(theta_dot / P[I_VC])
    q1 = P[I_KU] * u - tau_f
    # normal force F_n = f0 + f_th * theta_ddot
    n_dot_p = nx * px + ny * py
    p_cross_n = px * ny - py * nx
    nwy = st * nx + ct * ny
    f0 = m * (-n_dot_p * theta_dot * theta_dot + 2.0 * lam * theta_dot * phi_dot
              - lam * K * phi_dot * phi_dot) + m * g * nwy
    f_th = m * p_cross_n
    # rolling resistance Q_phi = -mu lam sgn (f0 + f_th th'')
    mu_s = P[I_MUR] * lam * np.tanh(phi_dot / P[I_VR])
    a11 = m11
    a12 = m12
    a21 = m12 + mu_s * f_th
    a22 = m22
    b1 = q1 - c1 - g1
    b2 = -mu_s * f0 - c2 - g2
    det = a11 * a22 - a12 * a21
    thdd = (a22 * b1 - a12 * b2) / det
    phdd = (a11 * b2 - a21 * b1) / det
    fn = f0 + f_th * thdd
    p_in = P[I_KU] * u * theta_dot
    p_diss = tau_f * theta_dot + mu_s * fn * phi_dot
    return thdd, phdd, p_in, p_diss, fn


@njit
def rigid_rhs(t, x, args):  # noqa: ANN001, ANN201
    """Right-hand side of the 6-state ODE ``[theta, phi, th', ph', W_in, W_diss]``.

    ``args = (u, P, R, rho0, orders, ccos, csin, bphi, bh, bw)`` with u held constant.
    """
    u, P, R, rho0, orders, ccos, csin, bphi, bh, bw = args
    thdd, phdd, p_in, p_diss, _ = rigid_terms(x[0], x[1], x[2], x[3], u, P, R, rho0, orders,
                                              ccos, csin, bphi, bh, bw)
    dx = np.empty(6)
    dx[0] = x[2]
    dx[1] = x[3]
    dx[2] = thdd
    dx[3] = phdd
    dx[4] = p_in
    dx[5] = p_diss
    return dx


@njit
def rigid_rk4_steps(x0, t0, dt, n, args):  # noqa: ANN001, ANN201
    """:func:`bfr_sim.integrators.rk4_steps` specialised to :func:`rigid_rhs`.

    The generic integrator takes the right-hand side as an argument, which numba cannot
    cache across processes (a few seconds of compilation per process); this specialisation
    of the live node's hot path is cached. Same scheme, same results to the last bit.
    """
    x = x0.copy()
    t = t0
    h2 = 0.5 * dt
    for _ in range(n):
        k1 = rigid_rhs(t, x, args)
        k2 = rigid_rhs(t + h2, x + h2 * k1, args)
        k3 = rigid_rhs(t + h2, x + h2 * k2, args)
        k4 = rigid_rhs(t + dt, x + dt * k3, args)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t = t + dt
    return x


@njit
def energy_terms(theta, phi, theta_dot, phi_dot, P, R, rho0, orders, ccos, csin, bphi, bh,
                 bw):  # noqa: ANN001, ANN201
    """Kinetic and potential energy [J] (module docstring), float or array arguments."""
    m11, m12, m22, _, _, _ = mass_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw)
    px, py = offset_kernel(phi, R, rho0, orders, ccos, csin, bphi, bh, bw)[:2]
    kin = 0.5 * (m11 * theta_dot * theta_dot + 2.0 * m12 * theta_dot * phi_dot
                 + m22 * phi_dot * phi_dot)
    pot = P[I_M] * P[I_G] * (np.sin(theta) * px + np.cos(theta) * py)
    return kin, pot


class RigidModel:
    """The rigid two-degree-of-freedom model of one parameter set.

    Parameters
    ----------
    params : RigParams
        Physical parameters (see :mod:`bfr_sim.params`).
    """

    def __init__(self, params: RigParams) -> None:
        self.params = params
        self.curve = OffsetCurve.from_params(params)
        P = np.zeros(P_SIZE)
        P[I_M] = params.ball.mass
        P[I_JB] = params.ball.inertia
        P[I_JF] = params.frame.inertia
        P[I_R] = params.ball.rolling_radius
        P[I_G] = params.environment.in_plane_gravity
        P[I_CV] = params.joint.viscous_friction
        P[I_TC] = params.joint.coulomb_friction
        P[I_VC] = params.joint.coulomb_smoothing
        P[I_MUR] = params.track.rolling_resistance
        P[I_VR] = params.track.rolling_smoothing
        P[I_KU] = params.actuator.torque_gain
        self.P = P
        self.geom_args = self.curve.arrays.as_args()
        self.kernel_args = (P, *self.geom_args)

    # -- matrices of M q_ddot + C q_dot + G = B u ------------------------------------------
    def mass_matrix(self, phi: ArrayLike) -> FloatArray:
        """M(phi), shape (..., 2, 2) [kg m^2]."""
        m11, m12, m22 = mass_terms(np.asarray(phi, float), *self.kernel_args)[:3]
        return np.stack([np.stack([m11, m12], -1), np.stack([m12, m22], -1)], -2)

    def mass_matrix_derivative(self, phi: ArrayLike) -> FloatArray:
        """dM/dphi, shape (..., 2, 2) [kg m^2 / rad]."""
        d11, d12, d22 = mass_terms(np.asarray(phi, float), *self.kernel_args)[3:]
        return np.stack([np.stack([d11, d12], -1), np.stack([d12, d22], -1)], -2)

    def coriolis_matrix(self, phi: ArrayLike, theta_dot: ArrayLike,
                        phi_dot: ArrayLike) -> FloatArray:
        """C(q, q_dot) with ``M_dot - 2 C`` skew-symmetric, shape (..., 2, 2)."""
        d11, d12, d22 = mass_terms(np.asarray(phi, float), *self.kernel_args)[3:]
        th = np.asarray(theta_dot, float)
        ph = np.asarray(phi_dot, float)
        row1 = np.stack([0.5 * d11 * ph, 0.5 * d11 * th + d12 * ph], -1)
        row2 = np.stack([-0.5 * d11 * th, 0.5 * d22 * ph], -1)
        return np.stack([row1, row2], -2)

    def gravity_vector(self, theta: ArrayLike, phi: ArrayLike) -> FloatArray:
        """G(q) = dV/dq, shape (..., 2) [N m]."""
        g = offset_kernel(np.asarray(phi, float), *self.geom_args)
        th = np.asarray(theta, float)
        mg = self.P[I_M] * self.P[I_G]
        st, ct = np.sin(th), np.cos(th)
        return np.stack([mg * (ct * g[0] - st * g[1]), mg * (st * g[2] + ct * g[3])], -1)

    # -- state functions -------------------------------------------------------------------
    def accelerations(self, x: ArrayLike, u: float = 0.0) -> tuple[float, float]:
        """(theta_ddot, phi_ddot) [rad/s^2] at state x under command u [N m]."""
        x = np.asarray(x, float)
        r = rigid_terms(x[0], x[1], x[2], x[3], float(u), *self.kernel_args)
        return float(r[0]), float(r[1])

    def normal_force(self, x: ArrayLike, u: ArrayLike = 0.0) -> FloatArray:
        """Normal force of the frame on the ball [N] (> 0: the rigid model holds)."""
        x = np.asarray(x, float)
        return rigid_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3],
                           np.asarray(u, float) + 0.0 * x[..., 0], *self.kernel_args)[4]

    def energy(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(kinetic, potential) energy [J] of state(s) x, shape (..., 4+)."""
        x = np.asarray(x, float)
        return energy_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], *self.kernel_args)

    def ball_position(self, x: ArrayLike) -> FloatArray:
        """Ball centre in the world frame, shape (..., 2) [m]."""
        x = np.asarray(x, float)
        p = self.curve.point(x[..., 1])
        st, ct = np.sin(x[..., 0]), np.cos(x[..., 0])
        return np.stack([ct * p[..., 0] - st * p[..., 1], st * p[..., 0] + ct * p[..., 1]], -1)

    def ball_spin_rate(self, x: ArrayLike) -> FloatArray:
        """Ball angular velocity in the world, omega_b = theta_dot - lam phi_dot / R [rad/s]."""
        x = np.asarray(x, float)
        lam = self.curve.speed(x[..., 1])
        return x[..., 2] - lam * x[..., 3] / self.P[I_R]

    def rhs_args(self, u: float) -> tuple:
        """``args`` tuple of :func:`rigid_rhs` for a held command u [N m]."""
        return (float(u), *self.kernel_args)

    def step(self, x: FloatArray, u: float, dt: float, n: int = 1, t0: float = 0.0) -> FloatArray:
        """Advance the 6-state x by n RK4 steps of dt [s] under a held command u [N m]."""
        return rigid_rk4_steps(np.asarray(x, float), float(t0), float(dt), int(n),
                               self.rhs_args(u))
