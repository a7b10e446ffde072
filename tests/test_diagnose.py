"""Tests of ``bfr diagnose``: each effect's recovery, the clean control, pairs found as two,
bad inputs, bags (written by the recorder's writer, and by ``bfr simulate``), and the real
rig's logs.

Synthetic recordings come from :mod:`bfr_diagnose.synth` (the node suite's controller in
closed loop, camera noise 0.1 mm); every diagnosis uses the default noise-injection null,
as a user's.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.effects import EFFECT_NAMES
from bfr_diagnose.synth import LogConventions, SynthConfig, stabilised_recording
from bfr_model.io.csv_io import write_csv
from bfr_model.params import RigParams, load_params

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ntnu-rig"
DUR = 12.0
BLOCK = 1.5

# hidden effect -> (RigParams changes, camera settings of SynthConfig, parameter name, true
# value); a float camera setting is the camera latency [s]
CASES = {
    "joint_coulomb_friction": ({"joint.coulomb_friction": 2e-3}, 0.0, "T_c", 2e-3),
    "joint_viscous_friction": ({"joint.viscous_friction": 6e-4}, 0.0, "c_v", 6e-4),
    "rolling_resistance": ({"track.rolling_resistance": 1e-2}, 0.0, "mu_rol", 1e-2),
    "track_bumps": ({"track.bump_phi": (2.0,), "track.bump_height": (6e-4,),
                     "track.bump_width": (0.12,)}, 0.0, "h", 6e-4),
    "frame_inertia": ({"frame.inertia": 1.58e-3 * 1.1}, 0.0, "J_f", 1.58e-3 * 1.1),
    "ball_radius": ({"ball.radius": 16.6e-3 * 0.97}, 0.0, "R_b", 16.6e-3 * 0.97),
    "ball_mass": ({"ball.mass": 3.3e-3}, 0.0, "m_b", 3.3e-3),
    "frame_shape": ({"frame.contour.harmonic_orders": (3,), "frame.contour.harmonic_cos":
                     (3e-4,), "frame.contour.harmonic_sin": (0.0,)}, 0.0, "c_3", 3e-4),
    "axis_misalignment": ({"environment.axis_misalignment": 0.25}, 0.0, "eps", 0.25),
    "camera_latency": ({}, 0.008, "L", 0.008),
    "torque_gain": ({"actuator.torque_gain": 0.9}, 0.0, "k_u", 0.9),
    # the NTNU logs show a few mm (docs/ntnu-rig-conventions.md section 4)
    "camera_offset": ({}, {"camera_offset": (3e-3, -2e-3)}, "c_x", 3e-3),
}
NOMINAL = {"T_c": 0.0, "c_v": 0.0, "mu_rol": 0.0, "h": 0.0, "J_f": 1.58e-3, "R_b": 16.6e-3,
           "m_b": 3e-3, "c_3": 0.0, "eps": 0.0, "L": 0.0, "k_u": 1.0, "c_x": 0.0}


def _rec(changes: dict, camera: float | dict, seed: int):  # noqa: ANN202
    base = RigParams()
    plant = base.replace(**changes) if changes else base
    cam = camera if isinstance(camera, dict) else {"camera_latency": camera}
    if "camera_offset" in cam:
        cam = {"log": LogConventions(camera_offset=cam["camera_offset"])}
    for k in range(4):
        rec = stabilised_recording(plant, base, SynthConfig(duration=DUR, **cam),
                                   np.random.default_rng(seed + 100 * k))
        if rec.meta["ball_rolled"]:
            return rec
    raise AssertionError("the synthetic ball did not keep rolling")


def _diagnose(rec, max_effects: int = 2):  # noqa: ANN001, ANN202
    """Diagnose with the defaults a user gets (noise-injection null on the recording)."""
    opts = DiagnoseOptions(max_effects=max_effects, block=BLOCK)
    return diagnose_recording(rec, RigParams(), opts).summary


def test_library_names() -> None:
    assert set(EFFECT_NAMES) == set(CASES)


@pytest.mark.parametrize("name", list(CASES))
def test_effect_recovered(name: str) -> None:
    changes, camera, pname, true = CASES[name]
    s = _diagnose(_rec(changes, camera, 11), max_effects=1)
    assert s["effects"] and s["effects"][0] == name, (s["effects"], s["ranking"][:3])
    est = next(p["value"] for p in s["parameters"] if p["effect"] == name
               and p["name"] == pname)
    if name == "camera_latency":
        est = s["camera_latency"]["fitted_total"]
    rel = abs(est - true) / abs(true - NOMINAL[pname])
    if name == "camera_offset":  # both components, as a vector
        off = np.array(camera["camera_offset"])
        fit = np.array([s["camera_offset"]["x"], s["camera_offset"]["y"]])
        rel = float(np.linalg.norm(fit - off) / np.linalg.norm(off))
    assert rel < 0.25, (name, est, true)
    assert max(s["metrics"]["improvement_per_signal"].values()) > 1.5


def test_clean_control_no_mismatch() -> None:
    """Nominal physics: nothing selected, nothing located, and the null's noise scale is the
    residual's (the noise-injection null is checked, not just the selection)."""
    s = _diagnose(_rec({}, 0.0, 4242))
    assert s["effects"] == []
    assert s["verdict"] == "no significant mismatch"
    for row, g in s["located"]["global"].items():
        assert 0.7 < g["rms_over_noise"] < 1.4, (row, g)
    assert len(s["located"]["windows"]) <= 1


