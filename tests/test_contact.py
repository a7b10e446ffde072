"""Contact model: exact closest point, energy balance, restitution, agreement with rigid."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from bfr_model.closest_point import (
    closest_point,
    contour_data,
    local_minima,
    seed_eq_4_36,
    taylor_closest_point,
)
from bfr_model.contact import (
    IVX,
    IVY,
    IWD,
    IWHC,
    IWIN,
    IWPX,
    IWPY,
    IX,
    IXI,
    IXI2,
    IY,
    IZ,
    NX,
    ContactModel,
    damping_for_restitution,
    restitution,
)
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import contour_kernel
from bfr_model.params import ParameterError, load_params
from bfr_model.perturbations import bump_row, with_asperities
from bfr_model.simulate import simulate

NOMINAL = load_params()
ROUGH = NOMINAL.replace(**{"track.asperity_phi": [0.1, -0.12, 0.105],
                           "track.asperity_height": [5e-4, 3e-4, 2e-4],
                           "track.asperity_width": [0.003, 0.004, 0.002]})


def _distances(data, c: np.ndarray, phi: np.ndarray) -> np.ndarray:  # noqa: ANN001
    r = contour_kernel(phi, data.rho0, data.orders, data.ccos, data.csin,
                       np.concatenate([data.bphi, data.aphi]),
                       np.concatenate([data.bh, data.ah]),
                       np.concatenate([data.bw, data.aw]))[0]
    return np.hypot(r * np.sin(phi) - c[0], r * np.cos(phi) - c[1])


def _brute(data, c: np.ndarray, n: int = 400_000) -> tuple[float, float]:  # noqa: ANN001
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    d = _distances(data, c, phi)
    i = int(np.argmin(d))
    return float(phi[i]), float(d[i])


def _row(params, phi0: float, count: int = 30, length: float = 0.03, height: float = 5e-4,  # noqa: ANN001, ANN202
         width: float = 1e-4, edge: int = 0, shift: float = 0.0):
    """The study's dense row of sharp bumps from phi0 (one edge or both), shifted along it."""
    ph, h, w = bump_row(params, phi0, count, length, height, width)
    return ph + shift * (ph[1] - ph[0]), h, w, edge


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


def test_local_minima_finds_every_minimum_within_reach() -> None:
    """The event-based search (sampled sign changes of f, bracketed Newton) finds the same
    local minima of the distance as a dense brute-force scan, over a row of sharp bumps."""
    ph, h, w, _ = _row(NOMINAL, 0.25)
    data = contour_data(with_asperities(NOMINAL, ph, h, w))
    R = NOMINAL.ball.rolling_radius
    rng = np.random.default_rng(5)
    out_phi, out_d = np.zeros(64), np.zeros(64)
    checked = 0
    for a in rng.uniform(0.27, 0.5, 12):
        nrm = RigidModel(NOMINAL).curve.normal(a)
        c = RigidModel(NOMINAL).curve.contour_point(a) + (R + 5e-4 + rng.uniform(0, 1.5e-4)) * nrm
        reach = R + 2e-4
        n, _ = local_minima(c[0], c[1], a, reach, 5e-4, 0.25 * float(np.min(w)), 1e-3,
                            *data.as_args(), out_phi, out_d)
        phi = np.linspace(a - 0.06, a + 0.06, 120_001)
        d = _distances(data, c, phi)
        inner = (d[1:-1] < d[:-2]) & (d[1:-1] <= d[2:]) & (d[1:-1] < reach)
        brute = phi[1:-1][inner]
        if not brute.size:
            assert n == 1 and out_d[0] >= reach  # nothing within reach: the nearest minimum
            continue
        checked += 1
        assert n == brute.size
        assert np.all(np.diff(out_d[:n]) >= 0.0)  # nearest first
        got = np.sort(out_phi[:n])
        assert np.max(np.abs(got - brute)) < 2 * (phi[1] - phi[0])
    assert checked >= 6


def _row_run(model: ContactModel, start: float = 0.45, duration: float = 0.4
             ) -> tuple[np.ndarray, list]:
    """The ball rolling down onto a row (u = 0, from rest): states and contact sets."""
    x = model.state_from_rigid(np.array([0.0, start, 0.0, 0.0]))
    xs, snaps = [x], [model.snapshot()]
    for _ in range(round(duration / 1e-3)):
        x = model.step(x, 0.0, 1e-3)
        xs.append(x)
        snaps.append(model.snapshot())
    return np.array(xs), snaps


