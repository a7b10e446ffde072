"""One call that diagnoses a recording: :func:`diagnose_recording`.

Returns a JSON-ready dict (the ``--json`` output) plus the objects the report needs.
See docs/diagnosis.md for the method.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from bfr_model.params import RigParams
from bfr_model.recording import Recording

from bfr_diagnose import DiagnoseError
from bfr_diagnose.effects import EFFECTS, FRAME_ONLY_EFFECTS, display_values, plausibility
from bfr_diagnose.identify import Problem, Selection, autocorr_time, select_effects
from bfr_diagnose.locate import ljung_box, locate, prediction_errors, rms_by_block
from bfr_diagnose.null import NullCalibration, calibrate_null
from bfr_diagnose.preprocess import Prepared, PrepConfig, prepare_runs
from bfr_diagnose.residual import Residual, ResidualConfig, ResidualEvaluator

__all__ = ["DiagnoseOptions", "Diagnosis", "diagnose_recording"]


@dataclass
class DiagnoseOptions:
    """Options of a diagnosis (CLI flags map onto these)."""

    prep: PrepConfig = field(default_factory=PrepConfig)
    residual: ResidualConfig = field(default_factory=ResidualConfig)
    latency0: float = 0.0               # [s] nominal camera latency
    max_effects: int = 3
    only: list[str] | None = None
    null_runs: int = 6                  # noise injections of the null
    null_seed: int = 0
    null: bool = True
    block: float | None = None          # [s] train/test block (default: duration / 8)
    null_recordings: list[Recording] | None = None  # empirical null instead of injection
    null_calibration: NullCalibration | None = None  # precomputed (e.g. shared by blindtest)


@dataclass
class Diagnosis:
    """Result: ``summary`` is the JSON output; the rest feeds the report."""

    summary: dict[str, Any]
    prep: Prepared
    selection: Selection
    null: NullCalibration
    res_before: Residual
    res_after: Residual
    test_mask: np.ndarray
    pred_before: dict[str, Any]
    pred_after: dict[str, Any]
    base: RigParams


def _f(x: float) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def diagnose_recording(rec: Recording | list[Recording], base: RigParams,
                       opts: DiagnoseOptions | None = None, progress: Any = None) -> Diagnosis:
    """Locate, name, model and show the mismatch between ``rec`` and ``base``.

    Parameters
    ----------
    rec : Recording or list of Recording
        The recording, or several runs of one rig (diagnosed together: each preprocessed
        on its own, then stitched with unusable gaps, :func:`~.preprocess.stitch`).
    base : RigParams
        Nominal parameters.
    opts : DiagnoseOptions, optional
        Settings.
    progress : callable, optional
        ``progress(str)`` for messages (stderr in the CLI).

    Raises
    ------
    DiagnoseError
        Unusable recording.
    """
    opts = opts or DiagnoseOptions()
    t_start = time.perf_counter()
    say = progress or (lambda _m: None)
    recs = list(rec) if isinstance(rec, (list, tuple)) else [rec]
    rec = recs[0]
    prep = prepare_runs(recs, opts.prep, latency0=opts.latency0)
    ev = ResidualEvaluator(prep, opts.residual)
    if ev.idx.size < 50:
        raise DiagnoseError("too few usable samples after preprocessing "
                            f"({ev.idx.size} residual samples)")
    dur = float(prep.t[-1] - prep.t[0])
    block = opts.block or float(np.clip(dur / 8.0, 1.5, 5.0))
    say(f"preprocessed {dur:.1f} s: {prep.info.get('ball')}; {prep.info.get('theta_source')}")
    prob = Problem(ev, base, block)
    if opts.null and opts.null_calibration is not None:
        null = opts.null_calibration
    elif opts.null:
        null = calibrate_null(prep, base, opts.prep, opts.residual, block,
                              runs=opts.null_runs, seed=opts.null_seed, rec=recs,
                              null_recordings=opts.null_recordings, progress=say,
                              problem=prob)
    else:
        prob0 = Problem(ev, base, block)
        prob0.set_weights([])
        w = prob0.weighted([])
        null = NullCalibration(sigma=list(prob0.s), gains={}, thresholds={},
                               tau=autocorr_time(w[0]), runs=0, noise=dict(prep.noise),
                               source="none (--no-null): weights from the nominal residual")
    sel = select_effects(prob, null.thresholds if opts.null else
                         {n: 0.05 for n in EFFECTS}, max_effects=opts.max_effects,
                         only=opts.only, progress=say, weights=tuple(null.sigma))
    res0 = ev.evaluate(base, 0.0)
    res1 = ev.evaluate(sel.params, sel.sensor)
    tau = max(null.tau, 1.0)
    loc = locate(prep, res0, tuple(null.sigma), tau, msq=null.msq)
    test_k = prob.test
    rows = ["frame_torque_row"] + (["ball_row"] if prep.has_ball else [])
    before = {}
    after = {}
    for i, (name, r0, r1) in enumerate(zip(rows, (res0.r1, res0.r2), (res1.r1, res1.r2),
                                           strict=False)):
        s = null.sigma[i]
        before[name] = {"rmse": rms_by_block(r0, test_k), "rmse_over_noise":
                        rms_by_block(r0, test_k) / s}
        after[name] = {"rmse": rms_by_block(r1, test_k), "rmse_over_noise":
                       rms_by_block(r1, test_k) / s}
        lag = max(round(2 * opts.residual.half_width / (opts.prep.dt
                                                           * opts.residual.stride)), 1)
        before[name]["whiteness"] = ljung_box(r0[test_k], lag)
        after[name]["whiteness"] = ljung_box(r1[test_k], lag)
    # the same, restricted to the held-out samples inside the windows where this row's
    # nominal residual exceeded the noise (a local effect, e.g. a bump, acts only there)
    t_res = prep.t[res0.idx]
    located = {}
    for name, r0, r1 in zip(rows, (res0.r1, res0.r2), (res1.r1, res1.r2), strict=False):
        m = np.zeros(t_res.size, bool)
        for win in loc["windows"]:
            if name in win.get("signals", []):
                m |= (t_res >= win["t0"]) & (t_res < win["t1"])
        m &= test_k
        if m.sum() >= 5:
            b, a = rms_by_block(r0, m), rms_by_block(r1, m)
            located[name] = {"rmse_before": b, "rmse_after": a,
                             "improvement": b / max(a, 1e-300),
                             "fraction_of_heldout": float(m.sum() / max(test_k.sum(), 1))}
        else:
            located[name] = None
    comb_b = float(np.sqrt(np.mean([before[r]["rmse_over_noise"] ** 2 for r in rows])))
    comb_a = float(np.sqrt(np.mean([after[r]["rmse_over_noise"] ** 2 for r in rows])))
    t_grid = prep.t - prep.t[0]
    test_t = (np.floor(t_grid / block).astype(int) % 2) == 1
    say("short-horizon prediction before/after on the held-out blocks")
    pred_b = prediction_errors(prep, base, res0.phi, res0.phi_dot, 0.0, test_t,
                               keep_traces=400)
    pred_a = prediction_errors(prep, sel.params, res1.phi, res1.phi_dot, sel.sensor,
                               test_t, keep_traces=400)
    notes = []
    implausible = {}
    for name, vals in zip(sel.final.effects, sel.final.values, strict=True):
        why = plausibility(name, display_values(EFFECTS[name], vals), base, opts.latency0)
        if why:
            implausible[name] = why
    for p in sel.parameters:
        p["plausible"] = p["effect"] not in implausible
    for name, why in implausible.items():
        notes.append(f"{name} is physically implausible ({why}).")
    significant_loc = any(v["significant"] for v in loc["global"].values())
    good = [n for n in sel.chosen if n not in implausible]
    bad = [n for n in sel.chosen if n in implausible]
    if good:
        verdict = ("mismatch found: the nominal model leaves out " + ", ".join(good)
                   + (f"; {', '.join(bad)} also improve(s) the fit but at a physically "
                      "implausible value (a stand-in for something outside the library)"
                      if bad else ""))
    elif bad:
        verdict = ("mismatch found, but the effects that reduce it (" + ", ".join(bad)
                   + ") take physically implausible values: the missing physics is most "
                   "likely outside the library")
    elif significant_loc:
        verdict = ("mismatch located (the residual exceeds the noise) but no effect of the "
                   "library explains it significantly")
    else:
        verdict = "no significant mismatch"
    ranked = []
    chosen_set = list(sel.chosen)
    for r in sel.ranking:
        ranked.append({**r, "selected": r["effect"] in chosen_set})
    ranked.sort(key=lambda r: (not r["selected"], chosen_set.index(r["effect"])
                               if r["selected"] else 0, -r["heldout_gain"]))
    latency_total = opts.latency0 + sel.sensor.latency
    if not prep.has_ball:
        lost = [f"'{e[1]}' at t = {e[0]:.2f} s" for r in recs for e in r.meta.get("events", [])
                if isinstance(e, (list, tuple)) and len(e) == 2 and "lost" in str(e[1])]
        notes.append(
            f"{prep.info.get('ball')}" + (f" (the log reports {', '.join(lost)})" if lost
                                          else "") + ". Only the frame's torque row is "
            "analysed: the ball effects (" + ", ".join(
                n for n in EFFECTS if n not in FRAME_ONLY_EFFECTS) + ") cannot be assessed, "
            "and frame inertia, torque gain and friction are identifiable only as ratios "
            "to one another (J_f/k_u, T_c/k_u, c_v/k_u).")
    if len(recs) > 1:
        notes.append(f"{len(recs)} runs diagnosed together (each preprocessed alone, placed "
                     "back to back with unusable gaps); times refer to the stitched axis.")
    summary: dict[str, Any] = {
        "source": rec.meta.get("source"),
        "source_kind": rec.meta.get("source_kind"),
        "duration": dur,
        "has_ball": prep.has_ball,
        "verdict": verdict,
        "notes": notes,
        "effects": sel.chosen,
        "implausible": implausible,
        "parameters": sel.parameters,
        "camera_latency": {"nominal": opts.latency0, "fitted_total": latency_total,
                           "fitted": "camera_latency" in sel.chosen},
        "camera_offset": {"x": sel.sensor.offset_x, "y": sel.sensor.offset_y,
                          "fitted": "camera_offset" in sel.chosen,
                          "meaning": "the camera reports (x, y) = true + (x, y) offset [m]"},
        "ranking": ranked,
        "stages": sel.stages,
        "confounded": sel.confounded,
        "located": loc,
        "metrics": {
            "heldout_before": before, "heldout_after": after,
            "heldout_rmse_over_noise": {"before": comb_b, "after": comb_a,
                                        "improvement_factor": comb_b / max(comb_a, 1e-12)},
            "improvement_per_signal": {r: before[r]["rmse"] / max(after[r]["rmse"], 1e-300)
                                       for r in rows},
            "located_windows": located,
            "prediction_before": {k: v for k, v in pred_b.items() if k != "traces"},
            "prediction_after": {k: v for k, v in pred_a.items() if k != "traces"},
        },
        "null": {k: v for k, v in null.to_json().items() if k != "gains"},
        "preprocessing": {**prep.info, "noise": {k: _f(v) for k, v in prep.noise.items()},
                          "config": asdict(opts.prep), "residual": asdict(opts.residual),
                          "block_s": block},
        "recording": {**rec.summary(), "runs_used": len(recs),
                      "duration_used": float(sum(r.duration for r in recs))},
        "wall_time_s": None,
    }
    summary["wall_time_s"] = time.perf_counter() - t_start
    return Diagnosis(summary=summary, prep=prep, selection=sel, null=null, res_before=res0,
                     res_after=res1, test_mask=test_k, pred_before=pred_b, pred_after=pred_a,
                     base=base)
