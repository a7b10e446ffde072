"""``bfr doctor``: check that the environment can run the node suite.

Checks, in order: the Python version, the ROS 2 variables, that ``rclpy`` and the project's
messages import, that the workspace packages are in the ament index, and a DDS round trip of
every ``bfr_interfaces`` message inside this process (publisher and subscription on one
node, over the configured RMW). Prints one line per check; exits 1 if any check fails.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

from bfr_tools.run import package_prefix

PACKAGES = ("bfr_interfaces", "bfr_model", "bfr_ros", "bfr_camera", "bfr_control", "bfr_sim",
            "bfr_diagnose", "bfr_tools")
MESSAGES = ("BallObservation", "ControllerState", "SimTruth")
_INTEGER_TYPES = frozenset(
    ("octet", "uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64")
)


def sample_message(cls: type) -> Any:
    """Return an instance of a ROS message class with every numeric field non-default.

    Parameters
    ----------
    cls : type
        Generated ROS 2 message class.

    Returns
    -------
    object
        Message with float fields 1.5, 2.5, ..., bools True, integers 1, 2, ..., strings set.
    """
    msg = cls()
    counter = 0
    for name, kind in msg.get_fields_and_field_types().items():
        counter += 1
        if kind in ("float", "double"):
            setattr(msg, name, counter + 0.5)
        elif kind == "boolean":
            setattr(msg, name, True)
        elif kind in _INTEGER_TYPES:
            setattr(msg, name, counter % 100)
        elif kind == "string":
            setattr(msg, name, f"{name}_{counter}")
        elif kind == "std_msgs/Header":
            msg.header.stamp.sec = 1234
            msg.header.stamp.nanosec = 567
            msg.header.frame_id = "world"
    return msg


def _round_trip(timeout: float) -> str:
    """Publish every project message and receive it on the same node; return a summary."""
    # Imported here so that a broken ROS install is reported by its check, not fatal.
    import rclpy  # noqa: PLC0415 - a broken ROS install is this check's finding
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415 - likewise

    module = importlib.import_module("bfr_interfaces.msg")
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node(f"bfr_doctor_{os.getpid()}", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        received: dict[str, Any] = {}
        pairs = []
        for name in MESSAGES:
            cls = getattr(module, name)
            topic = f"bfr_doctor_{os.getpid()}/{name.lower()}"

            def store(msg: Any, key: str = name) -> None:
                received[key] = msg

            sub = node.create_subscription(cls, topic, store, 10)
            pub = node.create_publisher(cls, topic, 10)
            pairs.append((name, cls, pub, sub))
        deadline = time.monotonic() + timeout
        while any(p.get_subscription_count() < 1 for _, _, p, _ in pairs):
            if time.monotonic() > deadline:
                raise TimeoutError("publishers and subscriptions did not match")
            executor.spin_once(timeout_sec=0.05)
        sent = {}
        for name, cls, pub, _ in pairs:
            sent[name] = sample_message(cls)
            pub.publish(sent[name])
        while len(received) < len(MESSAGES):
            if time.monotonic() > deadline:
                missing = sorted(set(MESSAGES) - set(received))
                raise TimeoutError(f"no message received for {', '.join(missing)}")
            executor.spin_once(timeout_sec=0.05)
        bad = [name for name in MESSAGES if received[name] != sent[name]]
        if bad:
            raise ValueError(f"received values differ for {', '.join(bad)}")
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return f"{', '.join(MESSAGES)} round trip over {os.environ.get('RMW_IMPLEMENTATION')}"


def _packages() -> str:
    """Return the install prefix of every workspace package (ament index lookup)."""
    return ", ".join(f"{p} ({package_prefix(p)})" for p in PACKAGES)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the checks and print one line each.

    Parameters
    ----------
    argv : sequence of str, optional
        Command-line arguments after ``doctor``.

    Returns
    -------
    int
        0 if every check passed, 1 otherwise.
    """
    parser = argparse.ArgumentParser(prog="bfr doctor", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--timeout", type=float, default=10.0, help="DDS round-trip timeout [s] (default 10)"
    )
    args = parser.parse_args(argv)
    # Keep discovery on this machine unless the user configured it.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    checks: list[tuple[str, Callable[[], str]]] = [
        ("python", lambda: sys.version.split()[0] + f" ({sys.executable})"),
        (
            "ros environment",
            lambda: " ".join(
                f"{key}={os.environ.get(key, '<unset>')}"
                for key in (
                    "ROS_DISTRO",
                    "RMW_IMPLEMENTATION",
                    "ROS_DOMAIN_ID",
                    "ROS_AUTOMATIC_DISCOVERY_RANGE",
                )
            ),
        ),
        ("rclpy", lambda: importlib.import_module("rclpy").__file__ or "rclpy"),
        (
            "bfr_interfaces.msg",
            lambda: ", ".join(
                n for n in MESSAGES if hasattr(importlib.import_module("bfr_interfaces.msg"), n)
            ),
        ),
        ("ament index", _packages),
        ("dds", lambda: _round_trip(args.timeout)),
    ]
    failed = 0
    for label, check in checks:
        try:
            detail = check()
        except Exception as exc:  # noqa: BLE001 - report every failure, keep checking
            failed += 1
            print(f"FAIL {label}: {type(exc).__name__}: {exc}")
        else:
            print(f"ok   {label}: {detail}")
    if failed:
        print(f"doctor: {failed} of {len(checks)} checks FAILED")
    else:
        print(f"doctor: all {len(checks)} checks ok")
    return 1 if failed else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
