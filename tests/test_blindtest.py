"""Tests of ``bfr blindtest``: the case draw, the scoring, and one case end to end.

The full run (40 cases, several minutes on two cores) is the acceptance proof and is not
repeated here; these tests check that its parts do what the table claims.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.effects import EFFECT_NAMES
from bfr_model.params import load_params

from bfr_diagnose import blindtest as bt


def test_draw_covers_every_effect_pairs_clean_and_contact_cases() -> None:
    base = load_params()
    cases = bt.draw_cases(1, 40, base)
    singles = [c.effects[0] for c in cases if c.kind == "single"]
    assert sorted(singles) == sorted(EFFECT_NAMES)
    assert sum(c.kind == "clean" for c in cases) >= 6
    assert sum(c.kind.startswith("contact") for c in cases) >= 4
    assert sum(c.kind == "pair" for c in cases) >= 10
    assert {c.sensors.writer for c in cases} == {"rig_log", "bag"}
    # every case draws its own sensor conventions, inside the documented ranges
    s = [c.sensors for c in cases]
    assert all(0.0 <= x.velocity_lag <= 0.01 for x in s)
    assert all(abs(x.torque_delay) <= 2e-3 for x in s)
    assert all(150.0 <= x.log_rate <= 1000.0 for x in s)
    assert all(150.0 <= x.camera_rate <= 250.0 for x in s)
    assert len({round(x.log_rate) for x in s}) > 30
    # same seed, same cases; the truth is drawn inside the ranges
    again = bt.draw_cases(1, 40, base)
    assert [(c.kind, c.effects, c.seed, c.sensors) for c in cases] == [
        (c.kind, c.effects, c.seed, c.sensors) for c in again]
    for c in cases:
        m = bt._materialise(c, base, 1.0)
        assert set(m.truth) == set(c.effects)
        if "ball_inertia" in m.truth:   # a ball that can exist: at most a thin shell
            assert m.truth["ball_inertia"][0] <= 2.0 / 3.0 * base.ball.mass * base.ball.radius ** 2
        if c.kind.startswith("contact"):
            assert set(c.effects) <= set(bt.CONTACT_EFFECTS)


def test_small_draws_keep_a_clean_control() -> None:
    cases = bt.draw_cases(3, 2, load_params())
    assert len(cases) == 2 and any(c.kind == "clean" for c in cases)


def _result(kind: str, truth: list[str], found: list[str], err: float = 0.05,
            impr: float = 3.0) -> dict:
    st = {"writer": "rig_log", "camera_latency": 0.01, "log_rate": 500.0,
          "torque_delay": 1e-3, "velocity_lag": 6e-3}
    return {"kind": kind, "truth": truth, "found": found, "exact": set(truth) == set(found),
            "param_errors": {e: err for e in truth if e in found},
            "improvement_located": impr, "improvement_whole": impr, "sensors_true": st,
            "sensors_found": {"camera_latency": 0.0115, "torque_delay": 1.2e-3,
                              "velocity_lag": 6.1e-3}}


def test_score_counts_what_the_table_says() -> None:
    res = [_result("single", ["ball_mass"], ["ball_mass"], 0.1, 4.0),
           _result("single", ["rolling_resistance"], ["ball_inertia"], 0.0, 1.5),
           _result("pair", ["ball_mass", "torque_offset"], ["torque_offset", "ball_mass"],
                   0.02, 10.0),
           _result("single", ["frame_inertia"], ["frame_inertia", "ball_mass"], 0.01, 9.0),
           _result("clean", [], [], impr=1.0),
           _result("clean", [], ["track_bumps"], impr=1.0)]
    sc = bt.score(res)
    assert sc["exact"] == 3 and sc["exact_fraction"] == pytest.approx(0.5)
    assert sc["top1_accuracy"] == pytest.approx(3 / 4)
    assert sc["clean_false_positives"] == 1
    assert sc["clean_false_positive_rate"] == pytest.approx(0.5)
    assert sc["halved_fraction"] == pytest.approx(3 / 4)
    assert sc["confusion"]["rolling_resistance"]["ball_inertia"] == 1
    assert sc["confusion"]["clean"]["none"] == 1 and sc["confusion"]["clean"]["track_bumps"] == 1
    # parameter errors only of the effects found
    assert sc["median_param_error"] == pytest.approx(np.median([0.1, 0.02, 0.02, 0.01]))
    # a rig log times a fix by its first line: the latency plus half a line is expected
    assert sc["sensor_error_median"]["camera_latency"] == pytest.approx(0.0005, abs=1e-9)
    assert sc["sensor_error_median"]["torque_delay"] == pytest.approx(2e-4, abs=1e-9)
    # the velocity's lag: the filter's constant as drawn (the logger is exactly that late)
    assert sc["sensor_error_median"]["velocity_lag"] == pytest.approx(1e-4, abs=1e-9)
    # a record without the drawn lag (an older table) is not scored on it
    old = _result("single", ["ball_mass"], ["ball_mass"])
    del old["sensors_true"]["velocity_lag"]
    assert bt.score([old])["sensor_error_median"]["velocity_lag"] is None
    assert not bt.targets_met(sc)


def test_exact_up_to_confounds_lets_only_a_reported_pair_stand_in() -> None:
    pair = [["plate_distance", "ball_inertia"]]
    # the report said it cannot tell these two apart: the found one stands for the concealed
    assert bt.exact_up_to_confounds(["ball_inertia"], ["plate_distance"], pair)
    assert bt.exact_up_to_confounds(["ball_inertia", "joint_coulomb_friction"],
                                    ["joint_coulomb_friction", "plate_distance"], pair)
    # no reported pair, another pair, an extra effect, or both found: not exact
    assert not bt.exact_up_to_confounds(["ball_inertia"], ["plate_distance"], [])
    assert not bt.exact_up_to_confounds(["ball_inertia"], ["plate_distance"],
                                        [["plate_distance", "ball_mass"]])
    assert not bt.exact_up_to_confounds(["ball_inertia"], ["plate_distance", "ball_mass"],
                                        pair)
    assert not bt.exact_up_to_confounds(["ball_inertia"], ["ball_inertia", "plate_distance"],
                                        pair)
    # a clean case with a confounded pair found is a false positive either way
    assert not bt.exact_up_to_confounds([], ["plate_distance"], pair)
    # one stand-in per concealed effect
    assert not bt.exact_up_to_confounds(["ball_inertia"], ["plate_distance", "ball_mass"],
                                        [*pair, ["ball_mass", "ball_inertia"]])
    res = [{**_result("single", ["ball_inertia"], ["plate_distance"]),
            "exact_up_to_confounds": True},
           _result("single", ["ball_mass"], ["ball_mass"])]
    sc = bt.score(res)
    assert sc["exact"] == 1 and sc["exact_up_to_confounds"] == 2


def test_parameter_error_of_vector_effects() -> None:
    base = load_params()
    err = bt._param_error("frame_imbalance", [3e-4, 4e-4], {"M_x": 3e-4, "M_y": 4.5e-4}, base)
    assert err == pytest.approx(0.1)
    err = bt._param_error("track_bumps", [1.0, 5e-4, 0.1],
                          {"phi_b": 1.0 + 2 * np.pi, "h": 5.5e-4, "w": 0.1}, base)
    assert err == pytest.approx(0.1)
    assert bt._param_error("track_bumps", [1.0, 5e-4, 0.1],
                           {"phi_b": 1.5, "h": 5e-4, "w": 0.1}, base) == 1.0


def test_one_case_end_to_end_through_a_rig_log() -> None:
    """A clean case with its own random sensors: simulated, written as rig-log text, read
    back, diagnosed as a user does; nothing found, the torque timing measured."""
    base = load_params()
    case = next(c for c in bt.draw_cases(7, 12, base) if c.kind == "clean")
    case = bt.Case(index=case.index, kind="clean", effects=[], seed=case.seed,
                   sensors=bt.SensorDraw(**{**case.sensors.__dict__, "writer": "rig_log"}))
    r = bt.run_case((case, None, 8.0, 0.036))
    assert r["exact"] and r["found"] == [], r["verdict"]
    exp = bt.expected_sensors(r["sensors_true"])
    assert abs(r["sensors_found"]["torque_delay"] - exp["torque_delay"]) < 5e-4
    assert abs(r["sensors_found"]["camera_latency"] - exp["camera_latency"]) < 3e-3


def test_targets_met_ignores_untested_targets() -> None:
    clean_only = bt.score([_result("clean", [], [], impr=1.0)])
    assert bt.targets_met(clean_only)
    fp = bt.score([_result("clean", [], ["ball_mass"], impr=1.0)])
    assert not bt.targets_met(fp)
    miss = bt.score([_result("single", ["ball_mass"], ["ball_mass"], 0.5, 1.5)])
    assert not bt.targets_met(miss)


def test_a_bump_beside_a_torque_offset_is_not_taken_for_contour_harmonics(
        tmp_path: Path) -> None:
    """The strongest evidence is added first, not the largest held-out gain.

    Blind case 6 of seed 1 (a 0.79 mm dip 0.15 rad wide and a -0.54 mN m torque offset, a
    bag): at the first stage the fourteen contour harmonics took part of the missing offset's
    residual too and reached a larger held-out gain (0.75) than the bump (0.60), though the
    bump's evidence per parameter was the stronger (dBIC -68 against -63). Chosen by gain,
    the harmonics came first and the bump was then fitted 0.3 rad away with the opposite
    sign; chosen by dBIC the offset and the bump are found, the bump where it is.
    """
    base = load_params()
    sensors = bt.SensorDraw(velocity_lag=8.94e-3, torque_delay=4.25e-4, log_rate=252.6,
                            camera_rate=229.6, camera_latency=0.0208,
                            camera_offset=(-1.67e-3, -1.20e-3), camera_scale=1.012,
                            camera_rotation=-0.0159, theta_turns=90, encoder_counts=0,
                            writer="bag")
    changes = {"actuator.torque_offset": -5.38e-4, "track.bump_phi": (2.2975,),
               "track.bump_height": (-7.89e-4,), "track.bump_width": (0.1485,)}
    case = bt.Case(index=6, kind="pair", effects=["torque_offset", "track_bumps"],
                   seed=917647715, sensors=sensors, changes=changes, truth={})
    runs = bt._write_and_read(bt._simulate(case, base, 12.0), "bag", tmp_path)
    s = diagnose_recording(runs, base, DiagnoseOptions()).summary
    assert sorted(s["effects"]) == ["torque_offset", "track_bumps"], s["verdict"]
    bump = {p["name"]: p["value"] for p in s["parameters"] if p["effect"] == "track_bumps"}
    assert abs(bump["phi_b"] - 2.2975) < 0.02 and bump["h"] == pytest.approx(-7.89e-4, rel=0.1)
