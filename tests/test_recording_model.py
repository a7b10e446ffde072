"""The Recording data model: validation, helpers, slicing, resampling, from_sim."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from bfr_model.recording import Recording, RecordingError, ball_centre_angle


def make_rec(n: int = 1000, rate: float = 1000.0, cam_every: int = 6, **over: object) -> Recording:
    """Synthetic rig-like recording: 1 kHz loop, a camera fix every ``cam_every`` samples."""
    t = np.arange(n) / rate
    theta = 2.0 * t
    held = (np.arange(n) // cam_every) * cam_every
    bx = 0.1 * np.sin(0.5 * t[held])
    by = 0.1 * np.cos(0.5 * t[held]) + 0.02
    kw: dict[str, object] = dict(
        t=t, theta=theta, theta_dot=np.full(n, 2.0), torque=np.where(t < 0.5, 0.01, -0.01),
        ball_x=bx, ball_y=by, ball_valid=np.ones(n, bool),
        phi=theta[held] + np.arctan2(bx, by), meta={"source": "synthetic"})
    kw.update(over)
    return Recording(**kw)  # type: ignore[arg-type]


def test_valid_recording_basics() -> None:
    rec = make_rec()
    assert len(rec) == 1000
    assert rec.duration == pytest.approx(0.999)
    assert rec.sample_rate() == pytest.approx(1000.0)
    assert rec.camera_fix_rate() == pytest.approx(1000.0 / 6, rel=1e-3)
    assert rec.new_fix_mask().sum() == int(np.ceil(1000 / 6))
    assert rec.meta["conversions"] == [] and rec.meta["notes"] == []
    assert rec.allclose(rec.copy())


def test_invalid_samples_are_normalised_to_nan() -> None:
    valid = np.ones(1000, bool)
    valid[100:200] = False
    rec = make_rec(ball_valid=valid)
    assert np.isnan(rec.ball_x[100:200]).all() and np.isnan(rec.phi[100:200]).all()
    assert np.isfinite(rec.ball_x[:100]).all()
    assert rec.valid_fraction() == pytest.approx(0.9)
    # re-validation after an invalid gap counts the first valid sample as a new fix
    assert rec.new_fix_mask()[200]


@pytest.mark.parametrize(("over", "message"), [
    ({"t": np.array([])}, "empty"),
    ({"theta": np.zeros(999)}, "mismatched lengths: 'theta' has 999"),
    ({"t": np.r_[np.arange(999) / 1000, np.nan]}, "NaN in 't' at sample 999"),
    ({"torque": np.r_[np.zeros(10), np.inf, np.zeros(989)]}, "infinite value in 'torque'"),
    ({"t": np.r_[np.arange(500), np.arange(499, 999)] / 1000}, "t repeats at sample 500"),
    ({"t": np.r_[np.arange(500), np.arange(498, 998)] / 1000}, "t goes backwards"),
    ({"ball_x": np.full(1000, np.nan)}, "marked ball_valid but 'ball_x' is nan"),
    ({"theta": np.zeros((1000, 2))}, "one-dimensional"),
    ({"theta": ["a"] * 1000}, "not numeric"),
])
def test_validation_errors_name_the_problem(over: dict, message: str) -> None:
    if "t" in over and len(over["t"]) == 0:
        with pytest.raises(RecordingError, match=message):
            Recording(t=[], theta=[], theta_dot=[], torque=[], ball_x=[], ball_y=[],
                      ball_valid=[], phi=[])
        return
    with pytest.raises(RecordingError, match=message):
        make_rec(**over)


def test_slice_time() -> None:
    rec = make_rec()
    part = rec.slice_time(0.2, 0.4)
    assert part.t[0] == pytest.approx(0.2) and part.t[-1] == pytest.approx(0.4)
    assert len(part) == 201
    assert "sliced" in part.meta["conversions"][-1]
    assert rec.meta["conversions"] == []  # original untouched
    with pytest.raises(RecordingError, match="holds no sample"):
        rec.slice_time(5.0, 6.0)


def test_resample_holds_torque_and_ball_interpolates_theta() -> None:
    rec = make_rec()
    rs = rec.resample(rate=100.0)
    assert len(rs) == 100
    assert np.allclose(np.diff(rs.t), 0.01)
    assert np.allclose(rs.theta, 2.0 * rs.t)
    # torque switches at 0.5 s: zero-order hold keeps the earlier value up to the switch
    assert rs.torque[rs.t < 0.5].max() == 0.01 and rs.torque[rs.t >= 0.5].min() == -0.01
    # ball held: the value of the latest fix at or before each grid time
    idx = np.searchsorted(rec.t, rs.t, side="right") - 1
    assert np.array_equal(rs.ball_x, rec.ball_x[idx])
    lin = rec.resample(dt=0.0105, ball="linear")
    assert lin.ball_valid.all() and np.isfinite(lin.phi).all()
    assert lin.meta["sample_rate"] == pytest.approx(1 / 0.0105)
    with pytest.raises(RecordingError, match="exactly one"):
        rec.resample()
    with pytest.raises(RecordingError, match="positive"):
        rec.resample(dt=-1.0)


def test_differences_reports_field() -> None:
    a = make_rec()
    b = make_rec(theta=a.theta + 1e-3)
    diff = a.differences(b)
    assert len(diff) == 1 and diff[0].startswith("theta:")
    assert not a.allclose(b)


def test_ball_centre_angle_turn_selection() -> None:
    phi = ball_centre_angle(10.0, 0.0, 1.0, near=10.0 + 2 * np.pi * 3)
    assert phi == pytest.approx(10.0 + 2 * np.pi * 3)


def test_from_sim_uses_contact_angle_as_truth() -> None:
    n = 50
    t = np.linspace(0, 0.049, n)
    theta = 0.1 + t
    phi_c = 0.2 + 2 * t
    # ball centre at world angle (phi_c - theta) + small offset: phi_ball differs from phi_c
    ang = phi_c + 0.01 - theta
    ball = 0.12 * np.c_[np.sin(ang), np.cos(ang)]
    x = np.c_[theta, phi_c + 2 * np.pi * 5, np.ones(n), 2 * np.ones(n), np.zeros(n), np.zeros(n)]
    res = SimpleNamespace(t=t, x=x, u=np.zeros(n), ball=ball, kinetic=np.ones(n),
                          potential=np.zeros(n), info={"method": "rk4"})
    rec = Recording.from_sim(res)
    assert rec.has_truth
    assert np.allclose(rec.phi_true, phi_c + 2 * np.pi * 5)
    assert np.allclose(rec.phi, phi_c + 0.01 + 2 * np.pi * 5)  # same turn as the state
    assert np.allclose(rec.energy, 1.0)
    assert rec.meta["source_kind"] == "simulation"
    assert rec.camera_fix_rate() == pytest.approx(rec.sample_rate(), rel=1e-6)
