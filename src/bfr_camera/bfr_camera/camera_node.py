"""The camera node: the ball's position in each camera frame, with OpenCV.

A thin node over :class:`bfr_camera.detector.BallDetector`:

- subscribes ``camera/image_raw`` (``sensor_msgs/Image``; mono8, mono16, 32FC1, colour, a
  raw Bayer mosaic or 4:2:2 YUV: :func:`bfr_ros.node_common.image_to_array`),
  ``camera/camera_info`` (the intrinsics: size, K, D, distortion model) and
  ``joint_states`` (the frame angle theta, interpolated at each frame's exposure mid-time
  from a short buffer, for the observation's ``phi = theta + atan2(x, y)``; the samples are
  taken from the subscription's queue at each image, not one callback per sample); images and
  camera_info with sensor-data QoS keeping the newest message only (best effort, keep last
  1: after a stall the node measures the present image, it never works through a backlog);
- publishes one ``ball_observation`` (``bfr_interfaces/BallObservation``, reliable) per
  image it measures, stamped with the image's stamp (the exposure mid-time). The detector
  keeps the last fix and searches a region of interest around it first;
- at ``markers.rate`` Hz of the images' stamps (0: off, as in hardware.yaml), what it saw for
  Foxglove and RViz: ``ball_markers`` (``visualization_msgs/MarkerArray``, frame ``world``: a
  sphere of the ball's size at the fix, deleted when no ball is found) and
  ``camera/detection`` (``visualization_msgs/ImageMarker``: a circle round the ball on the
  image, in the image's frame and stamp).

Calibration. With ``input.use_camera_info: true`` (the default) the node measures nothing
until the first valid ``camera_info`` has arrived: an image before it gives an
``INVALID_INPUT`` observation ("waiting for camera_info"), never a fix computed with
another camera's intrinsics. With ``false`` it uses ``camera.*`` (k, d, size) from its
parameters and ignores camera_info. It logs which calibration it uses, and again when a
camera_info changes it. The camera's pose and timing (``camera.position``,
``camera.orientation``, ``camera.exposure_time``) always come from the parameters
(docs/hardware.md).

Bad input never stops the node: an image it cannot use (encoding, size, step, a size that
does not match the calibration, a non-finite theta) gives an observation with status
``INVALID_INPUT`` and a throttled warning that says why; no ball gives ``NOT_FOUND``;
several give ``AMBIGUOUS``; no image for ``input.frame_timeout`` seconds of the node's clock
(simulated time under ``use_sim_time``) gives an ``INVALID_INPUT`` observation stamped now
and a warning. When no current joint_states sample covers a frame, the ball's position is
still reported (valid) with ``phi`` and ``theta_used`` NaN. Log messages name the topics as
resolved (remapping and namespace applied).
"""

from __future__ import annotations

import bisect
import math
import time
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from bfr_model.dynamics import RigidModel
from bfr_model.param_file import check, config_path
from bfr_model.params import RigParams, default_params_path, params_from_dict
from bfr_model.scene import fix_markers
from bfr_ros.markers import MARKER_QOS, MarkerPublisher, image_circle
from bfr_ros.node_common import (
    IMAGE_SUB_QOS,
    JOINT_STATES_POLLED_QOS,
    STATE_QOS,
    CdrError,
    JointPicker,
    PolledSubscription,
    RawImage,
    Throttle,
    declare_parameter_tree,
    format_published,
    image_to_array,
    load_yaml_parameters,
    ns_to_stamp,
    parse_joint_state,
    place_process,
    read_parameter_tree,
    run_node,
    turn_unwrapper,
    wrong_type_publishers,
)
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from visualization_msgs.msg import ImageMarker

from bfr_camera.calibration import (
    CameraModel,
    CameraModelError,
    camera_from_dict,
    default_camera_path,
)
from bfr_camera.detector import BallDetector, DetectionStatus, detector_config_from_dict
from bfr_camera.stamps import MAX_STAMPS, driver_period
from bfr_interfaces.msg import BallObservation

__all__ = ["CameraNode", "ThetaBuffer", "main", "node_defaults"]

