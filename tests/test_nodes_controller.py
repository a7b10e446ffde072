"""The controller node alone, in its own process; the test plays the rig (plant + camera).

The test steps the rigid model (bfr_model.dynamics) itself and publishes ``/clock``,
``joint_states`` and ``ball_observation`` like the simulator and camera nodes, in lock-step
with the node (after each camera frame it waits for the node's answer). Then it feeds bad
input: a missing ball, NaN encoder samples, stale stamps, a dead encoder, and checks the
mode, the zero torque and the log.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import rosutil
from bfr_model.dynamics import RigidModel
from bfr_model.param_file import config_path
from bfr_model.params import load_params
from bfr_ros.node_common import COMMAND_QOS, STATE_QOS, wrong_type_publishers
from bfr_tools.rig import orbit_start
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from bfr_interfaces.msg import BallObservation, ControllerState

NS = 1_000_000_000
MS = 1_000_000
WAITING, ROLLING, BALL_LOST, FAULT = (ControllerState.WAITING, ControllerState.ROLLING,
                                      ControllerState.BALL_LOST, ControllerState.FAULT)


class Rig:
    """Plant, encoder and camera of the test, in lock-step with the controller node."""

    def __init__(self, h: rosutil.RosHarness, x0: list[float] | None = None,
                 t0_ns: int = 0) -> None:
        self.h = h
        self.model = RigidModel(load_params())
        self.x = np.zeros(6)
        if x0 is not None:
            self.x[:4] = x0
        self.t_ns = t0_ns
        self.u = 0.0
        self.rng = np.random.default_rng(3)
        n = h.node
        self.clock_pub = n.create_publisher(Clock, "/clock", 10)
        self.js_pub = n.create_publisher(JointState, "joint_states", 50)
        self.obs_pub = n.create_publisher(BallObservation, "ball_observation", STATE_QOS)
        self.cmds: list[float] = []
        self.states: list[ControllerState] = []
        self.cmd_sub = n.create_subscription(Float64MultiArray, "effort_controller/commands",
                                             lambda m: self.cmds.append(m.data[0]), COMMAND_QOS)
        self.state_sub = n.create_subscription(ControllerState, "controller_state",
                                               self.states.append, STATE_QOS)
        self.truth: list[tuple[int, float, float]] = []  # t, phi, phi_dot

    def wait_for_node(self, proc: rosutil.NodeProcess) -> None:
        for e in (self.js_pub, self.obs_pub, self.clock_pub):
            self.h.wait_for_match(e, timeout=60)
        self.h.wait_for_match(self.state_sub, timeout=60)
        self.h.spin_for(1.0)  # let the node's side of the discovery finish too
        assert proc.alive, proc.output()

    def clock(self, t_ns: int) -> None:
        m = Clock()
        m.clock.sec, m.clock.nanosec = t_ns // NS, t_ns % NS
        self.clock_pub.publish(m)

    def joint_state(self, t_ns: int | None = None, theta: float | None = None,
                    theta_dot: float | None = None) -> None:
        t_ns = self.t_ns if t_ns is None else t_ns
        m = JointState()
        m.header.stamp.sec, m.header.stamp.nanosec = t_ns // NS, t_ns % NS
        m.name = ["frame_joint"]
        m.position = [float(self.x[0]) if theta is None else theta]
        m.velocity = [float(self.x[2]) if theta_dot is None else theta_dot]
        m.effort = [self.u]
        self.js_pub.publish(m)

    def observation(self, valid: bool = True) -> None:
        m = BallObservation()
        m.header.stamp.sec, m.header.stamp.nanosec = self.t_ns // NS, self.t_ns % NS
        m.header.frame_id = "world"
        if valid:
            bx, by = self.model.ball_position(self.x[:4]) + 1e-4 * self.rng.standard_normal(2)
            m.status, m.valid, m.confidence = BallObservation.FOUND, True, 0.9
            m.x, m.y = float(bx), float(by)
            m.phi = float(self.x[0] + math.atan2(bx, by))
            m.theta_used = float(self.x[0])
        else:
            m.status, m.valid = BallObservation.NOT_FOUND, False
            m.x = m.y = m.phi = m.theta_used = math.nan
        m.u = m.v = m.radius_px = math.nan
        self.obs_pub.publish(m)

    def answered(self) -> bool:
        return bool(self.states) and rosutil.stamp_ns(self.states[-1]) >= self.t_ns and \
            bool(self.cmds) and self.cmds[-1] == self.states[-1].torque

    def frame(self, proc: rosutil.NodeProcess, valid: bool = True, steps: int = 5) -> None:
        """Advance one camera period (encoder at 1 kHz), show a frame, wait for the answer."""
        for _ in range(steps):
            self.x = self.model.step(self.x, self.u, 1e-3, 1)
            self.t_ns += MS
            self.clock(self.t_ns)
            self.joint_state()
        self.truth.append((self.t_ns, float(self.x[1]), float(self.x[3])))
        self.observation(valid)
        assert self.h.spin_until(self.answered, timeout=20.0), proc.output()[-3000:]
        self.u = self.cmds[-1]

    def modes_since(self, t_ns: int) -> list[int]:
        return [s.mode for s in self.states if rosutil.stamp_ns(s) > t_ns]


def test_controller_node_keeps_the_ball_rolling_and_stops_safely(
        ros_harness: rosutil.RosHarness, node_processes) -> None:  # noqa: ANN001
    h = ros_harness
    start = orbit_start(0.3, 0.05)
    rig = Rig(h, [start[f"initial.{k}"] for k in ("theta", "phi", "theta_dot", "phi_dot")])
    ctl = node_processes.start("bfr_control", "controller_node",
                               ros_args=["-p", "use_sim_time:=true"])
    rig.wait_for_node(ctl)
    for _ in range(30):  # the first exchange, until the node's side of discovery is done
        rig.clock(0)
        rig.joint_state()
        rig.observation()
        if h.spin_until(rig.answered, timeout=1.0):
            break
    assert rig.answered(), ctl.output()[-3000:]
    for _ in range(800):  # 4 s of closed loop over DDS
        rig.frame(ctl)
    truth = np.array(rig.truth)
    assert np.all(truth[:, 2] > 0.5), "the ball stopped"
    mean_pd = (truth[-1, 1] - truth[0, 1]) / ((truth[-1, 0] - truth[0, 0]) / NS)
    assert 2.2 < mean_pd < 2.6
    assert rig.states[-1].mode == ROLLING and "ROLLING at t = " in ctl.output()
    assert max(abs(c) for c in rig.cmds) <= 0.1 + 1e-12
    tail = [s for s in rig.states if rosutil.stamp_ns(s) > 2 * NS]
    assert np.sqrt(np.mean([s.y ** 2 for s in tail])) < 0.02  # on the constraint
    assert all(0.0 <= s.ball_age < 0.006 for s in tail)
    s = rig.states[-1]
    assert s.phase == rig.states[-1].phi % math.pi and math.isfinite(s.z)

    # the ball disappears: BALL_LOST after supervisor.lost_timeout (0.25 s), zero torque ...
    t_lost = rig.t_ns
    for _ in range(60):
        rig.frame(ctl, valid=False)
    assert BALL_LOST in rig.modes_since(t_lost)
    assert rig.states[-1].mode == BALL_LOST and rig.states[-1].torque == 0.0
    assert rig.cmds[-1] == 0.0
    # ... latched: the ball is back (in the camera), the torque stays zero
    for _ in range(10):
        rig.frame(ctl)
    assert rig.states[-1].mode == BALL_LOST and rig.cmds[-1] == 0.0
    assert "BALL_LOST at t = " in ctl.output() and "no valid ball fix" in ctl.output()
    # ... also through an encoder fault: FAULT, and when good samples come back (the ball in
    # view) BALL_LOST again, never WAITING or ROLLING (a stand-in's 0.3 s encoder gap once
    # re-armed the motor without anybody asking)
    t_bad = rig.t_ns + MS
    rig.clock(t_bad)
    rig.joint_state(t_bad, theta=math.nan)
    assert h.spin_until(lambda: rig.states[-1].mode == FAULT, timeout=10.0), ctl.output()[-2000:]
    rig.t_ns = t_bad
    for _ in range(20):
        rig.frame(ctl)
    assert set(rig.modes_since(t_bad - 1)) == {FAULT, BALL_LOST}, rig.modes_since(t_bad - 1)
    assert rig.states[-1].torque == 0.0 and rig.cmds[-1] == 0.0
    assert "the controller stays BALL_LOST (latched" in ctl.output()
    # ~/reset re-arms it
    client = h.node.create_client(Trigger, "/controller/reset")
    assert client.wait_for_service(timeout_sec=10.0)
    fut = client.call_async(Trigger.Request())
    assert h.spin_until(fut.done, timeout=10.0) and fut.result().success
    t_reset = rig.t_ns
    rig.frame(ctl)
    assert rig.modes_since(t_reset)[0] == WAITING

    # a NaN encoder sample: FAULT, zero torque; good samples again: WAITING
    t_nan = rig.t_ns + MS
    rig.clock(t_nan)
    rig.joint_state(t_nan, theta=math.nan)
    assert h.spin_until(lambda: rig.states[-1].mode == FAULT, timeout=10.0), ctl.output()[-2000:]
    assert rig.states[-1].torque == 0.0 and rig.cmds[-1] == 0.0
    # stamped with the sample it derives from (the measurement's time), with its values
    fault = rig.states[-1]
    assert rosutil.stamp_ns(fault) == t_nan
    assert math.isnan(fault.theta) and fault.theta_dot == float(rig.x[2])
    rig.t_ns = t_nan
    for _ in range(4):
        rig.frame(ctl)
    assert rig.states[-1].mode in (WAITING, ROLLING, BALL_LOST)
    out = ctl.output()
    assert "FAULT: non-finite joint_states sample" in out
    assert "controller restarts in WAITING" in out
    assert ctl.alive


def test_controller_node_names_the_joints_that_came_instead_of_its_own(
        ros_harness: rosutil.RosHarness, node_processes) -> None:  # noqa: ANN001
    """A driver whose frame joint is named otherwise: no step, no torque, and the warning
    says which joints arrived (it had said only "no joint_states received yet")."""
    h = ros_harness
    ctl = node_processes.start("bfr_control", "controller_node")
    pub = h.node.create_publisher(JointState, "joint_states", 50)
    h.wait_for_match(pub, timeout=60)
    m = JointState()
    m.name, m.position, m.velocity = ["joint1"], [1.0], [0.0]

    def warned() -> bool:
        m.header.stamp = h.node.get_clock().now().to_msg()
        pub.publish(m)
        return "arrived without joint 'frame_joint' (names ['joint1'])" in ctl.output()

    assert h.spin_until(warned, timeout=40.0), ctl.output()[-2000:]
    assert "no joint_states received yet on /joint_states" in ctl.output()
    assert "is arriving" not in ctl.output() and ctl.alive


def test_controller_node_stale_and_dead_encoder(ros_harness: rosutil.RosHarness,
                                                node_processes) -> None:  # noqa: ANN001
    h = ros_harness
    rig = Rig(h, [0.0, 0.0, 0.0, 2.0], t0_ns=10 * NS)
    ctl = node_processes.start("bfr_control", "controller_node", ros_args=[
        "-p", "use_sim_time:=true", "-p", "safety.watchdog_timeout:=0.5",
        "-p", "safety.max_stamp_age:=2.0", "-p", "loop.trigger:=joint_states"])
    rig.wait_for_node(ctl)
    # the start-up backlog: samples the subscription queued while the node set up arrive
    # stamped up to the queue's length ago; before any good one they are dropped, not a FAULT
    for _ in range(5):  # the clock reaches the node
        rig.t_ns += MS
        rig.clock(rig.t_ns)
        h.spin_for(0.05)
    for k in range(3):
        rig.joint_state(rig.t_ns - 3 * NS + k * MS, theta=0.1)
    # a good sample, then one stamped 2 s behind the clock
    for _ in range(20):
        rig.t_ns += MS
        rig.clock(rig.t_ns)
        rig.joint_state()
        if h.spin_until(lambda: bool(rig.states), timeout=1.0):
            break
    assert rig.states, ctl.output()[-2000:]
    assert rig.states[-1].mode == WAITING and rig.cmds[-1] == 0.0
    assert not any(st.mode == FAULT for st in rig.states), ctl.output()[-2000:]
    assert ("/joint_states is arriving (the first 3 sample(s), queued while the node set up, "
            "dropped: stamped over safety.max_stamp_age ago)") in ctl.output(), ctl.output()
    # a backlog sample behind a good one (the node drains its queue while the samples' age
    # hovers about max_stamp_age: a probe saw FAULTs flap at 2 of 15 starts) is still the
    # backlog, within max_stamp_age (2 s) of wall time from the first sample's arrival
    rig.joint_state(rig.t_ns - 3 * NS + 3 * MS, theta=0.1)
    assert h.spin_until(lambda: "stale samples of the start-up backlog after the first good "
                        "one" in ctl.output(), timeout=5.0), ctl.output()[-2000:]
    assert not any(st.mode == FAULT for st in rig.states), ctl.output()[-2000:]
    h.spin_for(2.1)  # past the window: stale is a FAULT
    rig.t_ns += MS
    rig.clock(rig.t_ns)
    rig.joint_state(rig.t_ns - 5 * NS, theta=0.25)
    assert h.spin_until(lambda: rig.states[-1].mode == FAULT, timeout=10.0), ctl.output()[-2000:]
    assert rig.cmds[-1] == 0.0
    # stamped with the stale sample's own stamp, with its values
    assert rosutil.stamp_ns(rig.states[-1]) == rig.t_ns - 5 * NS
    assert rig.states[-1].theta == 0.25
    assert "joint_states stamped +5.000 s from the node's clock" in ctl.output()
    # good samples: back to WAITING (joint_states trigger: a step per sample)
    for _ in range(5):
        rig.t_ns += MS
        rig.clock(rig.t_ns)
        rig.joint_state()
    assert h.spin_until(lambda: rig.states[-1].mode == WAITING, timeout=10.0)
    # the encoder goes silent (a dead driver) while the clock runs on: FAULT and zero torque
    # within the watchdog time of the node's clock (simulated time here)
    n = len(rig.states)
    t_dead = rig.t_ns
    for _ in range(200):
        rig.t_ns += 10 * MS
        rig.clock(rig.t_ns)
        if h.spin_until(lambda: any(s.mode == FAULT for s in rig.states[n:]), timeout=0.05):
            break
    assert any(s.mode == FAULT for s in rig.states[n:]), ctl.output()[-2000:]
    assert 0.5 * NS <= rig.t_ns - t_dead <= 1.0 * NS  # watchdog_timeout 0.5 s (+ its period)
    # no sample to derive it from: stamped with the node's clock at the check, theta unknown
    dead = next(s for s in rig.states[n:] if s.mode == FAULT)
    assert t_dead + NS // 2 <= rosutil.stamp_ns(dead) <= rig.t_ns
    assert math.isnan(dead.theta) and math.isnan(dead.theta_dot)
    assert rig.cmds[-1] == 0.0
    assert "no /joint_states for" in ctl.output() and ctl.alive
    # shutdown: a last zero command, a clean exit
    n_cmd = len(rig.cmds)
    assert ctl.stop() == 0
    h.spin_for(0.5)
    assert len(rig.cmds) > n_cmd and rig.cmds[-1] == 0.0
    assert "zero torque published on exit" in ctl.log_path.read_text()


def test_every_callback_the_node_registers_puts_an_exception_into_fault() -> None:
    """The node's promise (module docstring): an exception in any callback never ends it but
    puts the controller in FAULT. Each callback it registers (joint_states, ball_observation,
    timer, ~/reset, watchdog) is called on an object that has none of a node's state: the
    error must reach ``_on_exception`` with the callback's name, not the caller."""
    from types import SimpleNamespace  # noqa: PLC0415

    from bfr_control.controller_node import ControllerNode  # noqa: PLC0415

    calls = {"_on_joints": (b"",), "_on_ball": (BallObservation(),), "_on_timer": (),
             "_on_reset": (Trigger.Request(), Trigger.Response()), "_watchdog": ()}
    for name, args in calls.items():
        seen: list[tuple[str, Exception]] = []
        bare = SimpleNamespace(_on_exception=lambda where, exc, seen=seen: seen.append(
            (where, exc)))
        getattr(ControllerNode, name)(bare, *args)
        assert len(seen) == 1 and isinstance(seen[0][1], Exception), (name, seen)


