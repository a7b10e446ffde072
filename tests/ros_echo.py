"""Echo node for tests: republish every message received, unchanged, in its own process.

For each message type given (``<package>/msg/<Type>``) it subscribes to ``echo_in/<Type>``
and publishes what it receives on ``echo_out/<Type>`` (reliable, depth 10). Stops on SIGINT.

Usage: python tests/ros_echo.py bfr_interfaces/msg/SimTruth [more types...]
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rosutil import message_class


def main(argv: Sequence[str] | None = None) -> int:
    """Run the echo node until interrupted."""
    types = list(sys.argv[1:] if argv is None else argv)
    rclpy.init()
    node = rclpy.create_node("ros_echo")
    keep = []
    for type_name in types:
        cls = message_class(type_name)
        name = type_name.split("/")[-1]
        pub = node.create_publisher(cls, f"echo_out/{name}", 10)
        keep.append(node.create_subscription(cls, f"echo_in/{name}", pub.publish, 10))
        keep.append(pub)
    node.get_logger().info(f"echoing {', '.join(types)}")
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
