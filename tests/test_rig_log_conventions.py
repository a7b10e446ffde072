"""The inferred conventions of the NTNU rig logs, checked on the real files.

Numbers and reasoning: docs/ntnu-rig-conventions.md (printed by
``python -m bfr_model.io.rig_conventions``).
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from bfr_model.io.rig_conventions import (
    ball_radius_fit,
    derivative_delay,
    fix_statistics,
    frame_fit_no_ball,
    phi_theta_lag,
    rolling_direction,
)
from bfr_model.io.rig_log import RigLog, parse_rig_log

DATA = Path(os.environ.get("BFR_RIG_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data" / "ntnu-rig"))
pytestmark = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"NTNU rig logs not found at {DATA} (CI has ../shared beside "
                              f"the clone; set BFR_RIG_DATA to override)")
ROLLING = ("Actually_worked", "fin")


@cache
def log(name: str) -> RigLog:
    return parse_rig_log(DATA / f"{name}.txt", warn=False)


@pytest.mark.parametrize("name", ROLLING)
def test_phi_is_theta_eight_samples_earlier_plus_atan2(name: str) -> None:
    lag = phi_theta_lag(log(name).runs[0])
    assert lag["best_lag"] == 8
    assert lag["table"][8]["frac_within"] > 0.99
    assert lag["table"][0]["frac_within"] < 0.05  # same-sample theta does not fit
    assert 0.0083 < lag["best_lag_s"] < 0.0091


@pytest.mark.parametrize("name", ROLLING)
def test_recording_phi_matches_rig_phi(name: str) -> None:
    rec = log(name).recording()
    v = rec.ball_valid & (np.abs(rec.extra["phi_rig"] - rec.phi) < 0.5)
    err = np.abs(rec.extra["phi_rig"][v] - rec.phi[v])
    assert np.mean(err <= rec.meta["theta_resolution"] * 1.01) > 0.99
    assert np.max(err) < 0.02


@pytest.mark.parametrize("name", ROLLING)
def test_theta_and_phi_advance_together(name: str) -> None:
    rd = rolling_direction(log(name).runs[0])
    assert rd["theta_rate"] > 1.5 and rd["phi_rate"] > 1.5  # same sign: ours, no flip
    assert rd["phi_rate"] == pytest.approx(rd["theta_rate"], rel=0.02)
    assert rd["increment_correlation"] > 0.4


@pytest.mark.parametrize("name", ROLLING)
def test_camera_radius_follows_nominal_offset_curve(name: str) -> None:
    fit = ball_radius_fit(log(name).runs[0])
    # x, y are world coordinates: the radius traces |p| of the frame angle with theta's
    # zero aligned to ours (offset < 0.04 rad mod pi) ...
    assert abs(fit.theta_offset) < 0.06 and abs(fit.theta_offset_with_camera) < 0.01
    # ... about 5 mm larger than nominal; a camera-origin offset of a few mm explains most
    assert 0.003 < fit.mean_nominal < 0.007 and fit.rms_nominal < 0.007
    assert fit.rms_with_offset < 0.0016
    assert np.hypot(fit.cx, fit.cy) < 0.009
    # the waist (frame angle 0) and wing (pi/2) radii bracket the nominal ones
    waist = next(b for b in fit.binned if b[0] < 0.3)
    wing = next(b for b in fit.binned if 1.4 < b[0] < 1.5)
    assert waist[1] - waist[2] == pytest.approx(0.005, abs=0.002)
    assert wing[1] - wing[2] == pytest.approx(0.0035, abs=0.002)


@pytest.mark.parametrize("name", ROLLING)
def test_camera_and_loop_rates(name: str) -> None:
    st = fix_statistics(log(name).runs[0])
    assert st["camera_rate"] == pytest.approx(165.0, abs=0.2)
    assert 915.0 < st["loop_rate_mean"] < 928.0
    assert st["fix_interval_max"] < 0.012
    # start-up backlog: ~4 s of frames queued since program start, replayed at loop rate
    assert 750 < st["backlog_fixes"] < 850
    assert st["backlog_end_t"] < 5.1


@pytest.mark.parametrize("name", ["Actually_worked", "step_response_tau_001"])
def test_dtheta_is_theta_derivative_delayed_about_6ms(name: str) -> None:
    run = log(name).runs[0]
    dd = derivative_delay(run.column("t"), run.column("theta"), run.column("dtheta"))
    assert 0.0055 < dd["delay"] < 0.0075
    assert dd["gain"] == pytest.approx(1.0, abs=0.002)


def test_no_ball_frame_fit() -> None:
    nb = frame_fit_no_ball(log("step_response_tau_001").runs, log("friction_v_ref_1").runs[0])
    assert nb.runs == 6 and nb.torque_sign == 1
    assert nb.accel0 == pytest.approx(9.2, abs=0.3) and nb.accel0_std < 0.2
    assert nb.decay == pytest.approx(0.066, abs=0.006)
    assert nb.hold_speed == pytest.approx(1.0, abs=0.01)
    assert nb.hold_torque == pytest.approx(1.98e-3, abs=0.1e-3)
    assert 0.8e-3 < nb.inertia < 0.96e-3  # J/k, against the nominal J_f = 1.58e-3
    assert 1.7e-3 < nb.coulomb < 2.1e-3
    assert 4e-5 < nb.viscous < 7.5e-5
