"""Launch the bfr rig on a real ROS 2 Jazzy install (``ros2 launch bfr_tools rig.launch.py``).

Emulated rig (default): simulator, camera, controller and, with ``record:=<dir>``, the
recorder, the simulator started once the recorder has matched the camera's and controller's
publishers (as ``bfr rig``); every node but the simulator follows its ``/clock``. The ball
starts on the controller's orbit at contact angle ``phase`` with the frame ``d_theta`` off
it.

    ros2 launch bfr_tools rig.launch.py mode:=realtime record:=/tmp/run1

Real rig (``hardware:=true``): only the camera and controller nodes, against the drivers'
topics (docs/hardware.md): ``image_topic``/``camera_info_topic`` of the camera driver,
ros2_control's ``/joint_states`` and ``/effort_controller/commands``. The recorder (with
``record:=``) gets the same remappings and hardware.yaml's topic list, so it records the
topics the hardware has (no ``sim_truth``) under the names the remappings give them.

The camera and controller nodes run composed in one process (``bfr_tools loop_node``)
pinned to one CPU, the last of the machine (``loop:=separate`` for two processes,
``loop_cpu:=N`` or ``-1``), as ``bfr rig --realtime`` runs them (why, and what it saved:
docs/hardware.md, "Scheduling"); in lock-step they run as two processes, unpinned.

The default mode, ``realtime``, is the real rig's: the simulator paces itself by the wall
clock, the controller predicts through the measured delay from a sample to its torque, and
the ball keeps rolling on a busy 2-core machine (docs/notes/issue-17.md); ``lockstep``
remains for bit-for-bit repeatable runs.

    ros2 launch bfr_tools rig.launch.py hardware:=true camera_params:=my_camera.yaml \
        image_topic:=/cam/image_raw camera_info_topic:=/cam/camera_info

Here, where ``ros2 launch`` is not available, ``scripts/bfr rig`` starts the same nodes.
"""

from __future__ import annotations

from typing import Any

from bfr_camera.camera_node import default_files as camera_files
from bfr_control.controller_node import default_files as controller_files
from bfr_model.param_file import config_path
from bfr_tools.rig import LOOP_NODE, RECORDER_MATCH_TOPICS, loop_layout, orbit_start
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    TimerAction,
)
from launch.event_handlers import OnProcessIO
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _config(package: str, name: str) -> str:
    return str(config_path(package, name))


def _loop(camera: list[Any], controller: list[Any], both: dict[str, Any], composed: bool,
          remaps: list[tuple[str, str]]) -> list[Any]:
    """The camera and controller: one composed process, or two named nodes."""
    if composed:  # each node accepts the other's names (loop_node's docstring)
        # only the files that are not a node's shipped defaults (the nodes load those
        # themselves): camera_node.yaml and controller_node.yaml are /** files, so in one
        # process each would set the other node's values (its process.realtime_priority),
        # and rcl drops a later override of a parameter that two earlier files both set in
        # a nested group (process.cpu stayed -1; docs/notes/issue-17.md)
        shipped = {str(p) for p in [*camera_files(), *controller_files()]}
        files = [f for f in [*camera, *controller] if isinstance(f, str) and f not in shipped]
        return [Node(package=LOOP_NODE[0], executable=LOOP_NODE[1], output="screen",
                     parameters=[*dict.fromkeys(files), both], remappings=remaps)]
    return [Node(package="bfr_camera", executable="camera_node", name="camera",
                 output="screen", parameters=[*camera, both], remappings=remaps),
            Node(package="bfr_control", executable="controller_node", name="controller",
                 output="screen", parameters=[*controller, both])]