def test_pair_found_as_two() -> None:
    rec = _rec({"joint.viscous_friction": 5e-4, "track.rolling_resistance": 1e-2}, 0.0, 77)
    s = _diagnose(rec)
    assert set(s["effects"][:2]) == {"joint_viscous_friction", "rolling_resistance"}
    ci = next(p["ci95"] for p in s["parameters"] if p["name"] == "c_v")
    assert ci[0] < 5e-4 < ci[1] or abs(ci[0] - 5e-4) < 5e-5


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src" / p) for p in
                                         ("bfr_model", "bfr_ros", "bfr_camera", "bfr_control",
                                          "bfr_sim", "bfr_diagnose")]
                                        + [env.get("PYTHONPATH", "")])
    return env


def _cli(*args: str) -> subprocess.CompletedProcess:
    """``bfr diagnose ARGS`` in a subprocess."""
    return subprocess.run([sys.executable, "-m", "bfr_diagnose.cli", *args],
                          check=False, capture_output=True, text=True, env=_env(),
                          timeout=300)


def _bfr(*args: str) -> subprocess.CompletedProcess:
    """``bfr ARGS`` (the project's command line) in a subprocess."""
    return subprocess.run([sys.executable, "-m", "bfr_tools.cli", *args], check=False,
                          capture_output=True, text=True, env=_env(), timeout=300)


@pytest.mark.parametrize("content,what", [
    ("", "empty"),
    ("hello\x00\x01 garbage\nnot a log at all\n", "no data lines"),
    ("[inf] t=1.0,torque=0.0,theta=0.1,phi=0.2,dth", "truncated"),
    ("[inf] t=1.0,torque=nan,theta=0.1,phi=0.2,dtheta=0,dphi=0,x=0,y=0\n", "non-finite"),
])
def test_cli_bad_input(tmp_path: Path, content: str, what: str) -> None:
    f = tmp_path / "bad.txt"
    f.write_text(content)
    out = tmp_path / "out"
    r = _cli(str(f), "--out-dir", str(out), "--no-null")
    assert r.returncode == 2, r.stderr
    assert "error" in r.stderr
    assert not out.exists()


def test_cli_nan_csv(tmp_path: Path) -> None:
    f = tmp_path / "bad.csv"
    f.write_text("t,theta,theta_dot,phi,phi_dot,ball_x,ball_y,torque\n0,0,0,0,0,0,0.1,0\n"
                 "0.001,nan,0,0,0,0,0.1,0\n")
    r = _cli(str(f), "--no-null")
    assert r.returncode == 2 and "error" in r.stderr


def test_bag_written_by_recorder(tmp_path: Path) -> None:
    bag = pytest.importorskip("bfr_model.io.bag")
    rec = _rec({"joint.viscous_friction": 6e-4}, 0.0, 5)
    path = tmp_path / "run_bag"
    bag.write_recording_bag(path, rec)
    back = bag.read_bag(path)
    assert back.n > 0.9 * rec.n
    s = _diagnose(back, max_effects=1)
    assert s["effects"][:1] == ["joint_viscous_friction"]


def _record_like_the_recorder(path: Path, rec, latency: float) -> None:  # noqa: ANN001
    """Write ``rec`` as the recorder node does: rclpy's CDR bytes into BagWriter.

    joint_states and the command at every control step (log time = stamp + 0.2 ms), a
    BallObservation per camera fix stamped with its exposure time and logged on arrival.
    """
    rclpy_ser = pytest.importorskip("rclpy.serialization", reason="rclpy not installed")
    sensor_msgs = pytest.importorskip("sensor_msgs.msg", reason="sensor_msgs not installed")
    std_msgs = pytest.importorskip("std_msgs.msg", reason="std_msgs not installed")
    bfr_msgs = pytest.importorskip("bfr_interfaces.msg", reason="bfr_interfaces not built")
    from bfr_model.io.bag import BagWriter  # noqa: PLC0415

    def stamp(msg, t: float) -> None:  # noqa: ANN001
        ns = round(t * 1e9)
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9

    new = rec.new_fix_mask()
    with BagWriter(path) as bag:
        for k in range(rec.n):
            t = 1.0 + float(rec.t[k])
            js = sensor_msgs.JointState()
            stamp(js, t)
            js.name = ["frame_joint"]
            js.position = [float(rec.theta[k])]
            js.velocity = [float(rec.theta_dot[k])]
            js.effort = [float(rec.torque[k])]
            log = round((t + 2e-4) * 1e9)
            bag.write("/joint_states", "sensor_msgs/msg/JointState",
                      rclpy_ser.serialize_message(js), log)
            cmd = std_msgs.Float64MultiArray()
            cmd.data = [float(rec.torque[k])]
            bag.write("/effort_controller/commands", "std_msgs/msg/Float64MultiArray",
                      rclpy_ser.serialize_message(cmd), round(t * 1e9))
            if new[k]:
                ob = bfr_msgs.BallObservation()
                stamp(ob, t - latency)
                ob.status, ob.valid = 0, True
                ob.x, ob.y = float(rec.ball_x[k]), float(rec.ball_y[k])
                ob.phi = float(rec.phi[k])
                bag.write("/ball_observation", "bfr_interfaces/msg/BallObservation",
                          rclpy_ser.serialize_message(ob), log)


