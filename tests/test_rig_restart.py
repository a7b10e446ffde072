"""Killing the controller mid-run and starting a new one.

The simulator must keep running (lock-step falls back to running free after its timeout) and
apply zero torque once the commands stop; a new controller node must either pick the ball up
again (ROLLING) or report it lost (BALL_LOST), with a clear log either way, and the simulator
must resume lock-step with it.
"""

from __future__ import annotations

import signal

import pytest
import rosutil
from bfr_ros.node_common import STATE_QOS
from bfr_tools.rig import orbit_start

from bfr_interfaces.msg import ControllerState, SimTruth

NS = 1_000_000_000
pytestmark = pytest.mark.slow


def test_kill_and_restart_the_controller(ros_harness: rosutil.RosHarness,
                                         node_processes) -> None:  # noqa: ANN001
    h = ros_harness
    states: list[ControllerState] = []
    truth: list[SimTruth] = []
    ssub = h.node.create_subscription(ControllerState, "controller_state", states.append,
                                      STATE_QOS)
    tsub = h.node.create_subscription(SimTruth, "sim_truth", truth.append, STATE_QOS)
    start = orbit_start(0.3, 0.05)
    ctl_args = ["-p", "use_sim_time:=true", "-p", "safety.watchdog_timeout:=5.0"]
    node_processes.start("bfr_camera", "camera_node",
                         ros_args=["-p", "use_sim_time:=true", "-p", "input.frame_timeout:=5.0"])
    ctl = node_processes.start("bfr_control", "controller_node", ros_args=ctl_args)
    # the controller's state reaches this harness before the simulation runs: lock-step can
    # pass 3 s of simulated time before discovery matches a late subscription (a clean-clone
    # CI once received no state at all while the controller logged ROLLING)
    h.wait_for_match(ssub, timeout=60)
    sim = node_processes.start("bfr_sim", "simulator_node", ros_args=[
        "-p", "sim.mode:=lockstep", "-p", "lockstep.timeout:=1.0",
        "-p", "start.wait_subscribers:=2", "-p", "render.noise_sigma:=0.0",
        *[a for k, v in start.items() for a in ("-p", f"{k}:={v!r}")]])
    h.wait_for_match(tsub, timeout=60)

    def sim_time() -> int:
        return rosutil.stamp_ns(truth[-1]) if truth else 0

    # rolling under control for 3 s of simulated time
    assert h.spin_until(lambda: sim_time() > 3 * NS, timeout=180), sim.output()[-3000:]
    assert states and states[-1].mode == ControllerState.ROLLING, ctl.output()[-2000:]
    # the controller crashes (SIGKILL: no last zero command)
    ctl.process.send_signal(signal.SIGKILL)
    ctl.process.wait(timeout=10)
    t_kill = sim_time()
    # the simulator keeps running, with zero torque after command.timeout
    assert h.spin_until(lambda: sim_time() > t_kill + 2 * NS, timeout=60), sim.output()[-3000:]
    assert sim.alive
    late = [m for m in truth if rosutil.stamp_ns(m) > t_kill + 200_000_000]
    assert late and all(m.torque == 0.0 for m in late)
    out = sim.output()
    assert "lock-step: no answer from the controller" in out
    assert "no effort command for 0.1 s (simulated): applying zero torque" in out
    # a new controller: it picks the ball up again or reports it lost
    n0 = len(states)
    ctl2 = node_processes.start("bfr_control", "controller_node", ros_args=ctl_args)
    outcome = (ControllerState.ROLLING, ControllerState.BALL_LOST)
    assert h.spin_until(lambda: any(s.mode in outcome for s in states[n0:]), timeout=180), \
        ctl2.output()[-3000:]
    new = states[n0:]
    assert all(abs(s.torque) <= 0.1 for s in new)
    assert all(s.torque == 0.0 for s in new if s.mode != ControllerState.ROLLING)
    # ... and says so in its log (the state message may arrive before the log line is out)
    said = ("ROLLING at t = ", "BALL_LOST: ball seen but off the orbit", "BALL_LOST at t = ")
    assert h.spin_until(lambda: any(m in ctl2.output() for m in said), timeout=30), \
        ctl2.output()[-3000:]
    assert h.spin_until(lambda: "controller is back: lock-step resumed" in sim.output(),
                        timeout=30)
    assert ctl2.alive and sim.alive
    assert sim.stop() == 0
    assert "simulator stopped at t = " in sim.log_path.read_text()
