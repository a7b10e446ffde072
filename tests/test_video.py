"""``bfr video``: frames, sizes and contents of videos of a CSV, a bag and a real rig log.

The recordings are made here from the rigid model's kinematics (not by the video code), a bag
is written with the project's bag writer, and the real NTNU log is used where present; each
video is read back with OpenCV (frame count, size) and single frames are checked where the
rig's geometry puts the ball, the axis and the contact point. Bad input gives one line and
exit status 2, and never replaces a file.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import OffsetCurve
from bfr_model.io.bag import write_recording_bag
from bfr_model.io.csv_io import write_csv
from bfr_model.params import load_params
from bfr_model.recording import Recording
from bfr_model.scene import COLORS, rig_picture
from bfr_tools.video import (
    FrameState,
    VideoPlan,
    frame_times,
    main,
    recording_modes,
    render_frame,
)

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ntnu-rig"
P = load_params()
CURVE = OffsetCurve.from_params(P)


def bgr(name: str) -> tuple[int, int, int]:
    r, g, b, _ = COLORS[name]
    return (round(255 * b), round(255 * g), round(255 * r))


def synthetic(duration: float = 2.0, rate: float = 100.0) -> Recording:
    """The ball rolling on the frame (rigid kinematics), a torque ramp, a 0.2 s camera gap."""
    t = np.arange(0.0, duration + 1e-9, 1.0 / rate)
    theta, phi = 0.3 + 2.4 * t, 0.2 + 2.4 * t
    ball = RigidModel(P).ball_position(np.column_stack([theta, phi]))
    valid = ~((t >= 1.0) & (t < 1.2))
    mode = np.where(valid, 1.0, 2.0)  # ROLLING, BALL_LOST in the gap
    return Recording(t=t, theta=theta, theta_dot=np.full_like(t, 2.4),
                     torque=np.clip(0.1 * t - 0.05, -0.1, 0.1), ball_x=ball[:, 0],
                     ball_y=ball[:, 1], ball_valid=valid,
                     phi=theta + np.arctan2(ball[:, 0], ball[:, 1]), extra={"mode": mode},
                     meta={"source_kind": "test"})


def count_frames(path: Path) -> tuple[int, int, int]:
    cap = cv2.VideoCapture(str(path))
    n, shape = 0, (0, 0)
    while True:
        ok, f = cap.read()
        if not ok:
            break
        n, shape = n + 1, f.shape[:2]
    cap.release()
    return n, shape[1], shape[0]


def test_frame_times() -> None:
    assert len(frame_times(0.0, 2.0, 10.0, 1.0)) == 21
    assert len(frame_times(0.0, 2.0, 10.0, 2.0)) == 11  # twice as fast: half the frames
    assert frame_times(1.0, 1.05, 30.0, 1.0).tolist() == [1.0, 1.0 + 1 / 30]


def test_csv_video_frame_count_size_and_mode(tmp_path: Path) -> None:
    rec = synthetic()
    csv = tmp_path / "run.csv"
    write_csv(csv, rec)
    out = tmp_path / "run.mp4"
    assert main([str(csv), "-o", str(out), "--fps", "10", "--size", "320x240", "--quiet"]) == 0
    assert count_frames(out) == (21, 320, 240)
    modes = recording_modes(csv, rec)
    assert modes is not None and set(modes[1].tolist()) == {1, 2}
    assert not list(tmp_path.glob(".run.partial*"))  # the temporary file is gone


def test_bag_video_and_its_modes(tmp_path: Path) -> None:
    bag = write_recording_bag(tmp_path / "bag", synthetic(1.0))
    out = tmp_path / "bag.mp4"
    assert main([str(bag), "-o", str(out), "--fps", "20", "--quiet"]) == 0
    assert count_frames(out) == (21, 640, 480)
    from bfr_model.io import read_recording  # noqa: PLC0415 - only here

    modes = recording_modes(bag, read_recording(bag))
    assert modes is not None and modes[1][0] == 1  # the bag writer's ROLLING


def test_frame_shows_the_rig_where_the_recording_puts_it() -> None:
    plan = VideoPlan.fit(P, CURVE, 640, 480, "test")
    theta, phi = 0.7, 1.9
    ball = RigidModel(P).ball_position([theta, phi])
    pic = rig_picture(CURVE, theta, ball_xy=ball, ball_radius=P.ball.radius,
                      plate_distance=P.ball.plate_distance)
    img = render_frame(plan, FrameState(t=1.5, picture=pic, truth=None, torque=0.1,
                                        mode="ROLLING", ball_seen=True))
    u, v = np.round(plan.px(ball)).astype(int)
    assert tuple(img[v, u]) == bgr("ball")
    cu, cv_ = np.round(plan.px(pic.contact)).astype(int)
    assert tuple(img[cv_, cu]) == bgr("contact")
    au, av = np.round(plan.px([0.0, 0.0])).astype(int)
    assert tuple(img[av, au]) == bgr("shaft")
    # a point of the plate inside the contour, away from the mark: the plate's colour
    inner = np.round(plan.px(0.5 * pic.contour[30])).astype(int)
    assert tuple(img[inner[1], inner[0]]) == bgr("back_plate")
    # the torque bar at the limit: red, reaching the right end
    row = img[round(480 - 0.065 * 480)]
    red = np.nonzero((row[:, 2] > 200) & (row[:, 1] < 60))[0]
    assert red.size and red.max() >= round(0.9 * 640) - 3 and red.min() >= 320 - 1
    # no ball: nothing ball-coloured anywhere
    empty = rig_picture(CURVE, theta, ball_radius=P.ball.radius,
                        plate_distance=P.ball.plate_distance)
    img2 = render_frame(plan, FrameState(t=1.5, picture=empty, truth=None, torque=0.0,
                                         mode="", ball_seen=False))
    assert not np.any(np.all(img2 == bgr("ball"), axis=-1))


def test_gif_and_the_no_codec_fallback(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    csv = tmp_path / "r.csv"
    write_csv(csv, synthetic(1.0))
    gif = tmp_path / "r.gif"
    assert main([str(csv), "-o", str(gif), "--fps", "5", "--size", "160x120", "--quiet"]) == 0
    ok, anim = cv2.imreadanimation(str(gif))
    assert ok and len(anim.frames) == 6 and anim.frames[0].shape[:2] == (120, 160)
    # a codec OpenCV cannot open: the same video as a GIF beside the requested name
    mp4 = tmp_path / "nocodec.mp4"
    assert main([str(csv), "-o", str(mp4), "--fourcc", "ZZZZ", "--fps", "5", "--size",
                 "160x120", "--quiet"]) == 0
    err = capsys.readouterr()
    assert not mp4.exists() and (tmp_path / "nocodec.gif").exists()
    assert "wrote an animated GIF instead" in err.err and "nocodec.gif" in err.out


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ntnu-rig is absent")
def test_real_rig_log(tmp_path: Path) -> None:
    out = tmp_path / "fin.mp4"
    assert main([str(DATA / "fin.txt"), "-o", str(out), "--start", "10", "--end", "11",
                 "--quiet"]) == 0
    assert count_frames(out) == (31, 640, 480)


@pytest.mark.parametrize(("args", "message"), [
    (["missing.csv"], "no such recording"),
    (["{csv}", "--start", "50"], "outside the recording"),
    (["{csv}", "--end", "0.5", "--start", "1"], "must not precede"),
    (["{csv}", "--fps", "0"], "--fps must be > 0"),
    (["{txt}"], "no data lines"),
])
def test_bad_input_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                   args: list[str], message: str) -> None:
    csv = tmp_path / "r.csv"
    write_csv(csv, synthetic(1.0))
    txt = tmp_path / "notalog.txt"
    txt.write_text("hello\nworld\n")
    argv = [a.format(csv=csv, txt=txt) for a in args]
    if argv[0] == "missing.csv":
        argv[0] = str(tmp_path / "missing.csv")
    out = tmp_path / "v.mp4"
    assert main([*argv, "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    # one error line; before it at most the read's account (one line)
    lines = err.splitlines()
    assert lines[-1].startswith("bfr video: error:") and message in lines[-1], err
    assert len(lines) == 1 or (len(lines) == 2 and lines[0].startswith("bfr video: read ")), err
    assert not out.exists() and not list(tmp_path.glob(".v.partial*"))


def test_never_overwrites_without_force(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "r.csv"
    write_csv(csv, synthetic(0.5))
    out = tmp_path / "v.mp4"
    out.write_bytes(b"precious")
    assert main([str(csv), "-o", str(out), "--quiet"]) == 2
    assert "exists already" in capsys.readouterr().err
    assert out.read_bytes() == b"precious"
    assert main([str(csv), "-o", str(tmp_path / "v.webm"), "--quiet"]) == 2
    assert main([str(csv), "-o", str(out), "--quiet", "--force"]) == 0
    assert count_frames(out)[0] == math.floor(0.5 * 30) + 1
