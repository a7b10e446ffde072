"""Tests of the diagnosis's short-horizon predictions (:mod:`bfr_diagnose.locate`).

Two measures of a model's 100 ms open-loop prediction on held-out data: from the smoothed
state at each window start (:func:`~bfr_diagnose.locate.prediction_errors`), and from the
state the model itself fits to the 100 ms before (causal,
:func:`~bfr_diagnose.locate.causal_prediction_errors`). The tests: a closed form (the frame
alone under a constant torque: the fitted start is the truth, the prediction exact); a
rolling recording made by the rigid model (the true model predicts at the noise level, a
wrong inertia clearly worse); and the point of the causal measure: from the truth it is well
below the smoothed start's error, which measures the smoother rather than the model.
"""

from __future__ import annotations

import numpy as np
import pytest
from bfr_diagnose.locate import (
    causal_prediction_errors,
    phi_dot_misfit_by_place,
    prediction_errors,
)
from bfr_diagnose.preprocess import Prepared, SensorCorrection, prepare
from bfr_diagnose.residual import ResidualEvaluator
from bfr_diagnose.synth import SynthConfig, held_frame_recording, stabilised_recording
from bfr_model.params import RigParams

DT = 0.002  # [s] grid step of the closed-form recording (the diagnosis's grid)


# -- closed form: the frame alone under a constant torque -------------------------------------

def _constant_torque_frame(params: RigParams, u: float, th0: float, v0: float,
                           duration: float, velocity_bias: float) -> tuple[Prepared, float]:
    """A frame-only recording of ``J_f theta_ddot = k_u u + tau_0 - T_c`` (theta_dot > 0).

    ``theta(t) = theta_0 + v_0 t + a t^2 / 2``, ``a = (k_u u + tau_0 - T_c) / J_f``: the
    Coulomb friction is constant while the frame turns one way (``tanh(theta_dot / v_c)``
    is 1 to the last bit for ``theta_dot >> v_c``). No noise; the measured rate is off by
    ``velocity_bias`` (a start guess the fit must correct). Returns the prepared recording
    and a.
    """
    j = params.joint
    a = (params.actuator.torque_gain * u + params.actuator.torque_offset
         - j.coulomb_friction) / params.frame.inertia
    t = DT * np.arange(round(duration / DT) + 1)
    theta = th0 + v0 * t + 0.5 * a * t * t
    nan = np.full(t.size, np.nan)
    prep = Prepared(t=t, theta=theta, theta_dot=v0 + a * t + velocity_bias,
                    theta_ddot=np.full(t.size, a), u=np.full(t.size, u), psi_w=nan,
                    psi_w_dot=nan.copy(), ball_ok=np.zeros(t.size, bool),
                    frame_ok=np.ones(t.size, bool), has_ball=False, latency0=0.0,
                    noise={"camera": float("nan"), "theta": 0.0})
    return prep, a


def test_frame_alone_under_constant_torque_the_fitted_start_is_the_truth() -> None:
    """Exact model, no noise: the start each window fits to the 100 ms before is the true
    ``(theta, theta_dot)`` and the causal prediction exact (the frame's step is exact for a
    constant acceleration); the smoothed start, which takes the measured rate, is off by the
    rate's bias times the time ahead (``RMS = b sqrt(mean t^2)``)."""
    params = RigParams().replace(**{"joint.coulomb_friction": 2e-3})
    bias = 0.05
    prep, a = _constant_torque_frame(params, u=8e-3, th0=1.3, v0=0.4, duration=6.0,
                                     velocity_bias=bias)
    # held out: [1, 3) s and [4, 6) s; windows every 0.2 s whose 100 ms lie inside
    test = ((prep.t >= 1.0) & (prep.t < 3.0)) | ((prep.t >= 4.0) & (prep.t < 6.0))
    nan = np.full(prep.n, np.nan)
    causal = causal_prediction_errors(prep, params, nan, nan, None, test, keep_traces=100)
    smoothed = prediction_errors(prep, params, nan, nan, None, test)
    assert causal["start"] == "fitted" and smoothed["start"] == "smoothed"
    # starts 1.0, 1.2, ..., 2.8 s and 4.0, ..., 5.8 s (each block's 100 ms inside it)
    assert causal["n_windows"] == smoothed["n_windows"] == 20
    assert causal["n_skipped"] == 0
    assert causal["fit_window"] == pytest.approx(0.1, abs=1e-12)
    for tr in causal["traces"]:
        tj = tr["fit_t"]
        th, _, v, _ = tr["fit_state"]
        assert th == pytest.approx(1.3 + 0.4 * tj + 0.5 * a * tj * tj, abs=1e-9)
        assert v == pytest.approx(0.4 + a * tj, abs=1e-7)
    assert causal["rmse"]["theta"] < 1e-9
    # the smoothed start: theta off by b k dt at step k = 1..50
    k = np.arange(1, 51)
    expected = bias * DT * np.sqrt(np.mean(k ** 2.0))
    assert smoothed["rmse"]["theta"] == pytest.approx(expected, rel=1e-6)
    # against the (biased) measured rate both are off by the bias
    assert causal["rmse"]["theta_dot"] == pytest.approx(bias, rel=1e-6)
    assert np.isnan(causal["rmse"]["ball_angle"])


