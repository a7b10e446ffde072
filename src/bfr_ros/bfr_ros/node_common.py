"""Helpers shared by the bfr nodes (simulator, camera, controller, recorder).

Node plumbing only, no physics or vision: parameters mirrored from the packages' YAML files,
the executor, QoS profiles of the topic contract, time-stamp conversion, image conversion
and the standard ``main`` loop with a clean SIGINT/SIGTERM shutdown.

Parameters mirrored from YAML
-----------------------------
Each node declares one ROS parameter per leaf of its shipped parameter files, with the
file's value as the default (nested groups become dotted names: ``ball.mass``,
``camera.k``). So ``--params-file <file>`` and ``-p name:=value`` override exactly the
names of the files, a node started without any file runs with the shipped values, and the
YAML file stays the one source of every value. Parameters accept any type on override
(``-p ball.mass:=1`` is read as 1.0); :func:`read_parameter_tree` casts back to the type of
the default.

The nodes read their parameters once, at start-up: every parameter is declared read-only
(``ros2 param set`` answers "Trying to set a read-only parameter", ``ros2 param describe``
says "read at start-up"), and a name given with ``-p`` or a parameter file that the node
does not know stops it at start with one line naming it (and the nearest known names), so a
misspelt parameter is never silently ignored. An unreadable parameter file or a malformed
``--ros-args`` is a one-line FATAL as well (exit status 2), never a traceback.

A ``-p name:=value`` of the command line is the last word: ROS 2 stores it for every node
(``/**``) and applies a parameter file's section for the node itself (``/**/camera:``, as
hardware.yaml has) over it, so ``--params-file hardware.yaml -p markers.rate:=30.0`` would
keep the file's 0.0 without a word. :func:`declare_parameter_tree` puts the command line's
values back over such a section and says so in one line per parameter
(:func:`command_line_params`; ``-p node:name:=value`` for one node of a composed process).
"""

from __future__ import annotations

import difflib
import gc
import math
import os
import re
import signal
import struct
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from bfr_model.param_file import ParameterError, load_ros_parameters
from bfr_model.turns import TurnUnwrapper
from rcl_interfaces.msg import ParameterDescriptor
from rclpy._rclpy_pybind11 import RCLError
from rclpy.duration import Duration
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.type_support import check_is_valid_msg_type

__all__ = [
    "CLOCK_QOS",
    "COMMAND_QOS",
    "IMAGE_QOS",
    "IMAGE_SUB_QOS",
    "JOINT_STATES_POLLED_QOS",
    "JOINT_STATES_QOS",
    "STATE_PUB_QOS",
    "STATE_QOS",
    "CdrError",
    "Interrupted",
    "JointPicker",
    "PolledSubscription",
    "RawImage",
    "StopFlag",
    "Throttle",
    "check_process",
    "command_line_params",
    "declare_parameter_tree",
    "finite",
    "flatten",
    "flush_publishers",
    "format_published",
    "freeze_heap",
    "image_to_array",
    "init_ros",
    "load_yaml_parameters",
    "make_executor",
    "ns_to_stamp",
    "parse_joint_state",
    "parse_published",
    "pin_threads",
    "place_process",
    "read_parameter_tree",
    "realtime_scheduling",
    "ros_params_files",
    "run_node",
    "run_nodes",
    "section_applies",
    "stamp_to_ns",
    "turn_unwrapper",
    "unapplied_sections",
    "unflatten",
    "wrong_type_publishers",
]

_NS = 1_000_000_000


# -- QoS of the topic contract (README, "Topic contract") -----------------------------------
#: Images and camera_info, publisher side (the emulated camera driver): reliable, keep last
#: 5, as image_transport's default publisher, so that a recorder that asks for reliable
#: delivery gets every frame, while a best-effort subscriber (the camera node) still
#: matches and is never blocked by it.
IMAGE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Images and camera_info, the camera node's subscriptions: sensor data, keep last 1 (the
#: newest image only: a stalled node finds no backlog, it measures the present), best
#: effort (matches reliable and best-effort drivers alike).
IMAGE_SUB_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                           reliability=ReliabilityPolicy.BEST_EFFORT,
                           durability=DurabilityPolicy.VOLATILE)
#: Effort commands (and the simulator's joint_states publisher): reliable.
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
#: Project topics (ball_observation, controller_state, sim_truth): reliable, deeper queue.
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: The simulator's joint_states, camera_info and sim_truth publishers: as STATE_QOS with a
#: deeper history. A reliable reader that missed a sample (a recorder's DDS thread held up
#: on a busy machine) gets it repaired only while the writer still keeps it: keep last 100
#: was 0.17 s of joint_states at 600 Hz, and the recorder lost samples repaired later than
#: that (docs/notes/issue-17.md); 1000 keeps 1-5 s. Only for topics whose control-loop
#: readers are best effort: a reliable reader delivers in order, so a deep history would
#: let one missed sample hold back a controller's fresh ones for longer.
STATE_PUB_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)
#: joint_states subscriptions: best effort, which matches reliable publishers (ros2_control's
#: joint_state_broadcaster, the simulator) and best-effort ones alike.
JOINT_STATES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                              reliability=ReliabilityPolicy.BEST_EFFORT,
                              durability=DurabilityPolicy.VOLATILE)
#: joint_states taken by the node itself (:class:`PolledSubscription`): as JOINT_STATES_QOS,
#: with room for a second of a 1 kHz encoder between two takes.
JOINT_STATES_POLLED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                                     reliability=ReliabilityPolicy.BEST_EFFORT,
                                     durability=DurabilityPolicy.VOLATILE)
#: /clock publisher: reliable (rclpy's and rclcpp's time sources subscribe best effort).
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


# -- parameters mirrored from YAML ---------------------------------------------------------
def load_yaml_parameters(path: str | Path) -> dict[str, Any]:
    """The nested ``ros__parameters`` mapping of a ROS 2 parameter file."""
    return load_ros_parameters(path)


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}`` (lists are leaves)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, name + "."))
        else:
            out[name] = value
    return out


