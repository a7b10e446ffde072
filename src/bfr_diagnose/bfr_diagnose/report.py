"""Outputs of ``bfr diagnose``: PNG figures, a one-minute Markdown report, corrected YAML.

Everything is written into a temporary directory next to ``out_dir`` and moved into place
only when complete, so a failure never leaves half-written results over earlier ones.

Files: ``report.md``, ``diagnosis.json``, ``corrected_params.yaml`` (the plausible physics
only: a suspect never goes into it), ``sensor_model.yaml`` (each recording's measured sensor
timing and camera extrinsics; never physics), and figures (:func:`_plots`).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.params import params_to_ros_yaml

from bfr_diagnose.api import Diagnosis, PartResult
from bfr_diagnose.effects import DESTINATION, EFFECTS, display_values
from bfr_diagnose.grip import SlipLaw, creep_is_contact, creep_is_suspect
from bfr_diagnose.locate import phi_dot_misfit_by_place
from bfr_diagnose.synth import SynthConfig, stabilised_recording

__all__ = ["corrected_yaml", "format_text", "phi_dot_profiles", "sensor_yaml",
           "write_outputs"]

_UNITS = {"theta": "rad", "theta_dot": "rad/s", "ball_angle": "rad"}

#: The metrics' keys of the short-horizon predictions: from the smoothed state, and from the
#: state each model fits to the data before (locate.prediction_errors,
#: locate.causal_prediction_errors).
_PREDICTIONS = ("prediction", "prediction_causal")


def _prediction_start(pred: dict[str, Any]) -> str:
    """Where a prediction starts, in words (its ``start`` and ``fit_window``)."""
    if pred.get("start") == "fitted":
        return (f"from the state the model fits to the {pred['fit_window'] * 1e3:.0f} ms "
                "before")
    return "from the smoothed state"


def _ratio(a: float | None, b: float | None) -> float | None:
    """``a / b``, or None when either is missing or b is not positive."""
    return a / b if a is not None and b is not None and b > 0 else None


def _used(row: dict[str, Any]) -> str:
    """'yes', or 'no' with the reason a per-recording value was left out of the joint one."""
    if row.get("used"):
        return "yes"
    return "no" + (": " + row["degenerate"] if row.get("degenerate") else "")


def _num(x: Any, fmt: str = ".4g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return format(x, fmt)


def _sources(s: dict[str, Any]) -> str:
    src = s["source"]
    return ", ".join(Path(str(x)).name for x in src) if isinstance(src, list) else \
        Path(str(src)).name


def corrected_yaml(d: Diagnosis) -> str:
    """The corrected parameter file (loads with ``load_params``; simulator node format).

    The nominal parameters with the plausible effects only; suspects are listed in the
    header and left out.
    """
    s = d.summary
    lines = [
        "Corrected Butterfly rig parameters written by bfr diagnose.",
        f"Recordings: {_sources(s)} ({s['duration']:.1f} s).",
        f"Effects applied: {', '.join(s['effects']) or 'none (nominal model kept)'}.",
    ]
    for p in s["parameters"]:
        if p.get("plausible", True):
            lines.append(f"  {p['effect']}.{p['name']} = {p['value']:.6g} {p['unit']} "
                         f"(95 % CI {p['ci95'][0]:.4g} .. {p['ci95'][1]:.4g})")
    for name, why in s["suspects"].items():
        lines.append(f"NOT applied (suspect, physically implausible): {name}: {why}.")
    for rec in s["recordings"]:
        g = rec.get("grip", {})
        if g.get("verdict") == "slips" and g["slip_test"]["law"] == "coulomb":
            lines.append(f"{Path(rec['name']).name}: the ball slips (mu = "
                         f"{g['slip_test']['mu']:.3g}); contact.static_friction and "
                         "contact.dynamic_friction carry it for the contact model (the rigid "
                         "model cannot slip).")
        elif g.get("verdict") == "slips" and creep_is_contact(g["slip_test"]):
            lines.append(f"{Path(rec['name']).name}: the ball slips "
                         f"({SlipLaw.of(g['slip_test']).text()}); ball.creep_time carries it "
                         "for the rigid model the simulator runs (the median over the "
                         "recordings that creep).")
        elif g.get("verdict") == "slips":
            lines.append(f"NOT applied (suspect, physically implausible): "
                         f"{Path(rec['name']).name}: the ball's "
                         f"{SlipLaw.of(g['slip_test']).text()} ({_creep_why(g['slip_test'])}); "
                         "ball.creep_time stays 0.")
    for c in s["confounded"]:
        if c.get("kind") in ("pair", "sensor"):
            lines.append(f"Confounded: {' / '.join(c['effects'])} (only a combination is "
                         "identified).")
    lines.append("Sensor timing and camera extrinsics are in sensor_model.yaml (not physics).")
    return params_to_ros_yaml(d.corrected, "\n".join(lines))


def sensor_yaml(d: Diagnosis) -> str:
    """Each recording's measured sensor model (timing, camera extrinsics) as YAML.

    They describe the sensors of one recording, not the rig's physics, so they never
    enter rig.yaml.
    """
    s = d.summary
    out = ["# Sensor model of each recording, measured by bfr diagnose (not physics: rig.yaml",
           "# is unchanged by it). The camera logs (x, y) = scale Rot(rotation) true + offset;",
           "# a fix is latency_total old when it arrives; the true frame angle is the logged",
           "# one + theta_zero; the drive applies a logged torque torque_delay later; the",
           "# logged velocity lags the angle's rate by velocity_lag.", "recordings:"]
    lat0 = s["options"]["latency0"]
    for pr in d.parts:
        out.append(f"  - name: {json.dumps(pr.name)}")
        out.append(f"    kind: {pr.kind}")
        vals = {r["name"]: r for r in s["sensor_timing"] if r["recording"] == pr.name}
        for name, r in vals.items():
            v = r["value"] + (lat0 if name == "latency" else 0.0)
            key = "latency_total" if name == "latency" else name
            out.append(f"    {key}: {v:.6g}   # [{r['unit']}] 95 % CI "
                       f"{_num(r['ci95'][0] + (lat0 if name == 'latency' else 0.0))} .. "
                       f"{_num(r['ci95'][1] + (lat0 if name == 'latency' else 0.0))}")
        lag = pr.prep.info.get("velocity_lag")
        if lag is not None:
            out.append(f"    velocity_lag: {lag['lag_s']:.6g}   # [s] {lag.get('how', '')}")
    return "\n".join(out) + "\n"


def format_text(s: dict[str, Any]) -> str:
    """Short human-readable summary for the terminal."""
    out = [f"bfr diagnose: {_sources(s)} ({s['duration']:.1f} s)",
           f"verdict: {s['verdict']}"]
    out += [f"note: {n}" for n in s.get("notes", [])]
    for p in s["parameters"]:
        out.append(f"  {p['effect']:24s} {p['name']:6s} = {p['value']:.5g} {p['unit']} "
                   f"[{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]"
                   + ("" if p.get("plausible", True) else "  (suspect: implausible)"))
    for j in s.get("between_recordings", {}).get("joint", []):
        if j["recordings_used"] >= 2:
            out.append(f"  {j['effect']}.{j['name']}: between-recording sd {j['tau']:.3g}, "
                       f"interval with it [{j['ci95'][0]:.4g}, {j['ci95'][1]:.4g}] "
                       f"({j['recordings_used']} recordings)")
    for c in s["confounded"]:
        out.append(f"  {c.get('kind')}: {c['note']}")
    out.append("sensor model (per recording):")
    for r in s["sensor_timing"]:
        out.append(f"  {Path(r['recording']).name[:40]:40s} {r['name']:12s} {r['value']:.5g} "
                   f"{r['unit']}")
    for rec in s["recordings"]:
        m = rec["metrics"]
        h = m["heldout_rmse_over_noise"]
        out.append(f"{Path(rec['name']).name} ({rec['kind']}): held-out equation error / "
                   f"noise {h['before']:.3g} -> {h['after']:.3g} (x{h['improvement_factor']:.2f})")
        for key in _PREDICTIONS:
            if f"{key}_before" not in m:
                continue
            start = _prediction_start(m[f"{key}_before"])
            pb, pa = m[f"{key}_before"]["rmse"], m[f"{key}_after"]["rmse"]
            out.append(f"  {m[f'{key}_before']['horizon'] * 1e3:.0f} ms prediction RMSE "
                       f"{start}: " + ", ".join(
                           f"{k} {_num(pb[k], '.3g')} -> {_num(pa[k], '.3g')} "
                           f"(x{_num(_ratio(pb[k], pa[k]), '.3g')})"
                           for k in pb if _num(pb[k]) != "n/a"))
            if f"{key}_after_slip" in m:
                ps = m[f"{key}_after_slip"]["rmse"]["ball_angle"]
                law = _slip_label(rec["grip"]["slip_test"], m[f"{key}_after_slip"])
                out.append(f"    with the ball's slip ({law}, "
                           f"plausible effects only): ball_angle "
                           f"{_num(pb['ball_angle'], '.3g')} -> {_num(ps, '.3g')} "
                           f"(x{_num(_ratio(pb['ball_angle'], ps), '.3g')})")
        g = rec.get("grip", {})
        if g:
            out.append(f"  ball's grip: {g['verdict']}: {g['meaning']}")
    out.append(f"wall time {s['wall_time_s']:.1f} s")
    return "\n".join(out)


# -- the Markdown report ---------------------------------------------------------------------


def _nominal_values(d: Diagnosis) -> dict[tuple[str, str], float]:
    out = {}
    for name in d.summary["effects_selected"]:
        eff = EFFECTS[name]
        vals = display_values(eff, np.asarray(eff.start(d.base), float))
        for pn, v in zip(eff.names, vals, strict=True):
            out[(name, pn)] = float(v)
    return out


def _md_read(d: Diagnosis) -> list[str]:
    """What each reader used against what its source held (the read accounts)."""
    accounts = d.summary.get("read_accounts") or []
    if not accounts:
        return []
    L = ["## What was read", "",
         "| source | samples used / present | seconds used / present | lost | by cause |",
         "| --- | --- | --- | --- | --- |"]
    for a in accounts:
        causes = ", ".join(f"{k} {v}" for k, v in {**a["dropped"], **a["degraded"]}.items())
        sp = a["seconds_present"]
        L.append(f"| `{Path(a['source']).name}` | {a['samples_used']} / "
                 f"{'' if a['exact'] else '~'}{a['samples_present']} | "
                 f"{a['seconds_used']:.3f} / {'?' if sp is None else f'{sp:.3f}'} | "
                 f"{100 * a['lost_fraction']:.2f} % | {causes or 'none'} |")
    actions = [f"- `{Path(a['source']).name}`: {x}" for a in accounts for x in a["actions"]]
    return [*L, "", *actions, ""] if actions else [*L, ""]


def _md_physics(d: Diagnosis) -> list[str]:
    s = d.summary
    if not s["parameters"]:
        return []
    nominal = _nominal_values(d)
    joint = {(j["effect"], j["name"]): j for j in s["between_recordings"].get("joint", [])}
    L = ["## What the nominal model leaves out (one set of physics for the rig)", "",
         "| effect | parameter | fitted | 95 % CI (joint fit) | with the spread between "
         "recordings | nominal | unit | goes into | plausible |",
         "|---|---|---|---|---|---|---|---|---|"]
    for p in s["parameters"]:
        nom = nominal.get((p["effect"], p["name"]))
        j = joint.get((p["effect"], p["name"]))
        spread = (f"{_num(j['ci95'][0])} .. {_num(j['ci95'][1])} (sd {_num(j['tau'], '.2g')}, "
                  f"{j['recordings_used']} rec.)" if j and j["recordings_used"] >= 2 else "")
        L.append(f"| {p['effect']} | {p['name']} | {p['value']:.4g} | "
                 f"{_num(p['ci95'][0])} .. {_num(p['ci95'][1])} | {spread} | "
                 f"{_num(nom) if nom is not None else ''} | {p['unit']} | "
                 f"{DESTINATION.get(p['effect'], '')} | "
                 f"{'yes' if p.get('plausible', True) else '**no: suspect**'} |")
    L.append("")
    per = s["between_recordings"].get("per_recording", [])
    if per:
        L += ["Per recording (each selected effect fitted on that recording alone; 'used' = "
              "counted in the spread):", "",
              "| recording | effect | parameter | value | 95 % CI | used |",
              "|---|---|---|---|---|---|"]
        for r in per:
            L.append(f"| {Path(r['recording']).name} | {r['effect']} | {r['name']} | "
                     f"{r['value']:.4g} | {_num(r['ci95'][0])} .. {_num(r['ci95'][1])} | "
                     f"{_used(r)} |")
        L.append("")
    return L


def _md_sensors(d: Diagnosis) -> list[str]:
    s = d.summary
    lat0 = s["options"]["latency0"]
    L = ["## Sensor timing and camera, measured on each recording (not physics)", "",
         "Prior: the camera's calibration prior (nominal +- one sd), the value's pull in prior "
         "widths and its posterior sd over the prior's (near 1: the prior, not the data, "
         "holds it).", "",
         "| recording | quantity | value | 95 % CI | unit | prior | pull | post./prior |",
         "|---|---|---|---|---|---|---|---|"]
    for r in s["sensor_timing"]:
        add = lat0 if r["name"] == "latency" else 0.0
        name = "camera latency (total)" if r["name"] == "latency" else r["description"]
        if r.get("at_bound") is not None:
            name += " (**at its bound: not identified**)"
        pr = r.get("prior")
        prior = (f"{pr['nominal']:g} +- {pr['width']:g} | {r['pull']:+.2f} | "
                 f"{r['posterior_over_prior']:.2f}" if pr else " | | ")
        L.append(f"| {Path(r['recording']).name} | {name} | {r['value'] + add:.4g} | "
                 f"{_num(r['ci95'][0] + add)} .. {_num(r['ci95'][1] + add)} | {r['unit']} | "
                 f"{prior} |")
    for pr in d.parts:
        lag = pr.prep.info.get("velocity_lag")
        if lag is not None:
            L.append(f"| {Path(pr.name).name} | logged velocity's lag ({lag.get('how', '')}) | "
                     f"{lag['lag_s']:.4g} | {_num(lag.get('std_s'), '.2g')} (sd) | s |")
        clock = pr.prep.info.get("camera_clock")
        if clock is not None:
            L.append(f"| {Path(pr.name).name} | camera clock: {clock['reason']} | "
                     f"{_num(clock['residual_std_s'], '.3g')} (arrivals' scatter about it) | "
                     f"{_num(clock['line_wait_std_s'], '.3g')} (a line's wait) | s |")
    return [*L, ""]


def _md_fit(d: Diagnosis) -> list[str]:
    L = ["## Fit before / after (held-out blocks, never used for fitting)", "",
         "Before = the nominal physics with each recording's sensor model; after = the "
         "selected effects (suspects included, as fitted); raw = the nominal model with no "
         "sensor model at all.", "",
         "| recording | signal | nominal | corrected | ratio | Ljung-Box p nominal -> corr. |",
         "|---|---|---|---|---|---|"]
    for pr in d.parts:
        m = pr.summary["metrics"]
        for row, v in m["heldout_before"].items():
            a = m["heldout_after"][row]
            L.append(f"| {Path(pr.name).name} | {row} [{v['unit']}] | {v['rmse']:.3g} | "
                     f"{a['rmse']:.3g} | {v['rmse'] / max(a['rmse'], 1e-300):.3g} | "
                     f"{_num(v['whiteness']['p_value'], '.2g')} -> "
                     f"{_num(a['whiteness']['p_value'], '.2g')} |")
        for key in _PREDICTIONS:
            if f"{key}_before" not in m:
                continue
            start = _prediction_start(m[f"{key}_before"])
            pr_, pb, pa = (m[f"{key}_{k}"]["rmse"] for k in ("raw", "before", "after"))
            h = m[f"{key}_before"]["horizon"] * 1e3
            for k in pb:
                if pb[k] is None or not math.isfinite(pb[k]):
                    continue
                L.append(f"| {Path(pr.name).name} | {h:.0f} ms prediction {start}: {k} "
                         f"[{_UNITS[k]}] (raw {_num(pr_.get(k), '.3g')}) | "
                         f"{_num(pb[k], '.3g')} | {_num(pa[k], '.3g')} | "
                         f"{_num(_ratio(pb[k], pa[k]), '.3g')} | |")
            if f"{key}_after_slip" in m:
                ps = m[f"{key}_after_slip"]["rmse"]["ball_angle"]
                law = _slip_label(pr.summary["grip"]["slip_test"], m[f"{key}_after_slip"])
                L.append(f"| {Path(pr.name).name} | {h:.0f} ms prediction {start}: "
                         f"ball_angle [rad], plausible effects with the ball's slip "
                         f"({law}) | {_num(pb['ball_angle'], '.3g')} | "
                         f"{_num(ps, '.3g')} | {_num(_ratio(pb['ball_angle'], ps), '.3g')} | |")
    return [*L, ""]


def _creep_why(slip_test: dict[str, Any]) -> str:
    """Why a creep is not a contact's creep (:func:`bfr_diagnose.grip.creep_is_contact`)."""
    cs = slip_test.get("creep_slip", {})
    if cs.get("plausible") is None:
        return "its slip could not be measured"
    return (f"its spin lags rolling by a median {100 * cs['slip_ratio']['p50']:.0f} %: no "
            "contact creeps that far; a stand-in")


