"""Analyses: the seed's impact equations 3.1-3.4, paths A/B/C, energy terms, the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params
from bfr_model.perturbations import load_study
from bfr_model.simulate import simulate
from bfr_tools.analysis.bounce import bounce_along, classify, impact_energy, impact_momentum
from bfr_tools.analysis.cli import main
from bfr_tools.analysis.edges import EdgeCase, case_params, kinematic_lift
from bfr_tools.analysis.energy import energy_analysis, rigid_forces
from bfr_tools.analysis.trajectory import Trajectory

P = load_params()
STUDY = load_study()
M, JB, R = P.ball.mass, P.ball.inertia, P.ball.rolling_radius
G = 9.81


@pytest.mark.parametrize("h", [1e-5, 1.6e-4, 5e-4, 2e-3])
@pytest.mark.parametrize("v", [0.05, 0.2, 0.6])
def test_impact_conserves_energy_and_pivots_about_the_bump_top(h: float, v: float) -> None:
    """Eqs. 3.1-3.4: m v^2 + J psi_dot^2 = (J + m R^2) omega^2; the centre moves at omega R
    perpendicular to O->centre; for a rolling ball omega = v / R."""
    psi_dot = v / R
    omega, vt, vn = impact_energy(np.array(v), np.array(psi_dot), M, JB, R, h)
    assert M * v**2 + JB * psi_dot**2 == pytest.approx((JB + M * R**2) * omega**2, rel=1e-12)
    assert omega == pytest.approx(v / R, rel=1e-12)
    assert math.hypot(vt, vn) == pytest.approx(omega * R, rel=1e-12)
    xc = math.sqrt(R**2 - (R - h) ** 2)
    # O->centre is (-x_c, R - h): the velocity is perpendicular to it, forward and up
    assert vt * (-xc) + vn * (R - h) == pytest.approx(0.0, abs=1e-15)
    assert vt > 0.0 and vn > 0.0
    # plastic alternative: angular momentum about O conserved, energy lost
    om2, _, _ = impact_momentum(np.array(v), np.array(psi_dot), M, JB, R, h)
    assert (JB + M * R**2) * om2 == pytest.approx(JB * psi_dot + M * v * (R - h), rel=1e-12)
    assert om2 <= omega + 1e-15


def test_curvatures_match_the_curves_they_describe() -> None:
    """y''_C of the circle about O and y''_B of the free parabola, by finite differences."""
    h = 3e-4
    vt, vn, gt, gn = 0.25, 0.08, -1.0, -9.7
    c = classify(np.array([vt]), np.array([vn]), np.array([gt]), np.array([gn]), R, h)
    xc = math.sqrt(R**2 - (R - h) ** 2)

    def circle(x: float) -> float:
        return math.sqrt(R**2 - (x - xc) ** 2)  # centre height above O, moving forward

    dx = 1e-6
    ypp_c = (circle(dx) - 2 * circle(0.0) + circle(-dx)) / dx**2
    assert c["ypp_C"][0] == pytest.approx(ypp_c, rel=1e-5)

    def parab(t: float) -> tuple[float, float]:
        return vt * t + 0.5 * gt * t**2, vn * t + 0.5 * gn * t**2

    dt = 1e-6
    (x0, y0), (x1, y1), (x2, y2) = parab(-dt), parab(0.0), parab(dt)
    slope = lambda a, b, c_, d: (d - b) / (c_ - a)  # noqa: E731
    ypp_b = (slope(x1, y1, x2, y2) - slope(x0, y0, x1, y1)) / (0.5 * (x2 - x0))
    assert c["ypp_B"][0] == pytest.approx(ypp_b, rel=1e-4)


def test_path_classification_on_hand_cases() -> None:
    """Flat track (g_t = 0): contact is lost iff s_dot^2 > g (R - h); path A when the flight's
    apex s_dot^2 x_c^2 / (2 g R^2) exceeds h."""
    h = 2e-4
    v_crit = math.sqrt(G * (R - h))
    xc = math.sqrt(R**2 - (R - h) ** 2)
    v_a = math.sqrt(2 * G * h) * R / xc * 1.01  # apex just above h
    cases = {0.5 * v_crit: 2, 1.05 * v_crit: 1 if v_a > 1.05 * v_crit else 0, 1.01 * v_a: 0}
    for v, path in cases.items():
        _, vt, vn = impact_energy(np.array([v]), np.array([v / R]), M, JB, R, h)
        c = classify(vt, vn, np.array([0.0]), np.array([-G]), R, h)
        assert int(c["path"][0]) == path, (v, c)
    # uphill (g_t < 0) makes the parabola flatter: contact is lost at a lower speed
    v = 0.97 * v_crit
    _, vt, vn = impact_energy(np.array([v]), np.array([v / R]), M, JB, R, h)
    flat = classify(vt, vn, np.array([0.0]), np.array([-G]), R, h)["path"][0]
    up = classify(vt, vn, np.array([-0.3 * G]), np.array([-0.95 * G]), R, h)["path"][0]
    assert flat == 2 and up in (0, 1)


def _open_loop_traj() -> Trajectory:
    m = RigidModel(P)
    res = simulate(m, np.array([0.0, 0.3, 0.0, 0.0]), 1.0, 0.0, dt=1e-3)
    return Trajectory(res.t, res.x[:, :4], res.u, label="open loop")


def test_energy_terms_on_an_open_loop_run() -> None:
    """The analysis takes any trajectory; spot checks of the seed's formulas."""
    traj = _open_loop_traj()
    rep = energy_analysis(traj, P, STUDY)
    f = rigid_forces(RigidModel(P), traj)
    pm = STUDY.perturbations
    # E_pot (2.10) = m g dh n_y; the ball near the valley bottom: n_y ~ 1
    assert rep.terms["E_pot"].seed == pytest.approx(M * P.environment.in_plane_gravity
                                                    * pm.bump_height * f["n_y"])
    # E_ela (2.11) = F_n^2 / (2 k_bt)
    assert rep.terms["E_ela"].seed == pytest.approx(f["F_n"] ** 2 / (2 * pm.elastic_stiffness))
    # E_rol (2.4): mu int |F_n| |s_dot| dt grows monotonically
    assert np.all(np.diff(rep.terms["E_rol"].seed) >= 0.0)
    # E_mass (2.12): the same states, +1 % of every mass and inertia: +1 % of T + V
    assert rep.terms["E_mass"].seed == pytest.approx(0.01 * rep.e_sys, rel=1e-9, abs=1e-15)
    # fluctuation (2.13): forward difference
    _, de = rep.fluctuation(rep.terms["E_rol"].seed)
    assert de[5] == pytest.approx((rep.terms["E_rol"].seed[6] - rep.terms["E_rol"].seed[5])
                                  / (traj.t[6] - traj.t[5]))
    fig = rep.figures()
    b = fig["bump"]
    assert b["dE_pot_bump"] == pytest.approx(
        b["E_pot_max"] * b["s_dot_avg"] / math.sqrt(R**2 - (R - pm.bump_height) ** 2))
    assert set(fig["rank_energy"]["seed"]) == set(fig["seed_rank_energy"])
    # the F_n of the kernel and of the force decomposition agree
    assert np.max(np.abs(f["F_n"] - f["F_n_check"])) < 1e-12


