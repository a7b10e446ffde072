#!/usr/bin/env python3
"""A hardware stand-in on the wall clock, for ``bfr rig --hardware`` (not the simulator node).

It keeps only the hardware topic contract of docs/hardware.md, as a ros2_control system
with a camera driver would: ``joint_states`` (``frame_joint``, reliable, keep last 10) at
``--joint-rate``, ``camera/image_raw`` (mono8) and ``camera/camera_info`` (plumb_bob, the
same stamp: the exposure's mid-time) at ``--frame-rate``, both stamped with **this
computer's clock** (no ``/clock``: ``use_sim_time`` false), and it takes
``effort_controller/commands`` (``std_msgs/Float64MultiArray``). Its plant and images are
the independent rig's (tests/independent/physics.py, render.py: written apart from bfr),
with the frame braked (the commanded torque is counted, not applied) and the ball rolling
to and fro in the waist, as in the commissioning's first recording (docs/hardware.md 4b).

Usage::

    python tests/hardware_standin.py --camera-params-out /tmp/hw_camera.yaml [--duration S]

Writes the camera's pose and intrinsics as a parameter file for the camera node, then runs
until SIGINT/SIGTERM (or ``--duration`` wall seconds) and prints on stderr
``stand-in: published N joint_states, M images; received K commands, last U N m``.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the independent rig's modules

import rclpy
from independent import physics, render
from independent.standin_node import camera_parameter_yaml
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import (
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray

NS = 1_000_000_000


def stamp(msg_time: object, t_ns: int) -> None:
    msg_time.sec, msg_time.nanosec = t_ns // NS, t_ns % NS  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--camera-params-out", required=True)
    p.add_argument("--duration", type=float, default=0.0, help="wall seconds (0: until SIGINT)")
    p.add_argument("--joint-rate", type=float, default=500.0)
    p.add_argument("--frame-rate", type=float, default=100.0)
    p.add_argument("--ball-angle", type=float, default=0.25, help="ball-centre angle [rad]")
    args = p.parse_args(argv)

    params = physics.RigParams()
    camera = render.CameraModel()
    plant = physics.Plant(params, ball=True, theta=0.0, ball_angle=args.ball_angle,
                          frame_locked=True, dt=1e-3)
    renderer = render.Renderer(params, camera, np.random.default_rng(5), noise_std=1.5)
    Path(args.camera_params_out).write_text(camera_parameter_yaml(camera, args.frame_rate))

    rclpy.init(args=["--ros-args"], signal_handler_options=SignalHandlerOptions.NO)
    stop: list[int] = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    node = rclpy.create_node("hardware_standin")
    reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                          reliability=ReliabilityPolicy.RELIABLE)
    js_pub = node.create_publisher(JointState, "joint_states", reliable)
    img_pub = node.create_publisher(Image, "camera/image_raw", qos_profile_sensor_data)
    info_pub = node.create_publisher(CameraInfo, "camera/camera_info", qos_profile_sensor_data)
    commands: list[float] = []
    node.create_subscription(Float64MultiArray, "effort_controller/commands",
                             lambda m: commands.append(float(m.data[0]) if m.data else math.nan),
                             reliable)
    info = CameraInfo()
    info.width, info.height = camera.width, camera.height
    info.distortion_model = "plumb_bob"
    info.d = [float(v) for v in camera.distortion]
    info.k = [float(v) for v in camera.k_matrix.reshape(-1)]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.p = [info.k[0], 0.0, info.k[2], 0.0, 0.0, info.k[4], info.k[5], 0.0, 0.0, 0.0, 1.0, 0.0]
    info.header.frame_id = "camera_optical_frame"

    executor = SingleThreadedExecutor()  # the commands, taken on a thread of their own
    executor.add_node(node)
    done = threading.Event()

    def spin() -> None:
        while not done.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    dt_js, dt_img = 1.0 / args.joint_rate, 1.0 / args.frame_rate
    t0 = time.monotonic()
    next_js = next_img = t0
    n_js = n_img = 0
    print(f"stand-in: joint_states {args.joint_rate:g} Hz, images {args.frame_rate:g} Hz on "
          f"the system clock; frame braked, ball at {args.ball_angle:g} rad", file=sys.stderr,
          flush=True)
    while not stop and (args.duration <= 0 or time.monotonic() - t0 < args.duration):
        now = time.monotonic()
        if now >= next_js:
            plant.advance(dt_js, 0.0)  # braked: the command is not applied
            s = plant.state()
            js = JointState()
            stamp(js.header.stamp, time.time_ns())
            js.name = ["frame_joint"]
            js.position, js.velocity, js.effort = [s.theta], [s.theta_dot], [0.0]
            js_pub.publish(js)
            n_js += 1
            next_js += dt_js
        if now >= next_img:
            s = plant.state()
            t_exp = time.time_ns()  # the exposure, now: what the frame shows
            frame = renderer.render(s.theta, (s.ball_x, s.ball_y)
                                    if math.isfinite(s.ball_x) else None)
            img = Image()
            stamp(img.header.stamp, t_exp)
            img.header.frame_id = "camera_optical_frame"
            img.height, img.width = frame.shape
            img.encoding, img.step = "mono8", frame.shape[1]
            img.data = frame.tobytes()
            img_pub.publish(img)
            stamp(info.header.stamp, t_exp)
            info_pub.publish(info)
            n_img += 1
            next_img += dt_img
        time.sleep(max(0.0, min(next_js, next_img) - time.monotonic()))
    last = f"{commands[-1]:g}" if commands else "none"
    print(f"stand-in: published {n_js} joint_states, {n_img} images; received "
          f"{len(commands)} commands, last {last} N m", file=sys.stderr, flush=True)
    done.set()
    spinner.join(timeout=5.0)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
