"""``bfr video``: any recording (bag, CSV, rig log) as a video of the rig seen from the front.

Reads the recording with :func:`bfr_model.io.read_recording` (so every format and every rig
the readers know), samples it at ``--fps`` frames per video second (``--speed`` recorded
seconds per video second, zero-order hold: each frame shows the latest sample at or before
its instant) and draws each frame with OpenCV:

- the frame (one plate, filled) at its angle theta, with a mark on its +y axis (the contour
  is pi-symmetric: the mark shows the turns) and the shaft;
- the ball where the recording puts it (the camera's fix, held; nothing when the fix is not
  valid), the simulator's true ball as a white ring when the recording has a truth, and the
  contact point (red) from theta and the ball's position alone (:mod:`bfr_model.scene`);
- a torque bar (the command against the actuator's limit; red when at the limit), the
  controller's mode when the recording has it (a bag's ``controller_state``, a CSV's ``mode``
  column), whether the ball is seen, and the time stamp.

Geometry and colours are those of the markers the nodes publish (:mod:`bfr_model.scene`), from
the rig parameters (``--params``, default the shipped rig.yaml): draw another rig of the
design by giving its file.

Output: ``.mp4`` (OpenCV's writer, MPEG-4 Part 2 ``mp4v``), ``.avi`` (``MJPG``) or ``.gif``
(``cv2.imwriteanimation``). When the writer cannot open the codec, the video is written as an
animated GIF beside the requested name instead, and the command says so. The file is written
under a temporary name and renamed at the end, so a failure leaves nothing behind and an
existing file is replaced only with ``--force``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from bfr_model.geometry import OffsetCurve
from bfr_model.io import account_line, read_recording
from bfr_model.io.bag import make_typestore, read_bag_messages
from bfr_model.param_file import ParameterError
from bfr_model.params import RigParams, load_params
from bfr_model.recording import Recording
from bfr_model.scene import COLORS, RigPicture, rig_picture
from numpy.typing import NDArray

from bfr_interfaces.msg import ControllerState

__all__ = ["VideoError", "VideoPlan", "frame_times", "main", "render_frame"]

#: ``ControllerState.mode`` code -> name, from the message definition's constants.
MODE_NAMES = {getattr(ControllerState, n): n for n in ("WAITING", "ROLLING", "BALL_LOST",
                                                        "FAULT")}
_NS = 1_000_000_000
_GIF_MAX_BYTES = 1 << 30  # frames a GIF holds in memory before it is written


class VideoError(ValueError):
    """Bad input or output for ``bfr video``; the message is one line naming the problem."""


def _bgr(name: str) -> tuple[int, int, int]:
    r, g, b, _ = COLORS[name]
    return (round(255 * b), round(255 * g), round(255 * r))


# -- what to draw ----------------------------------------------------------------------------
def frame_times(t0: float, t1: float, fps: float, speed: float) -> NDArray[np.float64]:
    """Recording instants [s] of the video's frames: ``t0 + k speed / fps`` up to ``t1``.

    ``n = floor((t1 - t0) fps / speed) + 1`` frames (a 1 ns tolerance for rounding).
    """
    n = math.floor((t1 - t0) * fps / speed + 1e-9) + 1
    return t0 + np.arange(n) * (speed / fps)


def _bag_modes(path: Path, rec: Recording) -> tuple[NDArray[np.float64], NDArray[np.int64]] | None:
    """(times [s] on the recording's axis, mode codes) of a bag's ``controller_state``."""
    topics = rec.meta.get("bag_topics", {})
    topic = str(topics.get("controller", "controller_state")).lstrip("/")
    msgs = [m for m in read_bag_messages(path).messages if m.topic.lstrip("/") == topic]
    if not msgs:
        return None
    store = make_typestore()
    states = [store.deserialize_cdr(m.data, m.msgtype) for m in msgs]
    stamp = np.array([s.header.stamp.sec * _NS + s.header.stamp.nanosec for s in states])
    origin = int(rec.meta.get("time_origin_ns", 0))
    order = np.argsort(stamp, kind="stable")
    return ((stamp[order] - origin) / _NS,
            np.array([states[i].mode for i in order], dtype=np.int64))


def recording_modes(path: Path, rec: Recording) -> tuple[NDArray[np.float64],
                                                         NDArray[np.int64]] | None:
    """The controller's mode over time, when the recording has it (else None).

    A bag's ``controller_state`` messages (their stamps on the recording's time axis), or a
    CSV's ``mode`` column (``rec.extra["mode"]``). A rig log has none.
    """
    if "mode" in rec.extra:
        m = np.asarray(rec.extra["mode"], dtype=float)
        ok = np.isfinite(m)
        return (rec.t[ok], m[ok].astype(np.int64)) if ok.any() else None
    if rec.meta.get("source_kind") == "bag" or rec.meta.get("bag_storage"):
        return _bag_modes(path, rec)
    return None


@dataclass(frozen=True, kw_only=True)
class VideoPlan:
    """How recording coordinates map to the picture, and what surrounds the rig.

    Attributes
    ----------
    width, height : int
        Frame size [px].
    scale : float
        Pixels per metre.
    centre : tuple of 2 float
        Pixel position of the frame's axis [px].
    torque_limit : float
        The actuator's limit [N m]: the torque bar's full scale.
    title : str
        Shown in the top line (the recording's name).
    """

    width: int
    height: int
    scale: float
    centre: tuple[float, float]
    torque_limit: float
    title: str

    @classmethod
    def fit(cls, params: RigParams, curve: OffsetCurve, width: int, height: int,
            title: str) -> VideoPlan:
        """The rig (contour and ball at any angle) fitted between the text lines."""
        reach = float(np.max(curve.rho(np.linspace(0, 2 * np.pi, 720)))) \
            + 2.0 * params.ball.radius
        top, bottom = 0.11 * height, 0.16 * height  # text lines, torque bar
        avail = min(width, height - top - bottom)
        scale = 0.5 * avail / (1.06 * reach)
        return cls(width=width, height=height, scale=scale,
                   centre=(0.5 * width, top + 0.5 * (height - top - bottom)),
                   torque_limit=params.actuator.torque_limit, title=title)

    def px(self, xy: Any) -> NDArray[np.float64]:
        """World (x, y) [m] -> pixel (u, v) [px] (x right, y up)."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([self.centre[0] + self.scale * xy[..., 0],
                         self.centre[1] - self.scale * xy[..., 1]], -1)


