"""The camera and controller nodes composed in one process: ``ros2 run bfr_tools loop_node``.

The control loop's two nodes (``camera`` and ``controller``, the same classes, parameters
and topics as ``camera_node`` and ``controller_node``) in one process with one executor,
as an rclcpp component container would hold them. It lives here, above both packages in the
dependency order: the controller package does not depend on the camera package. What it
changes (measured with ``bfr bench --only loop``: docs/notes/issue-17.md, sixth session):

- the observation from the camera to the controller does not cross processes (Fast DDS
  delivers it inside the participant), and the 1 kHz encoder samples both nodes take are
  received once, by one DDS thread;
- one process to pin to one CPU (``process.cpu``): with both nodes under ``SCHED_FIFO``
  in two processes, each preempted the other and the kernel moved the preempted thread to
  another CPU.

Parameters
----------
Each node reads its own files and overrides as it does alone (``--params-file`` sections
``/**/camera:`` / ``/**/controller:`` reach one node in any namespace, ``/**:`` both; a bare
``camera:`` reaches /camera only, which a node in a namespace names at start). A
``-p name:=value`` reaches both nodes (rcl's rule for a process): each accepts the other's
parameter names, and a name neither knows stops the process at start.
``process.realtime_priority`` and ``process.cpu`` are applied once for the whole process,
after both nodes have warmed up: the higher of the two priorities, and the CPU both name (a
CPU for one and -1 for the other pins; two different CPUs are refused).

Do not rename the nodes with ``-r __node:=...`` (it would rename both to one name); give
the process a namespace with ``-r __ns:=...`` if several loops share a graph.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from bfr_camera.camera_node import CameraNode
from bfr_camera.camera_node import node_defaults as camera_defaults
from bfr_control.controller_node import ControllerNode
from bfr_control.controller_node import node_defaults as controller_defaults
from bfr_ros.node_common import check_process, flatten, place_process, run_nodes

__all__ = ["main", "process_settings"]


def process_settings(nodes: Iterable[Any]) -> dict[str, int]:
    """The ``process`` parameters for a process that hosts ``nodes`` (each has ``.process``).

    Returns
    -------
    dict
        ``realtime_priority``: the highest of the nodes'; ``cpu``: the one CPU the nodes
        name (-1 if none names one).

    Raises
    ------
    ValueError
        If a node's value is invalid, or two nodes name different CPUs.
    """
    nodes = list(nodes)
    for n in nodes:  # each node's values as it would check them alone
        check_process(n.process)
    cpus = {n.process["cpu"] for n in nodes} - {-1}
    if len(cpus) > 1:
        named = ", ".join(f"{n.get_name()} {n.process['cpu']}" for n in nodes)
        raise ValueError(f"process.cpu: the nodes of one process name different CPUs "
                         f"({named}); give one value")
    return {"realtime_priority": max(n.process["realtime_priority"] for n in nodes),
            "cpu": cpus.pop() if cpus else -1}


def _place(nodes: list[Any]) -> None:
    """Apply the process's priority and CPU once and log it from every node."""
    settings = process_settings(nodes)
    text = place_process(settings, nodes[-1].get_logger())
    for node in nodes:
        node.scheduling = text
        node.get_logger().info(f"composed with {', '.join(n.get_name() for n in nodes)} "
                               f"in one process; {text}")


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_tools loop_node``."""
    camera_names = set(flatten(camera_defaults()))
    controller_names = set(flatten(controller_defaults()))
    return run_nodes([lambda: CameraNode(accepted=controller_names, place=False),
                      lambda: ControllerNode(accepted=camera_names, place=False)],
                     argv, after_start=_place)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
