"""``bfr camera-eval``: accuracy and speed of the ball detector on seeded rendered frames.

Renders frames of the rig with :mod:`bfr_sim.render` (the frame at a random theta, the ball on
its track at a random phi, rolling, the front plate hiding part of it) under several
conditions, detects the ball with :class:`bfr_camera.detector.BallDetector` and prints one
table: position error (median and 99th percentile, pixels and millimetres), detection rate,
false detections on ball-free frames, median render time and median detection time (with a
region of interest and full-frame), each next to its target and whether it is met.

Conditions
----------
clean
    No noise, no blur (exposure 0), default lighting; the front plate hides part of the ball.
noise_blur
    Read + shot noise, defocus, motion blur over a 4 ms exposure at rolling speeds.
low_contrast
    Brighter background, dim ball, oblique light, vignetting, some noise and defocus.
occluded
    A foreign object (a bar) hides a further part of the ball's outline; some noise.
ball_free
    No ball, mixed conditions: any reported ball is a false detection.

The ROI timing gives the detector the ball's position one camera frame earlier as the last
fix (what tracking sees); the full-frame timing gives it none. Times are wall-clock medians on
this machine, single-threaded. It joins the renderer (``bfr_sim.render``) and the detector
(``bfr_camera.detector``), so it lives with the tools.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from bfr_camera.calibration import CameraModel, load_camera
from bfr_camera.detector import (
    BallDetector,
    Detection,
    DetectionStatus,
    DetectorConfig,
    load_detector_config,
)
from bfr_model.io.output import OutputError, atomic_dir
from bfr_model.params import load_params
from bfr_sim.render import (
    FrameRenderer,
    Lighting,
    Occluder,
    RenderOptions,
    RigScene,
    rig_scene,
)

__all__ = ["TARGETS", "evaluate", "format_table", "main"]

#: (condition, metric) -> (comparison, threshold, unit). Conditions "*" apply to all.
TARGETS: dict[tuple[str, str], tuple[str, float, str]] = {
    ("clean", "error_px_median"): ("<", 0.1, "px"),
    ("clean", "error_px_p99"): ("<", 0.5, "px"),
    ("noise_blur", "error_px_median"): ("<", 0.5, "px"),
    ("ball_free", "false_detections_full"): ("==", 0, ""),
    ("ball_free", "false_detections_roi"): ("==", 0, ""),
    ("*", "detect_ms_roi"): ("<", 1.0, "ms"),
    ("*", "render_ms"): ("<", 2.0, "ms"),
}

CONDITIONS = ("clean", "noise_blur", "low_contrast", "occluded", "ball_free")


@dataclass
class _Stats:
    errors_px: list[float] = field(default_factory=list)
    errors_mm: list[float] = field(default_factory=list)
    found: int = 0
    frames: int = 0
    false_full: int = 0
    false_roi: int = 0
    render_s: list[float] = field(default_factory=list)
    roi_s: list[float] = field(default_factory=list)
    full_s: list[float] = field(default_factory=list)


def _options(name: str, plate_z: float, rng: np.random.Generator) -> Any:
    """Render options of a condition (some drawn at random per frame)."""
    if name == "clean":
        return RenderOptions(plate_z=plate_z, exposure_time=0.0)
    if name == "noise_blur":
        return RenderOptions(plate_z=plate_z, noise_sigma=3.0, shot_noise=0.05,
                             defocus_sigma=0.7, exposure_time=4.0e-3)
    if name == "low_contrast":
        return RenderOptions(plate_z=plate_z, background=60.0, frame_level=90.0,
                             ball_level=125.0, noise_sigma=2.0, defocus_sigma=0.5,
                             lighting=Lighting(ambient=0.75, direction=(0.5, -0.4, 1.0),
                                               vignetting=0.35))
    if name == "occluded":
        return RenderOptions(plate_z=plate_z, noise_sigma=2.0)
    # ball_free: a mix of the others
    pick = int(rng.integers(0, 3))
    return _options(("clean", "noise_blur", "low_contrast")[pick], plate_z, rng)


def _bar_occluder(centre_px: np.ndarray, radius_px: float, outward: np.ndarray,
                  rng: np.random.Generator, level: float) -> Any:
    """A bar across part of the ball's visible outline (about a quarter of it)."""
    a = math.atan2(outward[1], outward[0]) + rng.uniform(-1.2, 1.2)
    d = np.array([math.cos(a), math.sin(a)])
    t = np.array([-d[1], d[0]])
    c = centre_px + d * radius_px * rng.uniform(0.85, 1.1)
    half_w, half_l = 0.2 * radius_px, 2.0 * radius_px
    pts = [c + sx * half_w * d + sy * half_l * t for sx, sy in ((-1, -1), (1, -1), (1, 1),
                                                                  (-1, 1))]
    return Occluder(tuple(map(tuple, pts)), level)


