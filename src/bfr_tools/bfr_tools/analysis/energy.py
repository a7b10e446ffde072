"""Energy analysis of the ideal system and of each perturbation (seed chapter 2).

Evaluated along a trajectory of the ideal (nominal, rigid) model, as the seed did with
the 10 s, 1 kHz data of its predecessors; every quantity is a function of the state, so the
analysis takes any :class:`~bfr_tools.analysis.trajectory.Trajectory`. Notation: m, J_b, J_f,
R as in rig.yaml; ``s_dot = lam phi_dot`` the ball centre's speed along its path relative to
the frame; ``n_y`` the world y component of the track normal at the contact; ``F_n``, ``F_t``
the normal and tangential contact force of the rigid model; ``F_load`` the bearing load.

==========  =================================================  ===========================
symbol      seed formula (equation)                             exact counterpart (ours)
==========  =================================================  ===========================
E_sys       T + V of the ideal model (2.1)                      same (the exact Lagrangian)
E_in        E_sys - E_sys(0) (2.3)                              same
E_rol       mu_rol int |F_n| ds (2.4)                           same
E_joint     int T_fric |d theta|, T = c F_load (2.5)            same, F_load = |m (r_dd + g)
                                                                + m_f g|
E_rot       s_dot^2 / 2 (J_b / R*^2 - J_b / R^2) (2.6)          J_b / 2 ((th' - s_dot/R*)^2
                                                                - (th' - s_dot/R)^2)
E_tr        m / 2 v_z^2, v_z = sin(eps) d/dt(r sin theta)       v_z = sin(eps) p_x'(phi) ph'
            (2.7-2.9)                                           (frame wobble, exact)
E_pot       m g delta_h n_y (2.10)                              same
E_ela       F_n^2 / (2 k_bt) (2.11)                             Hertz/Hunt-Crossley stored
                                                                energy 2/5 F_n^(5/3) / k^(2/3)
E_mass      E_sys(m*, J*) - E_sys (2.12)                        same
E_ell       (seed 2.1.3, situation 2) m g e(beta) n_y           same, e = delta_h/2 cos 2 beta
E_g         (shaft pitch) m g (cos eps - 1) y_ball              same
==========  =================================================  ===========================

Fluctuations are time derivatives by the seed's forward difference (2.13),
``dE(t) = (E(t + T) - E(t)) / T``. Energies are ranked by their peak magnitude over the run,
fluctuations by their peak magnitude after the start-up (``run.settle``; the seed discarded
``s < 1``). The bump estimate (2.14-2.15): ``dE_bump = E_pot,max / T_bump``,
``T_bump = sqrt(R^2 - (R - delta_h)^2) / s_dot_avg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from bfr_model.dynamics import RigidModel, curve_terms, rigid_terms
from bfr_model.geometry import contour_kernel
from bfr_model.params import RigParams
from bfr_model.perturbations import StudySettings, perturbed
from numpy.typing import NDArray

from bfr_tools.analysis.trajectory import Trajectory, closed_loop_rigid, progress

__all__ = [
    "SEED",
    "EnergyReport",
    "EnergyTerm",
    "closed_loop_check",
    "energy_analysis",
    "plot_energy",
    "rigid_forces",
]

FloatArray = NDArray[np.float64]

#: The seed's reported results (Knol 2016, sections 2.2-2.3), for comparison.
SEED = {
    "rank_energy": ["E_joint", "E_rol", "E_mass", "E_pot", "E_rot", "E_tr", "E_ela"],
    "rank_fluctuation": ["E_mass", "E_joint", "E_pot", "E_rot", "E_rol", "E_tr", "E_ela"],
    "E_pot_max": 1.45e-5,  # [J] eq. 2.14
    "dE_pot_bump": 9e-4,  # [W] "about 9e-4"
    "ratio_to_others": 20.0,  # "at least 20 times higher than the other fluctuations"
    "fraction_of_controller": 0.10,  # "roughly 10 % of the average change in energy"
}


@dataclass
class EnergyTerm:
    """One energy function along the trajectory.

    Attributes
    ----------
    symbol : str
        E_rol, E_joint, ...
    title : str
        What it is.
    seed : ndarray
        The seed's formula [J].
    exact : ndarray
        Our exact counterpart [J] (the same array where the formulas agree).
    """

    symbol: str
    title: str
    seed: FloatArray
    exact: FloatArray


@dataclass
class EnergyReport:
    """Results of :func:`energy_analysis` (see :meth:`figures`)."""

    t: FloatArray
    e_sys: FloatArray
    terms: dict[str, EnergyTerm]
    settle: float
    figures_: dict = field(default_factory=dict)

    def fluctuation(self, e: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Seed eq. 2.13: ``(t[:-1], (E[1:] - E[:-1]) / (t[1:] - t[:-1]))``."""
        return self.t[:-1], np.diff(e) / np.diff(self.t)

    def figures(self) -> dict:
        """The figures of the analysis as a JSON-ready dict (computed by energy_analysis)."""
        return self.figures_


