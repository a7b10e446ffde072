"""The recorder node: a ROS 2 bag (MCAP) of the rig's topics, readable by ``ros2 bag``.

Generic: for each topic of ``recorder.topics`` it makes a raw (serialized) subscription and
hands the CDR bytes to :class:`bfr_model.io.bag.BagWriter`, which writes a rosbag2 directory
(``metadata.yaml`` + one ``.mcap``; schemas ``ros2msg``, the project's own types included)
that ``ros2 bag info/play``, Foxglove and :func:`bfr_model.io.bag.read_bag` (``bfr diagnose``)
read. The types of the topic contract are known in advance; any other topic's type is
looked up in the ROS graph until a publisher appears.

The receive (log) time of each message is the node's clock, as ``ros2 bag record`` does:
simulated time under ``use_sim_time:=true``. Topic names are resolved like any other
node's, so the remappings given to the rig's nodes (``-r camera/camera_info:=/cam/info``)
given to the recorder too make it record the remapped topics.

Nothing the publishers sent while it ran is lost:

- it subscribes to every topic of the contract at start, so a rig that waits for its
  subscriptions before it starts (``bfr rig`` does) loses nothing at the beginning;
- QoS follows the publishers, as ``ros2 bag record`` does: each subscription starts
  reliable with a deep queue (``recorder.depth``); when a best-effort publisher appears on
  its topic (a camera driver's sensor-data QoS), which a reliable subscription cannot
  match, it is made again best effort, and the log says so;
- on SIGINT/SIGTERM it keeps taking messages until none has arrived for
  ``recorder.drain_quiet`` seconds (at most ``recorder.drain_timeout``), then closes the bag
  (a last flush, the MCAP summary and ``metadata.yaml``) and logs the message count per
  topic (``recorded: /topic N, ...``).
"""

from __future__ import annotations

import importlib
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from bfr_model.io.bag import BagWriter
from bfr_model.param_file import config_path
from bfr_ros.node_common import (
    declare_parameter_tree,
    format_published,
    load_yaml_parameters,
    place_process,
    read_parameter_tree,
    run_node,
)
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["CONTRACT_TYPES", "RecorderNode", "main", "node_defaults"]

#: Types of the topic contract (README), by default topic name.
CONTRACT_TYPES: dict[str, str] = {
    "joint_states": "sensor_msgs/msg/JointState",
    "effort_controller/commands": "std_msgs/msg/Float64MultiArray",
    "ball_observation": "bfr_interfaces/msg/BallObservation",
    "controller_state": "bfr_interfaces/msg/ControllerState",
    "sim_truth": "bfr_interfaces/msg/SimTruth",
    "camera/camera_info": "sensor_msgs/msg/CameraInfo",
    "camera/image_raw": "sensor_msgs/msg/Image",
    "clock": "rosgraph_msgs/msg/Clock",
    "sim_markers": "visualization_msgs/msg/MarkerArray",
    "ball_markers": "visualization_msgs/msg/MarkerArray",
    "camera/detection": "visualization_msgs/msg/ImageMarker",
}


def node_defaults() -> dict[str, Any]:
    """Defaults from recorder_node.yaml (bfr_sim's ``config/``)."""
    return dict(load_yaml_parameters(config_path("bfr_sim", "recorder_node.yaml")))