def _slip_label(slip_test: dict[str, Any], pred: dict[str, Any]) -> str:
    """The slip law of a prediction's row, and where a creeping spin's start comes from.

    Under creep the relative spin is a state no smoother measures: from a smoothed state it
    is the lag of the measured rolling rate before the start (:meth:`SlipLaw.spin`), from a
    fitted one a fifth unknown of the fit.
    """
    law = SlipLaw.of(slip_test)
    text = law.text() if law is not None else "rolling"
    if law is not None and law.states == 5:
        text += (", the spin the lag of the rolling rate before the start"
                 if pred.get("start") == "smoothed" else ", the spin fitted with the start")
    return text


def _md_grip(d: Diagnosis) -> list[str]:
    """The ball's grip: friction demand and slip test per recording (bfr_diagnose.grip)."""
    L = ["## The ball's grip: does it roll without slipping?", "",
         "Friction demand: the friction coefficient (on a plate edge) that rolling without "
         "slip needs along the recording under the corrected model. Slip test: the ball alone "
         "under the measured frame motion, 100 ms ahead of the state fitted to the 100 ms "
         "before each held-out window, rolling against the slip law the training windows "
         "chose: friction-limited rolling (Coulomb, mu) or linear creep (the spin's "
         "relaxation time tau_s; docs/diagnosis.md).", "",
         "| recording | demand p50 / p90 / p99 / max | where the max is | law chosen | "
         "ball [rad]: nominal, rolling -> slipping (ratio) | windows better / worse (p) | "
         "verdict |", "|---|---|---|---|---|---|---|"]
    for pr in d.parts:
        g = pr.summary.get("grip", {})
        fd, st = g.get("friction_demand", {}), g.get("slip_test")
        if "p50" not in fd:
            L.append(f"| {Path(pr.name).name} | | | | | | {g.get('verdict', 'not tested')}: "
                     f"{g.get('meaning', '')} |")
            continue
        where = f"t = {fd['t_max']:.2f} s, phi = {fd['phi_max_deg']:.0f} deg"
        cells = "| | |"
        mu = "rolling"
        if st:
            law = SlipLaw.of(st)
            mu = "rolling" if law is None else law.text()
            cells = (f"{st['ball_rmse_nominal_rolling']:.3g}, {st['ball_rmse_rolling']:.3g} -> "
                     f"{st['ball_rmse_slipping']:.3g} (x{st['improvement']:.2f}) | "
                     f"{st['windows_better']} / {st['windows_worse']} "
                     f"({st['p_value']:.1g}) |")
        if st and creep_is_suspect(st):
            mu += f" (a suspect: {_creep_why(st)})"
        L.append(f"| {Path(pr.name).name} | {fd['p50']:.3g} / {fd['p90']:.3g} / "
                 f"{fd['p99']:.3g} / {fd['max']:.3g} | {where} | {mu} | {cells} "
                 f"**{g['verdict']}** |")
    for pr in d.parts:
        ee = pr.summary.get("grip", {}).get("equation_error")
        if ee:
            frame = (f"; the frame's row {ee['frame_heldout_rolling']:.2f} -> "
                     f"{ee['frame_heldout_creep']:.2f}" if "frame_heldout_creep" in ee else "")
            L += ["", f"**{Path(pr.name).name}**, the creep by another method: the equation "
                  "error (no start, no integration; the spin the lag of the measured rolling "
                  "rate, docs/diagnosis.md) of the corrected model, the ball's row held out "
                  f"over its noise, rolling {ee['heldout_rolling']:.2f} -> creeping with "
                  f"tau_s = {ee['tau_s']:.2g} s {ee['heldout_creep']:.2f} (the selection "
                  f"with its suspects {ee['heldout_selection']:.2f}){frame}; on the training "
                  f"samples the ball's row is smallest at tau_s = {ee['tau_s_train']:.2g} s "
                  f"(rolling {ee['train_rolling']:.3g}, "
                  + ", ".join(f"{k} s {v:.3g}" for k, v in ee["train"].items()) + ")."]
    return [*L, ""]