ROW = with_asperities(NOMINAL, *_row(NOMINAL, 0.05, length=0.02)[:3])


def test_event_based_stepping_matches_the_exhaustive_reference() -> None:
    """Over a row of sharp bumps (the ball reaches it at 0.2 s and bounces over it): from the
    same states and contact sets, one millisecond of the event-based stepping (search after
    M/2 of travel, lazy candidates, free-flight steps) lands where searching and evaluating
    every candidate at every step lands, to round-off, with fewer steps."""
    ev = ContactModel(ROW)
    xs, snaps = _row_run(ev)
    assert ev.sst[2] < 0.95 * 0.4 / ev.time_step  # long steps were taken in flight
    ex = ContactModel(ROW, exhaustive=True)
    worst, bounces = 0.0, 0
    for k in range(190, len(xs) - 1, 2):
        ex.restore(snaps[k])
        ev.restore(snaps[k])
        a = ev.step(xs[k], 0.0, 1e-3)
        b = ex.step(xs[k], 0.0, 1e-3)
        worst = max(worst, float(np.max(np.abs(a[[IVX, IVY]] - b[[IVX, IVY]]))))
        bounces += ev.diagnostics(a)["penetration"] < 0.0
    assert bounces > 20  # the ball left the track over the row
    assert worst < 1e-9


def test_two_edges_reduce_exactly_to_one() -> None:
    """Seed recommendation 3: with the same bumps on both plate edges the two-edge contact is
    today's model, bit for bit (each edge carries exactly half of every force and energy),
    and the ball never moves sideways."""
    a = ContactModel(ROUGH, time_step=1e-5)
    b = ContactModel(ROUGH, time_step=1e-5, edges=2)
    xa = a.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    xb = b.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    for i in range(300):  # 0.3 s over the asperities (bounces from about 0.16 s)
        u = 2e-3 * math.sin(5.0 * i * 1e-3)
        xa = a.step(xa, u, 1e-3)
        xb = b.step(xb, u, 1e-3)
    assert a.edges == 1 and b.edges == 2
    assert np.array_equal(xa[:IZ], xb[:IZ])
    assert xb[IZ] == 0.0 and xb[IXI2] == xb[IXI] and xb[IWPX] == xb[IWPY] == 0.0
    assert a.diagnostics(xa)["normal_force"] == b.diagnostics(xb)["normal_force"]


def test_ball_on_a_one_edge_bump_rests_where_the_geometry_puts_it() -> None:
    """A bump of height h under the front plate only (frame held): the ball settles with its
    centre on the bisector of the two edges, R_b from each (exact 3-D geometry): about h/2
    higher and R h / d_f towards the back plate, to the contact's compliance; the two edge
    forces carry the weight."""
    h = 5e-4
    p = NOMINAL.replace(**{"frame.inertia": 1e3, "track.asperity_phi": [0.0],
                           "track.asperity_height": [h], "track.asperity_width": [0.3],
                           "track.asperity_edge": [1]})
    m = ContactModel(p)
    assert m.edges == 2
    x = m.state_from_rigid(np.array([0.0, 0.0, 0.0, 0.0]), preload=False)
    x[IY] += h
    m.reset(x, phi_guess=0.0)
    for _ in range(200):
        x = m.step(x, 0.0, 1e-3)
    rb, ze = p.ball.radius, 0.5 * p.ball.plate_distance
    rho = p.frame.contour.a - p.frame.contour.b
    half = math.hypot(ze, h / 2)
    along = math.sqrt(rb**2 - half**2) / math.hypot(2 * ze, h)
    assert x[IY] == pytest.approx(rho + h / 2 + along * 2 * ze, abs=1e-6)  # deflection 0.2 um
    assert x[IZ] == pytest.approx(-along * h, abs=1e-7)
    assert abs(x[IX]) < 1e-12
    d = m.diagnostics(x)
    assert sum(d["edge_normal_force"]) == pytest.approx(p.ball.mass * 9.81, rel=1e-6)
    assert min(d["edge_normal_force"]) > 0.3 * p.ball.mass * 9.81  # both edges carry it


