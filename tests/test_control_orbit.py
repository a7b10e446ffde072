"""Virtual constraint, reduced dynamics and periodic orbit (bfr_control.constraint / .orbit)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_control.constraint import ConstraintSpec, VirtualConstraint, contour_period
from bfr_control.orbit import OrbitError, OrbitSpec, PeriodicOrbit, reduced_dynamics
from bfr_control.periodic import PeriodicTable, periodic_integral
from bfr_control.transverse import pfl_torque
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params
from scipy.integrate import solve_ivp

NOMINAL = load_params()


@pytest.fixture(scope="module")
def model() -> RigidModel:
    return RigidModel(NOMINAL)


@pytest.fixture(scope="module")
def orbit(model: RigidModel) -> PeriodicOrbit:
    return PeriodicOrbit(model, VirtualConstraint(model, ConstraintSpec(c=0.03)),
                         OrbitSpec(mean_phi_dot=2.4))


def test_periodic_integral_and_table_are_spectral() -> None:
    """Spectral integral of exp(m s) f(s) and Hermite interpolation against closed forms."""
    P = math.pi
    n = 128
    phi = np.arange(n) * P / n
    f = np.cos(2 * phi) + 0.5
    for m in (0.0, 0.4):
        F, FP = periodic_integral(f, P, m)

        def exact(x: np.ndarray, m: float = m) -> np.ndarray:
            if m == 0.0:
                return np.sin(2 * x) / 2 + 0.5 * x
            # int_0^x e^{ms} cos 2s ds = (e^{mx}(m cos 2x + 2 sin 2x) - m) / (m^2 + 4)
            return ((np.exp(m * x) * (m * np.cos(2 * x) + 2 * np.sin(2 * x)) - m) / (m * m + 4)
                    + 0.5 * (np.exp(m * x) - 1) / m)

        assert np.max(np.abs(F - exact(phi))) < 1e-13
        assert abs(FP - exact(np.array(P))) < 1e-13
    tab = PeriodicTable(P, np.column_stack([np.sin(2 * phi) + phi]), drift=[1.0])
    x = np.array([-4.0, 0.3, 10.0])
    assert np.max(np.abs(tab.evaluate(x)[:, 0] - (np.sin(2 * x) + x))) < 1e-7
    assert abs(tab(0.3)[0] - tab.evaluate(0.3)[0]) < 1e-14


def test_constraint_tangent_inclination_and_symmetry(model: RigidModel) -> None:
    """World inclination of the tangent is atan(c sin 2 phi); Theta(phi + pi) = Theta + pi."""
    c = 0.03
    vc = VirtualConstraint(model, ConstraintSpec(c=c))
    assert contour_period(model) == pytest.approx(math.pi)
    phi = np.linspace(-4.0, 4.0, 41)
    th = vc(phi)
    t = model.curve.tangent(phi)  # frame coordinates, direction of increasing phi
    world_t = np.stack([np.cos(th) * t[:, 0] - np.sin(th) * t[:, 1],
                        np.sin(th) * t[:, 0] + np.cos(th) * t[:, 1]], -1)
    incl = np.arctan2(world_t[:, 1], world_t[:, 0])
    assert np.max(np.abs(incl - np.arctan(c * np.sin(2 * phi)))) < 1e-12
    assert np.max(np.abs(vc(phi + math.pi) - vc(phi) - math.pi)) < 1e-12
    at = vc.tangent_angle(np.array([0.0, 2 * math.pi]))[0]
    assert at[0] == pytest.approx(0.0, abs=1e-15)
    assert at[1] == pytest.approx(-2 * math.pi, abs=1e-12)


def test_constraint_derivatives_match_finite_differences(model: RigidModel) -> None:
    vc = VirtualConstraint(model, ConstraintSpec(c=0.05, fourier_orders=(1, 3),
                                                 fourier_cos=(0.01, 0.002),
                                                 fourier_sin=(0.02, -0.004)))
    phi = np.linspace(-3.0, 3.0, 13)
    h = 1e-5
    _, th1, th2 = vc.evaluate(phi)
    assert np.max(np.abs((vc(phi + h) - vc(phi - h)) / (2 * h) - th1)) < 1e-8
    d2 = (vc.evaluate(phi + h)[1] - vc.evaluate(phi - h)[1]) / (2 * h)
    assert np.max(np.abs(d2 - th2)) < 1e-7 * max(1.0, float(np.max(np.abs(th2))))


def test_reduced_dynamics_match_model(model: RigidModel) -> None:
    """On the constraint, y_ddot = 0 (PFL): phi_ddot = -(beta phi_dot^2 + gamma) / alpha."""
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03))
    phi = np.linspace(0.1, 6.0, 11)
    alpha, beta, gamma = reduced_dynamics(model, vc, phi)
    th0, th1, th2 = vc.evaluate(phi)
    for i, p in enumerate(phi):
        pd = 1.3 + 0.2 * i
        x = np.array([th0[i], p, th1[i] * pd, pd])
        u = pfl_torque(model, th1[i], th2[i], x, 0.0)
        _, phdd = model.accelerations(x, u)
        expected = -(beta[i] * pd * pd + gamma[i]) / alpha[i]
        assert phdd == pytest.approx(expected, rel=1e-10, abs=1e-10)


def test_orbit_is_periodic_positive_and_has_the_requested_speed(orbit: PeriodicOrbit) -> None:
    """Integrate dY/dphi = -2 beta/alpha Y - 2 gamma/alpha independently over one period."""
    assert orbit.kind == "family"  # reversible constraint on a symmetric frame
    model, vc = orbit.model, orbit.constraint

    def rhs(phi: float, Y: np.ndarray) -> np.ndarray:
        a, b, g = reduced_dynamics(model, vc, np.array(phi))
        return -2.0 * b / a * Y - 2.0 * g / a

    sol = solve_ivp(rhs, (0.0, math.pi), [orbit.Y[0]], method="DOP853", rtol=1e-12,
                    atol=1e-12, dense_output=True)
    assert sol.y[0, -1] == pytest.approx(orbit.Y[0], rel=1e-9)
    mid = np.linspace(0.0, math.pi, 17)
    assert np.max(np.abs(sol.sol(mid)[0] - orbit.phi_dot_sq(mid))) < 1e-8 * orbit.Y.max()
    assert np.all(orbit.Y > 0.0)
    assert np.all(orbit.alpha > 0.0)
    assert orbit.mean_phi_dot == pytest.approx(2.4, rel=1e-9)
    # the rig: the ball advances about pi every 1.2-1.5 s
    assert 1.2 <= orbit.time_period <= 1.5


def test_default_orbit_is_within_the_rig_torque(orbit: PeriodicOrbit) -> None:
    """c = +0.03 needs less than the 0.1 N m clamp on the orbit; c = -0.03 would need 0.35."""
    assert np.max(np.abs(orbit.nominal_torque())) < 0.1
    model = orbit.model
    other = PeriodicOrbit(model, VirtualConstraint(model, ConstraintSpec(c=-0.03)),
                          OrbitSpec(mean_phi_dot=2.4))
    assert np.max(np.abs(other.nominal_torque())) > 0.1


def test_orbit_errors_name_the_reason(model: RigidModel) -> None:
    # an even (cos) term breaks reversibility: an isolated orbit with phi_dot^2 < 0
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03, fourier_orders=(1,),
                                                 fourier_cos=(0.05,), fourier_sin=(0.0,)))
    with pytest.raises(OrbitError, match=r"turn back|no periodic orbit"):
        PeriodicOrbit(model, vc, OrbitSpec(mean_phi_dot=2.4))
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03))
    with pytest.raises(OrbitError, match="too slow"):
        PeriodicOrbit(model, vc, OrbitSpec(mean_phi_dot=None, phi_dot_0=0.5))
