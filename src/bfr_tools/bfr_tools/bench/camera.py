"""``bfr bench`` section ``camera``: render and detect time per 640x480 frame.

Reuses :func:`bfr_tools.camera_eval.evaluate` (the code of ``bfr camera-eval``) with one timing
run per frame (``repeat=1``: a plain median over the frames of each repeat, not a best-of),
on its ``noise_blur`` condition (read and shot noise, defocus, motion blur over a 4 ms
exposure at rolling speeds: the harder case for the detector) and, for the render time of the
simulator node's own settings, its ``clean`` condition. Each bench repeat renders and detects
``frames`` new frames (a different seed per repeat); the table shows the median over repeats
of these per-repeat medians, with their min and max.

The camera node's sustained frame rate needs the node suite running and is measured by the
``loop`` section.
"""

from __future__ import annotations

from typing import Any

from bfr_tools.bench.common import (
    BenchOptions,
    Budget,
    Figure,
    FigureSpec,
    Progress,
)
from bfr_tools.camera_eval import TARGETS, evaluate

__all__ = ["SPECS", "run"]


def _target(key: str) -> Budget | None:
    """camera-eval's target for a metric (all conditions), as a budget."""
    t = TARGETS.get(("*", key))
    if t is None:
        return None
    return Budget(t[0], float(t[1]), "camera-eval target")


SPECS: list[FigureSpec] = [
    FigureSpec("camera.detect_ms_roi", "detect per frame, tracking ROI (noise+blur)", "ms",
               Budget("<", 1.0)),
    FigureSpec("camera.detect_ms_full", "detect per frame, full-frame search (noise+blur)",
               "ms"),
    FigureSpec("camera.render_ms", "render per frame 640x480 (noise+blur)", "ms",
               _target("render_ms")),
    FigureSpec("camera.render_ms_clean", "render per frame 640x480 (clean)", "ms",
               _target("render_ms")),
    FigureSpec("camera.detect_ms_roi_clean", "detect per frame, tracking ROI (clean)", "ms",
               Budget("<", 1.0)),
]
_BY_KEY = {s.key: s for s in SPECS}


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``camera`` section (module docstring)."""
    frames = min(opts.frames, 20) if opts.quick else opts.frames
    repeats = opts.repeats
    vals: dict[str, list[float]] = {s.key: [] for s in SPECS}
    meta: dict[str, Any] = {}
    for rep in range(repeats):
        say(f"camera: render + detect {frames} frames per condition, repeat {rep + 1}/{repeats}")
        res = evaluate(frames=frames, seed=1000 + rep, conditions=("noise_blur", "clean"),
                       repeat=1)
        meta = res["camera"]
        nb = res["conditions"]["noise_blur"]
        cl = res["conditions"]["clean"]
        vals["camera.detect_ms_roi"].append(nb["detect_ms_roi"])
        vals["camera.detect_ms_full"].append(nb["detect_ms_full"])
        vals["camera.render_ms"].append(nb["render_ms"])
        vals["camera.render_ms_clean"].append(cl["render_ms"])
        vals["camera.detect_ms_roi_clean"].append(cl["detect_ms_roi"])
    size = f"{meta.get('width', '?')}x{meta.get('height', '?')}"
    note = (f"bfr_tools.camera_eval, {frames} frames per repeat, {size}, median over frames "
            f"(no best-of), single thread; {repeats} repeat(s)")
    return [Figure(s, vals[s.key], note=note) for s in SPECS]
