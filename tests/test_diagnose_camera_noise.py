"""The camera's noise across and along the ball's path (:func:`fix_noise_path`) and the null's.

A camera fix has two errors: its position (the detector's noise, the same in every
direction) and its time (a fix logged at the next line of a log, not at its exposure), which
moves it along its path by its speed times the error. The per-axis estimate
(:func:`fix_noise`) mixes the two; the null injected that mixture in every direction, so the
ball's distance from the shaft, which the timing barely moves, got the timing's noise:
limits case 719 (a 269 Hz log of a 173 Hz camera with 0.060 mm of noise) read 0.28 mm per
axis, and its rows sat at a tenth of the null's noise. Tested on a closed form (an ellipse
at a known speed, known position noise and time jitter) and on the null's injection.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from bfr_diagnose.null import _levels, noisy_copy
from bfr_diagnose.preprocess import fix_noise, fix_noise_path, path_steps
from bfr_model.recording import Recording

A, B, W = 0.11, 0.06, 9.0   # ellipse semi-axes [m], angular rate [rad/s]
RATE = 200.0                # camera [Hz]


def _fixes(sigma: float, jitter: float, seed: int) -> tuple[np.ndarray, ...]:
    """Fixes of an ellipse at their nominal times; positions at jittered times plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 1.0 / RATE)
    te = t + rng.uniform(-jitter, jitter, t.size)     # when each image was really taken
    x = A * np.sin(W * te) + sigma * rng.standard_normal(t.size)
    y = B * np.cos(W * te) + sigma * rng.standard_normal(t.size)
    return t, x, y


def test_across_is_the_position_noise_along_adds_speed_times_jitter() -> None:
    sigma, jitter = 5e-5, 1.5e-3
    t, x, y = _fixes(sigma, jitter, 1)
    across, along = fix_noise_path(t, x, y, max_gap=0.05)
    # along the path: the position noise and the speed times the time error (uniform: /sqrt 3)
    speed = W * np.sqrt(0.5 * (A ** 2 + B ** 2))      # RMS speed on the ellipse
    want_along = np.hypot(sigma, speed * jitter / np.sqrt(3.0))
    # across: the position noise, a little above it (the neighbours' timing errors lie
    # along their own directions, which the path's curvature turns by up to 2 W / RATE)
    assert sigma <= across <= 1.25 * sigma
    assert along == pytest.approx(want_along, rel=0.2)
    assert along > 4.0 * across
    # the per-axis estimate mixes them: far above the position noise
    assert fix_noise(t, x, y, max_gap=0.05) > 2.5 * sigma
    # without timing errors the two agree with the per-axis one
    t, x, y = _fixes(sigma, 0.0, 2)
    across, along = fix_noise_path(t, x, y, max_gap=0.05)
    assert across == pytest.approx(sigma, rel=0.08)
    assert along == pytest.approx(sigma, rel=0.08)
    assert fix_noise(t, x, y, max_gap=0.05) == pytest.approx(sigma, rel=0.08)


def test_too_few_fixes_are_not_estimated() -> None:
    """Too few fixes, or a ball at rest (no path): not estimated, the per-axis level used."""
    t, x, y = _fixes(5e-5, 0.0, 3)
    assert all(np.isnan(v) for v in fix_noise_path(t[:8], x[:8], y[:8], max_gap=0.05))
    still = np.full(t.size, 0.1)
    assert all(np.isnan(v) for v in fix_noise_path(t, still, still, max_gap=0.05))

    # what null._levels reads of a preprocessed recording
    prep = SimpleNamespace(info={}, noise={"camera": 5e-5, "camera_across": float("nan"),
                                           "camera_along": float("nan"), "theta": 0.0,
                                           "theta_dot": 0.0})
    levels = _levels(prep)
    assert levels["camera_across"] == levels["camera_along"] == 5e-5


def test_null_injects_each_component_in_its_direction() -> None:
    """Along-only noise moves each fix along its path; across-only noise normal to it.

    The path's direction is the ellipse's exact tangent (not a difference stencil), and the
    estimate's stencil (:func:`path_steps`, which the injection shares) lies along it.
    """
    t, x, y = _fixes(0.0, 0.0, 4)
    n = t.size
    rec = Recording(t=t, theta=np.zeros(n), theta_dot=np.zeros(n), torque=np.zeros(n),
                    ball_x=x, ball_y=y, ball_valid=np.ones(n, bool), phi=np.zeros(n))
    dx_path, dy_path = A * W * np.cos(W * t), -B * W * np.sin(W * t)
    unit = np.hypot(dx_path, dy_path)
    sx, sy = path_steps(x, y)
    turn = np.arcsin((sy * dx_path - sx * dy_path) / (np.hypot(sx, sy) * unit))
    assert np.max(np.abs(turn[2:-2])) < 0.01  # the stencil's chord against the tangent [rad]
    for across, along in ((0.0, 1e-4), (1e-4, 0.0)):
        noisy = noisy_copy(rec, {"camera": 1.0, "camera_across": across,
                                 "camera_along": along}, np.random.default_rng(5))
        ex, ey = noisy.ball_x - x, noisy.ball_y - y
        par = (ex * dx_path + ey * dy_path) / unit
        perp = (ey * dx_path - ex * dy_path) / unit
        # the other component leaks in by the chord's turn at most (< 1 %)
        assert np.std(par) == pytest.approx(along, rel=0.05, abs=0.01 * across)
        assert np.std(perp) == pytest.approx(across, rel=0.05, abs=0.01 * along)