def _md_held(d: Diagnosis) -> list[str]:
    """The ball's swing on a held frame: measured against each model (bfr_diagnose.held)."""
    held = [(Path(pr.name).name, pr.summary["held_frame"]) for pr in d.parts
            if (pr.summary.get("held_frame") or {}).get("measured")]
    if not held:
        return []
    L = ["## The ball on the held frame, in closed form", "",
         "With the frame held the ball's row is one conservative degree of freedom: where it "
         "rests (the lowest point of its centre's path), how that path curves there (the "
         "contour's curvature less the rolling radius) and how long a swing takes (that "
         "curvature and the spin's share of the ball's energy) are measured from the camera "
         "alone, and each model predicts them with no fit (bfr_diagnose.held). Positions as "
         "the camera reports them; periods per swing at the measured amplitude.", "",
         "| recording | | rest: distance from the shaft [mm] | path radius at rest [mm] | "
         "period, median [s] | measured / model period (median per swing) | spin share "
         "J_b / (m_b R^2) |",
         "|---|---|---|---|---|---|---|"]
    for name, h in held:
        m = h["measured"]
        per = "" if m["period_median"] is None else f"{m['period_median']:.3g}"
        cf = h.get("closed_form") or {}
        kap = ("" if not cf else f"{cf['spin_share']:.2f} [{cf['spin_share_ci95'][0]:.2f}, "
               f"{cf['spin_share_ci95'][1]:.2f}] (closed form)")
        L.append(f"| {name} | **measured** ({m['n_swings']} swings) | "
                 f"{m['rest_distance'] * 1e3:.1f} | {m['path_radius'] * 1e3:.0f} | {per} | | "
                 f"{kap} |")
        for label, md in h["models"].items():
            if "why" in md:
                L.append(f"| {name} | {label} | {md['why']} | | | | |")
                continue
            per = "" if md["period_median"] is None else f"{md['period_median']:.3g}"
            ratio = "" if md.get("period_ratio") is None else f"{md['period_ratio']:.2f}"
            L.append(f"| {name} | {label} | {md['rest_distance'] * 1e3:.1f} | "
                     f"{md['path_radius'] * 1e3:.0f} | {per} | {ratio} | "
                     f"{md['spin_share']:.2f} |")
        if cf and cf["rolling_radius_from_spin_share"] is not None:
            lo, hi = cf["spin_share_ci95"]
            L += ["", f"**{name}**, in closed form: each swing's period against a "
                  "frictionless bead's on the measured path at the swing's height gives the "
                  f"spin's share {cf['spin_share']:.2f} [{lo:.2f}, {hi:.2f}] (mean of "
                  f"{len(cf['spin_share_per_swing'])} swings, t interval; the camera's scale "
                  "taken as calibrated); with the nominal ball's J_b / m_b that is a rolling "
                  f"radius of {cf['rolling_radius_from_spin_share'] * 1e3:.1f} mm (nominal "
                  f"{cf['rolling_radius_nominal'] * 1e3:.1f} mm). The rest point, "
                  f"{(m['rest_distance'] - h['models']['nominal']['rest_distance']) * 1e3:+.1f}"
                  " mm from the nominal model's, would put R at "
                  f"{cf['rolling_radius_from_rest'] * 1e3:.1f} mm if the camera's offset and "
                  "the contour's height there were the nominal's.", ""]
    return [*L, ""]