# -- a rolling recording made by the rigid model -----------------------------------------------

@pytest.fixture(scope="module")
def rolling() -> tuple[Prepared, ResidualEvaluator]:
    """6 s of the stabilised rolling ball on the nominal rigid plant (camera noise 0.1 mm,
    a 65536-count encoder), prepared as the diagnosis prepares it."""
    base = RigParams()
    rec = stabilised_recording(base, base, SynthConfig(duration=6.0), np.random.default_rng(2))
    assert rec.meta["ball_rolled"]
    prep = prepare(rec)
    return prep, ResidualEvaluator(prep)


def _predictions(rolling: tuple[Prepared, ResidualEvaluator],
                 changes: dict) -> tuple[dict, dict]:
    """(smoothed-start, causal) predictions of the nominal model with ``changes`` on the
    whole recording held out; each model's own smoothed phi, phi_dot start the fit."""
    prep, ev = rolling
    params = RigParams().replace(**changes) if changes else RigParams()
    res = ev.evaluate(params, SensorCorrection())
    test = np.ones(prep.n, bool)
    return (prediction_errors(prep, params, res.phi, res.phi_dot, None, test),
            causal_prediction_errors(prep, params, res.phi, res.phi_dot, None, test))


def _camera_angle_noise(prep: Prepared) -> float:
    """The camera's noise as an angle [rad]: per-axis noise over the ball's distance."""
    return prep.noise["camera"] / float(np.nanmedian(prep.rho))


def test_the_true_model_predicts_at_the_noise_level(
        rolling: tuple[Prepared, ResidualEvaluator]) -> None:
    """The plant's own parameters, the state fitted to the 100 ms before: the ball's
    predicted world angle is off by about the camera's noise as an angle (measured 1.9 x:
    the noise plus the torque's anti-aliasing on the 2 ms grid, which the open-loop run over
    200 ms accumulates)."""
    _, causal = _predictions(rolling, {})
    noise = _camera_angle_noise(rolling[0])
    assert causal["n_windows"] >= 25 and causal["n_skipped"] == 0
    assert causal["rmse"]["ball_angle"] < 3.0 * noise, (causal["rmse"], noise)
    assert causal["rmse"]["theta"] < 3e-3


@pytest.mark.parametrize(("changes", "least"), [
    ({"frame.inertia": 1.58e-3 * 0.6}, 10.0),   # measured 22 x
    ({"ball.inertia": 5.48e-7 * 1.3}, 2.5),     # measured 4.2 x
])
def test_a_wrong_inertia_predicts_clearly_worse(
        rolling: tuple[Prepared, ResidualEvaluator], changes: dict, least: float) -> None:
    """A wrong frame or ball inertia, with its own fitted start: the ball's 100 ms
    prediction error is ``least`` times the true model's or more (the smoothed start's
    ratio is 3.6 x and 1.1 x: its own error hides the ball's inertia)."""
    _, truth = _predictions(rolling, {})
    _, wrong = _predictions(rolling, changes)
    ratio = wrong["rmse"]["ball_angle"] / truth["rmse"]["ball_angle"]
    assert ratio > least, ratio