def _step_per_sample(h: rosutil.RosHarness, node_processes  # noqa: ANN001
                     ) -> tuple[Rig, rosutil.NodeProcess]:
    """A test rig and a controller node stepping on each sample, under its simulated clock."""
    rig = Rig(h, [0.0, 0.0, 0.0, 2.0], t0_ns=10 * NS)
    ctl = node_processes.start("bfr_control", "controller_node", ros_args=[
        "-p", "use_sim_time:=true", "-p", "loop.trigger:=joint_states"])
    rig.wait_for_node(ctl)
    return rig, ctl


def test_controller_node_clock_mismatch_from_the_start(ros_harness: rosutil.RosHarness,
                                                       node_processes) -> None:  # noqa: ANN001
    """Every sample stale from the first on (a driver on another clock) is not a start-up
    backlog: after safety.max_stamp_age of steady time from the first one's arrival, FAULT
    with zero torque."""
    h = ros_harness
    rig, ctl = _step_per_sample(h, node_processes)
    for _ in range(5):  # the clock reaches the node (without one no age is checked)
        rig.t_ns += MS
        rig.clock(rig.t_ns)
        h.spin_for(0.05)
    for _ in range(100):  # 10 ms of the node's clock a sample, every one 3 s behind it
        rig.t_ns += 10 * MS
        rig.clock(rig.t_ns)
        rig.joint_state(rig.t_ns - 3 * NS)
        if h.spin_until(lambda: bool(rig.states), timeout=0.05):
            break
    assert rig.states and rig.states[-1].mode == FAULT, ctl.output()[-2000:]
    assert rig.cmds[-1] == 0.0
    assert "joint_states stamped +3.000 s from the node's clock" in ctl.output()
    assert "is arriving" not in ctl.output()