def unflatten(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1}`` -> ``{"a": {"b": 1}}``."""
    out: dict[str, Any] = {}
    for name, value in flat.items():
        node = out
        parts = name.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


#: Parameters every rclpy node has or accepts (rclpy, rcl), besides a node's own.
_ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")

#: What ``ros2 param describe`` shows for a bfr node's parameters.
_STARTUP_ONLY = "read at start-up (read-only): restart the node to change it"


def declare_parameter_tree(node: Any, defaults: Mapping[str, Any],
                           accepted: Iterable[str] = ()) -> None:
    """Declare one read-only parameter per leaf of ``defaults``; refuse unknown overrides.

    Parameters
    ----------
    node : rclpy.node.Node
        The node.
    defaults : mapping
        Nested defaults, e.g. the ``ros__parameters`` of a shipped YAML file.
    accepted : iterable of str
        Further names the node accepts without using them (the other entries of a shared
        parameter file such as rig.yaml, given to several nodes).

    Raises
    ------
    bfr_model.param_file.ParameterError
        If a parameter override (``-p``, ``--params-file``) names a parameter that is
        neither declared nor accepted (the message names it and the nearest known names).
    """
    flat = flatten(defaults)
    _command_line_over_files(node, flat)
    for name, value in flat.items():
        if node.has_parameter(name):
            continue
        node.declare_parameter(name, list(value) if isinstance(value, tuple) else value,
                               ParameterDescriptor(dynamic_typing=True, read_only=True,
                                                   description=_STARTUP_ONLY))
    known = set(flat) | set(accepted) | set(_ROS_PARAMETERS)
    overrides = getattr(node, "_parameter_overrides", {})  # rclpy keeps them there only
    unknown = sorted(n for n in overrides
                     if n not in known and not n.startswith("qos_overrides."))
    if unknown:
        hints = []
        for n in unknown:
            near = difflib.get_close_matches(n, sorted(known), n=2, cutoff=0.6)
            hints.append(f"{n}" + (f" (did you mean {' or '.join(near)}?)" if near else ""))
        raise ParameterError(
            f"unknown parameter{'s' if len(unknown) > 1 else ''} for node "
            f"{node.get_fully_qualified_name()}: {', '.join(hints)}")


#: The ``-p`` assignments of the process's command line, kept by :func:`init_ros`.
_COMMAND_LINE: list[tuple[str, str, str]] = []


def command_line_params(argv: Iterable[str]) -> list[tuple[str, str, str]]:
    """The ``-p`` / ``--param`` assignments of a command line's ``--ros-args`` blocks.

    Returns
    -------
    list of (str, str, str)
        In order, ``(node, name, text)``: the node prefix of ``-p node:name:=value`` ('' for
        every node), the parameter's dotted name and its value as typed.
    """
    out = []
    for flag, value in _ros_args(argv):
        lhs, sep, text = value.partition(":=")
        if flag != "--params-file" and sep:
            node, _, name = lhs.rpartition(":")
            out.append((node, name, text))
    return out


def _command_line_value(text: str) -> Any:
    """A ``-p`` value read as rcl reads it: YAML (``1.0``, ``1``, ``true``, ``[a, b]``)."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return text if value is None or isinstance(value, dict) else value


def _command_line_over_files(node: Any, flat: Mapping[str, Any]) -> None:
    """Put the command line's ``-p`` values over the node's parameter-file sections.

    rclpy keeps the overrides rcl resolved in ``node._parameter_overrides``; where a
    parameter file's section for this node gave a name that ``-p`` gives too, rcl kept the
    file's value. The command line's (the last ``-p`` of the name that reaches this node)
    replaces it before the parameter is declared, and a line says so.
    """
    overrides = getattr(node, "_parameter_overrides", None)
    if overrides is None:
        return
    name, fqn = node.get_name(), node.get_fully_qualified_name()
    given: dict[str, str] = {}
    for prefix, pname, text in _COMMAND_LINE:
        if pname in flat and (not prefix or prefix == name or section_applies(prefix, fqn)):
            given[pname] = text
    for pname, text in given.items():
        old = overrides.get(pname)
        value = _command_line_value(text)
        if old is None or _same(old.value, value):
            continue
        overrides[pname] = Parameter(pname, value=value)
        node.get_logger().info(
            f"-p {pname}:={text} of the command line applied over {old.value!r} of a "
            f"parameter file's section for this node (ROS 2 alone keeps the file's)")


def _same(a: Any, b: Any) -> bool:
    """Whether two parameter values are equal (arrays element by element)."""
    if isinstance(a, (list, tuple)) or hasattr(a, "tolist"):
        a = list(a)
    if isinstance(b, (list, tuple)):
        b = list(b)
    return type(a) is type(b) and a == b


def _cast(name: str, value: Any, default: Any) -> Any:
    """Cast a parameter value to the kind of its default; raise ValueError if impossible."""
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise ValueError(f"parameter {name}: expected a boolean, got {value!r}")
    if isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ValueError(f"parameter {name}: expected a number, got {value!r}")
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"parameter {name}: expected an integer, got {value!r}")
        if float(value) != int(value):
            raise ValueError(f"parameter {name}: expected an integer, got {value!r}")
        return int(value)
    if isinstance(default, str):
        return str(value)
    if isinstance(default, (list, tuple)):
        seq = list(value) if isinstance(value, (list, tuple, np.ndarray)) else [value]
        if default and isinstance(default[0], float):
            return [float(v) for v in seq]
        if default and isinstance(default[0], int) and not isinstance(default[0], bool):
            return [int(v) if float(v) == int(v) else float(v) for v in seq]
        return seq
    return value


def read_parameter_tree(node: Any, defaults: Mapping[str, Any]) -> dict[str, Any]:
    """Current values of the parameters declared by :func:`declare_parameter_tree`.

    Returns
    -------
    dict
        Nested mapping like ``defaults``, each value cast to the type of its default.

    Raises
    ------
    ValueError
        If a value cannot be cast (the message names the parameter).
    """
    flat = {}
    for name, default in flatten(defaults).items():
        value = node.get_parameter(name).value
        flat[name] = _cast(name, value, default)
    return unflatten(flat)