def test_bag_from_the_recorders_writer(tmp_path: Path) -> None:
    """A bag as the recorder node writes it (BagWriter + rclpy CDR), diagnosed by the CLI."""
    rec = _rec({"track.rolling_resistance": 1.2e-2}, 0.004, 21)
    _record_like_the_recorder(tmp_path / "rec_bag", rec, 0.004)
    r = _cli(str(tmp_path / "rec_bag"), "--json", "--quiet", "--no-plots", "--max-effects", "2")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["has_ball"]
    assert set(s["effects"][:2]) == {"rolling_resistance", "camera_latency"}, s["effects"]
    mu = next(p["value"] for p in s["parameters"] if p["name"] == "mu_rol")
    assert abs(mu - 1.2e-2) < 0.25 * 1.2e-2
    # the fixes are read at their arrival (log time): the camera's 4 ms are found
    assert abs(s["camera_latency"]["fitted_total"] - 0.004) < 1e-3


def test_node_suite_simulation_is_clean(tmp_path: Path) -> None:
    """`bfr simulate --controller --out x.mcap`, then `bfr diagnose x`: the nominal model's
    own noise-free closed loop must give no mismatch (the processing's resolution is part
    of the null)."""
    out = tmp_path / "sim.mcap"
    r = _bfr("simulate", "--controller", "--duration", "12", "--out", str(out))
    assert r.returncode == 0, r.stderr
    bag = out.with_suffix("")
    assert bag.is_dir()
    r = _cli(str(bag), "--json", "--quiet", "--no-plots")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["effects"] == [] and s["verdict"] == "no significant mismatch", s["verdict"]


def test_camera_offset_and_ball_mass_found_as_two() -> None:
    """The real rig's question: a camera offset must not be taken for a lighter ball."""
    rec = _rec({"ball.mass": 3.3e-3}, {"camera_offset": (4e-3, 3e-3)}, 31)
    s = _diagnose(rec)
    assert set(s["effects"][:2]) == {"camera_offset", "ball_mass"}, s["effects"]
    m = next(p["value"] for p in s["parameters"] if p["name"] == "m_b")
    assert abs(m - 3.3e-3) < 0.25 * 0.3e-3
    assert math.hypot(s["camera_offset"]["x"] - 4e-3, s["camera_offset"]["y"] - 3e-3) < 5e-4


def test_cli_json_and_outputs(tmp_path: Path) -> None:
    rec = _rec({"joint.viscous_friction": 6e-4}, 0.0, 6)
    f = tmp_path / "run.csv"
    write_csv(f, rec)
    out = tmp_path / "diag"
    r = _cli(str(f), "--out-dir", str(out), "--json", "--no-null", "--quiet",
             "--max-effects", "1")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["effects"] == ["joint_viscous_friction"]
    for name in ("report.md", "corrected_params.yaml", "residual_time.png", "overlay.png",
                 "ranking.png", "residual_phi.png", "diagnosis.json", "camera_correction.yaml"):
        assert (out / name).is_file(), name
    fitted = load_params(out / "corrected_params.yaml")
    assert math.isclose(fitted.joint.viscous_friction, 6e-4, rel_tol=0.2)


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ntnu-rig is absent")
def test_real_log_step_response_all_runs() -> None:
    """Six frame-only runs at one constant torque: inertia and viscous friction; the torque
    gain (and Coulomb friction, a constant like the command) confounded with the inertia."""
    r = _cli(str(DATA / "step_response_tau_001.txt"), "--run", "all", "--json", "--quiet",
             "--no-plots")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["has_ball"] is False and s["recording"]["runs_used"] == 6
    assert s["effects"][:1] in (["frame_inertia"], ["torque_gain"])
    assert any({"frame_inertia", "torque_gain"} <= set(c["effects"]) for c in s["confounded"])
    assert all(math.isfinite(p["value"]) for p in s["parameters"])


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ntnu-rig is absent")
def test_real_log_without_ball_data_says_so() -> None:
    """sin_wave: one camera fix, then 'ball was lost': frame-only analysis, said clearly."""
    r = _cli(str(DATA / "sin_wave_001_5_ball_center.txt"), "--json", "--quiet", "--no-plots")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["has_ball"] is False
    assert any("no usable ball data" in n and "ball was lost" in n for n in s["notes"])
    assert set(s["effects"]) <= {"joint_coulomb_friction", "joint_viscous_friction",
                                 "frame_inertia", "torque_gain"}
