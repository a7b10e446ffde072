"""The camera node: the ball's position in each camera frame, with OpenCV.

A thin node over :class:`bfr_camera.detector.BallDetector`:

- subscribes ``camera/image_raw`` (``sensor_msgs/Image``; mono8, mono16, 32FC1 or colour;
  sensor-data QoS), ``camera/camera_info`` (the intrinsics, which replace those of
  ``camera.*`` when ``input.use_camera_info``) and ``joint_states`` (the frame angle theta,
  interpolated at each frame's exposure mid-time from a short buffer, for the observation's
  ``phi = theta + atan2(x, y)``);
- publishes one ``ball_observation`` (``bfr_interfaces/BallObservation``, reliable) per
  image, stamped with the image's stamp (the exposure mid-time). The detector keeps the last
  fix and searches a region of interest around it first;
- at ``markers.rate`` Hz of the images' stamps (0: off, as in hardware.yaml), what it saw for
  Foxglove and RViz: ``ball_markers`` (``visualization_msgs/MarkerArray``, frame ``world``: a
  sphere of the ball's size at the fix, deleted when no ball is found) and
  ``camera/detection`` (``visualization_msgs/ImageMarker``: a circle round the ball on the
  image, in the image's frame and stamp).

Bad input never stops the node: an image it cannot use (encoding, size, step, a size that
does not match the calibration, a non-finite theta) gives an observation with status
``INVALID_INPUT`` and a throttled warning that says why; no ball gives ``NOT_FOUND``;
several give ``AMBIGUOUS``; no image for ``input.frame_timeout`` seconds (wall time) gives
an ``INVALID_INPUT`` observation stamped now and a warning. When no current joint_states
sample covers a frame, the ball's position is still reported (valid) with ``phi`` and
``theta_used`` NaN.
"""

from __future__ import annotations

import bisect
import math
import time
from collections import deque
from typing import Any

from bfr_model.param_file import check, config_path
from bfr_model.params import default_params_path
from bfr_model.scene import fix_markers
from bfr_ros.markers import MARKER_QOS, MarkerPublisher, image_circle
from bfr_ros.node_common import (
    IMAGE_QOS,
    JOINT_STATES_QOS,
    STATE_QOS,
    declare_parameter_tree,
    image_to_array,
    load_yaml_parameters,
    read_parameter_tree,
    run_node,
    stamp_to_ns,
)
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from visualization_msgs.msg import ImageMarker

from bfr_camera.calibration import (
    CameraModel,
    CameraModelError,
    camera_from_dict,
    default_camera_path,
)
from bfr_camera.detector import BallDetector, DetectionStatus, detector_config_from_dict
from bfr_interfaces.msg import BallObservation

__all__ = ["CameraNode", "ThetaBuffer", "main", "node_defaults"]

_NS = 1_000_000_000


