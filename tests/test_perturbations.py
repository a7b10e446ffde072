"""Perturbation library: each switch changes the dynamics as it should; rough tracks are seeded."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_model.dynamics import RigidModel, curve_terms, rigid_rhs, rigid_terms
from bfr_model.integrators import rk4_steps, solve_adaptive
from bfr_model.params import ParameterError, load_params
from bfr_model.perturbations import (
    PERTURBATIONS,
    bump_row,
    hc_stiffness_from_linear,
    load_study,
    perturbed,
    rough_track,
    with_asperities,
    write_params,
)
from bfr_model.simulate import simulate

NOMINAL = load_params()
STUDY = load_study()
X0 = np.array([0.0, 0.3, 0.0, 0.0])  # the ball rocking in the waist's valley, F_n > 0


def _run(params, duration: float = 1.0, u: float = 0.0):  # noqa: ANN001, ANN202
    return simulate(RigidModel(params), X0, duration, u, dt=1e-3)


@pytest.mark.parametrize("key", ["wobble", "ellipse", "bump", "mass", "radius", "pitch"])
def test_conservative_perturbations_conserve_energy(key: str) -> None:
    """No losses in these: the exact Lagrangian conserves T + V (adaptive integrator)."""
    m = RigidModel(perturbed(NOMINAL, key, STUDY))
    x = np.array([0.3, 1.2, 0.5, 2.0, 0.0, 0.0])
    _, xs = solve_adaptive(rigid_rhs, x, (0.0, 2.0), m.rhs_args(0.0),
                           t_eval=np.linspace(0.0, 2.0, 201))
    kin, pot = m.energy(xs)
    e = kin + pot
    assert np.max(np.abs(e - e[0])) / abs(e[0]) < 1e-8


def test_friction_perturbations_dissipate() -> None:
    """Rolling resistance and load-dependent joint friction remove energy, the balance holds."""
    for key in ("rolling", "joint"):
        p = perturbed(NOMINAL, key, STUDY)
        res = simulate(RigidModel(p), np.array([0.1, 0.2, 1.0, 2.0]), 0.5,
                       lambda t: 0.01 * math.sin(3 * t), dt=5e-4)
        assert res.energy_drift_rel < 1e-7
        assert res.x[-1, 5] > 0.0
        # dissipation only while the ball presses on the track (where the rigid model holds)
        on = (res.normal_force[:-1] > 0.0) & (res.normal_force[1:] > 0.0)
        assert on.sum() > 100
        assert np.all(np.diff(res.x[:, 5])[on] >= -1e-15)


def test_joint_load_friction_is_c_times_the_bearing_load() -> None:
    """T = c |m (r_dd + g) + m_f g|: with the ball at rest on the held frame, F_load is the
    weight of ball and frame, so the dissipated power is c (m + m_f) g |theta_dot|."""
    c = 1e-3
    p = NOMINAL.replace(**{"joint.load_friction": c, "joint.coulomb_smoothing": 1e-9})
    m = RigidModel(p)
    # ball at the bottom of the valley, frame turning slowly: loads are static to first order
    thd = 1e-4
    _, _, _, p_diss, fn = rigid_terms(0.0, 0.0, thd, thd, 0.0, *m.kernel_args)
    load = (p.ball.mass + p.frame.mass) * p.environment.gravity
    assert p_diss == pytest.approx(c * load * thd, rel=1e-3)
    assert fn == pytest.approx(p.ball.mass * p.environment.gravity, rel=1e-3)


def test_normal_force_matches_finite_differences_with_wobble_and_ellipse() -> None:
    """F_n = n3 . m (r_dd + g y) with the 3-D ball position of the wobbling frame."""
    w = 0.2
    p = NOMINAL.replace(**{"frame.wobble": w, "ball.ellipticity": 1e-3})
    m = RigidModel(p)
    x0 = np.array([0.3, 1.2, 0.5, 2.0, 0.0, 0.0])
    u = 0.01
    h = 1e-4

    def pos(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = curve_terms(x[1], *m.kernel_args)
        c, s = math.cos(w), math.sin(w)
        rz = np.array([[math.cos(x[0]), -math.sin(x[0]), 0], [math.sin(x[0]), math.cos(x[0]), 0],
                       [0, 0, 1]])
        return rz @ np.array([c * g[0], g[1], s * g[0]]), rz @ np.array([c * g[6], g[7], s * g[6]])

    xp = rk4_steps(rigid_rhs, x0, 0.0, h, 1, m.rhs_args(u))
    xm = rk4_steps(rigid_rhs, x0, 0.0, -h, 1, m.rhs_args(u))
    acc = (pos(xp)[0] - 2 * pos(x0)[0] + pos(xm)[0]) / h**2
    fn_fd = p.ball.mass * pos(x0)[1] @ (acc + np.array([0.0, 9.81, 0.0]))
    fn = rigid_terms(*x0[:4], u, *m.kernel_args)[4]
    assert fn == pytest.approx(fn_fd, rel=1e-5)
    z, vz = m.ball_sway(x0)
    assert z == pytest.approx(math.sin(w) * curve_terms(x0[1], *m.kernel_args)[0])
    assert abs(vz) > 0.0


def test_switches_change_the_dynamics_in_the_expected_direction() -> None:
    nominal = _run(NOMINAL)
    # heavier ball and frame: more kinetic energy in the same state
    km, _ = RigidModel(perturbed(NOMINAL, "mass", STUDY)).energy(np.array([0.2, 0.5, 2.0, 2.0]))
    kn, _ = RigidModel(NOMINAL).energy(np.array([0.2, 0.5, 2.0, 2.0]))
    assert km == pytest.approx(1.01 * kn, rel=1e-9)
    # smaller rolling radius: R* = 0.99 R and a faster spin for the same rolling
    pr = perturbed(NOMINAL, "radius", STUDY)
    assert pr.ball.rolling_radius == pytest.approx(0.99 * NOMINAL.ball.rolling_radius)
    # a bump raises the ball's potential energy where it stands (normal offset m g h n_y)
    pb = perturbed(NOMINAL, "bump", STUDY)
    phi_b = STUDY.perturbations.smooth_bump_phi
    vb = RigidModel(pb).energy(np.array([phi_b, phi_b, 0.0, 0.0]))[1]
    vn = RigidModel(NOMINAL).energy(np.array([phi_b, phi_b, 0.0, 0.0]))[1]
    h = STUDY.perturbations.bump_height
    assert 0.8 * NOMINAL.ball.mass * 9.81 * h < vb - vn < 1.05 * NOMINAL.ball.mass * 9.81 * h
    # pitched shaft: in-plane gravity g cos(eps), the ball rocks more slowly
    pp = perturbed(NOMINAL, "pitch", STUDY)
    assert pp.environment.in_plane_gravity == pytest.approx(
        9.81 * math.cos(STUDY.perturbations.misalignment))
    # rolling friction: the rocking ball loses energy (the nominal one keeps it)
    rf = _run(perturbed(NOMINAL, "rolling", STUDY), 0.5)
    n05 = _run(NOMINAL, 0.5)
    assert np.all(rf.normal_force > 0.0)
    assert rf.energy[-1] < rf.energy[0] - 1e-7
    assert abs(n05.energy[-1] - n05.energy[0]) < 1e-10
    assert rf.energy[0] - rf.energy[-1] == pytest.approx(rf.x[-1, 5], rel=1e-6)
    # elliptic ball: the normal force is modulated at the ball's spin (twice per turn)
    pe = perturbed(NOMINAL, "ellipse", STUDY)
    fe = _run(pe).normal_force
    assert np.std(fe - nominal.normal_force) > 1e-4
    # elastic: the contact model's Hunt-Crossley k has the seed's linear stiffness at m g
    pk = perturbed(NOMINAL, "elastic", STUDY)
    load = NOMINAL.ball.mass * NOMINAL.environment.in_plane_gravity
    k = pk.contact.stiffness
    w = (load / k) ** (2 / 3)
    assert 1.5 * k * w**0.5 == pytest.approx(STUDY.perturbations.elastic_stiffness)
    assert hc_stiffness_from_linear(1.5 * k * w**0.5, load) == pytest.approx(k)
    assert set(PERTURBATIONS) >= {"mass", "radius", "rolling", "joint", "wobble", "pitch",
                                  "bump", "ellipse", "elastic"}


def test_rough_track_is_seeded_and_reproducible(tmp_path) -> None:  # noqa: ANN001
    a = rough_track(NOMINAL, np.random.default_rng(7), 25, (0.5, 1.5))
    b = rough_track(NOMINAL, np.random.default_rng(7), 25, (0.5, 1.5))
    c = rough_track(NOMINAL, np.random.default_rng(8), 25, (0.5, 1.5))
    for u, v in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, v)
    assert not np.array_equal(a[0], c[0])
    assert np.all((a[0] >= 0.5) & (a[0] <= 1.5)) and np.all(np.diff(a[0]) >= 0)
    assert np.all((a[1] >= 1e-4) & (a[1] <= 5e-4))
    p = with_asperities(NOMINAL, *a)
    f = write_params(p, tmp_path / "rough.yaml", header="test")
    q = load_params(f)
    assert q == p
    assert len(q.track.asperity_phi) == 25
    # the rigid model leaves sharp asperities out (they are the contact model's)
    RigidModel(q)


def test_bump_row_spacing_along_the_contour() -> None:
    ph, h, w = bump_row(NOMINAL, 1.0, 30, 0.03, 5e-4, 1e-4)
    a, b = NOMINAL.frame.contour.a, NOMINAL.frame.contour.b
    mid = 0.5 * (ph[1:] + ph[:-1])
    speed = np.hypot(a - b * np.cos(2 * mid), 2 * b * np.sin(2 * mid))  # |delta'|
    assert np.diff(ph) * speed == pytest.approx(np.full(29, 1e-3), rel=1e-3)
    sp = np.hypot(a - b * np.cos(2 * ph), 2 * b * np.sin(2 * ph))
    assert w * sp == pytest.approx(np.full(30, 1e-4), rel=1e-2)
    assert np.all(h == 5e-4)


def test_study_file_and_errors(tmp_path) -> None:  # noqa: ANN001
    s = load_study()
    assert s.perturbations.misalignment == pytest.approx(math.pi / 80)
    assert s.perturbations.joint_load_friction == 1e-5
    bad = tmp_path / "s.yaml"
    bad.write_text("perturbations:\n  mass_increas: 0.1\n")
    with pytest.raises(ParameterError, match="mass_increas"):
        load_study(bad)
    with pytest.raises(KeyError):
        perturbed(NOMINAL, "nope", s)