def flush_publishers(node: Any, timeout: float = 3.0) -> list[str]:
    """Wait until every reliable publisher's messages are acknowledged, ``timeout`` s in all.

    A process that exits right after publishing can take its last messages with it (they
    are sent asynchronously); called on shutdown so that a recorder gets all of them. On a
    loaded machine the acknowledgements took longer than the half second this once waited
    per publisher, and a realtime rig's bag lost the simulator's last 35 ms (7 frames,
    docs/notes/issue-17.md). Topics still unacknowledged at the deadline are returned and
    warned about, one line.
    """
    deadline = time.monotonic() + timeout
    late = []
    for pub in list(getattr(node, "publishers", [])):
        if pub.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
            continue
        try:
            left = max(deadline - time.monotonic(), 0.0)
            if not pub.wait_for_all_acked(Duration(seconds=left)):
                late.append(pub.topic_name)
        except Exception:  # noqa: BLE001 - best effort on the way out
            late.append(pub.topic_name)
    if late:
        node.get_logger().warn(f"on exit, not every subscriber had acknowledged the last "
                               f"messages of {', '.join(late)} within {timeout:g} s: a "
                               f"recorder may miss them")
    return late


# -- counts of what a node published (logged on exit, compared with a bag by bfr rig) -------
def format_published(counts: Mapping[str, int]) -> str:
    """``"published: /a 5, /b 6"``: the log line of a node's published message counts."""
    return "published: " + ", ".join(f"{topic} {n}" for topic, n in counts.items())


def parse_published(text: str) -> dict[str, int]:
    """Counts of every ``published: ...`` line in a node's log (the last one per topic)."""
    out: dict[str, int] = {}
    for line in text.splitlines():
        _, sep, rest = line.partition("published: ")
        if not sep:
            continue
        for item in rest.split(", "):
            topic, _, n = item.strip().rpartition(" ")
            if topic.startswith("/") and n.isdigit():
                out[topic] = int(n)
    return out


# -- time ----------------------------------------------------------------------------------
def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def ns_to_stamp(ns: int, stamp: Any) -> Any:
    """Fill a ``builtin_interfaces/Time`` from integer nanoseconds (>= 0); returns it."""
    ns = max(int(ns), 0)
    stamp.sec = ns // _NS
    stamp.nanosec = ns % _NS
    return stamp


# -- images --------------------------------------------------------------------------------
_ENCODINGS = {
    "mono8": (np.uint8, 1), "8uc1": (np.uint8, 1),
    "mono16": (np.uint16, 1), "16uc1": (np.uint16, 1),
    "32fc1": (np.float32, 1),
    "bgr8": (np.uint8, 3), "rgb8": (np.uint8, 3), "8uc3": (np.uint8, 3),
    "bgra8": (np.uint8, 4), "rgba8": (np.uint8, 4),
    # a colour camera's raw mosaic, 8 or 16 bits a photosite (returned as grey, demosaiced)
    **{f"bayer_{p}{b}": (np.uint8 if b == 8 else np.uint16, 1)
       for p in ("rggb", "bggr", "gbrg", "grbg") for b in (8, 16)},
    # 4:2:2 YUV (a USB camera's): two bytes a pixel, returned as its luma (grey)
    "yuv422": (np.uint8, 2), "uyvy": (np.uint8, 2),
    "yuv422_yuy2": (np.uint8, 2), "yuyv": (np.uint8, 2),
}
#: OpenCV's Bayer-to-grey code of each ROS mosaic (cv_bridge's mapping: OpenCV names the
#: pattern from the second row's second pixel, ROS from the first row's first).
_BAYER_TO_GREY = {"rggb": "COLOR_BayerBG2GRAY", "bggr": "COLOR_BayerRG2GRAY",
                  "gbrg": "COLOR_BayerGR2GRAY", "grbg": "COLOR_BayerGB2GRAY"}
#: Where the luma is in each pair of bytes of 4:2:2 YUV (UYVY: second, YUYV: first).
_YUV_LUMA = {"yuv422": 1, "uyvy": 1, "yuv422_yuy2": 0, "yuyv": 0}
_SUPPORTED = ("mono8, mono16, 8UC1, 16UC1, 32FC1, bgr8, rgb8, 8UC3, bgra8, rgba8, "
              "bayer_{rggb,bggr,gbrg,grbg}{8,16}, yuv422 or uyvy, yuv422_yuy2 or yuyv")


def image_to_array(msg: Any) -> tuple[np.ndarray | None, str]:
    """Convert a ``sensor_msgs/Image`` to an array without copying when possible.

    Supported encodings: mono8, mono16, 8UC1, 16UC1, 32FC1, bgr8, rgb8, bgra8, rgba8
    (colour images are returned in BGR(A) order, as OpenCV expects); the Bayer mosaics
    ``bayer_rggb8`` ... ``bayer_grbg16`` (demosaiced by OpenCV straight to grey, copied) and
    4:2:2 YUV ``yuv422`` (UYVY) and ``yuv422_yuy2`` (YUYV) (their luma: grey, a view).

    Returns
    -------
    (ndarray or None, str)
        The image (H, W) or (H, W, C) and an empty string, or None and the reason it
        cannot be used (unsupported encoding, inconsistent size or step).
    """
    enc = str(msg.encoding).lower()
    if enc not in _ENCODINGS:
        return None, f"unsupported image encoding {msg.encoding!r} (supported: {_SUPPORTED})"
    dtype, ch = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).itemsize
    if h <= 0 or w <= 0:
        return None, f"empty image ({w}x{h})"
    if step < w * ch * item:
        return None, f"image step {step} B is smaller than width {w} x {ch * item} B"
    data = msg.data
    if len(data) != step * h:
        return None, (f"image data has {len(data)} B, expected step {step} x height {h} = "
                      f"{step * h} B")
    buf = np.frombuffer(data, dtype=np.uint8).reshape(h, step)[:, : w * ch * item]
    arr = buf.view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<"))
    arr = arr.reshape(h, w, ch) if ch > 1 else arr.reshape(h, w)
    if item > 1 and bool(msg.is_bigendian) != (sys.byteorder == "big"):
        arr = arr.astype(arr.dtype.newbyteorder("="))
    if enc in _YUV_LUMA:
        return arr[:, :, _YUV_LUMA[enc]], ""
    if enc.startswith("bayer_"):
        import cv2  # noqa: PLC0415 - only colour images need it; the other nodes never load it

        code = getattr(cv2, _BAYER_TO_GREY[enc[6:10]])
        return cv2.cvtColor(np.ascontiguousarray(arr), code), ""
    if enc in ("rgb8", "rgba8"):
        import cv2  # noqa: PLC0415 - only colour images need it; the other nodes never load it

        # OpenCV's channel swap: 15 us for 640x480 against 0.2-1 ms for numpy's fancy
        # indexing, which had made an rgb8 camera drop half its frames
        arr = cv2.cvtColor(np.ascontiguousarray(arr), cv2.COLOR_RGB2BGR if ch == 3
                           else cv2.COLOR_RGBA2BGRA)
    return arr, ""


