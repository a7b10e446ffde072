"""Markers for Foxglove and RViz: :class:`bfr_model.scene.MarkerSpec` -> ``visualization_msgs``.

The nodes build what to show with the pure functions of :mod:`bfr_model.scene` and publish it
with :func:`marker_array`; the camera node also annotates its image with
:func:`image_circle`. Conventions of every marker published by bfr:

- ``header.frame_id`` is :data:`WORLD_FRAME` (``world``: origin on the frame's axis, x right,
  y up, z towards the camera, DEVELOPERS.md) for the 3-D markers; no transform is published
  or needed: set the fixed frame (RViz) or display frame (Foxglove 3D panel) to ``world`` -
  the shipped RViz config and Foxglove layout do;
- ``header.stamp`` is the instant shown (simulated time under ``use_sim_time``);
- a marker is replaced by the next one of the same ``ns`` and ``id``; a part that is not
  known at an instant (no ball, no camera fix) is sent as a DELETE of its ``ns``/``id``.

:class:`RateGate` decides which samples to publish at a given rate of their own stamps, so a
marker stream is ``markers.rate`` Hz of simulated time whatever the wall-clock speed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from bfr_model.param_file import nonnegative
from bfr_model.scene import MarkerSpec
from geometry_msgs.msg import Point
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import ImageMarker, Marker, MarkerArray

from bfr_ros.node_common import ns_to_stamp

__all__ = ["MARKER_QOS", "WORLD_FRAME", "MarkerPublisher", "RateGate", "image_circle",
           "marker_array", "marker_message"]

#: The frame of every 3-D marker (the world frame of DEVELOPERS.md).
WORLD_FRAME = "world"
#: Markers: reliable, the latest few (what RViz's and Foxglove's subscriptions match).
MARKER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
_NS = 1_000_000_000
_TYPES = {"sphere": Marker.SPHERE, "cylinder": Marker.CYLINDER,
          "line_strip": Marker.LINE_STRIP, "sphere_list": Marker.SPHERE_LIST,
          "text_view_facing": Marker.TEXT_VIEW_FACING}


_POINTS: dict[int, tuple[Any, list[Point]]] = {}


def _points(arr: Any) -> list[Point]:
    """``geometry_msgs/Point`` objects of an (n, 3) array; read-only arrays converted once.

    The simulator's plate outlines are the same read-only array in every message (their pose
    turns them), so their points are built once and shared.
    """
    if getattr(arr, "flags", None) is None or arr.flags.writeable:
        return [Point(x=float(a), y=float(b), z=float(c)) for a, b, c in arr]
    hit = _POINTS.get(id(arr))
    if hit is None or hit[0] is not arr:
        if len(_POINTS) > 64:
            _POINTS.clear()
        hit = _POINTS[id(arr)] = (arr, [Point(x=float(a), y=float(b), z=float(c))
                                        for a, b, c in arr])
    return hit[1]


def marker_message(spec: MarkerSpec, stamp_ns: int, frame_id: str = WORLD_FRAME) -> Marker:
    """One ``visualization_msgs/Marker`` from a spec, stamped ``stamp_ns`` [ns]."""
    m = Marker()
    ns_to_stamp(stamp_ns, m.header.stamp)
    m.header.frame_id = frame_id
    m.ns = spec.ns
    m.id = int(spec.id)
    if spec.kind == "delete":
        m.action = Marker.DELETE
        return m
    m.type = _TYPES[spec.kind]
    m.action = Marker.ADD
    p, q = m.pose.position, m.pose.orientation
    p.x, p.y, p.z = (float(v) for v in spec.position)
    q.x, q.y, q.z, q.w = (float(v) for v in spec.orientation)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in spec.scale)
    c = m.color
    c.r, c.g, c.b, c.a = (float(v) for v in spec.color)
    if spec.points is not None:
        m.points = _points(spec.points)
    m.text = spec.text
    life_ns = round(spec.lifetime * _NS)
    m.lifetime.sec, m.lifetime.nanosec = life_ns // _NS, life_ns % _NS
    m.frame_locked = False
    return m


def marker_array(specs: Iterable[MarkerSpec], stamp_ns: int,
                 frame_id: str = WORLD_FRAME) -> MarkerArray:
    """A ``visualization_msgs/MarkerArray`` of specs, all stamped ``stamp_ns`` [ns]."""
    return MarkerArray(markers=[marker_message(s, stamp_ns, frame_id) for s in specs])


def image_circle(u: float, v: float, radius_px: float, stamp: Any, frame_id: str,
                 valid: bool, *, ns: str = "ball", color: tuple[float, float, float, float]
                 = (0.1, 0.75, 0.95, 1.0)) -> ImageMarker:
    """A ``visualization_msgs/ImageMarker`` circle round the detected ball [px].

    ``scale`` carries the radius [px] (what Foxglove's Image panel draws as the radius; the
    message's comment calls it a diameter). An invalid detection gives a REMOVE.

    Parameters
    ----------
    u, v : float
        Centre in pixel coordinates [px] (origin at the top-left pixel's centre).
    radius_px : float
        Radius [px].
    stamp : builtin_interfaces/Time
        The image's stamp (annotations are matched to images by stamp).
    frame_id : str
        The image's frame id.
    valid : bool
        Whether the detection is valid.
    """
    m = ImageMarker()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.ns = ns
    m.id = 0
    ok = valid and all(math.isfinite(x) for x in (u, v, radius_px)) and radius_px > 0
    if not ok:
        m.action = ImageMarker.REMOVE
        return m
    m.type = ImageMarker.CIRCLE
    m.action = ImageMarker.ADD
    m.position.x, m.position.y = float(u), float(v)
    m.scale = float(radius_px)
    c = m.outline_color
    c.r, c.g, c.b, c.a = (float(x) for x in color)
    m.filled = 0
    return m


class RateGate:
    """Let samples through at ``rate`` Hz of their own stamps (0: none).

    The n-th sample let through is the first with a stamp at or after ``t_first + n / rate``
    (a sample far behind that schedule restarts it), so over a long run the mean rate is
    ``rate`` whatever the samples' own rate, as long as they come faster.

    Parameters
    ----------
    rate : float
        Rate [Hz], >= 0.
    name : str
        Parameter name for the error message.
    """

    def __init__(self, rate: float, name: str = "markers.rate") -> None:
        nonnegative(name, rate)
        self.rate = float(rate)
        self.period_ns = round(_NS / self.rate) if self.rate > 0 else 0
        self.next_ns: int | None = None

    @property
    def enabled(self) -> bool:
        """Whether any sample passes (rate > 0)."""
        return self.rate > 0

    def due(self, t_ns: int) -> bool:
        """True (and the schedule advances) if the sample stamped ``t_ns`` [ns] is let through."""
        if not self.enabled:
            return False
        if self.next_ns is None or t_ns < self.next_ns - self.period_ns:  # first, or time reset
            self.next_ns = t_ns + self.period_ns
            return True
        if t_ns < self.next_ns:
            return False
        self.next_ns += self.period_ns
        if t_ns >= self.next_ns:  # far behind (a gap): restart from this sample
            self.next_ns = t_ns + self.period_ns
        return True


class MarkerPublisher:
    """A ``MarkerArray`` publisher at ``rate`` Hz of the stamps it is offered (0: none).

    Nothing is created when the rate is 0, so a node with markers off has no such topic.

    Parameters
    ----------
    node : rclpy.node.Node
        The publishing node.
    topic : str
        Relative topic name.
    rate : float
        ``markers.rate`` [Hz] of the samples' stamps (simulated time under use_sim_time).
    frame_id : str
        ``header.frame_id`` of the markers.
    """

    def __init__(self, node: Any, topic: str, rate: float,
                 frame_id: str = WORLD_FRAME) -> None:
        self.gate = RateGate(rate)
        self.frame_id = frame_id
        self.count = 0
        self.pub = (node.create_publisher(MarkerArray, topic, MARKER_QOS)
                    if self.gate.enabled else None)

    def due(self, t_ns: int) -> bool:
        """Whether a sample stamped ``t_ns`` [ns] is to be published (see :class:`RateGate`)."""
        return self.pub is not None and self.gate.due(t_ns)

    def publish(self, specs: Iterable[MarkerSpec], t_ns: int) -> None:
        """Publish the specs as one ``MarkerArray`` stamped ``t_ns`` [ns]."""
        if self.pub is not None:
            self.pub.publish(marker_array(specs, t_ns, self.frame_id))
            self.count += 1
