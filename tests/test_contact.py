"""Contact model: exact closest point, energy balance, restitution, agreement with rigid."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_model.closest_point import (
    closest_point,
    contour_data,
    seed_eq_4_36,
    taylor_closest_point,
)
from bfr_model.contact import (
    IWD,
    IWHC,
    IWIN,
    ContactModel,
    damping_for_restitution,
    restitution,
)
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import contour_kernel
from bfr_model.params import load_params
from bfr_model.simulate import simulate

NOMINAL = load_params()
ROUGH = NOMINAL.replace(**{"track.asperity_phi": [0.1, -0.12, 0.105],
                           "track.asperity_height": [5e-4, 3e-4, 2e-4],
                           "track.asperity_width": [0.003, 0.004, 0.002]})


def _brute(data, c: np.ndarray, n: int = 400_000) -> tuple[float, float]:  # noqa: ANN001
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    r = contour_kernel(phi, data.rho0, data.orders, data.ccos, data.csin,
                       np.concatenate([data.bphi, data.aphi]),
                       np.concatenate([data.bh, data.ah]),
                       np.concatenate([data.bw, data.aw]))[0]
    d = np.hypot(r * np.sin(phi) - c[0], r * np.cos(phi) - c[1])
    i = int(np.argmin(d))
    return float(phi[i]), float(d[i])


@pytest.mark.parametrize("params", [NOMINAL, ROUGH], ids=["smooth", "asperities"])
def test_closest_point_matches_brute_force(params) -> None:  # noqa: ANN001
    """Global solve = dense search (to its grid), and it is a stationary point to 1e-12."""
    data = contour_data(params)
    rng = np.random.default_rng(3)
    pts = [np.array([r * math.sin(a), r * math.cos(a)]) for a, r in
           zip(rng.uniform(-0.3, 0.3, 6), rng.uniform(0.075, 0.085, 6), strict=True)]
    pts += [np.array([0.12 * math.sin(a), 0.12 * math.cos(a)]) for a in rng.uniform(-3, 3, 4)]
    h = 2 * np.pi / 400_000
    for c in pts:
        phi, d = closest_point(data, c)
        pb, db = _brute(data, c)
        assert abs((phi - pb + np.pi) % (2 * np.pi) - np.pi) < 3 * h
        assert d <= db + 1e-12
        # stationarity: f = (delta - c) . delta' = 0, relative to |delta'| d
        dd = 1e-7
        d_plus = closest_point(data, c, phi0=phi + dd)[1]
        assert d_plus == pytest.approx(d, abs=1e-13)


def test_taylor_estimate_is_one_newton_step_and_the_seeds_formula() -> None:
    """Seed eqs. 4.33-4.37: our Taylor estimate is the vertex of the 2nd-order expansion,
    equal in magnitude to the printed eq. 4.36 (whose sign is flipped, eq. 4.35); its error
    is real when the ball is R away and vanishes as the point approaches the contour."""
    data = contour_data(NOMINAL)
    a, b = NOMINAL.frame.contour.a, NOMINAL.frame.contour.b
    R = NOMINAL.ball.rolling_radius
    errs = []
    m = RigidModel(NOMINAL)
    for phi_true in (0.3, 0.9, 1.4, 2.2):
        for off in (R, 1e-4):
            # a point at distance off along the outward normal of the contour at phi_true
            n = m.curve.normal(phi_true)
            c = m.curve.contour_point(phi_true) + off * n
            phi_b = math.atan2(c[0], c[1])
            step = taylor_closest_point(data, c) - phi_b
            rb = float(np.hypot(*c))
            assert step == pytest.approx(-seed_eq_4_36(a, -b, rb, phi_b), rel=1e-9, abs=1e-15)
            err = abs(taylor_closest_point(data, c) - closest_point(data, c, phi0=phi_true)[0])
            errs.append((off, err))
    far = max(e for o, e in errs if o == R)
    near = max(e for o, e in errs if o == 1e-4)
    assert far > 1e-4  # the seed's noted error at the ball's distance
    assert near < far / 100


def test_restitution_laws() -> None:
    """d is solved for the restitution; p = 1/4 keeps it at every speed, Hunt-Crossley not."""
    k = NOMINAL.contact_stiffness
    m = NOMINAL.ball.mass
    for p, e in ((0.25, 0.85), (1.5, 0.85), (0.25, 0.5)):
        d = damping_for_restitution(k, 1.5, p, m, e, 0.1)
        assert restitution(d, k, 1.5, p, m, 0.1) == pytest.approx(e, abs=1e-4)
    d = damping_for_restitution(k, 1.5, 0.25, m, 0.85, 0.1)
    for v in (0.003, 0.03, 0.5):
        assert restitution(d, k, 1.5, 0.25, m, v) == pytest.approx(0.85, abs=2e-3)
    d = damping_for_restitution(k, 1.5, 1.5, m, 0.85, 0.1)
    assert restitution(d, k, 1.5, 1.5, m, 0.003) > 0.99  # HC: slow impacts barely damped


def test_drop_on_the_waist_rebounds_with_the_restitution() -> None:
    """A ball dropped onto the level waist (frame held) leaves it at e times the impact speed."""
    p = NOMINAL.replace(**{"frame.inertia": 1e3})
    cm = ContactModel(p)
    x = cm.state_from_rigid(np.array([0.0, 0.0, 0.0, 0.0]), preload=False)
    h = 0.5e-3
    x[1] += h  # lift the ball by h: impact speed sqrt(2 g h)
    cm.reset(x, phi_guess=0.0)
    v_in = math.sqrt(2 * 9.81 * h)
    vy_max = 0.0
    for _ in range(60):  # 12 ms: fall (10 ms) and the first rebound
        x = cm.step(x, 0.0, 2e-4)
        vy_max = max(vy_max, x[5])
    assert vy_max == pytest.approx(p.contact.restitution * v_in, rel=0.02)


def test_energy_balance_and_damping_never_adds_energy() -> None:
    """Over sharp asperities (bounces, several contacts): E + E_el - E(0) = W_in - W_diss to
    a small fraction of the dissipation, and the damping's dissipation grows at every step."""
    cm = ContactModel(ROUGH, time_step=1e-5)
    x = cm.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    e0 = sum(cm.energy(x))
    w_hc = [x[IWHC]]
    bal = []
    for i in range(400):  # 0.4 s, bounces on the asperities from about 0.16 s
        u = 2e-3 * math.sin(5.0 * i * 1e-3)
        x = cm.step(x, u, 1e-3)
        w_hc.append(x[IWHC])
        bal.append(sum(cm.energy(x)) - e0 - (x[IWIN] - x[IWD]))
    w_hc = np.array(w_hc)
    assert np.all(np.diff(w_hc) >= 0.0)
    assert w_hc[-1] > 1e-7  # impacts happened
    assert np.max(np.abs(bal)) < 0.01 * x[IWD]
    assert x[IWD] >= w_hc[-1]