def test_controller_node_unwraps_a_driver_within_a_turn(ros_harness: rosutil.RosHarness,
                                                        node_processes) -> None:  # noqa: ANN001
    """A driver that reports theta within a turn ([-pi, pi)): the controller's states carry
    the accumulating angle across the wraps (no leap of a turn, no FAULT), and it says once
    that it unwraps."""
    h = ros_harness
    rig, ctl = _step_per_sample(h, node_processes)
    rate = 40.0  # [rad/s]: a turn in 0.16 s, 5 ms a sample
    sent = {}  # stamp [ns] -> the accumulating angle the driver wrapped
    for k in range(120):
        rig.t_ns += 5 * MS
        rig.clock(rig.t_ns)
        acc = 2.5 + rate * 5e-3 * k
        sent[rig.t_ns] = acc
        rig.joint_state(theta=math.remainder(acc, 2 * math.pi), theta_dot=rate)
        h.spin_for(0.003)
    assert h.spin_until(lambda: rosutil.stamp_ns(rig.states[-1]) == rig.t_ns if rig.states
                        else False, timeout=10.0), ctl.output()[-2000:]
    assert len(rig.states) >= 100 and not any(s.mode == FAULT for s in rig.states)
    # each state paired with its sample by stamp (a best-effort sample may be missing)
    theta = np.array([s.theta for s in rig.states])
    acc = np.array([sent[rosutil.stamp_ns(s)] for s in rig.states])
    assert np.all(np.diff(theta) > 0) and theta[-1] - theta[0] > 4 * math.pi
    # the turns before the first sample are the driver's to know: a whole number of them
    turns = (theta - acc) / (2 * math.pi)
    np.testing.assert_allclose(turns, np.round(turns[0]), atol=1e-9)
    out = ctl.output()
    assert out.count("the frame angle wraps at a turn") == 1, out[-3000:]


