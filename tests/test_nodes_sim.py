"""The simulator node alone, in its own process; the test plays the controller over DDS.

Assertions are on simulated time (stamps), never on wall-clock speed.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import rosutil
from bfr_ros.node_common import COMMAND_QOS, IMAGE_QOS, JOINT_STATES_QOS, STATE_QOS
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray

from bfr_interfaces.msg import ControllerState, SimTruth

NS = 1_000_000_000


class Controller:
    """Answers each camera frame like the controller node: a command, then a state."""

    def __init__(self, h: rosutil.RosHarness, torque: float = 0.0) -> None:
        n = h.node
        self.torque = torque
        self.answering = True
        self.js: list[JointState] = []
        self.images: list[Image] = []
        self.infos: list[CameraInfo] = []
        self.truth: list[SimTruth] = []
        self.clock: list[int] = []
        self.cmd = n.create_publisher(Float64MultiArray, "effort_controller/commands",
                                      COMMAND_QOS)
        self.state = n.create_publisher(ControllerState, "controller_state", STATE_QOS)
        self.subs = [
            n.create_subscription(JointState, "joint_states", self.js.append, JOINT_STATES_QOS),
            n.create_subscription(Image, "camera/image_raw", self._on_image, IMAGE_QOS),
            n.create_subscription(CameraInfo, "camera/camera_info", self.infos.append,
                                  IMAGE_QOS),
            n.create_subscription(SimTruth, "sim_truth", self.truth.append, STATE_QOS),
            n.create_subscription(
                Clock, "/clock", lambda m: self.clock.append(m.clock.sec * NS + m.clock.nanosec),
                QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)),
        ]

    def _on_image(self, msg: Image) -> None:
        self.images.append(msg)
        if self.answering:
            self.answer(rosutil.stamp_ns(msg), self.torque)

    def answer(self, t_ns: int, torque: float) -> None:
        c = Float64MultiArray()
        c.data = [float(torque)]
        self.cmd.publish(c)
        st = ControllerState()
        st.header.stamp.sec, st.header.stamp.nanosec = t_ns // NS, t_ns % NS
        st.mode = ControllerState.ROLLING
        st.torque = float(torque)
        self.state.publish(st)


def test_simulator_lockstep_contract(ros_harness: rosutil.RosHarness, node_processes) -> None:  # noqa: ANN001
    h = ros_harness
    ctl = Controller(h, torque=0.5)  # beyond the limit: clamped
    sim = node_processes.start("bfr_sim", "simulator_node", ros_args=[
        "-p", "sim.mode:=lockstep", "-p", "sim.duration:=1.5", "-p", "lockstep.timeout:=1.0",
        "-p", "lockstep.resend:=10.0",  # no re-sent frames: the counts below are exact
        "-p", "start.wait_subscribers:=1", "-p", "actuator.torque_limit:=0.05",
        "-p", "initial.phi_dot:=2.0", "-p", "truth.rate:=200"])
    h.wait_for_match(ctl.subs[0], timeout=60)
    h.wait_for_match(ctl.state, timeout=30)
    # answer every frame up to t = 0.8 s, then a NaN command, then go silent (dead controller)
    assert h.spin_until(lambda: ctl.images and rosutil.stamp_ns(ctl.images[-1]) >= 800_000_000,
                        timeout=120), sim.output()[-3000:]
    ctl.answering = False
    t_nan = rosutil.stamp_ns(ctl.images[-1])
    bad = Float64MultiArray()
    bad.data = [math.nan]
    ctl.cmd.publish(bad)
    ctl.answer(t_nan, 0.5)  # the state says 0.5 was sent, so the frame counts as answered
    assert h.wait_exit(sim, 120) == 0
    h.spin_for(0.5)
    out = sim.output()
    # rates in simulated time; exact in the lock-step part (t <= t_nan), where nothing can be
    # lost, since the simulator waits for this test after every frame
    lock = t_nan
    js_t = np.array([rosutil.stamp_ns(m) for m in ctl.js])
    assert np.all(np.diff(js_t) > 0)
    assert js_t[0] == 0 and max(ctl.clock) == 1_500_000_000
    jl = js_t[js_t <= lock]
    assert np.max(np.diff(jl)) <= 2_000_000  # 500 Hz, plus a sample at each frame
    assert jl.size == lock // 10_000_000 * 6 + 1 + (lock % 10_000_000 > 0) * 3
    img_t = np.array([rosutil.stamp_ns(m) for m in ctl.images])
    il = img_t[img_t <= lock]
    assert il.size == lock // 5_000_000 + 1 and set(np.diff(il)) == {5_000_000}
    assert set(img_t) <= set(js_t) | {t for t in img_t if t > lock}  # encoder sampled at frames
    im = ctl.images[0]
    assert (im.encoding, im.width, im.height, im.step, len(im.data)) == ("mono8", 640, 480,
                                                                          640, 640 * 480)
    info_t = {rosutil.stamp_ns(i) for i in ctl.infos}
    assert set(il) <= info_t
    assert ctl.infos[0].k[0] == pytest.approx(600.0) and ctl.infos[0].header.frame_id
    tr_t = np.array([rosutil.stamp_ns(m) for m in ctl.truth])
    tl = tr_t[tr_t <= lock]
    assert tl.size == lock // 5_000_000 + 1 and set(np.diff(tl)) == {5_000_000}
    assert np.all(np.diff(ctl.clock) >= 0)
    # /clock with the frames (200 Hz), not with every encoder sample (clock.rate)
    cl = np.unique(np.array(ctl.clock))
    cl = cl[cl <= lock]
    assert np.all(cl % 5_000_000 == 0) and cl.size >= 0.9 * (lock // 5_000_000 + 1)
    # the actuator: clamped to the -p override, the NaN ignored, then the timeout
    torque = {rosutil.stamp_ns(m): m.torque for m in ctl.truth}
    assert torque[500_000_000] == pytest.approx(0.05)
    assert "ignoring effort command: effort command is not finite" in out
    held = [q for t, q in torque.items() if lock < t <= lock + 90_000_000]
    zero = [q for t, q in torque.items() if t > lock + 110_000_000]
    assert held and np.allclose(held, 0.05)  # the last good command holds ...
    assert zero and np.all(np.array(zero) == 0.0)  # ... until command.timeout (0.1 s)
    assert "no effort command for 0.1 s (simulated): applying zero torque" in out
    assert "lock-step: no answer from the controller" in out  # ... and it kept running
    js_by_t = {rosutil.stamp_ns(m): m for m in ctl.js}
    assert js_by_t[500_000_000].effort[0] == pytest.approx(0.05)
    # the simulator never publishes the hardware command topic
    pubs = h.node.get_publishers_info_by_topic("/effort_controller/commands")
    assert [p.node_name for p in pubs] == [h.node.get_name()]
    assert "simulator finished at t = 1.500 s" in out


def test_simulator_params_file_remap_and_realtime(ros_harness: rosutil.RosHarness,
                                                  node_processes, tmp_path: Path) -> None:  # noqa: ANN001
    h = ros_harness
    params = tmp_path / "sim.yaml"
    params.write_text("/**:\n  ros__parameters:\n    truth:\n      rate: 100.0\n"
                      "    render:\n      publish: false\n    sim:\n      real_time_factor: 2.0\n")
    truth: list[SimTruth] = []
    sub = h.node.create_subscription(SimTruth, "/rig/truth", truth.append, STATE_QOS)
    js = h.node.create_subscription(JointState, "joint_states", lambda m: None,
                                    JOINT_STATES_QOS)
    sim = node_processes.start("bfr_sim", "simulator_node", ros_args=[
        "--params-file", str(params), "-r", "sim_truth:=/rig/truth", "-p", "sim.duration:=4.0",
        "-p", "start.wait_subscribers:=1", "-p", "initial.phi_dot:=2.0"])
    h.wait_for_match(js, timeout=60)
    h.wait_for_match(sub, timeout=30)
    assert h.spin_until(lambda: len(truth) >= 20, timeout=60), sim.output()[-2000:]
    t0, wall0 = rosutil.stamp_ns(truth[-1]), time.monotonic()
    assert h.wait_exit(sim, 60) == 0
    t1, wall1 = rosutil.stamp_ns(truth[-1]), time.monotonic()
    # 100 Hz from the file
    assert set(np.diff([rosutil.stamp_ns(m) for m in truth])) == {10_000_000}
    # realtime pacing: never faster than the requested factor (slower is allowed: load)
    assert (t1 - t0) / NS <= 2.0 * (wall1 - wall0) + 0.3
    assert "camera 200 Hz" in sim.output()


@pytest.mark.parametrize(("args", "message"), [
    (["-p", "sim.mode:=bogus"], "parameter sim.mode: must be one of realtime, lockstep"),
    (["-p", "ball.plate_distance:=1.0"], "ball.plate_distance"),
    (["-p", "ball.mass:=heavy"], "parameter ball.mass: expected a number"),
])
def test_simulator_refuses_bad_parameters(ros_harness: rosutil.RosHarness, node_processes,  # noqa: ANN001
                                          args: list[str], message: str) -> None:
    sim = node_processes.start("bfr_sim", "simulator_node", ros_args=args)
    assert ros_harness.wait_exit(sim, 60) == 2
    assert message in sim.output()
