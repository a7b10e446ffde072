"""Tests of the ball's grip (:mod:`bfr_diagnose.grip`): the friction demand and the slip test.

Physics first: the ball alone under the frame's motion, rolling, follows the rigid model's
own trajectory (and converges at first order as the step shrinks); a friction coefficient no
demand reaches leaves it rolling to the last bit; with no friction at all the ball slides as
the rigid model with a spinless ball; the friction demand equals the one derived apart from
the model's spin rate and normal force. Then the verdicts on truth the slip model did not
make: a closed loop on the rigid model (no slip) and on the force-based contact model
(compliant contact, friction-limited rolling, :mod:`bfr_model.contact`) whose friction is
below what its orbit demands.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from bfr_diagnose.cli import main as diagnose_main
from bfr_diagnose.locate import _rigid_rollout, prediction_errors
from bfr_diagnose.preprocess import Prepared, SensorCorrection, prepare
from bfr_diagnose.residual import ResidualEvaluator
from bfr_diagnose.synth import SynthConfig, contact_recording, stabilised_recording
from bfr_model.contact import ContactModel
from bfr_model.dynamics import RigidModel, energy_terms
from bfr_model.params import RigParams

from bfr_diagnose import grip

DT = 0.002  # [s] grid step (the diagnosis's)
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ntnu-rig"


def _torque(t: float) -> float:
    """A torque that shakes the frame both ways [N m]."""
    return 0.006 * np.sin(2 * np.pi * 1.3 * t) + 0.003 * np.sin(2 * np.pi * 3.1 * t + 0.4)


def _rigid_run(params: RigParams, duration: float = 0.6, sub: int = 20
               ) -> tuple[Prepared, np.ndarray]:
    """The rigid model under :func:`_torque` from the ball in the top waist (contact kept:
    the normal force stays above 28 mN).

    RK4 at ``DT / sub`` with the torque of each sub-step's middle; the grid carries the exact
    theta, theta_dot and theta_ddot (the model's own acceleration). Returns a Prepared of the
    frame motion (the ball's measurements are not used) and the true states ``[theta, phi,
    theta_dot, phi_dot]`` on the grid.
    """
    m = RigidModel(params)
    n = round(duration / DT)
    x = np.array([0.0, 0.05, 0.0, 0.3, 0.0, 0.0])
    xs = np.empty((n + 1, 4))
    acc = np.empty(n + 1)
    for k in range(n + 1):
        xs[k] = x[:4]
        acc[k] = m.accelerations(x[:4], _torque(k * DT))[0]
        for s in range(sub):  # the torque at each sub-step's middle: smooth in time
            x = m.step(x, _torque((k + (s + 0.5) / sub) * DT), DT / sub, 1, 0.0)
    return _frame_motion(xs, acc), xs


def _frame_motion(xs: np.ndarray, acc: np.ndarray) -> Prepared:
    """A Prepared of the frame motion of states xs on the grid (theta_ddot = acc, the torque
    :func:`_torque`); the ball's measurements are not used."""
    t = DT * np.arange(xs.shape[0])
    nan = np.full(t.size, np.nan)
    return Prepared(t=t, theta=xs[:, 0], theta_dot=xs[:, 2], theta_ddot=acc,
                    u=np.array([_torque(v) for v in t]), psi_w=nan, psi_w_dot=nan.copy(),
                    ball_ok=np.ones(t.size, bool), frame_ok=np.ones(t.size, bool),
                    has_ball=True, latency0=0.0, noise={"camera": 1e-4, "theta": 0.0})


def test_rolling_ball_alone_follows_the_rigid_model_and_converges() -> None:
    """Under the frame's exact motion the ball's row alone reproduces the coupled model's
    contact angle (the frame's torque is whatever gives the measured theta_ddot): over 0.5 s
    the error at a 2 ms step is below 3e-5 rad (measured 1.1e-5), less than half that at
    1 ms (4.4e-6), and at 0.5 ms near the floor of the frame's motion interpolated linearly
    across a grid step (3.4e-6): the step is not what limits the slip test."""
    params = RigParams()
    prep, xs = _rigid_run(params)
    ball = grip._Ball.of(params, prep, SensorCorrection())
    n = 250
    errs = []
    for step in (grip.MAX_STEP, grip.MAX_STEP / 2, grip.MAX_STEP / 4):
        ns = round(DT / step)
        phi = grip._rollout(xs[0, 1], xs[0, 3], 0, n, ball.th, ball.thd, ball.thdd, -1.0, DT, ns,
                         ball.pf, ball.pt, *ball.model.geom_args, ball.jb, ball.rb, ball.rr)
        errs.append(float(np.max(np.abs(phi - xs[:n + 1, 1]))))
    assert errs[0] < 3e-5 and errs[1] < 0.5 * errs[0] and errs[2] < errs[1] < 6e-6, errs


def test_a_friction_no_demand_reaches_keeps_it_rolling_to_the_last_bit() -> None:
    """mu far above the demand: the ball never slips, the rollout is rolling's, bit for bit."""
    params = RigParams()
    prep, xs = _rigid_run(params)
    ball = grip._Ball.of(params, prep, SensorCorrection())
    rolling = ball.roll(xs[0, [1, 3]], 0, 250, None)
    assert np.array_equal(ball.roll(xs[0, [1, 3]], 0, 250, grip.SlipLaw(kind="coulomb",
                                                                        value=50.0)), rolling)


def test_without_friction_the_ball_slides_like_a_spinless_ball() -> None:
    """mu = 0: no torque ever reaches the spin, so the ball's centre moves as the rigid model's
    with J_b = 0 rolling (the spin's share of the row is all friction's); the same start and
    frame, and the seed's ball slides measurably apart from its rolling self."""
    params = RigParams()
    prep, xs = _rigid_run(params)
    ball = grip._Ball.of(params, prep, SensorCorrection())
    spinless = grip._Ball.of(params.replace(**{"ball.inertia": 1e-15}), prep, SensorCorrection())
    slide = ball.roll(xs[0, [1, 3]], 0, 250, grip.SlipLaw(kind="coulomb", value=0.0))
    point = spinless.roll(xs[0, [1, 3]], 0, 250, None)
    assert np.max(np.abs(slide - point)) < 1e-9
    assert np.max(np.abs(slide - ball.roll(xs[0, [1, 3]], 0, 250, None))) > 1e-2


def test_friction_demand_matches_the_spin_rate_and_normal_force() -> None:
    """The demand ``|J_b omega_b'| / (F_n R_b)`` against an independent derivation along
    the rigid run: omega_b from :meth:`RigidModel.ball_spin_rate` differentiated by central
    differences of the RK4 trajectory, F_n from :meth:`RigidModel.normal_force` (measured
    agreement 1e-5 relative where the demand exceeds a thousandth)."""
    params = RigParams()
    prep, xs = _rigid_run(params)
    m = RigidModel(params)
    ball = grip._Ball.of(params, prep, SensorCorrection())
    idx = np.arange(1, prep.n - 1)
    mu_req, fn = grip._demand_kernel(idx, ball.th, ball.thd, ball.thdd,
                                  np.ascontiguousarray(xs[:, 1]),
                                  np.ascontiguousarray(xs[:, 3]), ball.pf,
                                  *m.geom_args, ball.jb, ball.rr, ball.rb)
    w = m.ball_spin_rate(xs)
    wdot = (w[2:] - w[:-2]) / (2 * DT)
    fn_ref = np.array([m.normal_force(xs[k], prep.u[k]) for k in idx])
    ref = np.abs(params.ball.inertia * wdot) / (fn_ref * params.ball.radius)
    assert np.allclose(fn, fn_ref, rtol=1e-9)
    big = ref > 1e-3
    assert big.sum() > 100
    assert np.allclose(mu_req[big], ref[big], rtol=2e-3), np.max(np.abs(mu_req / ref - 1)[big])


# -- the coupled model with slip (the prediction's) ---------------------------------------------

def _shaking(n: int, amp: float = 0.02, dt: float = 1e-3) -> np.ndarray:
    """A torque record that shakes the frame at 4 Hz [N m]."""
    return amp * np.sin(2 * np.pi * 4 * dt * np.arange(n))


def test_coupled_rollout_without_slip_is_the_rigid_rollout_to_the_last_bit() -> None:
    """mu < 0 (rolling) and a mu no demand reaches give the rigid model's RK4 rollout
    (:func:`bfr_diagnose.locate._rigid_rollout`) bit for bit."""
    m = RigidModel(RigParams())
    x0 = np.array([0.1, 0.3, 1.0, 2.5])
    u = _shaking(200, dt=DT)
    ref = _rigid_rollout(np.r_[x0, 0.0, 0.0], u, DT, *m.kernel_args)
    assert np.array_equal(grip.coupled_rollout(m, x0, u, DT, -1.0), ref)
    assert np.array_equal(grip.coupled_rollout(m, x0, u, DT, 50.0), ref)


def test_a_frictionless_ball_slides_and_the_rest_keeps_its_energy() -> None:
    """mu = 0: no torque reaches the spin, so frame and ball move as the rigid model without
    the spin's inertia (J_b = 0), whose energy ``T + V`` is conserved without a torque. The
    midpoint rule's drift over 0.5 s is second order in the step (measured 1.6e-5, 4.2e-6,
    1.1e-6 of the kinetic energy at 1, 0.5, 0.25 ms); the rolling ball (J_b in M) follows
    another path."""
    m = RigidModel(RigParams())
    pf, pt, jb, rb, rr = grip.slip_parameters(m)
    x0 = np.array([0.0, 0.3, 2.0, 3.0, 0.0, 0.0])
    drift = []
    for ns in (1, 2, 4):
        xs = grip._coupled_rollout(x0, np.zeros(500), 1e-3, ns, 0.0, pf, pt, *m.geom_args, jb,
                                   rb, rr)
        kin, pot = energy_terms(xs[:, 0], xs[:, 1], xs[:, 2], xs[:, 3], pt, *m.geom_args)
        drift.append(np.max(np.abs(kin + pot - kin[0] - pot[0])) / np.max(kin))
    assert drift[0] < 3e-5 and drift[0] / drift[1] > 3.5 and drift[1] / drift[2] > 3.5, drift
    rolling = grip.coupled_rollout(m, x0[:4], np.zeros(500), 1e-3, -1.0)
    assert np.max(np.abs(rolling[:, 1] - xs[:, 1])) > 0.05


# -- linear creep -------------------------------------------------------------------------------

def _creep(m: RigidModel, x5: np.ndarray, u: np.ndarray, dt: float, tau_s: float, ns: int = 1
           ) -> np.ndarray:
    """The coupled creep kernel's states from ``[theta, phi, theta_dot, phi_dot, omega_b]``."""
    _, pt, jb, _, _ = grip.slip_parameters(m)
    return grip._creep_coupled_rollout(np.asarray(x5, float), u, dt, ns, 1.0 / tau_s, jb, pt,
                                       *m.geom_args)


def test_creep_lies_between_rolling_and_a_spinless_ball() -> None:
    """tau_s -> 0 is rolling: the coupled creep rollout approaches the rigid model's at first
    order in tau_s (it lags by a spin relaxation of ~tau_s / 2.6); tau_s -> inf is Coulomb's
    mu = 0, a spinless ball (no torque reaches the spin): the rigid model with J_b = 0,
    rolling, within 1e-6 (measured 7e-8 rad/s, 3e-9 rad: two RK4 codes on the same grid,
    the spin's residual 1e-9 / tau_s coupling). The relative spin at the start is a
    state that changes the path."""
    m = RigidModel(RigParams())
    x0 = np.array([0.1, 0.3, 1.0, 2.5])
    dt, n = 2e-4, 1500
    u = np.repeat(_shaking(n // 5 + 1, dt=5 * dt), 5)[:n]
    ref = grip.coupled_rollout(m, x0, u, dt, -1.0)
    errs = [float(np.max(np.abs(grip.creep_rollout(m, x0, u, dt, tau)[:, 1] - ref[:, 1])))
            for tau in (4e-3, 2e-3, 1e-3)]
    # measured 0.0172, 0.0086, 0.0043 rad
    assert errs[0] < 0.03 and 1.6 < errs[0] / errs[1] < 2.4 and 1.6 < errs[1] / errs[2] < 2.4, \
        errs
    free = grip.creep_rollout(m, x0, u, dt, 1e9)
    spinless = RigidModel(RigParams().replace(**{"ball.inertia": 1e-15}))
    point = grip.coupled_rollout(spinless, x0, u, dt, -1.0)
    assert np.max(np.abs(free - point)) < 1e-6, np.max(np.abs(free - point))
    assert np.max(np.abs(free[:, 1] - ref[:, 1])) > 0.05
    ahead = grip.creep_rollout(m, np.r_[x0, -30.0], u, dt, 0.05)
    plain = grip.creep_rollout(m, np.r_[x0, 0.0], u, dt, 0.05)
    assert np.array_equal(plain, grip.creep_rollout(m, x0, u, dt, 0.05))
    assert abs(ahead[250, 1] - plain[250, 1]) > 1e-3


def test_creep_dissipates_exactly_what_the_energy_loses() -> None:
    """Without a torque or joint friction the energy ``T + V`` of the model without the spin
    plus the spin's ``J_b omega_b^2 / 2`` falls by the friction's work ``int (J_b / tau_s)
    (omega_b - omega_roll)^2 dt`` (trapezoid on the fine grid): the balance closes to 1e-4 of
    the work (RK4 at 0.1 ms) and the work is a real share of the energy."""
    params = RigParams()
    m = RigidModel(params)
    _, pt, jb, _, rr = grip.slip_parameters(m)
    lam0 = float(m.curve.speed(np.array([0.3]))[0])
    x5 = np.array([0.0, 0.3, 2.0, 3.0, 2.0 - lam0 * 3.0 / rr + 40.0])
    dt, tau = 1e-4, 0.03
    xs = _creep(m, x5, np.zeros(5000), dt, tau)
    kin, pot = energy_terms(xs[:, 0], xs[:, 1], xs[:, 2], xs[:, 3], pt, *m.geom_args)
    energy = kin + pot + 0.5 * jb * xs[:, 4] ** 2
    rel = xs[:, 4] - (xs[:, 2] - m.curve.speed(xs[:, 1]) * xs[:, 3] / rr)
    power = jb / tau * rel ** 2
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * dt)])
    assert work[-1] > 0.01 * kin[0], (work[-1], kin[0])
    assert np.max(np.abs(energy[0] - energy - work)) < 1e-4 * work[-1], \
        (np.max(np.abs(energy[0] - energy - work)), work[-1])
    assert np.all(np.diff(energy) <= 1e-12)