_SHIFT = 4  # sub-pixel bits of OpenCV's drawing calls


def _pt(uv: Any) -> tuple[int, int]:
    return (round(float(uv[0]) * (1 << _SHIFT)), round(float(uv[1]) * (1 << _SHIFT)))


def _text(img: NDArray[np.uint8], s: str, org: tuple[int, int], size: float,
          color: tuple[int, int, int] = (235, 235, 235)) -> None:
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, size, color, max(1, round(2 * size)),
                cv2.LINE_AA)


@dataclass(frozen=True, kw_only=True)
class FrameState:
    """What one frame shows (recording values held at its instant).

    Attributes
    ----------
    t : float
        Time stamp [s].
    picture : RigPicture
        Frame, ball (the recording's fix) and contact point.
    truth : ndarray, shape (2,), or None
        The simulator's true ball centre [m].
    torque : float
        Commanded torque [N m].
    mode : str
        The controller's mode, or "" when not recorded.
    ball_seen : bool
        Whether a valid fix is held.
    """

    t: float
    picture: RigPicture
    truth: NDArray[np.float64] | None
    torque: float
    mode: str
    ball_seen: bool


def render_frame(plan: VideoPlan, s: FrameState) -> NDArray[np.uint8]:
    """One BGR frame (module docstring), shape (height, width, 3)."""
    img = np.full((plan.height, plan.width, 3), (38, 34, 30), np.uint8)
    pic = s.picture
    poly = np.array([_pt(p) for p in plan.px(pic.contour)], np.int32)
    cv2.fillPoly(img, [poly], _bgr("back_plate"), cv2.LINE_AA, _SHIFT)
    cv2.polylines(img, [poly], True, _bgr("front_plate"), 2, cv2.LINE_AA, _SHIFT)
    axis = plan.px(np.zeros(2))
    mark = plan.px(pic.contour[0] * 0.8)  # contour[0]: phi = 0, the frame's +y axis
    cv2.line(img, _pt(axis), _pt(mark), _bgr("front_plate"), 2, cv2.LINE_AA, _SHIFT)
    cv2.circle(img, _pt(axis), round(0.006 * plan.scale * (1 << _SHIFT)), _bgr("shaft"), -1,
               cv2.LINE_AA, _SHIFT)
    r_px = pic.ball_radius * plan.scale
    if pic.ball is not None:
        cv2.circle(img, _pt(plan.px(pic.ball[:2])), round(r_px * (1 << _SHIFT)), _bgr("ball"),
                   -1, cv2.LINE_AA, _SHIFT)
    if s.truth is not None and bool(np.all(np.isfinite(s.truth))):
        cv2.circle(img, _pt(plan.px(s.truth)), round(r_px * (1 << _SHIFT)), _bgr("truth"), 1,
                   cv2.LINE_AA, _SHIFT)
    if pic.contact is not None:
        cv2.circle(img, _pt(plan.px(pic.contact)), round(max(2.5, 0.2 * r_px) * (1 << _SHIFT)),
                   _bgr("contact"), -1, cv2.LINE_AA, _SHIFT)
    _draw_text_and_torque(img, plan, s)
    return img


