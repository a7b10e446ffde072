"""One call that diagnoses a recording: :func:`diagnose_recording`.

Returns a :class:`Diagnosis`: the JSON-ready summary (:meth:`Diagnosis.to_json`, the
``--json`` output) plus the objects the report needs. See docs/diagnosis.md for the method.

The steps of :func:`diagnose_recording`, each a function here: preprocessing and the
residual, the noise-only null (:func:`_null_calibration`), the selection of effects, the
location of the mismatch, the held-out metrics of each equation row
(:func:`_heldout_rows`), the same inside the located windows (:func:`_located_rows`), the
short-horizon predictions (:func:`_predictions`), the plausibility of the fitted values and
the verdict (:func:`_implausible`, :func:`_verdict`), and the summary dict
(:func:`_summary`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from bfr_model.params import RigParams
from bfr_model.recording import Recording
from numpy.typing import NDArray

from bfr_diagnose import DiagnoseError
from bfr_diagnose.effects import EFFECTS, FRAME_ONLY_EFFECTS, display_values, plausibility
from bfr_diagnose.identify import Problem, Selection, autocorr_time, select_effects
from bfr_diagnose.locate import ljung_box, locate, prediction_errors, rms_by_block
from bfr_diagnose.null import NullCalibration, calibrate_null
from bfr_diagnose.preprocess import Prepared, PrepConfig, prepare_runs
from bfr_diagnose.residual import Residual, ResidualConfig, ResidualEvaluator

__all__ = ["DiagnoseOptions", "Diagnosis", "diagnose_recording"]

Say = Callable[[str], None]  # ``progress(str)``: where progress messages go


@dataclass(kw_only=True)
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


@dataclass(frozen=True, kw_only=True)
class Diagnosis:
    """Result of :func:`diagnose_recording`.

    Attributes
    ----------
    findings : dict
        The JSON-ready summary without the wall time (see :meth:`to_json`).
    wall_time_s : float or None
        Wall time of the diagnosis [s]; a caller that times more (the CLI: reading the
        recording too) records its own with ``dataclasses.replace``.
    prep, selection, null, res_before, res_after, test_mask, pred_before, pred_after, base
        What the report needs: the preprocessed recording, the selection, the null, the
        nominal and corrected residuals, the held-out residual samples, the short-horizon
        predictions (with traces) and the nominal parameters.
    """

    findings: dict[str, Any]
    wall_time_s: float | None = None
    prep: Prepared
    selection: Selection
    null: NullCalibration
    res_before: Residual
    res_after: Residual
    test_mask: NDArray[np.bool_]
    pred_before: dict[str, Any]
    pred_after: dict[str, Any]
    base: RigParams

    def to_json(self) -> dict[str, Any]:
        """The JSON-ready summary (the ``--json`` output and ``diagnosis.json``).

        Returns
        -------
        dict
            :attr:`findings` followed by ``wall_time_s`` (a new top-level dict; the nested
            values are shared).
        """
        return {**self.findings, "wall_time_s": self.wall_time_s}

    @property
    def summary(self) -> dict[str, Any]:
        """The JSON-ready summary, :meth:`to_json` (read-only view for existing callers)."""
        return self.to_json()


def _f(x: float) -> float | None:
    """``x`` as a float, or None when missing or not finite (JSON has no NaN)."""
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

    Returns
    -------
    Diagnosis
        The summary (:meth:`Diagnosis.to_json`) and what the report needs.

    Raises
    ------
    DiagnoseError
        Unusable recording.
    """
    opts = opts or DiagnoseOptions()
    t_start = time.perf_counter()
    say = progress or (lambda _m: None)
    recs = list(rec) if isinstance(rec, (list, tuple)) else [rec]
    prep = prepare_runs(recs, opts.prep, latency0=opts.latency0)
    ev = ResidualEvaluator(prep, opts.residual)
    if ev.idx.size < 50:
        raise DiagnoseError("too few usable samples after preprocessing "
                            f"({ev.idx.size} residual samples)")
    dur = float(prep.t[-1] - prep.t[0])
    block = opts.block or float(np.clip(dur / 8.0, 1.5, 5.0))
    say(f"preprocessed {dur:.1f} s: {prep.info.get('ball')}; {prep.info.get('theta_source')}")
    prob = Problem(ev, base, block)
    null = _null_calibration(prep, prob, recs, opts, block, say)
    sel = select_effects(prob, null.thresholds if opts.null else
                         {n: 0.05 for n in EFFECTS}, max_effects=opts.max_effects,
                         only=opts.only, progress=say, weights=tuple(null.sigma))
    res0 = ev.evaluate(base, 0.0)
    res1 = ev.evaluate(sel.params, sel.sensor)
    loc = locate(prep, res0, tuple(null.sigma), max(null.tau, 1.0), msq=null.msq)
    rows = ["frame_torque_row"] + (["ball_row"] if prep.has_ball else [])
    before, after = _heldout_rows(rows, res0, res1, null.sigma, prob.test,
                                  _whiteness_lag(opts))
    located = _located_rows(rows, prep.t[res0.idx], res0, res1, loc["windows"], prob.test)
    pred_b, pred_a = _predictions(prep, base, sel, res0, res1, block, say)
    implausible = _implausible(sel, base, opts.latency0)
    findings = _summary(
        recs=recs, prep=prep, opts=opts, sel=sel, null=null, block=block,
        implausible=implausible, loc=loc,
        metrics=_metrics(rows, before, after, located, pred_b, pred_a))
    return Diagnosis(findings=findings, wall_time_s=time.perf_counter() - t_start, prep=prep,
                     selection=sel, null=null, res_before=res0, res_after=res1,
                     test_mask=prob.test, pred_before=pred_b, pred_after=pred_a, base=base)


