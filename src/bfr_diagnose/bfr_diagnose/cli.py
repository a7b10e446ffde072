"""``bfr diagnose``: what the nominal model leaves out of a recording.

Examples::

    scripts/bfr diagnose ../shared/data/ntnu-rig/fin.txt --out-dir diag-fin --json
    scripts/bfr diagnose ../shared/data/ntnu-rig/*.txt --out-dir diag-rig   # one rig
    scripts/bfr diagnose run_bag --topic joint_states=/rig/joint_states

Method: docs/diagnosis.md (noise-injection null on the recording itself, equation error
of both rows of the rigid model, library fits ranked on held-out data and BIC).

Every recording's read account (samples and seconds used against present, by cause) is
printed in one line on stderr and written to report.md and diagnosis.json; more than 1 %
lost stops unless ``--allow-partial``. ``--out-dir`` is written atomically and an existing
one is replaced only with ``--force``.

Exit codes: 0 success, 2 bad input (unreadable, empty, garbage, more than 1 % lost, NaN,
too short, an existing --out-dir without --force).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from bfr_model.io import account_line, read_runs
from bfr_model.io.output import OutputError, check_new
from bfr_model.params import ParameterError, load_params
from bfr_model.recording import Recording

from bfr_diagnose import DiagnoseError
from bfr_diagnose.api import DiagnoseOptions, diagnose_recordings
from bfr_diagnose.effects import EFFECT_NAMES
from bfr_diagnose.preprocess import PrepConfig
from bfr_diagnose.report import format_text, json_text, write_outputs

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr diagnose``."""
    p = argparse.ArgumentParser(
        prog="bfr diagnose",
        description="Compare recordings of one rig with the nominal model: locate where the "
                    "residual exceeds the noise, name the physical effects the model leaves "
                    "out (fitted from a library, ranked on held-out data against a noise-only "
                    "null, one set of physics for all the recordings, each with its own "
                    "sensor timing), write the corrected parameter YAML and a before/after "
                    "report.",
        epilog="Inputs: rig logs (.txt), the simulator's CSV (.csv), ROS 2 bags (a rosbag2 "
               "directory, .mcap or .db3), any number of them. Example: bfr diagnose "
               "../shared/data/ntnu-rig/fin.txt ../shared/data/ntnu-rig/rolling_data.txt "
               "--out-dir diag --json")
    p.add_argument("recordings", type=Path, nargs="+", metavar="recording",
                   help="recording file or bag directory (several: one rig, diagnosed "
                        "together)")
    p.add_argument("--params", type=Path, help="nominal parameter YAML (default: rig.yaml)")
    p.add_argument("--out-dir", type=Path, help="write report.md, PNGs, corrected YAML here")
    p.add_argument("--json", action="store_true", help="print the machine-readable result")
    p.add_argument("--topic", action="append", default=[], metavar="NAME=TOPIC",
                   help="remap a bag topic (e.g. joint_states=/rig/joint_states)")
    p.add_argument("--run", help="run of a rig log holding several runs: an index, or 'all' "
                   "(default: every run, diagnosed together)")
    p.add_argument("--camera-latency", type=float, default=None,
                   help="starting guess of the camera latency [s] (it is fitted on every "
                        "recording; default: 0, or the recording's meta camera_latency_nominal)")
    p.add_argument("--velocity-lag", type=float, default=None,
                   help="lag of a logged velocity [s] (default: measured on every recording)")
    p.add_argument("--ball", choices=("auto", "yes", "no"), default="auto",
                   help="use the ball rows (auto: when the recording has ball fixes)")
    p.add_argument("--camera-prior", type=float, default=1.0, metavar="F",
                   help="the camera's calibration prior (offset 5 mm, rotation 0.05 rad, scale "
                        "3 %%, one sd) with its widths times F; 0: no prior (1)")
    p.add_argument("--max-effects", type=int, default=6, help="most effects to add (6)")
    p.add_argument("--effects", help="comma-separated subset of the library to consider: "
                   + ", ".join(EFFECT_NAMES))
    p.add_argument("--null-runs", type=int, default=6,
                   help="noise injections of the noise-only null (6)")
    p.add_argument("--no-null", action="store_true",
                   help="skip the null (thresholds: 5 %% held-out gain; for quick looks)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    p.add_argument("--t-from", type=float, help="analyse from this time [s]")
    p.add_argument("--t-to", type=float, help="analyse up to this time [s]")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out-dir (default: refuse)")
    p.add_argument("--allow-partial", action="store_true",
                   help="use a recording even when more than 1 %% of its samples could not be "
                        "read (corrupt, truncated, duplicate, out of order or out of range; "
                        "the read's account says which)")
    return p


def _read(path: Path, topics: list[str], run: str | None,
          allow_partial: bool) -> list[Recording]:
    """The runs of the recording at ``path`` (a rig log's every run, or the one chosen)."""
    remap = {}
    for item in topics:
        if "=" not in item:
            raise DiagnoseError(f"--topic {item!r}: expected NAME=TOPIC")
        k, v = item.split("=", 1)
        remap[k.strip()] = v.strip()
    if run is not None and path.suffix.lower() != ".txt":
        raise DiagnoseError("--run applies to rig logs (.txt) only")
    return read_runs(path, run, allow_partial=allow_partial, topic_map=remap or None)


def _check_arguments(args: argparse.Namespace) -> None:
    """Refuse option values that cannot mean anything, before anything is read."""
    if args.null_runs < 1:
        raise DiagnoseError(f"--null-runs {args.null_runs}: expected at least 1 (--no-null "
                            f"skips the null)")
    if args.max_effects < 0:
        raise DiagnoseError(f"--max-effects {args.max_effects}: expected a number >= 0")
    if args.velocity_lag is not None and not (math.isfinite(args.velocity_lag)
                                              and args.velocity_lag >= 0.0):
        raise DiagnoseError(f"--velocity-lag {args.velocity_lag!r}: expected a lag >= 0 s "
                            f"(a filtered velocity follows its angle)")
    for name in ("t_from", "t_to", "camera_latency"):
        v = getattr(args, name)
        if v is not None and not math.isfinite(v):
            raise DiagnoseError(f"--{name.replace('_', '-')} {v!r}: expected a number")
    if args.t_from is not None and args.t_to is not None and args.t_from >= args.t_to:
        raise DiagnoseError(f"--t-from {args.t_from:g} is not before --t-to {args.t_to:g}")
    if args.topic and all(Path(r).suffix.lower() == ".txt" for r in args.recordings):
        raise DiagnoseError("--topic applies to bags only; the recordings are rig logs")
    files = [Path(r) for r in args.recordings if Path(r).is_file()]
    sizes = [f.stat().st_size for f in files]
    seen: dict[str, Path] = {}
    for path, size in zip(files, sizes, strict=True):
        if sizes.count(size) < 2:
            continue  # only files of one size can hold the same bytes (a bag is not read)
        key = hashlib.sha256(path.read_bytes()).hexdigest()
        if key in seen:
            raise DiagnoseError(f"{path} and {seen[key]} hold the same recording (the same "
                                f"bytes): give it once, or it counts twice")
        seen[key] = path


def _window(path: Path, runs: list[Recording], t_from: float | None,
            t_to: float | None) -> list[Recording]:
    """The runs' samples within ``[t_from, t_to]`` (runs without any left out)."""
    kept = [r.slice_time(t_from, t_to) for r in runs
            if np.any((r.t >= (-np.inf if t_from is None else t_from))
                      & (r.t <= (np.inf if t_to is None else t_to)))]
    if not kept:
        lo = min(float(r.t[0]) for r in runs)
        hi = max(float(r.t[-1]) for r in runs)
        raise DiagnoseError(f"{path}: time window [{t_from}, {t_to}] s holds no sample (its "
                            f"{len(runs)} run(s) span [{lo:g}, {hi:g}] s)")
    return kept


def _options(args: argparse.Namespace, first: Recording) -> DiagnoseOptions:
    """The diagnosis options of the command line."""
    only = None
    if args.effects:
        only = [e.strip() for e in args.effects.split(",") if e.strip()]
        bad = [e for e in only if e not in EFFECT_NAMES]
        if bad:
            raise DiagnoseError(f"--effects: unknown effect(s) {bad}; known: "
                                f"{', '.join(EFFECT_NAMES)}")
    if not (math.isfinite(args.camera_prior) and args.camera_prior >= 0.0):
        raise DiagnoseError(f"--camera-prior {args.camera_prior!r}: expected a number >= 0")
    lat0 = args.camera_latency
    if lat0 is None:
        lat0 = float(first.meta.get("camera_latency_nominal", 0.0) or 0.0)
    return DiagnoseOptions(prep=PrepConfig(ball=args.ball, dtheta_delay=args.velocity_lag),
                           latency0=lat0, max_effects=args.max_effects, only=only,
                           null_runs=args.null_runs, null=not args.no_null,
                           camera_prior=args.camera_prior)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``bfr diagnose``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()

    def say(msg: str) -> None:
        if not args.quiet:
            print(f"[diagnose {time.perf_counter() - t0:5.1f} s] {msg}", file=sys.stderr,
                  flush=True)

    try:
        _check_arguments(args)
        if args.out_dir is not None:
            check_new(args.out_dir, args.force)
        recordings = []
        accounts = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # what the readers found is in their account
            for path in args.recordings:
                runs = _read(path, args.topic, args.run, args.allow_partial)
                # the read's account, one line, always (also with --quiet)
                print(f"bfr diagnose: {account_line(runs)}", file=sys.stderr, flush=True)
                accounts += [r.meta["read_account"] for r in runs if "read_account" in r.meta]
                if args.t_from is not None or args.t_to is not None:
                    runs = _window(path, runs, args.t_from, args.t_to)
                recordings.append((str(path), runs))
                say(f"read {path}: {len(runs)} run(s), {sum(r.n for r in runs)} samples, "
                    f"{sum(r.duration for r in runs):.1f} s")
        base = load_params(args.params)
        opts = _options(args, recordings[0][1][0])
        d = diagnose_recordings(recordings, base, opts, progress=say)
        d.findings["read_accounts"] = accounts
    except (DiagnoseError, ParameterError, ValueError, OSError) as exc:
        print(f"bfr diagnose: error: {exc}", file=sys.stderr)
        return 2
    if args.out_dir is not None:
        try:
            write_outputs(d, args.out_dir, plots=not args.no_plots, progress=say)
        except (OSError, OutputError) as exc:
            print(f"bfr diagnose: error: cannot write {args.out_dir}: {exc}", file=sys.stderr)
            return 2
        say(f"wrote {args.out_dir}/report.md, figures and corrected_params.yaml")
    # the command's own wall time (reading the recordings included) for what it prints;
    # diagnosis.json above keeps the diagnosis's
    d = dataclasses.replace(d, wall_time_s=time.perf_counter() - t0)
    if args.json:
        print(json_text(d))
    else:
        print(format_text(d.to_json()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
