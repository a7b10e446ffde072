"""The camera's calibration prior in ``bfr diagnose`` (a MAP term in the least squares).

Closed forms first: a parameter the data do not fix gets back exactly its prior width in the
reported interval (the ``sqrt(tau)`` of the prior rows against the ``tau`` inflation of the
intervals), and one the data fix is the weighted mean of the data's estimate and the prior's
nominal. Then a diagnosis of a synthetic closed-loop recording whose camera is miscalibrated
within a calibration's tolerance: the camera's parameters are recovered, the recording stays
clean, and the report says the prior was used and how far each value moved against it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.effects import CAMERA_PRIOR, SENSOR_PARAMS, SensorParam, sensor_param
from bfr_diagnose.identify import _covariance, _prior_rows
from bfr_diagnose.synth import LogConventions, SynthConfig, stabilised_recording
from bfr_model.params import RigParams


def _rows(names: list[str], tau: float, x0: np.ndarray, scales: np.ndarray):  # noqa: ANN202
    return _prior_rows([CAMERA_PRIOR.get(n) for n in names], names, tau, x0, scales, 0)


def test_prior_widths_are_the_sensor_models_and_valid() -> None:
    priors = {p.name: p.prior for p in SENSOR_PARAMS if p.prior is not None}
    assert priors == CAMERA_PRIOR
    for name, w in priors.items():
        p = sensor_param(name)
        assert p.lower < p.upper and 3.0 * w < (p.upper - p.lower)  # a prior, not a bound
    with pytest.raises(ValueError, match="prior width"):
        SensorParam("x", "m", 1e-3, -1.0, 1.0, "camera", "x", prior=0.0)


@pytest.mark.parametrize("tau", [1.0, 7.0, 40.0])
def test_an_unfixed_parameter_gets_its_prior_width(tau: float) -> None:
    """Data columns with nothing of the scale: its reported sd (cov * tau) is the prior's."""
    rng = np.random.default_rng(4)
    scales = np.array([2e-4, 1e-3])
    prior = _rows(["offset_x", "scale"], tau, np.array([0.0, 1.0]), scales)
    jd = np.column_stack([rng.normal(size=500), np.zeros(500)])  # the data fix offset_x only
    jp = np.zeros((2, 2))
    jp[np.arange(2), prior.cols] = prior.b
    cov = _covariance(np.vstack([jd, jp]), 1.0, scales) * tau
    assert math.sqrt(cov[1, 1]) == pytest.approx(CAMERA_PRIOR["scale"], rel=1e-12)
    # the fixed one: data information sum(jd^2)/tau beside the prior's 1/width^2
    info = np.sum(jd[:, 0] ** 2) / tau / scales[0] ** 2 + 1.0 / CAMERA_PRIOR["offset_x"] ** 2
    assert cov[0, 0] == pytest.approx(1.0 / info, rel=1e-12)


def test_the_map_estimate_is_the_precision_weighted_mean() -> None:
    """One parameter, data saying ``d`` with sd ``s_d``: the optimum of data rows + prior
    row is ``(d / s_d^2 + x0 / w^2) / (1 / s_d^2 + 1 / w^2)`` (a Gaussian's posterior)."""
    tau, w = 9.0, CAMERA_PRIOR["scale"]
    d, n, sig = 1.08, 400, 0.5         # n samples of a measurement of the scale, noise sig
    prior = _rows(["scale"], tau, np.array([1.0]), np.array([1.0]))
    # rows: (x - d) / sig for n samples (correlated over tau), and the prior row
    a = np.concatenate([np.full(n, (1.0 - d) / sig), prior.a])
    b = np.concatenate([np.full(n, 1.0 / sig), prior.b])
    xn = -np.dot(a, b) / np.dot(b, b)
    s_d2 = sig ** 2 * tau / n
    expect = (d / s_d2 + 1.0 / w ** 2) / (1.0 / s_d2 + 1.0 / w ** 2)
    assert 1.0 + xn == pytest.approx(expect, rel=1e-12)
    assert 1.0 < expect < d


def test_no_prior_when_switched_off() -> None:
    prior = _prior_rows([None, None], ["scale", "offset_x"], 5.0, np.array([1.0, 0.0]),
                        np.array([1e-3, 2e-4]), 0)
    assert prior.cols.size == 0 and prior.rows(np.zeros(2)).size == 0


def test_miscalibrated_camera_within_tolerance_is_measured_and_clean() -> None:
    """A clean closed-loop recording through a camera 2 % large, turned 0.02 rad and 3 mm
    off: nothing selected, the camera's parameters recovered, the prior reported."""
    base = RigParams()
    log = LogConventions(camera_scale=1.02, camera_rotation=0.02, camera_offset=(3e-3, -2e-3))
    rec = None
    for k in range(4):
        rec = stabilised_recording(base, base, SynthConfig(duration=10.0, log=log),
                                   np.random.default_rng(21 + 100 * k))
        if rec.meta["ball_rolled"]:
            break
    assert rec is not None and rec.meta["ball_rolled"]
    s = diagnose_recording(rec, base, DiagnoseOptions(max_effects=2, block=1.5)).summary
    assert s["effects"] == [], s["effects"]
    got = {r["name"]: r for r in s["sensor_timing"]}
    assert got["scale"]["value"] == pytest.approx(1.02, abs=0.01)
    assert got["offset_x"]["value"] == pytest.approx(3e-3, abs=1e-3)
    assert got["offset_y"]["value"] == pytest.approx(-2e-3, abs=1e-3)
    for name in CAMERA_PRIOR:
        r = got[name]
        assert r["prior"]["width"] == CAMERA_PRIOR[name]
        assert abs(r["pull"]) < 2.0
        assert 0.0 < r["posterior_over_prior"] < 1.0
    assert any("calibration prior" in n for n in s["notes"])
    assert s["options"]["camera_prior"] == 1.0