# -- the null -------------------------------------------------------------------------------------


def _null_calibration(prep: Prepared, prob: Problem, recs: list[Recording],
                      opts: DiagnoseOptions, block: float, say: Say) -> NullCalibration:
    """The noise-only null of the recording (:func:`~.null.calibrate_null`).

    Precomputed when ``opts.null_calibration`` is given; with ``opts.null`` off (``--no-null``)
    only the weights, from the robust scales of the nominal residual, and no thresholds.
    """
    base = prob.base
    if opts.null and opts.null_calibration is not None:
        return opts.null_calibration
    if opts.null:
        return calibrate_null(prep, base, opts.prep, opts.residual, block,
                              runs=opts.null_runs, seed=opts.null_seed, rec=recs,
                              null_recordings=opts.null_recordings, progress=say,
                              problem=prob)
    prob0 = Problem(prob.ev, base, block)
    prob0.set_weights([])
    w = prob0.weighted([])
    return NullCalibration(sigma=list(prob0.s), gains={}, thresholds={},
                           tau=autocorr_time(w[0]), runs=0, noise=dict(prep.noise),
                           source="none (--no-null): weights from the nominal residual")


# -- held-out metrics -----------------------------------------------------------------------------


def _whiteness_lag(opts: DiagnoseOptions) -> int:
    """Residual samples per kernel width (near-independent samples for the Ljung-Box test)."""
    return max(round(2 * opts.residual.half_width / (opts.prep.dt * opts.residual.stride)), 1)


def _row_pairs(rows: list[str], res0: Residual, res1: Residual
               ) -> list[tuple[str, NDArray[np.float64], NDArray[np.float64]]]:
    """``(row name, nominal residual, corrected residual)`` of each analysed row."""
    return list(zip(rows, (res0.r1, res0.r2), (res1.r1, res1.r2), strict=False))


def _heldout_rows(rows: list[str], res0: Residual, res1: Residual, sigma: list[float],
                  test: NDArray[np.bool_], lag: int
                  ) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, Any]]]:
    """Held-out RMSE, RMSE over the row's noise and whiteness, nominal and corrected.

    Parameters
    ----------
    rows : list of str
        Names of the analysed rows (``frame_torque_row``, and ``ball_row`` with a ball).
    res0, res1 : Residual
        Equation error of the nominal and of the corrected model.
    sigma : list of float
        Noise scale of each row [N m] (the null's).
    test : ndarray of bool
        Held-out residual samples.
    lag : int
        Sampling step of the Ljung-Box test (:func:`_whiteness_lag`).

    Returns
    -------
    before, after : dict
        Per row: ``rmse`` [N m], ``rmse_over_noise``, ``whiteness``.
    """
    before: dict[str, dict[str, Any]] = {}
    after: dict[str, dict[str, Any]] = {}
    for i, (name, r0, r1) in enumerate(_row_pairs(rows, res0, res1)):
        s = sigma[i]
        before[name] = {"rmse": rms_by_block(r0, test),
                        "rmse_over_noise": rms_by_block(r0, test) / s}
        after[name] = {"rmse": rms_by_block(r1, test),
                       "rmse_over_noise": rms_by_block(r1, test) / s}
        before[name]["whiteness"] = ljung_box(r0[test], lag)
        after[name]["whiteness"] = ljung_box(r1[test], lag)
    return before, after


