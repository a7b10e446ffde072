"""The ball estimator and the controller core on bad, short, empty and stale input.

Every path of :class:`bfr_control.estimator.BallEstimator` that can meet an empty, one-sample
or stale encoder history, a gap, an absurd fix or a diverged estimate; the gate; the
prediction through camera gaps (closed loop, nominal plant); and the controller's
prediction through the actuation delay (``lead``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_control.controller import (
    BALL_LOST,
    ROLLING,
    OrbitalController,
)
from bfr_control.estimator import BallEstimator, BallObservation, passive_phi_ddot
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params
from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop

NOMINAL = load_params()


@pytest.fixture
def est(controller: OrbitalController) -> BallEstimator:
    e = BallEstimator(controller.model, controller.orbit, controller.config.estimator)
    return e


def orbit_track(controller: OrbitalController, phi0: float, n: int, dt: float = 1e-3,
                t0: float = 0.0) -> list[tuple[float, np.ndarray]]:
    """States of the ball on the orbit from phi0, sampled every dt (exact, from the table)."""
    out = []
    x = controller.orbit.state(phi0)
    model = controller.model
    x6 = np.zeros(6)
    x6[:4] = x
    u = 0.0
    for k in range(n):
        out.append((t0 + k * dt, x6[:4].copy()))
        # the orbit is unstable open loop; over a few hundred ms it stays close enough
        x6 = model.step(x6, u, dt, 1)
    return out


def feed(est: BallEstimator, track: list[tuple[float, np.ndarray]], model: RigidModel,
         every: int = 5, noise: float = 0.0, rng: np.random.Generator | None = None) -> int:
    used = 0
    for k, (t, x) in enumerate(track):
        est.record(t, float(x[0]), float(x[2]))
        if k % every == 0:
            bx, by = model.ball_position(x)
            if noise:
                bx, by = bx + noise * rng.standard_normal(), by + noise * rng.standard_normal()
            used += est.update(BallObservation(t, float(bx), float(by)))
    return used


# -- passive row: no division by zero ---------------------------------------------------------
def test_passive_row_returns_nan_where_it_has_no_slope(controller: OrbitalController) -> None:
    args = controller.model.kernel_args
    a = passive_phi_ddot(0.1, 0.3, 0.2, 2.4, 1.0, *args)
    assert math.isfinite(a)
    # absurd speed: a unit torque no longer changes theta_ddot in floating point
    assert math.isnan(passive_phi_ddot(0.1, 0.3, 0.2, 1e12, 1.0, *args))
    assert math.isnan(passive_phi_ddot(0.1, math.nan, 0.2, 2.4, 1.0, *args))


# -- empty, short and stale histories ---------------------------------------------------------
def test_fix_without_encoder_history_is_not_used(est: BallEstimator,
                                                 controller: OrbitalController) -> None:
    bx, by = controller.model.ball_position(controller.orbit.state(0.4))
    assert not est.update(BallObservation(0.0, float(bx), float(by)))  # empty history
    est.record(0.0, 0.0, 0.0)
    assert not est.update(BallObservation(0.001, float(bx), float(by)))  # after the only sample
    assert not est.initialized
    est.record(0.002, 0.0, 0.0)
    assert est.update(BallObservation(0.001, float(bx), float(by)))  # covered now
    assert est.initialized and est.frames == 1


def test_propagation_with_one_sample_or_backwards_is_a_no_op(est: BallEstimator) -> None:
    assert est._propagate(0.3, 2.4, 0.0, 0.0, 1.0) == (0.3, 2.4, 0.0)  # empty
    est.record(0.0, 0.0, 0.0)
    assert est._propagate(0.3, 2.4, 0.0, 0.0, 1.0) == (0.3, 2.4, 0.0)  # one sample
    est.record(0.001, 0.0, 0.0)
    assert est._propagate(0.3, 2.4, 0.0, 0.001, 0.0) == (0.3, 2.4, 0.0)  # t1 < t0
    phi, pd, _ = est._propagate(0.3, 2.4, 0.0, -5.0, 0.001)  # starts before the history
    assert math.isfinite(phi) and math.isfinite(pd)


def test_record_ignores_repeated_out_of_order_and_nan_samples(est: BallEstimator) -> None:
    est.record(0.0, 0.0, 0.0)
    est.record(0.0, 1.0, 1.0)
    est.record(-1.0, 1.0, 1.0)
    est.record(0.001, math.nan, 0.0)
    est.record(math.inf, 0.0, 0.0)
    assert est._ts == [0.0] and est._th == [0.0]


def test_long_encoder_gap_restarts_the_filter_and_keeps_two_samples(
        est: BallEstimator, controller: OrbitalController) -> None:
    model = controller.model
    track = orbit_track(controller, 0.4, 120)
    assert feed(est, track, model) > 5 and est.initialized
    restarts = est.restarts["gap"]
    t_last, x = track[-1]
    # the encoder goes silent for 2 s (dead driver), then comes back: no IndexError, no
    # propagation through the gap, the filter restarts
    est.record(t_last + 2.0, float(x[0]), float(x[2]))
    assert not est.initialized and est.restarts["gap"] == restarts + 1
    assert len(est._ts) == 1
    est.record(t_last + 2.001, float(x[0]), float(x[2]))
    bx, by = model.ball_position(x)
    assert est.update(BallObservation(t_last + 2.0005, float(bx), float(by)))
    # a history trimmed right after a gap just under max_gap still keeps >= 2 samples
    est2 = BallEstimator(model, controller.orbit, controller.config.estimator)
    for k in range(100):
        est2.record(k * 1e-3, 0.0, 0.0)
    est2.record(0.099 + 0.45, 0.0, 0.0)
    est2.record(0.099 + 0.451, 0.0, 0.0)
    assert len(est2._ts) >= 2


def test_stale_old_and_future_fixes(est: BallEstimator, controller: OrbitalController) -> None:
    model = controller.model
    track = orbit_track(controller, 1.0, 100)
    feed(est, track, model)
    frames = est.frames
    t, x = track[-1]
    bx, by = (float(v) for v in model.ball_position(x))
    assert not est.update(BallObservation(t - 0.05, bx, by))  # older than the last fix
    assert not est.update(BallObservation(t + 1.0, bx, by))  # future: beyond the history
    assert not est.update(BallObservation(t, math.nan, by))
    assert not est.update(BallObservation(t, bx, by, valid=False))
    assert not est.update(BallObservation(t + 0.0001, 0.0, 0.0))  # the rig's "no ball"
    assert est.frames == frames and est.initialized


# -- the gate ------------------------------------------------------------------------------
def test_absurd_fixes_are_rejected_and_the_filter_restarts_after_a_run_of_them(
        est: BallEstimator, controller: OrbitalController) -> None:
    model = controller.model
    track = orbit_track(controller, 0.6, 200)
    feed(est, track[:100], model)
    phi0 = est.phi
    for k, (t, x) in enumerate(track[100:103]):
        est.record(t, float(x[0]), float(x[2]))
        # 1 m from the axis: not a ball on this frame
        assert not est.update(BallObservation(t, 1.0, 0.2 + k))
    assert est.rejected["radial"] == 3 and "off the ball's track" in est.last_rejection
    assert abs(est.phi - phi0) < 0.1  # the estimate ran on, untouched
    # on the track but at the wrong place (the ball mirrored across the axis): innovation
    t, x = track[103]
    est.record(t, float(x[0]), float(x[2]))
    bx, by = model.ball_position(x)
    assert not est.update(BallObservation(t, float(-bx), float(-by)))
    assert est.rejected["innovation"] == 1 and "sigma" in est.last_rejection
    # four in a row: the filter gives up its estimate and starts from the next good fix
    assert not est.initialized and est.restarts["gate"] == 1
    feed(est, track[104:], model)
    assert est.initialized and abs(est.phi - track[-1][1][1]) < 1e-3


def test_a_diverged_estimate_resets(est: BallEstimator, controller: OrbitalController) -> None:
    model = controller.model
    track = orbit_track(controller, 0.6, 60)
    feed(est, track, model)
    est.phi_dot = 1e12  # as if an absurd fix had slipped through
    t, x = track[-1]
    est.record(t + 0.001, float(x[0]), float(x[2]))
    assert not est.initialized and est.restarts["diverged"] == 1


# -- prediction through gaps (closed loop, nominal plant) --------------------------------------
@pytest.mark.parametrize("gap", [0.15, 0.25])
def test_prediction_rides_through_camera_gaps(controller: OrbitalController, gap: float) -> None:
    """No fix for ``gap`` seconds: the estimate stays within 20 mrad, the ball rolls on."""
    assert controller.config.supervisor.lost_timeout >= gap
    for seed, phase in enumerate((0.3, 1.0)):
        x0 = orbit_initial_state(controller, phase, d_theta=0.02)
        res = run_closed_loop(controller, NOMINAL, 5.0, x0,
                              SensorConfig(camera_blackouts=((3.0, 3.0 + gap - 0.006),)),
                              seed=seed, control_rate=200.0)
        s = res.summary()
        assert s["ball_rolling"], s
        w = (res.t >= 3.0) & (res.t <= 3.0 + gap)
        assert np.all(res.mode[w] == 1)
        assert np.max(np.abs(res.phi_hat[w] - res.x[w, 1])) < 0.02
        assert np.max(np.abs(res.phi_dot_hat[w] - res.x[w, 3])) < 0.2


def test_a_gap_longer_than_the_bound_is_ball_lost(controller: OrbitalController) -> None:
    timeout = controller.config.supervisor.lost_timeout
    x0 = orbit_initial_state(controller, 0.5)
    res = run_closed_loop(controller, NOMINAL, 4.0, x0,
                          SensorConfig(camera_blackouts=((2.0, 10.0),)), seed=2,
                          control_rate=200.0)
    lost = res.mode == 2
    t_lost = res.t[np.argmax(lost)]
    assert 2.0 + timeout - 0.01 <= t_lost <= 2.0 + timeout + 0.02
    assert np.all(res.u[lost] == 0.0)


# -- the controller core: lead, a camera back after BALL_LOST, absurd input ----------------------
def test_prediction_through_the_actuation_delay(controller: OrbitalController) -> None:
    """lead = d: the law answers the state the torque meets; the command equals that of a
    step taken d later on the predicted encoder sample (same torque meanwhile)."""
    controller.reset()
    model = controller.model
    track = orbit_track(controller, 0.8, 60)
    cmd = None
    for k, (t, x) in enumerate(track[:50]):
        obs = None
        if k % 5 == 0:
            bx, by = model.ball_position(x)
            obs = BallObservation(t, float(bx), float(by))
        cmd = controller.step(t, float(x[0]), float(x[2]), obs)
    assert cmd is not None and cmd.mode == ROLLING and cmd.lead == 0.0
    u_prev = controller.last_torque
    t, x = track[50]
    controller.estimator.record(t, float(x[0]), float(x[2]))  # the step's own sample
    est_x = np.array([x[0], controller.estimator.phi, x[2], controller.estimator.phi_dot])
    lead = 0.008
    xp = controller.predict(est_x, lead, u_prev)
    cmd_lead = controller.step(t, float(x[0]), float(x[2]), None, lead=lead)
    assert cmd_lead.lead == pytest.approx(lead)
    assert cmd_lead.phi == pytest.approx(xp[1], abs=1e-4)
    assert cmd_lead.phi_dot == pytest.approx(xp[3], abs=1e-3)
    # nonsense leads are clipped, never propagated
    assert controller.step(t + 0.001, float(x[0]), float(x[2]), None,
                           lead=math.nan).lead == 0.0
    assert controller.step(t + 0.002, float(x[0]), float(x[2]), None,
                           lead=-1.0).lead == 0.0
    big = controller.step(t + 0.003, float(x[0]), float(x[2]), None, lead=10.0)
    assert big.lead <= controller.config.supervisor.lost_timeout


def test_camera_back_after_ball_lost_without_a_reset(controller: OrbitalController) -> None:
    """The ball is lost (no fixes), the encoder keeps running, the camera comes back with
    fixes again and even absurd ones: no exception, BALL_LOST and zero torque throughout."""
    controller.reset()
    model = controller.model
    track = orbit_track(controller, 0.3, 400)
    for k, (t, x) in enumerate(track):
        obs = None
        if k % 5 == 0 and not 100 <= k < 300:
            bx, by = model.ball_position(x)
            obs = BallObservation(t, float(bx), float(by))
            if k % 35 == 0:
                obs = BallObservation(t, 1e9, -1e9)
        cmd = controller.step(t, float(x[0]), float(x[2]), obs)
        if k > 100 + 260:
            assert cmd.mode == BALL_LOST and cmd.torque == 0.0


# -- camera stamps that jitter --------------------------------------------------------------------
@pytest.mark.parametrize(("jitter", "drop"), [(0.0, 0.0), (0.0, 0.3), (5e-4, 0.0), (5e-4, 0.3)])
def test_stamp_jitter_is_measured_from_the_stamps(est: BallEstimator, jitter: float,
                                                  drop: float) -> None:
    """The stamps of a 200 Hz camera, 30 % of its frames never delivered (their intervals
    whole periods), each stamp off its exposure by Gaussian jitter: the estimator's
    ``stamp_jitter`` is the jitter within 15 % (400 stamps), and 0 to rounding without one.
    Invalid fixes count: their stamps are the camera's as much as a valid fix's."""
    rng = np.random.default_rng(7)
    stamps = np.arange(600) / 200.0
    stamps = stamps[rng.random(stamps.size) >= drop][:400]
    stamps = stamps + jitter * rng.standard_normal(stamps.size)
    assert np.all(np.diff(stamps) > 0)
    for s in stamps:
        est.update(BallObservation(float(s), 0.0, 0.0, valid=False))
    if jitter:
        assert est.stamp_jitter == pytest.approx(jitter, rel=0.15)
    else:
        assert est.stamp_jitter < 1e-9


def test_camera_stamps_that_jitter_are_weighed_not_rejected(
        controller: OrbitalController) -> None:
    """A camera whose stamps are off its exposures by 2 ms (Gaussian; a software stamp at
    arrival) in bfr's closed loop: each fix's variance gains the jitter times the rate the
    innovation moves at (the ball's world rate through dphi/dpsi), the jitter estimated from
    the stamps (1.32-1.37 ms measured: stamps that come out of order are dropped, so it
    reads low). Measured over 15 s, seeds 1 and 2: 0 fixes rejected, the ball rolls, phi's
    error 2.5-2.6 mrad RMS. Without the stamp term the gate rejected 1724 and 1822 fixes,
    restarted the filter 318 and 380 times, and the ball was lost on both (at 1 ms: 105 and
    369 rejected, lost on seed 2)."""
    x0 = orbit_initial_state(controller, 0.5)
    res = run_closed_loop(controller, NOMINAL, 10.0, x0,
                          SensorConfig(camera_stamp_jitter=2e-3), seed=2)
    e = controller.estimator
    assert res.summary()["ball_rolling"]
    assert 0.5e-3 < e.stamp_jitter < 2.4e-3
    assert e.rejected["innovation"] <= 5 and e.restarts["gate"] == 0, (e.rejected, e.restarts)
    w = res.mode == 1
    assert np.sqrt(np.mean((res.phi_hat[w] - res.x[w, 1]) ** 2)) < 5e-3