def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type``."""
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


class RecorderNode(Node):
    """Records topics into a bag (module docstring)."""

    def __init__(self) -> None:
        super().__init__("recorder")
        self.defaults = node_defaults()
        declare_parameter_tree(self, self.defaults)
        tree = read_parameter_tree(self, self.defaults)
        self.scheduling = place_process(tree["process"], self.get_logger())
        p = tree["recorder"]
        path = str(p["path"]) or datetime.now().strftime("bfr_%Y%m%d_%H%M%S")
        self.depth = int(p["depth"])
        self.drain_quiet = float(p["drain_quiet"])
        self.drain_timeout = float(p["drain_timeout"])
        self.bag = BagWriter(Path(path), flush_interval=float(p["flush_interval"]),
                             custom_data={"recorded_by": "bfr_sim recorder_node"})
        self.wanted: dict[str, str] = {}  # resolved topic -> configured name
        for topic in p["topics"]:
            self.wanted[self.resolve_topic_name(str(topic))] = str(topic)
        self.subs: dict[str, Any] = {}
        self.reliable: dict[str, bool] = {}
        self.last_msg = time.monotonic()
        self.types: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.matched: set[str] = set()  # topics with a matched publisher (logged once)
        for resolved, name in self.wanted.items():
            known = CONTRACT_TYPES.get(name.lstrip("/")) or CONTRACT_TYPES.get(
                resolved.lstrip("/"))
            if known is not None:
                self._subscribe(resolved, known)
        # on the steady clock: under use_sim_time the node's clock stands still until /clock
        # comes, and the topics must be found and matched before the simulation starts
        self.create_timer(float(p["discovery_period"]), self._discover,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.t_start = time.monotonic()
        self.executor_ref: Any = None
        self.get_logger().info(
            f"recording {len(self.wanted)} topic(s) into {self.bag.path}: "
            + ", ".join(sorted(self.wanted)) + f"; {self.scheduling}")

    def _subscribe(self, topic: str, type_name: str, reliable: bool = True) -> None:
        try:
            cls = message_class(type_name)
        except (ImportError, AttributeError, ValueError) as exc:
            self.get_logger().error(f"cannot record {topic}: type {type_name} not importable "
                                    f"({exc})", throttle_duration_sec=10.0)
            return
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.depth,
                         reliability=(ReliabilityPolicy.RELIABLE if reliable
                                      else ReliabilityPolicy.BEST_EFFORT),
                         durability=DurabilityPolicy.VOLATILE)
        if topic not in self.types:
            self.types[topic] = type_name
            self.counts[topic] = 0
            self.bag.add_topic(topic, type_name)

        def callback(data: bytes, topic: str = topic, type_name: str = type_name) -> None:
            self.bag.write(topic, type_name, data, max(self.get_clock().now().nanoseconds, 0))
            self.counts[topic] += 1
            self.last_msg = time.monotonic()

        self.subs[topic] = self.create_subscription(cls, topic, callback, qos, raw=True)
        self.reliable[topic] = reliable

    def _adapt_qos(self) -> None:
        """A best-effort publisher on a reliably subscribed topic: subscribe best effort."""
        for topic, sub in list(self.subs.items()):
            if not self.reliable.get(topic):
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos):
                self.destroy_subscription(sub)
                self._subscribe(topic, self.types[topic], reliable=False)
                self.get_logger().info(f"{topic}: a publisher offers best effort only; "
                                       f"recording it best effort")

    def _discover(self) -> None:
        self._adapt_qos()
        for topic, sub in self.subs.items():  # "matched" lines: bfr rig starts the
            n = sub.get_publisher_count()      # simulation once the loop's topics have them
            if n and topic not in self.matched:
                self.matched.add(topic)
                self.get_logger().info(f"matched {topic}: {n} publisher(s)")
        missing = [t for t in self.wanted if t not in self.subs]
        if not missing:
            return
        graph = dict(self.get_topic_names_and_types())
        for topic in missing:
            types = graph.get(topic)
            if types:
                if len(types) > 1:
                    self.get_logger().warn(f"{topic} has several types {types}; recording "
                                           f"{types[0]}")
                self._subscribe(topic, types[0])
                self.get_logger().info(f"recording {topic} ({types[0]})")

    def drain(self) -> float:
        """Take what is still queued or in flight; returns the time it took [s].

        Spins until ``drain_quiet`` seconds pass without a message (at most
        ``drain_timeout`` seconds).
        """
        ex = self.executor_ref
        t0 = time.monotonic()
        if ex is None:
            return 0.0
        self.last_msg = max(self.last_msg, t0 - self.drain_quiet / 2.0)
        while True:
            now = time.monotonic()
            if now - self.last_msg >= self.drain_quiet or now - t0 >= self.drain_timeout:
                return now - t0
            ex.spin_once(timeout_sec=0.02)

    def on_shutdown(self) -> None:
        """Drain, close the bag (flush, summary, metadata.yaml) and log the counts."""
        n0 = self.bag.message_count
        took = self.drain()
        self.bag.close()
        wall = time.monotonic() - self.t_start
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.counts.items()))
        missing = [t for t in self.wanted if t not in self.subs]
        self.get_logger().info(
            f"bag {self.bag.path} closed: {self.bag.message_count} messages in {wall:.1f} s "
            f"({counts}; {self.bag.message_count - n0} taken while draining for {took:.2f} s)"
            + (f"; never seen: {', '.join(missing)}" if missing else ""))
        self.get_logger().info(format_published(dict(sorted(self.counts.items())))
                               .replace("published: ", "recorded: ", 1))


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_sim recorder_node``."""
    return run_node(RecorderNode, argv)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
