#!/usr/bin/env python3
"""A ROS 2 hardware stand-in for a Butterfly rig, written apart from bfr (a real rclpy node).

It is what a ros2_control hardware interface plus a camera driver would be on another rig of
the same design: its own physics (physics.py), its own camera and renderer (render.py), its
own encoder conventions (sensors.py). No lock-step: simulated time runs at ``time_scale``
times the wall clock whatever the other nodes do.

Usage::

    python tests/independent/standin_node.py --ros-args -p time_scale:=0.5 -p seed:=3 \\
        -p initial.ball_angle:=0.2 -p effects.coulomb_friction:=0.004 \\
        -p camera_params_out:=/tmp/cam.yaml -p truth_out:=/tmp/truth.csv

Topics (relative names; README "Topic contract" of bfr):

* publishes ``joint_states`` (sensor_msgs/JointState, ``["frame_joint"]``, position [rad],
  velocity [rad/s], effort [N m]: the torque the actuator is commanded to apply) at
  ``joint_states.rate`` of simulated time, reliable, keep last 10;
* publishes ``camera/image_raw`` (mono8 640x480) and ``camera/camera_info`` (plumb_bob,
  this camera's intrinsics; same stamp) at ``camera.frame_rate``, sensor-data QoS; stamp =
  exposure mid-time; published ``effects.camera_latency`` of simulated time later;
* publishes ``/clock`` (rosgraph_msgs/Clock) with every sample and frame, reliable;
* subscribes ``effort_controller/commands`` (std_msgs/Float64MultiArray, one element [N m]):
  clamped to +-``actuator.torque_limit``, held (zero-order hold), zero after
  ``command.timeout`` of simulated time without one.

Start: at once (a rig's drive and camera do not wait for anyone), or, with ``start.wait`` > 0,
once the image and effort topics each have a peer and joint_states ``start.joint_states_peers``
(as an operator holds the ball until the camera and the controller are up), waiting at most
``start.wait`` wall seconds.

Stops after ``duration`` [s simulated] (0: never) or on SIGINT/SIGTERM, writing
``truth_out`` (CSV: t, theta, theta_dot, ball_x, ball_y, ball_angle, ball_angle_dot,
in_contact) either way. Bad parameters: one line on stderr, exit code 2.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):  # run as a script: make the package importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    __package__ = "independent"

from . import physics, render, sensors

#: Truth CSV columns (in this order).
TRUTH_COLUMNS = ("t", "theta", "theta_dot", "ball_x", "ball_y", "ball_angle",
                 "ball_angle_dot", "in_contact")


class ConfigError(ValueError):
    """A parameter of the stand-in is unusable (reported on one line, exit code 2)."""


@dataclass(frozen=True, kw_only=True)
class StandInConfig:
    """Everything the stand-in was started with (read from ROS parameters).

    Parameters
    ----------
    rig : physics.RigParams
        Physics and effects.
    camera : render.CameraModel
        The camera.
    encoder : sensors.EncoderConfig
        Encoder and velocity conventions.
    time_scale : float
        Simulated seconds per wall second [-].
    duration : float
        Simulated time to run [s]; 0 runs until SIGINT.
    seed : int
        Seed of every random choice (bumps, pixel noise).
    ball : bool
        A ball is on the frame.
    frame_locked : bool
        The frame is braked.
    theta, theta_dot, ball_angle, ball_angle_dot : float
        Initial state [rad, rad/s] (ball angle clockwise from the frame's +y axis).
    joint_rate : float
        joint_states rate [Hz, simulated time].
    frame_rate : float
        Camera frame rate [Hz, simulated time].
    camera_latency : float
        Delay from exposure mid-time to publication [s, simulated].
    camera_noise : float
        Pixel noise [DN].
    camera_stamp_jitter : float
        Standard deviation of the error of an image's stamp [s] (a driver that stamps on
        arrival; 0: the exposure mid-time).
    camera_occlusion : bool
        The front plate hides the inner part of the ball (False: a transparent plate).
    torque_limit : float
        Actuator clamp [N m].
    command_timeout : float
        Zero torque after this long without a command [s, simulated].
    physics_dt : float
        Integration step [s].
    camera_params_out, truth_out : str
        Output paths ('' for none).
    status_period : float
        Wall time between status lines on stderr [s].
    start_wait : float
        Longest wall time to wait for the peers before starting [s]; 0 starts at once.
    start_js_peers : int
        Subscriptions of joint_states to wait for (the camera and the controller: 2).
    """

    rig: physics.RigParams
    camera: render.CameraModel
    encoder: sensors.EncoderConfig
    time_scale: float = 0.5
    duration: float = 0.0
    seed: int = 0
    ball: bool = True
    frame_locked: bool = False
    theta: float = 0.0
    theta_dot: float = 0.0
    ball_angle: float = 0.0
    ball_angle_dot: float = 0.0
    joint_rate: float = 1000.0
    frame_rate: float = 200.0
    camera_latency: float = 0.004
    camera_noise: float = 2.5
    camera_stamp_jitter: float = 0.0
    camera_occlusion: bool = True
    torque_limit: float = 0.1
    command_timeout: float = 0.05
    physics_dt: float = 1e-3
    camera_params_out: str = ""
    truth_out: str = ""
    status_period: float = 5.0
    start_wait: float = 0.0
    start_js_peers: int = 1
    bumps: tuple[physics.Bump, ...] = field(default=())

    def __post_init__(self) -> None:
        checks = (("time_scale", self.time_scale > 0.0), ("duration", self.duration >= 0.0),
                  ("joint_states.rate", 10.0 <= self.joint_rate <= 10000.0),
                  ("camera.frame_rate", 1.0 <= self.frame_rate <= 1000.0),
                  ("effects.camera_latency", 0.0 <= self.camera_latency <= 1.0),
                  ("camera.noise", self.camera_noise >= 0.0),
                  ("camera.stamp_jitter", 0.0 <= self.camera_stamp_jitter <= 0.1),
                  ("actuator.torque_limit", self.torque_limit > 0.0),
                  ("command.timeout", self.command_timeout > 0.0),
                  ("physics.dt", 1e-5 <= self.physics_dt <= 2e-3),
                  ("status_period", self.status_period > 0.0),
                  ("start.wait", 0.0 <= self.start_wait <= 600.0),
                  ("start.joint_states_peers", 1 <= self.start_js_peers <= 100))
        for name, ok in checks:
            if not ok:
                raise ConfigError(f"parameter {name} out of range: {getattr(self, _FIELD[name])}")


_FIELD = {"time_scale": "time_scale", "duration": "duration", "joint_states.rate": "joint_rate",
          "camera.frame_rate": "frame_rate", "effects.camera_latency": "camera_latency",
          "camera.noise": "camera_noise", "camera.stamp_jitter": "camera_stamp_jitter",
          "actuator.torque_limit": "torque_limit",
          "command.timeout": "command_timeout", "physics.dt": "physics_dt",
          "status_period": "status_period", "start.wait": "start_wait",
          "start.joint_states_peers": "start_js_peers"}

#: Declared parameters: name -> default (the type of the default is the expected type).
PARAMETERS: dict[str, Any] = {
    "time_scale": 0.5, "duration": 0.0, "seed": 0, "ball": True, "frame_locked": False,
    "initial.theta": 0.0, "initial.theta_dot": 0.0, "initial.ball_angle": 0.0,
    "initial.ball_angle_dot": 0.0,
    "effects.coulomb_friction": 0.0, "effects.coulomb_friction_negative": -1.0,
    "effects.viscous_friction": 0.0, "effects.torque_offset": 0.0, "effects.motor_gain": 1.0,
    "effects.frame_inertia_scale": 1.0, "effects.imbalance": 0.0,
    "effects.imbalance_angle": 0.0, "effects.rolling_radius_delta": 0.0,
    "effects.contour_radius_delta": 0.0, "effects.contour_b_delta": 0.0,
    "effects.harmonics_cos": [0.0] * physics.N_HARMONICS,
    "effects.harmonics_sin": [0.0] * physics.N_HARMONICS,
    "effects.ball_radius_delta": 0.0, "effects.ball_mass_scale": 1.0,
    "effects.rolling_resistance": 0.0, "effects.shaft_tilt": 0.0, "effects.bump_count": 0,
    "effects.bump_height": 3e-4, "effects.bump_width": 4e-3, "effects.camera_latency": 0.004,
    "joint_states.rate": 1000.0, "encoder.counts_per_rev": 16384,
    "encoder.velocity_window": 2, "encoder.velocity_filter": 0.0,
    "camera.frame_rate": 200.0, "camera.noise": 2.5, "camera.stamp_jitter": 0.0,
    "camera.occlusion": True,
    "camera.position": list(render.CameraModel().position),
    "camera.look_at": list(render.CameraModel().look_at), "camera.roll": render.CameraModel().roll,
    "actuator.torque_limit": 0.1, "command.timeout": 0.05, "physics.dt": 1e-3,
    "camera_params_out": "", "truth_out": "", "status_period": 5.0, "start.wait": 0.0,
    "start.joint_states_peers": 1,
}


def _typed(name: str, value: Any) -> Any:
    """Convert a parameter value to the type of its default, or raise ConfigError."""
    default = PARAMETERS[name]
    try:
        if isinstance(default, bool):
            if isinstance(value, bool):
                return value
            raise TypeError
        if isinstance(default, int):
            if isinstance(value, bool) or float(value) != int(value):
                raise TypeError
            return int(value)
        if isinstance(default, float):
            if isinstance(value, bool | str):
                raise TypeError
            out = float(value)
            if not math.isfinite(out):
                raise TypeError
            return out
        if isinstance(default, list):
            out_list = [float(v) for v in value]
            if len(out_list) != len(default) or not all(map(math.isfinite, out_list)):
                raise TypeError
            return out_list
        return str(value)
    except (TypeError, ValueError, OverflowError):
        kind = type(default).__name__ + (f"[{len(default)}]" if isinstance(default, list) else "")
        raise ConfigError(f"parameter {name} must be a finite {kind}, got {value!r}") from None


def config_from_values(values: dict[str, Any]) -> StandInConfig:
    """Build the configuration from parameter values (missing names take their defaults).

    Parameters
    ----------
    values : dict
        Parameter name -> value.

    Returns
    -------
    StandInConfig
        The checked configuration.

    Raises
    ------
    ConfigError
        Naming the first unusable parameter.
    """
    unknown = sorted(set(values) - set(PARAMETERS))
    if unknown:
        raise ConfigError(f"unknown parameter {unknown[0]}")
    v = {name: _typed(name, values.get(name, default)) for name, default in PARAMETERS.items()}
    rng = np.random.default_rng(v["seed"])
    bumps = tuple(physics.Bump(angle=float(a), height=v["effects.bump_height"],
                               width=v["effects.bump_width"])
                  for a in rng.uniform(0.0, 2 * np.pi, size=v["effects.bump_count"]))
    base = physics.RigParams()
    coulomb = v["effects.coulomb_friction"]
    coulomb_neg = v["effects.coulomb_friction_negative"]
    try:
        rig = physics.RigParams(
            coulomb_pos=coulomb, coulomb_neg=coulomb if coulomb_neg < 0.0 else coulomb_neg,
            viscous=v["effects.viscous_friction"], torque_offset=v["effects.torque_offset"],
            motor_gain=v["effects.motor_gain"],
            frame_inertia_scale=v["effects.frame_inertia_scale"],
            imbalance=v["effects.imbalance"], imbalance_angle=v["effects.imbalance_angle"],
            rolling_radius_delta=v["effects.rolling_radius_delta"],
            contour_radius_delta=v["effects.contour_radius_delta"],
            contour_b=base.contour_b + v["effects.contour_b_delta"],
            harmonics_cos=tuple(v["effects.harmonics_cos"]),
            harmonics_sin=tuple(v["effects.harmonics_sin"]),
            ball_radius=base.ball_radius + v["effects.ball_radius_delta"],
            ball_mass=base.ball_mass * v["effects.ball_mass_scale"],
            rolling_resistance=v["effects.rolling_resistance"],
            shaft_tilt=v["effects.shaft_tilt"], bumps=bumps)
        camera = render.CameraModel(position=tuple(v["camera.position"][:3]),  # type: ignore[arg-type]
                                    look_at=tuple(v["camera.look_at"][:3]),  # type: ignore[arg-type]
                                    roll=v["camera.roll"])
        encoder = sensors.EncoderConfig(counts_per_rev=v["encoder.counts_per_rev"],
                                        velocity_window=v["encoder.velocity_window"],
                                        velocity_filter=v["encoder.velocity_filter"])
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return StandInConfig(
        rig=rig, camera=camera, encoder=encoder, time_scale=v["time_scale"],
        duration=v["duration"], seed=v["seed"], ball=v["ball"], frame_locked=v["frame_locked"],
        theta=v["initial.theta"], theta_dot=v["initial.theta_dot"],
        ball_angle=v["initial.ball_angle"], ball_angle_dot=v["initial.ball_angle_dot"],
        joint_rate=v["joint_states.rate"], frame_rate=v["camera.frame_rate"],
        camera_latency=v["effects.camera_latency"], camera_noise=v["camera.noise"],
        camera_stamp_jitter=v["camera.stamp_jitter"],
        camera_occlusion=v["camera.occlusion"],
        torque_limit=v["actuator.torque_limit"], command_timeout=v["command.timeout"],
        physics_dt=v["physics.dt"], camera_params_out=v["camera_params_out"],
        truth_out=v["truth_out"], status_period=v["status_period"],
        start_wait=v["start.wait"], start_js_peers=v["start.joint_states_peers"], bumps=bumps)


def camera_parameter_yaml(camera: render.CameraModel, frame_rate: float) -> str:
    """The camera's pose and intrinsics as a ROS 2 parameter file for bfr's camera node.

    Format of bfr's docs/hardware.md, section 2: ``camera.position`` [m] and
    ``camera.orientation`` (quaternion x y z w) of the optical frame in the world frame,
    ``camera.exposure_time`` [s], ``camera.frame_rate`` [Hz], the intrinsics ``k``, ``d``,
    ``width``, ``height`` (used until the first camera_info) and
    ``input.use_camera_info: true``; for any node name (``/**``).

    Parameters
    ----------
    camera : render.CameraModel
        The camera.
    frame_rate : float
        Frame rate [Hz].

    Returns
    -------
    str
        YAML text.
    """
    q = camera.quaternion_xyzw()
    k = camera.k_matrix.reshape(-1).tolist()

    def fmt(values: Any) -> str:  # always with a decimal point: rcl wants one type per list
        return "[" + ", ".join(repr(float(x)) for x in values) + "]"

    return (
        "# Camera of the independent Butterfly rig (tests/independent/standin_node.py).\n"
        "# Pose of the optical frame in the world frame (origin on the axis, x right, y up,\n"
        "# z towards the camera); intrinsics as published on camera/camera_info.\n"
        "/**:\n"
        "  ros__parameters:\n"
        "    camera:\n"
        f"      position: {fmt(camera.position)}  # [m]\n"
        f"      orientation: {fmt(q)}  # [-] quaternion x y z w\n"
        f"      exposure_time: {float(camera.exposure_time)!r}  # [s]\n"
        f"      frame_rate: {float(frame_rate)!r}  # [Hz]\n"
        f"      width: {camera.width}  # [px]\n"
        f"      height: {camera.height}  # [px]\n"
        f"      k: {fmt(k)}  # [px]\n"
        f"      d: {fmt(camera.distortion)}  # [-] plumb_bob k1 k2 p1 p2 k3\n"
        "    input:\n"
        "      use_camera_info: true\n")


def write_truth(path: str, rows: list[tuple[float, ...]]) -> None:
    """Write the truth CSV (header: :data:`TRUTH_COLUMNS`); NaN where there is no ball.

    Parameters
    ----------
    path : str
        Output file.
    rows : list of tuple
        One tuple per joint_states sample.
    """
    data = np.asarray(rows, dtype=float).reshape(-1, len(TRUTH_COLUMNS))
    fmt = ["%.6f"] + ["%.9g"] * 6 + ["%d"]
    np.savetxt(path, data, delimiter=",", header=",".join(TRUTH_COLUMNS), comments="",
               fmt=fmt)


def _stamp(msg_time: Any, t_ns: int) -> None:
    msg_time.sec, msg_time.nanosec = divmod(t_ns, 1_000_000_000)


def _log(text: str) -> None:
    print(f"standin: {text}", file=sys.stderr, flush=True)


class StandIn:
    """The stand-in's ROS side and its real-time loop.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (parameters already read into ``config``).
    config : StandInConfig
        The configuration.
    """

    def __init__(self, node: Any, config: StandInConfig) -> None:
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: PLC0415 - ROS imports only where ROS is used
        from rosgraph_msgs.msg import Clock  # noqa: PLC0415
        from sensor_msgs.msg import CameraInfo, Image, JointState  # noqa: PLC0415
        from std_msgs.msg import Float64MultiArray  # noqa: PLC0415

        self.node, self.cfg = node, config
        self.rng = np.random.default_rng(config.seed)
        self.plant = physics.Plant(
            config.rig, ball=config.ball, theta=config.theta, theta_dot=config.theta_dot,
            ball_angle=config.ball_angle, ball_angle_dot=config.ball_angle_dot,
            frame_locked=config.frame_locked, dt=config.physics_dt)
        self.renderer = render.Renderer(config.rig, config.camera, self.rng,
                                        noise_std=config.camera_noise,
                                        occlusion=config.camera_occlusion)
        self.encoder = sensors.Encoder(config.encoder, 1.0 / config.joint_rate)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                              history=HistoryPolicy.KEEP_LAST)
        self.pub_js = node.create_publisher(JointState, "joint_states", reliable)
        self.pub_img = node.create_publisher(Image, "camera/image_raw", qos_profile_sensor_data)
        self.pub_info = node.create_publisher(CameraInfo, "camera/camera_info",
                                              qos_profile_sensor_data)
        self.pub_clock = node.create_publisher(Clock, "/clock", reliable)
        self.sub_cmd = node.create_subscription(Float64MultiArray, "effort_controller/commands",
                                                self._on_command, reliable)
        self._js = JointState()
        self._js.name = ["frame_joint"]
        self._clock = Clock()
        self._info = CameraInfo()
        cam = config.camera
        self._info.header.frame_id = "camera_optical_frame"
        self._info.width, self._info.height = cam.width, cam.height
        self._info.distortion_model = "plumb_bob"
        self._info.d = list(cam.distortion)
        self._info.k = cam.k_matrix.reshape(-1).tolist()
        self._info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        self._info.p = [cam.fx, 0.0, cam.cx, 0.0, 0.0, cam.fy, cam.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        self._image_cls = Image
        self.t_ns = 0
        self.command = 0.0
        self._cmd_t_ns: int | None = None
        self.commands_received = 0
        self.commands_rejected = 0
        self._bad_warned = 0.0
        self.truth: list[tuple[float, ...]] = []
        self.frames: list[tuple[int, int, np.ndarray]] = []
        self.stop = threading.Event()
        self.published = {"joint_states": 0, "image": 0, "clock": 0}

    # ---------------------------------------------------------------------- input
    def _on_command(self, msg: Any) -> None:
        data = list(msg.data)
        if len(data) != 1 or not math.isfinite(data[0]):
            self.commands_rejected += 1
            now = time.monotonic()
            if now - self._bad_warned > 2.0:
                self._bad_warned = now
                _log(f"ignoring command {data!r}: need one finite element [N m]")
            return
        limit = self.cfg.torque_limit
        self.command = min(limit, max(-limit, data[0]))
        self._cmd_t_ns = self.t_ns
        self.commands_received += 1

    def applied_command(self) -> float:
        """The torque command in force now (zero after the timeout) [N m]."""
        if self._cmd_t_ns is None:
            return 0.0
        if (self.t_ns - self._cmd_t_ns) * 1e-9 > self.cfg.command_timeout:
            return 0.0
        return self.command

    # --------------------------------------------------------------------- output
    def _publish_clock(self) -> None:
        _stamp(self._clock.clock, self.t_ns)
        self.pub_clock.publish(self._clock)
        self.published["clock"] += 1

    def _publish_joint(self, effort: float) -> None:
        s = self.plant
        pos, vel = self.encoder.sample(s.theta)
        _stamp(self._js.header.stamp, self.t_ns)
        self._js.position = [pos]
        self._js.velocity = [vel]
        self._js.effort = [effort]
        self.pub_js.publish(self._js)
        self.published["joint_states"] += 1
        x, y, _, _ = s.ball_world()
        st = s.state() if s.mode == physics.FLIGHT else None
        angle = st.ball_angle if st else (s.psi if s.mode == physics.ROLLING else math.nan)
        angle_dot = st.ball_angle_dot if st else (
            s.psi_dot if s.mode == physics.ROLLING else math.nan)
        self.truth.append((self.t_ns * 1e-9, s.theta, s.theta_dot, x, y, angle, angle_dot,
                           1.0 if s.mode == physics.ROLLING else 0.0))

    def _render_frame(self) -> None:
        x, y, _, _ = self.plant.ball_world()
        ball = (x, y) if math.isfinite(x) else None
        img = self.renderer.render(self.plant.theta, ball)
        due = self.t_ns + round(self.cfg.camera_latency * 1e9)
        stamp = self.t_ns
        if self.cfg.camera_stamp_jitter:  # a stamp taken on arrival, not at the exposure
            stamp += round(self.cfg.camera_stamp_jitter * 1e9 * self.rng.standard_normal())
        self.frames.append((due, stamp, img))

    def _publish_due_frames(self) -> None:
        while self.frames and self.frames[0][0] <= self.t_ns:
            _, stamp_ns, img = self.frames.pop(0)
            msg = self._image_cls()
            _stamp(msg.header.stamp, stamp_ns)
            msg.header.frame_id = "camera_optical_frame"
            msg.height, msg.width = img.shape
            msg.encoding = "mono8"
            msg.is_bigendian = 0
            msg.step = img.shape[1]
            msg.data = img.tobytes()
            _stamp(self._info.header.stamp, stamp_ns)
            self.pub_img.publish(msg)
            self.pub_info.publish(self._info)
            self.published["image"] += 1

    # ----------------------------------------------------------------------- loop
    def _next_event(self, next_js: int, next_cam: int) -> int:
        """Next simulated instant that needs attention: sample, exposure or publication."""
        due = self.frames[0][0] if self.frames else next_js
        return min(next_js, next_cam, max(due, self.t_ns + 1))

    def wait_for_peers(self) -> None:
        """Hold the start until every topic has a peer, at most ``start_wait`` wall seconds.

        Peers are counted from the ROS graph (a subscription of the image,
        ``start_js_peers`` of joint_states, a publisher of the effort commands); the start
        follows 0.5 s after the last one appeared, so that the peers' side of discovery has
        completed too.
        """
        deadline = time.monotonic() + self.cfg.start_wait
        waited = time.monotonic()

        def missing() -> list[str]:
            out = []
            if self.pub_img.get_subscription_count() < 1:
                out.append("a subscription of camera/image_raw")
            if (n := self.pub_js.get_subscription_count()) < self.cfg.start_js_peers:
                out.append(f"{self.cfg.start_js_peers - n} more subscription(s) of joint_states")
            if self.sub_cmd.get_publisher_count() < 1:
                out.append("a publisher of effort_controller/commands")
            return out

        while (left := missing()) and time.monotonic() < deadline and not self.stop.is_set():
            self.stop.wait(0.02)
        if left:
            _log(f"start: waited {time.monotonic() - waited:.1f} s, starting without "
                 + ", ".join(left))
        else:
            self.stop.wait(0.5)
            _log(f"start: peers matched after {time.monotonic() - waited:.1f} s")

    def run(self) -> None:
        """Advance simulated time at ``time_scale`` of the wall clock until stopped."""
        cfg = self.cfg
        js_ns = round(1e9 / cfg.joint_rate)
        cam_ns = round(1e9 / cfg.frame_rate)
        end_ns = round(cfg.duration * 1e9) if cfg.duration > 0.0 else None
        next_js, next_cam = 0, 0
        wall0 = time.monotonic()
        cpu0 = time.process_time()
        last_status, last_wall, last_cpu, last_t = wall0, wall0, cpu0, 0
        self._publish_joint(0.0)
        self._publish_clock()
        next_js += js_ns
        while not self.stop.is_set():
            now = time.monotonic()
            target = round(cfg.time_scale * (now - wall0) * 1e9)
            budget = now + 0.02
            while self._next_event(next_js, next_cam) <= target \
                    and time.monotonic() < budget:
                t_next = self._next_event(next_js, next_cam)
                if end_ns is not None and t_next > end_ns:
                    self.stop.set()
                    break
                command = self.applied_command()
                self.plant.advance((t_next - self.t_ns) * 1e-9, command)
                self.t_ns = t_next
                if t_next == next_cam:
                    self._render_frame()
                    next_cam += cam_ns
                if t_next == next_js:
                    self._publish_joint(self.applied_command())
                    next_js += js_ns
                self._publish_due_frames()
                self._publish_clock()
            if now - last_status >= cfg.status_period:
                cpu = time.process_time()
                rtf = (self.t_ns - last_t) * 1e-9 / max(1e-9, now - last_wall)
                load = 100 * (cpu - last_cpu) / (now - last_wall)
                _log(f"t = {self.t_ns * 1e-9:.2f} s simulated, {rtf / cfg.time_scale:.2f} of "
                     f"time_scale {cfg.time_scale:g}, CPU {load:.0f} %, "
                     f"ball {self.plant.mode}, theta {self.plant.theta:.3f} rad, "
                     f"command {self.applied_command():+.4f} N m, "
                     f"{self.commands_received} commands")
                last_status, last_wall, last_cpu, last_t = now, now, cpu, self.t_ns
            wait = (self._next_event(next_js, next_cam) - target) * 1e-9 / cfg.time_scale
            if wait > 0.0:
                self.stop.wait(min(wait, 0.005))
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        _log(f"stopped at t = {self.t_ns * 1e-9:.3f} s simulated after {wall:.2f} s wall "
             f"(real-time factor {self.t_ns * 1e-9 / max(wall, 1e-9):.3f}, time_scale "
             f"{cfg.time_scale:g}; CPU {100 * cpu / max(wall, 1e-9):.0f} %); published "
             f"{self.published['joint_states']} joint_states, {self.published['image']} "
             f"images; {self.commands_received} commands ({self.commands_rejected} rejected)")


def read_parameters(node: Any) -> StandInConfig:
    """Declare every parameter (dynamic typing) and build the configuration.

    A parameter given on the command line that the stand-in does not know is an error
    (a misspelt effect must not pass silently); ``use_sim_time`` and ``qos_overrides.*``
    are let through.
    """
    from rcl_interfaces.msg import ParameterDescriptor  # noqa: PLC0415

    given = set(getattr(node, "_parameter_overrides", {}) or {})
    unknown = sorted(n for n in given - set(PARAMETERS)
                     if n != "use_sim_time" and not n.startswith("qos_overrides."))
    if unknown:
        raise ConfigError(f"unknown parameter {unknown[0]} (see --help)")
    values = {}
    for name, default in PARAMETERS.items():
        desc = ParameterDescriptor(dynamic_typing=True)
        values[name] = node.declare_parameter(name, default, desc).value
    return config_from_values(values)


def main(argv: list[str] | None = None) -> int:
    """Run the stand-in node.

    Parameters
    ----------
    argv : list of str, optional
        Command line (``--ros-args ...``); ``sys.argv`` when omitted.

    Returns
    -------
    int
        0 on a clean stop, 2 on bad parameters.
    """
    argv = sys.argv if argv is None else argv
    if any(a in ("-h", "--help") for a in argv[1:]):
        print(__doc__)
        return 0
    import cv2  # noqa: PLC0415
    import rclpy  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415

    cv2.setNumThreads(1)
    stop_requested = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        stop_requested.set()

    # A background job of a non-interactive shell inherits SIGINT ignored: install ours.
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    context = rclpy.Context()
    rclpy.init(args=argv, context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("butterfly_standin", context=context)
    try:
        try:
            config = read_parameters(node)
            if config.camera_params_out:
                Path(config.camera_params_out).write_text(
                    camera_parameter_yaml(config.camera, config.frame_rate))
            if config.truth_out:
                Path(config.truth_out).parent.mkdir(parents=True, exist_ok=True)
                with open(config.truth_out, "a"):
                    pass
            standin = StandIn(node, config)
        except (ConfigError, OSError, ValueError) as exc:
            print(f"standin: error: {exc}", file=sys.stderr, flush=True)
            return 2
        except Exception as exc:  # noqa: BLE001 - rclpy parameter exceptions, one line
            print(f"standin: error: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
            return 2
        rig = config.rig
        _log(f"independent Butterfly rig up: time_scale {config.time_scale:g}, duration "
             f"{config.duration:g} s (0: until SIGINT), seed {config.seed}, ball "
             f"{'on' if config.ball else 'off'} ({standin.plant.mode}), joint_states "
             f"{config.joint_rate:g} Hz, camera {config.frame_rate:g} Hz latency "
             f"{config.camera_latency * 1e3:g} ms, R {rig.rolling_radius * 1e3:.3f} mm, "
             f"a {rig.a_eff * 1e3:.2f} mm, J_f {rig.frame_inertia_total:.4g} kg m^2, "
             f"Coulomb +{rig.coulomb_pos:g}/-{rig.coulomb_neg:g} N m, "
             f"{len(rig.bumps)} bumps")
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spinner = threading.Thread(target=_spin, args=(executor, standin.stop), daemon=True)
        spinner.start()
        watcher = threading.Thread(target=_forward, args=(stop_requested, standin.stop),
                                   daemon=True)
        watcher.start()
        try:
            if config.start_wait > 0.0:
                standin.wait_for_peers()
            standin.run()
        finally:
            standin.stop.set()
            if stop_requested.is_set():
                _log("SIGINT/SIGTERM: stopping")
            if config.truth_out:
                write_truth(config.truth_out, standin.truth)
                _log(f"truth: {len(standin.truth)} rows -> {config.truth_out}")
            executor.shutdown(timeout_sec=1.0)
            spinner.join(timeout=2.0)
        return 0
    finally:
        node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)


def _spin(executor: Any, stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=0.05)
        except Exception:
            if stop.is_set():
                return
            raise


def _forward(source: threading.Event, target: threading.Event) -> None:
    source.wait()
    target.set()


if __name__ == "__main__":
    sys.exit(main())