def test_controller_node_in_a_namespace_gets_the_hardware_file_or_says_why_not(
        ros_harness: rosutil.RosHarness, node_processes, tmp_path: Path) -> None:  # noqa: ANN001
    """Under ``-r __ns:=/rig1`` the shipped hardware.yaml (sections ``/**/controller``) sets
    the controller's trigger; a file with a bare ``controller:`` section, which ROS 2 skips
    for /rig1/controller without a word, is named at start (a probe written apart found
    the rig's 0.2 s watchdog and per-sample trigger silently not applied)."""
    hw = config_path("bfr_control", "hardware.yaml")
    bare = tmp_path / "mine.yaml"
    bare.write_text("controller:\n  ros__parameters:\n    loop: {trigger: joint_states}\n")
    good = node_processes.start("bfr_control", "controller_node",
                                ros_args=["-r", "__ns:=/rig1", "--params-file", str(hw)])
    skipped = node_processes.start("bfr_control", "controller_node",
                                   ros_args=["-r", "__ns:=/rig2", "--params-file", str(bare)])
    for proc, trigger in ((good, "joint_states"), (skipped, "observation")):
        assert ros_harness.spin_until(lambda p=proc: "trigger " in p.output(), timeout=60.0), \
            proc.output()[-2000:]
        assert f"trigger {trigger}," in proc.output(), proc.output()[-2000:]
    assert "was not applied" not in good.output()
    assert (f"parameter file {bare}: its section 'controller' is for /controller, not this "
            f"node (/rig2/controller), and was not applied") in skipped.output()