def rigid_forces(model: RigidModel, traj: Trajectory) -> dict[str, FloatArray]:
    """Contact and bearing forces of the rigid model along a trajectory.

    ``F_c = m (r_dd + g_e y)`` (frame coordinates) with the accelerations of
    :func:`bfr_model.dynamics.rigid_terms` under the trajectory's torque:
    ``F_n = n . F_c``, ``F_t = t . F_c``, ``F_load = |F_c + m_f g_e y|``. Also returns
    ``s_dot = lam phi_dot`` [m/s], the world y component of the normal and the ball height.
    """
    th, ph, thd, phd = traj.x.T
    args = model.kernel_args
    thdd, phdd, _, _, fn = rigid_terms(th, ph, thd, phd, traj.u, *args)
    px, py, p1x, p1y, p2x, p2y, nx, ny, lam, _ = curve_terms(ph, *args)
    m = model.params.ball.mass
    g = model.params.environment.in_plane_gravity
    st, ct = np.sin(th), np.cos(th)
    ax = -thdd * py - thd**2 * px - 2 * thd * phd * p1y + phd**2 * p2x + phdd * p1x + g * st
    ay = thdd * px - thd**2 * py + 2 * thd * phd * p1x + phd**2 * p2y + phdd * p1y + g * ct
    fcx, fcy = m * ax, m * ay
    mf = model.params.frame.mass
    load = np.hypot(fcx + mf * g * st, fcy + mf * g * ct)
    return {"F_n": fn, "F_n_check": nx * fcx + ny * fcy, "F_t": ny * fcx - nx * fcy,
            "F_load": load, "s_dot": lam * phd, "lam": lam, "n_y": st * nx + ct * ny,
            "y_ball": st * px + ct * py, "p1x": p1x, "nx": nx, "ny": ny}


def _cumulative(rate: FloatArray, t: FloatArray) -> FloatArray:
    return np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])


def energy_analysis(traj: Trajectory, params: RigParams, study: StudySettings) -> EnergyReport:
    """Energies of the ideal system and of the seed's perturbations along ``traj``.

    Parameters
    ----------
    traj : Trajectory
        A trajectory of the ideal model (``params``), e.g. a closed-loop run.
    params : RigParams
        The nominal parameters.
    study : StudySettings
        Perturbation magnitudes and the start-up time to leave out.

    Returns
    -------
    EnergyReport
        Terms, fluctuations and the figures (rankings, bump estimate, seed comparison).
    """
    pm = study.perturbations
    model = RigidModel(params)
    t = traj.t
    th, ph, thd, phd = traj.x.T
    kin, pot = model.energy(traj.x)
    e_sys = kin + pot
    f = rigid_forces(model, traj)
    m, jb = params.ball.mass, params.ball.inertia
    g = params.environment.in_plane_gravity
    R = params.ball.rolling_radius
    s_dot = f["s_dot"]
    terms: dict[str, EnergyTerm] = {}

    def add(symbol: str, title: str, seed: FloatArray, exact: FloatArray | None = None) -> None:
        terms[symbol] = EnergyTerm(symbol, title, seed, seed if exact is None else exact)

    # friction (2.4, 2.5)
    add("E_rol", f"rolling friction, mu_rol = {pm.rolling_resistance:g}",
        pm.rolling_resistance * _cumulative(np.abs(f["F_n"]) * np.abs(s_dot), t))
    add("E_joint", f"joint friction, T = {pm.joint_load_friction:g} F_load",
        pm.joint_load_friction * _cumulative(f["F_load"] * np.abs(thd), t))
    # kinetic (2.6-2.9)
    r_star = R * (1.0 - pm.radius_decrease)
    add("E_rot", f"rolling radius -{100 * pm.radius_decrease:g} %",
        0.5 * s_dot**2 * (jb / r_star**2 - jb / R**2),
        0.5 * jb * ((thd - s_dot / r_star) ** 2 - (thd - s_dot / R) ** 2))
    eps = pm.misalignment
    c = model.curve.arrays
    rho, rho1 = contour_kernel(ph, c.rho0, c.orders, c.ccos, c.csin, c.bump_phi, c.bump_h,
                               c.bump_w)[:2]
    vz_seed = math.sin(eps) * (rho1 * phd * np.sin(th) + rho * np.cos(th) * thd)
    vz_exact = math.sin(eps) * f["p1x"] * phd
    add("E_tr", f"sway along z, eps = {eps:.4g} rad (frame wobble)", 0.5 * m * vz_seed**2,
        0.5 * m * vz_exact**2)
    # potential (2.10), elastic (2.11)
    add("E_pot", f"constant offset delta_h = {pm.bump_height:g} m",
        m * g * pm.bump_height * f["n_y"])
    k_hc = params.contact_stiffness
    fn_pos = np.maximum(f["F_n"], 0.0)
    add("E_ela", f"elastic, k_bt = {pm.elastic_stiffness:g} N/m",
        f["F_n"] ** 2 / (2.0 * pm.elastic_stiffness),
        0.4 * fn_pos ** (5.0 / 3.0) / k_hc ** (2.0 / 3.0))
    # mass and inertia (2.12)
    pmass = RigidModel(perturbed(params, "mass", study))
    k2, p2 = pmass.energy(traj.x)
    add("E_mass", f"mass and inertia +{100 * pm.mass_increase:g} %", k2 + p2 - e_sys)
    # beyond the seed's set: elliptic ball (2.1.3 situation 2), pitched shaft
    s_arc = model.curve.arc_length(ph)
    beta2 = 2.0 * s_arc / R  # 2 beta = 2 s / R + 2 nu, nu the normal's angle
    cos2b = np.cos(beta2) * (f["nx"] ** 2 - f["ny"] ** 2) - np.sin(beta2) * 2 * f["nx"] * f["ny"]
    add("E_ell", f"elliptic ball, delta_h = {pm.ellipticity:g} m",
        m * g * 0.5 * pm.ellipticity * cos2b * f["n_y"])
    add("E_g", f"pitched shaft, eps = {eps:.4g} rad",
        m * g * (math.cos(eps) - 1.0) * f["y_ball"])
    settle = min(study.run.settle, 0.5 * (t[0] + t[-1]))  # short runs: their second half
    rep = EnergyReport(t=t, e_sys=e_sys, terms=terms, settle=settle)
    rep.figures_ = _figures(rep, traj, model, f, study)
    return rep