def _nodes(context: Any) -> list[Any]:
    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context)

    hardware = arg("hardware").lower() in ("true", "1", "yes")
    record = arg("record")
    rig = _config("bfr_model", "rig.yaml")
    camera = arg("camera_params") or _config("bfr_camera", "camera.yaml")
    camera_node = _config("bfr_camera", "camera_node.yaml")
    controller = _config("bfr_control", "controller.yaml")
    controller_node = _config("bfr_control", "controller_node.yaml")
    nodes = []
    remaps: list[tuple[str, str]] = []
    hw = _config("bfr_control", "hardware.yaml")
    lockstep = not hardware and arg("mode") == "lockstep"
    cpu_arg = arg("loop_cpu")
    if cpu_arg != "auto" and not cpu_arg.lstrip("-").isdigit():
        raise ValueError(f"loop_cpu: expected auto, -1 or a CPU index, got {cpu_arg!r}")
    composed, cpu = loop_layout("lockstep" if lockstep else "realtime", arg("loop"),
                                None if cpu_arg == "auto" else int(cpu_arg))
    if hardware:
        remaps = [("camera/image_raw", arg("image_topic")),
                  ("camera/camera_info", arg("camera_info_topic"))]
        nodes += _loop([camera, rig, camera_node, hw], [rig, controller, controller_node, hw],
                       {"process.cpu": cpu}, composed, remaps)
        sim_time = {"use_sim_time": False}
    else:
        start = orbit_start(float(arg("phase")), float(arg("d_theta")))
        rec = 1 if record else 0
        simulator = Node(
            package="bfr_sim", executable="simulator_node", name="simulator", output="screen",
            parameters=[rig, camera, _config("bfr_sim", "simulator_node.yaml"),
                        {"sim.mode": arg("mode"), "start.wait_subscribers": 2 + rec,
                         "start.wait_info_subscribers": 1 + rec,
                         "start.wait_truth_subscribers": rec,
                         "start.wait_controller": True,
                         "start.wait_observation_subscribers": 1 + rec,
                         "start.settle": 2.0 if rec else 0.5, **start}])
        sim_time = {"use_sim_time": True}
        if lockstep:  # no wall-clock deadline: the normal scheduler
            sim_time["process.realtime_priority"] = 0
        nodes += _loop([camera, rig, camera_node], [rig, controller, controller_node],
                       {**sim_time, "process.cpu": cpu}, composed, [])
    if record:
        recorder = Node(
            package="bfr_sim", executable="recorder_node", name="recorder", output="screen",
            parameters=[_config("bfr_sim", "recorder_node.yaml"), *([hw] if hardware else []),
                        {"recorder.path": record, **sim_time}],
            remappings=remaps)
        nodes.append(recorder)
        if not hardware:
            nodes += _after_recorder_matched(recorder, simulator)
    elif not hardware:
        nodes.append(simulator)
    return nodes


def _after_recorder_matched(recorder: Any, simulator: Any,
                            timeout: float = 30.0) -> list[Any]:
    """Start ``simulator`` once the recorder has matched the loop's publishers.

    As ``bfr rig`` does (:data:`bfr_tools.rig.RECORDER_MATCH_TOPICS`): a reliable, volatile
    subscription gets nothing sent before it matched, and the recorder once missed the
    controller's first 0.125 s. The recorder logs ``matched <topic>: N publisher(s)`` once
    per topic; after ``timeout`` seconds the simulation starts anyway, with a note.
    """
    seen: set[str] = set()
    started: list[bool] = []

    def start_once(why: str = "") -> list[Any]:
        if started:
            return []
        started.append(True)
        return [LogInfo(msg=why)] * bool(why) + [simulator]

    def on_output(event: Any) -> list[Any] | None:
        text = event.text.decode(errors="replace")
        seen.update(t for t in RECORDER_MATCH_TOPICS if f"matched {t}:" in text)
        return start_once() if seen >= set(RECORDER_MATCH_TOPICS) else None

    def on_timeout(_: Any) -> list[Any]:
        return start_once(f"the recorder had not matched {', '.join(RECORDER_MATCH_TOPICS)} "
                          f"within {timeout:g} s; starting the simulation anyway (the bag "
                          f"may miss their start)")

    return [RegisterEventHandler(OnProcessIO(target_action=recorder, on_stdout=on_output,
                                             on_stderr=on_output)),
            TimerAction(period=timeout, actions=[OpaqueFunction(function=on_timeout)])]


def generate_launch_description() -> LaunchDescription:
    """The launch description (arguments: see the module docstring and ``--show-args``)."""
    return LaunchDescription([
        DeclareLaunchArgument("mode", default_value="realtime",
                              description="simulator: realtime or lockstep"),
        DeclareLaunchArgument("hardware", default_value="false",
                              description="true: camera and controller only, real drivers"),
        DeclareLaunchArgument("record", default_value="",
                              description="bag directory to record into ('' = no recorder)"),
        DeclareLaunchArgument("phase", default_value="0.3",
                              description="contact angle on the orbit at t = 0 [rad]"),
        DeclareLaunchArgument("d_theta", default_value="0.05",
                              description="frame angle offset from the orbit at t = 0 [rad]"),
        DeclareLaunchArgument("loop", default_value="auto",
                              description="camera and controller: composed (one process), "
                                          "separate, or auto (composed unless lockstep)"),
        DeclareLaunchArgument("loop_cpu", default_value="auto",
                              description="CPU the camera and controller are pinned to (-1: "
                                          "none; auto: the last CPU unless lockstep)"),
        DeclareLaunchArgument("camera_params", default_value="",
                              description="camera.yaml with the calibration and pose "
                                          "('' = the shipped one)"),
        DeclareLaunchArgument("image_topic", default_value="/camera/image_raw",
                              description="hardware: the camera driver's image topic"),
        DeclareLaunchArgument("camera_info_topic", default_value="/camera/camera_info",
                              description="hardware: the camera driver's camera_info topic"),
        OpaqueFunction(function=_nodes),
    ])