def test_the_ball_alone_creeps_as_the_coupled_model_under_its_frame_motion() -> None:
    """The slip test's ball alone under creep (the midpoint rule on the 2 ms grid) reproduces
    the coupled creep model's contact angle when given that model's own frame motion
    (theta, theta_dot, theta_ddot on the grid from a 0.1 ms run) and its start spin: 0.5 s
    within 3e-5 rad at the 2 ms grid and at half of it (measured 1.5e-5 both: the floor of
    the frame's motion interpolated linearly across a grid step, as for rolling)."""
    m = RigidModel(RigParams())
    _, pt, jb, _, rr = grip.slip_parameters(m)
    tau, sub, n = 0.05, 20, 250
    lam0 = float(m.curve.speed(np.array([0.05]))[0])
    x5 = np.array([0.0, 0.05, 0.0, 0.3, -lam0 * 0.3 / rr + 5.0])
    u_fine = np.array([_torque(k * DT / sub) for k in range(n * sub)])
    fine = _creep(m, x5, u_fine, DT / sub, tau)[::sub]
    acc = np.array([grip._creep_rhs(x, _torque(k * DT), 1.0 / tau, jb, pt, *m.geom_args)[2]
                    for k, x in enumerate(fine)])
    ball = grip._Ball.of(RigParams(), _frame_motion(fine, acc), SensorCorrection())
    law = grip.SlipLaw(kind="creep", value=tau)
    rel0 = x5[4] - (x5[2] - lam0 * x5[3] / rr)
    errs = []
    for ns in (1, 2):
        phi = grip._creep_ball_rollout(x5[1], x5[3], rel0, 0, n, ball.th, ball.thd, ball.thdd,
                                       1.0 / tau, DT, ns, ball.pf, ball.pt,
                                       *ball.model.geom_args, ball.jb, ball.rr)
        errs.append(float(np.max(np.abs(phi - fine[:, 1]))))
    assert max(errs) < 3e-5, errs
    assert np.array_equal(ball.roll(np.array([x5[1], x5[3], rel0]), 0, n, law),
                          grip._creep_ball_rollout(x5[1], x5[3], rel0, 0, n, ball.th, ball.thd,
                                                   ball.thdd, 1.0 / tau, DT, 1, ball.pf,
                                                   ball.pt, *ball.model.geom_args, ball.jb,
                                                   ball.rr))