def test_from_the_truth_the_fitted_start_beats_the_smoothed_start(
        rolling: tuple[Prepared, ResidualEvaluator]) -> None:
    """The point of the causal measure: with the true model, the prediction from the state
    fitted to the past is well below the one from the smoothed state (measured 0.24 x),
    whose error is the smoother's (its phi_dot), common to every model."""
    smoothed, causal = _predictions(rolling, {})
    assert causal["n_windows"] >= 0.8 * smoothed["n_windows"]
    ratio = causal["rmse"]["ball_angle"] / smoothed["rmse"]["ball_angle"]
    assert ratio < 0.5, (causal["rmse"], smoothed["rmse"])


# -- a held frame: the ball alone ---------------------------------------------------------------

def test_on_a_held_frame_the_ball_alone_is_fitted_and_predicted() -> None:
    """The frame held, the ball rolling freely from 0.8 rad (no torque): only (phi, phi_dot)
    are fitted, to the ball's world angle. The true model predicts the ball at the camera's
    noise (measured 0.88 x its angle; no torque to sample here), five times better than from
    the smoothed state; a ball inertia 1.3 x the truth is far worse (measured 17.6 x). No
    frame signal is scored."""
    base = RigParams()
    rec = held_frame_recording(base, SynthConfig(duration=6.0), np.random.default_rng(5),
                               phi0=0.8)
    prep = prepare(rec)
    assert prep.frame_held
    ev = ResidualEvaluator(prep)
    test = np.ones(prep.n, bool)
    out = {}
    for name, params in (("truth", base), ("wrong", base.replace(**{"ball.inertia":
                                                                    5.48e-7 * 1.3}))):
        res = ev.evaluate(params, SensorCorrection())
        out[name] = (prediction_errors(prep, params, res.phi, res.phi_dot, None, test),
                     causal_prediction_errors(prep, params, res.phi, res.phi_dot, None, test))
    smoothed, causal = out["truth"]
    assert causal["n_windows"] >= 25 and causal["n_skipped"] == 0
    assert np.isnan(causal["rmse"]["theta"]) and np.isnan(causal["rmse"]["theta_dot"])
    assert causal["rmse"]["ball_angle"] < 1.5 * _camera_angle_noise(prep)
    assert causal["rmse"]["ball_angle"] < 0.4 * smoothed["rmse"]["ball_angle"]
    assert out["wrong"][1]["rmse"]["ball_angle"] > 8.0 * causal["rmse"]["ball_angle"]


# -- where on the frame the ball's predicted speed departs ------------------------------------

def test_phi_dot_misfit_by_place_small_for_the_truth_larger_for_a_wrong_ball(
        rolling: tuple[Prepared, ResidualEvaluator]) -> None:
    """The open-loop panel of ``phi_dot.png``: the traces carry the predicted phi and
    phi_dot; binned by the place on the frame, the true model's phi_dot 100 ms ahead stays
    near the measured (its RMS over bins well under the orbit's speed), a wrong ball inertia
    departs further in most bins, and an empty prediction gives NaN."""
    prep, ev = rolling
    test = np.ones(prep.n, bool)
    edges = np.linspace(0.0, np.pi, 13)
    out = {}
    for label, params in (("truth", RigParams()),
                          ("wrong", RigParams().replace(**{"ball.inertia": 5.48e-7 * 1.3}))):
        res = ev.evaluate(params, SensorCorrection())
        pred = causal_prediction_errors(prep, params, res.phi, res.phi_dot, None, test,
                                        keep_traces=1000)
        assert pred["traces"] and len(pred["traces"][0]["phi_dot"]) == len(
            pred["traces"][0]["t"])
        out[label] = phi_dot_misfit_by_place(pred, res.phi_dot, prep.t, edges)
    truth, wrong = out["truth"], out["wrong"]
    both = np.isfinite(truth) & np.isfinite(wrong)
    assert both.sum() >= 6, (truth, wrong)
    speed = float(np.nanmean(np.abs(ev.evaluate(RigParams(), SensorCorrection()).phi_dot)))
    assert np.sqrt(np.mean(truth[both] ** 2)) < 0.1 * speed, (truth, speed)
    assert np.sqrt(np.mean(wrong[both] ** 2)) > 1.5 * np.sqrt(np.mean(truth[both] ** 2)), (
        truth, wrong)
    assert np.mean(wrong[both] > truth[both]) >= 0.6, (truth, wrong)
    assert np.isnan(phi_dot_misfit_by_place({"traces": []}, res.phi_dot, prep.t, edges)).all()
