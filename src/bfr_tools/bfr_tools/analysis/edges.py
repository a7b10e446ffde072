"""Bumps on both plate edges: when do they cancel, when do they add (seed recommendation 3).

The seed ends (section 5.2, recommendation 3): "the ball is supported at 2 sides, if both
have bumps then the effect can either be nullified or amplified". The two-edge contact
model (:class:`bfr_model.contact.ContactModel` with ``edges=2``) gives each plate edge its
own bumps, contacts, normal forces, friction and stick spring, and the ball its lateral
position z and its yaw. Two views of the same question:

*Kinematic (rigid edges, quasi-static).* A ball resting on both edges has its centre on the
bisector of the two edge lines, R_b from each; raising one edge by ``H_e`` lifts the centre
by ``H_e / 2`` and moves it ``R H_e / d_f`` towards the other plate (to first order; the
exact form is checked in the tests). Along a row, each edge's support height is the
envelope of the in-plane disc of radius R rolling over that edge's bumps,
``H_e(s) = max_q [g_e(q) + sqrt(R^2 - (s - q)^2) - R]`` (g_e the edge's bump profile along
the contour, s the arc length), so the centre follows ``y(s) = (H_1(s) + H_2(s)) / 2``:
bumps in phase add (the full height, ``y = H``: the one-edge model's row), bumps on one
edge give half of it, rows shifted by half a spacing fill each other's valleys. Reported:
the mean lift, the ripple (peak-to-peak of y about its mean over the row's middle) and
the steepest downward curvature ``-min y''``, for which the ball leaves the track above
``v_c = sqrt(g / -min y'')`` (flat track).

*Dynamic (the contact model in closed loop).* The nominal controller keeps the ball
rolling over rows on both halves of the contour (``two_edge.*`` of perturbation_study.yaml):
a phase sweep of the back edge's row against the front one, a spacing sweep and a height
sweep, each beside the front row alone and no bumps. Measured after the start-up
(``run.settle``): the slip per frame turn (``int v_slip / R dt``, the mean over the two
edges' primary contacts, less the baseline's rate), the airborne fraction (both edges
apart), the largest lateral excursion ``|z|``, and whether the ball kept rolling.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.contact import ITH, IZ, ContactModel
from bfr_model.params import RigParams
from bfr_model.perturbations import (
    StudySettings,
    TwoEdgeSettings,
    bump_row,
    contour_arc_to_phi,
    with_asperities,
)
from numpy.typing import NDArray

from bfr_tools.analysis.bounce import bounce_analysis
from bfr_tools.analysis.trajectory import closed_loop_contact, closed_loop_rigid, progress

__all__ = ["EdgeCase", "case_params", "edge_cases", "kinematic_lift", "plot_edges",
           "two_edge_study"]

FloatArray = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class EdgeCase:
    """One configuration of bumps on the two edges.

    Attributes
    ----------
    name : str
        Label.
    sweep : str
        ``"phase"``, ``"spacing"``, ``"height"`` or ``"none"``.
    spacing, height : float
        Bump spacing along the contour and height [m] (0 height: no bumps).
    phase : float or None
        The back edge's row shifted by this fraction of the spacing; None: front row alone.
    """

    name: str
    sweep: str
    spacing: float
    height: float
    phase: float | None


def edge_cases(cfg: TwoEdgeSettings) -> list[EdgeCase]:
    """The study's configurations (module docstring): baseline, then the three sweeps."""
    cases = [EdgeCase("no bumps", "none", cfg.spacing, 0.0, None)]

    def trio(sweep: str, spacing: float, height: float, phases: tuple[float, ...]) -> None:
        tag = f"{1e3 * spacing:g} mm apart, {1e3 * height:g} mm"
        cases.append(EdgeCase(f"{tag}, front only", sweep, spacing, height, None))
        cases.extend(EdgeCase(f"{tag}, phase {p:g}", sweep, spacing, height, p)
                     for p in phases)

    trio("phase", cfg.spacing, cfg.height, cfg.phases)
    for sp in cfg.spacings:
        trio("spacing", sp, cfg.height, (0.0, 0.5))
    for h in cfg.heights:
        trio("height", cfg.spacing, h, (0.0, 0.5))
    return cases


