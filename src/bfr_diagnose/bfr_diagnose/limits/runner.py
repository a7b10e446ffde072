"""One case end to end, and the run of many on Dask distributed.

:func:`run_case` draws the case, simulates it, writes and reads it back as a user's file,
runs ``bfr diagnose`` on it exactly as a user does (nominal parameters, every default) and
the PySINDy peer (:mod:`.peer`) on the same data, and scores both alike: the mechanisms
named, exactness of the set, the parameter error ``|fitted - true| / |true - nominal|``
(vector effects: norms; a bump: its height, when found within a width of its place). Its
record is flat (one row of the table): every drawn value, both answers, their errors.

:func:`run_cases` runs the cases not yet on disk on a Dask cluster (a ``LocalCluster`` of
``workers`` single-threaded processes, or an existing scheduler by address), writes each
record as ``cases/case_NNNNNN.json`` the moment it arrives (atomically: a killed run leaves
only whole records) and reports progress; a rerun skips the records present.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.params import RigParams, load_params
from bfr_model.recording import Recording

from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.effects import EFFECT_NAMES, EFFECTS
from bfr_diagnose.limits.cases import LimitCase, draw_case
from bfr_diagnose.limits.generate import case_recording, controller_config, read_back
from bfr_diagnose.limits.peer import peer_diagnose

__all__ = ["Recorder", "case_path", "done_indices", "param_error", "run_case", "run_cases"]


def param_error(name: str, true: list[float], est: list[float], base: RigParams) -> float:
    """``|fitted - true| / |true - nominal|`` of one effect (module docstring)."""
    eff = EFFECTS[name]
    if not est or not np.all(np.isfinite(est)):
        return float("nan")
    if name == "track_bumps":
        ph, h, w = true
        dphi = abs((est[0] - ph + math.pi) % (2 * math.pi) - math.pi)
        return abs(est[1] - h) / abs(h) if dphi < w else 1.0
    a, b = np.asarray(est, float), np.asarray(true, float)
    b0 = np.asarray(eff.start(base), float)
    return float(np.linalg.norm(a - b) / max(float(np.linalg.norm(b - b0)), 1e-300))


def _score(found: list[str], case: LimitCase, values: dict[str, list[float]],
           base: RigParams, prefix: str) -> dict[str, Any]:
    """The same columns for either tool: found, exact, top-1, per-effect detection and error."""
    out: dict[str, Any] = {f"{prefix}_found": ";".join(found),
                           f"{prefix}_exact": set(found) == set(case.effects),
                           f"{prefix}_top1": found[0] if found else "none",
                           f"{prefix}_n_found": len(found)}
    for e in EFFECT_NAMES:
        if e in case.effects:
            out[f"{prefix}_hit_{e}"] = e in found
            out[f"{prefix}_err_{e}"] = (param_error(e, case.truth[e], values[e], base)
                                        if e in found and e in values else float("nan"))
    return out


def _case_columns(case: LimitCase) -> dict[str, Any]:
    """Every drawn value of a case as flat columns."""
    s = case.sensors
    ctrl = controller_config(case)
    row: dict[str, Any] = {
        "index": case.index, "seed": case.seed, "noise_seed": case.noise_seed,
        "generator": case.generator, "kind": case.kind,
        "sensors_applied": case.generator in ("rigid", "contact"),
        "effects": ";".join(case.effects),
        "n_effects": len(case.effects), "changes": json.dumps(case.changes, default=list),
        "truth": json.dumps(case.truth), "writer": s.writer, "velocity_lag": s.velocity_lag,
        "torque_delay": s.torque_delay, "log_rate": s.log_rate, "camera_rate": s.camera_rate,
        "camera_latency": s.camera_latency, "camera_offset_x": s.camera_offset[0],
        "camera_offset_y": s.camera_offset[1], "camera_scale": s.camera_scale,
        "camera_rotation": s.camera_rotation, "theta_turns": s.theta_turns,
        "encoder_counts": s.encoder_counts, "camera_noise": case.camera_noise,
        "orbit_speed": ctrl.orbit.mean_phi_dot, "q_y": ctrl.riccati.q_y,
        "q_y_dot": ctrl.riccati.q_y_dot}
    for e in EFFECT_NAMES:
        row[f"size_{e}"] = (case.sizes[case.effects.index(e)] if e in case.effects
                            else float("nan"))
    return row


#: ``recorder(case, base, duration) -> (runs, loop)``: another source of a case's truth
#: (the recordings as read back, and ``ball_rolling``, ``rms_torque``, ``mean_phi_dot``).
Recorder = Callable[[LimitCase, RigParams, float], tuple[list[Recording], dict[str, Any]]]


def _model_recorder(case: LimitCase, base: RigParams, duration: float
                    ) -> tuple[list[Recording], dict[str, Any]]:
    """The offline truths (:mod:`.generate`), written and read back."""
    rec = case_recording(case, base, duration)
    loop = dict(rec.meta.get("loop", {}))
    loop["ball_rolling"] = bool(rec.meta.get("ball_rolled"))
    return read_back(rec, case.sensors.writer), loop


def run_case(seed: int, index: int, duration: float, params: str | None = None,
             truth: str | None = None, recorder: Recorder | None = None) -> dict[str, Any]:
    """Draw, simulate, write, read back, diagnose (bfr and the peer) and score one case.

    ``truth`` and ``recorder`` replace the offline truths by another recorder (the node
    suite: :mod:`bfr_tools.limits`). A case whose simulation or diagnosis fails is a record
    too (``status`` names why), so that a run never stops and never retries it silently.
    """
    base = load_params(params)
    case = draw_case(seed, index, base, truth)
    row = _case_columns(case)
    row["duration"] = duration
    t0 = time.perf_counter()
    try:
        runs, loop = (recorder or _model_recorder)(case, base, duration)
    except (ValueError, RuntimeError, FloatingPointError, OSError) as exc:
        row.update(status=f"simulation failed: {exc}", t_sim=time.perf_counter() - t0)
        return row
    row.update(rolled=bool(loop.get("ball_rolling")),
               rms_torque=float(loop.get("rms_torque", float("nan"))),
               mean_phi_dot=float(loop.get("mean_phi_dot", float("nan"))),
               t_sim=time.perf_counter() - t0)
    if not row["rolled"]:
        row["status"] = "ball not rolling (the controller lost it: visible, not scored)"
        return row
    t1 = time.perf_counter()
    try:
        d = diagnose_recording(runs, base, DiagnoseOptions())
    except Exception as exc:  # noqa: BLE001 - a failed diagnosis is a result to record
        row.update(status=f"diagnosis failed: {type(exc).__name__}: {exc}",
                   error="".join(traceback.format_exception_only(exc)).strip())
        return row
    row["t_bfr"] = time.perf_counter() - t1
    s = d.summary
    fitted: dict[str, list[float]] = {}
    for e in s["effects"]:
        names = EFFECTS[e].names
        vals = {p["name"]: p["value"] for p in s["parameters"] if p["effect"] == e}
        fitted[e] = [float(vals.get(n, float("nan"))) for n in names]
    row.update(_score(list(s["effects"]), case, fitted, base, "bfr"))
    row["bfr_suspects"] = ";".join(s["suspects"])
    t2 = time.perf_counter()
    try:
        p = peer_diagnose(d, base)
        row.update(_score(p.found, case, {k: [v] for k, v in p.parameters.items()}, base,
                          "peer"))
        row["peer_terms"] = json.dumps({str(k): v for k, v in p.terms.items()})
        row["peer_thresholds"] = json.dumps({str(k): v for k, v in p.thresholds.items()})
    except Exception as exc:  # noqa: BLE001 - the peer's failure is its result
        row.update(peer_found="", peer_exact=False, peer_top1="none", peer_n_found=0,
                   peer_error=f"{type(exc).__name__}: {exc}")
    row["t_peer"] = time.perf_counter() - t2
    row["status"] = "ok"
    return row


def case_path(out: Path, index: int) -> Path:
    """Where the record of case ``index`` is kept."""
    return out / "cases" / f"case_{index:06d}.json"


def done_indices(out: Path) -> set[int]:
    """Indices of the cases whose records are on disk."""
    folder = out / "cases"
    if not folder.is_dir():
        return set()
    return {int(p.stem.split("_")[1]) for p in folder.glob("case_*.json")}


def _write_record(out: Path, row: dict[str, Any]) -> None:
    path = case_path(out, int(row["index"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(row, default=float))
    os.replace(tmp, path)


def _bar(done: int, total: int, t0: float, width: int = 30) -> str:
    frac = done / total if total else 1.0
    el = time.perf_counter() - t0
    eta = el / frac - el if frac > 0 else float("nan")
    fill = round(width * frac)
    return (f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{total} "
            f"{el:6.0f} s elapsed, ETA {eta:6.0f} s")


def run_cases(seed: int, indices: list[int], out: Path, duration: float, *,
              params: str | None = None, workers: int = 2, scheduler: str | None = None,
              progress: bool = True, say: Callable[[str], None] | None = None,
              truth: str | None = None, recorder: Recorder | None = None) -> dict[str, Any]:
    """Run the cases not yet on disk on Dask; returns timing figures of this run.

    Parameters
    ----------
    seed : int
        The run's seed.
    indices : list of int
        Cases wanted (those with a record in ``out`` are skipped: resuming).
    out : Path
        Output folder (records in ``out/cases``).
    duration : float
        Recording length [s].
    params : str, optional
        Nominal parameter file.
    workers : int
        Worker processes of the LocalCluster (ignored with ``scheduler``).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``; dask-jobqueue or
        Kubernetes clusters expose one).
    progress : bool
        Draw a progress bar on stderr.
    say : callable, optional
        Progress messages.
    truth, recorder : optional
        Another recorder of the truth (:func:`run_case`).
    """
    from dask.distributed import Client, LocalCluster, as_completed  # noqa: PLC0415 - optional heavy dependency

    say = say or (lambda m: None)
    todo = sorted(set(indices) - done_indices(out))
    say(f"{len(indices) - len(todo)} of {len(indices)} cases already on disk, {len(todo)} to run")
    if not todo:
        return {"ran": 0, "wall_s": 0.0, "workers": 0}
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=40)
        client = Client(cluster)
    n_workers = len(client.scheduler_info().get("workers", {}))
    say(f"Dask: {'scheduler ' + scheduler if scheduler else 'LocalCluster'}, "
        f"{n_workers} workers")
    t0 = time.perf_counter()
    done = 0
    times: list[float] = []
    try:
        futs = [client.submit(run_case, seed, i, duration, params, truth, recorder,
                              key=f"case-{seed}-{i}", pure=False) for i in todo]
        for fut in as_completed(futs):
            row = fut.result()
            _write_record(out, row)
            done += 1
            times.append(float(row.get("t_sim", 0.0)) + float(row.get("t_bfr", 0.0))
                         + float(row.get("t_peer", 0.0)))
            if progress:
                sys.stderr.write(_bar(done, len(todo), t0))
                sys.stderr.flush()
    finally:
        if progress:
            sys.stderr.write("\n")
        client.close()
        if cluster is not None:
            cluster.close()
    wall = time.perf_counter() - t0
    return {"ran": done, "wall_s": wall, "workers": n_workers,
            "cases_per_min": 60.0 * done / wall if wall > 0 else float("nan"),
            "median_case_s": float(np.median(times)) if times else float("nan")}
