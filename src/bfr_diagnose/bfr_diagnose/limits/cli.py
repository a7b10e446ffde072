"""``bfr limits``: detection limits of ``bfr diagnose`` beside PySINDy, on Dask.

``bfr limits run`` draws cases ``0 .. N-1`` of a seed (each reproducible alone from
``(seed, index)``: truth generator, effects and sizes, sensor timing, camera, controller),
runs both tools on each on a Dask cluster (a LocalCluster by default, ``--scheduler ADDRESS``
for an existing one) and keeps one record per case in ``OUT/cases/``; a rerun continues
where the last stopped. ``bfr limits report`` turns the records into the table (Parquet and
CSV), the statistics (``summary.json``: detection curves with 50 % and 90 % sizes and their
bootstrap intervals, parameter error, confusion matrices, pairs and triples, Wilson
intervals of the false-positive rate), the PNG figures and ``report.md``.

Examples::

    scripts/bfr limits run --seed 1 --cases 1000 --out limits-1
    scripts/bfr limits run --seed 1 --cases 1000 --out limits-1 --scheduler tcp://host:8786
    scripts/bfr limits report limits-1

Exit codes: 0 success, 2 bad input, 130 interrupted (the records so far are kept).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from bfr_diagnose.limits.plots import plot_all
from bfr_diagnose.limits.runner import done_indices, run_cases
from bfr_diagnose.limits.stats import load_records, summarise, write_report

__all__ = ["main"]

#: Single-threaded numerics in every worker: the cluster's processes are the parallelism.
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "NUMBA_NUM_THREADS")


def _error(msg: str) -> int:
    print(f"bfr limits: error: {msg}", file=sys.stderr)
    return 2


def _parser(truths: tuple[str, ...] = ()) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="bfr limits", description=__doc__.split("\n\n")[0],
                                 epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the cases not yet on disk (Dask)")
    r.add_argument("--seed", type=int, default=1, help="seed of the run (1)")
    r.add_argument("--cases", type=int, default=1000, help="cases 0..N-1 (1000)")
    r.add_argument("--first", type=int, default=0, help="first case index (0)")
    r.add_argument("--out", required=True, help="output folder (records kept in OUT/cases)")
    r.add_argument("--duration", type=float, default=10.0, help="recording length [s] (10)")
    r.add_argument("--workers", type=int, default=2, help="LocalCluster workers (2)")
    r.add_argument("--scheduler", help="address of an existing Dask scheduler")
    r.add_argument("--params", help="nominal parameter YAML (default: rig.yaml)")
    r.add_argument("--truth", choices=("model", *truths), default="model",
                   help="the truth: 'model' (rigid and contact models, offline; default)"
                   + "".join(f", '{t}'" for t in truths))
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    p = sub.add_parser("report", help="table, statistics, figures and report.md of a run")
    p.add_argument("out", help="the run's folder (the report is written there)")
    p.add_argument("--also", action="append", default=[], metavar="RUN",
                   help="pool the records of another run (e.g. --truth nodes); repeatable")
    p.add_argument("--bootstrap", type=int, default=400, help="bootstrap resamples (400)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    p.add_argument("--json", action="store_true", help="print summary.json")
    return ap


def _run(args: argparse.Namespace, recorders: dict[str, Any]) -> int:
    if args.cases < 1 or args.first < 0 or args.workers < 1:
        return _error("need --cases >= 1, --first >= 0 and --workers >= 1")
    if not 8.0 <= args.duration <= 60.0:
        return _error(f"--duration {args.duration:g} s outside [8, 60] s")
    if args.params and not Path(args.params).is_file():
        return _error(f"parameter file {args.params} not found")
    out = Path(args.out)
    meta_path = out / "run.json"
    meta = {"seed": args.seed, "duration": args.duration, "params": args.params,
            "truth": args.truth}
    if meta_path.is_file():
        old = {"truth": "model", **json.loads(meta_path.read_text())}
        if {k: old.get(k) for k in meta} != meta:
            return _error(f"{out} holds a run with {dict((k, old.get(k)) for k in meta)}; "
                          "use another --out (nothing changed)")
    out.mkdir(parents=True, exist_ok=True)
    meta_path.write_text(json.dumps(meta))
    for v in _THREAD_VARS:
        os.environ.setdefault(v, "1")
    t0 = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[limits {time.perf_counter() - t0:7.1f} s] {msg}", file=sys.stderr, flush=True)

    try:
        figs = run_cases(args.seed, list(range(args.first, args.first + args.cases)), out,
                         args.duration, params=args.params, workers=args.workers,
                         scheduler=args.scheduler, progress=not args.no_progress, say=say,
                         truth=None if args.truth == "model" else args.truth,
                         recorder=recorders.get(args.truth))
    except KeyboardInterrupt:
        print(f"\nbfr limits: interrupted; {len(done_indices(out))} case records kept in "
              f"{out / 'cases'}: the same command continues", file=sys.stderr)
        return 130
    figs.update(seed=args.seed, first=args.first, cases=args.cases,
                finished=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    with (out / "throughput.jsonl").open("a") as fh:
        fh.write(json.dumps(figs) + "\n")
    say(f"ran {figs['ran']} cases in {figs['wall_s']:.0f} s on {figs['workers']} workers"
        + (f" ({figs['cases_per_min']:.2f} cases/min, median case "
           f"{figs['median_case_s']:.1f} s)" if figs["ran"] else ""))
    return 0


def _report(args: argparse.Namespace) -> int:
    out = Path(args.out)
    runs = [out, *map(Path, args.also)]
    for run in runs:
        if not (run / "cases").is_dir():
            return _error(f"{run} has no cases/ folder (not a bfr limits run)")
    rows = load_records(*runs)
    if not rows:
        return _error(f"{out}/cases holds no records")
    summary: dict[str, Any] = summarise(rows, n_boot=args.bootstrap, seed=0)
    figs = [] if args.no_plots else plot_all(out, [r for r in rows if r.get("status") == "ok"],
                                             summary)
    files = [*write_report(out, rows, summary, figs), *figs]
    if args.json:
        print(json.dumps(summary, default=float))
    else:
        print("\n".join(f"wrote {f}" for f in files))
    return 0


def main(argv: list[str] | None = None, recorders: dict[str, Any] | None = None) -> int:
    """Entry point of ``bfr limits``; returns 0 on success, 2 on bad input.

    ``recorders`` adds truths by name (``run --truth NAME``), each a
    :data:`bfr_diagnose.limits.runner.Recorder` (``bfr_tools.limits`` adds ``nodes``).
    """
    recorders = recorders or {}
    args = _parser(tuple(recorders)).parse_args(argv)
    return _run(args, recorders) if args.command == "run" else _report(args)


if __name__ == "__main__":
    raise SystemExit(main())