@dataclass(frozen=True, kw_only=True)
class _Setup:
    """What every condition of a run shares.

    Attributes
    ----------
    camera : CameraModel
        The camera.
    scene : RigScene
        The rig's frame outline and ball kinematics.
    detector_config : DetectorConfig
        The detector's parameters.
    repeat : int
        Timed runs per render and detection (the fastest kept).
    out_dir : Path or None
        Where example frames go.
    """

    camera: CameraModel
    scene: RigScene
    detector_config: DetectorConfig
    repeat: int
    out_dir: Path | None


@dataclass(frozen=True, kw_only=True)
class _Frame:
    """One drawn frame of a condition: the rig's state and what is rendered of it.

    Attributes
    ----------
    theta, phi, theta_dot, phi_dot : float
        Frame and contact angle [rad] and their rates [rad/s].
    options : RenderOptions
        How it is rendered.
    centre, velocity : ndarray
        The ball centre [m] and its velocity [m/s] in the world frame.
    truth_px : ndarray
        The ball centre's image [px].
    occluders : tuple of Occluder
        Extra occluders of this frame.
    """

    theta: float
    phi: float
    theta_dot: float
    phi_dot: float
    options: RenderOptions
    centre: np.ndarray
    velocity: np.ndarray
    truth_px: np.ndarray
    occluders: tuple[Occluder, ...]


def _draw_frame(name: str, setup: _Setup, rng: np.random.Generator) -> _Frame:
    """Draw the next frame of condition ``name`` (the order of the draws is the seed's)."""
    cam, scene = setup.camera, setup.scene
    theta = float(rng.uniform(-math.pi, math.pi))
    phi = float(rng.uniform(-math.pi, math.pi))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    theta_dot = sign * float(rng.uniform(1.5, 3.5))
    phi_dot = theta_dot * float(rng.uniform(0.7, 1.3))
    opts: RenderOptions = _options(name, scene.plate_z, rng)
    centre = scene.ball_centre(theta, phi)
    truth_px = cam.project(centre)
    occ: tuple[Occluder, ...] = ()
    if name == "occluded":
        outward = truth_px - cam.project(np.zeros(3))
        r_px = scene.ball_radius * cam.pixels_per_metre(centre)
        occ = (_bar_occluder(truth_px, r_px, outward, rng, float(rng.uniform(10, 90))),)
    return _Frame(theta=theta, phi=phi, theta_dot=theta_dot, phi_dot=phi_dot, options=opts,
                  centre=centre, velocity=scene.ball_velocity(theta, phi, theta_dot, phi_dot),
                  truth_px=truth_px, occluders=occ)


def _render_timed(rend: FrameRenderer, frame: _Frame, ball: np.ndarray | None, r_b: float,
                  rng: np.random.Generator, scratch: np.random.Generator, repeat: int
                  ) -> tuple[np.ndarray, float]:
    """Render ``frame`` (noise from ``rng``) and its best time of ``repeat`` runs [s].

    The repeated runs draw their noise from ``scratch``, so the image and ``rng`` do not
    depend on ``repeat``.
    """
    def render(noise: np.random.Generator) -> np.ndarray:
        return rend.render(frame.theta, ball, r_b, rng=noise, theta_dot=frame.theta_dot,
                           ball_velocity=frame.velocity, occluders=frame.occluders)

    t0 = time.perf_counter()
    img = render(rng)
    best = time.perf_counter() - t0
    for _ in range(repeat - 1):  # the same work again (scratch noise), for timing
        t0 = time.perf_counter()
        render(scratch)
        best = min(best, time.perf_counter() - t0)
    return img, best