# -- executor and the main loop ------------------------------------------------------------
def make_executor(context: Any = None) -> Any:
    """The events executor of rclpy (Jazzy: ``rclpy.experimental.EventsExecutor``).

    The events executor (a C++ event queue) spends about a third of the CPU time per message
    of the single-threaded executor (measured here: ~60 us against ~200 us per callback).
    """
    return EventsExecutor(context=context)


class PolledSubscription:
    """A subscription no executor serves: the node takes its messages when it needs them.

    For a high-rate input whose samples are needed only at a slower event: the camera node
    needs the 1 kHz encoder samples only when an image arrives, the controller (triggered by
    the camera) when an observation arrives. Served by an executor, every message costs a
    Python callback dispatch (the events executor: ~60 us here, so ~0.06 cores at 1 kHz per
    node); taken here, one C call per message (``take_message``, a few us) at the slower
    event. The DDS reader queues the messages in between (keep last ``qos.depth``): take at
    least every ``depth / rate`` seconds to lose none.

    Created through rcl like any subscription (the node's remapping and namespace apply, it is
    in the graph as a subscription of the node), but not registered in ``node.subscriptions``,
    so no executor waits on it. :meth:`destroy` it before the node (``on_shutdown``).

    Parameters
    ----------
    node : rclpy.node.Node
        The node the subscription belongs to.
    msg_type : type
        Message class (the messages are returned serialized: CDR bytes).
    topic : str
        Topic name (relative names are resolved and remapped as by ``create_subscription``).
    qos : QoSProfile
        Quality of service; its depth bounds what is kept between two takes.
    """

    def __init__(self, node: Any, msg_type: Any, topic: str, qos: QoSProfile) -> None:
        check_is_valid_msg_type(msg_type)  # loads the type support
        with node.handle:
            self.handle = _rclpy.Subscription(node.handle, msg_type, topic,
                                              qos.get_c_qos_profile())
        self.msg_type = msg_type
        self.topic_name: str = self.handle.get_topic_name()
        self.taken = 0

    def take(self) -> list[bytes]:
        """Every message queued since the last take, oldest first (CDR bytes)."""
        out: list[bytes] = []
        h, mt = self.handle, self.msg_type
        while True:
            got = h.take_message(mt, True)
            if got is None:
                self.taken += len(out)
                return out
            out.append(got[0])

    def get_publisher_count(self) -> int:
        """Publishers matched (as :meth:`rclpy.subscription.Subscription.get_publisher_count`)."""
        return int(self.handle.get_publisher_count())

    def destroy(self) -> None:
        """Destroy the rcl subscription (idempotent)."""
        if self.handle is not None:
            self.handle.destroy_when_not_in_use()
            self.handle = None


def realtime_scheduling(priority: int, logger: Any = None,
                        not_now: str = "") -> tuple[bool, str]:
    """Run every thread of this process under ``SCHED_FIFO`` at ``priority`` (0: unchanged).

    A control loop on a general-purpose Linux machine is only as punctual as the scheduler
    lets it be: beside four busy processes the controller node of a real-time run was not
    scheduled for 100 ms at the orbit's fast turn, the drive held a stale torque and the ball
    was lost (docs/notes/issue-17.md). Under ``SCHED_FIFO`` a runnable thread preempts every
    normal (``SCHED_OTHER``) thread, whatever the niceness and the session groups of the
    others; the kernel's real-time throttling (``/proc/sys/kernel/sched_rt_runtime_us``, 95 %
    by default) still leaves the rest of the machine some CPU. This is what ros2_control's
    controller manager does for its update thread (``thread_priority``, default 50).

    Every thread that exists now is switched (the DDS threads made with the node receive and
    hand over the messages the loop waits for); threads started later inherit the policy of
    the thread that starts them. All or nothing: if the first thread is refused, none is
    changed.

    Parameters
    ----------
    priority : int
        ``SCHED_FIFO`` priority 1-98 (higher preempts lower), 0 for the normal scheduler.
    logger : rclpy logger, optional
        Warned once (the description) when the priority is refused.
    not_now : str
        If given, the priority is only checked and the normal scheduler kept, for this
        reason (e.g. a simulator in lock-step: no deadline).

    Returns
    -------
    applied : bool
        True if the threads now run under ``SCHED_FIFO`` at ``priority``.
    description : str
        For the node's start-up log: what was applied, or why not (the missing privilege:
        ``CAP_SYS_NICE`` or a real-time priority limit, ``ulimit -r``).

    Raises
    ------
    ValueError
        If ``priority`` is outside 0-98.
    """
    _check_priority(priority)
    if priority == 0 or not_now:
        return False, f"scheduling: normal ({not_now or 'process.realtime_priority 0'})"
    if not hasattr(os, "sched_setscheduler"):
        return False, "scheduling: normal (SCHED_FIFO is not available on this system)"
    param = os.sched_param(priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, param)  # the calling thread first
    except OSError as exc:
        why = (f"scheduling: normal; SCHED_FIFO priority {priority} refused ({exc.strerror}: "
               f"needs CAP_SYS_NICE or a real-time priority limit, ulimit -r {priority}); "
               f"on a busy machine the loop's timing is not guaranteed")
        if logger is not None:
            logger.warn(why)
        return False, why
    switched = 1 + _each_other_thread(lambda tid: os.sched_setscheduler(tid, os.SCHED_FIFO,
                                                                        param))
    return True, (f"scheduling: SCHED_FIFO priority {priority} ({switched} threads; "
                  f"process.realtime_priority)")