def _row(params: RigParams, cfg: TwoEdgeSettings, start: float, spacing: float,
         height: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A row of ``row_length / spacing`` bumps from ``start`` and its copy half a turn on."""
    n = max(1, round(cfg.row_length / spacing))
    ph, h, w = bump_row(params, start, n, n * spacing, height, cfg.width)
    return (np.concatenate([ph, ph + math.pi]), np.concatenate([h, h]),
            np.concatenate([w, w]))


def case_params(params: RigParams, cfg: TwoEdgeSettings, start: float, case: EdgeCase
                ) -> RigParams:
    """``params`` with the case's rows: front edge, and the back edge's shifted by phase."""
    p = params.replace(**{"contact.time_step": cfg.time_step})
    if case.height == 0.0:
        return p
    ph, h, w = _row(params, cfg, start, case.spacing, case.height)
    p = with_asperities(p, ph, h, w, edge=1)
    if case.phase is not None:
        dphi = float(contour_arc_to_phi(params, start, case.phase * case.spacing)) - start
        p = with_asperities(p, ph + dphi, h, w, edge=2)
    return p


def kinematic_lift(params: RigParams, cfg: TwoEdgeSettings, case: EdgeCase,
                   n: int = 6000) -> dict[str, Any]:
    """The rigid-edge, quasi-static lift of the ball centre along the row (module docstring).

    Flat-track approximation of the row (30 mm against contour radii of 70-160 mm); arc
    length s from the row's start. Returns the mean lift and the ripple [m] over the row's
    middle half, the steepest downward curvature [1/m], its critical speed [m/s] and the
    profiles (``_s``, ``_y``).
    """
    R = params.ball.rolling_radius
    g = params.environment.in_plane_gravity
    if case.height == 0.0:
        return {"mean_lift": 0.0, "ripple": 0.0, "max_down_curvature": 0.0,
                "critical_speed": math.inf}
    count = max(1, round(cfg.row_length / case.spacing))
    length = count * case.spacing
    centres = (np.arange(count) + 0.5) * case.spacing
    s = np.linspace(-0.2 * length, 1.2 * length, n)
    q = s  # the bump profile on the same grid (spacing << width)

    def profile(shift: float) -> FloatArray:
        x = (q[:, None] - centres[None, :] - shift) / cfg.width
        return case.height * np.exp(-0.5 * x * x).sum(axis=1)

    def support(gq: FloatArray) -> FloatArray:
        ds = s[1] - s[0]
        band = int(np.ceil(min(R, 3.0 * case.spacing + 6.0 * cfg.width) / ds))
        out = np.full(s.size, -np.inf)
        for k in range(-band, band + 1):
            off = k * ds
            if abs(off) >= R:
                continue
            lo, hi = max(0, -k), min(s.size, s.size - k)
            cap = math.sqrt(R * R - off * off) - R
            out[lo:hi] = np.maximum(out[lo:hi], gq[lo + k:hi + k] + cap)
        return out

    h_front = support(profile(0.0))
    h_back = support(profile(case.phase * case.spacing)) if case.phase is not None else 0.0
    y = 0.5 * (h_front + h_back)
    mid = (s > 0.25 * length) & (s < 0.75 * length)
    ypp = np.gradient(np.gradient(y, s), s)
    down = float(max(0.0, -np.min(ypp[mid])))
    return {"mean_lift": float(np.mean(y[mid])), "ripple": float(np.ptp(y[mid])),
            "max_down_curvature": down,
            "critical_speed": math.sqrt(g / down) if down > 0.0 else math.inf,
            "_s": s, "_y": y}


def _location(params: RigParams, study: StudySettings) -> tuple[float, str]:
    """The rows' centre: ``two_edge.location``, else where the discrete model puts path B."""
    if study.two_edge.location is not None:
        return float(study.two_edge.location), "given (two_edge.location)"
    progress("the discrete model's path-B region (rigid closed loop, seed chapter 3)")
    rep = bounce_analysis(closed_loop_rigid(params, study, params), params, study)
    phi = rep["phi_B_region_mod_pi"]
    if phi is None:
        return float(rep["phi_C_region_mod_pi"]), "the discrete model's path-C region"
    return float(phi), "the discrete model's path-B region"


def _run_case(params: RigParams, study: StudySettings, start: float, case: EdgeCase,
              base_rate: float) -> dict[str, Any]:
    """One closed-loop run with the two-edge contact plant; its slip, lift and bounce."""
    cfg = study.two_edge
    model = ContactModel(case_params(params, cfg, start, case), edges=2)
    res = closed_loop_contact(model, params, study, cfg.duration, seed=study.run.seed,
                              report_every=0.0, stop_after_lost=0.2)
    until = res.rolling_until
    sel = (res.t >= study.run.settle) & (res.t <= until)
    out: dict[str, Any] = {
        "name": case.name, "sweep": case.sweep, "spacing": case.spacing,
        "height": case.height, "phase": case.phase, "rolling_until": until,
        "ball_kept_rolling": bool(until >= cfg.duration - 1e-6),
        "plant_real_time_factor": float((res.t[-1] - res.t[0]) / max(res.wall_time, 1e-9)),
        "kinematic": {k: v for k, v in kinematic_lift(params, cfg, case).items()
                      if not k.startswith("_")}}
    if sel.sum() < 2:
        return out
    th, slip, t = res.x[sel, ITH], res.slip[sel], res.t[sel]
    turns = (th[-1] - th[0]) / (2.0 * math.pi)
    dur = t[-1] - t[0]
    rate = (slip[-1] - slip[0]) / dur
    out.update({
        "turns": float(turns), "slip_rate": float(rate),
        "slip_per_turn": float((slip[-1] - slip[0]) / turns),
        "excess_slip_per_turn": float((rate - base_rate) * dur / turns),
        "airborne_fraction": float(np.mean(res.penetration[sel] < 0.0)),
        "max_abs_z": float(np.max(np.abs(res.x[sel, IZ]))),
        "_t": res.t, "_slip": res.slip, "_z": res.x[:, IZ], "_pen": res.penetration})
    return out


def two_edge_study(params: RigParams, study: StudySettings) -> dict[str, Any]:
    """Run every case (module docstring); returns the location, the rows and the runs."""
    cfg = study.two_edge
    loc, why = _location(params, study)
    start = float(contour_arc_to_phi(params, loc, -0.5 * cfg.row_length))
    out: dict[str, Any] = {"location": loc, "location_from": why, "row_start": start,
                           "settings": dataclasses.asdict(cfg), "runs": []}
    base_rate = 0.0
    for case in edge_cases(cfg):
        progress(f"two-edge contact, closed loop {cfg.duration:g} s: {case.name}")
        run = _run_case(params, study, start, case, base_rate)
        if case.sweep == "none":
            base_rate = run.get("slip_rate", 0.0)
            run["excess_slip_per_turn"] = 0.0
        out["runs"].append(run)
    return out


def plot_edges(res: dict[str, Any], params: RigParams, study: StudySettings,
               out_dir: Path) -> list[Path]:
    """The study's figures as PNGs.

    The phase sweep, the spacing and height sweeps, and the kinematic lift profiles of the
    reference row.
    """
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    runs = [r for r in res["runs"] if "slip_per_turn" in r]
    cfg = study.two_edge

    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    ph = [r for r in runs if r["sweep"] == "phase" and r["phase"] is not None]
    front = [r for r in runs if r["sweep"] == "phase" and r["phase"] is None]
    x = [r["phase"] for r in ph]
    ax[0].plot(x, [abs(r["excess_slip_per_turn"]) for r in ph], "o-", label="both edges")
    ax[1].plot(x, [1e6 * r["kinematic"]["ripple"] for r in ph], "o-", label="both edges")
    ax[2].plot(x, [r["airborne_fraction"] for r in ph], "o-", label="both edges")
    for r in front:
        ax[0].axhline(abs(r["excess_slip_per_turn"]), color="C1", ls="--", label="front only")
        ax[1].axhline(1e6 * r["kinematic"]["ripple"], color="C1", ls="--", label="front only")
        ax[2].axhline(r["airborne_fraction"], color="C1", ls="--", label="front only")
    ax[0].set(xlabel="back row's shift [bump spacings]", ylabel="|slip| per turn [rad]",
              title="(a) slip (closed loop, contact model)")
    ax[1].set(xlabel="back row's shift [bump spacings]", ylabel="ripple of the centre [um]",
              title="(b) kinematic ripple (rigid edges)")
    ax[2].set(xlabel="back row's shift [bump spacings]", ylabel="fraction of time airborne",
              title="(c) loss of contact")
    for a in ax:
        a.legend(fontsize=8)
    fig.suptitle(f"Bumps on both edges: phase ({1e3 * cfg.spacing:g} mm apart, "
                 f"{1e3 * cfg.height:g} mm high)")
    fig.tight_layout()
    paths.append(out_dir / "fig_edges_phase.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for a, sweep, key, scale, unit in ((ax[0], "spacing", "spacing", 1e3, "mm"),
                                       (ax[1], "height", "height", 1e3, "mm")):
        ref = [r for r in runs if r["sweep"] == "phase" and r["phase"] in (None, 0.0, 0.5)]
        for phase, label, c in ((None, "front only", "C1"), (0.0, "in phase", "C3"),
                                (0.5, "interleaved (0.5)", "C0")):
            rows = [r for r in runs if r["sweep"] == sweep and r["phase"] == phase]
            rows += [r for r in ref if r["phase"] == phase]
            rows.sort(key=lambda r: r[key])
            a.plot([scale * r[key] for r in rows], [abs(r["excess_slip_per_turn"])
                                                   for r in rows], "o-", color=c, label=label)
            lost = [r for r in res["runs"] if r["sweep"] == sweep and r["phase"] == phase
                    and not r["ball_kept_rolling"]]
            for r in lost:
                a.plot(scale * r[key], 0.0, "x", color=c, ms=10, mew=2)
                a.annotate("ball lost", (scale * r[key], 0.0), color=c, fontsize=8,
                           xytext=(4, 6), textcoords="offset points")
        a.set(xlabel=f"bump {key} [{unit}]", ylabel="|slip| per turn [rad]",
              xscale="log" if sweep == "spacing" else "linear",
              title=f"({'a' if sweep == 'spacing' else 'b'}) {sweep} sweep")
        if sweep == "spacing":
            ticks = sorted({scale * r["spacing"] for r in res["runs"] if r["height"] > 0.0})
            a.set_xticks(ticks, [f"{v:g}" for v in ticks])
            a.minorticks_off()
        a.legend(fontsize=8)
    fig.suptitle("Bumps on both edges: spacing and height (closed loop, contact model)")
    fig.tight_layout()
    paths.append(out_dir / "fig_edges_spacing_height.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    mid = 0.5 * cfg.row_length
    for phase, label in ((None, "front row only"), (0.0, "both, in phase"),
                         (0.5, "both, interleaved")):
        case = EdgeCase(label, "phase", cfg.spacing, cfg.height, phase)
        k = kinematic_lift(params, cfg, case)
        ss, y = 1e3 * k["_s"], 1e6 * k["_y"]
        ax[0].plot(ss, y, lw=0.9, label=label)
        near = np.abs(k["_s"] - mid) < 2.0 * cfg.spacing
        ax[1].plot(ss[near], y[near] - 1e6 * k["mean_lift"], lw=0.9, label=label)
    ax[0].set(xlabel="arc length along the row [mm]", ylabel="lift of the ball centre [um]",
              title="(a) over the reference row")
    ax[1].set(xlabel="arc length along the row [mm]", ylabel="lift less its mean [um]",
              title="(b) two spacings in its middle: the ripple")
    ax[0].legend(fontsize=8)
    fig.suptitle("Kinematic lift, rigid edges: y = (H_front + H_back) / 2")
    fig.tight_layout()
    paths.append(out_dir / "fig_edges_kinematic_lift.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
