"""``bfr bench`` section ``diagnose``: wall time and peak memory of the diagnosis tools.

A closed-loop recording of ``diagnose_duration`` seconds (60 s by default) is made once with
``bfr simulate --controller --duration 60 --out rec.mcap`` (a ROS 2 bag of the rigid plant,
the controller, camera 200 Hz). ``bfr diagnose <bag> --json --no-plots --quiet`` then runs on
it as a subprocess, each time with an empty ``BFR_CACHE_DIR`` so that the noise-only null is
calibrated anew (a first diagnosis of a new recording; later runs of the same kind reuse the
cache). Wall time is measured around the subprocess; the peak resident memory is the
child's own ``ru_maxrss`` from ``os.wait4`` (it covers the child's waited-for descendants
too). Ten recordings of one rig diagnosed together (one call, one set of physics, each
recording its own sensor timing): ten closed-loop bags of ``diagnose_duration / 2`` seconds
(seeds 1-10, the ball started at different places) made the same way, then
``bfr diagnose <bag1> ... <bag10> --json --no-plots --quiet`` timed like the single one.
``bfr blindtest --cases N --json`` is timed the same way (its default recording length,
workers and null runs; a small case count keeps the bench short).

Real recordings cost more than the bench's bag (every stage selects something, the contour's
harmonics are fitted with up to 16 parameters): ``diagnose.real_s_per_s`` is the wall time
of ``bfr diagnose LOG --json --no-plots --quiet`` (empty cache) per second of recording on
each closed-loop rolling log of the real rig that is present (:data:`REAL_LOGS` in
``$BFR_RIG_DATA``, default ``../shared/data/ntnu-rig``), one value per log; the issue's
budget of 60 s for a 60 s recording is 1 s per second. Not measured with ``--quick``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bfr_tools.bench.common import (
    BenchOptions,
    Budget,
    Figure,
    FigureSpec,
    Progress,
    not_measured,
    rig_data_dir,
)

__all__ = ["REAL_LOGS", "SPECS", "run", "run_measured"]

#: The real rig's closed-loop rolling logs timed by ``diagnose.real_s_per_s`` (those present).
REAL_LOGS = ("fin.txt", "Actually_worked.txt")

SPECS: list[FigureSpec] = [
    FigureSpec("diagnose.wall_s", "bfr diagnose, 60 s recording: wall time", "s",
               Budget("<", 60.0)),
    FigureSpec("diagnose.peak_mib", "bfr diagnose, 60 s recording: peak memory (RSS)", "MiB",
               Budget("<", 2048.0)),
    FigureSpec("diagnose.ten_wall_s", "bfr diagnose, ten recordings together: wall time", "s",
               Budget("<", 300.0)),
    FigureSpec("diagnose.ten_peak_mib", "bfr diagnose, ten recordings together: peak memory",
               "MiB", Budget("<", 2048.0)),
    FigureSpec("diagnose.real_s_per_s", "bfr diagnose, real rolling rig logs: wall time per "
               "second recorded", "s/s", Budget("<", 1.0, "issue 12: 60 s for 60 s")),
    FigureSpec("diagnose.blindtest_wall_s", "bfr blindtest: wall time", "s"),
    FigureSpec("diagnose.blindtest_peak_mib", "bfr blindtest: peak memory (RSS)", "MiB"),
]
_BY_KEY = {s.key: s for s in SPECS}


def run_measured(cmd: list[str], env: dict[str, str], out_path: Path, err_path: Path,
                 timeout: float) -> tuple[float, float, int]:
    """Run ``cmd`` to completion; return (wall time [s], peak RSS [MiB], exit status).

    Stdout goes to ``out_path``, stderr to ``err_path``. The peak RSS is the child's
    ``ru_maxrss`` (KiB on Linux) from ``os.wait4``. On timeout the child gets SIGINT, then
    SIGKILL; the exit status is then negative.
    """
    with out_path.open("wb") as out, err_path.open("wb") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=err)
        deadline = t0 + timeout
        signalled = 0
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                break
            now = time.perf_counter()
            if now > deadline and signalled == 0:
                proc.send_signal(signal.SIGINT)
                signalled = 1
                deadline = now + 10.0
            elif now > deadline and signalled == 1:
                proc.kill()
                signalled = 2
            time.sleep(0.01)
        wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    proc.returncode = code
    return wall, usage.ru_maxrss / 1024.0, code if not signalled else -abs(code or 1)


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "bfr_tools.cli", *args]


def _tail(path: Path, n: int = 400) -> str:
    try:
        return path.read_text(errors="replace")[-n:].strip().replace("\n", " | ")
    except OSError:
        return ""


@dataclass(frozen=True, kw_only=True)
class _Diagnosis:
    """One timed ``bfr diagnose ... --json --no-plots --quiet`` run with an empty cache."""

    wall: float                   # [s]
    mib: float                    # [MiB] peak RSS
    code: int                     # exit status (negative: timed out)
    doc: dict[str, Any]           # its JSON ({} when unreadable)
    failure: str                  # "" or the reason it failed (exit status, stderr's tail)


def _diagnose_cold(inputs: list[str], env: dict[str, str], work: Path, tag: str,
                   timeout: float, profile: Path | None = None) -> _Diagnosis:
    """Run ``bfr diagnose INPUTS --json --no-plots --quiet`` with a fresh ``BFR_CACHE_DIR``.

    Stdout and stderr go to ``work/TAG.out`` and ``work/TAG.err``; ``profile`` runs it under
    cProfile writing there.
    """
    cache = Path(tempfile.mkdtemp(prefix="cache-", dir=work))
    cmd = _cli("diagnose", *inputs, "--json", "--no-plots", "--quiet")
    if profile is not None:
        cmd = [cmd[0], "-m", "cProfile", "-o", str(profile), *cmd[1:]]
    out, err = work / f"{tag}.out", work / f"{tag}.err"
    w, m, c = run_measured(cmd, {**env, "BFR_CACHE_DIR": str(cache)}, out, err, timeout)
    try:
        doc = json.loads(out.read_text()) if c == 0 else {}
    except (OSError, ValueError):
        doc = {}
    return _Diagnosis(wall=w, mib=m, code=c, doc=doc if isinstance(doc, dict) else {},
                      failure="" if c == 0 else f"bfr diagnose exit {c}: {_tail(err)}")


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``diagnose`` section (module docstring)."""
    work = (Path(opts.keep) / "diagnose" if opts.keep
            else Path(tempfile.mkdtemp(prefix="bfr-bench-")))
    work.mkdir(parents=True, exist_ok=True)
    try:
        return _run(opts, say, work)
    finally:
        if not opts.keep:
            shutil.rmtree(work, ignore_errors=True)