def _md_where(d: Diagnosis) -> list[str]:
    L = ["## Where the nominal residual exceeds the noise", ""]
    for pr in d.parts:
        loc = pr.summary["located"]
        L.append(f"**{Path(pr.name).name}** ({pr.kind}):")
        for k, v in loc["global"].items():
            L.append(f"- {k}: RMS {v['rms_over_noise']:.3g} x noise, p = {v['p_value']:.2g}")
        L.append(f"- {len(loc['windows'])} of {loc['n_windows']} windows of 0.5 s exceed the "
                 "noise (Bonferroni 1 %)" + (": worst " + ", ".join(
                     f"{w['t0']:.1f}-{w['t1']:.1f} s" for w in loc["windows"][:5])
                     if loc["windows"] else "."))
        for r in loc["regions"][:6]:
            parts = [f"{k} {r[k]['rms_over_noise']:.3g}x" for k in r["signals"]]
            L.append(f"- region {r['region']}: " + ", ".join(parts))
        L.append("")
    return L


def _md_ranking(d: Diagnosis) -> list[str]:
    s = d.summary
    L = ["## Ranking: every effect alone (stage 1), and the stage that selected it", "",
         "| effect | alone: held-out gain | null threshold | dBIC | selected at stage | "
         "there: gain | threshold | dBIC |", "|---|---|---|---|---|---|---|---|"]
    for r in s["ranking"]:
        lin = " (linearised)" if r.get("fit", "full") != "full" else ""
        deg = f" (degenerate: {r['degenerate']})" if r.get("degenerate") else ""
        if r["selected"]:
            tail = (f"{r['stage_selected']} | {r['gain_at_selection']:.4f} | "
                    f"{r['threshold_at_selection']:.4f} | {r['dbic_at_selection']:.1f}")
        else:
            tail = "| | |"
        L.append(f"| {r['effect']} | {r['heldout_gain']:.4f}{lin}{deg} | {r['threshold']:.4f} | "
                 f"{r['dbic']:.1f} | {tail} |")
    L += ["", "Held-out gain: the fraction of the held-out cost an effect removes (with every "
          "recording's sensor model refitted with it); it must beat the largest gain the same "
          "fit reaches on pure noise (the null), lower the BIC by 6, be identifiable (not "
          "degenerate) and exceed its engineering floor. Of those, each stage adds the one "
          "with the lowest dBIC (the strongest evidence, its parameters counted; a plausible "
          "one before a suspect). An effect selected "
          "at a later stage is judged on top of the effects chosen before it.", ""]
    return L