def _detect_timed(detect: Callable[[], Detection], repeat: int) -> tuple[Detection, float]:
    """The first of ``repeat`` detections and the best processing time of them [s]."""
    first = detect()
    best = first.processing_time
    for _ in range(repeat - 1):
        best = min(best, detect().processing_time)
    return first, best


def _tally(st: _Stats, frame: _Frame, with_ball: bool, d_full: Detection,
           d_roi: Detection) -> None:
    """Count a frame's full-frame result (error to the truth), or a false detection."""
    found = (DetectionStatus.FOUND, DetectionStatus.AMBIGUOUS)
    if with_ball:
        if d_full.valid:
            st.found += 1
            st.errors_px.append(float(np.hypot(d_full.u - frame.truth_px[0],
                                               d_full.v - frame.truth_px[1])))
            st.errors_mm.append(1e3 * float(np.hypot(d_full.x - frame.centre[0],
                                                     d_full.y - frame.centre[1])))
    else:
        st.false_full += int(d_full.status in found)
        st.false_roi += int(d_roi.status in found)


def _run_condition(name: str, ci: int, frames: int, seed: int, setup: _Setup) -> _Stats:
    """Render, detect and score ``frames`` frames of condition ``name`` (the ``ci``-th)."""
    cam, scene, r_b, repeat = setup.camera, setup.scene, setup.scene.ball_radius, setup.repeat
    dt = 1.0 / cam.frame_rate
    rng = np.random.default_rng(np.random.SeedSequence([seed, ci]))
    scratch = np.random.default_rng(np.random.SeedSequence([seed, ci, 1]))
    det = BallDetector(cam, r_b, setup.detector_config)
    st = _Stats()
    renderers: dict[int, FrameRenderer] = {}
    with_ball = name != "ball_free"
    for k in range(frames):
        frame = _draw_frame(name, setup, rng)
        key = hash(frame.options)
        if key not in renderers:
            renderers[key] = FrameRenderer(cam, scene.outline, frame.options)
            renderers[key].render(0.0, None, rng=np.random.default_rng(0))  # warm-up
        img, render_s = _render_timed(renderers[key], frame, frame.centre if with_ball else None,
                                      r_b, rng, scratch, repeat)
        st.render_s.append(render_s)
        st.frames += 1
        # tracking: last fix = the ball one frame earlier; a fresh search: no fix
        prev = cam.project(scene.ball_centre(frame.theta - frame.theta_dot * dt,
                                             frame.phi - frame.phi_dot * dt))
        hint = (float(prev[0]), float(prev[1]))
        d_roi, roi_s = _detect_timed(partial(det.detect, img, frame.theta, hint=hint), repeat)
        st.roi_s.append(roi_s)
        det.reset()
        d_full, full_s = _detect_timed(partial(det.detect, img, frame.theta, use_roi=False),
                                       repeat)
        st.full_s.append(full_s)
        _tally(st, frame, with_ball, d_full, d_roi)
        if setup.out_dir is not None and k == 0:
            _save_example(setup.out_dir, name, img, d_full,
                          frame.truth_px if with_ball else None)
    return st