def test_a_command_line_value_beats_the_hardware_files_node_section(
        ros_harness: rosutil.RosHarness, node_processes) -> None:  # noqa: ANN001
    """``--params-file hardware.yaml -p loop.trigger:=observation``: ROS 2 applies the file's
    ``/**/controller`` section over ``-p`` (which it stores for every node), so the value
    typed on the command line was silently not used (a probe written apart: the docs' own
    ``-p markers.rate:=30.0`` and joint-name overrides did nothing; ``-p
    safety.watchdog_timeout:=-1.0`` started, with the file's 0.2 s). Now the command line
    wins and a line says so; a value that the checks refuse stops the node (exit 2)."""
    hw = config_path("bfr_control", "hardware.yaml")
    typed = node_processes.start("bfr_control", "controller_node", ros_args=[
        "--params-file", str(hw), "-p", "loop.trigger:=observation"])
    assert ros_harness.spin_until(lambda: "trigger " in typed.output(), timeout=60.0), \
        typed.output()[-2000:]
    assert "trigger observation," in typed.output(), typed.output()[-2000:]
    assert ("-p loop.trigger:=observation of the command line applied over 'joint_states' of "
            "a parameter file's section for this node") in typed.output()
    refused = node_processes.start("bfr_control", "controller_node", ros_args=[
        "--params-file", str(hw), "-p", "safety.watchdog_timeout:=-1.0"])
    assert ros_harness.wait_exit(refused, timeout=60.0) == 2, refused.output()[-2000:]
    assert ("[FATAL] cannot start: parameter safety.watchdog_timeout: must be > 0 s, got -1.0"
            in refused.output()), refused.output()[-2000:]