def _draw_text_and_torque(img: NDArray[np.uint8], plan: VideoPlan, s: FrameState) -> None:
    w, h = plan.width, plan.height
    size = 0.45 * h / 480
    line = round(0.045 * h)
    _text(img, f"t = {s.t:9.3f} s", (round(0.02 * w), line), 1.3 * size)
    mode = s.mode or "not recorded"
    ball = "ball seen" if s.ball_seen else "ball NOT seen"
    _text(img, f"mode {mode}   {ball}", (round(0.02 * w), 2 * line), size)
    tw = cv2.getTextSize(plan.title, cv2.FONT_HERSHEY_SIMPLEX, size, 1)[0][0]
    _text(img, plan.title, (w - tw - round(0.02 * w), line), size, (170, 170, 170))
    # the torque bar: zero in the middle, the actuator's limit at the ends
    y0, y1 = round(h - 0.085 * h), round(h - 0.045 * h)
    x0, x1 = round(0.1 * w), round(0.9 * w)
    xm = (x0 + x1) // 2
    cv2.rectangle(img, (x0, y0), (x1, y1), (90, 90, 90), 1)
    lim = plan.torque_limit
    frac = max(-1.0, min(1.0, s.torque / lim)) if math.isfinite(s.torque) else 0.0
    at_limit = math.isfinite(s.torque) and abs(s.torque) >= 0.999 * lim
    colour = (40, 40, 220) if at_limit else (80, 200, 80)
    xe = round(xm + frac * (x1 - xm))
    if xe != xm:
        cv2.rectangle(img, (min(xm, xe), y0 + 2), (max(xm, xe), y1 - 2), colour, -1)
    cv2.line(img, (xm, y0 - 4), (xm, y1 + 4), (200, 200, 200), 1)
    _text(img, f"torque {s.torque:+.4f} N m  (limit {lim:g})", (x0, y0 - round(0.012 * h)),
          size)


