"""``bfr analyze``: the seed's perturbation study, printed next to the seed's figures.

Subcommands::

    bfr analyze energy [RECORDING ...] [--corrected PATH ...] [--diagnose] [--json] ...
    bfr analyze bounce [--json] [--out-dir DIR] [--params YAML] [--study YAML] [--no-contact]
    bfr analyze edges  [--json] [--out-dir DIR] [--quick] ...
    bfr analyze rough  --count N --seed S --out YAML [--phi-range A B] ...

``energy`` (seed chapter 2) and ``bounce`` (chapter 3, chapter 4's closest point and
recommendation 1) evaluate a closed-loop run of the nominal controller on the nominal rigid
plant (``bfr_control``), print our figures next to the seed's with the relative difference,
save PNG plots like the seed's figures (``--out-dir``, default ``analysis_out``), and with
``--json`` print one JSON document instead of the table. ``energy RECORDING...`` does the
seed's recommendation 2 on real recordings instead (:mod:`.recorded`): motor work against
the ideal energy input, their discrepancy per turn and over the run beside the chapter-2
energies, and again with ``bfr diagnose``'s correction (``--corrected`` file or output
folder, or ``--diagnose`` to run it). ``edges`` answers the seed's recommendation 3 with the
two-edge contact model (:mod:`.edges`). ``rough`` draws a seeded rough surface into a
parameter file. Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from bfr_diagnose.cli import main as diagnose_main
from bfr_model.io import account_line, read_recording
from bfr_model.io.output import atomic_file
from bfr_model.params import ParameterError, load_params
from bfr_model.perturbations import load_study, rough_track, with_asperities, write_params

from bfr_tools.analysis.bounce import (
    SEED,
    bounce_analysis,
    contact_row_runs,
    contact_rtf,
    plot_bounce,
    taylor_error,
)
from bfr_tools.analysis.edges import plot_edges, two_edge_study
from bfr_tools.analysis.energy import closed_loop_check, energy_analysis, plot_energy
from bfr_tools.analysis.recorded import analyze_recording, plot_recorded
from bfr_tools.analysis.trajectory import closed_loop_rigid, progress

__all__ = ["main"]


def _rel(ours: float | None, seed: float | None) -> str:
    if ours is None or seed is None or seed == 0 or not math.isfinite(ours):
        return "n/a"
    return f"{100.0 * (ours - seed) / seed:+.0f} %"


def _fmt(v: Any) -> str:
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _clean(obj: Any) -> Any:
    """JSON-ready copy: private keys (``_...``) dropped, numpy scalars converted."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _emit(args: argparse.Namespace, doc: dict, table: Any) -> int:
    """Print ``doc`` as one JSON document (``--json``) or as ``table(doc)``; exit code 0."""
    print(json.dumps(_clean(doc), indent=1) if args.json else table(doc))
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--params", type=Path, help="rig parameter YAML (default: rig.yaml)")
    p.add_argument("--study", type=Path,
                   help="study settings YAML (default: perturbation_study.yaml)")
    p.add_argument("--out-dir", type=Path, default=Path("analysis_out"),
                   help="folder for the PNG plots (default: analysis_out)")
    p.add_argument("--no-plots", action="store_true", help="do not save plots")
    p.add_argument("--duration", type=float, help="closed-loop run length [s] (study: 10)")
    p.add_argument("--json", action="store_true", help="print one JSON document")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr analyze``."""
    p = argparse.ArgumentParser(
        prog="bfr analyze",
        description="The seed thesis' perturbation study (Knol 2016), rebuilt: energy and "
                    "energy fluctuation of each perturbation (energy), bounces, loss of "
                    "contact and slip over bumps with the discrete and the contact model "
                    "(bounce), bumps on both plate edges (edges), seeded rough tracks "
                    "(rough); with recordings, the motor's energy on real data (energy "
                    "RECORDING...).")
    sub = p.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("energy", help="seed chapter 2: energies, fluctuations, rankings; with "
                                      "recordings: recommendation 2 on real data")
    _common(e)
    e.add_argument("recordings", nargs="*", type=Path, metavar="RECORDING",
                   help="rig logs (.txt), CSV or ROS 2 bags: motor work against the ideal "
                        "energy input along each (default: a simulated closed-loop run)")
    e.add_argument("--allow-partial", action="store_true",
                   help="use a recording even when more than 1 %% of its samples could not be "
                        "read (the read's account on stderr says which)")
    e.add_argument("--corrected", nargs="+", type=Path, metavar="PATH",
                   help="bfr diagnose's correction: its corrected_params.yaml or its "
                        "--out-dir folder; one for all recordings or one per recording")
    e.add_argument("--diagnose", action="store_true",
                   help="run bfr diagnose on each recording for the correction (its outputs "
                        "go to OUT_DIR/diagnose_<name>)")
    e.add_argument("--closed-loop-check", action="store_true",
                   help="also run the closed loop with each perturbation in the plant")
    b = sub.add_parser("bounce", help="seed chapter 3: paths A/B/C, threshold, slip; "
                                      "contact model over rows of bumps")
    _common(b)
    b.add_argument("--no-contact", action="store_true",
                   help="skip the contact-model runs (the discrete model only)")
    b.add_argument("--contact-duration", type=float, help="contact runs' length [s]")
    g = sub.add_parser("edges", help="seed recommendation 3: bumps on both plate edges, when "
                                     "they cancel and when they add (two-edge contact model)")
    _common(g)
    g.add_argument("--quick", action="store_true",
                   help="the phase sweep only (in phase, interleaved, front only), 3 s runs")
    r = sub.add_parser("rough", help="draw a seeded rough surface into a parameter file")
    r.add_argument("--params", type=Path, help="base parameter YAML (default: rig.yaml)")
    r.add_argument("--count", type=int, required=True, help="number of asperities")
    r.add_argument("--seed", type=int, default=0, help="generator seed")
    r.add_argument("--phi-range", type=float, nargs=2, default=(0.0, 2 * math.pi),
                   metavar=("FROM", "TO"), help="contour angle range [rad]")
    r.add_argument("--height", type=float, nargs=2, default=(1e-4, 5e-4),
                   metavar=("MIN", "MAX"), help="asperity heights [m]")
    r.add_argument("--width", type=float, nargs=2, default=(5e-5, 2e-4),
                   metavar=("MIN", "MAX"), help="asperity widths along the contour [m]")
    r.add_argument("--out", type=Path, required=True, help="parameter file to write")
    r.add_argument("--force", action="store_true",
                   help="replace an existing --out file (else refused, exit 2)")
    return p


def _setup(args: argparse.Namespace) -> tuple[Any, Any]:

    params = load_params(args.params)
    study = load_study(args.study)
    if args.duration:
        study = dataclasses.replace(study, run=dataclasses.replace(study.run,
                                                                   duration=args.duration))
    return params, study


def _run(params: Any, study: Any) -> Any:

    progress(f"closed loop, nominal controller on the nominal rigid plant, "
             f"{study.run.duration:g} s")
    traj = closed_loop_rigid(params, study, params)
    if not traj.info.get("ball_rolling", True):
        progress(f"warning: the ball stopped rolling at {traj.info.get('rolling_until')} s")
    return traj


# -- energy -------------------------------------------------------------------------------


def _energy(args: argparse.Namespace) -> int:

    params, study = _setup(args)
    if args.recordings:
        return _energy_recorded(args, params, study)
    if args.corrected or args.diagnose:
        raise ValueError("--corrected and --diagnose need recordings (RECORDING ...)")
    traj = _run(params, study)
    progress("energy terms (seed eqs. 2.1-2.15)")
    rep = energy_analysis(traj, params, study)
    fig = rep.figures()
    if args.closed_loop_check:
        fig["closed_loop_check"] = closed_loop_check(params, study, traj)
    if not args.no_plots:
        fig["plots"] = [str(p) for p in plot_energy(rep, args.out_dir)]
    return _emit(args, fig, _energy_table)


def _energy_table(fig: dict) -> str:
    tr = fig["trajectory"]
    ideal = fig["ideal"]
    lines = [
        "Energy analysis (seed chapter 2) along a "
        f"{tr['label']}: {tr['duration']:.1f} s, {tr['samples']} samples, start-up "
        f"{tr['settle']:g} s left out of peaks; mean phi_dot {_fmt(tr.get('mean_phi_dot'))}"
        " rad/s",
        "",
        f"Ideal system (eq. 2.1, Fig. 2.2): mean E_sys {ideal['mean_energy']:.4g} J, range "
        f"{ideal['energy_range']:.4g} J, peak |dE_sys/dt| {ideal['peak_fluctuation']:.4g} W,"
        f" mean |dE_sys/dt| {ideal['mean_abs_fluctuation']:.4g} W",
        f"Controller (motor) power: mean |u theta_dot| {ideal['controller_mean_abs_power']:.4g}"
        f" W, mean {ideal['controller_mean_power']:.3g} W",
        "",
        "Perturbations (Fig. 2.3-2.4; seed formulas / our exact counterparts):",
        f"  {'term':8s} {'peak E [J]':>22s} {'peak dE/dt [W]':>22s}  description",
    ]
    for sym, row in fig["terms"].items():
        s, e = row["seed"], row["exact"]
        pe = f"{s['peak_energy']:.3e}"
        pf = f"{s['peak_fluctuation']:.3e}"
        if abs(e["peak_energy"] - s["peak_energy"]) > 1e-12 * max(s["peak_energy"], 1e-300):
            pe += f" / {e['peak_energy']:.2e}"
            pf += f" / {e['peak_fluctuation']:.2e}"
        lines.append(f"  {sym:8s} {pe:>22s} {pf:>22s}  {row['title']}")
    lines += ["", "Ranking, large to small (the seed's seven perturbations):"]
    for what, key, skey in (("energy", "rank_energy", "seed_rank_energy"),
                            ("fluctuation", "rank_fluctuation", "seed_rank_fluctuation")):
        lines.append(f"  by {what:11s} ours (seed formulas): {', '.join(fig[key]['seed'])}")
        lines.append(f"  {'':14s} ours (exact):         {', '.join(fig[key]['exact'])}")
        lines.append(f"  {'':14s} seed:                 {', '.join(fig[skey])}")
    b = fig["bump"]
    sd = b["seed"]
    lines += [
        "",
        "Bump fluctuation estimate (eqs. 2.14-2.15):     ours        seed    rel. diff",
        f"  E_pot,max [J]                              {b['E_pot_max']:9.3g}  "
        f"{sd['E_pot_max']:9.3g}  {_rel(b['E_pot_max'], sd['E_pot_max']):>9s}",
        f"  s_dot average [m/s]                        {b['s_dot_avg']:9.3g}  "
        f"{'(~0.2)':>9s}  {_rel(b['s_dot_avg'], 0.2):>9s}",
        f"  T_bump [s]                                 {b['T_bump']:9.3g}",
        f"  dE_pot,bump [W]                            {b['dE_pot_bump']:9.3g}  "
        f"{sd['dE_pot_bump']:9.3g}  {_rel(b['dE_pot_bump'], sd['dE_pot_bump']):>9s}",
        f"  ratio to the largest other fluctuation     {b['ratio_to_largest_other']:9.3g}  "
        f"{sd['ratio_to_others']:9.3g}  "
        f"{_rel(b['ratio_to_largest_other'], sd['ratio_to_others']):>9s}",
        f"  ratio to all others combined               {b['ratio_to_sum_of_others']:9.3g}",
        f"  fraction of the controller's mean |power|  "
        f"{b['fraction_of_controller_power']:9.3g}  {sd['fraction_of_controller']:9.3g}  "
        f"{_rel(b['fraction_of_controller_power'], sd['fraction_of_controller']):>9s}",
        "  (the seed's s_dot ~0.2 m/s is implied by its 9e-4 W and 1.45e-5 J; see "
        "docs/perturbation-study.md for why the figures differ)",
    ]
    if "closed_loop_check" in fig:
        lines += ["", "Beyond the seed: each perturbation in the plant, nominal controller, "
                      "closed loop (after the start-up):",
                  f"  {'plant':9s} {'mean power [W]':>15s} {'d mean power':>13s} "
                  f"{'rms torque':>11s} {'mean phi_dot':>13s} rolling"]
        for k, v in fig["closed_loop_check"].items():
            state = "yes" if v["ball_rolling"] else (
                f"no: {v.get('failure')} at {_fmt(v.get('rolling_until'))} s")
            lines.append(f"  {k:9s} {v['mean_power']:15.4g} {v.get('d_mean_power', 0.0):13.3g} "
                         f"{v['rms_torque']:11.4g} {v['mean_phi_dot']:13.4g} {state}")
    if "plots" in fig:
        lines += ["", "Plots: " + ", ".join(fig["plots"])]
    return "\n".join(lines)


def _corrected_paths(args: argparse.Namespace) -> list[Path | None]:
    """The correction file of each recording: given, diagnosed here, or none."""
    n = len(args.recordings)
    if args.corrected and args.diagnose:
        raise ValueError("give --corrected or --diagnose, not both")
    if args.corrected:
        if len(args.corrected) not in (1, n):
            raise ValueError(f"--corrected: {len(args.corrected)} paths for {n} recordings "
                             "(give one for all or one per recording)")
        paths = list(args.corrected) * (n if len(args.corrected) == 1 else 1)
        out: list[Path | None] = []
        for p in paths:
            f = p / "corrected_params.yaml" if p.is_dir() else p
            if not f.is_file():
                raise ValueError(f"--corrected {p}: no such file"
                                 + (" (no corrected_params.yaml in the folder)"
                                    if p.is_dir() else ""))
            out.append(f)
        return out
    if not args.diagnose:
        return [None] * n
    out = []
    for rec in args.recordings:
        d = args.out_dir / f"diagnose_{rec.stem}"
        progress(f"bfr diagnose {rec} --out-dir {d}")
        with contextlib.redirect_stdout(io.StringIO()):  # its report is in d/report.md
            # its own folder under --out-dir, remade on every run (as the plots are)
            code = diagnose_main([str(rec), "--out-dir", str(d), "--no-plots", "--quiet",
                                  "--force",
                                  *(["--allow-partial"] if args.allow_partial else [])])
        if code != 0 or not (d / "corrected_params.yaml").is_file():
            raise ValueError(f"bfr diagnose failed on {rec} (exit {code}); run it alone to "
                             "see why")
        out.append(d / "corrected_params.yaml")
    return out


def _energy_recorded(args: argparse.Namespace, params: Any, study: Any) -> int:
    """``bfr analyze energy RECORDING...``: recommendation 2 on each recording."""
    for rec in args.recordings:
        if not rec.exists():
            raise ValueError(f"{rec}: no such file or directory")
    corrected = _corrected_paths(args)
    results = []
    for rec_path, cor_path in zip(args.recordings, corrected, strict=True):
        progress(f"energy along {rec_path}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # what the reader found is in its account
            rec = read_recording(rec_path, allow_partial=args.allow_partial)
        print(f"bfr analyze: {account_line([rec])}", file=sys.stderr, flush=True)
        cor = load_params(cor_path) if cor_path is not None else None
        res = analyze_recording(rec, params, study, cor, label=str(rec_path),
                                nominal_source=str(args.params or "rig.yaml"),
                                corrected_source=str(cor_path or ""))
        if not args.no_plots:
            res.figures["plots"] = [str(p) for p in
                                    plot_recorded(res, args.out_dir, rec_path.stem)]
        results.append(res.figures)
    return _emit(args, {"recordings": results},
                 lambda d: "\n\n".join(_recorded_table(f) for f in d["recordings"]))


def _recorded_table(f: dict) -> str:
    """The text report of one recording (``bfr analyze energy RECORDING``)."""
    n = f["nominal"]
    basis = n["basis"]
    lines = [
        f"Energy along {f['recording']} (seed recommendation 2): {f['analysed']:.1f} s of "
        f"{f['duration']:.1f} s in {f['segments']} segment(s), {f['frame_turns']:.2f} frame "
        f"turns, {'with' if f['has_ball'] else 'without'} the ball ({f['ball_note']})",
        f"  {'':26s} {'over the run':>13s} {f'per {basis} (mean +- std)':>26s}",
    ]

    def row(name: str, b: dict, key: str, total: str) -> str:
        r = b["rate"][key]
        per = (f"{r['mean']:+.3e} +- {r['std']:.1e}" if r["std"] is not None else
               f"{r['mean']:+.3e}" if r["mean"] is not None else "n/a")
        return f"  {name:26s} {b[total]:+13.4e} {per:>26s}"

    for b in (n, f.get("corrected")):
        if b is None:
            continue
        lines.append(f" {b['label']} model ({b['params']}):")
        lines.append(row("motor work W_m [J]", b, "motor_work", "motor_work"))
        lines.append(row("ideal input E_in [J]", b, "energy_in", "energy_in"))
        lines.append(row("model dissipation [J]", b, "dissipation", "model_dissipation"))
        lines.append(row("discrepancy [J]", b, "discrepancy", "discrepancy"))
        eq = b["equivalent"]
        alone = [f"joint Coulomb friction of {_fmt(v)} N m" if k == "joint_coulomb_torque"
                 else f"rolling resistance mu_rol = {_fmt(v)}" for k, v in eq.items()
                 if v is not None]
        lines.append(f"  mean power: motor {_fmt(b['mean_power']['motor'])} W, discrepancy "
                     f"{_fmt(b['mean_power']['discrepancy'])} W"
                     + (f"; alone it would take {' or '.join(alone)}" if alone else "")
                     + (f"; share left after the correction {_fmt(b['share_left'])}"
                        if "share_left" in b else ""))
    pt = f["perturbations"]
    lines += [f" Chapter-2 energies at the seed's magnitudes along the recording (loss per "
              f"{basis} {_fmt(pt['measured_loss'])} J, peak-to-peak about its trend "
              f"{_fmt(pt['measured_amplitude'])} J):",
              f"  {'term':8s} {f'per {basis} [J]':>14s} {'p-p [J]':>10s}  verdict"]
    for sym, r in pt["terms"].items():
        s = r["seed"]
        rate, amp = ((_fmt(s["rate"]), _fmt(s["amplitude"])) if r["applies"] else ("-", "-"))
        lines.append(f"  {sym:8s} {rate:>14s} {amp:>10s}  {r['verdict']}")
    if "plots" in f:
        lines.append(" Plots: " + ", ".join(f["plots"]))
    return "\n".join(lines)


# -- bounce -------------------------------------------------------------------------------


def _bounce(args: argparse.Namespace) -> int:


    params, study = _setup(args)
    if args.contact_duration:
        study = dataclasses.replace(study, contact_run=dataclasses.replace(
            study.contact_run, duration=args.contact_duration))
    traj = _run(params, study)
    progress("discrete impact model along the run (seed eqs. 3.1-3.16)")
    rep = bounce_analysis(traj, params, study)
    progress("seed's Taylor closest point against the exact solve (eqs. 4.33-4.37)")
    tay = taylor_error(traj, params)
    out: dict = {"seed": SEED, "discrete": rep, "taylor_closest_point": tay,
                 "trajectory": {"label": traj.label, **traj.info}}
    rows = None
    if not args.no_contact:
        progress("contact model: real-time factor in the simulator node's configuration")
        t0 = time.perf_counter()
        out["contact_rtf_node"] = contact_rtf(params)
        locations = {"C region": rep["phi_C_region_mod_pi"]}
        if rep["phi_B_region_mod_pi"] is not None:
            locations = {"B region": rep["phi_B_region_mod_pi"], **locations}
        rows = contact_row_runs(params, study, locations)
        out["contact_rows"] = rows
        out["contact_wall_time"] = time.perf_counter() - t0
    if not args.no_plots:
        out["plots"] = [str(p) for p in plot_bounce(rep, traj, args.out_dir, tay, rows)]
    return _emit(args, out, _bounce_table)


def _bounce_table(out: dict) -> str:
    s = out["seed"]
    d = out["discrete"]
    eh = d["energy_hinge"]
    lines = [
        f"Bounce analysis (seed chapter 3) along a {out['trajectory']['label']}, bump height "
        f"h = {d['bump_height']:g} m",
        f"  ball speed s_dot: mean {d['s_dot_mean']:.3g} m/s, max {d['s_dot_max']:.3g} m/s; "
        f"sqrt(g (R - h)) = {d['critical_speed']:.3g} m/s exceeded "
        f"{100 * d['fraction_above_critical_speed']:.0f} % of the time",
        "",
        "Discrete model (energy hinge, eqs. 3.1-3.16)      ours        seed    rel. diff",
        f"  path A (bounce higher than the bump) occurs {_fmt(d['path_A_occurs']):>9s}  "
        f"{_fmt(s['path_A_occurs']):>9s}",
        f"  threshold bump height for path B [m]      {_fmt(d['threshold_height']):>9s}  "
        f"{s['threshold_height']:9.3g}  {_rel(d['threshold_height'], s['threshold_height']):>9s}",
        f"  slip per bump (worst case, path B) [rad]  {eh['slip_per_bump_max']:9.3g}  "
        f"{s['slip_per_bump']:9.3g}  {_rel(eh['slip_per_bump_max'], s['slip_per_bump']):>9s}",
        f"  slip per bump, mean over path B [rad]     {eh['slip_per_bump_mean_B']:9.3g}",
        f"  region of path B per rotation [m]         {eh['region_B_per_rotation']:9.3g}  "
        f"{s['slip_region']:9.3g}  "
        f"{_rel(eh['region_B_per_rotation'], s['slip_region']):>9s}",
        f"  bumps in that region                      {eh['bumps_in_region']:9.3g}  "
        f"{s['bumps_in_region']:9.3g}  "
        f"{_rel(eh['bumps_in_region'], s['bumps_in_region']):>9s}",
        f"  slip per rotation (path B) [rad]          {eh['slip_per_rotation']:9.3g}  "
        f"{s['slip_per_rotation']:9.3g}  "
        f"{_rel(eh['slip_per_rotation'], s['slip_per_rotation']):>9s}",
        f"  region of path A per rotation [m]         {eh['region_A_per_rotation']:9.3g}  "
        f"{0.0:9.3g}",
        "",
        "Variants (beyond the seed):                 thresh. h  A region  B region  slip/bump"
        "  slip/rot(B)",
    ]
    for key, label in (("energy_hinge", "energy hinge (seed)"),
                       ("momentum_hinge", "momentum hinge"),
                       ("rotating_frame", "turning frame + gravity")):
        v = d[key]
        th = {"energy_hinge": d["threshold_height"],
              "momentum_hinge": d["threshold_height_momentum"],
              "rotating_frame": d["threshold_height_rotating"]}[key]
        lines.append(f"  {label:42s} {_fmt(th):>9s} {v['region_A_per_rotation']:9.3g} "
                     f"{v['region_B_per_rotation']:9.3g} {v['slip_per_bump_mean_B']:10.3g} "
                     f"{v['slip_per_rotation']:11.3g}")
    lines.append("  (threshold 0: at the run's top speed contact is lost over a bump of any "
                 "height)")
    t = out["taylor_closest_point"]
    lines += [
        "",
        "Closest point (seed eqs. 4.33-4.37) along the run, the seed's Taylor estimate vs the "
        "exact Newton solve:",
        f"  max |error| {t['max_abs_error_rad']:.3g} rad (rms {t['rms_error_rad']:.3g} rad, "
        f"up to {1e3 * t['max_arc_error_m']:.3g} mm along the contour) over "
        f"{t['samples']} samples; exact solve vs the known contact angle: "
        f"{t['exact_solve_max_error_rad']:.1e} rad",
    ]
    if "contact_rows" in out:
        rtf = out["contact_rtf_node"]
        rows = out["contact_rows"]
        lines += [
            "",
            f"Contact model: real-time factor {rtf['real_time_factor']:.3g} (wall; "
            f"{rtf['real_time_factor_cpu']:.3g} CPU) in the node's configuration "
            f"(step {rtf['time_step']:g} s, 1 kHz commands, smooth track)",
            "",
            "Contact model over rows of bumps, closed loop (seed recommendation 1); rows "
            "centred at " + ", ".join(f"{k} phi = {v:.3g} rad" for k, v in
                                      rows["locations"].items()) + " (and + pi):",
            f"  {'run':26s} {'bumps':>5s} {'rolling':>8s} {'slip/bump':>10s} "
            f"{'discrete':>9s} {'seed':>7s} {'slip/rot':>9s} {'seed':>6s} {'airborne':>9s} "
            f"{'RTF':>5s}",
        ]
        for name, r in rows["runs"].items():
            spb = r.get("slip_per_bump_mean")
            state = "yes" if r["ball_kept_rolling"] else f"lost@{r['rolling_until']:.2f}"
            lines.append(
                f"  {name:26s} {r['bumps']:5d} {state:>8s} "
                f"{_fmt(spb):>10s} {_fmt(r.get('discrete_slip_per_bump_mean')):>9s} "
                f"{(_fmt(s['slip_per_bump']) if r['bumps'] else ''):>7s} "
                f"{_fmt(r.get('slip_per_rotation')):>9s} "
                f"{(_fmt(s['slip_per_rotation']) if r['bumps'] else ''):>6s} "
                f"{_fmt(r.get('airborne_fraction')):>9s} "
                f"{r['plant_real_time_factor']:5.2g}")
        lines.append("  slip/bump: |int v_slip/R dt| over a passage of the row less the "
                     "baseline, per bump; discrete: the energy hinge at the same passages")
    if "plots" in out:
        lines += ["", "Plots: " + ", ".join(out["plots"])]
    return "\n".join(lines)


# -- edges --------------------------------------------------------------------------------


def _edges(args: argparse.Namespace) -> int:

    params, study = _setup(args)
    cfg = study.two_edge
    if args.duration:
        cfg = dataclasses.replace(cfg, duration=args.duration)
    if args.quick:
        cfg = dataclasses.replace(cfg, duration=min(cfg.duration, 3.0), phases=(0.0, 0.5),
                                  spacings=(), heights=())
        study = dataclasses.replace(study, run=dataclasses.replace(
            study.run, duration=min(study.run.duration, 4.0), settle=min(study.run.settle,
                                                                         1.0)))
    study = dataclasses.replace(study, two_edge=cfg)
    t0 = time.perf_counter()
    res = two_edge_study(params, study)
    res["wall_time"] = time.perf_counter() - t0
    if not args.no_plots:
        res["plots"] = [str(p) for p in plot_edges(res, params, study, args.out_dir)]
    return _emit(args, res, _edges_table)


def _edges_table(res: dict) -> str:
    """The text report of ``bfr analyze edges``."""
    c = res["settings"]
    lines = [
        "Bumps on both plate edges (seed recommendation 3), two-edge contact model in closed "
        f"loop, {c['duration']:g} s per run; rows of {1e3 * c['row_length']:g} mm centred at "
        f"phi = {res['location']:.3g} rad and + pi ({res['location_from']}); bumps sigma "
        f"{1e3 * c['width']:g} mm; phase = the back edge's row shifted by that fraction of "
        "the spacing (front only: no back row)",
        "",
        f"  {'case':38s} {'slip/turn':>9s} {'turns':>5s} {'airborne':>8s} {'max|z|':>7s} "
        f"{'lift':>6s} {'ripple':>7s} {'v_c':>5s}  rolling",
        f"  {'':38s} {'[rad]':>9s} {'':>5s} {'':>8s} {'[mm]':>7s} {'[um]':>6s} "
        f"{'[um]':>7s} {'[m/s]':>5s}",
    ]
    for r in res["runs"]:
        k = r["kinematic"]
        state = "yes" if r["ball_kept_rolling"] else f"lost at {r['rolling_until']:.2f} s"
        kin = (f"{1e6 * k['mean_lift']:6.0f} {1e6 * k['ripple']:7.1f} "
               f"{_fmt(k['critical_speed']):>5s}")
        if "slip_per_turn" not in r:
            lines.append(f"  {r['name']:38s} {'':>9s} {'':>5s} {'':>8s} {'':>7s} {kin}  "
                         f"{state}")
            continue
        lines.append(
            f"  {r['name']:38s} {r['excess_slip_per_turn']:+9.3f} {r['turns']:5.1f} "
            f"{r['airborne_fraction']:8.2f} {1e3 * r['max_abs_z']:7.3f} {kin}  {state}")
    lines += ["", "  slip/turn: int v_slip / R dt per frame turn after the start-up, less the "
                  "baseline's; turns: how many it rests on (two row passages each)",
              "  lift, ripple, v_c: rigid edges, quasi-static: the centre at (H_front + "
              "H_back) / 2 over the row (module bfr_tools.analysis.edges); v_c the speed "
              "above which the ball leaves the track over the row (flat track)",
              f"  wall time {res['wall_time']:.0f} s"]
    if "plots" in res:
        lines += ["", "Plots: " + ", ".join(res["plots"])]
    return "\n".join(lines)


# -- rough --------------------------------------------------------------------------------


def _rough(args: argparse.Namespace) -> int:

    params = load_params(args.params)
    rng = np.random.default_rng(args.seed)
    ph, h, w = rough_track(params, rng, args.count, tuple(args.phi_range), tuple(args.height),
                           tuple(args.width))
    p = with_asperities(params, ph, h, w)
    with atomic_file(args.out, args.force) as tmp:
        write_params(p, tmp, header=f"rough track: {args.count} asperities, seed {args.seed}"
                                    f" (bfr analyze rough)")
    print(f"wrote {args.out}: {args.count} asperities (track.asperity_*), heights "
          f"{h.min() if h.size else 0:.3g}..{h.max() if h.size else 0:.3g} m")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``bfr analyze``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    try:
        return {"energy": _energy, "bounce": _bounce, "edges": _edges,
                "rough": _rough}[args.cmd](args)
    except (ParameterError, ValueError, OSError) as exc:
        print(f"bfr analyze: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
