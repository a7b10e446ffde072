"""``bfr bench`` section ``view``: what watching the rig costs (markers, ``bfr video``).

- ``view.markers_ms``: one ``sim_markers`` message as the simulator node makes it at each
  ``markers.rate`` instant: the picture (:func:`bfr_model.scene.rig_picture`), the marker
  specs, the ``visualization_msgs/MarkerArray`` and its CDR serialisation (what DDS and the
  recorder send); median per message over ``frames`` messages at different states, per
  repeat. At 30 Hz of simulated time the share of one core is ``30 * markers_ms / 1000`` per
  simulated second.
- ``view.video_ms``: one 640x480 frame of ``bfr video`` (state lookup, drawing, the mp4v
  encoder), from the mean over a ``frames``-frame video of a synthetic rolling recording,
  per repeat; ``view.video_rtf`` is the same as a real-time factor at 30 frames/s.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import OffsetCurve
from bfr_model.params import load_params
from bfr_model.recording import Recording
from bfr_model.scene import rig_markers, rig_picture
from bfr_ros.markers import marker_array
from rclpy.serialization import serialize_message

from bfr_tools.bench.common import BenchOptions, Budget, Figure, FigureSpec, Progress
from bfr_tools.video import VideoPlan, _states, _Writer, frame_times, render_frame

__all__ = ["SPECS", "run"]

SPECS: list[FigureSpec] = [
    FigureSpec("view.markers_ms", "sim_markers message: picture, markers, CDR", "ms",
               Budget("<", 1.67, "issue 18: under 5 % of a core at 30 Hz")),
    FigureSpec("view.video_ms", "bfr video, per 640x480 frame (draw + mp4v)", "ms",
               Budget("<", 33.3, "issue 18: real time at 30 frames/s")),
    FigureSpec("view.video_rtf", "bfr video at 30 frames/s, real-time factor", "x"),
]


def _marker_ms(n: int, seed: int) -> float:
    """Median time of one sim_markers message [ms] over n random states."""
    p = load_params()
    curve = OffsetCurve.from_params(p)
    rng = np.random.default_rng(seed)
    out = []
    for theta, phi in rng.uniform(-np.pi, np.pi, size=(n, 2)):
        t0 = time.perf_counter()
        pic = rig_picture(curve, float(theta), phi=float(phi), ball_radius=p.ball.radius,
                          plate_distance=p.ball.plate_distance)
        serialize_message(marker_array(rig_markers(pic, label="t 1.00 s"), 1_000_000))
        out.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(out))


def _video_ms(frames: int) -> float:
    """Mean time of one 640x480 mp4v frame of ``bfr video`` [ms] on a rolling recording."""
    p = load_params()
    curve = OffsetCurve.from_params(p)
    t = np.arange(0.0, frames / 30.0, 1e-3)
    x = np.column_stack([0.3 + 2.4 * t, 0.2 + 2.4 * t])
    ball = RigidModel(p).ball_position(x)
    rec = Recording(t=t, theta=x[:, 0], theta_dot=np.full_like(t, 2.4),
                    torque=0.05 * np.sin(t), ball_x=ball[:, 0], ball_y=ball[:, 1],
                    ball_valid=np.ones(t.size, bool), phi=x[:, 1])
    plan = VideoPlan.fit(p, curve, 640, 480, "bench")
    times = frame_times(float(t[0]), float(t[-1]), 30.0, 1.0)
    with tempfile.TemporaryDirectory() as d:
        w = _Writer(Path(d) / "bench.mp4", "mp4", "mp4v", 30.0, (640, 480))
        t0 = time.perf_counter()
        for s in _states(rec, times, p, curve, None):
            w.write(render_frame(plan, s))
        w.close()
        return 1e3 * (time.perf_counter() - t0) / len(times)


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``view`` section (module docstring)."""
    n = min(opts.frames, 60) if opts.quick else max(opts.frames, 300)
    vals: dict[str, list[float]] = {s.key: [] for s in SPECS}
    for rep in range(opts.repeats):
        say(f"view: {n} marker messages and a {n}-frame video, repeat {rep + 1}/{opts.repeats}")
        vals["view.markers_ms"].append(_marker_ms(n, 100 + rep))
        ms = _video_ms(n)
        vals["view.video_ms"].append(ms)
        vals["view.video_rtf"].append((1000.0 / 30.0) / ms)
    note = (f"{n} messages / frames per repeat, {opts.repeats} repeat(s); OpenCV "
            f"{cv2.__version__} with {cv2.getNumThreads()} thread(s)")
    return [Figure(s, vals[s.key], note=note) for s in SPECS]