# -- the command ---------------------------------------------------------------------------
def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if not (64 <= w <= 4096 and 64 <= h <= 4096) or w % 2 or h % 2:
        raise argparse.ArgumentTypeError(f"size {w}x{h}: each side even and in [64, 4096]")
    return w, h


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bfr video",
        description="Render a recording (ROS 2 bag, simulator CSV or NTNU rig log) as a video "
        "of the rig seen from the front: the frame at its angle, the ball, the contact point, "
        "a torque bar, the controller's mode and a time stamp.")
    p.add_argument("recording", type=Path, help="bag directory / .mcap / .db3, .csv or .txt")
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="video file to write: .mp4 (mp4v), .avi (MJPG) or .gif")
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.add_argument("--allow-partial", action="store_true",
                   help="use the recording even when more than 1 %% of its samples could not "
                        "be read (the read's account on stderr says which)")
    p.add_argument("--fps", type=float, default=None,
                   help="frames per video second (default 30; 15 for a GIF)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="recorded seconds per video second (default 1: real time)")
    p.add_argument("--start", type=float, default=None,
                   help="first instant [s] on the recording's time axis (default: its start)")
    p.add_argument("--end", type=float, default=None,
                   help="last instant [s] (default: its end)")
    p.add_argument("--size", type=_size, default=None, metavar="WxH",
                   help="frame size in pixels (default 640x480; 320x240 for a GIF)")
    p.add_argument("--params", default=None,
                   help="rig.yaml of the rig drawn (default: the shipped one)")
    p.add_argument("--fourcc", default="mp4v",
                   help="OpenCV codec of an .mp4 (default mp4v); if it cannot be opened the "
                        "video is written as a GIF instead")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


class _ProgressBar:
    """Progress on stderr: a bar redrawn in place on a terminal, a line per 10 % otherwise."""

    def __init__(self, total: int, quiet: bool) -> None:
        self.total, self.quiet = max(total, 1), quiet
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.shown = -1

    def update(self, done: int) -> None:
        """Report ``done`` frames of the total."""
        if self.quiet:
            return
        pct = 100 * done // self.total
        step = 1 if self.tty else 10
        if pct // step == self.shown and done != self.total:
            return
        self.shown = pct // step
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        rate = done / max(time.perf_counter() - self.t0, 1e-9)
        text = f"bfr video: [{bar}] {pct:3d} % {done}/{self.total} frames, {rate:5.1f} frames/s"
        if self.tty:
            print("\r" + text, end="\n" if done == self.total else "", file=sys.stderr,
                  flush=True)
        else:
            print(text, file=sys.stderr, flush=True)


class _Writer:
    """mp4/avi through cv2.VideoWriter, GIF through cv2.imwriteanimation (frames in memory)."""

    def __init__(self, path: Path, kind: str, fourcc: str, fps: float,
                 size: tuple[int, int]) -> None:
        self.path, self.kind, self.fps = path, kind, fps
        self.frames: list[NDArray[np.uint8]] = []
        self.vw: Any = None
        if kind != "gif":
            code = cv2.VideoWriter_fourcc(*fourcc) if len(fourcc) == 4 else -2
            # the container follows the file name: keep the real extension on the temp file
            self.vw = cv2.VideoWriter(str(path), code, fps, size) if code != -2 else None
            if self.vw is None or not self.vw.isOpened():
                raise VideoError(f"OpenCV cannot write {kind} with codec {fourcc!r}")

    def write(self, frame: NDArray[np.uint8]) -> None:
        if self.vw is not None:
            self.vw.write(frame)
        else:
            self.frames.append(frame)

    def close(self) -> None:
        if self.vw is not None:
            self.vw.release()
            return
        anim = cv2.Animation()
        anim.frames = self.frames
        anim.durations = [round(1000.0 / self.fps)] * len(self.frames)
        anim.loop_count = 0
        if not cv2.imwriteanimation(str(self.path), anim):
            raise VideoError(f"{self.path}: OpenCV could not write the GIF")


def _states(rec: Recording, times: NDArray[np.float64], params: RigParams, curve: OffsetCurve,
            modes: tuple[NDArray[np.float64], NDArray[np.int64]] | None
            ) -> Any:
    """The :class:`FrameState` of each frame instant (a generator)."""
    idx = np.clip(np.searchsorted(rec.t, times, side="right") - 1, 0, len(rec) - 1)
    truth = rec.ball_x_true is not None and rec.ball_y_true is not None
    for t, k in zip(times, idx, strict=True):
        seen = bool(rec.ball_valid[k])
        pic = rig_picture(curve, float(rec.theta[k]),
                          ball_xy=(rec.ball_x[k], rec.ball_y[k]) if seen else None,
                          ball_radius=params.ball.radius,
                          plate_distance=params.ball.plate_distance)
        mode = ""
        if modes is not None:
            j = np.searchsorted(modes[0], t, side="right") - 1
            mode = MODE_NAMES.get(int(modes[1][j]), str(int(modes[1][j]))) if j >= 0 else "-"
        yield FrameState(
            t=float(t), picture=pic, torque=float(rec.torque[k]), mode=mode, ball_seen=seen,
            truth=np.array([rec.ball_x_true[k], rec.ball_y_true[k]]) if truth else None)


def _window(rec: Recording, start: float | None, end: float | None) -> tuple[float, float]:
    t0 = float(rec.t[0]) if start is None else start
    t1 = float(rec.t[-1]) if end is None else end
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise VideoError(f"--start {t0:g} s / --end {t1:g} s must be finite")
    if t0 > rec.t[-1] or t1 < rec.t[0]:
        raise VideoError(f"--start {t0:g} s / --end {t1:g} s lies outside the recording "
                         f"({rec.t[0]:g} to {rec.t[-1]:g} s)")
    if t1 < t0:
        raise VideoError(f"--start {t0:g} s / --end {t1:g} s: the end must not precede the start")
    return max(t0, float(rec.t[0])), min(t1, float(rec.t[-1]))


def _output(args: argparse.Namespace) -> tuple[Path, str]:
    out: Path = args.output
    kind = out.suffix.lower().lstrip(".")
    if kind not in ("mp4", "avi", "gif"):
        raise VideoError(f"{out}: unknown video kind {out.suffix!r} (use .mp4, .avi or .gif)")
    if out.is_dir():
        raise VideoError(f"{out}: is a directory")
    if out.exists() and not args.force:
        raise VideoError(f"{out} exists already (use --force to replace it)")
    if not out.parent.exists():
        raise VideoError(f"{out.parent}: no such directory")
    return out, kind


def make_video(args: argparse.Namespace) -> tuple[Path, int, str]:
    """Write the video (module docstring); returns (file written, frames, note)."""
    out, kind = _output(args)
    for name in ("fps", "speed"):
        v = getattr(args, name)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise VideoError(f"--{name} must be > 0, got {v}")
    try:
        params = load_params(args.params)
    except (ParameterError, OSError) as exc:
        raise VideoError(f"--params: {exc}") from exc
    if not args.recording.exists():
        raise VideoError(f"{args.recording}: no such recording (file or bag directory)")
    with warnings.catch_warnings(record=True) as caught:  # the reader's notes, one line each
        warnings.simplefilter("always")
        rec = read_recording(args.recording, allow_partial=args.allow_partial)
    for w in caught:
        print(f"bfr video: warning: {w.message}", file=sys.stderr)
    print(f"bfr video: {account_line([rec])}", file=sys.stderr)
    t0, t1 = _window(rec, args.start, args.end)
    note = ""
    gif = kind == "gif"
    fourcc = "MJPG" if kind == "avi" and args.fourcc == "mp4v" else args.fourcc
    fps = args.fps or (15.0 if gif else 30.0)
    size = args.size or ((320, 240) if gif else (640, 480))
    curve = OffsetCurve.from_params(params)
    plan = VideoPlan.fit(params, curve, size[0], size[1], args.recording.name)
    times = frame_times(t0, t1, fps, args.speed)
    tmp = out.with_name(f".{out.stem}.partial-{os.getpid()}{out.suffix}")
    try:
        writer = _Writer(tmp, kind, fourcc, fps, size)
    except VideoError as exc:  # no codec: an animated GIF instead
        out, gif = out.with_suffix(".gif"), True
        if out.exists() and not args.force:
            raise VideoError(f"{exc}; the GIF fallback {out} exists already (use --force)") \
                from None
        fps = args.fps or 15.0
        size = args.size or (320, 240)
        plan = VideoPlan.fit(params, curve, size[0], size[1], args.recording.name)
        times = frame_times(t0, t1, fps, args.speed)
        tmp = out.with_name(f".{out.stem}.partial-{os.getpid()}.gif")
        writer = _Writer(tmp, "gif", fourcc, fps, size)
        note = f"{exc}: wrote an animated GIF instead"
    if gif and len(times) * size[0] * size[1] * 3 > _GIF_MAX_BYTES:
        raise VideoError(f"a GIF of {len(times)} frames of {size[0]}x{size[1]} would hold "
                         f"{len(times) * size[0] * size[1] * 3 / 2**30:.1f} GiB in memory: "
                         f"lower --fps or --size, or shorten --start/--end")
    bar = _ProgressBar(len(times), args.quiet)
    modes = recording_modes(args.recording, rec)
    try:
        for k, state in enumerate(_states(rec, times, params, curve, modes), start=1):
            writer.write(render_frame(plan, state))
            bar.update(k)
        writer.close()
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return out, len(times), note


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``bfr video`` (module docstring)."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    t_wall = time.perf_counter()
    try:
        out, n, note = make_video(args)
    except (ValueError, OSError) as exc:  # RecordingError, BagError, VideoError, ...
        print(f"bfr video: error: {exc}".splitlines()[0], file=sys.stderr)
        return 2
    wall = time.perf_counter() - t_wall
    if note:
        print(f"bfr video: {note}", file=sys.stderr)
    print(f"bfr video: wrote {out} ({n} frames, {out.stat().st_size / 1e6:.1f} MB) in "
          f"{wall:.1f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