def test_contact_model_tracks_the_rigid_model() -> None:
    """Stiff contact, no bump: same start, same torque, 1.5 s: the closest-point state of the
    contact model follows the rigid model, closer with a stiffer contact."""
    xr = np.array([0.0, 0.3, 0.0, 0.0])
    rr = simulate(RigidModel(NOMINAL), xr, 1.5, 0.0, dt=1e-3)
    diffs = []
    for kmul in (1.0, 10.0):
        p = NOMINAL.replace(**{"contact.stiffness": NOMINAL.contact_stiffness * kmul})
        cm = ContactModel(p)
        res = cm.simulate(cm.state_from_rigid(xr), 1.5, 0.0, dt=1e-3)
        d = np.abs(res.rigid - rr.x[:, :4]).max(axis=0)
        diffs.append(d[1])
        assert d[1] < 2e-5 and d[3] < 2e-4  # phi [rad], phi_dot [rad/s]
        assert np.max(np.abs(res.normal_force - rr.normal_force)) < 1e-6
        assert np.max(np.abs(res.balance_error)) < 1e-12
        assert np.max(np.abs(res.slip_velocity)) < 1e-5  # it rolls
    assert diffs[1] < diffs[0]


def test_elliptic_ball_contact_conserves_energy_and_follows_the_rigid_one() -> None:
    p = NOMINAL.replace(**{"ball.ellipticity": 5e-4, "ball.ellipse_phase": 0.4})
    xr = np.array([0.0, 0.3, 0.0, 0.0])
    cm = ContactModel(p)
    res = cm.simulate(cm.state_from_rigid(xr), 0.6, 0.0, dt=1e-3)
    rr = simulate(RigidModel(p), xr, 0.6, 0.0, dt=1e-3)
    r0 = simulate(RigidModel(NOMINAL), xr, 0.6, 0.0, dt=1e-3)
    assert np.max(np.abs(res.balance_error)) < 1e-12
    # first-order model: the contact model is much closer to the rigid elliptic ball than the
    # rigid round ball is
    assert (np.max(np.abs(res.rigid[:, 1] - rr.x[:, 1]))
            < 0.2 * np.max(np.abs(r0.x[:, 1] - rr.x[:, 1])))


def test_wobble_is_refused() -> None:
    with pytest.raises(ValueError, match="planar"):
        ContactModel(NOMINAL.replace(**{"frame.wobble": 0.01}))