def _markdown(d: Diagnosis, figs: list[str]) -> str:
    """The one-minute report: verdict, physics, sensors, fit, confounds, where, ranking."""
    s = d.summary
    L = [f"# Diagnosis of `{_sources(s)}`", "", f"**{s['verdict'][0].upper() + s['verdict'][1:]}"
         ".**", ""]
    for note in s.get("notes", []):
        L += [f"> {note}", ""]
    L += [f"- Recordings: {len(d.parts)} part(s), {s['duration']:.1f} s: "
          + "; ".join(f"{Path(pr.name).name} ({pr.kind}, {pr.summary['usable_s']:.1f} s usable)"
                      for pr in d.parts) + ".",
          f"- Noise-only null: {s['null']['source']}.", ""]
    L += _md_physics(d)
    creeps = [(Path(r["name"]).name, r["grip"]["slip_test"]) for r in s["recordings"]
              if r.get("grip", {}).get("verdict") == "slips"
              and creep_is_suspect(r["grip"]["slip_test"])]
    if s["suspects"] or creeps:
        L += ["## Suspects (fitted, physically implausible: not in corrected_params.yaml)", ""]
        L += [f"- **{n}**: {why}" for n, why in s["suspects"].items()]
        L += [f"- **the ball's creep** ({name}, {SlipLaw.of(st).text()}): {_creep_why(st)} "
              "(bfr_diagnose.grip, 6)" for name, st in creeps] + [""]
    pairs = [c for c in s["confounded"] if c.get("kind") in ("pair", "sensor")]
    degen = [c for c in s["confounded"] if c.get("kind") == "degenerate"]
    if pairs:
        L += ["## Confounded (only a combination is identified here)", ""]
        L += [f"- {c['note']}" for c in pairs] + [""]
    if degen:
        L += ["## Degenerate fits (not added)", ""]
        L += [f"- {c['note']}" for c in degen] + [""]
    L += (_md_read(d) + _md_sensors(d) + _md_fit(d) + _md_grip(d) + _md_held(d)
          + _md_where(d))
    L += _md_ranking(d)
    L += ["## Figures", ""] + [f"![{f}]({f})" for f in figs] + [""]
    L += ["Files: `corrected_params.yaml` (physics: run it with `bfr simulate --params` or as "
          "the simulator node's parameter file; suspects left out), `sensor_model.yaml` (each "
          "recording's timing and camera), `diagnosis.json`.", ""]
    return "\n".join(L)


# -- figures ---------------------------------------------------------------------------------


