"""Outputs of ``bfr diagnose``: PNG figures, a one-minute Markdown report, corrected YAML.

Everything is written into a temporary directory next to ``out_dir`` and moved into place
only when complete, so a failure never leaves half-written results over earlier ones.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.params import params_to_ros_yaml

from bfr_diagnose.api import Diagnosis
from bfr_diagnose.effects import DESTINATION, EFFECTS, SENSOR_EFFECTS, display_values

__all__ = ["camera_yaml", "corrected_yaml", "format_text", "write_outputs"]


def _num(x: Any, fmt: str = ".4g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return format(x, fmt)


def corrected_yaml(d: Diagnosis) -> str:
    """The corrected parameter file (loads with ``load_params``; simulator node format)."""
    s = d.summary
    lines = [
        "Corrected Butterfly rig parameters written by bfr diagnose.",
        f"Recording: {s['source']} ({s['duration']:.1f} s).",
        f"Fitted effects: {', '.join(s['effects']) or 'none (nominal model kept)'}.",
    ]
    for p in s["parameters"]:
        lines.append(f"  {p['effect']}.{p['name']} = {p['value']:.6g} {p['unit']} "
                     f"(95 % CI {p['ci95'][0]:.4g} .. {p['ci95'][1]:.4g})"
                     + ("" if p.get("plausible", True) else " IMPLAUSIBLE: see report.md"))
    for c in s["confounded"]:
        if c.get("kind") != "degenerate":
            lines.append(f"Confounded: {' / '.join(c['effects'])} (only a combination is "
                         "identified).")
    sensor = [n for n in s["effects"] if n in SENSOR_EFFECTS]
    if sensor:
        lines.append(f"Sensor corrections fitted ({', '.join(sensor)}): see "
                     "camera_correction.yaml (camera parameters, not physics; not in this file).")
    return params_to_ros_yaml(d.selection.params, "\n".join(lines))


def camera_yaml(d: Diagnosis) -> str:
    """The fitted camera corrections (latency, origin offset) as a ROS 2 parameter file.

    They describe the sensor, not the rig's physics, so they never enter rig.yaml.
    """
    lat = d.summary["camera_latency"]
    off = d.summary["camera_offset"]
    return (
        "# Camera corrections fitted by bfr diagnose: the sensor model, not physics (rig.yaml\n"
        "# is unchanged by them). Fitted: "
        f"latency {'yes' if lat['fitted'] else 'no'}, offset {'yes' if off['fitted'] else 'no'}."
        "\n/**:\n  ros__parameters:\n    camera:\n"
        f"      latency: {lat['fitted_total']:.6g}   # [s] age of the image when its fix "
        f"arrives (nominal {lat['nominal']:.6g})\n"
        f"      origin_offset: [{off['x']:.6g}, {off['y']:.6g}]   # [m] the camera reports "
        "(x, y) = true + origin_offset;\n"
        "      # subtract it from the fixes (bfr_model.io.rig_log: camera_offset=(x, y)); for a\n"
        "      # camera looking along -z it is camera.position -= [x, y, 0] in camera.yaml\n")


def format_text(s: dict[str, Any]) -> str:
    """Short human-readable summary for the terminal."""
    out = [f"bfr diagnose: {s['source']} ({s['duration']:.1f} s, "
           f"{'with ball' if s['has_ball'] else 'frame only'})",
           f"verdict: {s['verdict']}"]
    out += [f"note: {n}" for n in s.get("notes", [])]
    for p in s["parameters"]:
        out.append(f"  {p['effect']:24s} {p['name']:6s} = {p['value']:.5g} {p['unit']} "
                   f"[{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]"
                   + ("" if p.get("plausible", True) else "  (implausible, see note)"))
    for c in s["confounded"]:
        out.append(f"  {'degenerate' if c.get('kind') == 'degenerate' else 'confounded'}: "
                   f"{c['note']}")
    m = s["metrics"]
    h = m["heldout_rmse_over_noise"]
    out.append(f"held-out equation error / noise: {h['before']:.3g} -> {h['after']:.3g} "
               f"(x{h['improvement_factor']:.2f})")
    for row, v in m["heldout_before"].items():
        a = m["heldout_after"][row]
        out.append(f"  {row:18s} RMSE {v['rmse']:.3g} -> {a['rmse']:.3g} N m; Ljung-Box p "
                   f"{_num(v['whiteness']['p_value'], '.2g')} -> "
                   f"{_num(a['whiteness']['p_value'], '.2g')}")
    pb, pa = m["prediction_before"]["rmse"], m["prediction_after"]["rmse"]
    out.append("  prediction RMSE (" + f"{m['prediction_before']['horizon'] * 1e3:.0f} ms): "
               + ", ".join(f"{k} {_num(pb[k], '.3g')} -> {_num(pa[k], '.3g')}" for k in pb))
    loc = s["located"]
    out.append(f"located: {len(loc['windows'])} of {loc['n_windows']} windows exceed the "
               "noise; regions: " + ("; ".join(r["region"] for r in loc["regions"][:4])
                                    or "none"))
    out.append(f"wall time {s['wall_time_s']:.1f} s")
    return "\n".join(out)


def _fmt_val(x: float) -> str:
    return f"{x:.4g}"


def _markdown(d: Diagnosis, figs: list[str]) -> str:
    """The one-minute report.

    Verdict, what is missing (values, CIs, where each goes), fit before/after, confounding,
    where the mismatch is, then the details.
    """
    s = d.summary
    m = s["metrics"]
    h = m["heldout_rmse_over_noise"]
    nominal = {}
    for name in s["effects"]:
        eff = EFFECTS[name]
        vals = display_values(eff, np.asarray(eff.start(d.base), float))
        for pn, v in zip(eff.names, vals, strict=True):
            nominal[(name, pn)] = float(v)
    L = [f"# Diagnosis of `{Path(str(s['source'])).name}`", "",
         f"**{s['verdict'][0].upper() + s['verdict'][1:]}.**", ""]
    for note in s.get("notes", []):
        L.append(f"> {note}")
        L.append("")
    L += [f"- Recording: {s['duration']:.1f} s, "
          f"{'ball rolling' if s['has_ball'] else 'frame only (no ball)'}; "
          f"{s['preprocessing'].get('ball')}.",
          f"- Held-out equation error, in units of the noise: {h['before']:.3g} with the "
          f"nominal model, {h['after']:.3g} corrected (x{h['improvement_factor']:.3g}).",
          f"- Noise-only null: {s['null']['source']}.", ""]
    if s["parameters"]:
        L += ["## What the nominal model leaves out", "",
              "| effect | parameter | fitted | 95 % CI | nominal | unit | goes into | "
              "plausible |", "|---|---|---|---|---|---|---|---|"]
        for p in s["parameters"]:
            nom = nominal.get((p["effect"], p["name"]))
            L.append(f"| {p['effect']} | {p['name']} | {_fmt_val(p['value'])} | "
                     f"{_num(p['ci95'][0])} .. {_num(p['ci95'][1])} | "
                     f"{_num(nom) if nom is not None else ''} | {p['unit']} | "
                     f"{DESTINATION.get(p['effect'], '')} | "
                     f"{'yes' if p.get('plausible', True) else '**no**'} |")
        L.append("")
    pairs = [c for c in s["confounded"] if c.get("kind") != "degenerate"]
    degen = [c for c in s["confounded"] if c.get("kind") == "degenerate"]
    if pairs:
        L += ["## Confounded (not separately identifiable here)", ""]
        L += [f"- {c['note']}" for c in pairs] + [""]
    if degen:
        L += ["## Degenerate fits (not added)", ""]
        L += [f"- {c['note']}" for c in degen] + [""]
    L += ["## Fit before / after (held-out blocks, never used for fitting)", "",
          "| signal | RMSE nominal | RMSE corrected | ratio | Ljung-Box p nominal | "
          "corrected |", "|---|---|---|---|---|---|"]
    for row, v in m["heldout_before"].items():
        a = m["heldout_after"][row]
        L.append(f"| {row} [N m] | {v['rmse']:.3g} | {a['rmse']:.3g} | "
                 f"{v['rmse'] / max(a['rmse'], 1e-300):.3g} | "
                 f"{_num(v['whiteness']['p_value'], '.2g')} | "
                 f"{_num(a['whiteness']['p_value'], '.2g')} |")
    for row, v in (m.get("located_windows") or {}).items():
        if v:
            L.append(f"| {row}, located windows only ({v['fraction_of_heldout'] * 100:.0f} % "
                     f"of held-out) | {v['rmse_before']:.3g} | {v['rmse_after']:.3g} | "
                     f"{v['improvement']:.3g} | | |")
    pb, pa = m["prediction_before"]["rmse"], m["prediction_after"]["rmse"]
    units = {"theta": "rad", "theta_dot": "rad/s", "ball_angle": "rad"}
    for k in pb:
        if pb[k] is None or not math.isfinite(pb[k]):
            continue
        ratio = pb[k] / pa[k] if pa[k] else float("nan")
        L.append(f"| {m['prediction_before']['horizon'] * 1e3:.0f} ms open-loop prediction "
                 f"{k} [{units[k]}] | {_num(pb[k], '.3g')} | {_num(pa[k], '.3g')} | "
                 f"{_num(ratio, '.3g')} | | |")
    L += ["", "## Where the nominal residual exceeds the noise", ""]
    loc = s["located"]
    for k, v in loc["global"].items():
        L.append(f"- {k}: RMS {v['rms_over_noise']:.3g} x noise, p = {v['p_value']:.2g}")
    L.append(f"- {len(loc['windows'])} of {loc['n_windows']} windows of 0.5 s exceed the "
             "noise (Bonferroni 1 %)" + (": worst " + ", ".join(
                 f"{w['t0']:.1f}-{w['t1']:.1f} s" for w in loc["windows"][:5])
                 if loc["windows"] else "."))
    for r in loc["regions"][:6]:
        parts = [f"{k} {r[k]['rms_over_noise']:.3g}x" for k in r["signals"]]
        L.append(f"- region {r['region']}: " + ", ".join(parts))
    L += ["", "## Ranking (each effect alone against the nominal model)", "",
          "| effect | held-out gain | null threshold | dBIC | selected |",
          "|---|---|---|---|---|"]
    for r in s["ranking"]:
        lin = " (linearised)" if r.get("fit", "full") != "full" else ""
        L.append(f"| {r['effect']} | {r['heldout_gain']:.4f}{lin} | {r['threshold']:.4f} | "
                 f"{r['dbic']:.1f} | {'yes' if r['selected'] else ''} |")
    L += ["", "Held-out gain: the fraction of the held-out cost an effect removes; it must beat "
          "the largest gain the same fit reaches on pure noise (the null) and lower the BIC by "
          "6. Effects far below their threshold after a linearised screening are not fitted "
          "further.", ""]
    L += ["## Figures", ""] + [f"![{f}]({f})" for f in figs] + [""]
    L += ["Files: `corrected_params.yaml` (physics: run it with `bfr simulate --params` or as "
          "the simulator node's parameter file), `camera_correction.yaml` (sensor: latency, "
          "origin offset), `diagnosis.json`.", ""]
    return "\n".join(L)


def _plots(d: Diagnosis, out: Path) -> list[str]:
    """Draw the report's figures into ``out``; returns their file names.

    ``residual_time.png``, ``residual_phi.png`` (with a ball), ``overlay.png`` and
    ``ranking.png`` (docs/diagnosis.md).
    """
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    rows = _plot_rows(d)
    names = [_plot_residual_time(plt, d, rows, out)]
    if d.prep.has_ball:
        names.append(_plot_residual_phi(plt, d, rows, out))
    names.append(_plot_overlay(plt, d, out))
    names.append(_plot_ranking(plt, d, out))
    return names


@dataclass(frozen=True, kw_only=True, eq=False)
class _PlotRow:
    """One equation row as plotted: label, nominal and corrected residual, noise scale."""

    label: str
    nominal: np.ndarray       # [N m]
    corrected: np.ndarray     # [N m]
    sigma: float              # [N m] the null's noise scale


def _plot_rows(d: Diagnosis) -> list[_PlotRow]:
    """The frame's torque row, and the ball's row when the recording has a ball."""
    rows = [_PlotRow(label="frame torque row r1 [N m]", nominal=d.res_before.r1,
                     corrected=d.res_after.r1, sigma=d.null.sigma[0])]
    if d.prep.has_ball:
        rows.append(_PlotRow(label="ball row r2 [N m]", nominal=d.res_before.r2,
                             corrected=d.res_after.r2, sigma=d.null.sigma[1]))
    return rows


def _save(plt: Any, fig: Any, out: Path, name: str) -> str:
    """Lay out, write ``out / name`` at 90 dpi and close the figure; returns ``name``."""
    fig.tight_layout()
    fig.savefig(out / name, dpi=90)
    plt.close(fig)
    return name


def _plot_residual_time(plt: Any, d: Diagnosis, rows: list[_PlotRow], out: Path) -> str:
    """``residual_time.png``: both rows against time, the windows exceeding the noise red."""
    t0 = d.prep.t[0]
    tk = d.prep.t[d.res_before.idx] - t0
    fig, axs = plt.subplots(len(rows), 1, figsize=(10, 2.6 * len(rows)), sharex=True,
                            squeeze=False)
    # break the lines where samples are missing (ball gaps, stitched runs)
    gap = np.diff(tk) > 3.0 * np.median(np.diff(tk)) if tk.size > 2 else np.zeros(0, bool)
    cut = np.nonzero(gap)[0] + 1

    def broken(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.insert(tk, cut, np.nan), np.insert(np.asarray(y, float), cut, np.nan)

    for ax, row in zip(axs[:, 0], rows, strict=True):
        ax.plot(*broken(row.nominal), lw=0.6, label="nominal")
        ax.plot(*broken(row.corrected), lw=0.6, label="corrected")
        ax.axhspan(-2 * row.sigma, 2 * row.sigma, color="0.85", label="+-2 noise (null)")
        for w in d.summary["located"]["windows"][:40]:
            ax.axvspan(w["t0"] - t0, w["t1"] - t0, color="r", alpha=0.08)
        ax.set_ylabel(row.label)
    axs[0, 0].legend(loc="upper right", fontsize=8)
    axs[-1, 0].set_xlabel("t [s] (red: windows exceeding the noise)")
    return _save(plt, fig, out, "residual_time.png")


def _plot_residual_phi(plt: Any, d: Diagnosis, rows: list[_PlotRow], out: Path) -> str:
    """``residual_phi.png``: each row's mean in 5-degree bins of the ball's place ``phi``."""
    ph = np.mod(d.res_before.phi[d.res_before.idx], 2 * np.pi)
    ph1 = np.mod(d.res_after.phi[d.res_after.idx], 2 * np.pi)
    bins = np.linspace(0, 2 * np.pi, 73)
    fig, axs = plt.subplots(len(rows), 1, figsize=(10, 2.6 * len(rows)), sharex=True,
                            squeeze=False)
    for ax, row in zip(axs[:, 0], rows, strict=True):
        for p, r, name in ((ph, row.nominal, "nominal"), (ph1, row.corrected, "corrected")):
            k = np.digitize(p, bins) - 1
            mean = np.array([np.nanmean(r[k == i]) if np.any(k == i) else np.nan
                             for i in range(72)])
            ax.plot(np.degrees(0.5 * (bins[1:] + bins[:-1])), mean, label=name)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_ylabel("mean " + row.label)
    axs[0, 0].legend(fontsize=8)
    axs[-1, 0].set_xlabel("ball's place on the frame: contact angle phi mod 360 [deg]")
    return _save(plt, fig, out, "residual_phi.png")


def _plot_overlay(plt: Any, d: Diagnosis, out: Path) -> str:
    """``overlay.png``: 100 ms predictions, nominal and corrected, over 3 s of measurement.

    The ball's world angle (or, frame only, theta_dot) around the middle prediction; with a
    fitted camera correction also the corrected measurement the corrected model predicts.
    """
    prep = d.prep
    t0 = prep.t[0]
    key = "ball_angle" if prep.has_ball else "theta_dot"
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ref = prep.psi_w if prep.has_ball else prep.theta_dot
    tr_b = d.pred_before.get("traces", [])
    tr_a = d.pred_after.get("traces", [])
    if tr_b:
        tmid = tr_b[len(tr_b) // 2]["t"][0]
        lo, hi = tmid - 1.5, tmid + 1.5
        m = (prep.t >= lo) & (prep.t <= hi)
        ax.plot(prep.t[m] - t0, ref[m], "k", lw=1.2, label="measured (smoothed)")
        sensor = d.selection.sensor
        if prep.has_ball and (sensor.latency != 0.0 or sensor.has_offset):
            # the corrected model is compared with the camera-corrected measurement
            ref_c = prep.psi_for(sensor)[0]
            ax.plot(prep.t[m] - t0, ref_c[m], "k--", lw=1.0,
                    label="measured, camera corrected (compare with the corrected model)")
        for traces, colour, label in ((tr_b, "C0", "nominal 100 ms prediction"),
                                      (tr_a, "C1", "corrected 100 ms prediction")):
            shown = [tr for tr in traces if lo <= tr["t"][0] <= hi]
            for i, tr in enumerate(shown):
                ax.plot(np.array(tr["t"]) - t0, tr[key], colour, lw=1,
                        label=label if i == 0 else None)
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        ax.legend(uniq.values(), uniq.keys(), fontsize=8)
    ax.set_xlabel("t [s] (held-out block)")
    ax.set_ylabel("ball world angle [rad]" if prep.has_ball else "theta_dot [rad/s]")
    return _save(plt, fig, out, "overlay.png")


def _plot_ranking(plt: Any, d: Diagnosis, out: Path) -> str:
    """``ranking.png``: each effect's held-out gain alone against its null threshold."""
    rk = d.summary["ranking"]
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(rk) + 1.2))
    y = np.arange(len(rk))
    gains = [max(r["heldout_gain"], -0.05) for r in rk]
    ax.barh(y, gains, color=["C2" if r["selected"] else "C7" for r in rk])
    ax.scatter([r["threshold"] for r in rk], y, marker="|", color="r", s=200,
               label="null threshold")
    ax.set_yticks(y, [r["effect"] for r in rk])
    ax.invert_yaxis()
    ax.set_xlabel("held-out cost reduction, single effect vs nominal (green: selected)")
    ax.legend(fontsize=8)
    return _save(plt, fig, out, "ranking.png")


def write_outputs(d: Diagnosis, out_dir: Path, plots: bool = True) -> Path:
    """Write report.md, diagnosis.json, the YAML files and PNGs atomically into out_dir."""
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; the result is an ordinary dir
    try:
        figs = _plots(d, tmp) if plots else []
        (tmp / "report.md").write_text(_markdown(d, figs))
        (tmp / "diagnosis.json").write_text(json.dumps(d.to_json(), indent=1, default=str))
        (tmp / "corrected_params.yaml").write_text(corrected_yaml(d))
        (tmp / "camera_correction.yaml").write_text(camera_yaml(d))
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
