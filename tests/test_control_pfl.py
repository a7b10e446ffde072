"""Partial feedback linearisation and transverse linearisation (bfr_control.transverse)."""

from __future__ import annotations

import numpy as np
import pytest
from bfr_control.constraint import ConstraintSpec, VirtualConstraint
from bfr_control.orbit import OrbitSpec, PeriodicOrbit, reduced_dynamics
from bfr_control.transverse import (
    pfl_torque,
    pfl_torque_explicit,
    transverse_coordinates,
    transverse_linearization,
    y_ddot,
)
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params

NOMINAL = load_params()
LOSSY = NOMINAL.replace(**{"joint.viscous_friction": 3e-4, "joint.coulomb_friction": 2e-3,
                           "track.rolling_resistance": 4e-3, "actuator.torque_gain": 0.9})


def random_states(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-4, 4, n), rng.uniform(-4, 4, n),
                            rng.uniform(-6, 9, n), rng.uniform(0.3, 5, n)])


@pytest.mark.parametrize("params", [NOMINAL, LOSSY], ids=["nominal", "with_losses"])
def test_pfl_is_exact_on_the_model(params: object) -> None:
    """u from PFL for a commanded w; the model's accelerations then give y_ddot = w."""
    model = RigidModel(params)
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03))
    rng = np.random.default_rng(7)
    for x in random_states(20, 1):
        _, th1, th2 = vc.evaluate(x[1])
        w = float(rng.uniform(-80.0, 80.0))
        u = pfl_torque(model, th1, th2, x, w)
        got = float(y_ddot(model, th1, th2, x, u))
        assert abs(got - w) <= 1e-9 * max(abs(w), 1.0)


@pytest.mark.parametrize("params", [NOMINAL, LOSSY.replace(**{"track.rolling_resistance": 0.0})],
                         ids=["nominal", "joint_friction"])
def test_explicit_pfl_formula_matches(params: object) -> None:
    """Seed eq. 4.46 written out with M, c, G gives the same torque and y_ddot = w."""
    model = RigidModel(params)
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03))
    xs = random_states(30, 2)
    _, th1, th2 = vc.evaluate(xs[:, 1])
    w = np.linspace(-50.0, 50.0, 30)
    u = pfl_torque_explicit(model, th1, th2, xs, w)
    assert np.max(np.abs(y_ddot(model, th1, th2, xs, u) - w)) < 1e-9 * 50.0
    u2 = np.array([pfl_torque(model, th1[i], th2[i], xs[i], w[i]) for i in range(30)])
    assert np.max(np.abs(u - u2)) < 1e-12


def test_transverse_linearization_matches_finite_differences() -> None:
    """A(phi), B(phi) against central differences of the exact PFL'd transverse dynamics."""
    model = RigidModel(NOMINAL)
    vc = VirtualConstraint(model, ConstraintSpec(c=0.03))
    orbit = PeriodicOrbit(model, vc, OrbitSpec(mean_phi_dot=2.4))

    def f(phi: float, xp: np.ndarray, w: float) -> np.ndarray:
        I_dev, y, y_dot = xp
        th0, th1, th2, Y = orbit.table(phi)
        pd = np.sqrt(Y + I_dev)
        x = np.array([th0 + y, phi, y_dot + th1 * pd, pd])
        u = pfl_torque(model, th1, th2, x, w)
        thdd, phdd = model.accelerations(x, u)
        a, b, g = reduced_dynamics(model, vc, np.array(phi))
        dY = -2.0 * b / a * Y - 2.0 * g / a
        return np.array([2.0 * pd * phdd - dY * pd, y_dot, thdd - th1 * phdd - th2 * pd * pd])

    for phi in (0.2, 1.0, 1.7, 2.9):
        A, B = transverse_linearization(orbit, np.array(phi))
        # on the orbit the transverse state is at rest
        assert np.max(np.abs(f(phi, np.zeros(3), 0.0))) < 1e-8
        h = 1e-6
        An = np.column_stack([(f(phi, h * e, 0.0) - f(phi, -h * e, 0.0)) / (2 * h)
                              for e in np.eye(3)])
        Bn = (f(phi, np.zeros(3), h) - f(phi, np.zeros(3), -h)) / (2 * h)
        assert np.max(np.abs(A - An)) < 1e-7 * np.max(np.abs(A))
        assert np.max(np.abs(B - Bn)) < 1e-7 * np.max(np.abs(B))


def test_transverse_coordinates_vanish_on_the_orbit() -> None:
    model = RigidModel(NOMINAL)
    orbit = PeriodicOrbit(model, VirtualConstraint(model, ConstraintSpec(c=0.03)),
                          OrbitSpec(mean_phi_dot=2.4))
    phi = np.linspace(-5.0, 5.0, 23)
    tr = transverse_coordinates(orbit, orbit.state(phi))
    assert np.max(np.abs(tr)) < 1e-9
    x = orbit.state(0.7) + np.array([0.01, 0.0, 0.0, 0.1])
    I_dev, y, _, z = transverse_coordinates(orbit, x)
    assert y == pytest.approx(0.01)
    assert z == pytest.approx(0.1)
    assert I_dev == pytest.approx((orbit.phi_dot(0.7) + 0.1) ** 2 - orbit.phi_dot_sq(0.7))