def _plots(d: Diagnosis, out: Path, progress: Callable[[str], None] | None = None
           ) -> list[str]:
    """Draw the report's figures into ``out``; returns their file names.

    Per recording ``residual_time_<k>.png`` and (with a ball) ``residual_phi_<k>.png`` and
    ``overlay_<k>.png``; ``ranking.png``; with a rolling ball ``phi_dot.png`` (the ball's
    speed along the frame: measured, nominal and corrected model in closed loop).
    """
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    names = []
    for k, pr in enumerate(d.parts):
        names.append(_plot_residual_time(plt, pr, out, k))
        if pr.prep.has_ball:
            names.append(_plot_residual_phi(plt, pr, out, k))
        names.append(_plot_overlay(plt, pr, out, k))
    names.append(_plot_ranking(plt, d, out))
    for k, pr in enumerate(d.parts):
        if (pr.summary.get("held_frame") or {}).get("measured"):
            names.append(_plot_held(plt, pr, out, k))
    rolling = [pr for pr in d.parts if pr.kind == "rolling"]
    if rolling:
        if progress:
            progress("phi_dot.png: nominal and corrected model in closed loop")
        names.append(_plot_phi_dot(plt, d, rolling[0], out))
    return names


def _plot_held(plt: Any, pr: PartResult, out: Path, k: int) -> str:
    """``held_<k>.png``: the ball on the held frame, measured and as each model predicts it.

    Its swings' periods against their amplitudes, and its centre's path about the rest point.
    """
    h = pr.summary["held_frame"]
    m = h["measured"]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    amp = np.array(m["amplitudes"]) * 1e3
    ax.plot(amp, np.array(m["periods"], float), "ko", label="measured")
    prep = pr.prep
    ok = prep.ball_ok & np.isfinite(prep.ball_xy[0])
    ax2.plot((prep.ball_xy[0][ok] - m["rest_x"]) * 1e3, (prep.ball_xy[1][ok] - m["rest_y"]) * 1e3,
             "k.", ms=1, label="measured")
    for label, md in h["models"].items():
        if "why" in md:
            continue
        ax.plot(amp, np.array([np.nan if p is None else p for p in md["periods"]]), "-",
                label=label)
        path = md.get("path")
        if path:
            ax2.plot(np.array(path["x"]) * 1e3, np.array(path["y"]) * 1e3, "-", label=label)
    ax.set_xlabel("swing amplitude (centre's horizontal excursion) [mm]")
    ax.set_ylabel("period [s]")
    ax.set_title(f"{Path(pr.name).name}: the ball's swings on the held frame")
    ax.legend(fontsize=8)
    ax2.set_xlabel("x - rest [mm]")
    ax2.set_ylabel("y - rest [mm]")
    ax2.set_title("the centre's path about its rest point")
    ax2.legend(fontsize=8)
    return _save(plt, fig, out, f"held_{k}.png")


def _rows_of(pr: PartResult) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    labels = {1: "frame torque row r1 [N m]", 2: "ball row r2 [N m]",
              3: "ball distance row r3 [m]"}
    return [(labels[r], pr.res_before.rows[r - 1], pr.res_after.rows[r - 1],
             float(pr.sigma[r - 1])) for r in pr.rows]


def _save(plt: Any, fig: Any, out: Path, name: str) -> str:
    """Lay out, write ``out / name`` at 90 dpi and close the figure; returns ``name``."""
    fig.tight_layout()
    fig.savefig(out / name, dpi=90)
    plt.close(fig)
    return name


def _plot_residual_time(plt: Any, pr: PartResult, out: Path, k: int) -> str:
    """Every row against time (nominal with the sensor model, corrected), windows red."""
    rows = _rows_of(pr)
    t0 = pr.prep.t[0]
    tk = pr.prep.t[pr.res_before.idx] - t0
    fig, axs = plt.subplots(len(rows), 1, figsize=(10, 2.4 * len(rows)), sharex=True,
                            squeeze=False)
    gap = np.diff(tk) > 3.0 * np.median(np.diff(tk)) if tk.size > 2 else np.zeros(0, bool)
    cut = np.nonzero(gap)[0] + 1

    def broken(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.insert(tk, cut, np.nan), np.insert(np.asarray(y, float), cut, np.nan)

    for ax, (label, r0, r1, sig) in zip(axs[:, 0], rows, strict=True):
        ax.plot(*broken(r0), lw=0.6, label="nominal")
        ax.plot(*broken(r1), lw=0.6, label="corrected")
        ax.axhspan(-2 * sig, 2 * sig, color="0.85", label="+-2 noise (null)")
        for w in pr.summary["located"]["windows"][:40]:
            ax.axvspan(w["t0"] - t0, w["t1"] - t0, color="r", alpha=0.08)
        ax.set_ylabel(label, fontsize=8)
    axs[0, 0].legend(loc="upper right", fontsize=8)
    axs[0, 0].set_title(f"{Path(pr.name).name} ({pr.kind})", fontsize=9)
    axs[-1, 0].set_xlabel("t [s] (red: windows exceeding the noise)")
    return _save(plt, fig, out, f"residual_time_{k}.png")


def _plot_residual_phi(plt: Any, pr: PartResult, out: Path, k: int) -> str:
    """Each row's mean in 5-degree bins of the ball's place ``phi``."""
    rows = _rows_of(pr)
    ph = np.mod(pr.res_before.phi[pr.res_before.idx], 2 * np.pi)
    ph1 = np.mod(pr.res_after.phi[pr.res_after.idx], 2 * np.pi)
    bins = np.linspace(0, 2 * np.pi, 73)
    fig, axs = plt.subplots(len(rows), 1, figsize=(10, 2.4 * len(rows)), sharex=True,
                            squeeze=False)
    for ax, (label, r0, r1, _sig) in zip(axs[:, 0], rows, strict=True):
        for p, r, name in ((ph, r0, "nominal"), (ph1, r1, "corrected")):
            idx = np.digitize(p, bins) - 1
            mean = np.array([np.nanmean(r[idx == i]) if np.any((idx == i) & np.isfinite(r))
                             else np.nan for i in range(72)])
            ax.plot(np.degrees(0.5 * (bins[1:] + bins[:-1])), mean, label=name)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_ylabel("mean " + label, fontsize=8)
    axs[0, 0].legend(fontsize=8)
    axs[-1, 0].set_xlabel("ball's place on the frame: contact angle phi mod 360 [deg]")
    return _save(plt, fig, out, f"residual_phi_{k}.png")


def _plot_overlay(plt: Any, pr: PartResult, out: Path, k: int) -> str:
    """100 ms predictions, nominal and corrected, over 3 s of the (corrected) measurement."""
    prep = pr.prep
    t0 = prep.t[0]
    key = "ball_angle" if prep.has_ball else "theta_dot"
    fig, ax = plt.subplots(figsize=(10, 3.2))
    tr_b = pr.pred_before.get("traces", [])
    tr_a = pr.pred_after.get("traces", [])
    if tr_b:
        tmid = tr_b[len(tr_b) // 2]["t"][0]
        lo, hi = tmid - 1.5, tmid + 1.5
        m = (prep.t >= lo) & (prep.t <= hi)
        for sensor, style, label in ((pr.sensor0, "k", "measured (sensor model, nominal "
                                                       "physics)"),
                                     (pr.sensor, "k--", "measured (sensor model, corrected "
                                                        "physics)")):
            ref = prep.psi_for(sensor)[0] if prep.has_ball else prep.theta_dot
            ax.plot(prep.t[m] - t0, ref[m], style, lw=1.0, label=label)
        for traces, colour, label in (
                (tr_b, "C0", "nominal 100 ms prediction (from the smoothed state)"),
                (tr_a, "C1", "corrected 100 ms prediction (from the smoothed state)")):
            shown = [tr for tr in traces if lo <= tr["t"][0] <= hi]
            for i, tr in enumerate(shown):
                ax.plot(np.array(tr["t"]) - t0, tr[key], colour, lw=1,
                        label=label if i == 0 else None)
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        ax.legend(uniq.values(), uniq.keys(), fontsize=7)
    ax.set_title(f"{Path(pr.name).name}", fontsize=9)
    ax.set_xlabel("t [s] (held-out block)")
    ax.set_ylabel("ball world angle [rad]" if prep.has_ball else "theta_dot [rad/s]")
    return _save(plt, fig, out, f"overlay_{k}.png")


def _plot_ranking(plt: Any, d: Diagnosis, out: Path) -> str:
    """Each effect's held-out gain alone against its null threshold; the stage selected."""
    rk = d.summary["ranking"]
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(rk) + 1.2))
    y = np.arange(len(rk))
    gains = [max(r["heldout_gain"], -0.05) for r in rk]
    ax.barh(y, gains, color=["C2" if r["selected"] else "C7" for r in rk])
    ax.scatter([r["threshold"] for r in rk], y, marker="|", color="r", s=200,
               label="null threshold")
    ax.set_yticks(y, [r["effect"] + (f" (stage {r['stage_selected']})" if r["selected"]
                                     else "") for r in rk])
    ax.invert_yaxis()
    ax.set_xlabel("held-out cost reduction of each effect alone (green: selected)")
    ax.legend(fontsize=8)
    return _save(plt, fig, out, "ranking.png")


