"""The simulator node: the rig's physics, encoder and camera, behind the hardware topics.

A thin node over :class:`RigSimulation` (pure: the rigid model stepped by RK4 with the
actuator's zero-order hold, clamp and command timeout) and :mod:`bfr_sim.render` (synthetic
camera frames). It publishes what the real rig's drivers publish, and subscribes to what the
controller sends the real motor:

================================  ===================================  ===================
topic                             type                                 direction
================================  ===================================  ===================
``joint_states``                  ``sensor_msgs/JointState``           out (500 Hz)
``camera/image_raw``              ``sensor_msgs/Image`` mono8          out (camera rate)
``camera/camera_info``            ``sensor_msgs/CameraInfo``           out (camera rate)
``sim_truth``                     ``bfr_interfaces/SimTruth``          out (optional)
``/clock``                        ``rosgraph_msgs/Clock``              out
``sim_markers``                   ``visualization_msgs/MarkerArray``   out (``markers.rate``)
``effort_controller/commands``    ``std_msgs/Float64MultiArray``       in (never published)
``controller_state``              ``bfr_interfaces/ControllerState``   in (lock-step only)
================================  ===================================  ===================

Modes (``sim.mode``)
--------------------
``realtime``
    Simulated time advances with the wall clock (times ``sim.real_time_factor``); every
    message that has arrived is taken before each RK4 step, so the latest effort command
    acts from the next step on (zero-order hold), as a drive applies it. (Taking one
    message per camera frame instead, as this node did, let commands queue up whenever the
    simulation ran behind real time, and the torque then acted tens of milliseconds after
    the frame it answered: the cause of the ball lost in real time, docs/notes/issue-17.md.)
    When it falls behind real time it runs flat out to catch up (simulated time stays
    consistent for every node on ``/clock``) and drops the lag only beyond 1 s.
``lockstep``
    As fast as the loop allows: after publishing a camera frame at simulated time ``t``
    the simulator waits until the controller has answered that frame, i.e. a
    ``controller_state`` stamped ``>= t`` has arrived and the latest effort command equals
    its torque, then applies it from ``t`` on. The answer to frame ``t`` is therefore
    computed from exactly the data up to ``t``, whatever the machine's load: runs are
    repeatable. A controller that does not answer within ``lockstep.timeout`` (wall time)
    counts as absent; the simulation then runs free, paced at ``sim.real_time_factor`` as
    in real-time mode (as a rig runs on without its controller; flat out, it flooded the
    camera node with frames it had to measure at its real-time priority), until a
    ``controller_state`` arrives again, so a dead controller never freezes it.

The effort command: one element (``joint_states.joint_name``), clamped to
``actuator.torque_limit`` (rig.yaml); a non-finite or wrongly sized command is ignored with
a warning; no command for ``command.timeout`` simulated seconds means zero torque. The
simulator never publishes on ``effort_controller/commands``.

Time: simulated time starts at 0 and is published on ``/clock`` with every camera frame and
otherwise at ``clock.rate`` (200 Hz: not with every encoder sample, which would cost every
sim-time node a callback per sample); every other node runs with
``use_sim_time:=true`` (``bfr rig`` and the launch file set it). Images are stamped with the
exposure mid-time (the state they show), published ``render.latency`` later.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from bfr_camera.calibration import CameraModel, camera_from_dict, default_camera_path
from bfr_model.dynamics import RigidModel, curve_terms
from bfr_model.layout import I_CW, I_SW
from bfr_model.param_file import check, config_path, nonnegative, one_of, positive
from bfr_model.params import RigParams, default_params_path, params_from_dict
from bfr_model.scene import MarkerSpec, rig_markers, rig_picture
from bfr_ros.markers import MarkerPublisher
from bfr_ros.node_common import (
    CLOCK_QOS,
    COMMAND_QOS,
    IMAGE_QOS,
    STATE_PUB_QOS,
    STATE_QOS,
    declare_parameter_tree,
    flatten,
    format_published,
    load_yaml_parameters,
    ns_to_stamp,
    place_process,
    read_parameter_tree,
    run_node,
    stamp_to_ns,
)
from numpy.typing import NDArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray

from bfr_interfaces.msg import ControllerState, SimTruth
from bfr_sim.render import FrameRenderer, RenderOptions, rig_scene

__all__ = ["RigSimulation", "SimulatorNode", "main", "node_defaults"]

FloatArray = NDArray[np.float64]
_NS = 1_000_000_000


def node_defaults() -> dict[str, Any]:
    """Defaults of every parameter: rig.yaml, the camera group of camera.yaml, this node's file."""
    d = dict(load_yaml_parameters(default_params_path()))
    d["camera"] = dict(load_yaml_parameters(default_camera_path())["camera"])
    d.update(load_yaml_parameters(config_path("bfr_sim", "simulator_node.yaml")))
    return d


