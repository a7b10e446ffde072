"""Tests of ``bfr limits``: the draw, the statistics, the peer, a run on a LocalCluster.

The full run (1000 cases, hours on two cores) is the measurement and is not repeated here;
these tests check that its parts do what the report claims, and run a handful of cases
end to end on a Dask LocalCluster (two workers), resuming, then the report.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from bfr_diagnose.blindtest import CONTACT_EFFECTS
from bfr_diagnose.effects import (
    BALL_INERTIA_RATIO,
    EFFECT_NAMES,
    effect_size,
    possible_ball_inertia,
)
from bfr_diagnose.limits import cli, peer, stats
from bfr_diagnose.limits.cases import FLOOR, draw_case
from bfr_diagnose.limits.runner import done_indices, run_cases
from bfr_model.params import load_params


def test_draw_reproducible_case_by_case_with_the_sizes_it_claims() -> None:
    base = load_params()
    cases = [draw_case(1, i, base) for i in range(200)]
    kinds = [c.kind for c in cases]
    assert kinds.count("clean") == 50                 # a quarter of any run is clean
    assert kinds.count("pair") >= 40 and kinds.count("triple") >= 15
    gens = [c.generator for c in cases]
    assert 25 <= gens.count("contact") <= 75          # about a quarter
    assert {c.sensors.writer for c in cases} == {"rig_log", "bag"}
    assert len({c.orbit_speed for c in cases if c.generator == "rigid"}) == 3
    assert len({c.gain_scale for c in cases if c.generator == "rigid"}) == 3
    assert min(c.camera_noise for c in cases) >= 5e-5
    assert max(c.camera_noise for c in cases) <= 3e-4
    xs = []
    for c in cases:
        assert len(set(c.effects)) == len(c.effects)
        if c.generator == "contact":
            assert set(c.effects) <= set(CONTACT_EFFECTS)
        for e, s in zip(c.effects, c.sizes, strict=True):
            x = math.log10(s / FLOOR[e])
            assert -1.0 <= x <= 1.0
            xs.append(x)
            # the diagnosis's own size of the true values is the drawn size
            assert effect_size(e, np.array(c.truth[e]), base) == pytest.approx(s, rel=1e-9)
    # log-uniform: about as many sizes in each half decade
    counts = np.histogram(xs, bins=4, range=(-1, 1))[0]
    assert counts.min() > 0.6 * counts.mean()
    assert {e for c in cases for e in c.effects} == set(EFFECT_NAMES)
    # a case does not depend on the run's length or on the others
    again = draw_case(1, 137, base)
    assert again == cases[137]
    assert draw_case(2, 137, base) != cases[137]


def test_ball_inertia_drawn_as_a_real_ball_can_be() -> None:
    """No draw is a ball with more inertia than a thin shell of its mass and radius."""
    base = load_params()
    mr2 = base.ball.mass * base.ball.radius ** 2
    lo, hi = BALL_INERTIA_RATIO
    assert hi == pytest.approx(2.0 / 3.0)
    # the seed's ball is (nearly) a thin shell: a heavier inertia is mirrored to a lighter one
    assert possible_ball_inertia(base, 0.1) == pytest.approx(base.ball.inertia * 0.9)
    assert possible_ball_inertia(base, -0.1) == pytest.approx(base.ball.inertia * 0.9)
    assert possible_ball_inertia(base, 0.001) == pytest.approx(base.ball.inertia * 1.001)
    assert possible_ball_inertia(base, 0.9) == pytest.approx(hi * mr2)   # neither: clipped
    # a ball halfway between solid and shell takes either sign as drawn
    mid = base.replace(**{"ball.inertia": 0.5 * mr2})
    assert possible_ball_inertia(mid, 0.1) == pytest.approx(0.55 * mr2)
    assert possible_ball_inertia(mid, -0.1) == pytest.approx(0.45 * mr2)
    ratios = [c.truth["ball_inertia"][0] / mr2 for c in (draw_case(1, i, base)
                                                          for i in range(400))
              if "ball_inertia" in c.effects]
    assert len(ratios) > 10
    assert all(lo - 1e-12 <= r <= hi + 1e-12 for r in ratios)
    assert min(ratios) < 0.6                     # large changes are drawn, as lighter shells


def test_wilson_interval_known_values() -> None:
    lo, hi = stats.wilson(0, 200)
    assert lo == pytest.approx(0.0, abs=1e-12)
    assert hi == pytest.approx(0.01884, abs=2e-5)   # 3.84 / 203.84
    lo, hi = stats.wilson(50, 100)
    assert lo == pytest.approx(0.4038, abs=1e-4) and hi == pytest.approx(0.5962, abs=1e-4)
    assert all(math.isnan(v) for v in stats.wilson(0, 0))


def test_newcombe_difference_interval_published_values() -> None:
    # Newcombe (1998), Statistics in Medicine 17:873, Table II, method 10 (hybrid score)
    for (k1, n1, k0, n0), (lo, hi) in [((56, 70, 48, 80), (0.0524, 0.3339)),
                                       ((9, 10, 3, 10), (0.1705, 0.8090)),
                                       ((6, 7, 2, 7), (0.0582, 0.8062)),
                                       ((5, 56, 0, 29), (-0.0381, 0.1926))]:
        d, a, b = stats.newcombe_difference(k1, n1, k0, n0)
        assert d == pytest.approx(k1 / n1 - k0 / n0)
        assert (a, b) == (pytest.approx(lo, abs=6e-5), pytest.approx(hi, abs=6e-5))
    # a tool naming a mechanism on every case has J = 0, whatever it "finds"
    d, a, b = stats.newcombe_difference(40, 40, 120, 120)
    assert d == 0.0 and a < 0.0 < b
    assert all(math.isnan(v) for v in stats.newcombe_difference(1, 0, 1, 2))


def test_logistic_fit_recovers_a_known_curve_and_its_sizes() -> None:
    rng = np.random.default_rng(4)
    a, b = 1.0, 5.0                       # 50 % at x = -0.2, 90 % at x = (ln 9 - 1) / 5
    x = rng.uniform(-1.0, 1.0, 4000)
    hit = rng.random(x.size) < 1.0 / (1.0 + np.exp(-(a + b * x)))
    fa, fb = stats.logistic_fit(x, hit.astype(float))
    assert fa == pytest.approx(a, abs=0.15) and fb == pytest.approx(b, abs=0.5)
    # the bootstrap intervals cover the true sizes about as often as they claim (95 %)
    x50, x90 = -a / b, (math.log(9.0) - a) / b
    cover = {"x50": 0, "x90": 0}
    runs = 30
    for k in range(runs):
        xs = x[k * 120:(k + 1) * 120]
        hs = hit[k * 120:(k + 1) * 120]
        cur = stats.detection_curve(xs, hs, 60, np.random.default_rng(k))
        assert cur["x50_lo"] <= cur["x50"] <= cur["x50_hi"]
        cover["x50"] += cur["x50_lo"] <= x50 <= cur["x50_hi"]
        cover["x90"] += cur["x90_lo"] <= x90 <= cur["x90_hi"]
    assert cover["x50"] >= 0.8 * runs and cover["x90"] >= 0.8 * runs


def test_peer_threshold_by_held_out_error_keeps_the_true_terms() -> None:
    rng = np.random.default_rng(2)
    n = 1500
    t = np.linspace(0.0, 10.0, n)
    X = np.column_stack([np.ones(n), np.sin(3 * t), np.cos(5 * t), t / 10, np.sin(7 * t + 1),
                         rng.standard_normal(n)])
    y = 0.3 * X[:, 1] - 0.2 * X[:, 3] + 0.02 * rng.standard_normal(n)
    coef, lam = peer.sparse_fit(X, y)
    assert set(np.nonzero(coef)[0]) == {1, 3}
    assert coef[1] == pytest.approx(0.3, rel=0.05) and coef[3] == pytest.approx(-0.2, rel=0.05)
    assert peer.THRESHOLDS[0] <= lam <= peer.THRESHOLDS[-1]
    # the mapping was fixed for every term of the library, and names only library effects
    assert set(peer.MAPPING) == {(r, t) for r, terms in peer.LIBRARY.items() for t in terms}
    assert {m for m in peer.MAPPING.values() if m} <= set(EFFECT_NAMES)


def test_bad_input_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["run", "--out", str(tmp_path / "r"), "--duration", "3"]) == 2
    assert cli.main(["report", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("bfr limits: error:") for e in err)
    assert not (tmp_path / "r").exists()


def test_cases_on_a_local_cluster_resume_and_report(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # seed 31: case 0 clean on the rigid truth, case 1 a viscous friction of 0.14 F on the
    # contact model (another model structure), both written as bags
    figs = run_cases(31, [0, 1], out, 8.0, workers=2, progress=False)
    assert figs["ran"] == 2 and figs["workers"] == 2
    assert done_indices(out) == {0, 1}
    rows = stats.load_records(out)
    base = load_params()
    for r in rows:
        c = draw_case(31, r["index"], base)
        assert r["effects"] == ";".join(c.effects) and r["generator"] == c.generator
        assert r["status"] == "ok", r["status"]
        for tool in ("bfr", "peer"):
            found = [e for e in r[f"{tool}_found"].split(";") if e]
            assert r[f"{tool}_exact"] == (set(found) == set(c.effects))
    # a rerun finds both on disk and runs nothing
    assert run_cases(31, [0, 1], out, 8.0, workers=2, progress=False)["ran"] == 0
    assert cli.main(["report", str(out), "--bootstrap", "20"]) == 0
    for name in ("table.csv", "summary.json", "report.md", "detection.png", "confusion.png"):
        assert (out / name).is_file(), name
    summ = json.loads((out / "summary.json").read_text())
    assert summ["scored"] == 2 and summ["records"] == 2
    assert "| false positives on clean cases |" in (out / "report.md").read_text()


def test_all_found_beyond_chance_discounts_a_tool_that_names_everything() -> None:
    """A tool that names every mechanism on every case finds every pair, and has J = 0; a
    tool that names exactly the truth has J = 1; one that finds the pair half the time and
    names it on no clean case has J = 0.5 (its interval about it)."""
    rng = np.random.default_rng(0)
    pairs = [{"effects": "ball_mass;frame_inertia"}, {"effects": "track_bumps;torque_gain"}]
    clean = [{"effects": ""} for _ in range(20)]
    everything = ";".join(EFFECT_NAMES)
    for r in [*pairs, *clean]:
        r["peer_found"] = everything
        r["bfr_found"] = r["effects"]
    assert stats._all_found_beyond_chance(pairs, clean, "peer", 50, rng)["rate"] == 0.0
    assert stats._all_found_beyond_chance(pairs, clean, "bfr", 50, rng)["rate"] == 1.0
    half = [dict(p, bfr_found=p["effects"] if i % 2 else "") for i, p in
            enumerate(pairs * 10)]
    j = stats._all_found_beyond_chance(half, clean, "bfr", 200, rng)
    assert j["rate"] == pytest.approx(0.5) and j["lo"] < 0.5 < j["hi"]