def _run(opts: BenchOptions, say: Progress, work: Path) -> list[Figure]:
    duration = 10.0 if opts.quick else opts.diagnose_duration
    figs: list[Figure] = []
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    say(f"diagnose: recording {duration:g} s of closed loop (bfr simulate --controller)")
    rec = work / "rec.mcap"
    wall, _, code = run_measured(
        _cli("simulate", "--controller", "--duration", f"{duration:g}", "--out", str(rec),
             "--json"), env, work / "simulate.out", work / "simulate.err", 600.0)
    bag = work / "rec"
    spec_w, spec_m = _BY_KEY["diagnose.wall_s"], _BY_KEY["diagnose.peak_mib"]
    if duration != 60.0:  # the budgets are for a 60 s recording
        spec_w = replace(spec_w, label=f"bfr diagnose, {duration:g} s recording: wall time",
                         budget=None)
        spec_m = replace(spec_m, label=f"bfr diagnose, {duration:g} s recording: peak memory",
                         budget=None)
    if code != 0 or not bag.exists():
        reason = f"recording failed (exit {code}): {_tail(work / 'simulate.err')}"
        figs += [not_measured(spec_w, reason), not_measured(spec_m, reason)]
    else:
        walls, mems = [], []
        verdict = ""
        failure = ""
        for rep in range(opts.diagnose_repeats):
            say(f"diagnose: bfr diagnose on the {duration:g} s recording, cold null cache, "
                f"run {rep + 1}/{opts.diagnose_repeats}")
            prof = None
            if opts.profile:
                Path(opts.profile).mkdir(parents=True, exist_ok=True)
                prof = Path(opts.profile).resolve() / f"diagnose-{rep}.prof"
            d = _diagnose_cold([str(bag)], env, work, f"diagnose-{rep}", 900.0, prof)
            if d.failure:
                failure = d.failure
                break
            walls.append(d.wall)
            mems.append(d.mib)
            verdict = str(d.doc.get("verdict", ""))
            say(f"diagnose: {d.wall:.1f} s wall, peak RSS {d.mib:.0f} MiB")
        if failure:
            figs += [not_measured(spec_w, failure), not_measured(spec_m, failure)]
        else:
            note = (f"{duration:g} s closed-loop bag (made in {wall:.1f} s), "
                    + ("" if duration == 60.0 else "no budget: the budgets are for 60 s; ")
                    + "`bfr diagnose <bag> --json --no-plots --quiet`, empty BFR_CACHE_DIR "
                    f"(null calibrated anew); {len(walls)} run(s); verdict: {verdict}"
                    + ("; UNDER cProfile (slower than normal)" if opts.profile else ""))
            figs.append(Figure(spec_w, walls, note=note, extra={"verdict": verdict}))
            figs.append(Figure(spec_m, mems, note="ru_maxrss of the diagnose process "
                                                 "(os.wait4)"))
    figs += _ten(opts, say, work, env, duration)
    figs.append(_real(opts, say, work, env))
    cases = 1 if opts.quick else opts.blindtest_cases
    spec_b, spec_bm = _BY_KEY["diagnose.blindtest_wall_s"], _BY_KEY["diagnose.blindtest_peak_mib"]
    say(f"diagnose: bfr blindtest --cases {cases} (cold null cache)")
    cache = Path(tempfile.mkdtemp(prefix="cache-", dir=work))
    args = ["blindtest", "--cases", str(cases), "--json"]
    if opts.quick:
        args += ["--duration", "5", "--null-runs", "1"]
    w, m, c = run_measured(_cli(*args), {**env, "BFR_CACHE_DIR": str(cache)},
                           work / "blindtest.out", work / "blindtest.err", 1800.0)
    if c not in (0, 1):  # 1: ran, but a target of the blind test was missed
        reason = f"bfr blindtest exit {c}: {_tail(work / 'blindtest.err')}"
        figs += [not_measured(spec_b, reason), not_measured(spec_bm, reason)]
    else:
        info: dict[str, Any] = {}
        try:
            doc = json.loads((work / "blindtest.out").read_text())
            info = {"score": doc.get("score"), "duration": doc.get("duration")}
        except (OSError, ValueError):
            pass
        say(f"diagnose: blindtest {w:.1f} s wall, peak RSS {m:.0f} MiB")
        note = (f"`bfr blindtest {' '.join(args[1:])}` (its defaults otherwise: 20 s "
                f"recordings, 2 workers, 3 null runs); 1 run; exit {c}"
                if not opts.quick else f"`bfr blindtest {' '.join(args[1:])}`; 1 run; exit {c}")
        figs.append(Figure(spec_b, [w], note=note, extra=info))
        figs.append(Figure(spec_bm, [m], note="ru_maxrss of the blindtest process tree "
                                              "(os.wait4)"))
    return figs


