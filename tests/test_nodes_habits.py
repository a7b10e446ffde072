"""ROS habits of the nodes (issue 17, item 7) and the cheap input paths they rely on.

Start-up-only parameters are read-only (a parameter-set request fails with the reason),
unknown parameters and unreadable parameter files stop a node at start with one FATAL line
(exit status 2, no traceback), log lines name resolved topics, the environment is
localhost-only unless told otherwise; the CDR parsers of joint_states and images agree with
rclpy's deserialisation field by field.
"""

from __future__ import annotations

import contextlib
import os
import random
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import rosutil
from bfr_ros.node_common import (
    JOINT_STATES_POLLED_QOS,
    CdrError,
    PolledSubscription,
    RawImage,
    image_to_array,
    parse_joint_state,
)
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image, JointState

REPO = Path(__file__).resolve().parents[1]


def wait_exit(proc: rosutil.NodeProcess, timeout: float = 60.0) -> int:
    deadline = time.monotonic() + timeout
    while proc.alive and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not proc.alive, proc.output()[-2000:]
    return proc.process.returncode


# -- start-up refusals ------------------------------------------------------------------------
@pytest.mark.parametrize(("package", "exe", "args", "message"), [
    ("bfr_control", "controller_node", ["-p", "loop.trigerr:=joint_states"],
     "unknown parameter for node /controller: loop.trigerr (did you mean loop.trigger?)"),
    ("bfr_camera", "camera_node", ["-p", "detector.n_ray:=32"],
     "unknown parameter for node /camera: detector.n_ray (did you mean detector.n_rays"),
    ("bfr_control", "controller_node", ["-p", "actuator.torque_limit:=1e9"],
     "actuator.torque_limit"),
    ("bfr_camera", "camera_node", ["-p", "process.realtime_priority:=120"],
     "process.realtime_priority: must be an integer 0-98"),
    ("bfr_camera", "camera_node", ["-p", "process.cpu:=4096"],
     "process.cpu: CPU 4096 is not available to this process"),
    # composed: a name neither node knows stops the process; one node's name is accepted
    # by the other (a -p reaches both nodes of a process)
    ("bfr_tools", "loop_node", ["-p", "loop.trigerr:=joint_states",
                                  "-p", "input.frame_timeout:=2.0"],
     "unknown parameter for node /camera: loop.trigerr (did you mean loop.trigger?)"),
])
def test_bad_parameters_stop_the_node_with_one_line(node_processes, package: str, exe: str,  # noqa: ANN001
                                                    args: list[str], message: str) -> None:
    proc = node_processes.start(package, exe, ros_args=args)
    assert wait_exit(proc) == 2
    out = proc.output()
    assert message in out, out
    assert "Traceback" not in out
    fatal = [line for line in out.splitlines() if "[FATAL]" in line]
    assert len(fatal) == 1


def test_unreadable_parameter_file_is_one_fatal_line(node_processes, tmp_path: Path) -> None:  # noqa: ANN001
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    camera:\n      k: [706.4, 0, 327.3]\n")
    proc = node_processes.start("bfr_camera", "camera_node", ros_args=["--params-file",
                                                                        str(bad)])
    assert wait_exit(proc) == 2
    out = proc.output()
    assert "Traceback" not in out and "RCLError" not in out
    fatal = [line for line in out.splitlines() if "[FATAL]" in line]
    assert len(fatal) == 1 and str(bad) in fatal[0]
    assert "Sequence should be of same type" in fatal[0]


def test_startup_parameters_are_read_only(ros_harness: rosutil.RosHarness,
                                          node_processes) -> None:  # noqa: ANN001
    h = ros_harness
    ctl = node_processes.start("bfr_control", "controller_node")
    client = h.node.create_client(SetParameters, "/controller/set_parameters")
    assert client.wait_for_service(timeout_sec=60.0), ctl.output()[-2000:]
    req = SetParameters.Request()
    req.parameters = [Parameter(name="actuator.torque_limit", value=ParameterValue(
        type=ParameterType.PARAMETER_DOUBLE, double_value=0.05))]
    fut = client.call_async(req)
    assert h.spin_until(fut.done, timeout=30.0)
    result = fut.result().results[0]
    assert not result.successful
    assert "read-only" in result.reason and "actuator.torque_limit" in result.reason
    assert ctl.alive


