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

    Q_theta = k_u u + tau_0 - c_v th' - T_c tanh(th' / v_c)   motor gain and offset, friction
    Q_phi   = -mu_rol F_n lam tanh(ph' / v_r)                        rolling resistance (seed 2.4)

with F_n the normal force of the frame on the ball, ``F_n = n_w . m (r_ddot + g_e y_hat)``:

    F_n = m [-(n.p) th'^2 + 2 lam th' ph' + (p x n) th'' - lam K ph'^2] + m g_e n_w,y

It is linear in theta_ddot, so the rolling-resistance term is solved exactly together with
the accelerations (a 2x2 system). ``F_n > 0`` is the condition for the rigid model to hold
(the ball pressed onto the track); a negative value means the ball would lift off.

Perturbation terms (bfr_model.perturbations; all off by default, exact unless stated):

* Wobble ``w`` (``frame.wobble``): the frame's plane is tilted about the frame's y axis, a
  frame point p sits at ``q = W p = (c p_x, p_y, s p_x)``, ``c = cos w``, ``s = sin w``, in the
  shaft's rotating coordinates (W is an isometry of the plane into 3-D). With
  ``r = Rot_z(theta) q`` the Lagrangian keeps its form with

      M11 = m (c^2 p_x^2 + p_y^2) + J_b + J_f,  M12 = c (m (p x p') - J_b lam / R),
      M22 = m |p'|^2 + J_b lam^2 / R^2,         V = m g_e (sin(theta) c p_x + cos(theta) p_y)

  (the ball's spin relative to the frame is about the frame's normal, whose z component is
  c). The ball sways along z by ``s p_x`` (seed eqs. 2.7-2.9 with phi_b ~ theta).
* Elliptic ball (``ball.ellipticity`` = 2 e0): the centre stands ``R + e(beta)`` off the
  track, ``e = e0 cos 2 beta``, beta the contact direction in ball-fixed coordinates. Rolling
  makes beta holonomic: ``beta = beta0 + s(phi) / R + nu(phi)`` with nu the normal's angle
  (``nu' = -K``), so the centre curve becomes ``p~ = p + e n`` (first order: the spin keeps
  ``omega_b = theta_dot - lam phi_dot / R``). ``s(phi)`` is carried as a Fourier series.
* Load-dependent joint friction (``joint.load_friction`` = c_L): ``T = c_L F_load
  tanh(th' / v_c)``, ``F_load = |m (r_ddot + g_e y) + m_f g_e y|`` the bearing load. It
  depends on the accelerations; two fixed-point passes of the 2x2 solve make it exact to
  machine precision (each pass shrinks the error by ``c_L m |p| / M11`` ~ 1e-6), and the
  torque that is applied is the one booked as dissipation, so the energy balance is exact.

* Frame imbalance (``frame.imbalance`` = m_f e, ``frame.imbalance_angle`` = theta_e): the
  frame's centre of mass at ``e [sin theta_e, cos theta_e]`` in frame coordinates adds
  ``V_f = g_e (sin(theta) c M_x + cos(theta) M_y)``, ``M = m_f e [sin, cos] theta_e`` the first
  mass moment (c: the wobble factor), so ``G1 += g_e (cos(theta) c M_x - sin(theta) M_y)``,
  i.e. the torque ``m_f e g_e sin(theta - theta_e)`` without wobble. Conservative.
* Torque offset (``actuator.torque_offset`` = tau_0): the drive applies ``k_u u + tau_0``;
  its power ``(k_u u + tau_0) th'`` is booked as motor work.

With all three the normal force is ``F_n = n3 . m (r_ddot + g_e y)``, ``n3 = W n``, linear in
both accelerations: ``F_n = f0 + f_th th'' + f_ph ph''``.

A creeping spin (``ball.creep_time`` = tau_s > 0; linear creep at the plate edges, Kalker's
linear theory, Johnson 1985 ch. 8): the ball does not roll exactly; its spin omega_b is a
coordinate of its own, driven by the edges' friction torque

    tau_f = -(J_b / tau_s) (omega_b - omega_roll),   omega_roll = th' - lam ph' / R,
    J_b omega_b' = tau_f,

and the translation is the model above with ``J_b = 0`` plus the friction's generalised
forces ``(-tau_f, lam tau_f / R)`` on ``(theta, phi)`` (:func:`creep_terms`; ``tau_s -> 0``
is rolling: ``tau_f`` becomes the rolling constraint's ``J_b omega_roll'``). The friction's
power ``tau_f (omega_b - omega_roll)`` is never positive and is booked as dissipation; the
kinetic energy holds ``J_b omega_b^2 / 2`` instead of rolling's. The integrators then carry
omega_b as a seventh entry (:meth:`RigidModel.state`). The diagnosis's slip test finds this
law on the real rig (:mod:`bfr_diagnose.grip`, 5), and the same kernel predicts with it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bfr_model.geometry import OffsetCurve, offset_kernel
from bfr_model.jit import njit
from bfr_model.layout import (
    I_CL,
    I_CV,
    I_CW,
    I_EB0,
    I_EL,
    I_G,
    I_JB,
    I_JF,
    I_KU,
    I_M,
    I_MEX,
    I_MEY,
    I_MF,
    I_MUR,
    I_NS,
    I_R,
    I_SBAR,
    I_SW,
    I_TAU0,
    I_TC,
    I_TS,
    I_VC,
    I_VR,
    rigid_vector,
)
from bfr_model.params import RigParams

__all__ = [
    "RigidModel",
    "creep_terms",
    "curve_terms",
    "forced_terms",
    "frame_gravity",
    "joint_torque",
    "mass_terms",
    "rigid_rhs",
    "rigid_rk4_steps",
    "rigid_terms",
]

FloatArray = NDArray[np.float64]

# The scalar parameter vector P handed to the compiled kernels: bfr_model.layout.


@njit
def curve_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw):  # noqa: ANN001, ANN201
    """Ball-centre curve p~(phi) and its first two derivatives (frame-plane coordinates).

    The offset curve of :func:`bfr_model.geometry.offset_kernel`, displaced along the normal
    by an elliptic ball's ``e(beta) = e0 cos 2 beta`` (module docstring) when ``P[I_EL]``
    is non-zero::

        p~   = p + e n
        p~'  = p' + e' n + e K t
        p~'' = p'' + (2 e' K + e K') t + (e'' - e K^2) n

    with ``beta' = lam / R - K``, ``beta'' = lam' / R - K'`` and
    ``K' = -(p''' . n + 2 lam' K) / lam``.

    Returns
    -------
    tuple
        ``(px, py, p1x, p1y, p2x, p2y, nx, ny, lam, lam1)``: lam and lam' are those of the
        round ball's offset curve (the rolling rate ds/dphi).
    """
    px, py, p1x, p1y, p2x, p2y, p3x, p3y, nx, ny, lam, lam1, K = offset_kernel(
        phi, R, rho0, orders, ccos, csin, bphi, bh, bw)
    e0 = P[I_EL]
    if e0 != 0.0:
        ns = int(P[I_NS])
        # the series ends P (counted from the end, not from P_SIZE: a kernel cached under an
        # older, shorter layout would keep reading at the old P_SIZE)
        tail = P.shape[0] - 2 * ns
        s = P[I_SBAR] * phi
        c1 = np.cos(phi)
        s1 = np.sin(phi)
        ck = c1
        sk = s1
        for k in range(1, ns + 1):  # cos k phi, sin k phi by the angle-addition recurrence
            s = s + P[tail + k - 1] * (ck - 1.0) + P[tail + ns + k - 1] * sk
            ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
        K1 = -((p3x * nx + p3y * ny) + 2.0 * lam1 * K) / lam
        tx = ny
        ty = -nx
        b0 = 2.0 * (P[I_EB0] + s / R)
        c2n = nx * nx - ny * ny
        s2n = 2.0 * nx * ny
        cb = np.cos(b0) * c2n - np.sin(b0) * s2n  # cos 2 beta
        sb = np.sin(b0) * c2n + np.cos(b0) * s2n  # sin 2 beta
        db = lam / R - K
        ddb = lam1 / R - K1
        e = e0 * cb
        e1 = -2.0 * e0 * sb * db
        e2 = -4.0 * e0 * cb * db * db - 2.0 * e0 * sb * ddb
        ct2 = 2.0 * e1 * K + e * K1
        cn2 = e2 - e * K * K
        p2x = p2x + ct2 * tx + cn2 * nx
        p2y = p2y + ct2 * ty + cn2 * ny
        p1x = p1x + e1 * nx + e * K * tx
        p1y = p1y + e1 * ny + e * K * ty
        px = px + e * nx
        py = py + e * ny
    return px, py, p1x, p1y, p2x, p2y, nx, ny, lam, lam1


@njit
def mass_from_curve(px, py, p1x, p1y, p2x, p2y, lam, lam1, P, R):  # noqa: ANN001, ANN202
    """M11, M12, M22 and their phi-derivatives from the ball-centre curve's terms.

    The one place the mass matrix is written (module docstring; with the frame's wobble
    factor ``c = P[I_CW]``); :func:`mass_terms`, :func:`rigid_terms` and the diagnosis
    residual all call it.
    """
    m = P[I_M]
    jb = P[I_JB]
    c = P[I_CW]
    sig = lam / R
    sig1 = lam1 / R
    m11 = m * (c * c * px * px + py * py) + jb + P[I_JF]
    m12 = c * (m * (px * p1y - py * p1x) - jb * sig)
    m22 = m * (p1x * p1x + p1y * p1y) + jb * sig * sig
    dm11 = 2.0 * m * (c * c * px * p1x + py * p1y)
    dm12 = c * (m * (px * p2y - py * p2x) - jb * sig1)
    dm22 = 2.0 * m * (p1x * p2x + p1y * p2y) + 2.0 * jb * sig * sig1
    return m11, m12, m22, dm11, dm12, dm22


@njit
def frame_gravity(st, ct, P):  # noqa: ANN001, ANN201
    """G1 of the frame's own weight, ``dV_f/dtheta`` (module docstring: frame imbalance).

    ``V_f = g (sin(theta) c M_x + cos(theta) M_y)``, so
    ``G1_f = g (cos(theta) c M_x - sin(theta) M_y)`` = ``-m_f e g sin(theta - theta_e)``
    without wobble. Zero for a balanced frame.
    """
    return P[I_G] * (ct * P[I_CW] * P[I_MEX] - st * P[I_MEY])


@njit
def gravity_from_curve(st, ct, px, py, p1x, p1y, P):  # noqa: ANN001, ANN202
    """G = dV/dq with ``V = m g (sin(theta) c p_x + cos(theta) p_y) + V_f`` (c: wobble).

    ``V_f`` is the frame's own weight (:func:`frame_gravity`; zero when it is balanced).
    """
    mg = P[I_M] * P[I_G]
    c = P[I_CW]
    return (mg * (ct * c * px - st * py) + frame_gravity(st, ct, P),
            mg * (st * c * p1x + ct * p1y))


@njit
def joint_torque(u, theta_dot, P):  # noqa: ANN001, ANN201
    """Q_theta without the load friction: ``k_u u + tau_0 - c_v th' - T_c tanh(th' / v_c)``.

    The drive's torque (gain and offset) and the joint's viscous and Coulomb friction (module
    docstring); the one place they are written, for the kernels and the diagnosis residual.
    """
    return (P[I_KU] * u + P[I_TAU0] - P[I_CV] * theta_dot
            - P[I_TC] * np.tanh(theta_dot / P[I_VC]))


@njit
def mass_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw):  # noqa: ANN001, ANN201
    """M11, M12, M22 and their phi-derivatives (module docstring), float or array phi."""
    px, py, p1x, p1y, p2x, p2y, _, _, lam, lam1 = curve_terms(
        phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw)
    return mass_from_curve(px, py, p1x, p1y, p2x, p2y, lam, lam1, P, R)


@njit
def rigid_terms(theta, phi, theta_dot, phi_dot, u, P, R, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN201
                bw):  # noqa: ANN001
    """Accelerations, powers and normal force of the rigid model at one state.

    Returns
    -------
    tuple
        ``(theta_ddot, phi_ddot, p_in, p_diss, F_n)``: [rad/s^2], [rad/s^2], motor power
        ``(k_u u + tau_0) theta_dot`` [W], dissipated power [W] (>= 0 while F_n >= 0), normal
        force [N].
    """
    return forced_terms(theta, phi, theta_dot, phi_dot, u, 0.0, 0.0, P, R, rho0, orders, ccos,
                        csin, bphi, bh, bw)


@njit
def forced_terms(theta, phi, theta_dot, phi_dot, u, f1, f2, P, R, rho0, orders, ccos, csin,  # noqa: ANN001, ANN201
                 bphi, bh, bw):  # noqa: ANN001
    """:func:`rigid_terms` with extra generalised forces ``(f1, f2)`` [N m] on theta and phi.

    ``M q_ddot + c + G = Q + f``: forces from outside the model's terms (the friction torque
    of a slipping ball, :mod:`bfr_diagnose.grip`). They enter the accelerations and, through
    them, the normal force; the powers ``p_in`` and ``p_diss`` do not book them. With
    ``f1 = f2 = 0`` the results are :func:`rigid_terms`' to the last bit.
    """
    m = P[I_M]
    g = P[I_G]
    c = P[I_CW]
    sw = P[I_SW]
    px, py, p1x, p1y, p2x, p2y, nx, ny, lam, lam1 = curve_terms(
        phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw)
    st = np.sin(theta)
    ct = np.cos(theta)
    m11, m12, m22, dm11, dm12, dm22 = mass_from_curve(px, py, p1x, p1y, p2x, p2y, lam, lam1,
                                                      P, R)
    # Coriolis/centrifugal vector
    c1 = dm11 * theta_dot * phi_dot + dm12 * phi_dot * phi_dot
    c2 = -0.5 * dm11 * theta_dot * theta_dot + 0.5 * dm22 * phi_dot * phi_dot
    # gravity, V = m g (sin(theta) c p_x + cos(theta) p_y)
    g1, g2 = gravity_from_curve(st, ct, px, py, p1x, p1y, P)
    # joint: motor gain and offset, viscous and (smoothed) Coulomb friction
    sgn_th = np.tanh(theta_dot / P[I_VC])
    tau_f = P[I_CV] * theta_dot + P[I_TC] * sgn_th
    q1 = joint_torque(u, theta_dot, P)
    # ball acceleration plus g_e y in the shaft's rotating coordinates (3-D, q = W p):
    # r_dd + g y = a0 + a_th theta_dd + a_ph phi_dd,  a_th = z x q,  a_ph = q'
    qx = c * px
    qy = py
    q1x = c * p1x
    q1y = p1y
    q1z = sw * p1x
    thd2 = theta_dot * theta_dot
    phd2 = phi_dot * phi_dot
    cor = 2.0 * theta_dot * phi_dot
    a0x = -thd2 * qx - cor * q1y + phd2 * c * p2x + g * st
    a0y = -thd2 * qy + cor * q1x + phd2 * p2y + g * ct
    a0z = phd2 * sw * p2x
    # normal force F_n = n3 . m (r_dd + g y), n3 = W n
    n3x = c * nx
    n3y = ny
    n3z = sw * nx
    f0 = m * (n3x * a0x + n3y * a0y + n3z * a0z)
    f_th = m * (-n3x * qy + n3y * qx)
    f_ph = m * (n3x * q1x + n3y * q1y + n3z * q1z)
    # rolling resistance Q_phi = -mu lam sgn(phi_dot) F_n
    mu_s = P[I_MUR] * lam * np.tanh(phi_dot / P[I_VR])
    a11 = m11
    a12 = m12
    a21 = m12 + mu_s * f_th
    a22 = m22 + mu_s * f_ph
    b1 = q1 + f1 - c1 - g1
    b2 = f2 - mu_s * f0 - c2 - g2
    det = a11 * a22 - a12 * a21
    thdd = (a22 * b1 - a12 * b2) / det
    phdd = (a11 * b2 - a21 * b1) / det
    cl = P[I_CL]
    if cl != 0.0:
        # load-dependent bearing friction: fixed point on F_load(theta_dd, phi_dd), where
        # F_load = m (r_dd + g y) + m_f g y is the force the bearing carries
        mf = P[I_MF]
        t_load = 0.0 * thdd
        for _ in range(2):
            fx = m * (a0x - qy * thdd + q1x * phdd) + mf * g * st
            fy = m * (a0y + qx * thdd + q1y * phdd) + mf * g * ct
            fz = m * (a0z + q1z * phdd)
            t_load = cl * np.sqrt(fx * fx + fy * fy + fz * fz) * sgn_th
            b1l = b1 - t_load
            thdd = (a22 * b1l - a12 * b2) / det
            phdd = (a11 * b2 - a21 * b1l) / det
        tau_f = tau_f + t_load
    fn = f0 + f_th * thdd + f_ph * phdd
    p_in = (P[I_KU] * u + P[I_TAU0]) * theta_dot
    p_diss = tau_f * theta_dot + mu_s * fn * phi_dot
    return thdd, phdd, p_in, p_diss, fn


@njit
def creep_terms(theta, phi, theta_dot, phi_dot, omega_b, u, inv_tau, jb, Pt, R, rho0, orders,  # noqa: ANN001, ANN201
                ccos, csin, bphi, bh, bw):  # noqa: ANN001
    """Accelerations, powers and normal force of a ball whose spin creeps (module docstring).

    ``Pt`` is the parameter vector with ``J_b = 0`` (the translation alone), ``jb`` the
    ball's J_b [kg m^2], ``inv_tau = 1 / tau_s`` [1/s].

    Returns
    -------
    tuple
        ``(theta_ddot, phi_ddot, omega_b_dot, p_in, p_diss, F_n)``: as :func:`rigid_terms`,
        the spin's acceleration [rad/s^2] third; ``p_diss`` includes the creep's
        ``(J_b / tau_s) (omega_b - omega_roll)^2``.
    """
    rr = Pt[I_R]
    lam = curve_terms(phi, Pt, R, rho0, orders, ccos, csin, bphi, bh, bw)[8]
    s = omega_b - (theta_dot - lam * phi_dot / rr)
    tau = -jb * inv_tau * s
    thdd, phdd, p_in, p_diss, fn = forced_terms(theta, phi, theta_dot, phi_dot, u, -tau,
                                                lam * tau / rr, Pt, R, rho0, orders, ccos,
                                                csin, bphi, bh, bw)
    return thdd, phdd, tau / jb, p_in, p_diss - tau * s, fn


@njit
def rigid_rhs(t, x, args):  # noqa: ANN001, ANN201
    """Right-hand side of the 6-state ODE ``[theta, phi, th', ph', W_in, W_diss]``.

    ``args = (u, P, R, rho0, orders, ccos, csin, bphi, bh, bw)`` with u held constant. A
    creeping spin (``P[I_TS] > 0``) is a seventh state, omega_b (:func:`creep_terms`); a
    six-entry x rolls whatever ``P[I_TS]`` says (the kernels that predict rolling).
    """
    u, P, R, rho0, orders, ccos, csin, bphi, bh, bw = args
    dx = np.empty(x.shape[0])
    if P[I_TS] > 0.0 and x.shape[0] > 6:
        Pt = P.copy()
        Pt[I_JB] = 0.0
        thdd, phdd, dx[6], p_in, p_diss, _ = creep_terms(
            x[0], x[1], x[2], x[3], x[6], u, 1.0 / P[I_TS], P[I_JB], Pt, R, rho0, orders,
            ccos, csin, bphi, bh, bw)
    else:
        thdd, phdd, p_in, p_diss, _ = rigid_terms(x[0], x[1], x[2], x[3], u, P, R, rho0,
                                                  orders, ccos, csin, bphi, bh, bw)
    dx[0] = x[2]
    dx[1] = x[3]
    dx[2] = thdd
    dx[3] = phdd
    dx[4] = p_in
    dx[5] = p_diss
    return dx


@njit
def rigid_rk4_steps(x0, t0, dt, n, args):  # noqa: ANN001, ANN201
    """:func:`bfr_model.integrators.rk4_steps` specialised to :func:`rigid_rhs`.

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
def energy_terms(theta, phi, theta_dot, phi_dot, P, R, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN202
                 bw):  # noqa: ANN001
    """Kinetic and potential energy [J] (module docstring), float or array arguments."""
    m11, m12, m22, _, _, _ = mass_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw)
    px, py = curve_terms(phi, P, R, rho0, orders, ccos, csin, bphi, bh, bw)[:2]
    kin = 0.5 * (m11 * theta_dot * theta_dot + 2.0 * m12 * theta_dot * phi_dot
                 + m22 * phi_dot * phi_dot)
    st = np.sin(theta)
    ct = np.cos(theta)
    pot = (P[I_M] * P[I_G] * (st * P[I_CW] * px + ct * py)
           + P[I_G] * (st * P[I_CW] * P[I_MEX] + ct * P[I_MEY]))
    return kin, pot


class RigidModel:
    """The rigid two-degree-of-freedom model of one parameter set.

    Parameters
    ----------
    params : RigParams
        Physical parameters (see :mod:`bfr_model.params`).
    """

    def __init__(self, params: RigParams) -> None:
        self.params = params
        self.curve = OffsetCurve.from_params(params)
        P = rigid_vector(params)
        if params.ball.ellipticity > 0.0:
            P = np.concatenate([P, _arc_length_series(self.curve, P)])
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
        g = curve_terms(np.asarray(phi, float), *self.kernel_args)
        th = np.asarray(theta, float)
        st, ct = np.sin(th), np.cos(th)
        g1, g2 = gravity_from_curve(st, ct, g[0], g[1], g[2], g[3], self.P)
        return np.stack([g1, g2], -1)

    # -- state functions -------------------------------------------------------------------
    def accelerations(self, x: ArrayLike, u: float = 0.0) -> tuple[float, float]:
        """(theta_ddot, phi_ddot) [rad/s^2] at state x under command u [N m].

        A creeping spin's (seven entries) with its own spin x[6].
        """
        x = np.asarray(x, float)
        if self.creeps and x.shape[-1] == 7:
            r = creep_terms(x[0], x[1], x[2], x[3], x[6], float(u), *self._creep_args())
        else:
            r = rigid_terms(x[0], x[1], x[2], x[3], float(u), *self.kernel_args)
        return float(r[0]), float(r[1])

    def normal_force(self, x: ArrayLike, u: ArrayLike = 0.0) -> FloatArray:
        """Normal force of the frame on the ball [N] (> 0: the rigid model holds).

        A creeping spin's (seven entries) with its own spin x[..., 6].
        """
        x = np.asarray(x, float)
        u = np.asarray(u, float) + 0.0 * x[..., 0]
        if self.creeps and x.shape[-1] == 7:
            return creep_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], x[..., 6], u,
                               *self._creep_args())[5]
        return rigid_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], u, *self.kernel_args)[4]

    @property
    def translation_vector(self) -> FloatArray:
        """The parameter vector without the ball's spin inertia (``J_b = 0``).

        The translation alone, whose spin a creeping or slipping ball carries apart.
        """
        Pt = self.P.copy()
        Pt[I_JB] = 0.0
        return Pt

    def _creep_args(self) -> tuple:
        """``(1 / tau_s, J_b, Pt, *geom_args)`` of :func:`creep_terms` (Pt: J_b = 0)."""
        return (1.0 / self.P[I_TS], float(self.P[I_JB]), self.translation_vector,
                *self.geom_args)

    def energy(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(kinetic, potential) energy [J] of state(s) x, shape (..., 4+).

        A creeping spin's (seven entries): the translation's with ``J_b = 0`` plus
        ``J_b omega_b^2 / 2``.
        """
        x = np.asarray(x, float)
        if not (self.creeps and x.shape[-1] == 7):
            return energy_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3], *self.kernel_args)
        kin, pot = energy_terms(x[..., 0], x[..., 1], x[..., 2], x[..., 3],
                                self.translation_vector, *self.geom_args)
        return kin + 0.5 * self.P[I_JB] * x[..., 6] ** 2, pot

    def ball_position(self, x: ArrayLike) -> FloatArray:
        """Ball centre in the world frame, shape (..., 2) [m] (x, y; see :meth:`ball_sway`)."""
        x = np.asarray(x, float)
        g = curve_terms(x[..., 1], *self.kernel_args)
        px = self.P[I_CW] * g[0]
        py = g[1]
        st, ct = np.sin(x[..., 0]), np.cos(x[..., 0])
        return np.stack([ct * px - st * py, st * px + ct * py], -1)

    def ball_sway(self, x: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Ball centre's z position [m] and velocity [m/s] (non-zero with a wobbling frame).

        ``z = sin(w) p_x(phi)``, ``v_z = sin(w) p_x'(phi) phi_dot`` (seed eqs. 2.8-2.9 are
        this with the ball's angle replaced by theta).
        """
        x = np.asarray(x, float)
        g = curve_terms(x[..., 1], *self.kernel_args)
        s = self.P[I_SW]
        return s * g[0], s * g[2] * x[..., 3]

    def ball_spin_rate(self, x: ArrayLike) -> FloatArray:
        """Ball angular velocity in the world, omega_b = theta_dot - lam phi_dot / R [rad/s].

        A creeping spin's is its own state (the seventh entry) where x holds it.
        """
        x = np.asarray(x, float)
        if self.creeps and x.shape[-1] == 7:
            return x[..., 6]
        lam = self.curve.speed(x[..., 1])
        return x[..., 2] - lam * x[..., 3] / self.P[I_R]

    @property
    def creeps(self) -> bool:
        """Whether the ball's spin creeps (``ball.creep_time`` > 0): a seventh state."""
        return bool(self.P[I_TS] > 0.0)

    def state(self, x: ArrayLike) -> FloatArray:
        """The integrators' state from ``[theta, phi, theta_dot, phi_dot]`` (more ignored).

        Six entries, the work integrals ``W_in = W_diss = 0``; a creeping spin's seventh,
        omega_b, starts rolling (:meth:`ball_spin_rate` of the four).
        """
        x4 = np.asarray(x, float)[:4]
        out = np.zeros(7 if self.creeps else 6)
        out[:4] = x4
        if self.creeps:
            out[6] = float(self.ball_spin_rate(x4))
        return out

    def rhs_args(self, u: float) -> tuple:
        """``args`` tuple of :func:`rigid_rhs` for a held command u [N m]."""
        return (float(u), *self.kernel_args)

    def step(self, x: FloatArray, u: float, dt: float, n: int = 1, t0: float = 0.0) -> FloatArray:
        """Advance the state x (:meth:`state`) by n RK4 steps of dt [s] under a held u [N m]."""
        x = np.asarray(x, float)
        if x.shape[-1] != (7 if self.creeps else 6):
            raise ValueError(f"state of {x.shape[-1]} entries: this model's has "
                             f"{7 if self.creeps else 6} (RigidModel.state)")
        return rigid_rk4_steps(x, float(t0), float(dt), int(n), self.rhs_args(u))


def _arc_length_series(curve: OffsetCurve, P: FloatArray, n: int = 8192,
                       tol: float = 1e-15) -> FloatArray:
    """Fourier series of the (round ball's) arc length s(phi), for the elliptic ball.

    ``s(phi) = sbar phi + sum A_k (cos k phi - 1) + B_k sin k phi``;
    ``lam = a0 + sum (a_k cos k phi + b_k sin k phi)`` (FFT of lam on n points) integrates to
    ``A_k = -b_k / k``, ``B_k = a_k / k``. Sets ``P[I_SBAR]``, ``P[I_NS]`` and returns the
    coefficient block ``[A_1..A_N, B_1..B_N]`` to append to P (N up to the last coefficient
    above ``tol`` metres).
    """
    phi = 2.0 * np.pi * np.arange(n) / n
    c = np.fft.rfft(curve.speed(phi)) / n
    k = np.arange(1, c.size)
    a = 2.0 * c.real[1:]
    b = -2.0 * c.imag[1:]
    A = -b / k
    B = a / k
    big = np.nonzero(np.maximum(np.abs(A), np.abs(B)) > tol)[0]
    N = int(big[-1]) + 1 if big.size else 0
    P[I_SBAR] = c.real[0]
    P[I_NS] = N
    return np.concatenate([A[:N], B[:N]])