def _peak(a: FloatArray) -> float:
    return float(np.max(np.abs(a))) if a.size else math.nan


def _rank(values: dict[str, float]) -> list[str]:
    return [k for k, _ in sorted(values.items(), key=lambda kv: -kv[1])]


def _figures(rep: EnergyReport, traj: Trajectory, model: RigidModel, f: dict,
             study: StudySettings) -> dict:
    t = rep.t
    late = t >= rep.settle
    late_d = t[:-1] >= rep.settle
    pm = study.perturbations
    R = model.params.ball.rolling_radius
    _, de_sys = rep.fluctuation(rep.e_sys)
    p_motor = traj.u * traj.theta_dot * model.params.actuator.torque_gain
    ctrl_avg = float(np.mean(np.abs(p_motor[late])))
    rows = {}
    for sym, term in rep.terms.items():
        row = {"title": term.title}
        for kind in ("seed", "exact"):
            e = getattr(term, kind)
            _, de = rep.fluctuation(e)
            row[kind] = {"peak_energy": _peak(e), "peak_fluctuation": _peak(de[late_d]),
                         "rms_fluctuation": float(np.sqrt(np.mean(de[late_d] ** 2)))}
        rows[sym] = row
    seed_set = SEED["rank_energy"]
    rank_e = {k: _rank({s: rows[s][k]["peak_energy"] for s in seed_set})
              for k in ("seed", "exact")}
    rank_f = {k: _rank({s: rows[s][k]["peak_fluctuation"] for s in seed_set})
              for k in ("seed", "exact")}
    # bump estimate (2.14-2.15)
    e_pot_max = _peak(rep.terms["E_pot"].seed[late])
    s_avg = float(np.mean(np.abs(f["s_dot"][late])))
    dh = pm.bump_height
    t_bump = math.sqrt(R**2 - (R - dh) ** 2) / s_avg if s_avg > 0.0 else math.inf
    de_bump = e_pot_max / t_bump
    others = max(rows[s]["seed"]["peak_fluctuation"] for s in seed_set)
    others_sum = float(np.max(np.abs(sum(np.diff(rep.terms[s].seed) / np.diff(t)
                                         for s in seed_set)[late_d])))
    def ratio(a: float, b: float) -> float:
        return a / b if b > 0.0 else math.nan

    return {
        "trajectory": {"label": traj.label, "duration": float(t[-1] - t[0]),
                       "samples": int(t.size), "settle": rep.settle, **traj.info},
        "ideal": {"mean_energy": float(np.mean(rep.e_sys[late])),
                  "energy_range": float(np.ptp(rep.e_sys[late])),
                  "peak_fluctuation": _peak(de_sys[late_d]),
                  "mean_abs_fluctuation": float(np.mean(np.abs(de_sys[late_d]))),
                  "controller_mean_abs_power": ctrl_avg,
                  "controller_mean_power": float(np.mean(p_motor[late]))},
        "terms": rows,
        "rank_energy": rank_e,
        "rank_fluctuation": rank_f,
        "seed_rank_energy": SEED["rank_energy"],
        "seed_rank_fluctuation": SEED["rank_fluctuation"],
        "bump": {"E_pot_max": e_pot_max, "s_dot_avg": s_avg, "T_bump": t_bump,
                 "dE_pot_bump": de_bump, "ratio_to_largest_other": ratio(de_bump, others),
                 "ratio_to_sum_of_others": ratio(de_bump, others_sum),
                 "fraction_of_controller_power": ratio(de_bump, ctrl_avg),
                 "seed": {k: SEED[k] for k in ("E_pot_max", "dE_pot_bump", "ratio_to_others",
                                               "fraction_of_controller")}},
    }


