"""An independent derivation of the equations of motion with sympy.

Nothing from bfr_sim's kernels is reused: the contour, the offset curve, the rolling
constraint and the Lagrangian are written here from rig-brief.md, differentiated by sympy,
and the resulting accelerations are compared with the compiled kernel at random states.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import sympy as sp
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params

#: Derivatives of the contour rho(phi) the equations need: up to the third (the contact
#: normal holds rho', the kinetic energy and the mass matrix rho'', the rest rho''').
_ORDERS = 4


@functools.cache
def _derive_general():  # noqa: ANN202
    """The equations for any contour rho(phi) and any constants, lambdified once.

    rho is an undefined function of phi while sympy differentiates the Lagrangian (the
    expressions stay small); its value and derivatives, and the constants, are arguments
    of the lambdified function: ``f(theta, phi, theta_dot, phi_dot, rho_0, ..., rho_3,
    R, m, J_b, J_f, g, m_f e, theta_e)`` with ``rho_k`` the k-th derivative.
    """
    th, ph, thd, phd = sp.symbols("theta phi theta_dot phi_dot", real=True)
    R, m, jb, jf, g, me, th_e = sp.symbols("R m J_b J_f g m_f_e theta_e", real=True)
    rho_f = sp.Function("rho")(ph)
    rho_k = sp.symbols(f"rho0:{_ORDERS}", real=True)
    delta = sp.Matrix([rho_f * sp.sin(ph), rho_f * sp.cos(ph)])
    d1 = delta.diff(ph)
    tang = d1 / sp.sqrt(d1.dot(d1))
    normal = sp.Matrix([-tang[1], tang[0]])
    p = delta + R * normal
    rot = sp.Matrix([[sp.cos(th), -sp.sin(th)], [sp.sin(th), sp.cos(th)]])
    r = rot * p
    q = [th, ph]
    qd = [thd, phd]
    r_dot = r.diff(th) * thd + r.diff(ph) * phd
    s_dot = sp.sqrt(p.diff(ph).dot(p.diff(ph))) * phd
    omega_b = thd - s_dot / R
    T = sp.Rational(1, 2) * (m * r_dot.dot(r_dot) + jb * omega_b**2 + jf * thd**2)
    # the frame's centre of mass at e [sin theta_e, cos theta_e] in frame coordinates
    com = rot * sp.Matrix([me * sp.sin(th_e), me * sp.cos(th_e)])
    V = m * g * r[1] + g * com[1]
    L = T - V
    M = sp.Matrix(2, 2, lambda i, j: sp.diff(L, qd[i], qd[j]))
    rest = sp.Matrix([
        sum(sp.diff(L, qd[i], q[j]) * qd[j] for j in range(2)) - sp.diff(L, q[i])
        for i in range(2)])
    nw = rot * normal
    out = [M, rest, r, nw, r.diff(th), r.diff(ph)]
    # rho and its derivatives -> plain symbols, the highest order first
    subs = [(sp.Derivative(rho_f, (ph, k)), rho_k[k]) for k in range(_ORDERS - 1, 0, -1)]
    out = [e.subs(subs).subs(rho_f, rho_k[0]) for e in out]
    # a derivative beyond _ORDERS - 1 would be left as one (of rho_{_ORDERS - 1})
    assert not any(e.has(rho_f) or e.has(sp.Derivative) for e in out), "raise _ORDERS"
    return sp.lambdify((th, ph, thd, phd, *rho_k, R, m, jb, jf, g, me, th_e), out, "numpy",
                       cse=True)


def _derive(params):  # noqa: ANN001, ANN202
    """Lambdified M(q), rest(q, q_dot) with M q_ddot + rest = Q, and F_n's pieces."""
    ph = sp.symbols("phi", real=True)
    c = params.frame.contour
    t = params.track
    rho = c.a - c.b * sp.cos(2 * ph)
    for k, ck, sk in zip(c.harmonic_orders, c.harmonic_cos, c.harmonic_sin, strict=True):
        rho += ck * sp.cos(k * ph) + sk * sp.sin(k * ph)
    for b0, h, w in zip(t.bump_phi, t.bump_height, t.bump_width, strict=True):
        rho += h * sp.exp(-((ph - b0) ** 2) / (2 * w**2))  # bumps away from the wrap point
    contour = sp.lambdify(ph, [rho.diff(ph, k) if k else rho for k in range(_ORDERS)],
                          "numpy")
    consts = (params.ball.rolling_radius, params.ball.mass, params.ball.inertia,
              params.frame.inertia, params.environment.in_plane_gravity,
              params.frame.imbalance, params.frame.imbalance_angle)
    general = _derive_general()

    def f(th: float, ph: float, thd: float, phd: float) -> list:
        return general(th, ph, thd, phd, *(float(v) for v in contour(ph)), *consts)

    return f


