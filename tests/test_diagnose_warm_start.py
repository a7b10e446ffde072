"""The equation error does not depend on what was evaluated before it.

:meth:`bfr_diagnose.residual.ResidualEvaluator.evaluate` solves the contact angle of every
sample by Newton's method from the last evaluation's solution moved by the change of the
ball's measured angle (a warm start: a fit's next evaluation is a small step from the last
one), and :class:`bfr_diagnose.identify.Problem`
keeps the physics of recent effect values. Both are speed-ups only: an evaluator that has
seen other parameter sets, sensor models and a fitted contour first must give the same
rows as a fresh one, to the Newton tolerance (1e-11 rad of the contact angle).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from bfr_diagnose.effects import EFFECTS
from bfr_diagnose.identify import Part, Problem
from bfr_diagnose.preprocess import SensorCorrection, prepare
from bfr_diagnose.residual import (
    TAYLOR_STEP,
    ResidualConfig,
    ResidualEvaluator,
    _sample_terms,
    pointwise_terms,
)
from bfr_diagnose.synth import SynthConfig, stabilised_recording
from bfr_model.dynamics import RigidModel
from bfr_model.params import RigParams


@pytest.fixture(scope="module")
def prep():  # noqa: ANN201 - a Prepared
    base = RigParams()
    rec = stabilised_recording(base, base, SynthConfig(duration=4.0), np.random.default_rng(3))
    assert rec.meta["ball_rolled"]
    return prepare(rec)


def _rows(ev: ResidualEvaluator, params: RigParams, sensor: SensorCorrection) -> np.ndarray:
    return np.vstack(ev.evaluate(params, sensor).rows[:3])


def test_rows_do_not_depend_on_the_evaluations_before(prep) -> None:  # noqa: ANN001
    base = RigParams()
    # a contour 2 mm off in cos 4 phi and 1.5 mm in cos 6 phi (fin's order of size), a
    # latency and a camera offset beside it
    shaped = base.replace(**{"frame.contour.harmonic_orders": [4.0, 6.0],
                             "frame.contour.harmonic_cos": [-2e-3, 1.5e-3],
                             "frame.contour.harmonic_sin": [0.0, 0.0]})
    sensor = SensorCorrection(latency=2e-3, offset_x=1e-3, scale=1.01)
    fresh = _rows(ResidualEvaluator(prep), shaped, sensor)
    ev = ResidualEvaluator(prep)
    _rows(ev, base, SensorCorrection())               # history: the nominal model first,
    _rows(ev, shaped, SensorCorrection(latency=-5e-3))  # then another sensor model
    warm = _rows(ev, shaped, sensor)
    ok = np.isfinite(fresh)
    assert ok.sum() > 100 and np.array_equal(ok, np.isfinite(warm))
    for r in range(3):
        scale = np.max(np.abs(fresh[r][ok[r]]))
        assert np.max(np.abs(warm[r][ok[r]] - fresh[r][ok[r]])) <= 1e-8 * scale
    # and the contour does move the contact angle (by up to 6.7 mrad here): the evaluator's
    # Newton starts from another solution than the one it must find
    phi0 = ResidualEvaluator(prep).evaluate(base).phi
    phi1 = ResidualEvaluator(prep).evaluate(shaped).phi
    assert np.nanmax(np.abs(phi1 - phi0)) > 0.005


def test_kept_physics_is_the_physics_of_the_values(prep) -> None:  # noqa: ANN001
    """The problem's kept parameter sets: the same values give the same rows, other values
    other rows (the key is the values, not the effect's name)."""
    base = RigParams()
    part = Part.of("rec", ResidualEvaluator(prep), 0.5, ("latency", "theta_zero"))
    prob = Problem([part], base)
    shape = EFFECTS["frame_contour"]
    s0 = np.zeros(len(part.sensor_names))
    a = prob.part_weighted(0, [(shape, np.array([0.1105, 0.040]))], s0)
    b = prob.part_weighted(0, [(shape, np.array([0.1085, 0.040]))], s0)
    a2 = prob.part_weighted(0, [(shape, np.array([0.1105, 0.040]))], s0)
    # the same to the Newton tolerance (a2's contact angles start from b's, a's from psi)
    ok = np.isfinite(a)
    assert np.array_equal(ok, np.isfinite(a2))
    assert np.max(np.abs(a2[ok] - a[ok])) <= 1e-8 * np.max(np.abs(a[ok]))
    assert np.max(np.abs(b[ok] - a[ok])) > 1e-3 * np.max(np.abs(a[ok]))


def _kernel_inputs(prep, params: RigParams) -> tuple:  # noqa: ANN001
    """The arguments of :func:`pointwise_terms` for ``params`` at the nominal camera."""
    ev = ResidualEvaluator(prep)
    phi = ev.evaluate(params).phi
    sel = ev._sel
    th = prep.theta[sel]
    psi_w, psi_wd, _ = prep.ball_for(None, at=sel)
    model = RigidModel(params)
    return (th, prep.theta_dot[sel], prep.theta_ddot[sel], th + psi_w,
            prep.theta_dot[sel] + psi_wd), phi[sel], model.kernel_args


@pytest.mark.parametrize("ellipticity", [0.0, 4e-4])
def test_the_parallel_loop_is_the_loop_of_its_samples(prep, ellipticity: float) -> None:  # noqa: ANN001
    """Every sample of the parallel kernel is exactly :func:`_sample_terms` of that sample
    alone (a loop-carried local in a parallel loop body once mixed the samples' normal
    forces and distances up: 60 % off, while the momenta were right)."""
    params = RigParams().replace(**{"frame.contour.harmonic_orders": (3, 8),
                                    "frame.contour.harmonic_cos": (1e-3, 1e-4),
                                    "frame.contour.harmonic_sin": (-5e-4, 2e-4),
                                    "ball.ellipticity": ellipticity})
    data, phi, kargs = _kernel_inputs(prep, params)
    guess = phi + 3e-3 * np.sin(np.arange(phi.size))  # Newton steps of every size
    out = np.array(pointwise_terms(*data, guess, *kargs))
    one = np.array([_sample_terms(*(d[i] for d in data), guess[i], *kargs)
                    for i in range(phi.size)]).T
    assert np.array_equal(out, one)


def test_the_last_small_step_moves_the_terms_as_an_evaluation_would(prep) -> None:  # noqa: ANN001
    """Newton's last step below ``TAYLOR_STEP`` moves the curve's terms by their Taylor
    series instead of evaluating the curve again: the nine outputs agree with Newton from
    the solution itself (no step) to 3e-10 of each output's scale, on an 8th harmonic (the
    Newton tolerance's own 1e-11 rad moves the ball row by 1e-10; without the third
    derivative in the series p'' would be 1e-5 off)."""
    params = RigParams().replace(**{"frame.contour.harmonic_orders": (4, 8),
                                    "frame.contour.harmonic_cos": (-2e-3, 1e-4),
                                    "frame.contour.harmonic_sin": (0.0, -1e-4)})
    data, phi, kargs = _kernel_inputs(prep, params)
    exact = np.array(pointwise_terms(*data, phi, *kargs))
    for off in (0.9 * TAYLOR_STEP, -0.5 * TAYLOR_STEP, 1e-8):
        moved = np.array(pointwise_terms(*data, phi + off, *kargs))
        scale = np.max(np.abs(exact), axis=1, keepdims=True)
        assert np.all(np.abs(moved - exact) <= 3e-10 * scale), (off, np.max(
            np.abs(moved - exact) / scale, axis=1))


@pytest.mark.parametrize(("stride", "quad_step", "half_width"),
                         [(6, 2, 0.2), (4, 2, 0.2), (2, 2, 0.2), (5, 1, 0.2), (7, 1, 0.2),
                          (14, 2, 0.004)])
def test_the_kernel_sums_by_phases_are_the_direct_sums(prep, stride: int,  # noqa: ANN001
                                                       quad_step: int,
                                                       half_width: float) -> None:
    """:meth:`ResidualEvaluator._conv` splits each kernel sum into the outputs' step of
    phases (polyphase decimation); the kept outputs are the direct convolution's, to the
    rounding of the sums' order, for steps of 1, 2, 3, 5 and 7 nodes, both kernels, outputs
    dropped where the ball was not seen, and a step longer than the kernel (7 nodes, 5
    weights)."""
    usable = prep.usable.copy()
    usable[prep.n // 3:prep.n // 3 + 200] = False  # a gap: outputs near it are not kept
    gapped = dataclasses.replace(prep, ball_ok=usable & prep.ball_ok)
    ev = ResidualEvaluator(gapped, ResidualConfig(stride=stride, quad_step=quad_step,
                                                  half_width=half_width))
    assert ev._step == max(round(stride / quad_step), 1)
    assert 0 < ev._kept.size < ev._n_out
    x = np.random.default_rng(stride).standard_normal(ev._grid.size)
    for kern in (ev.k, ev.kd):
        direct = np.convolve(x, kern, mode="valid")[ev._idx_s - ev.J]
        assert direct.size > 100
        assert np.allclose(ev._conv(x, kern), direct, rtol=0.0,
                           atol=1e-13 * np.max(np.abs(direct)))