def evaluate(frames: int = 200, seed: int = 0, camera: CameraModel | None = None,
             params_path: str | None = None, camera_path: str | None = None,
             out_dir: Path | None = None, conditions: Sequence[str] = CONDITIONS,
             repeat: int = 3) -> dict[str, Any]:
    """Run the evaluation and return its results (what ``--json`` prints).

    Parameters
    ----------
    frames : int
        Frames per condition.
    seed : int
        Seed of every random draw (scene, noise).
    camera : CameraModel, optional
        Default: ``camera.yaml`` (``camera_path``).
    params_path, camera_path : str, optional
        ``rig.yaml`` and ``camera.yaml`` to use instead of the shipped ones.
    out_dir : Path, optional
        Where to save one example PNG per condition (raw and annotated).
    conditions : sequence of str
        Which of :data:`CONDITIONS` to run.
    repeat : int
        Each frame's render and detections are timed this many times and the fastest kept
        (the median over frames of these minima is reported): other processes on the
        machine then inflate the figures less. Results do not depend on it.
    """
    cam = camera if camera is not None else load_camera(camera_path)
    setup = _Setup(camera=cam, scene=rig_scene(load_params(params_path)),
                   detector_config=load_detector_config(camera_path), repeat=repeat,
                   out_dir=out_dir)
    results: dict[str, Any] = {
        "frames_per_condition": frames, "seed": seed,
        "camera": {"width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy,
                   "distance_m": float(np.linalg.norm(cam.c)),
                   "exposure_time_s": cam.exposure_time, "frame_rate_hz": cam.frame_rate},
        "ball_radius_m": setup.scene.ball_radius,
        "timing": f"median over frames of the best of {repeat} runs",
        "conditions": {},
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    for ci, name in enumerate(conditions):
        if name not in CONDITIONS:
            raise ValueError(f"unknown condition {name!r} (known: {CONDITIONS})")
        results["conditions"][name] = _summarise(name, _run_condition(name, ci, frames, seed,
                                                                      setup))
    results["rows"] = _rows(results["conditions"])
    results["all_targets_met"] = all(r["met"] for r in results["rows"] if r["met"] is not None)
    return results


def _save_example(out_dir: Path, name: str, img: np.ndarray, det: Detection,
                  truth: np.ndarray | None) -> None:
    cv2.imwrite(str(out_dir / f"{name}.png"), img)
    vis = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if truth is not None:
        t = (round(truth[0] * 16), round(truth[1] * 16))
        cv2.drawMarker(vis, (t[0] >> 4, t[1] >> 4), (0, 200, 0), cv2.MARKER_CROSS, 12, 1)
    if det.valid:
        c = (round(det.u * 16), round(det.v * 16))
        cv2.circle(vis, c, round(det.radius_px * 16), (0, 0, 255), 1, cv2.LINE_AA, 4)
    cv2.putText(vis, f"{name}: {det.status.name} {det.reason[:60]}", (8, 20),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 255, 255), 1, cv2.LINE_AA)
    cv2.imwrite(str(out_dir / f"{name}_annotated.png"), vis)


def _pct(x: list[float], q: float) -> float | None:
    return float(np.percentile(x, q)) if x else None


def _summarise(name: str, st: _Stats) -> dict[str, Any]:
    out: dict[str, Any] = {"frames": st.frames}
    if name != "ball_free":
        out.update(
            detection_rate=st.found / st.frames if st.frames else None,
            error_px_median=_pct(st.errors_px, 50), error_px_p99=_pct(st.errors_px, 99),
            error_mm_median=_pct(st.errors_mm, 50), error_mm_p99=_pct(st.errors_mm, 99),
        )
    else:
        out.update(false_detections_full=st.false_full, false_detections_roi=st.false_roi)
    out.update(render_ms=1e3 * float(np.median(st.render_s)),
               detect_ms_roi=1e3 * float(np.median(st.roi_s)),
               detect_ms_full=1e3 * float(np.median(st.full_s)))
    return out


_LABELS = {
    "detection_rate": ("detection rate", "%"),
    "error_px_median": ("position error, median", "px"),
    "error_px_p99": ("position error, p99", "px"),
    "false_detections_full": ("false detections, full frame", ""),
    "false_detections_roi": ("false detections, with ROI", ""),
    "render_ms": ("render time, median", "ms"),
    "detect_ms_roi": ("detect time with ROI, median", "ms"),
    "detect_ms_full": ("detect time full frame, median", "ms"),
}