def _located_rows(rows: list[str], t_res: NDArray[np.float64], res0: Residual,
                  res1: Residual, windows: list[dict[str, Any]], test: NDArray[np.bool_]
                  ) -> dict[str, dict[str, float] | None]:
    """Held-out RMSE before and after inside the windows where each row exceeded the noise.

    A local effect (e.g. a bump) acts only there; a row needs 5 such held-out samples.

    Parameters
    ----------
    rows : list of str
        Names of the analysed rows.
    t_res : ndarray
        Times of the residual samples [s].
    res0, res1 : Residual
        Equation error of the nominal and of the corrected model.
    windows : list of dict
        Flagged windows of :func:`~.locate.locate` (``t0``, ``t1``, ``signals``).
    test : ndarray of bool
        Held-out residual samples.

    Returns
    -------
    dict
        Per row: ``rmse_before``, ``rmse_after``, ``improvement``, ``fraction_of_heldout``;
        or None.
    """
    located: dict[str, dict[str, float] | None] = {}
    for name, r0, r1 in _row_pairs(rows, res0, res1):
        m = np.zeros(t_res.size, bool)
        for win in windows:
            if name in win.get("signals", []):
                m |= (t_res >= win["t0"]) & (t_res < win["t1"])
        m &= test
        if m.sum() >= 5:
            b, a = rms_by_block(r0, m), rms_by_block(r1, m)
            located[name] = {"rmse_before": b, "rmse_after": a,
                             "improvement": b / max(a, 1e-300),
                             "fraction_of_heldout": float(m.sum() / max(test.sum(), 1))}
        else:
            located[name] = None
    return located


def _predictions(prep: Prepared, base: RigParams, sel: Selection, res0: Residual,
                 res1: Residual, block: float, say: Say
                 ) -> tuple[dict[str, Any], dict[str, Any]]:
    """Short-horizon open-loop predictions, nominal and corrected, on the held-out blocks.

    Returns
    -------
    before, after : dict
        :func:`~.locate.prediction_errors` of each model (with up to 400 traces).
    """
    t_grid = prep.t - prep.t[0]
    test_t = (np.floor(t_grid / block).astype(int) % 2) == 1
    say("short-horizon prediction before/after on the held-out blocks")
    pred_b = prediction_errors(prep, base, res0.phi, res0.phi_dot, 0.0, test_t,
                               keep_traces=400)
    pred_a = prediction_errors(prep, sel.params, res1.phi, res1.phi_dot, sel.sensor,
                               test_t, keep_traces=400)
    return pred_b, pred_a


def _metrics(rows: list[str], before: dict[str, dict[str, Any]],
             after: dict[str, dict[str, Any]], located: dict[str, dict[str, float] | None],
             pred_b: dict[str, Any], pred_a: dict[str, Any]) -> dict[str, Any]:
    """The ``metrics`` entry of the summary: held-out fit before and after, every measure."""
    comb_b = float(np.sqrt(np.mean([before[r]["rmse_over_noise"] ** 2 for r in rows])))
    comb_a = float(np.sqrt(np.mean([after[r]["rmse_over_noise"] ** 2 for r in rows])))
    return {
        "heldout_before": before, "heldout_after": after,
        "heldout_rmse_over_noise": {"before": comb_b, "after": comb_a,
                                    "improvement_factor": comb_b / max(comb_a, 1e-12)},
        "improvement_per_signal": {r: before[r]["rmse"] / max(after[r]["rmse"], 1e-300)
                                   for r in rows},
        "located_windows": located,
        "prediction_before": {k: v for k, v in pred_b.items() if k != "traces"},
        "prediction_after": {k: v for k, v in pred_a.items() if k != "traces"},
    }


# -- plausibility, verdict, notes -----------------------------------------------------------------


def _implausible(sel: Selection, base: RigParams, latency0: float) -> dict[str, str]:
    """Why each fitted effect is physically implausible, by name (the plausible are absent).

    Also marks each row of ``sel.parameters`` with ``plausible``.
    """
    implausible = {}
    for name, vals in zip(sel.final.effects, sel.final.values, strict=True):
        why = plausibility(name, display_values(EFFECTS[name], vals), base, latency0)
        if why:
            implausible[name] = why
    for p in sel.parameters:
        p["plausible"] = p["effect"] not in implausible
    return implausible