@pytest.mark.parametrize(("amp", "mu"), [(0.04, 0.1), (0.02, 0.05)])
def test_coupled_slip_follows_the_contact_model(amp: float, mu: float) -> None:
    """Truth of another structure: the force-based contact model (free ball, compliant
    Hunt-Crossley contact, a stick spring and Coulomb friction at the edges,
    :mod:`bfr_model.contact`) with mu on the plate edges, shaken for 0.4 s from rest with
    the ball in the top waist, slips at up to 0.2 m/s. The rigid model with friction-limited
    rolling follows its contact angle to 1e-3 rad (measured 1.5e-4 and 8.5e-4) where rolling
    without slip is 0.15-0.18 rad off."""
    params = RigParams().replace(**{"contact.static_friction": mu,
                                    "contact.dynamic_friction": mu})
    cm = ContactModel(params)
    xr = np.array([0.0, 0.3, 0.0, 0.0])
    res = cm.simulate(cm.state_from_rigid(xr), 0.4, lambda t: amp * np.sin(2 * np.pi * 4 * t),
                      dt=1e-3)
    assert np.max(np.abs(res.slip_velocity)) > 0.1 and res.normal_force.min() > 0.0
    m = RigidModel(params)
    slide = grip.coupled_rollout(m, xr, res.u[:-1], 1e-3, mu)
    roll = grip.coupled_rollout(m, xr, res.u[:-1], 1e-3, -1.0)
    e_slide = np.max(np.abs(slide[:, 1] - res.rigid[:, 1]))
    e_roll = np.max(np.abs(roll[:, 1] - res.rigid[:, 1]))
    assert e_slide < 1e-3 and e_roll > 0.1, (e_slide, e_roll)