def _each_other_thread(apply: Callable[[int], None]) -> int:
    """Call ``apply(tid)`` for every thread of this process but the calling one.

    Returns the number of threads it was applied to (a thread that ended meanwhile is
    skipped).
    """
    me = threading.get_native_id()
    done = 0
    for tid in sorted(int(t) for t in os.listdir("/proc/self/task")):
        if tid == me:
            continue
        try:
            apply(tid)
            done += 1
        except ProcessLookupError:  # the thread ended meanwhile
            continue
    return done


def _check_priority(priority: Any) -> None:
    """Raise ValueError unless ``priority`` is an integer 0-98."""
    if isinstance(priority, bool) or not isinstance(priority, int) or not 0 <= priority <= 98:
        raise ValueError(f"process.realtime_priority: must be an integer 0-98 (0: the normal "
                         f"scheduler), got {priority!r}")


def _check_cpu(cpu: Any) -> None:
    """Raise ValueError unless ``cpu`` is -1 or a CPU this process may use."""
    if isinstance(cpu, bool) or not isinstance(cpu, int) or cpu < -1:
        raise ValueError(f"process.cpu: must be -1 (any CPU) or a CPU index, got {cpu!r}")
    allowed = sorted(os.sched_getaffinity(0))
    if cpu != -1 and cpu not in allowed:
        raise ValueError(f"process.cpu: CPU {cpu} is not available to this process (it may "
                         f"use {', '.join(map(str, allowed))}; -1: any)")


def check_process(process: Mapping[str, Any]) -> None:
    """Raise ValueError unless ``process`` holds a valid ``realtime_priority`` and ``cpu``."""
    _check_priority(process["realtime_priority"])
    _check_cpu(process["cpu"])


def pin_threads(cpu: int) -> str:
    """Run every thread of this process on CPU ``cpu`` only (-1: leave them where they are).

    A control loop pinned to one CPU keeps its caches and is never moved between CPUs; with
    its threads under ``SCHED_FIFO`` (:func:`realtime_scheduling`) the kernel otherwise
    pushes a preempted real-time thread to another CPU at once (what that cost on the
    development machine: docs/notes/issue-17.md, sixth session). ros2_control's controller
    manager offers the same (``cpu_affinity``). Needs no privilege. Threads started later
    inherit the affinity of the thread that starts them.

    Parameters
    ----------
    cpu : int
        Index of the CPU (as in ``/proc/cpuinfo``), one of those this process may use; -1
        for no pinning.

    Returns
    -------
    str
        For the node's start-up log: the CPU and the number of threads pinned, or "any CPU".

    Raises
    ------
    ValueError
        If ``cpu`` is neither -1 nor a CPU this process may use (the message lists those).
    """
    _check_cpu(cpu)
    if cpu == -1:
        return "any CPU (process.cpu -1)"
    os.sched_setaffinity(0, {cpu})  # the calling thread, then the others
    pinned = 1 + _each_other_thread(lambda tid: os.sched_setaffinity(tid, {cpu}))
    return f"CPU {cpu} only ({pinned} threads; process.cpu)"


def place_process(process: Mapping[str, Any], logger: Any = None, not_now: str = "") -> str:
    """Apply a node's ``process.*`` parameters: real-time priority, then the CPU.

    Parameters
    ----------
    process : mapping
        The node's ``process`` group: ``realtime_priority`` (:func:`realtime_scheduling`)
        and ``cpu`` (:func:`pin_threads`).
    logger : rclpy logger, optional
        Warned once if the priority is refused.
    not_now : str
        If given, the normal scheduler is kept for this reason (:func:`realtime_scheduling`);
        the CPU is still applied.

    Returns
    -------
    str
        One phrase for the node's start-up log.

    Raises
    ------
    ValueError
        If a value is out of range (the message names the parameter).
    """
    check_process(process)  # both values before any change
    _, scheduling = realtime_scheduling(process["realtime_priority"], logger, not_now)
    return f"{scheduling}; {pin_threads(process['cpu'])}"


def freeze_heap() -> None:
    """Collect once, then exempt every object alive now from Python's cyclic collector.

    A node's heap after start-up holds ~140,000 objects (rclpy, numba, numpy, the model); a
    full collection traverses them all and took 0.30-0.37 s here (the controller node,
    measured with ``gc.collect()``). The collector runs one whenever enough objects have
    survived since the last, so a node stalled for a third of a second now and then: the
    controller of a 60 s real-time run under load stopped answering for 0.32 s and the ball
    was lost (docs/notes/issue-17.md). After :func:`gc.freeze` a full collection traverses
    only what the node made since start-up.
    """
    gc.collect()
    gc.freeze()


class Interrupted(BaseException):
    """SIGINT/SIGTERM while the process was still starting (raised by :class:`StopFlag`).

    A ``BaseException``, like ``KeyboardInterrupt``: the ``except Exception`` clauses of the
    code it interrupts (rclpy, numba's compiler) let it through to :func:`run_nodes`.
    """


#: Longest wall time [s] from a signal during the start to the exit. The signal raises
#: :class:`Interrupted`, which normally ends the start at once; where the main thread was
#: inside a callback from C (llvmlite calls Python back while numba compiles: an exception
#: there is printed and ignored) the start would run on to its end (a cold compile: 44 s
#: measured), so after this grace the process exits from another thread.
START_STOP_GRACE = 1.0


