"""``bfr bench``: the performance figures of the emulated rig, measured side by side.

Sections (``--only`` / ``--skip``):

``sim``
    Simulator speed as real-time factors: the rigid model (RK4 at 1 kHz) in the simulator
    node's configuration and against ``scipy.integrate.solve_ivp`` on the same equations
    at matching accuracy; the contact model over a row of bumps against solve_ivp
    (LSODA, Radau). See :mod:`bfr_tools.bench.sim`.
``camera``
    Render and detect time per 640x480 frame (``bfr camera-eval``'s code).
    See :mod:`bfr_tools.bench.camera`.
``loop``
    The node suite over DDS, every node in its own process: the camera node's sustained
    frame rate, the latency from a simulator state to the torque that answers it (median,
    99th percentile), the sustained control rate and dropped frames.
    See :mod:`bfr_tools.bench.loop`.
``diagnose``
    ``bfr diagnose`` wall time and peak memory on a 60 s recording, ``bfr blindtest`` wall
    time. See :mod:`bfr_tools.bench.diagnosis`.
``view``
    What watching costs: one ``sim_markers`` message, one ``bfr video`` frame.
    See :mod:`bfr_tools.bench.view`.
``read``
    Peak memory and speed of the streaming rig-log reader on a 200 MB log made of the real
    logs' runs (``bfr read``). See :mod:`bfr_tools.bench.read`.

Every figure is the median over repeats with their min and max (the machine's noise), next
to its budget and whether the median meets it; a figure that cannot be measured says why
("not measured: ...") instead of showing a number. Progress goes to stderr, the table (or
``--json``) to stdout. The exit status is 0 (1 with ``--strict`` when a budget is missed,
2 on bad arguments).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from collections.abc import Sequence
from typing import Any

from bfr_model.jit import JIT_ENABLED

from bfr_tools.bench import camera, diagnosis, loop, read, sim, view
from bfr_tools.bench.common import (
    BenchOptions,
    Figure,
    Progress,
    Section,
    fmt_value,
    not_measured,
)

__all__ = ["SECTION_NAMES", "format_table", "main", "run_bench", "sections"]

SECTION_NAMES = ("sim", "camera", "loop", "diagnose", "view", "read")


def sections() -> dict[str, Section]:
    """The sections, by name (their modules are imported here, not at start-up)."""
    return {
        "sim": Section("sim", "simulator real-time factors vs solve_ivp", sim.SPECS,
                       sim.run),
        "camera": Section("camera", "render / detect time per frame", camera.SPECS,
                          camera.run),
        "loop": Section("loop", "node suite over DDS: rates, latency, drops", loop.SPECS,
                        loop.run),
        "diagnose": Section("diagnose", "bfr diagnose / blindtest wall time, memory",
                            diagnosis.SPECS, diagnosis.run),
        "view": Section("view", "markers per message, bfr video per frame", view.SPECS,
                        view.run),
        "read": Section("read", "streaming rig-log reader: peak memory, speed", read.SPECS,
                        read.run),
    }


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in ("numpy", "scipy", "numba", "cv2"):
        try:
            mod = __import__(name)
            out["opencv" if name == "cv2" else name] = str(getattr(mod, "__version__", "?"))
        except ImportError:
            out[name] = "missing"
    return out


def machine_info() -> dict[str, Any]:
    """Cores, load average, platform and library versions of this machine."""
    cpu = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        affinity = os.cpu_count() or 0
    return {
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "cpu": cpu,
        "platform": platform.platform(),
        "load_average_start": [round(v, 2) for v in os.getloadavg()],
        "versions": _versions(),
        "jit": bool(JIT_ENABLED),
        "rmw": os.environ.get("RMW_IMPLEMENTATION", ""),
    }


def run_bench(names: Sequence[str], opts: BenchOptions, say: Progress) -> dict[str, Any]:
    """Run the named sections; return the JSON-ready result.

    Parameters
    ----------
    names : sequence of str
        Sections to run, in order (a subset of :data:`SECTION_NAMES`).
    opts : BenchOptions
        Repeats, durations, quick mode.
    say : Progress
        Progress printer (stderr).

    Returns
    -------
    dict
        ``machine``, ``options``, ``figures`` (one dict per figure, see
        :meth:`Figure.to_json`), counts of budgets met / missed / not measured, wall time.
    """
    t0 = time.perf_counter()
    info = machine_info()
    say(f"machine: {info['cores']} cores, load {info['load_average_start']}, "
        f"python {info['versions']['python']}")
    secs = sections()
    figures: list[Figure] = []
    section_walls: dict[str, float] = {}
    for name in names:
        sec = secs[name]
        ts = time.perf_counter()
        say(f"section {name}: {sec.title}")
        try:
            got = sec.run(opts, say)
        except Exception as exc:  # noqa: BLE001 - one broken section must not hide the rest
            got = [not_measured(s, f"{type(exc).__name__}: {exc}") for s in sec.specs]
        have = {f.spec.key for f in got}
        got += [not_measured(s, "not reported by the section") for s in sec.specs
                if s.key not in have]
        order = {s.key: i for i, s in enumerate(sec.specs)}
        figures += sorted(got, key=lambda f: order.get(f.spec.key, 1_000))
        section_walls[name] = time.perf_counter() - ts
    info["load_average_end"] = [round(v, 2) for v in os.getloadavg()]
    figs = [f.to_json() for f in figures]
    with_budget = [f for f in figs if f["budget"] is not None]
    return {
        "machine": info,
        "options": {"sections": list(names), **opts.__dict__},
        "figures": figs,
        "budgets": {
            "met": sum(f["met"] is True for f in with_budget),
            "missed": [f["key"] for f in with_budget if f["met"] is False],
            "not_measured": [f["key"] for f in with_budget if f["met"] is None],
            "total": len(with_budget),
        },
        "section_wall_s": {k: round(v, 2) for k, v in section_walls.items()},
        "wall_time_s": time.perf_counter() - t0,
    }


def format_table(result: dict[str, Any]) -> str:
    """The result as an aligned text table with notes (what ``bfr bench`` prints)."""
    m = result["machine"]
    v = m["versions"]
    lines = [
        f"bfr bench: {m['cores']} cores ({m['cores_usable']} usable) {m['cpu']}; load average "
        f"{'/'.join(f'{x:g}' for x in m['load_average_start'])} at start, "
        f"{'/'.join(f'{x:g}' for x in m.get('load_average_end', []))} at end",
        f"python {v['python']}, numpy {v.get('numpy')}, scipy {v.get('scipy')}, numba "
        f"{v.get('numba')} (JIT {'on' if m['jit'] else 'off'}), opencv {v.get('opencv')}, "
        f"RMW {m['rmw'] or '-'}; values: median over repeats [min, max]",
        "",
    ]
    fmt = "{:<4} {:<54} {:>10} {:>23} {:>10} {:>4}"
    lines.append(fmt.format("#", "figure", "median", "[min, max]", "budget", "met"))
    lines.append("-" * 110)
    notes = []
    for i, f in enumerate(result["figures"], start=1):
        unit = f["unit"]
        budget = f["budget"]["text"] if f["budget"] else ""
        if f["status"] != "measured":
            met = "n/m" if budget else ""
            lines.append(fmt.format(i, f["label"][:54], "-", "", budget, met).rstrip())
            notes.append(f"[{i}] {f['key']}: {f['status']}")
            continue
        rng = f"[{fmt_value(f['min'], unit)}, {fmt_value(f['max'], unit)}]"
        met = "" if f["met"] is None else ("yes" if f["met"] else "NO")
        lines.append(fmt.format(i, f["label"][:54], fmt_value(f["median"], unit), rng, budget,
                                met).rstrip())
        if f["note"]:
            notes.append(f"[{i}] {f['key']}: {f['note']}")
    b = result["budgets"]
    lines.append("")
    summary = f"budgets: {b['met']} of {b['total']} met"
    if b["missed"]:
        summary += "; NOT met: " + ", ".join(b["missed"])
    if b["not_measured"]:
        summary += "; not measured: " + ", ".join(b["not_measured"])
    lines.append(summary)
    lines.append(f"wall time {result['wall_time_s']:.0f} s ("
                 + ", ".join(f"{k} {w:.0f} s" for k, w in result["section_wall_s"].items())
                 + ")")
    lines.append("")
    lines.append("notes:")
    lines += [f"  {n}" for n in notes]
    return "\n".join(lines)


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (strict JSON), recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return json_safe(obj.item())
    return obj


def _sections_arg(text: str) -> list[str]:
    names = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in names if s not in SECTION_NAMES]
    if bad:
        raise argparse.ArgumentTypeError(
            f"unknown section(s) {', '.join(bad)}; choose from {', '.join(SECTION_NAMES)}")
    return names


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr bench``."""
    p = argparse.ArgumentParser(
        prog="bfr bench",
        description=(
            "Measure what a user of the emulated rig cares about, each figure as the median "
            "over repeats with min and max (the machine's noise), next to its budget: "
            "simulator real-time factors against scipy's solve_ivp (sim), render and detect "
            "time per camera frame (camera), the node suite over DDS in separate processes: "
            "camera node frame rate, state-to-torque latency, control rate, dropped frames "
            "(loop), and bfr diagnose / blindtest wall time and memory (diagnose). A figure "
            "that cannot be measured is reported as 'not measured' with the reason. Progress "
            "lines go to stderr. A full run takes about five minutes on 2 cores."),
        epilog="Budgets (issue 9; this machine, 2 cores): rigid model >= 50x real time in the "
               "simulator node's configuration; contact model >= 1x over a row of bumps; "
               "detection < 1 ms per frame; loop latency < 5 ms median with the camera at "
               "200 Hz and the controller at the camera's rate; no dropped frames at 200 Hz "
               "mono8; bfr diagnose of a 60 s recording < 60 s and < 2 GiB (render < 2 ms is "
               "camera-eval's target). Examples: bfr bench | bfr bench --json | bfr bench "
               "--only sim,camera --repeats 3 | bfr bench --quick --json --only sim,camera",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.add_argument("--only", type=_sections_arg, metavar="S[,S]",
                   help=f"run only these sections ({', '.join(SECTION_NAMES)})")
    p.add_argument("--skip", type=_sections_arg, metavar="S[,S]", default=[],
                   help="skip these sections")
    p.add_argument("--repeats", type=int, default=5, metavar="N",
                   help="repeats of the in-process measurements (sim, camera)")
    p.add_argument("--quick", action="store_true",
                   help="short horizons, few frames, one repeat unless --repeats is given, "
                        "a 6 s loop, a 10 s recording (for tests; noisier figures)")
    p.add_argument("--frames", type=int, default=100, metavar="N",
                   help="camera frames rendered and detected per repeat")
    p.add_argument("--loop-duration", type=float, default=30.0, metavar="S",
                   help="measured time of the DDS closed loop [s]")
    p.add_argument("--loop-windows", type=int, default=3, metavar="N",
                   help="the loop's measured time is split into N windows (its repeats)")
    p.add_argument("--loop-separate", action="store_true",
                   help="the loop's camera and controller as two processes (bfr rig --loop "
                        "separate) instead of composed in one (bfr rig --realtime's default)")
    p.add_argument("--diagnose-repeats", type=int, default=1, metavar="N",
                   help="runs of bfr diagnose (each about a minute)")
    p.add_argument("--diagnose-duration", type=float, default=60.0, metavar="S",
                   help="length of the recording diagnosed [s]")
    p.add_argument("--blindtest-cases", type=int, default=2, metavar="N",
                   help="cases of the timed bfr blindtest run")
    p.add_argument("--keep", metavar="DIR",
                   help="keep intermediate files (recording, node logs) in DIR")
    p.add_argument("--profile", metavar="DIR",
                   help="run the loop's node processes (timed by their main thread's CPU "
                        "time) and bfr diagnose under cProfile and write <node>.prof / "
                        "diagnose.prof to DIR (the figures are then slower: for finding what "
                        "limits them, not for the record)")
    p.add_argument("--strict", action="store_true",
                   help="exit with status 1 when a budget is not met")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bfr bench``; returns the exit status."""
    p = build_parser()
    args = p.parse_args(None if argv is None else list(argv))
    if args.repeats < 1 or args.frames < 1 or args.loop_windows < 1 \
            or args.diagnose_repeats < 1 or args.blindtest_cases < 1:
        p.error("--repeats, --frames, --loop-windows, --diagnose-repeats and "
                "--blindtest-cases must be >= 1")
    if not args.loop_duration > 0 or not args.diagnose_duration >= 10:
        p.error("--loop-duration must be > 0 s and --diagnose-duration >= 10 s")
    names = [n for n in (args.only or SECTION_NAMES) if n not in args.skip]
    if not names:
        p.error("no section left to run")
    opts = BenchOptions(
        repeats=1 if args.quick and args.repeats == 5 else args.repeats,
        quick=args.quick, frames=args.frames,
        loop_duration=min(args.loop_duration, 6.0) if args.quick else args.loop_duration,
        loop_windows=args.loop_windows, loop_separate=args.loop_separate,
        diagnose_repeats=args.diagnose_repeats,
        diagnose_duration=args.diagnose_duration, blindtest_cases=args.blindtest_cases,
        keep=args.keep, profile=args.profile)
    say = Progress(quiet=args.quiet)
    result = run_bench(names, opts, say)
    if args.json:
        sys.stdout.write(json.dumps(json_safe(result), indent=2, default=str,
                                    allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_table(result) + "\n")
    say(f"done in {result['wall_time_s']:.1f} s")
    return 1 if args.strict and result["budgets"]["missed"] else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