def test_two_edge_energy_balance_over_one_sided_bumps() -> None:
    """Bumps on each edge at other places (the ball tips from side to side, bounces, slips):
    E + E_el - E(0) = W_in - W_diss to a small fraction of the dissipation, the damping's
    dissipation never decreases, the lateral motion is real."""
    ph, h, w, _ = _row(NOMINAL, 0.05, count=8, length=0.02)
    p = with_asperities(NOMINAL, ph, h, w, edge=1)
    p = with_asperities(p, ph + 0.5 * (ph[1] - ph[0]), 0.6 * h, w, edge=2)
    cm = ContactModel(p)
    assert cm.edges == 2
    x = cm.state_from_rigid(np.array([0.0, 0.45, 0.0, 0.0]))
    e0 = sum(cm.energy(x))
    w_hc, bal, zs = [x[IWHC]], [], []
    for _ in range(400):  # on the bumps from 0.2 s
        x = cm.step(x, 0.0, 1e-3)
        w_hc.append(x[IWHC])
        zs.append(x[IZ])
        bal.append(sum(cm.energy(x)) - e0 - (x[IWIN] - x[IWD]))
    assert np.all(np.diff(w_hc) >= 0.0) and w_hc[-1] > 1e-8
    assert np.max(np.abs(bal)) < 0.01 * x[IWD]
    assert np.ptp(zs) > 1e-5  # the ball moved sideways over the one-sided bumps


def test_contact_converges_with_the_time_step() -> None:
    """Convergence in the step. Rolling on the smooth track (50 ms): RK4's fourth order until
    round-off, reached at the shipped 2e-5 s. A drop onto the level waist (impact, rebound;
    frame held, 6 ms): each halving of the step cuts the error at least 2.5 times (about
    second order: Hertz's w^(3/2) and the damping's w^(1/4) are not smooth at w = 0)."""
    def rolled(dt: float) -> np.ndarray:
        m = ContactModel(NOMINAL, time_step=dt)
        return m.step(m.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0])), 0.0, 1e-3, 50)

    def dropped(dt: float) -> np.ndarray:
        m = ContactModel(NOMINAL.replace(**{"frame.inertia": 1e3}), time_step=dt)
        x = m.state_from_rigid(np.array([0.0, 0.0, 0.0, 0.0]), preload=False)
        x[IY] += 2e-5
        m.reset(x, phi_guess=0.0)
        return m.step(x, 0.0, 1e-3, 6)

    sel = [IX, IY, IVX, IVY]
    ref = rolled(1.25e-6)
    e_roll = [float(np.max(np.abs(rolled(dt)[sel] - ref[sel]))) for dt in (8e-5, 4e-5, 2e-5)]
    assert e_roll[1] < e_roll[0] / 16 and e_roll[2] < 1e-12, e_roll
    ref = dropped(1.25e-6)
    e_drop = [float(np.max(np.abs(dropped(dt)[[IY, IVY]] - ref[[IY, IVY]])))
              for dt in (8e-5, 4e-5, 2e-5, 1e-5, 5e-6)]
    for a, b in itertools.pairwise(e_drop):
        assert b < a / 2.5, e_drop


def test_asperity_edges_are_checked_and_need_two_edges() -> None:
    with pytest.raises(ParameterError, match="asperity_edge"):
        NOMINAL.replace(**{"track.asperity_phi": [0.1], "track.asperity_height": [1e-4],
                           "track.asperity_width": [1e-3], "track.asperity_edge": [3]})
    with pytest.raises(ParameterError, match="one entry per asperity"):
        NOMINAL.replace(**{"track.asperity_phi": [0.1, 0.2], "track.asperity_height": [1e-4] * 2,
                           "track.asperity_width": [1e-3] * 2, "track.asperity_edge": [1]})
    p = with_asperities(NOMINAL, np.array([0.1]), np.array([1e-4]), np.array([1e-3]), edge=2)
    assert p.track.asperity_edge == (2,)
    with pytest.raises(ValueError, match="two-edge"):
        ContactModel(p, edges=1)
    assert ContactModel(p).edges == 2 and NX == 18