@pytest.mark.parametrize("variant", ["nominal", "harmonics_bump", "imbalance_offset"])
def test_equations_match_independent_sympy_derivation(variant: str) -> None:
    p = load_params()
    if variant == "harmonics_bump":
        p = p.replace(**{"frame.contour.harmonic_orders": [3, 4],
                         "frame.contour.harmonic_cos": [1e-3, -2e-3],
                         "frame.contour.harmonic_sin": [5e-4, 1e-3],
                         "track.bump_phi": [0.7], "track.bump_height": [5e-4],
                         "track.bump_width": [0.1],
                         "environment.axis_misalignment": 0.05})
    if variant == "imbalance_offset":
        # frame imbalance (a gravity term of the frame) and the drive's gain and offset:
        # Q_theta = k_u u + tau_0
        p = p.replace(**{"frame.imbalance": 2e-3, "frame.imbalance_angle": 0.7,
                         "actuator.torque_offset": 1.5e-3, "actuator.torque_gain": 1.3})
    model = RigidModel(p)
    f = _derive(p)
    k_u, tau0 = p.actuator.torque_gain, p.actuator.torque_offset
    rng = np.random.default_rng(11)
    for _ in range(25):
        th = rng.uniform(-np.pi, np.pi)
        ph = rng.uniform(0.2, 1.2) if variant == "harmonics_bump" else rng.uniform(-4, 4)
        thd, phd = rng.normal(0.0, 2.5, 2)
        u = rng.normal(0.0, 0.05)
        M, rest, *_ = f(th, ph, thd, phd)
        qdd_ref = np.linalg.solve(np.array(M, float),
                                  np.array([k_u * u + tau0, 0.0])
                                  - np.array(rest, float).ravel())
        qdd = np.array(model.accelerations([th, ph, thd, phd], u))
        np.testing.assert_allclose(qdd, qdd_ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(qdd_ref)))
        np.testing.assert_allclose(model.mass_matrix(ph), np.array(M, float), rtol=1e-10)


def test_normal_force_matches_newton() -> None:
    """F_n from the kernel equals n . m (r_ddot + g y) with r_ddot from the sympy kinematics."""
    p = load_params()
    model = RigidModel(p)
    f = _derive(p)
    rng = np.random.default_rng(5)
    m, g = p.ball.mass, p.environment.in_plane_gravity
    for _ in range(10):
        x = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), *rng.normal(0, 2, 2)])
        u = rng.normal(0.0, 0.05)
        thdd, phdd = model.accelerations(x, u)
        # r_ddot by differentiating r_dot(q, q_dot) numerically along the motion
        h = 1e-6
        xs = [x + s * h * np.array([x[2], x[3], thdd, phdd]) for s in (-1, 1)]
        vel = []
        for xi in xs:
            _, _, _, _, r_th, r_ph = f(*xi)
            vel.append(np.array(r_th, float).ravel() * xi[2]
                       + np.array(r_ph, float).ravel() * xi[3])
        r_ddot = (vel[1] - vel[0]) / (2 * h)
        nw = np.array(f(*x)[3], float).ravel()
        fn_ref = m * float(nw @ (r_ddot + np.array([0.0, g])))
        assert float(model.normal_force(x, u)) == pytest.approx(fn_ref, rel=1e-6, abs=1e-9)