def _thread_scheduling(pid: int) -> set[tuple[int, int]]:
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(ProcessLookupError):
            out.add((os.sched_getscheduler(int(tid)),
                     os.sched_getparam(int(tid)).sched_priority))
    return out


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="no POSIX scheduling API")
def test_nodes_run_at_their_realtime_priority(ros_harness: rosutil.RosHarness,
                                              node_processes) -> None:  # noqa: ANN001
    """Every thread of the controller at process.realtime_priority under SCHED_FIFO (or, where
    this user may not, a warning that says why and the normal scheduler throughout)."""
    ctl = node_processes.start("bfr_control", "controller_node",
                               ros_args=["-p", "process.realtime_priority:=21"])
    cam = node_processes.start("bfr_camera", "camera_node",
                               ros_args=["-p", "process.realtime_priority:=0"])
    assert ros_harness.spin_until(lambda: "mode WAITING" in ctl.output()
                                  and "scheduling:" in cam.output(), timeout=60)
    assert "scheduling: normal (process.realtime_priority 0)" in cam.output()
    assert _thread_scheduling(cam.process.pid) == {(os.SCHED_OTHER, 0)}
    threads = _thread_scheduling(ctl.process.pid)
    if "SCHED_FIFO priority 21 (" in ctl.output():
        assert threads == {(os.SCHED_FIFO, 21)}, threads
    else:
        warn = [line for line in ctl.output().splitlines() if "[WARN]" in line
                and "SCHED_FIFO priority 21 refused" in line]
        assert warn and "ulimit -r" in warn[0], ctl.output()[-2000:]
        assert threads == {(os.SCHED_OTHER, 0)}, threads


def _thread_cpus(pid: int) -> set[tuple[int, ...]]:
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(ProcessLookupError):
            out.add(tuple(sorted(os.sched_getaffinity(int(tid)))))
    return out


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity API")
def test_composed_loop_runs_both_nodes_in_one_pinned_process(
        ros_harness: rosutil.RosHarness, node_processes, tmp_path: Path) -> None:  # noqa: ANN001
    """``loop_node``: the camera and controller nodes in one process, placed once (the higher
    priority, the CPU), each reading its own section of a parameter file."""
    cpu = max(os.sched_getaffinity(0))
    scoped = tmp_path / "loop.yaml"
    scoped.write_text("camera:\n  ros__parameters:\n    process.realtime_priority: 22\n"
                      "controller:\n  ros__parameters:\n    process.realtime_priority: 21\n"
                      f"    process.cpu: {cpu}\n")
    # each -p reaches both nodes: the controller accepts the camera's input.frame_timeout
    # and the camera the controller's loop.trigger
    loop = node_processes.start("bfr_tools", "loop_node",
                                ros_args=["--params-file", str(scoped),
                                          "-p", "loop.trigger:=observation",
                                          "-p", "input.frame_timeout:=2.0"])
    assert ros_harness.spin_until(lambda: loop.output().count("composed with camera, "
                                                              "controller") == 2, timeout=60)
    # discovery is asynchronous: the process may print before the harness has seen its nodes
    both = {"camera", "controller"}
    ros_harness.spin_until(lambda: both <= set(ros_harness.node.get_node_names()), timeout=30)
    names = set(ros_harness.node.get_node_names())
    assert both <= names, names
    out = loop.output()
    assert f"CPU {cpu} only (" in out
    assert _thread_cpus(loop.process.pid) == {(cpu,)}
    if "SCHED_FIFO priority 22 (" in out:  # the higher of the two, for every thread
        assert _thread_scheduling(loop.process.pid) == {(os.SCHED_FIFO, 22)}
    else:
        assert "SCHED_FIFO priority 22 refused" in out, out[-2000:]
    # two CPUs named for one process: refused at start
    other = min(os.sched_getaffinity(0))
    if other != cpu:
        clash = tmp_path / "clash.yaml"
        clash.write_text(f"camera:\n  ros__parameters:\n    process.cpu: {other}\n"
                         f"controller:\n  ros__parameters:\n    process.cpu: {cpu}\n")
        bad = node_processes.start("bfr_tools", "loop_node",
                                   ros_args=["--params-file", str(clash)])
        assert wait_exit(bad) == 2
        assert (f"the nodes of one process name different CPUs (camera {other}, controller "
                f"{cpu})") in bad.output()