# -- verdicts on closed loops ------------------------------------------------------------------

def test_the_creeping_spin_is_the_lag_of_the_measured_rolling_rate() -> None:
    """Under creep the spin is a first-order lag of the rolling rate, whatever moves the
    frame and ball (``omega_b' = -(omega_b - omega_roll) / tau_s``): :meth:`SlipLaw.spin`
    from the coupled creep model's own frame rate, contact angle and rate on a 4, 2 and 1 ms
    grid gives that model's relative spin (its fifth state) once the start is forgotten
    (after 12 tau_s: the model starts 5 rad/s off rolling, the lag from rolling), to second
    order in the grid step (measured 5.3e-3, 1.3e-3, 3.3e-4 rad/s against a spin of up to
    17 rad/s). Coulomb friction has no such spin: None."""
    m = RigidModel(RigParams())
    _, _, _, _, rr = grip.slip_parameters(m)
    tau, dt_fine, n = 0.05, 1e-4, 10000
    lam0 = float(m.curve.speed(np.array([0.05]))[0])
    x5 = np.array([0.0, 0.05, 0.0, 0.3, -lam0 * 0.3 / rr + 5.0])
    u = np.array([_torque((k + 0.5) * dt_fine) for k in range(n)])
    xs = _creep(m, x5, u, dt_fine, tau)
    rel = xs[:, 4] - (xs[:, 2] - m.curve.speed(xs[:, 1]) * xs[:, 3] / rr)
    law = grip.SlipLaw(kind="creep", value=tau)
    errs = []
    for dt in (4e-3, 2e-3, 1e-3):
        g = xs[::round(dt / dt_fine)]
        r = law.spin(m, g[:, 2], g[:, 1], g[:, 3], np.ones(len(g), bool), dt)
        late = np.arange(len(g)) * dt > 12 * tau
        errs.append(float(np.max(np.abs(r - rel[::round(dt / dt_fine)])[late])))
    assert errs[1] < 2e-3 < 10.0 < np.max(np.abs(rel)), errs
    assert 3.0 < errs[0] / errs[1] < 5.0 and 3.0 < errs[1] / errs[2] < 5.0, errs
    assert grip.SlipLaw(kind="coulomb", value=0.2).spin(
        m, g[:, 2], g[:, 1], g[:, 3], np.ones(len(g), bool), 1e-3) is None
    # a gap restarts the lag from rolling; a sample without a rate is skipped (NaN)
    ok = np.ones(len(g), bool)
    ok[300:310] = False
    phd = g[:, 3].copy()
    phd[600] = np.nan
    r = law.spin(m, g[:, 2], g[:, 1], phd, ok, 1e-3)
    assert np.all(np.isnan(r[300:310])) and r[310] == 0.0 and np.isnan(r[600]) and r[601] == 0.0
    assert np.array_equal(r[:300], law.spin(m, g[:300, 2], g[:300, 1], g[:300, 3],
                                            np.ones(300, bool), 1e-3))
    # a relaxation far below the grid step stays finite and near rolling (the steps follow
    # tau_s): the coupled model at tau_s = 0.5 ms on a 2 ms grid
    u = np.repeat(_shaking(60, dt=5 * DT), 5)[:250]
    x4 = np.array([0.1, 0.3, 1.0, 2.5])
    fast = grip.creep_rollout(m, x4, u, DT, 5e-4)
    assert np.all(np.isfinite(fast))
    assert np.max(np.abs(fast[:, 1] - grip.coupled_rollout(m, x4, u, DT, -1.0)[:, 1])) < 0.01