class StopFlag:
    """Set by SIGINT/SIGTERM (installed by :func:`init_ros`); nodes poll it.

    While the process starts (``starting``: until :func:`run_nodes` spins) a signal also
    raises :class:`Interrupted` in the main thread, so that a start that takes long (a cold
    numba compile: a minute) stops at once instead of running to its end first; if the
    start has not stopped within :data:`START_STOP_GRACE` the process exits with status 0
    (:mod:`bfr_ros.startup`). Once running, a signal only sets the flag.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal_name = ""
        self.starting = True
        self.stopping = threading.Event()  # set when the shutdown of the nodes begins

    def __bool__(self) -> bool:
        return self.event.is_set()

    def handler(self, signum: int, frame: Any) -> None:
        """Signal handler: remember the signal and set the flag (during the start: raise)."""
        self.signal_name = signal.Signals(signum).name
        self.event.set()
        if self.starting:
            self.starting = False  # once: the shutdown that follows is not interrupted
            threading.Thread(target=self._exit_if_stuck, name="start-stop", daemon=True).start()
            raise Interrupted(self.signal_name)

    def _exit_if_stuck(self) -> None:
        """Exit (status 0) if the interrupted start has not reached the shutdown in time."""
        if not self.stopping.wait(START_STOP_GRACE):
            os.write(2, f"[INFO] {self.signal_name} while starting: exiting\n".encode())
            os._exit(0)

    def install(self) -> None:
        """Handle SIGINT and SIGTERM with :meth:`handler`.

        Also keeps :class:`Interrupted` out of ``sys.unraisablehook``: raised inside a
        callback from C (llvmlite's, while numba compiles) it cannot propagate, and Python
        would print it as "Exception ignored ..." with a traceback.
        """
        signal.signal(signal.SIGINT, self.handler)
        signal.signal(signal.SIGTERM, self.handler)
        default = sys.unraisablehook

        def hook(unraisable: Any) -> None:
            if not isinstance(unraisable.exc_value, Interrupted):
                default(unraisable)

        sys.unraisablehook = hook


def _ros_args(argv: Iterable[str]) -> Iterator[tuple[str, str]]:
    """``(flag, value)`` of the parameter flags of a command line's ``--ros-args`` blocks.

    The flags ``--params-file``, ``-p`` and ``--param``, in order.
    """
    inside, it = False, iter(argv)
    for a in it:
        if a == "--ros-args":
            inside = True
        elif a == "--":
            inside = False
        elif inside and a in ("--params-file", "-p", "--param"):
            yield a, next(it, "")


def ros_params_files(argv: Iterable[str]) -> list[str]:
    """The ``--params-file`` arguments of a command line's ``--ros-args`` blocks, in order."""
    return [v for flag, v in _ros_args(argv) if flag == "--params-file" and v]


def section_applies(key: str, fqn: str) -> bool:
    """Whether a parameter file's node section ``key`` applies to the node ``fqn``.

    rcl's rule: the key is a fully qualified node name (a leading ``/`` may be left out),
    in which ``*`` stands for one name token and ``**`` for any number of them (``/**``:
    every node; ``/**/controller``: a node named controller in any namespace).
    """
    tokens = [t for t in key.strip().split("/") if t]
    pattern = "".join("(/[^/]+)*" if t == "**" else "/[^/]+" if t == "*" else "/" + re.escape(t)
                      for t in tokens)
    return re.fullmatch(pattern, fqn) is not None


def _sections(doc: Mapping, prefix: str = "") -> Iterator[str]:
    """Node names of a parameter file's sections: its keys down to ``ros__parameters``.

    rcl reads both ``/rig1/controller: {ros__parameters: ...}`` and the nested form
    ``/rig1: {controller: {ros__parameters: ...}}``.
    """
    for key, body in doc.items():
        if not isinstance(key, str) or not isinstance(body, Mapping):
            continue
        name = "/" + "/".join(t for t in (prefix.strip("/"), key.strip("/")) if t)
        if "ros__parameters" in body:
            yield name
        else:
            yield from _sections(body, name)


def unapplied_sections(argv: Iterable[str], name: str, fqn: str) -> list[str]:
    """Bare sections of the command line's parameter files for this node, not applied.

    A section named by the node's own ``name`` alone (``controller:`` or ``/controller:``)
    reaches ``/controller`` only: for a node in a namespace (``-r __ns:=/rig1``) ROS 2 skips
    it without a word. One line per such section, saying what to write instead. A section
    that names a namespace (``/rig2/controller:``, another rig's in a shared file) is taken
    as meant for that namespace and not reported.
    """
    out = []
    for f in ros_params_files(argv):
        try:
            doc = yaml.safe_load(Path(f).read_text())
        except (OSError, yaml.YAMLError):
            continue  # rcl read it (or refused it) already
        if not isinstance(doc, Mapping):
            continue
        for section in _sections(doc):
            if section == "/" + name and not section_applies(section, fqn):
                out.append(f"parameter file {f}: its section '{name}' is for /{name}, not "
                           f"this node ({fqn}), and was not applied; write '/**/{name}:' "
                           f"for a node of that name in any namespace")
    return out


def init_ros(argv: list[str] | None, stop: StopFlag | None = None) -> StopFlag:
    """``rclpy.init`` without rclpy's own signal handlers, and ours for SIGINT/SIGTERM.

    rclpy's handlers shut the context down at once, so a node could not publish a last
    zero torque or close its bag; ours set a flag that the node's loop polls (and, while
    the process starts, raise :class:`Interrupted`). They are installed before
    ``rclpy.init``: no moment is left to Python's ``KeyboardInterrupt``.

    Parameters
    ----------
    argv : list of str or None
        Command line, ROS arguments included.
    stop : StopFlag, optional
        The flag to install (a new one when omitted).

    Raises
    ------
    bfr_model.param_file.ParameterError
        If rcl cannot parse the command line's ROS arguments or a parameter file (the
        message is rcl's first line, e.g. the file's YAML error).
    Interrupted
        If a signal came during ``rclpy.init``.
    """
    stop = stop if stop is not None else StopFlag()
    stop.install()
    _COMMAND_LINE[:] = command_line_params(sys.argv if argv is None else argv)
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        files = ros_params_files(argv or [])
        where = f" (parameter file{'s' if len(files) > 1 else ''} {', '.join(files)})" \
            if files else ""
        raise ParameterError(f"invalid ROS arguments{where}: {first}") from None
    return stop


def run_node(node_factory: Callable[[], Any], argv: list[str] | None = None,
             poll: float = 0.1) -> int:
    """The standard ``main`` of a bfr node: init, create, spin until SIGINT, shut down.

    The node may define ``run(stop) -> int`` (its own loop, e.g. the simulator) and
    ``on_shutdown()`` (called before the context goes down: publish a last command, close a
    bag, print counts).

    Parameters
    ----------
    node_factory : callable
        Creates the node (after ``rclpy.init``); it may raise to refuse to start, with a
        clear message (printed; exit status 2).
    argv : list of str, optional
        Command line (``sys.argv`` when omitted), ROS arguments included.
    poll : float
        Longest time between checks of the stop flag [s].

    Returns
    -------
    int
        Exit status.
    """
    return run_nodes([node_factory], argv, poll)


def run_nodes(node_factories: Iterable[Callable[[], Any]], argv: list[str] | None = None,
              poll: float = 0.1, after_start: Callable[[list[Any]], None] | None = None) -> int:
    """:func:`run_node` for one node or several composed in one process (one executor).

    Nodes composed in one process share one DDS participant, one receive thread and one
    executor thread: a message between them does not cross processes, and an encoder sample
    both take is received once (docs/notes/issue-17.md, sixth session). Every ``-p``
    override of the command line reaches every node of the process (rcl's rule); a parameter
    file's section for a node (``/**/<node name>:``, or the node's full name) reaches that
    node only, and a bare ``<node name>:`` section the namespace kept from its node is named
    at start (:func:`unapplied_sections`).

    Parameters
    ----------
    node_factories : iterable of callable
        Create the nodes in this order; if one refuses to start, those made are destroyed.
        Only a process of one node may use a node's own ``run(stop)`` loop.
    argv : list of str, optional
        Command line (``sys.argv`` when omitted), ROS arguments included.
    poll : float
        Longest time between checks of the stop flag [s].
    after_start : callable, optional
        Called with the nodes once all exist, before the executor spins (e.g. to place the
        process's threads); may raise ValueError/OSError/RuntimeError to refuse to start.

    Returns
    -------
    int
        Exit status.
    """
    args = list(sys.argv if argv is None else argv)
    stop = StopFlag()
    try:
        init_ros(args, stop)
    except ParameterError as exc:
        print(f"[FATAL] cannot start: {exc}", file=sys.stderr, flush=True)
        return 2
    except Interrupted:  # a signal during rclpy.init: nothing made yet
        stop.stopping.set()
        if rclpy.ok():
            rclpy.shutdown()
        return 0
    status = 0
    nodes: list[Any] = []
    try:
        try:
            for factory in node_factories:
                nodes.append(factory())
            for node in nodes:
                for line in unapplied_sections(args, node.get_name(),
                                               node.get_fully_qualified_name()):
                    node.get_logger().warn(line)
            if after_start is not None:
                after_start(nodes)
        except Exception as exc:
            if stop:  # the signal's consequence where Interrupted cannot pass: inside numba's
                # dispatcher a SystemError ("returned a result with an exception set"), in
                # llvmlite's callback a RuntimeError ("no compiled object yet")
                raise Interrupted(stop.signal_name) from None
            if not isinstance(exc, (ValueError, OSError, RuntimeError)):
                raise
            print(f"[FATAL] cannot start: {exc}", file=sys.stderr, flush=True)
            for node in reversed(nodes):
                node.destroy_node()
            nodes = []
            return 2
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
            node.executor_ref = executor
        freeze_heap()
        stop.starting = False  # from here a signal sets the flag that the loop polls
        if stop:
            pass  # the signal came as the start ended: straight to the shutdown
        elif len(nodes) == 1 and hasattr(nodes[0], "run"):
            status = int(nodes[0].run(stop) or 0)
        else:
            while not stop and rclpy.ok():
                executor.spin_once(timeout_sec=poll)
    except Interrupted:  # stopped while starting: the nodes made so far are shut down below
        stop.starting = False
    except KeyboardInterrupt:  # pragma: no cover - a second Ctrl-C
        pass
    finally:
        stop.starting = False
        stop.stopping.set()
        for node in reversed(nodes):  # each node shut down even if another's shutdown fails
            if stop:
                node.get_logger().info(f"{stop.signal_name}: shutting down")
            try:
                if hasattr(node, "on_shutdown"):
                    node.on_shutdown()
                flush_publishers(node)
            except Exception as exc:  # noqa: BLE001 - the others must still shut down
                node.get_logger().error(f"shutdown failed: {type(exc).__name__}: {exc}")
                status = status or 1
            finally:
                node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status


def finite(*values: float) -> bool:
    """True iff every value is a finite float."""
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


# -- cheap input paths: CDR parsing of the high-rate messages, throttled logging ------------
class Throttle:
    """At most one event per ``period`` seconds per key (monotonic clock).

    rclpy's ``throttle_duration_sec`` inspects the caller's frame on *every* call, throttled
    or not (about 0.3 ms here); a node that may log at its input rate checks this first.
    """

    def __init__(self) -> None:
        self._last: dict[str, float] = {}

    def __call__(self, key: str, period: float) -> bool:
        """True if ``key`` may log now (and remember that it did)."""
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) < period:
            return False
        self._last[key] = now
        return True