def _ten(opts: BenchOptions, say: Progress, work: Path, env: dict[str, str],
         duration: float) -> list[Figure]:
    """Ten recordings of one rig diagnosed together (module docstring)."""
    spec_w, spec_m = _BY_KEY["diagnose.ten_wall_s"], _BY_KEY["diagnose.ten_peak_mib"]
    each = duration / 2.0
    if duration != 60.0:  # the budget is for ten recordings of 30 s
        spec_w = replace(spec_w, label=f"bfr diagnose, ten {each:g} s recordings: wall time",
                         budget=None)
        spec_m = replace(spec_m, label=f"bfr diagnose, ten {each:g} s recordings: peak memory",
                         budget=None)
    bags = []
    for k in range(10):
        say(f"diagnose: recording {k + 1}/10 of {each:g} s (bfr simulate --controller)")
        out = work / f"ten{k}.mcap"
        _, _, code = run_measured(
            _cli("simulate", "--controller", "--duration", f"{each:g}", "--seed", str(k + 1),
                 "--phi", f"{0.3 * k:.2f}", "--out", str(out), "--json"),
            env, work / f"ten{k}.out", work / f"ten{k}.err", 600.0)
        if code != 0 or not (work / f"ten{k}").exists():
            reason = f"recording {k + 1} failed (exit {code}): {_tail(work / f'ten{k}.err')}"
            return [not_measured(spec_w, reason), not_measured(spec_m, reason)]
        bags.append(str(work / f"ten{k}"))
    say("diagnose: bfr diagnose on the ten recordings together, cold null cache")
    d = _diagnose_cold(bags, env, work, "ten", 1800.0)
    if d.failure:
        return [not_measured(spec_w, d.failure), not_measured(spec_m, d.failure)]
    w, m = d.wall, d.mib
    verdict = str(d.doc.get("verdict", ""))
    say(f"diagnose: ten recordings {w:.1f} s wall, peak RSS {m:.0f} MiB")
    note = (f"ten {each:g} s closed-loop bags (seeds 1-10), one `bfr diagnose <10 bags> --json "
            f"--no-plots --quiet`, empty BFR_CACHE_DIR; 1 run; verdict: {verdict}")
    return [Figure(spec_w, [w], note=note, extra={"verdict": verdict}),
            Figure(spec_m, [m], note="ru_maxrss of the diagnose process (os.wait4)")]


def _real(opts: BenchOptions, say: Progress, work: Path, env: dict[str, str]) -> Figure:
    """Wall time per recorded second on the real rig's rolling logs (module docstring)."""
    spec = _BY_KEY["diagnose.real_s_per_s"]
    if opts.quick:
        return not_measured(spec, "not run with --quick (a minute or more per log)")
    data = rig_data_dir()
    logs = [data / n for n in REAL_LOGS if (data / n).is_file()]
    if not logs:
        return not_measured(spec, f"none of {', '.join(REAL_LOGS)} in {data} "
                                  "(set BFR_RIG_DATA)")
    vals, parts = [], []
    for k, log in enumerate(logs):
        say(f"diagnose: bfr diagnose on the real log {log.name}, cold null cache")
        d = _diagnose_cold([str(log)], env, work, f"real{k}", 1800.0)
        if d.failure:
            return not_measured(spec, f"{log.name}: {d.failure}")
        try:
            rec_s = float(d.doc["duration"])
        except (KeyError, TypeError, ValueError):
            return not_measured(spec, f"no duration in the JSON of {log.name}")
        vals.append(d.wall / rec_s)
        parts.append(f"{log.name}: {d.wall:.1f} s for {rec_s:.1f} s, {d.mib:.0f} MiB")
        say(f"diagnose: {parts[-1]}")
    return Figure(spec, vals, note="`bfr diagnose LOG --json --no-plots --quiet`, empty "
                                   "BFR_CACHE_DIR, one run per log; " + "; ".join(parts))