def node_defaults() -> dict[str, Any]:
    """Defaults: camera.yaml (camera.*, detector.*), ball.radius of rig.yaml, this node's file."""
    d = dict(load_yaml_parameters(default_camera_path()))
    d["ball"] = {"radius": float(load_yaml_parameters(default_params_path())["ball"]["radius"])}
    d.update(load_yaml_parameters(config_path("bfr_camera", "camera_node.yaml")))
    return d


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

    def __init__(self) -> None:
        super().__init__("camera")
        self.defaults = node_defaults()
        declare_parameter_tree(self, self.defaults)
        p = read_parameter_tree(self, self.defaults)
        self.camera_params = dict(p["camera"])
        self.camera: CameraModel = camera_from_dict(self.camera_params)
        self.detector_config = detector_config_from_dict(p["detector"])
        self.ball_radius = float(p["ball"]["radius"])
        what = "is unknown" if self.ball_radius == 0 else f"must be > 0 m, got {self.ball_radius}"
        check(math.isfinite(self.ball_radius) and self.ball_radius > 0, "ball.radius",
              f"{what}: pass --params-file <bfr_model>/config/rig.yaml or -p ball.radius:=<m>")
        self.detector = BallDetector(self.camera, self.ball_radius, self.detector_config)
        inp = p["input"]
        self.use_camera_info = bool(inp["use_camera_info"])
        self.joint_name = str(inp["joint_name"])
        self.theta = ThetaBuffer(float(inp["theta_max_gap"]))
        self.frame_timeout = float(inp["frame_timeout"])
        self.obs_pub = self.create_publisher(BallObservation, "ball_observation", STATE_QOS)
        self.markers = MarkerPublisher(self, "ball_markers", float(p["markers"]["rate"]))
        self.detection_pub = (self.create_publisher(ImageMarker, "camera/detection", MARKER_QOS)
                              if self.markers.pub is not None else None)
        self.create_subscription(Image, "camera/image_raw", self._on_image, IMAGE_QOS)
        self.create_subscription(CameraInfo, "camera/camera_info", self._on_info, IMAGE_QOS)
        self.create_subscription(JointState, "joint_states", self._on_joints, JOINT_STATES_QOS)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(max(self.frame_timeout / 4.0, 0.05), self._watchdog, clock=self._steady)
        self.last_image_wall = time.monotonic()
        self.missing = False
        self.last_status: int | None = None
        self.last_reason = ""
        self.last_theta_problem = ""
        self.info_key: tuple | None = None
        self.stats = {"frames": 0, "found": 0, "not_found": 0, "ambiguous": 0, "invalid": 0,
                      "missing": 0, "time": 0.0}
        self.executor_ref: Any = None
        self.get_logger().info(
            f"camera: {self.camera.width}x{self.camera.height}, ball radius "
            f"{1e3 * self.ball_radius:.1f} mm ({self.detector.expected_radius_px:.1f} px), "
            f"ROI {'on' if self.detector_config.use_roi else 'off'}, camera_info "
            f"{'used' if self.use_camera_info else 'ignored'}")

    # -- inputs ----------------------------------------------------------------------------
    def _on_joints(self, msg: JointState) -> None:
        names = list(msg.name)
        if self.joint_name in names:
            j = names.index(self.joint_name)
        elif not names and len(msg.position) == 1:
            j = 0
        else:
            return  # another joint's message
        if j >= len(msg.position):
            return
        theta = float(msg.position[j])
        theta_dot = float(msg.velocity[j]) if j < len(msg.velocity) else 0.0
        self.theta.add(stamp_to_ns(msg.header.stamp), theta, theta_dot)

    def _on_info(self, msg: CameraInfo) -> None:
        if not self.use_camera_info:
            return
        key = (msg.width, msg.height, tuple(msg.k), tuple(msg.d), msg.distortion_model)
        if key == self.info_key:
            return
        self.info_key = key
        pose = {k: self.camera_params[k] for k in ("position", "orientation", "exposure_time",
                                                   "frame_rate", "frame_id")}
        try:
            cam = CameraModel.from_camera_info(msg, **{k: (tuple(v) if isinstance(v, list)
                                                           else v) for k, v in pose.items()})
            det = BallDetector(cam, self.ball_radius, self.detector_config)
        except (CameraModelError, ValueError) as exc:
            self.get_logger().error(f"camera_info rejected, keeping the previous calibration: "
                                    f"{exc}")
            return
        self.camera, self.detector = cam, det
        self.get_logger().info(f"calibration from camera_info: {cam.width}x{cam.height}, "
                               f"fx {cam.fx:.1f} fy {cam.fy:.1f} px, {cam.distortion_model}")

    def _on_image(self, msg: Image) -> None:
        t0 = time.perf_counter()
        self.last_image_wall = time.monotonic()
        if self.missing:
            self.missing = False
            self.get_logger().info("camera images are arriving again")
        out = BallObservation()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = "world"
        arr, err = image_to_array(msg)
        if arr is None:
            self._invalid(out, err, t0)
            return
        t_ns = stamp_to_ns(msg.header.stamp)
        theta, why = self.theta.theta_at(t_ns)
        det = self.detector.detect(arr, 0.0 if theta is None else theta)
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
                if kind != self.last_theta_problem:
                    self.get_logger().warn(f"phi not computed ({why}); x, y are still valid")
                else:
                    self.get_logger().warn(f"phi not computed ({why}); x, y are still valid",
                                           throttle_duration_sec=2.0)
                self.last_theta_problem = kind
        else:
            self.last_theta_problem = ""
            out.phi, out.theta_used = float(det.phi), float(det.theta_used)
        out.processing_time = time.perf_counter() - t0
        self.obs_pub.publish(out)
        self._publish_markers(out, msg)
        self.stats["time"] += out.processing_time
        self.last_reason = ""
        key = {0: "found", 1: "not_found", 2: "ambiguous"}.get(status, "invalid")
        self.stats[key] += 1
        if status != self.last_status:
            if det.valid:
                self.get_logger().info(f"ball found at ({det.x:+.4f}, {det.y:+.4f}) m")
            else:
                self.get_logger().warn(f"no ball position: {det.status.name} ({det.reason})",
                                       throttle_duration_sec=1.0)
        self.last_status = status

    def _publish_markers(self, out: BallObservation, img: Image) -> None:
        """The fix as markers (``markers.rate`` Hz of the image stamps; module docstring)."""
        if not self.markers.due(stamp_to_ns(out.header.stamp)):
            return
        self.markers.publish(fix_markers(out.x, out.y, out.valid, self.ball_radius),
                             stamp_to_ns(out.header.stamp))
        if self.detection_pub is not None:
            self.detection_pub.publish(image_circle(out.u, out.v, out.radius_px, img.header.stamp,
                                                    img.header.frame_id, out.valid))

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
        self.last_status = BallObservation.INVALID_INPUT
        # a new reason is logged at once, a repeated one at most once a second
        if reason.split(" (", maxsplit=1)[0] != self.last_reason:
            self.get_logger().warn(f"unusable camera frame: {reason}")
        else:
            self.get_logger().warn(f"unusable camera frame: {reason}", throttle_duration_sec=1.0)
        self.last_reason = reason.split(" (", maxsplit=1)[0]

    def _watchdog(self) -> None:
        gap = time.monotonic() - self.last_image_wall
        if gap < self.frame_timeout:
            return
        if self.stats["frames"] == 0:  # not armed before the first image
            if gap > 5.0:
                self.get_logger().warn("no camera image received yet (camera/image_raw)",
                                       throttle_duration_sec=10.0)
            return
        if not self.missing:
            self.get_logger().warn(f"no camera image for {gap:.1f} s (camera/image_raw)")
        self.missing = True
        out = BallObservation()
        out.header.stamp = self.get_clock().now().to_msg()
        out.header.frame_id = "world"
        self.stats["missing"] += 1
        self._invalid(out, f"no image for {gap:.1f} s", time.perf_counter(), counted=True)
        self.last_image_wall = time.monotonic()

    def on_shutdown(self) -> None:
        """Log the counts."""
        s = self.stats
        n = max(s["frames"], 1)
        self.get_logger().info(
            f"camera: {s['frames']} frames, {s['found']} found, {s['not_found']} not found, "
            f"{s['ambiguous']} ambiguous, {s['invalid']} invalid ({s['missing']} for missing "
            f"images); mean processing "
            f"{1e3 * s['time'] / n:.2f} ms")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_camera camera_node``."""
    return run_node(CameraNode, argv)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