# -- pure core ---------------------------------------------------------------------------------
@dataclass
class TruthSample:
    """Ground truth at one instant (the fields of ``bfr_interfaces/SimTruth``), SI units."""

    t_ns: int
    x: FloatArray  # [theta, phi, theta_dot, phi_dot, W_in, W_diss]
    ball: FloatArray  # [x, y, z] [m]
    ball_velocity: FloatArray  # [vx, vy, vz] [m/s]
    spin: float
    spin_rate: float
    torque: float
    kinetic: float
    potential: float
    normal_force: float


class RigSimulation:
    """The rigid model with the rig's actuator: pure numpy, no ROS.

    Parameters
    ----------
    params : RigParams
        Physics (rig.yaml).
    x0 : array_like, shape (4,)
        Initial ``[theta, phi, theta_dot, phi_dot]``.
    time_step : float
        RK4 step [s].
    command_timeout : float
        Simulated time without a command after which the torque is zero [s].
    """

    def __init__(self, params: RigParams, x0: Any, time_step: float = 1e-3,
                 command_timeout: float = 0.1) -> None:
        positive("sim.time_step", time_step)
        check(time_step <= 0.01, "sim.time_step", f"must be <= 0.01 s, got {time_step!r}")
        positive("command.timeout", command_timeout)
        x0 = np.asarray(x0, dtype=float)
        check(x0.shape == (4,) and bool(np.all(np.isfinite(x0))), "initial",
              f"the initial state must be 4 finite numbers, got {x0}")
        self.params = params
        self.model = RigidModel(params)
        self.x = self.model.state(x0)  # a creeping spin (ball.creep_time) is a seventh state
        self.dt = float(time_step)
        self.step_ns = round(self.dt * _NS)
        self.k = 0
        self.limit = params.actuator.torque_limit
        self.gain = params.actuator.torque_gain
        self.command_timeout_ns = round(command_timeout * _NS)
        self.command = 0.0
        self.command_ns: int | None = None  # simulated time the command arrived
        self.timed_out = False
        # arc length s(phi) of the ball-centre curve over one turn, for the spin angle
        grid = np.linspace(0.0, 2.0 * np.pi, 4097)
        self._s_grid, self._s_table = grid, self.model.curve.arc_length(grid)
        self._spin0 = float(self.x[0]) - self._arc_length(float(x0[1])) / \
            params.ball.rolling_radius
        self.model.step(self.x, 0.0, self.dt, 1)  # compile / load the cached kernel now

    def _arc_length(self, phi: float) -> float:
        """s(phi) [m] from the table (linear interpolation: error < 1e-8 m)."""
        turns = math.floor(phi / (2.0 * math.pi))
        rem = phi - turns * 2.0 * math.pi
        return turns * float(self._s_table[-1]) + float(np.interp(rem, self._s_grid,
                                                                  self._s_table))

    @property
    def t_ns(self) -> int:
        """Simulated time [ns]."""
        return self.k * self.step_ns

    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self.t_ns / _NS

    def set_command(self, data: Any) -> str:
        """Take an effort command (the ``data`` of Float64MultiArray) at the current time.

        Returns
        -------
        str
            Empty if accepted, else why it was ignored (the previous command stays).
        """
        try:
            values = [float(v) for v in data]
        except (TypeError, ValueError):
            return f"effort command is not numeric: {data!r}"
        if len(values) != 1:
            return f"effort command has {len(values)} elements, expected 1 (the frame joint)"
        if not math.isfinite(values[0]):
            return f"effort command is not finite ({values[0]})"
        self.command = values[0]
        self.command_ns = self.t_ns
        self.timed_out = False
        return ""

    def applied_command(self) -> float:
        """Command after timeout and clamp [N m] (the motor applies gain times this)."""
        if self.command_ns is None:
            return 0.0
        if self.t_ns - self.command_ns > self.command_timeout_ns:
            self.timed_out = True
            return 0.0
        return min(max(self.command, -self.limit), self.limit)

    @property
    def applied_torque(self) -> float:
        """Torque on the frame [N m]: ``torque_gain * clamped command``."""
        return self.gain * self.applied_command()

    def step(self) -> None:
        """Advance one RK4 step under the held command."""
        self.x = self.model.step(self.x, self.applied_command(), self.dt, 1)
        self.k += 1

    @property
    def finite(self) -> bool:
        """Whether the state is finite."""
        return bool(np.all(np.isfinite(self.x[:4])))

    def ball_kinematics(self) -> tuple[FloatArray, FloatArray]:
        """Ball centre [m] and velocity [m/s] in the world, each (3,) (z: wobble sway)."""
        th, ph, thd, phd = (float(v) for v in self.x[:4])
        P = self.model.P
        g = curve_terms(ph, *self.model.kernel_args)
        cw, sw = P[I_CW], P[I_SW]  # cos, sin of the frame's wobble
        px, py, p1x, p1y = cw * g[0], g[1], cw * g[2], g[3]
        c, s = math.cos(th), math.sin(th)
        rx, ry = c * px - s * py, s * px + c * py
        vx = -thd * ry + phd * (c * p1x - s * p1y)
        vy = thd * rx + phd * (s * p1x + c * p1y)
        return (np.array([rx, ry, sw * g[0]]), np.array([vx, vy, sw * g[2] * phd]))

    def truth(self) -> TruthSample:
        """Ground truth now.

        The spin angle is rolling's (the frame angle minus the rolled arc over R); a creeping
        spin's rate is its own state, its angle still rolling's.
        """
        x4 = self.x[:4]
        ball, vel = self.ball_kinematics()
        kin, pot = self.model.energy(self.x)
        u = self.applied_command()
        fn = float(self.model.normal_force(self.x, u))
        spin = float(x4[0]) - self._arc_length(float(x4[1])) / \
            self.params.ball.rolling_radius - self._spin0
        return TruthSample(self.t_ns, self.x[:6].copy(), ball, vel, spin,
                           float(self.model.ball_spin_rate(self.x)), self.gain * u, float(kin),
                           float(pot), fn)