def _rows(conds: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for cname, m in conds.items():
        for key, (label, unit) in _LABELS.items():
            if key not in m:
                continue
            value = m[key]
            tgt = TARGETS.get((cname, key)) or TARGETS.get(("*", key))
            met = None
            target = ""
            if tgt is not None:
                op, thr, tunit = tgt
                target = f"{op} {thr:g} {tunit}".strip()
                met = value is not None and (value < thr if op == "<" else value == thr)
            extra = None
            if key.startswith("error_px_"):
                extra = m.get(key.replace("_px_", "_mm_"))
            rows.append({"condition": cname, "metric": key, "label": label, "value": value,
                         "unit": unit, "mm": extra, "target": target, "met": met})
    return rows


def format_table(results: dict[str, Any]) -> str:
    """The results as an aligned text table."""
    cam = results["camera"]
    head = (f"bfr camera-eval: {results['frames_per_condition']} frames per condition, seed "
            f"{results['seed']}; camera {cam['width']}x{cam['height']} px, f = "
            f"{cam['fx']:.0f} px at {cam['distance_m']:.2f} m; ball R_b = "
            f"{1e3 * results['ball_radius_m']:.1f} mm; times: {results['timing']}")
    lines = [head, ""]
    fmt = "{:<13} {:<33} {:>22} {:>10} {:>5}"
    lines.append(fmt.format("condition", "metric", "value", "target", "met"))
    lines.append("-" * 87)
    for r in results["rows"]:
        v = r["value"]
        if v is None:
            text = "n/a"
        elif r["unit"] == "%":
            text = f"{100 * v:.1f} %"
        elif r["unit"] == "px":
            text = f"{v:.3f} px"
            if r["mm"] is not None:
                text += f" = {r['mm']:.3f} mm"
        elif r["unit"] == "ms":
            text = f"{v:.2f} ms"
        else:
            text = f"{v:g}"
        met = "" if r["met"] is None else ("yes" if r["met"] else "NO")
        lines.append(fmt.format(r["condition"], r["label"], text, r["target"], met).rstrip())
    lines.append("")
    lines.append("all targets met" if results["all_targets_met"] else "some targets NOT met")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bfr camera-eval``; returns the exit status."""
    p = argparse.ArgumentParser(
        prog="bfr camera-eval",
        description=(
            "Measure the ball detector on seeded rendered camera frames: position error "
            "(median, 99th percentile; px and mm), detection rate, false detections on "
            "ball-free frames, and median render / detect times, each against its target. "
            "Conditions: " + ", ".join(CONDITIONS) + "."),
        epilog="Times are wall-clock medians on this machine; the run is deterministic "
               "otherwise (same seed, same frames, same errors).")
    p.add_argument("--frames", type=int, default=200, metavar="N",
                   help="frames per condition (default: 200)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--out-dir", type=Path, default=None, metavar="DIR",
                   help="save an example frame per condition as PNG (raw and annotated); "
                        "written whole or not at all")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out-dir (else refused, exit 2)")
    p.add_argument("--camera", default=None, metavar="YAML",
                   help="camera parameter file (default: the shipped config/camera.yaml)")
    p.add_argument("--params", default=None, metavar="YAML",
                   help="rig parameter file (default: bfr_model's config/rig.yaml)")
    p.add_argument("--conditions", default=",".join(CONDITIONS), metavar="LIST",
                   help="comma-separated subset of: " + ", ".join(CONDITIONS))
    p.add_argument("--repeat", type=int, default=3, metavar="R",
                   help="time each frame's render and detection R times, keep the fastest "
                        "(default: 3; the median over frames is reported)")
    p.add_argument("--strict", action="store_true",
                   help="exit with status 1 if a target is not met")
    args = p.parse_args(None if argv is None else list(argv))
    if args.frames < 1:
        p.error("--frames must be >= 1")
    if args.repeat < 1:
        p.error("--repeat must be >= 1")
    conds = [c.strip() for c in args.conditions.split(",") if c.strip()]
    unknown = [c for c in conds if c not in CONDITIONS]
    if unknown:
        p.error(f"unknown condition(s) {unknown}; choose from {', '.join(CONDITIONS)}")
    try:
        with contextlib.ExitStack() as stack:
            out_dir = (None if args.out_dir is None
                       else stack.enter_context(atomic_dir(args.out_dir, args.force)))
            res = evaluate(frames=args.frames, seed=args.seed, params_path=args.params,
                           camera_path=args.camera, out_dir=out_dir, conditions=conds,
                           repeat=args.repeat)
    except (OutputError, OSError) as exc:
        print(f"bfr camera-eval: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        sys.stdout.write(json.dumps(res, indent=2) + "\n")
    else:
        sys.stdout.write(format_table(res) + "\n")
    return 1 if args.strict and not res["all_targets_met"] else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