@dataclass(frozen=True, kw_only=True)
class PhiDotProfiles:
    """The ball's speed along the frame, ``phi_dot`` in bins of ``phi mod pi``.

    Attributes
    ----------
    centres : ndarray
        Bin centres [rad].
    measured, nominal, corrected : ndarray
        Mean phi_dot per bin [rad/s]: the recording (through the corrected model's
        measurement model), and the nominal and corrected physics in closed loop with the
        nominal controller (NaN where no sample, or where that loop lost the ball).
    open_nominal, open_corrected : ndarray
        Under the recorded frame motion and torque, the RMS per bin [rad/s] of each model's
        phi_dot predicted open loop (the 100 ms after the state it fits to the 100 ms
        before, :func:`~bfr_diagnose.locate.causal_prediction_errors`) minus the measured
        phi_dot at the same instants (each in that model's contact angle; binned by the
        predicted phi). NaN where no held-out window reaches.
    open_slip : ndarray or None
        The same of the plausible effects with the ball's slip where the grip found it
        (``corrected_params.yaml``'s model and the slip law), else None.
    slip_law : str
        That law (``SlipLaw.text``), or "".
    notes : list of str
        What each closed loop did.
    """

    centres: np.ndarray
    measured: np.ndarray
    nominal: np.ndarray
    corrected: np.ndarray
    open_nominal: np.ndarray
    open_corrected: np.ndarray
    notes: list[str]
    open_slip: np.ndarray | None = None
    slip_law: str = ""

    def rms(self, which: str) -> float:
        """RMS difference [rad/s] of a profile from the measured one over the common bins."""
        a = getattr(self, which)
        ok = np.isfinite(a) & np.isfinite(self.measured)
        return float(np.sqrt(np.mean((a[ok] - self.measured[ok]) ** 2))) if ok.any() else \
            float("nan")


