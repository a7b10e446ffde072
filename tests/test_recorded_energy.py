"""Seed recommendation 2: motor work against the ideal energy input along a recording.

The truth is not the analysis' own model: the recording is made by the force-based contact
model (a free ball with Hunt-Crossley contact, stick-slip friction, contact damping) in
closed loop with the real controller, with joint friction and rolling resistance in the
plant; the generator books its own dissipation, which the analysis must find from the
recorded torque, frame angle and ball fixes alone.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from bfr_model.contact import ITH, ITHD, IWD, IX, IY, ContactModel
from bfr_model.io.csv_io import write_csv
from bfr_model.params import load_params
from bfr_model.perturbations import load_study, write_params
from bfr_model.recording import Recording
from bfr_tools.analysis.cli import main
from bfr_tools.analysis.recorded import analyze_recording, frame_only
from bfr_tools.analysis.trajectory import closed_loop_contact

NOMINAL = load_params()
STUDY = load_study()
PLANT = NOMINAL.replace(**{"joint.coulomb_friction": 1e-3, "track.rolling_resistance": 2e-3})
DATA = Path(os.environ.get("BFR_RIG_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data" / "ntnu-rig"))


@pytest.fixture(scope="module")
def generated() -> tuple[Recording, np.ndarray]:
    """6 s of the contact plant in closed loop, logged with a 200 Hz camera (held fixes)."""
    res = closed_loop_contact(ContactModel(PLANT), NOMINAL, STUDY, 6.0, seed=1,
                              report_every=0.0)
    assert res.rolling_until == pytest.approx(6.0)
    t, x = res.t, res.x
    k = np.arange(t.size)
    every = max(1, round(0.005 / (t[1] - t[0])))
    held = np.maximum.accumulate(np.where(k % every == 0, k, 0))
    bx, by = x[held, IX], x[held, IY]
    rec = Recording(t=t, theta=x[:, ITH], theta_dot=x[:, ITHD], torque=res.u, ball_x=bx,
                    ball_y=by, ball_valid=np.ones(t.size, bool),
                    phi=x[held, ITH] + np.arctan2(bx, by), meta={"source": "contact plant"})
    return rec, x


def test_discrepancy_is_the_generators_own_dissipation(generated) -> None:  # noqa: ANN001
    """The nominal model has no losses: the motor's work it cannot store, per turn, equals
    the dissipation the contact plant booked (joint friction, rolling resistance, contact
    damping, slip) to 2 %; with the plant's own friction the residual all but vanishes."""
    rec, x = generated
    res = analyze_recording(rec, NOMINAL, STUDY, PLANT, label="contact plant")
    f = res.figures
    n = f["nominal"]
    assert f["has_ball"] and n["basis"] == "turn" and n["count"] >= 2
    assert n["model_dissipation"] == 0.0
    t = res.nominal.t[0]
    def span(col: int) -> float:
        return float(np.interp(t[-1], rec.t, x[:, col]) - np.interp(t[0], rec.t, x[:, col]))

    booked = span(IWD)
    turns = span(ITH) / (2 * math.pi)
    assert n["discrepancy"] == pytest.approx(booked, rel=0.02)
    assert n["rate"]["discrepancy"]["mean"] == pytest.approx(booked / turns, rel=0.1)
    # the Coulomb torque that would explain it alone: the plant's 1 mN m plus its rolling
    assert 1e-3 < n["equivalent"]["joint_coulomb_torque"] < 1.15e-3
    c = f["corrected"]
    assert c["model_dissipation"] > 0.9 * n["discrepancy"]
    assert c["share_left"] < 0.02
    # the chapter-2 joint friction at the seed's 1e-5 F_load is far too small to explain it
    joint = f["perturbations"]["terms"]["E_joint"]
    assert joint["kind"] == "dissipative" and joint["verdict"].startswith("cannot explain")
    assert joint["seed"]["rate"] < 0.05 * n["rate"]["discrepancy"]["mean"]
    mass = f["perturbations"]["terms"]["E_mass"]
    assert "conservative" in mass["verdict"]


def test_frame_only_energy_is_the_frames() -> None:
    """Without the ball the model is the frame alone: E_in = J_f theta_dot^2 / 2 and the
    joint friction the only dissipation (a spin-down under Coulomb and viscous friction)."""
    p = NOMINAL.replace(**{"joint.coulomb_friction": 2e-3, "joint.viscous_friction": 1e-4})
    t = np.linspace(0.0, 4.0, 4001)
    jf = p.frame.inertia
    w = np.empty_like(t)  # exact solution of J w' = -c w - T_c (w > 0)
    tau = jf / 1e-4
    w0 = 6.0
    w[:] = (w0 + 2e-3 / 1e-4) * np.exp(-t / tau) - 2e-3 / 1e-4
    keep = w > 0.2
    t, w = t[keep], w[keep]
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    nan = np.full(t.size, np.nan)
    rec = Recording(t=t, theta=theta, theta_dot=w, torque=np.zeros(t.size), ball_x=nan,
                    ball_y=nan, ball_valid=np.zeros(t.size, bool), phi=nan)
    f = analyze_recording(rec, p, STUDY, label="spin-down").figures
    n = f["nominal"]
    assert not f["has_ball"] and n["motor_work"] == 0.0
    # the friction removed exactly the frame's kinetic energy: the residual vanishes
    assert abs(n["discrepancy"]) < 1e-4 * abs(n["energy_in"])
    assert n["model_dissipation"] == pytest.approx(-n["energy_in"], rel=1e-4)
    assert frame_only(p).ball.mass < 1e-9
    assert f["perturbations"]["terms"]["E_rol"]["verdict"].startswith("does not apply")


def test_cli_energy_on_recordings(generated, tmp_path, capsys) -> None:  # noqa: ANN001
    rec, _ = generated
    csv = tmp_path / "run.csv"
    write_csv(csv, rec)
    cor = write_params(PLANT, tmp_path / "corrected_params.yaml")
    out = tmp_path / "out"
    assert main(["energy", str(csv), "--corrected", str(tmp_path), "--json",
                 "--out-dir", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    (f,) = doc["recordings"]
    assert f["corrected"]["params"] == str(cor)
    assert f["corrected"]["share_left"] < 0.05
    assert len(f["plots"]) == 3 and all(Path(p).is_file() for p in f["plots"])
    assert main(["energy", str(csv), "--no-plots", "--out-dir", str(out)]) == 0
    text = capsys.readouterr().out
    assert "per turn" in text and "E_joint" in text and "cannot explain the loss" in text


@pytest.mark.parametrize(("extra", "needle"), [
    (["missing.txt"], "no such file"),
    (["{csv}", "--corrected", "{csv}.nope"], "no such file"),
    (["{csv}", "--corrected", "{dir}"], "no corrected_params.yaml"),
    (["{csv}", "{csv}", "--corrected", "a.yaml", "b.yaml", "c.yaml"], "3 paths for 2"),
    (["--corrected", "a.yaml"], "need recordings"),
])
def test_cli_energy_bad_input_is_one_line_exit_2(tmp_path, capsys, extra, needle) -> None:  # noqa: ANN001
    csv = tmp_path / "r.csv"
    csv.write_text("t,theta\n")
    args = [a.format(csv=csv, dir=tmp_path) for a in extra]
    assert main(["energy", *args, "--no-plots", "--out-dir", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and err[0].startswith("bfr analyze: error:")


@pytest.mark.skipif(not DATA.is_dir(), reason=f"NTNU rig logs not found at {DATA}")
def test_real_friction_run_against_the_seeds_joint_friction() -> None:
    """friction_v_ref_1 (frame alone at 1 rad/s): the motor's work per turn is lost to the
    joint; the seed's joint friction (1e-5 F_load) is two orders of magnitude short, a
    Coulomb torque of a few mN m would do (the diagnosis finds 1.96 mN m on this log)."""
    from bfr_model.io import read_recording  # noqa: PLC0415 - only with the data

    f = analyze_recording(read_recording(DATA / "friction_v_ref_1.txt", warn=False), NOMINAL,
                          STUDY, label="friction_v_ref_1").figures
    n = f["nominal"]
    assert n["basis"] == "turn" and n["count"] >= 5
    assert 1e-3 < n["equivalent"]["joint_coulomb_torque"] < 4e-3
    joint = f["perturbations"]["terms"]["E_joint"]
    assert joint["seed"]["rate"] < 0.02 * n["rate"]["discrepancy"]["mean"]