_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


class CdrError(ValueError):
    """A serialized message is truncated or malformed."""


def _cdr_string(data: bytes | memoryview, pos: int) -> tuple[str, int]:
    """A CDR string at ``pos`` (4-aligned, relative to the payload at byte 4)."""
    pos += -(pos - 4) % 4
    if pos + 4 > len(data):
        raise CdrError("truncated string length")
    (n,) = _U32.unpack_from(data, pos)
    end = pos + 4 + n
    if n == 0 or end > len(data):
        raise CdrError("bad string")
    return bytes(data[pos + 4:end - 1]).decode("utf-8", "replace"), end


def _cdr_doubles(data: bytes | memoryview, pos: int) -> tuple[tuple[float, ...], int]:
    """A CDR ``sequence<double>`` at ``pos``."""
    pos += -(pos - 4) % 4
    if pos + 4 > len(data):
        raise CdrError("truncated sequence length")
    (n,) = _U32.unpack_from(data, pos)
    pos += 4
    if n == 0:
        return (), pos
    pos += -(pos - 4) % 8
    end = pos + 8 * n
    if end > len(data):
        raise CdrError("truncated sequence of doubles")
    return struct.unpack_from(f"<{n}d", data, pos), end


def _cdr_header(data: bytes | memoryview) -> tuple[int, str, int]:
    """(stamp [ns], frame_id, position after the header) of a little-endian CDR message."""
    if len(data) < 16 or data[0] != 0 or data[1] != 1:
        raise CdrError("not a little-endian CDR message")
    sec, nsec = _STAMP.unpack_from(data, 4)
    frame_id, pos = _cdr_string(data, 12)
    return sec * _NS + nsec, frame_id, pos