def phi_dot_profiles(d: Diagnosis, pr: PartResult, duration: float = 15.0,
                     n_bins: int = 36) -> PhiDotProfiles:
    """The ball's speed along the frame: measured, and simulated with either physics.

    Closed loop: the simulations run the node suite's controller on its nominal model (as
    on the rig) against the nominal plant and against the corrected plant
    (:attr:`Diagnosis.corrected`: the plausible effects), started on the controller's
    orbit; the first 3 s are dropped. The rig's own controller is not this one, so the
    closed-loop profiles compare orbits, not physics alone. Open loop: under the recorded
    frame motion and torque, each model's misfit of phi_dot 100 ms ahead
    (:func:`~bfr_diagnose.locate.phi_dot_misfit_by_place`), where the physics alone differ.
    """
    edges = np.linspace(0.0, np.pi, n_bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])

    def profile(phi: np.ndarray, phid: np.ndarray) -> np.ndarray:
        ok = np.isfinite(phi) & np.isfinite(phid)
        k = np.digitize(np.mod(phi[ok], np.pi), edges) - 1
        v = phid[ok]
        return np.array([float(np.mean(v[k == i])) if np.any(k == i) else np.nan
                         for i in range(n_bins)])

    mask = pr.prep.ball_ok
    measured = profile(np.where(mask, pr.res_after.phi, np.nan),
                       np.where(mask, pr.res_after.phi_dot, np.nan))
    notes = []
    sims = {}
    for label, plant in (("nominal", d.base), ("corrected", d.corrected)):
        rec = stabilised_recording(plant, d.base, SynthConfig(duration=duration, phase=0.3),
                                   np.random.default_rng(1), source=f"{label} closed loop")
        keep = rec.t >= rec.t[0] + 3.0
        sims[label] = profile(rec.phi_true[keep], rec.phi_dot_true[keep])
        notes.append(f"{label} physics in closed loop: "
                     + ("the ball kept rolling" if rec.meta["ball_rolled"] else
                        "the nominal controller lost the ball (profile until then)")
                     + f", mean phi_dot {rec.meta['loop']['mean_phi_dot']:.3f} rad/s")
    return PhiDotProfiles(centres=centres, measured=measured, nominal=sims["nominal"],
                          corrected=sims["corrected"],
                          open_nominal=phi_dot_misfit_by_place(
                              pr.pred_causal_before, pr.res_before.phi_dot, pr.prep.t, edges),
                          open_corrected=phi_dot_misfit_by_place(
                              pr.pred_causal_after, pr.res_after.phi_dot, pr.prep.t, edges),
                          open_slip=(None if pr.pred_causal_slip is None else
                                     phi_dot_misfit_by_place(pr.pred_causal_slip,
                                                             pr.res_after.phi_dot, pr.prep.t,
                                                             edges)),
                          slip_law=(_slip_label(pr.summary["grip"]["slip_test"],
                                                pr.pred_causal_slip)
                                    if pr.pred_causal_slip is not None else ""),
                          notes=notes)


def _plot_phi_dot(plt: Any, d: Diagnosis, pr: PartResult, out: Path) -> str:
    """``phi_dot.png``: the ball's speed along the frame (:func:`phi_dot_profiles`).

    Top: measured and closed-loop profiles. Bottom: the open-loop misfit of each model
    under the recorded frame motion (the physics alone).
    """
    prof = phi_dot_profiles(d, pr)
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6.4), sharex=True)
    deg = np.degrees(prof.centres)
    ax.plot(deg, prof.measured, "k.-", label=f"measured ({Path(pr.name).name})")
    ax.plot(deg, prof.nominal, "C0-", label=f"nominal model in closed loop (rms diff. "
                                             f"{prof.rms('nominal'):.3f} rad/s)")
    ax.plot(deg, prof.corrected, "C1-", label=f"corrected model in closed loop (rms diff. "
                                               f"{prof.rms('corrected'):.3f} rad/s)")
    ax.set_ylabel("phi_dot [rad/s]")
    ax.set_title("the ball's speed along the frame (closed loop: bfr's controller, not the "
                 "rig's)", fontsize=9)
    ax.legend(fontsize=7)
    lines = [(prof.open_nominal, "C0", "nominal", "nominal physics"),
             (prof.open_corrected, "C1", "corrected", "corrected physics")]
    if prof.open_slip is not None:
        lines.append((prof.open_slip, "C2", "slip",
                      f"plausible effects with the ball's slip ({prof.slip_law})"))
    rms_open = {k: _finite(float(np.sqrt(np.nanmean(v ** 2)))) if np.isfinite(v).any()
                else None for v, _, k, _ in lines}
    for v, colour, key, label in lines:
        over = rms_open[key]
        ax2.plot(deg, v, colour + ".-", label=f"{label} (rms over bins "
                 + (f"{over:.3f}" if over is not None else "n/a") + " rad/s)")
    ax2.set_ylabel("RMS predicted - measured\nphi_dot [rad/s]")
    ax2.set_title("under the recorded frame motion: phi_dot 100 ms ahead of the state each "
                  "model fits (held-out windows)", fontsize=9)
    ax2.set_xlabel("ball's place on the frame: contact angle phi mod 180 [deg]")
    ax2.legend(fontsize=7)
    d.findings.setdefault("phi_dot_profile", {
        "recording": pr.name, "phi_deg": deg.tolist(),
        "measured": [_finite(v) for v in prof.measured],
        "nominal": [_finite(v) for v in prof.nominal],
        "corrected": [_finite(v) for v in prof.corrected],
        "rms_nominal": _finite(prof.rms("nominal")),
        "rms_corrected": _finite(prof.rms("corrected")),
        "open_loop_misfit_nominal": [_finite(v) for v in prof.open_nominal],
        "open_loop_misfit_corrected": [_finite(v) for v in prof.open_corrected],
        "open_loop_rms_nominal": rms_open["nominal"],
        "open_loop_rms_corrected": rms_open["corrected"],
        **({"open_loop_misfit_slip": [_finite(v) for v in prof.open_slip],
            "open_loop_rms_slip": rms_open["slip"], "slip_law": prof.slip_law}
           if prof.open_slip is not None else {}),
        "notes": prof.notes})
    return _save(plt, fig, out, "phi_dot.png")


def _finite(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def json_text(d: Diagnosis, indent: int | None = None) -> str:
    """``d.to_json()`` as strict JSON.

    A value that is not finite (an interval of a parameter the data do not constrain, a
    metric without samples) is ``null``: Python's ``NaN`` / ``Infinity`` are not JSON.
    """

    def clean(x: Any) -> Any:
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, (float, np.floating)):
            return _finite(float(x))
        return x

    return json.dumps(clean(d.to_json()), indent=indent, default=str, allow_nan=False)


def write_outputs(d: Diagnosis, out_dir: Path, plots: bool = True,
                  progress: Callable[[str], None] | None = None) -> Path:
    """Write report.md, diagnosis.json, the YAML files and PNGs atomically into out_dir."""
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the result is an ordinary dir
    try:
        figs = _plots(d, tmp, progress) if plots else []
        (tmp / "report.md").write_text(_markdown(d, figs))
        (tmp / "diagnosis.json").write_text(json_text(d, indent=1))
        (tmp / "corrected_params.yaml").write_text(corrected_yaml(d))
        (tmp / "sensor_model.yaml").write_text(sensor_yaml(d))
        if out_dir.exists():
            old = parent / f".{out_dir.name}.old-{os.getpid()}"
            out_dir.rename(old)
            tmp.rename(out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir

