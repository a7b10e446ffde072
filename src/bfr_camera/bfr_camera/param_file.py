"""Reading ROS 2 parameter files (``/**: ros__parameters: ...``) without rclpy.

The project's YAML files are both physics/sensor sources and node parameter files; every
loader (``bfr_sim.params``, ``bfr_camera.calibration``) extracts their ``ros__parameters``
mapping here, raising its own error type with the file named.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

__all__ = ["load_ros_parameters", "ros_parameters"]


def ros_parameters(doc: Any, source: str, error: type[Exception] = ValueError
                   ) -> dict[str, Any]:
    """The ``ros__parameters`` mapping of a parsed parameter file.

    Accepts a bare ``ros__parameters`` mapping or the first node entry (``/**`` or a node
    name) holding one; anything else raises ``error`` naming ``source``.
    """
    if not isinstance(doc, Mapping) or not doc:
        raise error(f"{source}: not a ROS 2 parameter file (expected a mapping)")
    if "ros__parameters" in doc:
        return dict(doc["ros__parameters"])
    for node_name, body in doc.items():
        if isinstance(body, Mapping) and "ros__parameters" in body:
            return dict(body["ros__parameters"])
        raise error(f"{source}: node entry {node_name!r} has no ros__parameters")
    raise error(f"{source}: no ros__parameters section")


def load_ros_parameters(path: str | Path, error: type[Exception] = ValueError
                        ) -> dict[str, Any]:
    """Read and parse a parameter file; unreadable or invalid YAML raises ``error``."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise error(f"cannot read parameter file {p}: {exc}") from exc
    except yaml.YAMLError as exc:
        raise error(f"{p}: invalid YAML: {exc}") from exc
    return ros_parameters(doc, str(p), error)