def closed_loop_check(params: RigParams, study: StudySettings, nominal: Trajectory,
                      keys: tuple[str, ...] = ("mass", "radius", "rolling", "joint", "wobble",
                                               "pitch", "bump", "ellipse")) -> dict:
    """Beyond the seed: each perturbation in the plant, the nominal controller, closed loop.

    Reports, against the nominal run, the mean motor power (what the controller feeds in),
    the RMS torque, the mean phi_dot and whether the ball kept rolling.
    """

    def stats(tr: Trajectory) -> dict:
        late = tr.t >= study.run.settle
        p = tr.u * tr.theta_dot * params.actuator.torque_gain
        return {"mean_power": float(np.mean(p[late])),
                "mean_abs_power": float(np.mean(np.abs(p[late]))),
                "rms_torque": float(np.sqrt(np.mean(tr.u[late] ** 2))),
                "mean_phi_dot": float((tr.phi[-1] - tr.phi[late][0])
                                      / (tr.t[-1] - tr.t[late][0])),
                "ball_rolling": bool(tr.info.get("ball_rolling", True)),
                "failure": tr.info.get("failure"), "rolling_until": tr.info.get("rolling_until"),
                "min_normal_force": tr.info.get("min_normal_force")}

    out = {"nominal": stats(nominal)}
    for key in keys:
        progress(f"closed loop with the perturbed plant: {key}")
        tr = closed_loop_rigid(perturbed(params, key, study), study, params)
        out[key] = stats(tr)
        out[key]["d_mean_power"] = out[key]["mean_power"] - out["nominal"]["mean_power"]
    return out


def plot_energy(rep: EnergyReport, out_dir: Path) -> list[Path]:
    """Figures like the seed's 2.2-2.4, as PNG files in out_dir; returns their paths."""
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    t = rep.t
    td, de = rep.fluctuation(rep.e_sys)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].plot(t, rep.e_sys)
    ax[0].set(xlabel="t [s]", ylabel="E_sys [J]", title="(a) energy of the ideal system")
    ax[1].plot(td, de, lw=0.6)
    ax[1].set(xlabel="t [s]", ylabel="dE_sys/dt [W]", title="(b) its fluctuation (eq. 2.13)")
    fig.suptitle("Fig. 2.2: ideal system")
    fig.tight_layout()
    paths.append(out_dir / "fig_2_2_ideal_energy.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    for num, what in ((3, "energy"), (4, "fluctuation")):
        fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
        for sym, term in rep.terms.items():
            if what == "energy":
                x, y = t, term.seed
            else:
                x, y = rep.fluctuation(term.seed)
            ax[0].plot(x, y, lw=0.7, label=sym)
            ax[1].semilogy(x, np.abs(y) + 1e-30, lw=0.5, label=sym)
        unit = "[J]" if what == "energy" else "[W]"
        ax[0].set(xlabel="t [s]", ylabel=f"{what} {unit}", title=f"(a) {what}, linear")
        ax[1].set(xlabel="t [s]", ylabel=f"|{what}| {unit}", title=f"(b) |{what}|, log",
                  ylim=(1e-12, None))
        ax[0].legend(fontsize=7, ncol=2)
        fig.suptitle(f"Fig. 2.{num}: {what} of the perturbations (seed formulas)")
        fig.tight_layout()
        paths.append(out_dir / f"fig_2_{num}_perturbation_{what}.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths
