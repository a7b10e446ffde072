"""The independent rig's logs: format, conventions as the sidecar says, controllers, CLI.

The log is read back with this file's own parser (a regular expression for data lines,
everything else noise), not with the generator's code.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from independent import physics, rig_log, sensors

WORKTREE = Path(__file__).resolve().parents[2]
DATA = re.compile(
    r"\[inf\] t=([^,]+),torque=([^,]+),theta=([^,]+),phi=([^,]+),dtheta=([^,]+),"
    r"dphi=([^,]+),x=([^,]+),y=([^,\r\n]+)\r\n")
MARKER = "[inf] initializing hardware.."

CONV = sensors.SensorConventions(
    line_rate=437.0, line_jitter=0.05, servo_rate=2000.0, counts_per_rev=65536,
    velocity_mode="difference", velocity_lag=0.006, torque_shift=0.0015,
    actuation_delay=0.002, camera_rate=171.0, camera_latency=0.008, camera_noise=1e-4,
    camera_offset=(8e-4, -5e-4), camera_scale=0.008, camera_rotation=0.005, lost_fill="hold",
    digits=8, t_start=4.2)


def parse(text: str) -> list[np.ndarray]:
    """Data rows of each run (a run starts after each 'initializing hardware' marker)."""
    runs = []
    for chunk in text.split(MARKER)[1:]:
        rows = [[float(v) for v in m.groups()] for m in DATA.finditer(chunk)]
        runs.append(np.array(rows))
    return runs


@pytest.fixture(scope="module")
def rolling() -> tuple[rig_log.RunResult, str]:
    rng = np.random.default_rng(11)
    result = rig_log.simulate_run(physics.RigParams(), CONV,
                                  rig_log.RunSpec(kind="rolling", duration=3.0), rng)
    text = rig_log.format_log([result], CONV, rig_log.Terminal(cut_last_line=True), rng)
    return result, text


def test_log_parses_as_the_format_says(rolling: tuple[rig_log.RunResult, str]) -> None:
    result, text = rolling
    (rows,) = parse(text)
    assert text.startswith("Script started on ")
    assert "\x1b[01;32m" in text and "[obs] psi_hat=" in text and "[inf] done\r\n" in text
    # every line ends in CRLF except the last one, which is cut mid-line
    assert not text.endswith("\r\n")
    assert len(rows) == len(result.rows) - 1
    t = rows[:, 0]
    assert np.all(np.diff(t) > 0) and 3.9 < t[0] < 5.5
    assert np.median(np.diff(t)) == pytest.approx(1 / 437.0, rel=0.05)
    assert np.all(np.abs(rows[:, 1]) <= 0.1)
    # numbers carry `digits` significant digits
    theta_text = re.findall(r"theta=([^,]+)", text)[500]
    assert len(theta_text.replace("-", "").replace(".", "").lstrip("0")) <= 8


def test_phi_dphi_and_fix_conventions(rolling: tuple[rig_log.RunResult, str]) -> None:
    result, text = rolling
    (rows,) = parse(text)
    t, theta, phi, dphi, x, y = rows[:, 0], rows[:, 2], rows[:, 3], rows[:, 5], rows[:, 6], \
        rows[:, 7]
    new = np.nonzero(np.any(np.diff(rows[:, 6:8], axis=0) != 0, axis=1))[0] + 1
    new = new[new > 60]  # past the first fixes and the phi_lead_in (0 here)
    assert len(new) > 300
    # phi = theta of the line that first shows the fix + atan2(x, y)
    assert np.max(np.abs(phi[new] - theta[new] - np.arctan2(x[new], y[new]))) < 1e-6
    # dphi = difference quotient between those lines; held between fixes
    quotient = np.diff(phi[new]) / np.diff(t[new])
    assert np.allclose(dphi[new[1:]], quotient, rtol=1e-5, atol=1e-4)
    held = np.setdiff1d(np.arange(new[0] + 1, len(rows)), new)
    assert np.all(dphi[held] == dphi[held - 1]) and np.all(x[held] == x[held - 1])
    # the ratio of lines to fixes follows the two rates (437 Hz lines, 171 Hz camera)
    assert len(new) / (t[-1] - t[new[0]]) == pytest.approx(171.0, rel=0.1)
    # fixes are the truth at the exposure (about latency + half a line period before the
    # line) up to the stated errors (1 mm offset, 0.8 % scale, 0.3 degrees, 0.1 mm noise)
    tr = result.truth
    t_exp = tr["t_line"][new] - CONV.camera_latency - 0.5 / CONV.line_rate
    tx = np.interp(t_exp, tr["t_line"], tr["ball_x"])
    ty = np.interp(t_exp, tr["t_line"], tr["ball_y"])
    assert np.max(np.hypot(x[new] - tx, y[new] - ty)) < 3e-3


def test_camera_error_model_is_the_stated_similarity() -> None:
    conv = replace(CONV, camera_noise=0.0)
    camera = sensors.Camera(conv, np.random.default_rng(0))
    p = np.array([[0.02, 0.09], [-0.1, 0.05], [0.12, -0.03], [0.0, 0.15]])
    fixes = np.array([camera.measure(*q) for q in p])
    # least-squares similarity fit fix = s R p + o, by hand: complex numbers
    zp, zf = p[:, 0] + 1j * p[:, 1], fixes[:, 0] + 1j * fixes[:, 1]
    a = np.column_stack([zp, np.ones(len(zp))])
    (m, o), *_ = np.linalg.lstsq(a, zf, rcond=None)
    assert abs(m) == pytest.approx(1 + conv.camera_scale, abs=1e-12)
    assert np.angle(m) == pytest.approx(conv.camera_rotation, abs=1e-12)
    assert (o.real, o.imag) == pytest.approx(conv.camera_offset, abs=1e-12)
    assert camera.measure(0.5, 0.0) is None and camera.measure(math.nan, 0.0) is None


def test_velocity_lags_by_the_stated_delay(rolling: tuple[rig_log.RunResult, str]) -> None:
    result, text = rolling
    (rows,) = parse(text)
    t_run = result.truth["t_line"][: len(rows)]
    true_rate = result.truth["theta_dot"][: len(rows)]
    logged = rows[:, 4]
    lags = np.arange(0.0, 0.012, 2.5e-4)
    cost = [np.mean((logged[200:] - np.interp(t_run[200:] - lag, t_run, true_rate)) ** 2)
            for lag in lags]
    best = lags[int(np.argmin(cost))]
    # window delay plus the servo's sample-and-hold (half a servo period) on average
    expected = CONV.effective_velocity_lag + 0.5 / CONV.servo_rate
    assert best == pytest.approx(expected, abs=7.5e-4)


def test_torque_column_acts_at_line_time_plus_shift(rolling: tuple[rig_log.RunResult, str]
                                                    ) -> None:
    result, text = rolling
    (rows,) = parse(text)
    t_run = result.truth["t_line"][: len(rows)]
    t_act = np.array([c[0] for c in result.commands])
    values = np.array([c[1] for c in result.commands])
    k = np.searchsorted(t_act, t_run + CONV.torque_shift + 1e-12, side="right") - 1
    acting = np.where(k >= 0, values[np.maximum(k, 0)], 0.0)
    assert np.allclose(rows[:, 1], acting, rtol=1e-7, atol=1e-12)
    # and the plant felt exactly those torques: on a step run the frame starts at t_act
    rng = np.random.default_rng(3)
    conv = replace(CONV, line_rate=909.0, counts_per_rev=0)
    step = rig_log.simulate_run(physics.RigParams(), conv,
                                rig_log.RunSpec(kind="step", duration=0.3, torque=0.01), rng)
    t, th = step.truth["t_line"], step.truth["theta"]
    moving = t[np.nonzero(th > 0)[0][0]]
    first_command = step.commands[0][0]
    assert first_command == pytest.approx(conv.actuation_delay, abs=1e-12)
    assert first_command <= moving <= first_command + 1.5 / 909.0
    alpha = 2 * np.polyfit(t[t > 0.05] - first_command, th[t > 0.05], 2)[0]
    assert alpha == pytest.approx(0.01 / physics.RigParams().frame_inertia, rel=1e-3)


def test_controller_keeps_the_ball_rolling_on_the_nominal_rig() -> None:
    result = rig_log.simulate_run(physics.RigParams(), sensors.SensorConventions(),
                                  rig_log.RunSpec(kind="rolling", duration=12.0),
                                  np.random.default_rng(5))
    s = result.summary
    assert s["final_mode"] == physics.ROLLING and s["ball_lost_at"] is None
    assert np.all(result.truth["in_contact"] == 1.0)
    speeds = s["half_lap_speeds"][2:]
    assert len(speeds) >= 5 and 2.0 < np.mean(speeds) < 2.7


def test_controller_keeps_rolling_with_moderate_effects_and_other_sensors() -> None:
    rig = physics.RigParams(coulomb_pos=4e-3, coulomb_neg=3e-3, torque_offset=-1e-3,
                            frame_inertia_scale=1.15, rolling_resistance=2e-3,
                            contour_radius_delta=1e-3, imbalance=2e-4, imbalance_angle=1.0,
                            bumps=(physics.Bump(angle=1.0, height=2e-4, width=4e-3),))
    conv = replace(sensors.SensorConventions(), line_rate=300.0, velocity_mode="filter",
                   velocity_lag=0.008, camera_latency=0.01, camera_rate=160.0,
                   camera_offset=(7e-4, -7e-4), camera_rotation=-0.005, torque_shift=-0.002)
    result = rig_log.simulate_run(rig, conv, rig_log.RunSpec(kind="rolling", duration=8.0),
                                  np.random.default_rng(9))
    assert result.summary["final_mode"] == physics.ROLLING
    assert result.summary["ball_lost_at"] is None
    assert result.truth["ball_angle"][-1] > 12.0  # about 2 laps forward


def test_other_run_kinds() -> None:
    rng = np.random.default_rng(2)
    conv = replace(sensors.SensorConventions(), velocity_mode="true")
    rig = physics.RigParams(coulomb_pos=3e-3, coulomb_neg=3e-3)
    friction = rig_log.simulate_run(rig, conv, rig_log.RunSpec(kind="friction", duration=3.0,
                                                               speed_ref=-1.0), rng)
    late = friction.truth["t_line"] > 2.0
    assert np.mean(friction.truth["theta_dot"][late]) == pytest.approx(-1.0, abs=0.05)
    rows = np.array(friction.rows)
    assert np.mean(rows[late, 1]) == pytest.approx(-3e-3, abs=5e-4)  # holds the friction
    assert np.all(rows[:, 6:8] == 0.0)  # no ball: x = y = 0
    held = rig_log.simulate_run(rig, conv, rig_log.RunSpec(kind="held", duration=2.0,
                                                           ball_offset=0.2), rng)
    assert np.ptp(held.truth["theta"]) == 0.0 and np.all(np.array(held.rows)[:, 1] == 0.0)
    assert np.all(held.truth["in_contact"] == 1.0)
    # the ball rolls in the waist: it swings through the top, both ways
    angle = held.truth["ball_angle"] - held.truth["theta"]
    assert angle.min() < -0.1 and angle.max() > 0.1
    sine = rig_log.simulate_run(physics.RigParams(), conv,
                                rig_log.RunSpec(kind="sine", duration=2.0, torque=0.01,
                                                frequency=0.5), rng)
    t = sine.truth["t_line"]
    assert np.allclose(np.array(sine.rows)[:, 1][t > 0.01],
                       0.01 * np.sin(2 * np.pi * 0.5 * (t[t > 0.01] + conv.torque_shift
                                                        - conv.actuation_delay)), atol=6e-5)


def test_two_runs_in_one_file_with_sidecar(tmp_path: Path) -> None:
    path = tmp_path / "steps.txt"
    spec = rig_log.RunSpec(kind="step", duration=0.6, torque=0.01)
    sidecar = rig_log.write_log(path, physics.RigParams(coulomb_pos=2e-3, coulomb_neg=2e-3),
                                CONV, [spec, spec], seed=4, truth_series=True)
    text = path.read_bytes().decode()
    runs = parse(text)
    assert len(runs) == 2 and text.count("[inf] stopped") >= 1
    assert runs[1][0, 0] < runs[0][-1, 0]  # the logger clock restarts
    assert runs[1][0, 2] >= runs[0][-1, 2]  # the frame angle does not
    saved = json.loads(path.with_suffix(".truth.json").read_text())
    assert saved["seed"] == 4 and saved["sensors"]["torque_shift"] == CONV.torque_shift
    assert saved["rig"]["effects"] == {"coulomb_pos": 2e-3, "coulomb_neg": 2e-3}
    assert [r["kind"] for r in saved["runs"]] == ["step", "step"] == \
        [r["kind"] for r in sidecar["runs"]]
    series = np.genfromtxt(path.with_suffix(".truth.csv"), delimiter=",", names=True)
    assert set(series["run"]) == {0.0, 1.0}


def test_command_line(tmp_path: Path) -> None:
    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "tests.independent.rig_log", *args],
                              cwd=WORKTREE, capture_output=True, text=True, check=False,
                              timeout=120)

    assert run("--help").returncode == 0
    out = tmp_path / "f.txt"
    ok = run("one", "--out", str(out), "--kind", "friction", "--duration", "0.4",
             "--drawn-sensors", "--effect", "coulomb_pos=0.004", "--sensor", "line_rate=250")
    assert ok.returncode == 0, ok.stderr
    assert len(parse(out.read_bytes().decode())[0]) > 50
    again = run("one", "--out", str(out), "--kind", "friction")
    assert again.returncode == 2 and "exists" in again.stderr
    for bad in (["--effect", "colomb=1"], ["--effect", "coulomb_pos=-1"],
                ["--sensor", "line_rate=5000"]):
        proc = run("one", "--out", str(tmp_path / "g.txt"), "--kind", "step", *bad)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("rig_log: error:")
        assert not (tmp_path / "g.txt").exists()
