"""A frame angle reported within one turn: unwrapped by the readers and the nodes alike.

The formats and the hardware contract carry theta accumulating over turns (docs/hardware.md);
a driver of another rig may report it modulo a turn. Without unwrapping, the readers' angle
gate took each wrap for a jump no hardware makes and kept only the longest stretch between
two wraps, and a controller saw its frame leap a turn.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from bfr_model.io.account import gate_samples
from bfr_model.io.bag import BagWriter, read_bag
from bfr_model.turns import TurnUnwrapper, unwrap_turns

TWO_PI = 2.0 * math.pi


def spinning(n: int = 3000, dt: float = 1e-3, rate: float = 9.0) -> np.ndarray:
    """An accumulating angle turning ``rate`` rad/s with a wobble: several turns."""
    t = np.arange(n) * dt
    return -2.0 + rate * t + 1.5 * np.sin(2.0 * t)


def swinging(n: int = 4000, dt: float = 1e-3) -> np.ndarray:
    """An angle that swings to and fro through +-pi (and 0) with its turning points near
    them: wraps forward and back, and dwelling at the wrap."""
    t = np.arange(n) * dt
    return math.pi + 4.0 * np.sin(2.5 * t) + 0.02 * np.sin(40.0 * t)


@pytest.mark.parametrize("low", [-math.pi, 0.0])
@pytest.mark.parametrize("motion", [spinning, swinging])
def test_a_wrapped_angle_is_the_accumulating_one_again(low: float, motion) -> None:  # noqa: ANN001
    truth = motion()
    wrapped = np.mod(truth - low, TWO_PI) + low  # [-pi, pi) or [0, 2 pi)
    back, at = unwrap_turns(wrapped)
    offset = back[0] - truth[0]  # the turns before the first sample are unknowable
    assert abs(offset / TWO_PI - round(offset / TWO_PI)) < 1e-12
    np.testing.assert_allclose(back - offset, truth, atol=1e-9)
    assert at.size == int(np.count_nonzero(np.abs(np.diff(wrapped)) > math.pi)) >= 3
    # the same with the rate (a sample's step must then be the motion the rate makes)
    t = np.arange(truth.size) * 1e-3
    rate = np.gradient(truth, t)
    with_rate, at_rate = unwrap_turns(wrapped, t, rate)
    np.testing.assert_array_equal(with_rate, back)
    np.testing.assert_array_equal(at_rate, at)
    # the stream version, sample by sample, agrees (without and with the rate)
    for unwrap, args in ((TurnUnwrapper(), lambda k: ()),
                         (TurnUnwrapper(), lambda k: (t[k], rate[k]))):
        np.testing.assert_allclose([unwrap(v, *args(k)) for k, v in enumerate(wrapped)], back,
                                   atol=1e-12)
        assert unwrap.wraps == at.size


def test_what_is_not_a_wrap_is_left_to_the_gates() -> None:
    truth = spinning()
    back, at = unwrap_turns(truth)  # accumulating already: the same array, no wrap
    assert back is truth and at.size == 0
    # a glitch of a whole turn far from zero (no encoder within a turn reports 20 rad)
    glitch = truth + 20.0
    glitch[1500:] += TWO_PI
    assert unwrap_turns(glitch)[1].size == 0
    # within a turn of zero: one bad sample of 0 in an angle near 5.5 rad is no pair of
    # wraps (its rest, 0.78 rad, no motion of a sample), a gap of a turn's motion neither
    near = np.full(200, 5.5) + 1e-3 * np.arange(200)
    near[100] = 0.0
    assert unwrap_turns(near)[1].size == 0
    t = np.arange(200) * 1e-3
    assert unwrap_turns(near, t, np.ones(200))[1].size == 0
    # a spike of half a turn, and NaN gaps, inside a wrapped angle: the wraps still undone
    wrapped = np.mod(truth + math.pi, TWO_PI) - math.pi
    wrapped[700] += math.pi / 2
    wrapped[1200:1210] = np.nan
    back, at = unwrap_turns(wrapped)
    ok = np.isfinite(wrapped)
    ok[700] = False
    d = (back - truth)[ok]
    np.testing.assert_allclose(d, d[0], atol=1e-9)


def test_the_gates_keep_every_sample_of_a_wrapped_encoder() -> None:
    n = 3000
    t = np.arange(n) * 1e-3
    truth = spinning(n)
    wrapped = np.mod(truth + math.pi, TWO_PI) - math.pi
    rate = np.gradient(truth, t)
    g = gate_samples(t, wrapped, rate, np.zeros(n))
    assert g.keep.all() and g.dropped == {} and g.wraps >= 3
    np.testing.assert_allclose(g.theta - g.theta[0], truth - truth[0], atol=1e-9)
    said = g.actions(lambda i: f"sample {i}")
    assert any(a.startswith("theta: reported within one turn; ") for a in said), said


def test_a_bag_of_a_wrapping_driver_reads_accumulating(tmp_path: Path) -> None:
    """joint_states from a driver within a turn and without velocity, as some drivers send:
    the bag reader unwraps the angle (its numerical rate too) and says so."""
    n = 3000
    t = 5.0 + np.arange(n) * 1e-3
    truth = spinning(n)
    wrapped = np.mod(truth + math.pi, TWO_PI) - math.pi
    with BagWriter(tmp_path / "bag", flush_interval=None) as bag:
        T = bag.typestore.types
        header_t, js_t = T["std_msgs/msg/Header"], T["sensor_msgs/msg/JointState"]
        time_t = T["builtin_interfaces/msg/Time"]
        for k in range(n):
            ns = round(t[k] * 1e9)
            msg = js_t(header=header_t(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9),
                                       frame_id=""),
                       name=["frame_joint"], position=np.array([wrapped[k]]),
                       velocity=np.zeros(0), effort=np.zeros(0))
            bag.write("/joint_states", js_t.__msgtype__,
                      bag.typestore.serialize_cdr(msg, js_t.__msgtype__), ns)
    back = read_bag(tmp_path / "bag")
    assert back.t.size == n
    np.testing.assert_allclose(back.theta - back.theta[0], truth - truth[0], atol=1e-9)
    rate = np.gradient(truth, t)
    assert np.max(np.abs(back.theta_dot[1:-1] - rate[1:-1])) < 1e-6
    actions = back.meta["read_account"]["actions"]
    assert any("wrap(s) undone" in a for a in actions), actions


def test_a_rig_log_of_a_wrapping_encoder_reads_accumulating() -> None:
    """The rig log format, from a rig whose software logs theta (and its phi) within a
    turn: every line used, theta accumulating, the rig's phi on its branch (so that its
    estimator counts as initialised and phi_dot stays), the print's resolution of the
    values as logged, the wraps said in the account."""
    from bfr_model.io.rig_log import parse_rig_log_text  # noqa: PLC0415

    n = 3000
    t = 4.0 + np.arange(n) * 1e-3
    truth = spinning(n)
    rate = np.gradient(truth, t)
    psi = 0.3 + 2.4 * (t - t[0])  # the ball's angle on the frame, a new fix every 5 ms
    held = (np.arange(n) // 5) * 5
    x, y = 0.09 * np.sin(psi[held]), 0.09 * np.cos(psi[held])
    phi = truth[held] + np.arctan2(x, y)

    def wrap(a: np.ndarray) -> np.ndarray:
        return np.mod(a + math.pi, TWO_PI) - math.pi

    th_w, phi_w = wrap(truth), wrap(phi)
    text = "\n".join(
        f"[inf] t={t[k]:.6f},torque=0.01,theta={th_w[k]:.9f},phi={phi_w[k]:.9f},"
        f"dtheta={rate[k]:.6f},dphi=2.4,x={x[k]:.9f},y={y[k]:.9f}\r" for k in range(n)) + "\n"
    rec = parse_rig_log_text(text, "wrapping").recording(phi_theta_lag=0)
    assert len(rec) == n
    d = rec.theta - truth
    np.testing.assert_allclose(d, d[0], atol=1e-8)
    late = rec.t > rec.t[0] + 0.5
    assert np.isfinite(rec.phi_dot[late]).mean() > 0.9, rec.meta["conversions"]
    assert rec.meta["theta_resolution"] < 1e-4
    actions = rec.meta["read_account"]["actions"]
    assert any("wrap(s) undone" in a for a in actions), actions