def test_the_slip_a_creep_implies_is_the_creep_models_own() -> None:
    """The slip a creep law implies (:func:`grip.creep_slip`, module docstring 6), from the
    coupled creep model's own frame rate, contact angle and rate on the 2 ms grid (the model
    starts rolling, as the lag does): its median and 90th-percentile slip ratio ``|r| R /
    |lam phi_dot|`` are the model's own to 1e-3 (measured 0.2062 / 0.4346 at tau_s = 50 ms,
    0.0236 / 0.0613 at 5 ms). A contact's creep saturates at creepages below about 2 %
    (Johnson 1985, 8.3): a median beyond 5 % is a suspect (50 ms here), within it a creep
    (5 ms); the verdict's helper says so, and no other law is a contact's creep."""
    m = RigidModel(RigParams())
    _, _, _, _, rr = grip.slip_parameters(m)
    dt_fine, n = 1e-4, 10000
    lam0 = float(m.curve.speed(np.array([0.05]))[0])
    u = np.array([_torque((k + 0.5) * dt_fine) for k in range(n)])
    for tau, plausible in ((0.05, False), (0.005, True)):
        xs = _creep(m, np.array([0.0, 0.05, 0.0, 0.3, -lam0 * 0.3 / rr]), u, dt_fine, tau)
        g = xs[::round(DT / dt_fine)]
        rel = g[:, 4] - (g[:, 2] - m.curve.speed(g[:, 1]) * g[:, 3] / rr)
        v = np.abs(m.curve.speed(g[:, 1]) * g[:, 3])
        take = v >= grip.MIN_TRACK_SPEED
        truth = np.abs(rel[take]) * rr / v[take]
        cs = grip.creep_slip(m, grip.SlipLaw(kind="creep", value=tau), g[:, 2], g[:, 1],
                             g[:, 3], np.ones(len(g), bool), DT)
        assert cs["samples"] == int(take.sum()) > 400, cs
        assert abs(cs["slip_ratio"]["p50"] - np.median(truth)) < 1e-3 * np.median(truth), cs
        assert abs(cs["slip_ratio"]["p90"] - np.quantile(truth, 0.9)) < 1e-3, cs
        speed = np.abs(rel[take]) * rr  # the slip at the edges [m/s]
        assert abs(cs["slip_speed"]["p50"] - np.median(speed)) < 1e-3 * np.median(speed), cs
        assert cs["plausible"] is plausible, cs
        test = {"law": "creep", "tau_s": tau, "creep_slip": cs}
        assert grip.creep_is_contact(test) is plausible
    assert not grip.creep_is_contact({"law": "creep", "tau_s": 0.05})  # not measured
    none = {"law": "creep", "tau_s": 0.05, "creep_slip": {"plausible": None}}
    assert not grip.creep_is_contact(none)
    assert not grip.creep_is_contact({"law": "coulomb", "mu": 0.2})
    assert not grip.creep_is_contact({"law": None})