def turn_unwrapper(node: Any, topic: str) -> TurnUnwrapper:
    """A :class:`bfr_model.turns.TurnUnwrapper` for ``node``'s encoder on ``topic``.

    The contract's theta accumulates over turns (docs/hardware.md); a driver that reports it
    within a turn is unwrapped, and the node says so once, at the first wrap.
    """
    def said() -> None:
        node.get_logger().warn(f"{topic}: the frame angle wraps at a turn (the contract, "
                               f"docs/hardware.md: it accumulates); unwrapped here")

    return TurnUnwrapper(on_first_wrap=said)


class JointPicker:
    """Which entry of a ``joint_states`` message is the frame's joint; what came without it.

    The entry named ``name``; a message without names and with one position is taken as
    that joint's. Messages of other joints only (a driver that publishes each joint apart)
    are left out and counted, with the names of the last one, so that a node waiting for
    its joint can say why (a joint named otherwise than ``name``).
    """

    __slots__ = ("name", "names_seen", "others", "parameter")

    def __init__(self, name: str, parameter: str = "joint_name") -> None:
        self.name = name
        self.parameter = parameter           # the node's parameter that names the joint
        self.others = 0                      # messages without the joint
        self.names_seen: tuple[str, ...] = ()  # the names of the last of them

    def index(self, names: list[str], position: tuple[float, ...]) -> int | None:
        """The joint's index in the message; None for a message without it (counted)."""
        if self.name in names:
            return names.index(self.name)
        if not names and len(position) == 1:
            return 0
        self.others += 1
        self.names_seen = tuple(names)
        return None

    def missing(self) -> str:
        """Why no sample of the joint came although messages did ('' if none came)."""
        if not self.others:
            return ""
        return (f"{self.others} message(s) arrived without joint {self.name!r} (names "
                f"{list(self.names_seen)}): is the frame's joint named otherwise? (parameter "
                f"{self.parameter})")


def wrong_type_publishers(node: Any, topic: str, expected: str) -> str:
    """What publishes ``topic`` with another type than ``expected``; '' if nothing does.

    A driver that publishes the topic with another type (``std_msgs/msg/Float64MultiArray``
    on ``/joint_states``) never matches the node's subscription, and the node would only
    see that nothing came; the graph says why. ``expected`` as ROS writes it,
    ``sensor_msgs/msg/JointState``.
    """
    infos = [i for i in node.get_publishers_info_by_topic(topic) if i.topic_type != expected]
    if not infos:
        return ""
    types = ", ".join(sorted({i.topic_type for i in infos}))
    return (f"{topic} is published as {types} by {len(infos)} publisher(s), not {expected}: "
            f"nothing of it can be read")


def parse_joint_state(data: bytes | memoryview) -> tuple[int, list[str], tuple[float, ...],
                                                        tuple[float, ...], tuple[float, ...]]:
    """Fields of a serialized ``sensor_msgs/JointState`` without building the message.

    About 10 us against rclpy's 50 us for the Python message: the nodes take the encoder at
    1 kHz. Tested field by field against rclpy's deserialisation (tests/test_nodes_unit.py).

    Returns
    -------
    tuple
        ``(stamp_ns, names, position, velocity, effort)``.

    Raises
    ------
    CdrError
        If the bytes are not a complete little-endian CDR JointState.
    """
    t_ns, _, pos = _cdr_header(data)
    pos += -(pos - 4) % 4
    if pos + 4 > len(data):
        raise CdrError("truncated name sequence")
    (n,) = _U32.unpack_from(data, pos)
    pos += 4
    if n > 10000:
        raise CdrError(f"implausible number of joint names ({n})")
    names = []
    for _ in range(n):
        name, pos = _cdr_string(data, pos)
        names.append(name)
    position, pos = _cdr_doubles(data, pos)
    velocity, pos = _cdr_doubles(data, pos)
    effort, pos = _cdr_doubles(data, pos)
    return t_ns, names, position, velocity, effort


class RawImage:
    """The fields of a serialized ``sensor_msgs/Image`` (no copy of the pixels).

    Has the attributes :func:`image_to_array` reads (``height``, ``width``, ``encoding``,
    ``is_bigendian``, ``step``, ``data``, a memoryview into the serialized bytes) plus
    ``stamp_ns`` and ``frame_id``.

    Raises
    ------
    CdrError
        If the bytes are not a complete little-endian CDR Image.
    """

    __slots__ = ("data", "encoding", "frame_id", "height", "is_bigendian", "stamp_ns", "step",
                 "width")

    def __init__(self, raw: bytes) -> None:
        self.stamp_ns, self.frame_id, pos = _cdr_header(raw)
        pos += -(pos - 4) % 4
        if pos + 8 > len(raw):
            raise CdrError("truncated image size")
        self.height, self.width = struct.unpack_from("<II", raw, pos)
        self.encoding, pos = _cdr_string(raw, pos + 8)
        if pos + 1 > len(raw):
            raise CdrError("truncated image")
        self.is_bigendian = raw[pos]
        pos += 1
        pos += -(pos - 4) % 4
        if pos + 8 > len(raw):
            raise CdrError("truncated image step")
        self.step, n = struct.unpack_from("<II", raw, pos)
        pos += 8
        if pos + n > len(raw):
            raise CdrError(f"image data truncated: {len(raw) - pos} of {n} B")
        self.data = memoryview(raw)[pos:pos + n]