_NS = 1_000_000_000


#: An image stamped later than this after its own arrival [ns] has a stamp from a clock ahead
#: of this computer's (a stamp is the exposure's time, which precedes the arrival): warned.
STAMP_AHEAD_NS = 2_000_000

#: Images in a row older than ``input.max_image_age`` on arrival before a warning: a camera
#: clock behind makes every image old, a stall of the node (its start) only one or two.
OLD_IMAGES_WARNED = 3

#: Logged before the detector's compiled kernels load (bfr_ros.startup: a signal stops this
#: at once).
SETTING_UP = ("setting up: the detector's compiled kernels (with a cold numba cache they "
              "compile: tens of seconds; bfr warm fills it); Ctrl-C stops this at once")

#: Groups of rig.yaml the camera node reads: the ball's size and the frame's contour.
RIG_GROUPS = ("ball", "frame", "environment", "joint", "actuator", "track", "contact")


def default_files() -> list[Path]:
    """The node's shipped parameter files, in order: camera.yaml, rig.yaml, camera_node.yaml."""
    return [Path(default_camera_path()), Path(default_params_path()),
            Path(config_path("bfr_camera", "camera_node.yaml"))]


def node_defaults() -> dict[str, Any]:
    """Defaults: camera.yaml (camera.*, detector.*), rig.yaml, this node's file."""
    d: dict[str, Any] = {}
    for path in default_files():
        d.update(load_yaml_parameters(path))
    return d


def ball_track(rig: RigParams) -> tuple[np.ndarray, np.ndarray]:
    """The ball's track for the detector's track gate: angle [rad] and radius [m].

    The ball centre's polar angle (clockwise from the frame's +y axis) and its distance from
    the axis over one turn of the contour, increasing in angle.
    """
    phi = np.linspace(0.0, 2.0 * np.pi, 2048, endpoint=False)
    x = np.zeros((phi.size, 4))
    x[:, 1] = phi
    pos = RigidModel(rig).ball_position(x)  # theta = 0: frame coordinates
    psi = np.mod(np.arctan2(pos[:, 0], pos[:, 1]), 2.0 * np.pi)
    order = np.argsort(psi)
    psi, r = psi[order], np.hypot(pos[order, 0], pos[order, 1])
    keep = np.concatenate([[True], np.diff(psi) > 0])
    return psi[keep], r[keep]


class ThetaBuffer:
    """Recent encoder samples; theta at any time inside (or just after) them.

    Parameters
    ----------
    max_gap : float
        Furthest a query may lie after the newest sample for linear extrapolation with its
        rate [s].
    size : int
        Samples kept.
    """

    def __init__(self, max_gap: float = 0.05, size: int = 400) -> None:
        self.max_gap_ns = round(max_gap * _NS)
        self.t: deque[int] = deque(maxlen=size)
        self.th: deque[float] = deque(maxlen=size)
        self.thd: deque[float] = deque(maxlen=size)

    def add(self, t_ns: int, theta: float, theta_dot: float) -> None:
        """Add a sample (older or repeated stamps are ignored)."""
        if self.t and t_ns <= self.t[-1]:
            return
        self.t.append(t_ns)
        self.th.append(theta)
        self.thd.append(theta_dot)

    def theta_at(self, t_ns: int) -> tuple[float | None, str]:
        """Frame angle [rad] at t (cubic Hermite inside, linear just after), or None and why."""
        if not self.t:
            return None, "no joint_states received"
        ts = self.t
        if t_ns > ts[-1]:
            gap = t_ns - ts[-1]
            if gap > self.max_gap_ns:
                return None, (f"newest joint_states sample is {gap / _NS:.3f} s older than the "
                              f"frame")
            return self.th[-1] + self.thd[-1] * gap / _NS, ""
        if t_ns < ts[0]:
            return None, "frame older than the joint_states buffer"
        i = bisect.bisect_right(ts, t_ns) - 1
        if i >= len(ts) - 1 or ts[i] == t_ns:
            return self.th[i], ""
        h = (ts[i + 1] - ts[i]) / _NS
        s = (t_ns - ts[i]) / _NS / h
        s2, s3 = s * s, s * s * s
        th0, th1, d0, d1 = self.th[i], self.th[i + 1], self.thd[i], self.thd[i + 1]
        return ((2 * s3 - 3 * s2 + 1) * th0 + (s3 - 2 * s2 + s) * h * d0
                + (-2 * s3 + 3 * s2) * th1 + (s3 - s2) * h * d1), ""