def test_the_equation_error_of_a_creeping_ball_vanishes_on_its_own_motion() -> None:
    """The equation error with the creeping spin (:mod:`bfr_diagnose.residual`, a creeping
    ball: the spin's momentum the lag of the rolling rate's) on the coupled creep model's own
    exact motion (1 s at 0.1 ms, sampled at the 2 ms grid; the ball rolls at the start, as
    the lag assumes) is zero to the grid's quadrature: both rows below 1e-3 of the rolling
    rows' (measured 1.4e-4 and 1.1e-4), which see the creep as a misfit; tau_s -> 0 gives
    the rolling rows back (1e-5 s: within 1e-3 of them)."""
    m = RigidModel(RigParams())
    _, pt, jb, _, rr = grip.slip_parameters(m)
    tau, sub, n = 0.05, 20, 500
    lam0 = float(m.curve.speed(np.array([0.05]))[0])
    x5 = np.array([0.0, 0.05, 0.0, 0.3, -lam0 * 0.3 / rr])
    u_fine = np.array([_torque((k + 0.5) * DT / sub) for k in range(n * sub)])
    xs = _creep(m, x5, u_fine, DT / sub, tau)[::sub]
    t = DT * np.arange(n + 1)
    acc = np.array([grip._creep_rhs(x, _torque(v), 1.0 / tau, jb, pt, *m.geom_args)[2]
                    for x, v in zip(xs, t, strict=True)])
    h = 1e-6
    dpsi = (m.curve.ball_angle(xs[:, 1] + h) - m.curve.ball_angle(xs[:, 1] - h)) / (2 * h)
    prep = Prepared(t=t, theta=xs[:, 0], theta_dot=xs[:, 2], theta_ddot=acc,
                    u=np.array([_torque(v) for v in t]),
                    psi_w=m.curve.ball_angle(xs[:, 1]) - xs[:, 0],
                    psi_w_dot=dpsi * xs[:, 3] - xs[:, 2], ball_ok=np.ones(t.size, bool),
                    frame_ok=np.ones(t.size, bool), has_ball=True, latency0=0.0,
                    noise={"camera": 1e-4, "theta": 0.0})
    ev = ResidualEvaluator(prep)
    rows = {c: ev.evaluate(RigParams(), SensorCorrection(), creep=c) for c in (None, tau, 1e-5)}
    for i in (0, 1):
        rolling = np.max(np.abs(rows[None].rows[i]))
        assert rolling > 1e-5, rolling
        assert np.max(np.abs(rows[tau].rows[i])) < 1e-3 * rolling, (i, rows[tau].rows[i])
        assert np.max(np.abs(rows[1e-5].rows[i] - rows[None].rows[i])) < 1e-3 * rolling


def _grip_of(rec) -> dict:  # noqa: ANN001
    """The grip of a recording under the nominal model (alternate seconds held out)."""
    base = RigParams()
    prep = prepare(rec)
    res = ResidualEvaluator(prep).evaluate(base, SensorCorrection())
    test = np.floor(prep.t) % 2 == 1
    return grip.grip(prep, base, base, SensorCorrection(), res.phi, res.phi_dot, test)


def test_a_rigid_ball_rolls() -> None:
    """A closed loop on the rigid model (it cannot slip): verdict ``rolls``, no contact lost,
    and the friction its orbit demands is reported (this controller's orbit needs up to
    about 0.7)."""
    base = RigParams()
    rec = stabilised_recording(base, base, SynthConfig(duration=12.0), np.random.default_rng(3))
    assert rec.meta["ball_rolled"]
    g = _grip_of(rec)
    assert g["verdict"] == "rolls", g
    fd = g["friction_demand"]
    assert fd["lift_off_fraction"] == 0.0
    assert 0.2 < fd["max"] < 2.0 and fd["p50"] < fd["p90"] < fd["p99"] <= fd["max"]


@pytest.mark.parametrize("seed", [3, 5])
def test_a_contact_model_ball_that_slips_gets_its_friction_coefficient(seed: int) -> None:
    """Truth of another structure: the contact model (free ball, compliant contact) with
    mu = 0.5 on the plate edges, below the 0.7-0.8 its closed loop demands at the peaks (the
    controller loses the ball below about 0.5). The training windows choose a coefficient
    within a grid step of the truth or rolling, never creep, and a coefficient below the
    truth's lower grid neighbour never: mu = 0.38 costs 7-17x rolling's. (0.57 on all nine
    recordings of 16-60 s measured in the fourteenth round; this round's kernels change the
    closed loop's last bits, so the samples are new: seeds 3-6 choose rolling, 0.57, 0.57,
    rolling, where 0.57 cost 1.3x and 3.3x rolling's. The slips are rare, at the demand's
    peaks, and the contact model's slip is not the rigid model's Coulomb slip to the bit.)
    The held-out verdict follows its own rule and is weak here, because the ball slips only
    at the demand's peaks: 4-23 held-out windows differ from rolling, and two of the seven
    measured with a first-order draft of the integrator passed a sign test at p < 0.01
    (this code's randomisation test: seed 3 10 of 13 windows better, p = 0.07; seed 5 8 of
    14, p = 0.76)."""
    base = RigParams()
    plant = base.replace(**{"contact.static_friction": 0.5, "contact.dynamic_friction": 0.5})
    rec = contact_recording(plant, base, SynthConfig(duration=40.0), np.random.default_rng(seed))
    assert rec.meta["ball_rolled"]
    g = _grip_of(rec)
    st = g["slip_test"]
    assert st["law"] in (None, "coulomb") and st["mu"] in (None, 0.38, 0.57), st
    assert st["train_cost"]["0.38"] > 3.0 * st["train_cost"]["rolling"], st
    assert g["friction_demand"]["max"] > 0.5
    slips = (st["improvement"] >= grip.MIN_GAIN and st["p_value"] < grip.ALPHA)
    assert g["verdict"] == ("slips" if slips else "rolls"), g


