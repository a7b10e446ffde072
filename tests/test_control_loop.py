"""Closed loop in simulation: orbital stabilisation, estimator and supervisor (bfr_control)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_control.controller import (
    BALL_LOST,
    ROLLING,
    WAITING,
    OrbitalController,
)
from bfr_control.estimator import BallObservation
from bfr_model.params import load_params
from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop

NOMINAL = load_params()


# (phase [rad], perturbation): frame off by a few degrees, ball displaced along the orbit,
# ball's speed off the orbit (across) together with the frame.
STARTS = [
    (0.3, {"d_theta": 0.05}),
    (1.2, {"d_phi": 0.05}),
    (2.5, {"d_phi_dot": -0.3, "d_theta": -0.035}),
]


@pytest.mark.parametrize(("seed", "start"), list(enumerate(STARTS)))
def test_closed_loop_keeps_rolling_for_60_s(controller: OrbitalController, seed: int,
                                            start: tuple) -> None:
    """60 s from a perturbed state, camera at 200 Hz, 5 ms late, 0.1 mm noise."""
    phase, pert = start
    x0 = orbit_initial_state(controller, phase, **pert)
    res = run_closed_loop(controller, NOMINAL, 60.0, x0, SensorConfig(), seed=seed)
    s = res.summary()
    assert s["ball_rolling"], s
    assert s["rolling_until"] == pytest.approx(60.0)
    assert np.all(res.x[:, 3] > 0.5)
    assert np.all(res.mode[res.t > 0.1] == 1)  # ROLLING from the 4th camera fix on
    # transverse coordinates converge to a small bound (last 30 s)
    tail = res.t >= 30.0
    tr = res.transverse[tail]
    assert np.max(np.abs(tr[:, 1])) < 0.01  # |y| [rad]
    assert np.max(np.abs(tr[:, 3])) < 0.15  # |z| [rad/s]
    assert s["rms_y"] < 0.003 and s["rms_z"] < 0.05
    head = res.transverse[res.t < 0.5]
    assert np.max(np.abs(head[:, 1])) > 3.0 * np.max(np.abs(tr[:, 1]))
    assert s["mean_phi_dot"] == pytest.approx(controller.orbit.mean_phi_dot, rel=0.02)
    assert s["saturation_fraction"] < 0.05


def test_estimator_compensates_the_camera_latency(controller: OrbitalController) -> None:
    """Noise-free camera 8 ms late: the estimate at the present is exact to ~1e-6."""
    x0 = orbit_initial_state(controller, 0.9, d_theta=0.02)
    res = run_closed_loop(controller, NOMINAL, 2.0, x0,
                          SensorConfig(camera_noise=0.0, camera_latency=0.008), seed=0)
    on = res.mode == 1
    assert np.max(np.abs(res.phi_hat[on] - res.x[on, 1])) < 1e-6
    assert np.max(np.abs(res.phi_dot_hat[on] - res.x[on, 3])) < 1e-3


def test_no_ball_means_waiting_and_no_torque(controller: OrbitalController) -> None:
    controller.reset()
    for k in range(300):
        t = k * 1e-3
        obs = BallObservation(t, 0.0, 0.0, valid=False) if k % 5 == 0 else None
        cmd = controller.step(t, 0.1 * t, 0.1, obs)
        assert cmd.mode == WAITING
        assert cmd.torque == 0.0
        assert cmd.reason
    assert not controller.estimator.initialized


def test_ball_lost_mid_run_zeroes_the_torque(controller: OrbitalController) -> None:
    x0 = orbit_initial_state(controller, 0.5)
    res = run_closed_loop(controller, NOMINAL, 3.0, x0,
                          SensorConfig(camera_blackouts=((1.5, 10.0),)), seed=1)
    lost = res.mode == 2
    assert lost.any()
    t_lost = res.t[np.argmax(lost)]
    timeout = controller.config.supervisor.lost_timeout
    assert 1.5 + timeout - 0.01 <= t_lost <= 1.5 + timeout + 0.02
    assert np.all(lost[res.t >= t_lost])  # latched
    assert np.all(res.u[lost] == 0.0)
    assert np.all(res.mode[(res.t > 0.1) & (res.t < 1.5)] == 1)
    assert "no valid ball fix" in res.summary()["lost_reason"]
    # a node's fault recovery resets with keep_lost: the latch and its reason stay; the
    # operator's reset (keep_lost False) re-arms
    reason, at = controller.reason, controller.lost_at
    controller.reset(keep_lost=True)
    assert (controller.mode, controller.reason, controller.lost_at) == (BALL_LOST, reason, at)
    assert not controller.estimator.initialized
    controller.reset()
    assert controller.mode == WAITING and controller.lost_at is None


def test_bad_frames_are_survived(controller: OrbitalController) -> None:
    """30 % invalid frames: the estimator runs on the model between fixes, the ball rolls."""
    x0 = orbit_initial_state(controller, 2.0, d_theta=0.02)
    res = run_closed_loop(controller, NOMINAL, 10.0, x0, SensorConfig(camera_dropout=0.3),
                          seed=4)
    s = res.summary()
    assert s["ball_rolling"] and s["rms_z"] < 0.1
    assert 0.6 < s["camera_valid_fraction"] < 0.8


def test_nan_stale_and_future_frames_are_ignored(controller: OrbitalController) -> None:
    controller.reset()
    orbit = controller.orbit
    model = controller.model
    # feed a few good fixes of a ball on the orbit (frame static at the orbit's theta)
    x = orbit.state(0.4)
    ball = model.ball_position(x)
    for k in range(6):
        t = 0.005 * k
        cmd = controller.step(t, x[0], x[2], BallObservation(t, ball[0], ball[1]))
    assert controller.estimator.frames == 6
    t = 0.03
    cmd = controller.step(t, x[0], x[2], BallObservation(t, math.nan, ball[1]))
    assert not cmd.new_fix and math.isfinite(cmd.phi)
    cmd = controller.step(t + 0.001, x[0], x[2], BallObservation(0.025, ball[0], ball[1]))
    assert not cmd.new_fix  # stale: not newer than the last fix
    cmd = controller.step(t + 0.002, x[0], x[2], BallObservation(t + 1.0, ball[0], ball[1]))
    assert not cmd.new_fix  # stamped in the future
    cmd = controller.step(t + 0.003, math.nan, x[2], None)
    assert cmd.torque == 0.0
    assert controller.estimator.frames == 6
    assert cmd.mode in (WAITING, ROLLING, BALL_LOST)


def test_warm_up_rolls_and_leaves_the_controller_fresh(controller: OrbitalController) -> None:
    """The node's warm-up runs the rolling path (pick-up, prediction, PFL), not only the
    acquisition: a warm-up whose ball never rolled left the first rolling step of a real run
    to load those kernels (25 ms here, 45-48 ms in the composed loop process)."""
    assert controller.warm_up() >= 4
    assert controller.mode == WAITING and not controller.estimator.initialized
    assert controller.last_torque == 0.0


def test_warm_up_loads_the_rolling_kernels_in_a_fresh_process() -> None:
    """In a process of its own (the node's), the kernels the rolling steps call are loaded
    by the warm-up: none before it, each after."""
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415

    code = (
        "from bfr_control.controller import OrbitalController\n"
        "from bfr_control.transverse import pfl_kernel\n"
        "from bfr_model.dynamics import rigid_rk4_steps\n"
        "from bfr_model.params import load_params\n"
        "c = OrbitalController(load_params())\n"
        "kernels = (pfl_kernel, rigid_rk4_steps)\n"
        "print([len(k.signatures) for k in kernels])\n"
        "c.warm_up()\n"
        "print([len(k.signatures) for k in kernels])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, check=True).stdout.split("\n")
    assert out[0] == "[0, 0]" and out[1] == "[1, 1]", out