class Schedule:
    """Publication instants on the simulation's step grid, in integer nanoseconds."""

    def __init__(self, rate: float, step_ns: int, name: str) -> None:
        positive(name, rate)
        self.rate = rate
        self.half = step_ns // 2
        self.n = 0

    def due(self, t_ns: int) -> bool:
        """True (once) when the next instant ``n / rate`` is reached at step time t_ns."""
        if t_ns + self.half >= round(self.n * _NS / self.rate):
            while t_ns + self.half >= round(self.n * _NS / self.rate):
                self.n += 1
            return True
        return False


# -- the node ----------------------------------------------------------------------------------
class SimulatorNode(Node):
    """ROS 2 wrapper of :class:`RigSimulation` and the renderer (module docstring)."""

    def __init__(self) -> None:
        super().__init__("simulator")
        # one frame at a time: OpenCV's worker threads cost more than they save on the
        # renderer's calls (they spin after each job: 0.15-0.19 cores of system time here)
        cv2.setNumThreads(1)
        self.defaults = node_defaults()
        # camera.yaml may be given whole: its detector.* group is the camera node's
        declare_parameter_tree(self, self.defaults,
                               flatten(load_yaml_parameters(default_camera_path())))
        p = read_parameter_tree(self, self.defaults)
        rig = {k: p[k] for k in ("ball", "frame", "environment", "joint", "actuator",
                                 "track", "contact") if k in p}
        self.rig_params = params_from_dict(rig)
        self.camera: CameraModel = camera_from_dict(p["camera"])
        s = p["sim"]
        self.mode = str(s["mode"]).lower()
        one_of("sim.mode", self.mode, ("realtime", "lockstep"))
        # real-time priority only where there is a deadline: lock-step runs as fast as its
        # peers answer and would hold a CPU against every normal process
        self.scheduling = place_process(
            p["process"], self.get_logger(),
            not_now="" if self.mode == "realtime" else "lock-step mode has no deadline")
        self.rtf = float(s["real_time_factor"])
        positive("sim.real_time_factor", self.rtf)
        self.duration_ns = round(max(float(s["duration"]), 0.0) * _NS)
        ini = p["initial"]
        x0 = [ini["theta"], ini["phi"], ini["theta_dot"], ini["phi_dot"]]
        self.sim = RigSimulation(self.rig_params, x0, s["time_step"], p["command"]["timeout"])
        step_ns = self.sim.step_ns
        self.joint_name = str(p["joint_states"]["joint_name"])
        self.js_sched = Schedule(p["joint_states"]["rate"], step_ns, "joint_states.rate")
        self.pub_truth = bool(p["truth"]["publish"])
        self.truth_sched = Schedule(p["truth"]["rate"], step_ns, "truth.rate")
        self.pub_clock = bool(p["clock"]["publish"])
        self.clock_sched = Schedule(p["clock"]["rate"], step_ns, "clock.rate")
        r = p["render"]
        self.pub_images = bool(r["publish"])
        self.frame_sched = Schedule(self.camera.frame_rate, step_ns, "camera.frame_rate")
        latency = float(r["latency"])
        nonnegative("render.latency", latency)
        self.latency_ns = math.ceil(round(latency * _NS) / step_ns) * step_ns
        self.scene = rig_scene(self.rig_params)
        self.renderer = FrameRenderer(
            self.camera, self.scene.outline,
            RenderOptions(plate_z=self.scene.plate_z, noise_sigma=float(r["noise_sigma"]),
                          shot_noise=float(r["shot_noise"]),
                          defocus_sigma=float(r["defocus_sigma"])))
        self.rng = np.random.default_rng(int(r["seed"]))
        self.renderer.render(0.0, None, rng=np.random.default_rng(0))  # warm-up
        self.lock_timeout = float(p["lockstep"]["timeout"])
        self.resend_period = float(p["lockstep"]["resend"])
        self.last_frame: tuple[Any, int] | None = None
        st = p["start"]
        self.wait_subscribers = int(st["wait_subscribers"])
        self.wait_info_subscribers = int(st["wait_info_subscribers"])
        self.wait_truth_subscribers = int(st["wait_truth_subscribers"])
        self.wait_controller = bool(st["wait_controller"])
        self.wait_obs_subscribers = int(st["wait_observation_subscribers"])
        self.start_settle = float(st["settle"])
        nonnegative("start.settle", self.start_settle)
        self.start_timeout = float(st["timeout"])
        info = self.camera.to_camera_info()
        self.info_msg = CameraInfo()
        for key in ("width", "height", "distortion_model", "d", "k", "r", "p",
                    "binning_x", "binning_y"):
            setattr(self.info_msg, key, info[key])
        self.info_msg.header.frame_id = info["frame_id"]
        # publishers and subscriptions (relative names: remappable, namespaceable)
        self.js_pub = self.create_publisher(JointState, "joint_states", STATE_PUB_QOS)
        self.img_pub = self.create_publisher(Image, "camera/image_raw", IMAGE_QOS)
        # camera_info as the state topics (small): a recorder's missed sample stays repairable
        self.info_pub = self.create_publisher(CameraInfo, "camera/camera_info", STATE_PUB_QOS)
        self.truth_pub = self.create_publisher(SimTruth, "sim_truth", STATE_PUB_QOS)
        self.clock_pub = self.create_publisher(Clock, "/clock", CLOCK_QOS)
        mk = p["markers"]  # the scene for Foxglove / RViz (bfr_model.scene); rate 0: off
        self.markers = MarkerPublisher(self, "sim_markers", float(mk["rate"]), str(mk["frame_id"]))
        self.cmd_sub = self.create_subscription(
            Float64MultiArray, "effort_controller/commands", self._on_command, COMMAND_QOS)
        # controller_state is read in lock-step only (the answer to a frame); the start waits
        # for a controller in either mode through the graph
        self.state_topic = self.resolve_topic_name("controller_state")
        self.obs_topic = self.resolve_topic_name("ball_observation")
        self.state_sub = (self.create_subscription(
            ControllerState, "controller_state", self._on_state, STATE_QOS)
            if self.mode == "lockstep" else None)
        self.events = 0  # messages taken (commands, states)
        self.clock_msg = Clock()
        self.js_msg = JointState()
        self.js_msg.name = [self.joint_name]
        self.pending: deque[tuple[int, Any, Any]] = deque()
        self.state_ns = -1  # stamp of the latest controller_state
        self.state_torque = math.nan
        self.controller_absent = False
        self.absent_check_ns = 0
        self.stats = {"frames": 0, "joint_states": 0, "truth": 0, "clock": 0, "commands": 0,
                      "ignored_commands": 0, "lockstep_waits": 0, "lockstep_timeouts": 0,
                      "resent": 0, "wait_wall": 0.0}
        self.finished = False
        self.executor_ref: Any = None
        truth = f"{self.truth_sched.rate:g} Hz" if self.pub_truth else "off"
        self.get_logger().info(
            f"simulator: mode {self.mode}, RK4 step {1e3 * self.sim.dt:g} ms, joint_states "
            f"{self.js_sched.rate:g} Hz, camera {self.camera.frame_rate:g} Hz "
            f"{self.camera.width}x{self.camera.height} mono8, truth "
            f"{truth}, torque limit "
            f"{self.sim.limit:g} N m, start x0 = {np.round(self.sim.x[:4], 4).tolist()}; "
            f"{self.scheduling}")

    # -- subscriptions --------------------------------------------------------------
    def _on_command(self, msg: Any) -> None:
        self.events += 1
        why = self.sim.set_command(msg.data)
        if why:
            self.stats["ignored_commands"] += 1
            self.get_logger().warn(f"ignoring effort command: {why}",
                                   throttle_duration_sec=1.0)
        else:
            self.stats["commands"] += 1

    def _on_state(self, msg: Any) -> None:
        self.events += 1
        if msg.mode == ControllerState.FAULT:
            return  # a controller in FAULT (e.g. its watchdog) does not answer a frame
        self.state_ns = max(self.state_ns, stamp_to_ns(msg.header.stamp))
        self.state_torque = float(msg.torque)
        if self.controller_absent:
            self.controller_absent = False
            self.get_logger().info("controller is back: lock-step resumed")

    # -- publishing -----------------------------------------------------------------
    def _publish_clock(self, t_ns: int) -> None:
        if self.pub_clock:
            m = self.clock_msg
            ns_to_stamp(t_ns, m.clock)
            self.clock_pub.publish(m)
            self.stats["clock"] += 1

    def _publish_joint_state(self, t_ns: int) -> None:
        m = self.js_msg
        ns_to_stamp(t_ns, m.header.stamp)
        x = self.sim.x
        m.position = [float(x[0])]
        m.velocity = [float(x[2])]
        m.effort = [self.sim.applied_torque]
        self.js_pub.publish(m)
        self.stats["joint_states"] += 1

    def _publish_truth(self) -> None:
        s = self.sim.truth()
        m = SimTruth()
        ns_to_stamp(s.t_ns, m.header.stamp)
        m.header.frame_id = "world"
        m.theta, m.phi, m.theta_dot, m.phi_dot = (float(v) for v in s.x[:4])
        m.ball_x, m.ball_y = float(s.ball[0]), float(s.ball[1])
        m.ball_vx, m.ball_vy = float(s.ball_velocity[0]), float(s.ball_velocity[1])
        m.ball_spin, m.ball_spin_rate = s.spin, s.spin_rate
        m.torque = s.torque
        m.kinetic, m.potential = s.kinetic, s.potential
        m.energy = s.kinetic + s.potential
        m.work_in = float(s.x[4])
        m.in_contact = s.normal_force > 0.0
        m.normal_force = max(s.normal_force, 0.0)
        m.slip_velocity = 0.0
        self.truth_pub.publish(m)
        self.stats["truth"] += 1

    def _render(self, t_ns: int) -> None:
        ball, vel = self.sim.ball_kinematics()
        x = self.sim.x
        img = self.renderer.render(float(x[0]), ball, self.scene.ball_radius, rng=self.rng,
                                   theta_dot=float(x[2]), ball_velocity=vel)
        m = Image()
        ns_to_stamp(t_ns, m.header.stamp)
        m.header.frame_id = self.camera.frame_id
        m.height, m.width = int(img.shape[0]), int(img.shape[1])
        m.encoding = "mono8"
        m.is_bigendian = 0
        m.step = int(img.shape[1])
        m.data = img.tobytes()
        self.pending.append((t_ns + self.latency_ns, m, t_ns))

    def _publish_frame(self, msg: Any, t_exp_ns: int) -> None:
        self.img_pub.publish(msg)
        info = self.info_msg
        ns_to_stamp(t_exp_ns, info.header.stamp)
        self.info_pub.publish(info)
        self.stats["frames"] += 1

    def scene_markers(self) -> list[MarkerSpec]:
        """The markers of the current state: frame, ball (the truth's centre), contacts, label."""
        ball, _ = self.sim.ball_kinematics()
        x = self.sim.x
        b = self.rig_params.ball
        pic = rig_picture(self.sim.model.curve, float(x[0]), phi=float(x[1]), ball_xy=ball[:2],
                          ball_z=float(ball[2]), ball_radius=b.radius,
                          plate_distance=b.plate_distance)
        return rig_markers(pic, label=f"t {self.sim.t:.2f} s  torque "
                                      f"{self.sim.applied_torque:+.4f} N m")

    def publish_due(self) -> bool:
        """Publish what is due at the current step; True if a frame went out."""
        t_ns = self.sim.t_ns
        if self.markers.due(t_ns):
            self.markers.publish(self.scene_markers(), t_ns)
        if self.pub_images and self.frame_sched.due(t_ns):
            self._render(t_ns)
        frame_out = bool(self.pending) and self.pending[0][0] <= t_ns
        js_due = self.js_sched.due(t_ns)
        truth_due = self.pub_truth and self.truth_sched.due(t_ns)
        clock_due = self.clock_sched.due(t_ns)
        if frame_out or clock_due:  # not with every encoder sample (clock.rate)
            self._publish_clock(t_ns)
        if frame_out or js_due:
            self._publish_joint_state(t_ns)
        if truth_due:
            self._publish_truth()
        while self.pending and self.pending[0][0] <= t_ns:
            _, msg, t_exp = self.pending.popleft()
            self._publish_frame(msg, t_exp)
            self.last_frame = (msg, t_exp)
        return frame_out

    def _resend_frame(self) -> None:
        """Publish the last frame (and the encoder sample and clock of now) once more."""
        if self.last_frame is None:
            return
        t_ns = self.sim.t_ns
        self._publish_clock(t_ns)
        self._publish_joint_state(t_ns)
        self.img_pub.publish(self.last_frame[0])
        ns_to_stamp(self.last_frame[1], self.info_msg.header.stamp)
        self.info_pub.publish(self.info_msg)
        self.stats["resent"] += 1

    # -- lock-step and pacing ---------------------------------------------------------
    def _answered(self, t_ns: int) -> bool:
        return self.state_ns >= t_ns and self.sim.command == self.state_torque

    def wait_for_answer(self, stop: Any) -> None:
        """Lock-step: process callbacks until the controller answered this frame."""
        t_ns = self.sim.t_ns
        ex = self.executor_ref
        if self.controller_absent:  # look for a returning controller every 50 ms
            if t_ns - self.absent_check_ns < 50_000_000:
                return
            self.absent_check_ns = t_ns
            ex.spin_once(timeout_sec=0.0)
            if not self._answered(t_ns):
                return
        t0 = time.monotonic()
        # the first frame waits as long as the start does (the controller may still be loading)
        first = self.stats["lockstep_waits"] == 0
        deadline = t0 + (max(self.start_timeout, self.lock_timeout) if first
                         else self.lock_timeout)
        resend = t0 + self.resend_period
        self.stats["lockstep_waits"] += 1
        while not self._answered(t_ns) and not stop:
            now = time.monotonic()
            if now > resend:  # a best-effort frame may be lost (e.g. before discovery is
                self._resend_frame()  # complete on the camera's side): send it again
                resend = now + self.resend_period
            if now > deadline:
                self.stats["lockstep_timeouts"] += 1
                self.controller_absent = True
                self.get_logger().warn(
                    f"lock-step: no answer from the controller to the frame at t = "
                    f"{t_ns / _NS:.3f} s within {self.lock_timeout:g} s (wall); running "
                    f"free until a controller_state arrives again")
                break
            ex.spin_once(timeout_sec=max(0.0, min(0.05, deadline - now, resend - now)))
        self.stats["wait_wall"] += time.monotonic() - t0

    def take_messages(self, limit: int = 100) -> None:
        """Take every message that has arrived (at most ``limit``): the newest command acts."""
        ex = self.executor_ref
        for _ in range(limit):
            n = self.events
            ex.spin_once(timeout_sec=0.0)
            if self.events == n:
                return

    def wait_for_peers(self, stop: Any) -> None:
        """Before t = 0: wait for subscribers / the controller (``start.*``)."""
        need_ctrl = self.wait_controller
        waits = [(self.js_pub, self.wait_subscribers), (self.info_pub, self.wait_info_subscribers),
                 (self.truth_pub, self.wait_truth_subscribers)]
        n_obs = self.wait_obs_subscribers
        if all(n <= 0 for _, n in waits) and not need_ctrl and n_obs <= 0:
            return
        ex = self.executor_ref
        deadline = time.monotonic() + self.start_timeout
        self.get_logger().info(
            "waiting for " + ", ".join(f"{n} subscriber(s) of {pub.topic_name}"
                                       for pub, n in waits if n > 0)
            + (f" and a controller ({self.state_topic})" if need_ctrl else "")
            + (f", a publisher and {n_obs} subscriber(s) of {self.obs_topic}" if n_obs > 0
               else "")
            + " before starting")

        def ready() -> bool:
            return (all(pub.get_subscription_count() >= n for pub, n in waits)
                    and (not need_ctrl or self.count_publishers(self.state_topic) > 0)
                    and (n_obs <= 0 or (self.count_publishers(self.obs_topic) > 0
                                        and self.count_subscribers(self.obs_topic) >= n_obs)))

        while not stop and not ready():
            if time.monotonic() > deadline:
                self.get_logger().warn(
                    f"start: peers missing after {self.start_timeout:g} s ("
                    + ", ".join(f"{pub.get_subscription_count()} subscriber(s) of "
                                f"{pub.topic_name}" for pub, _ in waits)
                    + f", {self.count_publishers(self.state_topic)} controller(s), "
                      f"{self.count_publishers(self.obs_topic)} / "
                      f"{self.count_subscribers(self.obs_topic)} publisher(s) / subscriber(s) "
                      f"of {self.obs_topic}); starting "
                      f"anyway")
                return
            ex.spin_once(timeout_sec=0.05)
        # let the remaining endpoints of the participants match one another (the simulator
        # sees the graph, not whether the recorder has matched the controller's publishers)
        settle = time.monotonic() + self.start_settle
        while not stop and time.monotonic() < settle:
            ex.spin_once(timeout_sec=0.05)

    def run(self, stop: Any) -> int:
        """The simulation loop (called by :func:`run_node`)."""
        self.wait_for_peers(stop)
        ex = self.executor_ref
        lock = self.mode == "lockstep"
        wall0 = time.monotonic()
        wall_base, t_base = wall0, 0
        paced = not lock  # the last step was paced by the wall clock
        was_timed_out = False
        self.get_logger().info("simulation started")
        while not stop:
            frame_out = self.publish_due()
            if lock and frame_out:
                self.wait_for_answer(stop)
            if lock and not self.controller_absent:
                paced = False
            else:  # real time, or lock-step without its controller: paced by the wall clock
                if not paced:
                    wall_base, t_base, paced = time.monotonic(), self.sim.t_ns, True
                target = wall_base + (self.sim.t_ns - t_base) / _NS / self.rtf
                now = time.monotonic()
                if now - target > 1.0:
                    self.get_logger().warn(
                        f"running {now - target:.2f} s behind real time: the machine "
                        f"cannot keep up; dropping the lag", throttle_duration_sec=5.0)
                    wall_base, t_base = now, self.sim.t_ns
                if now >= target:  # behind: no wait, so take what has arrived
                    self.take_messages()
                while now < target and not stop:  # the wait serves what arrives in it
                    ex.spin_once(timeout_sec=target - now)
                    now = time.monotonic()
            if self.duration_ns and self.sim.t_ns >= self.duration_ns:
                self.finished = True
                break
            self.sim.step()
            if self.sim.timed_out and not was_timed_out:
                self.get_logger().warn(
                    f"no effort command for {self.sim.command_timeout_ns / _NS:g} s "
                    f"(simulated): applying zero torque")
            was_timed_out = self.sim.timed_out
            if not self.sim.finite:
                self.get_logger().error(
                    f"the simulated state became non-finite at t = {self.sim.t:.4f} s; "
                    f"stopping")
                return 1
        wall = time.monotonic() - wall0
        self.report(wall)
        return 0

    def report(self, wall: float) -> None:
        """Log the run's figures."""
        st = self.stats
        t = self.sim.t
        self.get_logger().info(
            f"simulator {'finished' if self.finished else 'stopped'} at t = {t:.3f} s "
            f"after {wall:.1f} s wall (real-time factor {t / max(wall, 1e-9):.2f}); "
            f"{st['frames']} frames, {st['joint_states']} joint_states, {st['truth']} "
            f"truth, {st['commands']} commands ({st['ignored_commands']} ignored), "
            f"lock-step: {st['lockstep_waits']} waits, {st['lockstep_timeouts']} "
            f"timeouts, {st['resent']} frames re-sent, {st['wait_wall']:.1f} s waiting")
        self.get_logger().info(format_published({
            self.js_pub.topic_name: st["joint_states"],
            self.img_pub.topic_name: st["frames"] + st["resent"],
            self.info_pub.topic_name: st["frames"] + st["resent"],
            self.truth_pub.topic_name: st["truth"],
            self.clock_pub.topic_name: st["clock"]}))



def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_sim simulator_node``."""
    return run_node(SimulatorNode, argv)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
