"""Tests of ``bfr blindtest``: the case draw, the scoring, and a short run end to end.

The full default run (20 cases, ~1 min on two cores) is the acceptance proof and is not
repeated here; these tests check that its parts do what the table claims.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_diagnose.effects import EFFECT_NAMES
from bfr_model.params import load_params

from bfr_diagnose import blindtest as bt


def test_draw_covers_every_effect_pairs_and_clean_controls() -> None:
    base = load_params()
    cases = bt.draw_cases(1, 20, base)
    singles = [c.effects[0] for c in cases if c.kind == "single"]
    assert sorted(singles) == sorted(EFFECT_NAMES)
    assert sum(c.kind == "pair" for c in cases) == 4
    assert sum(c.kind == "clean" for c in cases) == 4
    # same seed, same cases; magnitudes are drawn inside the documented ranges
    again = bt.draw_cases(1, 20, base)
    assert [(c.kind, c.effects, c.seed) for c in cases] == [(c.kind, c.effects, c.seed)
                                                              for c in again]
    for c in cases:
        m = bt._materialise(c, base, 1.0)
        assert set(m.truth) == set(c.effects)
        if "camera_offset" in c.effects:
            assert 2e-3 <= math.hypot(*m.camera_offset) <= 7e-3


def test_small_draws_keep_a_clean_control() -> None:
    cases = bt.draw_cases(3, 2, load_params())
    assert len(cases) == 2 and cases[0].kind == "clean"


def _result(kind: str, truth: list[str], found: list[str], err: float = 0.05,
            impr: float = 3.0) -> dict:
    return {"kind": kind, "truth": truth, "found": found,
            "param_errors": {e: err for e in truth if e in found},
            "improvement_located": impr, "improvement_whole": impr}


def test_score_counts_what_the_table_says() -> None:
    res = [_result("single", ["ball_mass"], ["ball_mass"], 0.1, 4.0),
           _result("single", ["rolling_resistance"], ["camera_latency"], 0.0, 1.5),
           _result("pair", ["ball_mass", "camera_offset"], ["camera_offset", "ball_mass"],
                   0.02, 10.0),
           _result("clean", [], [], impr=1.0),
           _result("clean", [], ["track_bumps"], impr=1.0)]
    sc = bt.score(res)
    assert sc["top1_accuracy"] == pytest.approx(2 / 3)
    assert sc["clean_false_positives"] == 1
    assert sc["clean_false_positive_rate"] == pytest.approx(0.5)
    assert sc["halved_fraction"] == pytest.approx(2 / 3)
    assert sc["confusion"]["rolling_resistance"]["camera_latency"] == 1
    assert sc["confusion"]["clean"]["none"] == 1 and sc["confusion"]["clean"]["track_bumps"] == 1
    # parameter errors only of the effects found
    assert sc["median_param_error"] == pytest.approx(np.median([0.1, 0.02, 0.02]))


def test_parameter_error_of_vector_effects() -> None:
    base = load_params()
    err = bt._param_error("camera_offset", [3e-3, 4e-3], {"c_x": 3e-3, "c_y": 4.5e-3}, base)
    assert err == pytest.approx(0.1)
    err = bt._param_error("track_bumps", [1.0, 5e-4, 0.1],
                          {"phi_b": 1.0 + 2 * np.pi, "h": 5.5e-4, "w": 0.1}, base)
    assert err == pytest.approx(0.1)
    assert bt._param_error("track_bumps", [1.0, 5e-4, 0.1],
                           {"phi_b": 1.5, "h": 5e-4, "w": 0.1}, base) == 1.0


def test_short_run_end_to_end(capsys: pytest.CaptureFixture[str]) -> None:
    """One clean control of 8 s through the harness and diagnose: no false positive."""
    rc = bt.main(["--seed", "5", "--cases", "1", "--duration", "8", "--workers", "1",
                  "--clean-runs", "1"])
    out = capsys.readouterr().out
    assert "clean false positives          0" in out
    assert "top-1 accuracy" in out and "held-out RMSE halved" in out
    assert rc == 0  # the targets without cases are not applicable, the clean one is met


def test_targets_met_ignores_untested_targets() -> None:
    clean_only = bt.score([_result("clean", [], [], impr=1.0)])
    assert bt.targets_met(clean_only)
    fp = bt.score([_result("clean", [], ["ball_mass"], impr=1.0)])
    assert not bt.targets_met(fp)
    miss = bt.score([_result("single", ["ball_mass"], ["ball_mass"], 0.01, 1.5)])
    assert not bt.targets_met(miss)
