"""The commissioning loop on a rig with every real-rig effect (issue 17, item 4).

docs/hardware.md, "Commissioning": on a new rig (here the independent stand-in with dry
friction, a lighter frame, a late camera, a smaller rolling radius and a larger contour, all
at once), before the controller ever runs:

1. record the frame held (braked) with the ball rolling free on it: the ball's physics
   (contour, rolling radius) without the motor;
2. record a friction run without the ball: torque steps, the frame turning (no controller
   needed);
3. ``bfr diagnose`` them (the friction run first, ``--ball no``: there is no ball, then the
   held run on its corrected parameters: today's CLI takes one recording at a time);
4. start the controller and camera with the corrected parameters: the ball keeps rolling.

The test asserts only what the loop must achieve (the ball keeps rolling, the diagnosis
changed the parameters toward the rig), not which effects the diagnosis names, so that a
better diagnosis keeps it green.
"""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rosutil
from bfr_model.param_file import load_ros_parameters
from bfr_ros.node_common import COMMAND_QOS
from std_msgs.msg import Float64MultiArray
from test_standin_integration import (
    STANDIN,
    Watch,
    camera_args,
    camera_file,
    orbit_start_standin,
    standin_args,
    start_nodes,
)

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
#: The real rig's effects, all at once (the stand-in's names).
EFFECTS = {"effects.coulomb_friction": 0.002, "effects.frame_inertia_scale": 0.56,
           "effects.camera_latency": 0.008, "effects.rolling_radius_delta": -0.001,
           "effects.contour_radius_delta": 0.005}


def record(node_processes, h: rosutil.RosHarness, bag: Path, rig_args: dict,  # noqa: ANN001
           cam_yaml: Path, torque_steps: list[float] | None = None) -> None:
    """Run the stand-in with the camera and recorder nodes; optionally torque steps (1 s)."""
    rec = node_processes.start("bfr_sim", "recorder_node", ros_args=[
        "-p", "use_sim_time:=true", "-p", f"recorder.path:={bag}",
        "-p", "recorder.topics:=[joint_states, effort_controller/commands, ball_observation,"
              " camera/camera_info]"])
    cam = node_processes.start("bfr_camera", "camera_node", ros_args=camera_args(cam_yaml))
    assert h.spin_until(lambda: "recording" in rec.output() and "camera: images" in cam.output(),
                        timeout=90), rec.output() + cam.output()
    h.spin_for(1.0)
    rig = node_processes.start_python(str(STANDIN), args=standin_args(rig_args))
    if torque_steps:
        pub = h.node.create_publisher(Float64MultiArray, "effort_controller/commands",
                                      COMMAND_QOS)
        msg = Float64MultiArray()
        while rig.alive:
            k = int(time.monotonic() * rig_args["time_scale"]) % len(torque_steps)
            msg.data = [float(torque_steps[k])]
            pub.publish(msg)
            h.spin_for(0.02)
    assert h.wait_exit(rig, 300) == 0, rig.output()[-2000:]
    for proc in (cam, rec):
        assert proc.stop() == 0
    assert (bag / "metadata.yaml").exists(), rec.output()[-2000:]


def diagnose(bag: Path, out: Path, params: Path | None = None, ball: str = "auto") -> Path:
    args = [sys.executable, "-m", "bfr_diagnose.cli", str(bag), "--out-dir", str(out),
            "--no-plots", "--quiet", "--ball", ball]
    if params is not None:
        args += ["--params", str(params)]
    res = subprocess.run(args, capture_output=True, text=True, timeout=600, env=os.environ,
                         check=False)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    corrected = out / "corrected_params.yaml"
    assert corrected.exists(), res.stdout[-2000:]
    return corrected


def test_commissioning_loop_on_a_rig_with_every_effect(ros_harness: rosutil.RosHarness,
                                                       node_processes, tmp_path: Path) -> None:  # noqa: ANN001
    h = ros_harness
    cam_yaml = camera_file(node_processes, h, tmp_path)
    # 1. the frame held, the ball rolling free on it (to and fro in the waist's valley)
    held = tmp_path / "held"
    record(node_processes, h, held, {"time_scale": 0.5, "duration": 5.0, "seed": 7,
                                     "frame_locked": "true", "initial.ball_angle": 0.35,
                                     **EFFECTS}, cam_yaml)
    # 2. a friction run: no ball, torque steps of +-6 mN m and 10 mN m
    fric = tmp_path / "friction"
    record(node_processes, h, fric, {"time_scale": 0.5, "duration": 6.0, "seed": 7,
                                     "ball": "false", **EFFECTS}, cam_yaml,
           torque_steps=[0.006, -0.006, 0.010, -0.010])
    # 3. diagnose: the frame's run first, the ball's on its result
    c1 = diagnose(fric, tmp_path / "diag_friction", ball="no")
    c2 = diagnose(held, tmp_path / "diag_held", params=c1)
    nominal = load_ros_parameters(REPO / "src" / "bfr_model" / "config" / "rig.yaml")
    corrected = load_ros_parameters(c2)
    assert corrected != nominal  # the diagnosis found what the nominal model leaves out
    # 4. the controller and camera on the corrected parameters, the ball on their orbit,
    #    released once the stand-in's topics have peers (start.wait: see
    #    test_standin_integration)
    watch = Watch(h)
    duration = 3.0  # at a fifth of real time
    cam, ctl = start_nodes(node_processes, h, cam_yaml, watch, params=c2)
    watch.states.clear()
    truth_csv = tmp_path / "truth.csv"
    rig = node_processes.start_python(str(STANDIN), args=standin_args({
        "time_scale": 0.2, "duration": duration, "seed": 7, "truth_out": str(truth_csv),
        "start.wait": 60.0, "start.joint_states_peers": 2, **EFFECTS,
        **orbit_start_standin(0.3, c2)}))
    assert h.wait_exit(rig, duration / 0.2 + 120) == 0, rig.output()[-3000:]
    assert "start: peers matched" in rig.output(), rig.output()[-3000:]
    first = [float(x) for x in re.findall(r"ROLLING at t = ([0-9.]+) s", ctl.output())]
    assert first and first[0] <= 0.15, ctl.output()[-3000:]
    with truth_csv.open() as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["t"]) for r in rows])
    contact = np.array([float(r["in_contact"]) for r in rows])
    speed = np.array([float(r["ball_angle_dot"]) for r in rows])
    assert t[-1] == pytest.approx(duration, abs=0.01)
    on = contact == 1  # a hop of a few ms is the stand-in's hybrid physics, not a loss
    assert on.mean() > 0.99 and np.all(on[t > duration - 1.0]), ctl.output()[-3000:]
    assert np.all(speed[(t > 0.5) & on] > 0.5), ctl.output()[-3000:]
    assert watch.states[-1].mode == watch.states[-1].ROLLING
    assert cam.alive and ctl.alive