def test_log_lines_name_the_resolved_topics(ros_harness: rosutil.RosHarness,
                                            node_processes) -> None:  # noqa: ANN001
    ctl = node_processes.start("bfr_control", "controller_node", ros_args=[
        "-r", "joint_states:=/rig/encoder", "-r", "effort_controller/commands:=/rig/effort"])
    assert ros_harness.spin_until(lambda: "mode WAITING" in ctl.output(), timeout=60)
    assert "/rig/encoder + /ball_observation -> /rig/effort" in ctl.output()


def test_env_is_localhost_only_unless_told() -> None:
    script = REPO / "scripts" / "env.sh"
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_AUTOMATIC")}
    out = subprocess.run(["bash", "-c", f". {script} && echo $ROS_AUTOMATIC_DISCOVERY_RANGE"],
                         env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert out == "LOCALHOST"
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    out = subprocess.run(["bash", "-c", f". {script} && echo $ROS_AUTOMATIC_DISCOVERY_RANGE"],
                         env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert out == "SUBNET"


# -- CDR parsing against rclpy -------------------------------------------------------------------
def test_joint_state_parser_agrees_with_rclpy() -> None:
    rng = random.Random(0)
    for _ in range(300):
        js = JointState()
        js.header.stamp.sec = rng.randrange(0, 2 ** 31)
        js.header.stamp.nanosec = rng.randrange(0, 10 ** 9)
        js.header.frame_id = "f" * rng.randrange(0, 9)
        js.name = ["j" * rng.randrange(1, 13) for _ in range(rng.randrange(0, 4))]
        js.position = [rng.uniform(-9, 9) for _ in range(rng.randrange(0, 4))]
        js.velocity = [rng.uniform(-9, 9) for _ in range(rng.randrange(0, 4))]
        js.effort = [rng.uniform(-9, 9) for _ in range(rng.randrange(0, 4))]
        t, names, pos, vel, eff = parse_joint_state(serialize_message(js))
        assert t == js.header.stamp.sec * 10 ** 9 + js.header.stamp.nanosec
        assert names == list(js.name)
        assert list(pos) == list(js.position) and list(vel) == list(js.velocity)
        assert list(eff) == list(js.effort)
    js.effort = [1.0, 2.0]
    raw = serialize_message(js)
    for cut in (3, 10, len(raw) - 8):
        with pytest.raises(CdrError):
            parse_joint_state(raw[:cut])


def test_image_parser_agrees_with_rclpy() -> None:
    rng = np.random.default_rng(1)
    for enc, dtype, ch in (("mono8", np.uint8, 1), ("mono16", np.uint16, 1),
                           ("bgr8", np.uint8, 3)):
        arr = rng.integers(0, 200, (7, 5, ch) if ch > 1 else (7, 5)).astype(dtype)
        img = Image()
        img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
        img.header.frame_id = "camera_optical_frame"
        img.height, img.width = 7, 5
        img.encoding = enc
        img.step = arr.strides[0]
        img.data = arr.tobytes()
        raw = RawImage(serialize_message(img))
        assert (raw.stamp_ns, raw.frame_id, raw.encoding) == (12 * 10 ** 9 + 345,
                                                              "camera_optical_frame", enc)
        got, err = image_to_array(raw)
        assert err == "" and np.array_equal(got, arr)
    with pytest.raises(CdrError, match="truncated"):
        RawImage(serialize_message(img)[:-4])


# -- messages taken by the node, not by the executor ------------------------------------------
def test_polled_subscription_takes_every_message_the_executor_does_not(
        ros_harness: rosutil.RosHarness) -> None:
    h = ros_harness
    served: list[object] = []
    h.node.create_subscription(JointState, "polled_js", served.append, 100)  # an ordinary one
    polled = PolledSubscription(h.node, JointState, "polled_js", JOINT_STATES_POLLED_QOS)
    assert polled.topic_name == "/polled_js"
    pub = h.node.create_publisher(JointState, "polled_js", 100)
    h.wait_for_match(pub, count=2, timeout=10)
    assert polled.get_publisher_count() == 1
    js = JointState()
    js.name = ["frame_joint"]
    for k in range(50):
        js.header.stamp.nanosec = k + 1
        js.position = [0.01 * k]
        pub.publish(js)
    assert h.spin_until(lambda: len(served) == 50, timeout=10)  # the executor ran meanwhile
    taken = polled.take()
    assert [parse_joint_state(r)[0] for r in taken] == list(range(1, 51))  # all, in order
    assert [parse_joint_state(r)[2][0] for r in taken] == [0.01 * k for k in range(50)]
    assert polled.take() == [] and polled.taken == 50
    polled.destroy()
    polled.destroy()  # idempotent
