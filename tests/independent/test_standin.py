"""The independent stand-in node over real DDS: contract, command response, stop, bad input.

The node runs as a subprocess (``python tests/independent/standin_node.py --ros-args ...``)
in this test process's private ROS domain (tests/rosutil.py); the test's own rclpy node
subscribes, waits for matched endpoints and publishes commands.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
import rosutil
import yaml
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray

from independent import render

NODE = Path(__file__).resolve().parent / "standin_node.py"
J_F = 1.58e-3  # [kg m^2] nominal frame inertia of the rig (seed Table 6.1)


def _t(stamp: object) -> float:
    return stamp.sec + stamp.nanosec * 1e-9  # type: ignore[attr-defined]


def _ros_args(**params: object) -> list[str]:
    out = ["--ros-args"]
    for name, value in params.items():
        out += ["-p", f"{name.replace('__', '.')}:={value}"]
    return out


def test_contract_command_response_and_clean_stop(ros_harness: rosutil.RosHarness,
                                                  node_processes: object,
                                                  tmp_path: Path) -> None:
    truth = tmp_path / "truth.csv"
    cam_yaml = tmp_path / "camera.yaml"
    node = node_processes.start_python(  # type: ignore[attr-defined]
        str(NODE), args=_ros_args(ball="false", time_scale=0.5, seed=4,
                                  truth_out=truth, camera_params_out=cam_yaml,
                                  command__timeout=0.05, status_period=1.0))
    h = ros_harness
    best_effort = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT,
                             history=HistoryPolicy.KEEP_LAST)
    got: dict[str, list] = {"js": [], "img": [], "info": [], "clock": []}
    subs = [
        h.node.create_subscription(JointState, "joint_states",
                                   lambda m: got["js"].append((time.monotonic(), m)),
                                   best_effort),
        h.node.create_subscription(Image, "camera/image_raw", got["img"].append, best_effort),
        h.node.create_subscription(CameraInfo, "camera/camera_info", got["info"].append,
                                   best_effort),
        h.node.create_subscription(Clock, "/clock",
                                   lambda m: got["clock"].append((time.monotonic(), m)),
                                   best_effort),
    ]
    pub = h.node.create_publisher(Float64MultiArray, "effort_controller/commands",
                                  QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    for sub in subs:
        h.wait_for_match(sub, timeout=20.0)
    h.wait_for_match(pub, timeout=20.0)
    # collect for at least 3 s of wall time (the clock rate below), and enough messages
    start_wall = time.monotonic()
    assert h.spin_until(lambda: time.monotonic() - start_wall > 3.0 and len(got["js"]) > 300
                        and len(got["img"]) > 60 and len(got["clock"]) > 300, timeout=30.0)
    h.node.destroy_subscription(subs[1])  # the images are the bulk of this test's load
    out = node.output()

    # --- types and QoS as the contract says
    types = dict(h.node.get_topic_names_and_types())
    assert types["/joint_states"] == ["sensor_msgs/msg/JointState"]
    assert types["/camera/image_raw"] == ["sensor_msgs/msg/Image"]
    assert types["/camera/camera_info"] == ["sensor_msgs/msg/CameraInfo"]
    assert types["/clock"] == ["rosgraph_msgs/msg/Clock"]
    assert types["/effort_controller/commands"] == ["std_msgs/msg/Float64MultiArray"]
    (js_info,) = h.node.get_publishers_info_by_topic("/joint_states")
    assert js_info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    (img_info,) = h.node.get_publishers_info_by_topic("/camera/image_raw")
    assert img_info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert img_info.qos_profile.durability == DurabilityPolicy.VOLATILE
    (sub_info,) = h.node.get_subscriptions_info_by_topic("/effort_controller/commands")
    assert sub_info.qos_profile.reliability == ReliabilityPolicy.RELIABLE

    # --- joint_states: 1 kHz of simulated time, the frame joint, position/velocity/effort
    js = [m for _, m in got["js"]]
    assert len(js) > 200, out
    assert all(list(m.name) == ["frame_joint"] and len(m.position) == len(m.velocity)
               == len(m.effort) == 1 for m in js)
    stamps = np.array([_t(m.header.stamp) for m in js])
    assert np.median(np.diff(stamps)) == pytest.approx(1e-3, abs=1e-9)

    # --- images and camera_info: mono8 640x480, 200 Hz, same stamps, plumb_bob, non-zero d
    assert len(got["img"]) > 50
    img = got["img"][-1]
    assert (img.encoding, img.width, img.height, img.step) == ("mono8", 640, 480, 640)
    assert len(img.data) == 640 * 480
    img_stamps = np.array([_t(m.header.stamp) for m in got["img"]])
    assert np.median(np.diff(img_stamps)) == pytest.approx(5e-3, abs=1e-9)
    # camera_info carries its image's stamp (both best effort: under load one may drop)
    info_stamps = {_t(m.header.stamp) for m in got["info"]}
    assert np.mean([s in info_stamps for s in img_stamps]) > 0.8
    assert all(abs(s * 200 - round(s * 200)) < 1e-6 for s in info_stamps)
    info = got["info"][-1]
    assert info.distortion_model == "plumb_bob" and len(info.d) == 5
    assert np.count_nonzero(info.d) >= 3 and (info.width, info.height) == (640, 480)
    assert info.header.frame_id == img.header.frame_id == "camera_optical_frame"

    # --- /clock advances at time_scale (0.5) of the wall clock, not at 1 and not in
    # lock-step (a loose bound: the machine is shared and the receiving side lags under load)
    clock = got["clock"]
    (w0, c0), (w1, c1) = clock[len(clock) // 5], clock[-1]
    assert (_t(c1.clock) - _t(c0.clock)) / (w1 - w0) == pytest.approx(0.5, rel=0.4)

    # --- the camera parameter file describes the camera the images come from
    params = yaml.safe_load(cam_yaml.read_text())["/**"]["ros__parameters"]
    k = np.array(params["camera"]["k"]).reshape(3, 3)
    assert np.allclose(k, np.array(info.k).reshape(3, 3))
    assert np.allclose(params["camera"]["d"], info.d)
    q = np.array(params["camera"]["orientation"])
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert params["input"]["use_camera_info"] is True
    # ... and rcl itself accepts it as a parameter file (one type per list, etc.)
    check = rclpy.Context()
    rclpy.init(args=["--ros-args", "--params-file", str(cam_yaml)], context=check)
    rclpy.shutdown(context=check)

    # --- command response: 0.05 N m on the bare frame (no friction) accelerates it at u / J_f
    def command(value: float, samples: int, timeout: float = 20.0) -> list:
        """Publish ``value`` at ~100 Hz until ``samples`` consecutive samples apply it."""
        start = len(got["js"])
        msg = Float64MultiArray(data=[value])

        def applied() -> list:
            run: list = []
            for _, m in got["js"][start:]:
                ok = m.effort[0] == min(value, 0.1) and (
                    not run or round((_t(m.header.stamp) - _t(run[-1].header.stamp)) * 1e3) == 1)
                run = [*run, m] if ok else ([m] if m.effort[0] == min(value, 0.1) else [])
            return run

        end = time.monotonic() + timeout
        while time.monotonic() < end and len(applied()) < samples:
            pub.publish(msg)
            h.spin_for(0.01)
        return applied()

    driven = command(0.05, 300)
    assert len(driven) >= 300, out
    t = np.array([_t(m.header.stamp) for m in driven])
    theta = np.array([m.position[0] for m in driven])
    acc = 2 * np.polyfit(t - t[0], theta, 2)[0]
    assert acc == pytest.approx(0.05 / J_F, rel=0.01)
    assert driven[-1].velocity[0] == pytest.approx(acc * (t[-1] - t[0]) + driven[0].velocity[0],
                                                   rel=0.02)
    # clamped to 0.1 N m
    clamped = command(1.0, 20)
    assert len(clamped) >= 20 and all(m.effort[0] == 0.1 for m in clamped)
    # silence: zero effort after command.timeout, the frame coasts at constant speed
    start = len(got["js"])
    h.spin_for(0.5)
    assert h.spin_until(lambda: len(got["js"]) - start > 200, timeout=20.0)
    coast = [m for _, m in got["js"][start:]][-100:]
    assert all(m.effort[0] == 0.0 for m in coast)
    t = np.array([_t(m.header.stamp) for m in coast])
    theta = np.array([m.position[0] for m in coast])
    assert abs(2 * np.polyfit(t - t[0], theta, 2)[0]) < 1.0  # [rad/s^2], against 31.6
    # malformed commands are ignored (a warning), not applied
    pub.publish(Float64MultiArray(data=[0.01, 0.02]))
    pub.publish(Float64MultiArray(data=[math.nan]))
    h.spin_for(0.3)

    # --- SIGINT: clean exit, the truth file written
    assert node.stop(timeout=10.0) == 0, node.log_path.read_text()
    out = node.log_path.read_text()
    assert "standin: stopped at t =" in out and "Traceback" not in out
    assert "2 rejected" in out
    data = np.genfromtxt(truth, delimiter=",", names=True)
    assert data.dtype.names == ("t", "theta", "theta_dot", "ball_x", "ball_y", "ball_angle",
                                "ball_angle_dot", "in_contact")
    assert len(data) > 1000 and np.all(np.diff(data["t"]) > 0)
    assert np.all(np.isnan(data["ball_x"])) and np.all(data["in_contact"] == 0)
    assert data["theta_dot"].max() > 0.05 / J_F * 0.25  # driven for >= 0.3 s of sim time


def test_ball_on_the_rig_is_seen_rolling(ros_harness: rosutil.RosHarness,
                                         node_processes: object, tmp_path: Path) -> None:
    """With the ball: the image's brightest blob sits where the truth puts the ball."""
    truth = tmp_path / "truth.csv"
    node = node_processes.start_python(  # type: ignore[attr-defined]
        str(NODE), args=_ros_args(time_scale=1.0, seed=2, initial__ball_angle=0.3,
                                  effects__coulomb_friction=0.006, effects__camera_latency=0.0,
                                  camera__noise=0.0, truth_out=truth, duration=30.0))
    h = ros_harness
    images: list = []
    sub = h.node.create_subscription(Image, "camera/image_raw", images.append,
                                     qos_profile_sensor_data)
    h.wait_for_match(sub, timeout=20.0)
    assert h.spin_until(lambda: len(images) >= 20, timeout=20.0), node.output()
    assert node.stop() == 0
    data = np.genfromtxt(truth, delimiter=",", names=True)
    cam = render.CameraModel()
    checked = 0
    for msg in images[-10:]:
        stamp = _t(msg.header.stamp)
        k = int(np.argmin(np.abs(data["t"] - stamp)))
        assert abs(data["t"][k] - stamp) < 1e-6 and data["in_contact"][k] == 1
        uv = cam.project(np.array([[data["ball_x"][k], data["ball_y"][k], 0.0]]))[0]
        img = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(480, 640)
        vs, us = np.nonzero(img > 180)
        assert len(us) > 100
        # the front plate hides the inner part of the ball: the blob's centroid lies a few
        # pixels outward of the centre, never far
        assert math.hypot(us.mean() - uv[0], vs.mean() - uv[1]) < 6.0
        checked += 1
    assert checked == 10


@pytest.mark.parametrize(("params", "message"), [
    ({"time_scale": -1}, "parameter time_scale out of range"),
    ({"effects.colomb_friction": 0.1}, "unknown parameter effects.colomb_friction"),
    ({"duration": "abc"}, "parameter duration must be a finite float"),
    ({"effects.bump_count": 3, "effects.bump_width": 1e-4, "effects.bump_height": 1e-3},
     "not regular"),
    ({"effects.frame_inertia_scale": 0}, "frame_inertia_scale must be > 0"),
])
def test_bad_parameters_exit_2_with_one_line(params: dict, message: str) -> None:
    args = ["--ros-args"]
    for name, value in params.items():
        args += ["-p", f"{name}:={value}"]
    proc = subprocess.run([sys.executable, str(NODE), *args], capture_output=True, text=True,
                          check=False, timeout=60, env=rosutil.ros_env())
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and lines[0].startswith("standin: error:")