class CameraNode(Node):
    """ROS 2 wrapper of the ball detector (module docstring)."""

    def __init__(self, accepted: Iterable[str] = (), place: bool = True) -> None:
        """Start the node (``accepted``, ``place``: see :mod:`bfr_tools.loop_node`).

        Parameters
        ----------
        accepted : iterable of str
            Parameter names accepted without use (those of other nodes in this process).
        place : bool
            Apply ``process.*`` (priority, CPU) now; False when the process's host does.
        """
        super().__init__("camera")
        # one frame at a time: OpenCV's worker threads cost more than they save on the
        # detector's calls (they spin after each job: 0.15-0.19 cores of system time here)
        cv2.setNumThreads(1)
        self.defaults = node_defaults()
        declare_parameter_tree(self, self.defaults, accepted)
        p = read_parameter_tree(self, self.defaults)
        self.process = p["process"]
        self.camera_params = dict(p["camera"])
        self.camera: CameraModel = camera_from_dict(self.camera_params)
        self.detector_config = detector_config_from_dict(p["detector"])
        self.ball_radius = float(p["ball"]["radius"])
        what = "is unknown" if self.ball_radius == 0 else f"must be > 0 m, got {self.ball_radius}"
        check(math.isfinite(self.ball_radius) and self.ball_radius > 0, "ball.radius",
              f"{what}: pass --params-file <bfr_model>/config/rig.yaml or -p ball.radius:=<m>")
        self.track = ball_track(params_from_dict({k: p[k] for k in RIG_GROUPS if k in p}))
        self.get_logger().info(SETTING_UP)
        self.detector = self._make_detector(self.camera)
        warm = self.detector.warm_up()  # the compiled kernels loaded now, not at the 1st fix
        # after the warm-up: a cold compile does not hold a CPU at real-time priority
        self.scheduling = (place_process(self.process, self.get_logger()) if place
                           else "process placed by its host")
        inp = p["input"]
        self.use_camera_info = bool(inp["use_camera_info"])
        self.joint_name = str(inp["joint_name"])
        self.joints = JointPicker(self.joint_name, "input.joint_name")
        self.theta = ThetaBuffer(float(inp["theta_max_gap"]))
        self.frame_timeout = float(inp["frame_timeout"])
        check(self.frame_timeout > 0, "input.frame_timeout",
              f"must be > 0 s, got {self.frame_timeout}")
        max_age = float(inp["max_image_age"])
        check(max_age > 0, "input.max_image_age", f"must be > 0 s, got {max_age}")
        self.max_age_ns = round(max_age * _NS)
        self.ages: deque[int] = deque(maxlen=20000)  # arrival - stamp of recent images [ns]
        self.stamps: deque[int] = deque(maxlen=MAX_STAMPS)  # stamps of recent images [ns]
        self.old_images = 0  # images older than max_image_age on arrival
        self.old_streak = 0  # of them, in a row up to the newest
        self.obs_pub = self.create_publisher(BallObservation, "ball_observation", STATE_QOS)
        self.markers = MarkerPublisher(self, "ball_markers", float(p["markers"]["rate"]))
        self.detection_pub = (self.create_publisher(ImageMarker, "camera/detection", MARKER_QOS)
                              if self.markers.pub is not None else None)
        # images and joint_states arrive serialized and are parsed here (RawImage,
        # parse_joint_state): no Python message object per image or encoder sample. The
        # encoder samples and camera_info are taken at each image (and by the watchdog), not
        # one callback each (PolledSubscription); a camera_info is read only if it changed
        self.image_sub = self.create_subscription(Image, "camera/image_raw", self._on_image,
                                                  IMAGE_SUB_QOS, raw=True)
        self.info_sub = PolledSubscription(self, CameraInfo, "camera/camera_info",
                                           IMAGE_SUB_QOS)
        self.info_raw = b""  # the last camera_info taken, without its stamp
        self.js_sub = PolledSubscription(self, JointState, "joint_states",
                                         JOINT_STATES_POLLED_QOS)
        # a driver's within-a-turn angle made accumulating
        self.turns = turn_unwrapper(self, self.js_sub.topic_name)
        self.throttle = Throttle()
        # timeouts on the node's clock: simulated time under use_sim_time
        self.create_timer(max(self.frame_timeout / 4.0, 0.05), self._watchdog)
        self.started_ns = self.get_clock().now().nanoseconds
        self.last_image_ns = self.started_ns
        self.calibrated = not self.use_camera_info
        self.waiting_logged = False
        self.missing = False
        self.last_status: int | None = None
        self.last_reason = ""
        self.last_theta_problem = ""
        self.info_key: tuple | None = None
        self.info_rejected = ""  # why the newest camera_info was refused (empty: it was not)
        self.stats = {"frames": 0, "found": 0, "not_found": 0, "ambiguous": 0, "invalid": 0,
                      "missing": 0, "uncalibrated": 0, "published": 0, "time": 0.0}
        self.executor_ref: Any = None
        if self.use_camera_info:
            calib = (f"calibration: waiting for camera_info on {self.info_sub.topic_name} "
                     f"(no image is measured before it)")
        else:
            calib = (f"calibration: parameters camera.* ({self._describe(self.camera)}; "
                     f"input.use_camera_info false: {self.info_sub.topic_name} ignored)")
        self.get_logger().info(
            f"camera: images {self.image_sub.topic_name}, ball radius "
            f"{1e3 * self.ball_radius:.1f} mm, ROI "
            f"{'on' if self.detector_config.use_roi else 'off'}, detector warmed up in "
            f"{1e3 * warm:.0f} ms, pose "
            f"{[round(v, 4) for v in self.camera_params['position']]} m; {calib}; "
            f"{self.scheduling}")

    def _make_detector(self, cam: CameraModel) -> BallDetector:
        det = BallDetector(cam, self.ball_radius, self.detector_config)
        det.set_track(*self.track)
        return det

    @staticmethod
    def _describe(cam: CameraModel) -> str:
        return (f"{cam.width}x{cam.height}, fx {cam.fx:.1f} fy {cam.fy:.1f} px, "
                f"{cam.distortion_model} d {[round(float(v), 4) for v in cam.d]}")

    # -- inputs ----------------------------------------------------------------------------
    def take_joints(self) -> None:
        """Take the encoder samples queued since the last image into the theta buffer."""
        for raw in self.js_sub.take():
            self._on_joints(raw)

    def _on_joints(self, raw: bytes) -> None:
        try:
            t_ns, names, position, velocity, _ = parse_joint_state(raw)
        except CdrError as exc:
            if self.throttle("js", 2.0):
                self.get_logger().warn(f"malformed message on {self.js_sub.topic_name}: {exc}")
            return
        j = self.joints.index(names, position)
        if j is None or j >= len(position):  # another joint's message, or no position
            return
        theta_dot = float(velocity[j]) if j < len(velocity) else math.nan
        theta = self.turns(float(position[j]), t_ns * 1e-9, theta_dot)  # a driver's may wrap
        theta_dot = 0.0 if math.isnan(theta_dot) else theta_dot
        self.theta.add(t_ns, theta, theta_dot)

    def take_info(self) -> None:
        """Take the newest camera_info; read it if it differs from the last (stamp aside)."""
        taken = self.info_sub.take()
        if not taken or not self.use_camera_info:
            return
        raw = taken[-1]
        if raw[12:] == self.info_raw:  # CDR: encapsulation, stamp (8 bytes), then the rest
            return
        self.info_raw = raw[12:]
        self._on_info(deserialize_message(raw, CameraInfo))

    def _on_info(self, msg: CameraInfo) -> None:
        if not self.use_camera_info:
            return
        roi = msg.roi
        key = (msg.width, msg.height, tuple(msg.k), tuple(msg.d), msg.distortion_model,
               msg.binning_x, msg.binning_y, roi.x_offset, roi.y_offset, roi.width, roi.height)
        if key == self.info_key:
            return
        self.info_key = key
        pose = {k: self.camera_params[k] for k in ("position", "orientation", "exposure_time",
                                                   "frame_rate", "frame_id")}
        try:
            cam = CameraModel.from_camera_info(msg, **{k: (tuple(v) if isinstance(v, list)
                                                           else v) for k, v in pose.items()})
            det = self._make_detector(cam)
        except (CameraModelError, ValueError) as exc:
            self.info_rejected = str(exc)
            kept = ("keeping the previous calibration" if self.calibrated
                    else "no calibration yet: images are not measured")
            self.get_logger().error(f"camera_info rejected, {kept}: {exc}")
            return
        self.info_rejected = ""
        first = not self.calibrated
        self.camera, self.detector = cam, det
        self.calibrated = True
        self.get_logger().info(
            f"calibration{' changed' if not first else ''}: camera_info from "
            f"{self.info_sub.topic_name} ({self._describe(cam)}); pose from the parameters")

    def _on_image(self, raw: bytes) -> None:
        t0 = time.perf_counter()
        self.last_image_ns = self.get_clock().now().nanoseconds
        if self.missing:
            self.missing = False
            self.get_logger().info(f"camera images are arriving again on "
                                   f"{self.image_sub.topic_name}")
        out = BallObservation()
        out.header.frame_id = "world"
        try:
            msg = RawImage(raw)
        except CdrError as exc:
            out.header.stamp = self.get_clock().now().to_msg()
            self._invalid(out, f"malformed image message: {exc}", t0)
            return
        ns_to_stamp(msg.stamp_ns, out.header.stamp)
        self._check_age(msg.stamp_ns, self.last_image_ns)
        self.take_info()
        if not self.calibrated:
            self.stats["uncalibrated"] += 1
            self._invalid(out, (f"camera_info on {self.info_sub.topic_name} rejected "
                                f"({self.info_rejected}): no calibration, frame not measured"
                                if self.info_rejected else
                                f"waiting for camera_info on {self.info_sub.topic_name}: "
                                f"no calibration yet, frame not measured"), t0)
            return
        arr, err = image_to_array(msg)
        if arr is None:
            self._invalid(out, err, t0)
            return
        t_ns = msg.stamp_ns
        self.take_joints()
        theta, why = self.theta.theta_at(t_ns)
        det = self.detector.detect(arr, 0.0 if theta is None else theta,
                                   gate=theta is not None)
        self.stats["frames"] += 1
        status = int(det.status)
        if det.status == DetectionStatus.INVALID_INPUT:
            self._invalid(out, det.reason, t0, counted=True)
            return
        out.status = status
        out.valid = det.valid
        out.confidence = float(det.confidence)
        out.u, out.v, out.radius_px = float(det.u), float(det.v), float(det.radius_px)
        out.x, out.y = float(det.x), float(det.y)
        if theta is None:
            out.phi = out.theta_used = math.nan
            if det.valid:
                kind = why.split(" s ")[0].rstrip("0123456789.")  # without the figures
                if kind != self.last_theta_problem or self.throttle("theta", 2.0):
                    other = ""  # the graph asked only for a warning that is given
                    if why.startswith("no joint_states"):
                        other = self.joints.missing() or wrong_type_publishers(
                            self, self.js_sub.topic_name, "sensor_msgs/msg/JointState")
                    self.get_logger().warn(
                        f"phi not computed ({why.replace('joint_states', self.js_sub.topic_name)}"
                        + (f"; {other}" if other else "") + "); x, y are still valid")
                self.last_theta_problem = kind
        else:
            self.last_theta_problem = ""
            out.phi, out.theta_used = float(det.phi), float(det.theta_used)
        out.processing_time = time.perf_counter() - t0
        self.obs_pub.publish(out)
        self.stats["published"] += 1
        self._publish_markers(out, msg)
        self.stats["time"] += out.processing_time
        self.last_reason = ""
        key = {0: "found", 1: "not_found", 2: "ambiguous"}.get(status, "invalid")
        self.stats[key] += 1
        if status != self.last_status:
            if det.valid:
                self.get_logger().info(f"ball found at ({det.x:+.4f}, {det.y:+.4f}) m")
            else:
                if self.throttle("no_ball", 1.0):
                    self.get_logger().warn(f"no ball position: {det.status.name} "
                                           f"({det.reason})")
        self.last_status = status

    def _check_age(self, t_ns: int, arrival_ns: int) -> None:
        """The image's age on arrival (``arrival - stamp``): kept, warned if implausible.

        A stamp is the exposure's time, so an image arrives after it by the exposure's half,
        the readout and the transport. Stamped after its arrival: the camera's clock is
        ahead of this computer's (more than ``STAMP_AHEAD_NS``); older than
        ``input.max_image_age`` on arrival, ``OLD_IMAGES_WARNED`` images in a row: the clock
        is behind (or the images are stuck on the way). Either way phi pairs the fix with
        the wrong frame angle. Not judged before the node's clock runs (simulated time
        before the first /clock).
        """
        if arrival_ns <= 0:
            return
        age = arrival_ns - t_ns
        self.ages.append(age)
        self.stamps.append(t_ns)
        if age <= self.max_age_ns:
            self.old_streak = 0
        if -age > STAMP_AHEAD_NS and self.throttle("stamp_ahead", 5.0):
            self.get_logger().warn(
                f"image stamped {-age / 1e6:.1f} ms after it arrived: the camera's clock is "
                "ahead of this computer's, and phi pairs the fix with a later frame angle "
                "(the angle error is the stamp error times the frame's speed)")
        elif age > self.max_age_ns:
            self.old_images += 1
            self.old_streak += 1
            # a clock behind makes every image old; one or two late ones are a stall (the
            # node's own start, a busy machine): in the summary, not warned
            if self.old_streak >= OLD_IMAGES_WARNED and self.throttle("stamp_behind", 5.0):
                self.get_logger().warn(
                    f"image arrived {age / 1e6:.1f} ms after its stamp (more than "
                    f"input.max_image_age {self.max_age_ns / 1e6:g} ms): the camera's clock "
                    "is behind this computer's, or the images are late, and phi pairs the "
                    "fix with an earlier frame angle (the angle error is the stamp error "
                    "times the frame's speed)")

    def _publish_markers(self, out: BallObservation, img: RawImage) -> None:
        """The fix as markers (``markers.rate`` Hz of the image stamps; module docstring)."""
        if not self.markers.due(img.stamp_ns):
            return
        self.markers.publish(fix_markers(out.x, out.y, out.valid, self.ball_radius),
                             img.stamp_ns)
        if self.detection_pub is not None:
            self.detection_pub.publish(image_circle(out.u, out.v, out.radius_px, out.header.stamp,
                                                    img.frame_id, out.valid))

    def _invalid(self, out: BallObservation, reason: str, t0: float,
                 counted: bool = False) -> None:
        if not counted:
            self.stats["frames"] += 1
        self.stats["invalid"] += 1
        out.status = BallObservation.INVALID_INPUT
        out.valid = False
        out.confidence = 0.0
        out.u = out.v = out.radius_px = out.x = out.y = out.phi = out.theta_used = math.nan
        out.processing_time = time.perf_counter() - t0
        self.obs_pub.publish(out)
        self.stats["published"] += 1
        self.last_status = BallObservation.INVALID_INPUT
        # a new reason is logged at once, a repeated one at most once a second
        if reason.split(" (", maxsplit=1)[0] != self.last_reason:
            self.get_logger().warn(f"unusable camera frame: {reason}")
        elif self.throttle("unusable", 1.0):
            self.get_logger().warn(f"unusable camera frame: {reason}")
        self.last_reason = reason.split(" (", maxsplit=1)[0]

    def _watchdog(self) -> None:
        self.take_joints()  # keeps the queue short while no image arrives
        self.take_info()  # a calibration is logged when it arrives, images or not
        now = self.get_clock().now().nanoseconds
        if now < self.last_image_ns:  # the clock went back (a simulation restarted)
            self.last_image_ns = now
        gap = (now - self.last_image_ns) / _NS
        if gap < self.frame_timeout:
            return
        if self.stats["frames"] == 0:  # not armed before the first image
            if gap > 5.0:
                wrong = wrong_type_publishers(self, self.image_sub.topic_name,
                                              "sensor_msgs/msg/Image")
                self.get_logger().warn(f"no camera image received yet on "
                                       f"{self.image_sub.topic_name}"
                                       + (f"; {wrong}" if wrong else ""),
                                       throttle_duration_sec=10.0)
            return
        if not self.missing:
            self.get_logger().warn(f"no camera image for {gap:.1f} s on "
                                   f"{self.image_sub.topic_name}")
        self.missing = True
        out = BallObservation()
        out.header.stamp = self.get_clock().now().to_msg()
        out.header.frame_id = "world"
        self.stats["missing"] += 1
        self._invalid(out, f"no image for {gap:.1f} s", time.perf_counter(), counted=True)
        self.last_image_ns = now

    def _describe_ages(self) -> str:
        """Image age on arrival (arrival - stamp): median and range, and how many were old."""
        if not self.ages:
            return "image age on arrival: no image"
        a = np.sort(np.fromiter(self.ages, dtype=float)) / 1e6
        return (f"image age on arrival (arrival - stamp) median {a[a.size // 2]:.1f} ms, "
                f"min {a[0]:.1f}, max {a[-1]:.1f} over the last {a.size} images; "
                f"{self.old_images} older than input.max_image_age "
                f"{self.max_age_ns / 1e6:g} ms")

    def _describe_received(self) -> str:
        """How many of the driver's images reached the node, from the images' stamps.

        The node sees only what arrives; the driver's period is the one the received
        stamps' phase repeats with (:func:`bfr_camera.stamps.driver_period`: missed images
        and the stamps' jitter taken into account), and the span over it is what was sent.
        A best-effort subscription keeping the newest image takes fewer when the node is
        busy, and images too large for shared memory go in UDP fragments a loaded machine
        drops: a low share says so before the fixes' rate does.
        """
        t = np.unique(np.fromiter(self.stamps, dtype=np.int64))[-MAX_STAMPS:]
        if t.size < 10:
            return "images received: too few to judge"
        period = driver_period(t)
        span = (t[-1] - t[0]) / 1e9
        if period is None:
            return (f"images received {t.size} over the last {span:.1f} s (how many the driver "
                    f"sent cannot be told: the stamps show no period, their jitter a third of "
                    f"one or more)")
        sent = span / period + 1.0
        return (f"images received {t.size} of about {sent:.0f} the driver sent over the last "
                f"{span:.1f} s ({100.0 * t.size / sent:.0f} %, its period "
                f"{period * 1e3:.2f} ms from the stamps)")

    def on_shutdown(self) -> None:
        """Log the counts."""
        s = self.stats
        n = max(s["frames"], 1)
        self.get_logger().info(
            f"camera: {s['frames']} frames, {s['found']} found, {s['not_found']} not found, "
            f"{s['ambiguous']} ambiguous, {s['invalid']} invalid ({s['missing']} for missing "
            f"images, {s['uncalibrated']} before a usable camera_info"
            + (f"; the last camera_info was rejected ({self.info_rejected}): "
               + ("the previous calibration kept" if self.calibrated else "no calibration")
               if self.info_rejected else "")
            + "); mean processing "
            f"{1e3 * s['time'] / n:.2f} ms; {self._describe_ages()}; "
            f"{self._describe_received()}")
        self.get_logger().info(format_published({self.obs_pub.topic_name: s["published"]}))
        self.js_sub.destroy()
        self.info_sub.destroy()


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_camera camera_node``."""
    return run_node(CameraNode, argv)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