def test_a_driver_publishing_joint_states_with_another_type_is_named(
        ros_harness: rosutil.RosHarness, node_processes) -> None:  # noqa: ANN001
    """A driver that publishes ``/joint_states`` as ``std_msgs/Float64MultiArray``: the
    controller's subscription never matches it, and it had said only "no joint_states
    received yet" (a probe written apart); the graph names the type it found instead."""
    wrong = ros_harness.node.create_publisher(Float64MultiArray, "joint_states", 10)
    assert wrong_type_publishers(ros_harness.node, "/joint_states",
                                 "sensor_msgs/msg/JointState") == (
        "/joint_states is published as std_msgs/msg/Float64MultiArray by 1 publisher(s), not "
        "sensor_msgs/msg/JointState: nothing of it can be read")
    assert wrong_type_publishers(ros_harness.node, "/joint_states",
                                 "std_msgs/msg/Float64MultiArray") == ""
    ctrl = node_processes.start("bfr_control", "controller_node")
    msg = Float64MultiArray(data=[0.0, 0.0])
    expected = ("no joint_states received yet on /joint_states; /joint_states is published as "
                "std_msgs/msg/Float64MultiArray by 1 publisher(s), not "
                "sensor_msgs/msg/JointState")

    def named() -> bool:
        wrong.publish(msg)
        return expected in ctrl.output()

    assert ros_harness.spin_until(named, timeout=60.0), ctrl.output()[-2000:]