def _verdict(chosen: list[str], implausible: dict[str, str], significant_loc: bool) -> str:
    """One sentence: what the nominal model leaves out, or that nothing significant is.

    Parameters
    ----------
    chosen : list of str
        Selected effects, in the order of selection.
    implausible : dict
        Selected effects fitted at physically implausible values (:func:`_implausible`).
    significant_loc : bool
        Whether some row's nominal residual exceeds the noise over the whole recording.
    """
    good = [n for n in chosen if n not in implausible]
    bad = [n for n in chosen if n in implausible]
    if good:
        return ("mismatch found: the nominal model leaves out " + ", ".join(good)
                + (f"; {', '.join(bad)} also improve(s) the fit but at a physically "
                   "implausible value (a stand-in for something outside the library)"
                   if bad else ""))
    if bad:
        return ("mismatch found, but the effects that reduce it (" + ", ".join(bad)
                + ") take physically implausible values: the missing physics is most "
                "likely outside the library")
    if significant_loc:
        return ("mismatch located (the residual exceeds the noise) but no effect of the "
                "library explains it significantly")
    return "no significant mismatch"


def _notes(implausible: dict[str, str], prep: Prepared, recs: list[Recording]) -> list[str]:
    """Notes for the reader: implausible fits, a frame-only analysis, stitched runs."""
    notes = [f"{name} is physically implausible ({why})." for name, why in implausible.items()]
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
    return notes


def _ranked(sel: Selection) -> list[dict[str, Any]]:
    """The first stage's ranking, selected effects first (in order of selection)."""
    chosen = list(sel.chosen)
    ranked = [{**r, "selected": r["effect"] in chosen} for r in sel.ranking]
    ranked.sort(key=lambda r: (not r["selected"], chosen.index(r["effect"])
                               if r["selected"] else 0, -r["heldout_gain"]))
    return ranked


# -- the summary ----------------------------------------------------------------------------------


def _summary(*, recs: list[Recording], prep: Prepared, opts: DiagnoseOptions, sel: Selection,
             null: NullCalibration, block: float, implausible: dict[str, str],
             loc: dict[str, Any], metrics: dict[str, Any]) -> dict[str, Any]:
    """The JSON-ready summary of a diagnosis, without the wall time (docs/diagnosis.md).

    Parameters
    ----------
    recs : list of Recording
        The runs diagnosed (the first names the source).
    prep : Prepared
        The preprocessed (stitched) recording.
    opts : DiagnoseOptions
        Settings.
    sel : Selection
        The selected effects.
    null : NullCalibration
        The noise-only null.
    block : float
        Train/test block length [s].
    implausible : dict
        Implausible fitted effects (:func:`_implausible`).
    loc : dict
        Where the nominal residual exceeds the noise (:func:`~.locate.locate`).
    metrics : dict
        Held-out fit before and after (:func:`_metrics`).
    """
    rec = recs[0]
    significant_loc = any(v["significant"] for v in loc["global"].values())
    return {
        "source": rec.meta.get("source"),
        "source_kind": rec.meta.get("source_kind"),
        "duration": float(prep.t[-1] - prep.t[0]),
        "has_ball": prep.has_ball,
        "verdict": _verdict(sel.chosen, implausible, significant_loc),
        "notes": _notes(implausible, prep, recs),
        "effects": sel.chosen,
        "implausible": implausible,
        "parameters": sel.parameters,
        "camera_latency": {"nominal": opts.latency0,
                           "fitted_total": opts.latency0 + sel.sensor.latency,
                           "fitted": "camera_latency" in sel.chosen},
        "camera_offset": {"x": sel.sensor.offset_x, "y": sel.sensor.offset_y,
                          "fitted": "camera_offset" in sel.chosen,
                          "meaning": "the camera reports (x, y) = true + (x, y) offset [m]"},
        "ranking": _ranked(sel),
        "stages": sel.stages,
        "confounded": sel.confounded,
        "located": loc,
        "metrics": metrics,
        "null": {k: v for k, v in null.to_json().items() if k != "gains"},
        "preprocessing": {**prep.info, "noise": {k: _f(v) for k, v in prep.noise.items()},
                          "config": asdict(opts.prep), "residual": asdict(opts.residual),
                          "block_s": block},
        "recording": {**rec.summary(), "runs_used": len(recs),
                      "duration_used": float(sum(r.duration for r in recs))},
    }
