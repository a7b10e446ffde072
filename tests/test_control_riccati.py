"""Periodic Riccati gains, their stability and their cache (bfr_control.riccati)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bfr_control.constraint import ConstraintSpec, VirtualConstraint
from bfr_control.orbit import OrbitSpec, PeriodicOrbit
from bfr_control.riccati import (
    RiccatiWeights,
    _rk4_backward,
    compute_gains,
    monodromy,
)
from bfr_control.transverse import transverse_linearization
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params

NOMINAL = load_params()


def make_orbit(params: object = NOMINAL, grid: int = 2048) -> PeriodicOrbit:
    model = RigidModel(params)
    return PeriodicOrbit(model, VirtualConstraint(model, ConstraintSpec(c=0.03)),
                         OrbitSpec(mean_phi_dot=2.4, grid=grid))


@pytest.fixture(scope="module")
def solved(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    orbit = make_orbit()
    gains = compute_gains(orbit, RiccatiWeights(), directory=tmp_path_factory.mktemp("gains"))
    return orbit, gains


def test_riccati_solution_is_periodic(solved: tuple) -> None:
    """One more backward period from X(0) returns X(0) (relative 1e-8), X symmetric > 0."""
    orbit, gains = solved
    assert gains.info["periodicity"] < 1e-9
    n = orbit.phi.size
    h = orbit.period / n
    half = np.arange(2 * n + 1) * (h / 2.0)
    A, B = transverse_linearization(orbit, half)
    s = 1.0 / orbit.phi_dot(half)
    w = RiccatiWeights()
    X0 = gains.X[0]
    X1 = _rk4_backward(X0, A, B, s, w.q_matrix, w.gamma, h, None)
    assert np.max(np.abs(X1 - X0)) < 1e-8 * np.max(np.abs(X0))
    assert np.all(np.linalg.eigvalsh(gains.X) > 0.0)


def test_closed_loop_monodromy_is_stable(solved: tuple) -> None:
    """Spectral radius of the closed-loop transverse monodromy matrix < 1; open loop is not."""
    orbit, gains = solved
    rho = np.max(np.abs(np.linalg.eigvals(monodromy(orbit, gains.table))))
    rho_open = np.max(np.abs(np.linalg.eigvals(monodromy(orbit, gains.table, open_loop=True))))
    assert rho < 0.5
    assert rho_open >= 1.0 - 1e-6
    assert gains.info["monodromy_spectral_radius"] == pytest.approx(rho)


def test_gains_are_in_the_rig_range(solved: tuple) -> None:
    """The rig's gains are about k_y = -100, k_ydot = -17 (rig-brief.md)."""
    _, gains = solved
    k = gains.K
    assert np.all(k[:, 1] < -80.0) and np.all(k[:, 1] > -250.0)
    assert np.all(k[:, 2] < -12.0) and np.all(k[:, 2] > -35.0)


def test_gain_cache_hit_and_recompute_on_change(tmp_path: Path) -> None:
    orbit = make_orbit(grid=256)
    w = RiccatiWeights()
    first = compute_gains(orbit, w, directory=tmp_path)
    assert first.info["cache"] == "miss"
    files = list(tmp_path.glob("gains_*.npz"))
    assert len(files) == 1
    again = compute_gains(make_orbit(grid=256), w, directory=tmp_path)
    assert again.info["cache"] == "hit"
    assert np.array_equal(again.K, first.K)
    # a model parameter changes: recomputed, new file. J_f does not enter the transverse
    # dynamics under PFL (only M11 holds it), so the gains are the same ...
    heavier = make_orbit(NOMINAL.replace(**{"frame.inertia": 2.0e-3}), grid=256)
    changed = compute_gains(heavier, w, directory=tmp_path)
    assert changed.info["cache"] == "miss"
    assert len(list(tmp_path.glob("gains_*.npz"))) == 2
    assert np.allclose(changed.K, first.K, rtol=1e-9)
    # ... while the ball's inertia does change them
    ball = make_orbit(NOMINAL.replace(**{"ball.inertia": 7.0e-7}), grid=256)
    changed = compute_gains(ball, w, directory=tmp_path)
    assert changed.info["cache"] == "miss"
    assert not np.allclose(changed.K, first.K, rtol=1e-3)
    # the weights change: recomputed too
    other = compute_gains(make_orbit(grid=256), RiccatiWeights(q_I=1.0), directory=tmp_path)
    assert other.info["cache"] == "miss"
    # the stored inputs are checked, not only the file name
    with np.load(files[0]) as d:
        assert '"frame"' in str(d["inputs"]) and '"weights"' in str(d["inputs"])