def test_bounce_along_a_trajectory_and_slip_is_only_where_contact_is_lost() -> None:
    traj = _open_loop_traj()
    ev = bounce_along(RigidModel(P), traj, 5e-4)
    assert np.all(ev.slip[ev.path == 2] == 0.0)
    assert not np.any(np.isnan(ev.ypp_B)) and np.all(ev.s >= 0.0)


def test_cli_energy_json_and_rough(tmp_path, capsys) -> None:  # noqa: ANN001
    assert main(["energy", "--duration", "3", "--json", "--out-dir", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bump"]["seed"]["dE_pot_bump"] == 9e-4
    assert len(out["plots"]) == 3 and all((tmp_path / p.split("/")[-1]).exists()
                                          for p in out["plots"])
    f = tmp_path / "rough.yaml"
    assert main(["rough", "--count", "12", "--seed", "3", "--out", str(f)]) == 0
    assert len(load_params(f).track.asperity_phi) == 12
    # an existing parameter file is refused in one line and kept; --force replaces it
    capsys.readouterr()
    assert main(["rough", "--count", "5", "--seed", "3", "--out", str(f)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err, err
    assert len(load_params(f).track.asperity_phi) == 12
    assert main(["rough", "--count", "5", "--seed", "3", "--out", str(f), "--force"]) == 0
    assert len(load_params(f).track.asperity_phi) == 5


# -- bumps on both edges (seed recommendation 3) -------------------------------------------
def test_kinematic_lift_adds_in_phase_and_cancels_interleaved() -> None:
    """Rigid edges: bumps on one edge lift the centre by half their height, in phase by all
    of it (the one-edge model's row); a dense row shifted by half a spacing fills the other
    edge's valleys (a quarter of the ripple); isolated bumps in phase rise the full height."""
    cfg = STUDY.two_edge
    dense = {ph: kinematic_lift(P, cfg, EdgeCase("", "phase", 1e-3, 5e-4, ph))
             for ph in (None, 0.0, 0.5)}
    assert dense[0.0]["mean_lift"] == pytest.approx(5e-4, rel=0.02)
    assert dense[None]["mean_lift"] == pytest.approx(0.5 * dense[0.0]["mean_lift"], rel=0.01)
    assert dense[None]["ripple"] == pytest.approx(0.5 * dense[0.0]["ripple"], rel=0.05)
    assert dense[0.5]["ripple"] < 0.3 * dense[0.0]["ripple"]
    # the ball rides on the tops: the ripple is the sag of a chord over one spacing
    assert dense[0.0]["ripple"] == pytest.approx(1e-3**2 / (8 * R), rel=0.2)
    # the arcs over the tops have radius R: contact is lost above sqrt(g R) in phase
    assert dense[0.0]["critical_speed"] == pytest.approx(math.sqrt(9.81 * R), rel=0.05)
    sparse = kinematic_lift(P, cfg, EdgeCase("", "spacing", 8e-3, 1e-4, 0.0))
    assert sparse["ripple"] == pytest.approx(1e-4, rel=0.02)  # down to the track between


def test_case_rows_sit_on_their_edges() -> None:
    cfg = STUDY.two_edge
    case = EdgeCase("", "phase", 2e-3, 3e-4, 0.5)
    p = case_params(P, cfg, 0.8, case)
    edges = np.array(p.track.asperity_edge)
    phi = np.array(p.track.asperity_phi)
    n = edges.size // 2
    assert set(edges[:n]) == {1} and set(edges[n:]) == {2}
    front, back = np.sort(phi[:n]), np.sort(phi[n:])
    spacing_rad = front[1] - front[0]
    assert back[0] - front[0] == pytest.approx(0.5 * spacing_rad, rel=0.05)
    assert case_params(P, cfg, 0.8, EdgeCase("", "phase", 2e-3, 3e-4, None)
                       ).track.asperity_edges() == (1,) * n


def test_cli_edges_quick(tmp_path, capsys) -> None:  # noqa: ANN001
    """In phase the two edges are identical: the ball never moves sideways; over the front
    row alone it does."""
    study = tmp_path / "study.yaml"
    study.write_text("run:\n  settle: 0.3\ntwo_edge:\n  location: 0.9\n")
    assert main(["edges", "--quick", "--duration", "1.2", "--study", str(study), "--json",
                 "--no-plots"]) == 0
    out = json.loads(capsys.readouterr().out)
    runs = {(r["sweep"], r["phase"]): r for r in out["runs"]}
    assert set(runs) == {("none", None), ("phase", None), ("phase", 0.0), ("phase", 0.5)}
    assert runs[("phase", 0.0)]["max_abs_z"] == 0.0
    assert runs[("phase", None)]["max_abs_z"] > 1e-5
    assert all(math.isfinite(r["slip_per_turn"]) for r in out["runs"])