@pytest.mark.parametrize(("damping", "seed"), [(0.2, 5), (0.3, 3)])
def test_a_contact_model_ball_that_creeps_gets_creep(damping: float, seed: int) -> None:
    """Truth of another structure with a creeping contact: the contact model with its stick
    spring made soft (1 N/m) and a tangential damper c, so that the edges' friction is about
    ``-c v_slip`` (``v_slip = R (omega_b - omega_roll)``, the contact point's lever R) and
    the spin relaxes with ``tau_s = J_b / (c R^2)``: 0.024 s at c = 0.2, 0.016 s at 0.3 (mu
    1.0: never reached). The slip test chooses creep, not Coulomb, within a grid step of that
    tau_s (the grid starts at 0.02 s), and the held-out ball says ``slips`` (measured 2.6x and
    3.1x, p < 2e-4)."""
    base = RigParams()
    plant = base.replace(**{"contact.static_friction": 1.0, "contact.dynamic_friction": 1.0,
                            "contact.tangential_stiffness": 1.0,
                            "contact.tangential_damping": damping})
    rec = contact_recording(plant, base, SynthConfig(duration=20.0), np.random.default_rng(seed))
    assert rec.meta["ball_rolled"]
    g = _grip_of(rec)
    st = g["slip_test"]
    m = RigidModel(base)
    tau_true = base.ball.inertia / (damping * float(m.P[grip.I_R]) ** 2)
    assert st["law"] == "creep", st
    assert max(tau_true, grip.TAU_GRID[0]) / 1.5 <= st["tau_s"] <= tau_true * 1.5, (st, tau_true)
    assert g["verdict"] == "slips" and st["improvement"] > 1.5, g
    # the smoothed start of the coupled prediction: the measured state and the spin the law
    # implies from the rolling rate before it (measured 0.58x and 0.49x the rolling model's
    # error; the creep model started rolling was 1.95x and 1.03x it)
    prep = prepare(rec)
    ev = ResidualEvaluator(prep)
    res = ev.evaluate(base, SensorCorrection())
    args = (prep, base, res.phi, res.phi_dot, SensorCorrection(), np.floor(prep.t) % 2 == 1)
    rolling = prediction_errors(*args)["rmse"]["ball_angle"]
    creeping = prediction_errors(*args, slip=grip.SlipLaw(kind="creep", value=tau_true))
    assert creeping["rmse"]["ball_angle"] < 0.7 * rolling, (creeping["rmse"], rolling)
    # another method: the ball's row of the equation error with the creeping spin (the lag of
    # the measured rolling rate); its training samples choose tau_s within a grid step too,
    # and held out it is a fraction of rolling's (measured 0.27 at c = 0.2)
    test = np.floor(prep.t[ev.idx]) % 2 == 1

    def ball_row(creep: float | None, mask: np.ndarray) -> float:
        r = ev.evaluate(base, SensorCorrection(), creep=creep).r2[mask]
        return float(np.sqrt(np.nanmean(r ** 2)))

    tau_ee = min(grip.TAU_GRID, key=lambda t: ball_row(t, ~test))
    assert max(tau_true, grip.TAU_GRID[0]) / 1.5 <= tau_ee <= tau_true * 1.5, (tau_ee, tau_true)
    assert ball_row(st["tau_s"], test) < 0.4 * ball_row(None, test)


@pytest.mark.parametrize("seed", [3, 5])
def test_the_simulators_creeping_ball_gets_its_creep_time(seed: int) -> None:
    """The rigid model the simulator runs with the law the diagnosis writes
    (``ball.creep_time`` = 0.02 s) in bfr's closed loop: the slip test chooses creep at
    0.02 s, slipping 11x better held out (measured 11.1x both). The slip that creep implies
    on this orbit is measured (a median slip ratio of 5.1 % on both seeds, 90th percentile
    14 %: at the 5 % a contact's creep may reach, so whether corrected_params.yaml carries
    it is the rule's call, not asserted); bfr's controller, which assumes rolling, loses a
    ball that creeps with 0.03 s or more (measured at 0.03, 0.05 and 0.1 s)."""
    base = RigParams()
    plant = base.replace(**{"ball.creep_time": 0.02})
    rec = stabilised_recording(plant, base, SynthConfig(duration=20.0),
                               np.random.default_rng(seed))
    assert rec.meta["ball_rolled"]
    g = _grip_of(rec)
    st = g["slip_test"]
    assert g["verdict"] == "slips" and st["law"] == "creep", g
    assert 0.02 / 1.5 <= st["tau_s"] <= 0.02 * 1.5 and st["improvement"] > 3.0, st
    cs = st["creep_slip"]
    assert cs["samples"] > 5000 and 0.03 < cs["slip_ratio"]["p50"] < 0.08, cs
    assert grip.creep_is_contact(st) is (cs["slip_ratio"]["p50"] <= grip.MAX_CREEP_SLIP)


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ntnu-rig is absent")
@pytest.mark.parametrize(("name", "verdict"), [("Actually_worked", "slips"), ("fin", "rolls")])
def test_the_real_ball_slips_where_the_rig_brakes_hard(name: str, verdict: str,
                                                       tmp_path: Path) -> None:
    """The NTNU rig: on Actually_worked, whose controller brakes the frame at -0.1 N m from
    10 rad/s, rolling would need mu up to 0.56 and the ball slips: the training windows
    choose linear creep (its spin relaxes to rolling over tau_s = 0.1 s; Coulomb's best,
    mu = 0.17, costs 2.8x as much there) and the held-out ball is 2.4x better (42 of 69
    windows, p = 1.5e-4); on fin, gentler (rolling needs at most 0.12), it rolls, the data
    reject mu <= 0.075 and every creep. That creep is not a contact's: its spin lags rolling by
    a median 18 % (a contact's elastic creep saturates below about 2 %), so it is a suspect
    and corrected_params.yaml keeps ball.creep_time 0 on both logs; the open-loop
    panel of phi_dot.png shows the slip's model beside the others (Actually_worked: phi_dot
    misfit 1.29 nominal, 0.95 corrected, 0.51 rad/s with the creep, RMS over places)."""
    out = tmp_path / "out"
    assert diagnose_main([str(DATA / f"{name}.txt"), "--quiet", "--out-dir", str(out)]) == 0
    s = json.loads((out / "diagnosis.json").read_text())
    prof = s["phi_dot_profile"]
    g = s["grip"]
    assert g["verdict"] == verdict, g
    m = s["recordings"][0]["metrics"]
    st = g["slip_test"]
    if verdict == "slips":
        assert st["law"] == "creep" and 0.067 <= st["tau_s"] <= 0.15, st
        assert st["improvement"] > 2.0 and st["train_cost"]["tau_s 0.1"] < min(
            c for k, c in st["train_cost"].items() if not k.startswith("tau_s")), st
        assert g["friction_demand"]["max"] > 0.4
        assert any("slips" in n for n in s["notes"])
        # the coupled 100 ms prediction of the plausible effects with the slip, the relative
        # spin a fifth state of the start (measured 2.53x; Coulomb at mu = 0.17 was 1.44x,
        # the selection with its suspect ball inertia 1.14x)
        with_slip = m["prediction_causal_improvement_with_slip"]["ball_angle"]
        assert with_slip > 2.2 and with_slip > m["prediction_causal_improvement"]["ball_angle"]
        # from the smoothed state, the spin the creep implies from the rolling rate before
        # each start (measured 1.59x; started rolling 1.08x)
        assert m["prediction_improvement_with_slip"]["ball_angle"] > 1.4, m
        # the creep by another method, the equation error (the spin the lag of the measured
        # rolling rate): the ball's row held out 2.59 -> 1.00 x noise (the selection with its
        # suspect light ball 1.36); its training samples choose tau_s = 0.1 s too
        ee = g["equation_error"]
        assert ee["heldout_creep"] < 0.5 * ee["heldout_rolling"], ee
        assert ee["heldout_creep"] < ee["heldout_selection"], ee
        assert 0.067 <= ee["tau_s_train"] <= 0.15, ee
        # but no contact creeps that far: the spin lags rolling by a median 18 % (90th
        # percentile 86 %, slip speeds 0.05-0.21 m/s) where elastic creep saturates below
        # about 2 %: a suspect, not written into corrected_params.yaml (ball.creep_time 0)
        cs = st["creep_slip"]
        assert cs["plausible"] is False and cs["slip_ratio"]["p50"] > 0.1, cs
        assert "not a contact's creep" in g["meaning"], g["meaning"]
        written = (out / "corrected_params.yaml").read_text()
        assert "creep_time: 0.0" in written and "ball's creep, tau_s" in written, written
        # the suspect ball inertia and the creep: stand-ins for one thing
        assert any("both take from the ball's motion" in n for n in s["notes"]), s["notes"]
        assert prof["slip_law"].startswith("creep") and len(prof["open_loop_misfit_slip"]) == 36
        assert prof["open_loop_rms_slip"] < 0.7 * prof["open_loop_rms_corrected"], prof
    else:
        assert g["friction_demand"]["max"] < 0.2 and st["law"] is None
        assert st["mu"] is None and st["tau_s"] is None
        assert "equation_error" not in g
        assert "creep_time: 0.0" in (out / "corrected_params.yaml").read_text()
        assert "prediction_causal_after_slip" not in m and "open_loop_misfit_slip" not in prof
