"""Pure parts of the node suite (no ROS processes): parameters, conversions, the simulator's
actuator and schedule, the camera's theta buffer, the rig's orbit start and the launch file."""

from __future__ import annotations

import ast
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bfr_camera.camera_node import ThetaBuffer
from bfr_camera.camera_node import node_defaults as camera_defaults
from bfr_model.params import load_params
from bfr_ros.node_common import (
    JointPicker,
    _cast,
    _command_line_value,
    command_line_params,
    flatten,
    image_to_array,
    place_process,
    realtime_scheduling,
    ros_params_files,
    section_applies,
    unapplied_sections,
    unflatten,
)
from bfr_sim.simulator_node import RigSimulation, Schedule
from bfr_sim.simulator_node import node_defaults as sim_defaults
from bfr_tools.rig import orbit_start, run_warnings, set_autogroup_nice

REPO = Path(__file__).resolve().parents[1]


# -- parameters mirrored from YAML -----------------------------------------------------------
def test_flatten_round_trip() -> None:
    tree = {"ball": {"mass": 3e-3}, "frame": {"contour": {"a": 0.1, "harmonic_orders": [4]}}}
    flat = flatten(tree)
    assert flat == {"ball.mass": 3e-3, "frame.contour.a": 0.1,
                    "frame.contour.harmonic_orders": [4]}
    assert unflatten(flat) == tree


@pytest.mark.parametrize(("value", "default", "expected"), [
    (1, 0.5, 1.0), (2.0, 3, 2), ("x", "y", "x"), (True, False, True), ([1, 2], [0.5], [1.0, 2.0]),
])
def test_cast_to_default_type(value: object, default: object, expected: object) -> None:
    got = _cast("p", value, default)
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize(("value", "default"), [("a", 1.0), (1.5, 2), (1.0, True)])
def test_cast_rejects(value: object, default: object) -> None:
    with pytest.raises(ValueError, match="parameter p"):
        _cast("p", value, default)


def test_node_defaults_mirror_the_yaml_files() -> None:
    d = sim_defaults()
    assert d["ball"]["mass"] == pytest.approx(3e-3)  # rig.yaml
    assert d["camera"]["frame_rate"] == pytest.approx(200.0)  # camera.yaml
    assert d["sim"]["mode"] == "realtime"  # simulator_node.yaml
    assert "detector" not in d  # the simulator renders; it does not detect
    c = camera_defaults()
    assert c["ball"]["radius"] == pytest.approx(16.6e-3)  # rig.yaml: the ball and the contour
    assert c["frame"]["contour"]["a"] == pytest.approx(0.1095)
    assert "detector" in c and c["input"]["joint_name"] == "frame_joint"


# -- image conversion ------------------------------------------------------------------------
def _img(arr: np.ndarray, encoding: str, big: bool = False) -> SimpleNamespace:
    h, w = arr.shape[:2]
    data = arr.astype(arr.dtype.newbyteorder(">" if big else "<")).tobytes()
    return SimpleNamespace(height=h, width=w, step=len(data) // h, encoding=encoding,
                           is_bigendian=int(big), data=data)


def test_image_to_array_encodings() -> None:
    rng = np.random.default_rng(0)
    a8 = rng.integers(0, 255, (4, 6), dtype=np.uint8)
    got, err = image_to_array(_img(a8, "mono8"))
    assert err == "" and np.array_equal(got, a8)
    a16 = rng.integers(0, 65535, (4, 6), dtype=np.uint16)
    for big in (False, True):
        got, err = image_to_array(_img(a16, "mono16", big))
        assert err == "" and np.array_equal(got, a16)
    rgb = rng.integers(0, 255, (4, 6, 3), dtype=np.uint8)
    got, err = image_to_array(_img(rgb, "rgb8"))
    assert err == "" and np.array_equal(got, rgb[..., ::-1])
    rgba = rng.integers(0, 255, (4, 6, 4), dtype=np.uint8)
    got, err = image_to_array(_img(rgba, "rgba8"))
    assert err == "" and np.array_equal(got, rgba[..., [2, 1, 0, 3]])
    f = rng.random((3, 5)).astype(np.float32)
    got, err = image_to_array(_img(f, "32FC1"))
    assert err == "" and np.array_equal(got, f)


def test_image_to_array_bayer_and_yuv() -> None:
    """A Bayer mosaic is demosaiced to grey with ROS's pattern names (a pure red scene is
    red's share of grey, 0.299, only if R sits where the encoding says); 4:2:2 YUV gives its
    luma exactly, from the second byte of each pair (UYVY) or the first (YUYV)."""
    red = np.zeros((8, 10), np.uint8)  # bayer_rggb8: R at even rows and even columns
    red[0::2, 0::2] = 200
    for enc, where in (("bayer_rggb8", (0, 0)), ("bayer_bggr8", (1, 1)),
                       ("bayer_grbg8", (0, 1)), ("bayer_gbrg8", (1, 0))):
        mosaic = np.zeros((8, 10), np.uint8)
        mosaic[where[0]::2, where[1]::2] = 200  # the R photosites of this pattern
        got, err = image_to_array(_img(mosaic, enc))
        assert err == "" and got.shape == (8, 10) and got.dtype == np.uint8, (enc, err)
        assert np.all(np.abs(got[2:-2, 2:-2].astype(int) - round(0.299 * 200)) <= 1), (enc, got)
    grey = np.full((6, 8), 40000, np.uint16)
    got, err = image_to_array(_img(grey, "bayer_gbrg16"))
    assert err == "" and got.dtype == np.uint16 and np.all(got == 40000)
    rng = np.random.default_rng(1)
    luma = rng.integers(0, 255, (4, 6), dtype=np.uint8)
    chroma = rng.integers(0, 255, (4, 6), dtype=np.uint8)
    for enc, pair in (("yuv422", (chroma, luma)), ("yuv422_yuy2", (luma, chroma))):
        got, err = image_to_array(_img(np.stack(pair, axis=-1), enc))
        assert err == "" and np.array_equal(got, luma), enc
    _, err = image_to_array(_img(luma, "nv21"))
    assert err.startswith("unsupported image encoding 'nv21' (supported: mono8") and "bayer" in err


def test_image_to_array_padded_rows() -> None:
    a = np.arange(12, dtype=np.uint8).reshape(3, 4)
    padded = np.zeros((3, 8), np.uint8)
    padded[:, :4] = a
    msg = SimpleNamespace(height=3, width=4, step=8, encoding="mono8", is_bigendian=0,
                          data=padded.tobytes())
    got, err = image_to_array(msg)
    assert err == "" and np.array_equal(got, a)


@pytest.mark.parametrize(("change", "match"), [
    ({"encoding": "nv21"}, "unsupported image encoding"),
    ({"data": b"\0" * 10}, "image data has 10 B"),
    ({"step": 2}, "smaller than width"),
    ({"height": 0}, "empty image"),
])
def test_image_to_array_rejects(change: dict, match: str) -> None:
    msg = _img(np.zeros((4, 6), np.uint8), "mono8")
    for k, v in change.items():
        setattr(msg, k, v)
    got, err = image_to_array(msg)
    assert got is None and match in err


# -- camera node: theta at the exposure time --------------------------------------------------
def test_theta_buffer_interpolates_and_extrapolates() -> None:
    buf = ThetaBuffer(max_gap=0.01)
    assert buf.theta_at(0)[0] is None
    w = 2.0  # constant rate: Hermite interpolation and extrapolation are exact
    for k in range(10):
        t = k * 1_000_000
        buf.add(t, 0.1 + w * t * 1e-9, w)
    th, why = buf.theta_at(4_300_000)
    assert why == "" and th == pytest.approx(0.1 + w * 4.3e-3)
    th, _ = buf.theta_at(9_000_000 + 5_000_000)  # 5 ms after the newest sample
    assert th == pytest.approx(0.1 + w * 14e-3)
    th, why = buf.theta_at(9_000_000 + 20_000_000)
    assert th is None and "older than the frame" in why
    assert buf.theta_at(-1)[0] is None
    buf.add(5, 99.0, 0.0)  # out of order: ignored
    assert buf.theta_at(9_000_000)[0] == pytest.approx(0.1 + w * 9e-3)


# -- simulator: actuator, timeout, schedule, truth ---------------------------------------------
@pytest.fixture(scope="module")
def params():  # noqa: ANN201
    return load_params()


def test_simulation_clamps_and_ignores_bad_commands(params) -> None:  # noqa: ANN001
    sim = RigSimulation(params, [0.0, 0.0, 0.0, 2.0], 1e-3, command_timeout=0.1)
    assert sim.applied_command() == 0.0  # no command yet
    assert sim.set_command([0.5]) == ""
    assert sim.applied_command() == pytest.approx(params.actuator.torque_limit)
    assert sim.set_command([-0.02]) == ""
    assert sim.applied_command() == pytest.approx(-0.02)
    assert "not finite" in sim.set_command([math.nan])
    assert "2 elements" in sim.set_command([0.01, 0.02])
    assert "0 elements" in sim.set_command([])
    assert sim.applied_command() == pytest.approx(-0.02)  # the last good command holds
    for _ in range(100):
        sim.step()
    assert sim.applied_command() == pytest.approx(-0.02) and not sim.timed_out
    sim.step()  # 101 ms after the command
    assert sim.applied_command() == 0.0 and sim.timed_out


def test_simulation_truth_is_consistent(params) -> None:  # noqa: ANN001
    sim = RigSimulation(params, [-0.17, 0.3, 0.06, 2.3])
    ball, vel = sim.ball_kinematics()
    assert np.allclose(ball[:2], sim.model.ball_position(sim.x[:4]))
    sim.set_command([0.01])
    tr0 = sim.truth()
    sim.step()
    tr1 = sim.truth()
    assert np.allclose((tr1.ball - tr0.ball) / sim.dt, vel, rtol=2e-3, atol=1e-4)
    assert tr1.spin - tr0.spin == pytest.approx(tr0.spin_rate * sim.dt, rel=2e-3)
    assert tr1.torque == pytest.approx(0.01 * params.actuator.torque_gain)
    assert tr1.normal_force > 0.0
    e0, e1 = tr0.kinetic + tr0.potential, tr1.kinetic + tr1.potential
    assert e1 - e0 == pytest.approx(tr1.x[4] - tr0.x[4], rel=1e-3)  # work in = energy gained


def test_simulation_rejects_bad_settings(params) -> None:  # noqa: ANN001
    with pytest.raises(ValueError, match="time_step"):
        RigSimulation(params, [0, 0, 0, 0], time_step=0.0)
    with pytest.raises(ValueError, match="initial state"):
        RigSimulation(params, [0, math.nan, 0, 0])


def test_schedule_on_the_step_grid() -> None:
    step = 1_000_000
    for rate, expect in ((500.0, 500), (200.0, 200), (1000.0, 1000), (165.0, 165)):
        s = Schedule(rate, step, "r")
        n = sum(s.due(k * step) for k in range(1000))
        assert n == expect
    with pytest.raises(ValueError, match="must be > 0"):
        Schedule(0.0, step, "joint_states.rate")


# -- real-time scheduling of a node's threads ------------------------------------------------
#: Run in a child process (the test process itself must not become real-time): threads made
#: before the call, the call, a thread made after it; prints what each thread runs under.
_SCHED_CHILD = """
import json, os, sys, threading, time
from bfr_ros.node_common import realtime_scheduling
if len(sys.argv) > 2:  # drop root: an unprivileged user with no real-time limit
    os.setgid(65534); os.setuid(65534)
stop = threading.Event()
early = [threading.Thread(target=stop.wait) for _ in range(3)]
for t in early: t.start()
applied, text = realtime_scheduling(int(sys.argv[1]))
late = threading.Thread(target=stop.wait); late.start()
time.sleep(0.05)
tasks = {int(t): (os.sched_getscheduler(int(t)), os.sched_getparam(int(t)).sched_priority)
         for t in os.listdir("/proc/self/task")}
stop.set()
print(json.dumps({"applied": applied, "text": text, "tasks": list(tasks.values()),
                  "late": tasks[late.native_id]}))
"""


def _sched_child(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _SCHED_CHILD, *args], capture_output=True,
                         text=True, timeout=60, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _may_use_fifo() -> bool:
    try:
        out = subprocess.run([sys.executable, "-c", "import os; os.sched_setscheduler("
                              "0, os.SCHED_FIFO, os.sched_param(1))"], check=False,
                             capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return out.returncode == 0


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="no POSIX scheduling API")
def test_realtime_scheduling_switches_every_thread() -> None:
    if not _may_use_fifo():
        pytest.skip("this user may not use SCHED_FIFO (no CAP_SYS_NICE, ulimit -r 0)")
    got = _sched_child("7")
    assert got["applied"], got["text"]
    assert "SCHED_FIFO priority 7" in got["text"]
    # every thread: the main one, the three made before the call, the one made after it
    assert len(got["tasks"]) >= 5
    assert all(t == [os.SCHED_FIFO, 7] for t in got["tasks"]), got["tasks"]
    assert got["late"] == [os.SCHED_FIFO, 7]


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="no POSIX scheduling API")
def test_realtime_scheduling_zero_leaves_the_normal_scheduler() -> None:
    got = _sched_child("0")
    assert not got["applied"] and "normal" in got["text"]
    assert all(t == [os.SCHED_OTHER, 0] for t in got["tasks"]), got["tasks"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root to run the child as an unprivileged user")
def test_realtime_scheduling_refused_says_why_and_changes_nothing() -> None:
    got = _sched_child("40", "unprivileged")
    assert not got["applied"]
    assert "refused" in got["text"] and "CAP_SYS_NICE" in got["text"], got["text"]
    assert all(t == [os.SCHED_OTHER, 0] for t in got["tasks"]), got["tasks"]


@pytest.mark.parametrize("bad", [-1, 99, 1000])
def test_realtime_scheduling_rejects_out_of_range(bad: int) -> None:
    with pytest.raises(ValueError, match=r"process\.realtime_priority: must be an integer 0-98"):
        realtime_scheduling(bad)


# -- pinning a node's threads to one CPU ------------------------------------------------------
_PIN_CHILD = """
import json, os, sys, threading, time
from bfr_ros.node_common import pin_threads
stop = threading.Event()
early = [threading.Thread(target=stop.wait) for _ in range(3)]
for t in early: t.start()
before = sorted(os.sched_getaffinity(0))
try:
    text = pin_threads(int(sys.argv[1]))
except ValueError as exc:
    text = "ValueError: " + str(exc)
late = threading.Thread(target=stop.wait); late.start()
time.sleep(0.05)
tasks = {int(t): sorted(os.sched_getaffinity(int(t))) for t in os.listdir("/proc/self/task")}
stop.set()
print(json.dumps({"text": text, "before": before, "tasks": list(tasks.values()),
                  "late": tasks[late.native_id]}))
"""


def _pin_child(cpu: int) -> dict:
    out = subprocess.run([sys.executable, "-c", _PIN_CHILD, str(cpu)], capture_output=True,
                         text=True, timeout=60, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="no CPU affinity API, or one CPU only (nothing to tell apart)")
def test_pin_threads_pins_every_thread_and_later_ones() -> None:
    cpu = max(os.sched_getaffinity(0))
    got = _pin_child(cpu)
    assert got["text"].startswith(f"CPU {cpu} only (")
    assert len(got["tasks"]) >= 5  # the main thread, three before the call, one after
    assert all(t == [cpu] for t in got["tasks"]), got["tasks"]
    assert got["late"] == [cpu]


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity API")
def test_pin_threads_minus_one_and_unknown_cpus() -> None:
    got = _pin_child(-1)
    assert got["text"] == "any CPU (process.cpu -1)"
    assert all(t == got["before"] for t in got["tasks"])
    absent = max(os.sched_getaffinity(0)) + 1  # a CPU this process may not use
    got = _pin_child(absent)
    assert got["text"].startswith(f"ValueError: process.cpu: CPU {absent} is not available")
    assert all(t == got["before"] for t in got["tasks"])  # nothing changed


@pytest.mark.parametrize("bad", [-2, 1.5, True, "1"])
def test_place_process_rejects_bad_values(bad: object) -> None:
    with pytest.raises(ValueError, match=r"process\.cpu: must be -1 \(any CPU\) or a CPU"):
        place_process({"realtime_priority": 0, "cpu": bad})
    with pytest.raises(ValueError, match=r"process\.realtime_priority: must be an integer"):
        place_process({"realtime_priority": 1.5, "cpu": -1})


def test_composed_process_settings() -> None:
    from bfr_tools.loop_node import process_settings  # noqa: PLC0415

    def node(name: str, prio: int, cpu: int) -> SimpleNamespace:
        return SimpleNamespace(get_name=lambda: name,
                               process={"realtime_priority": prio, "cpu": cpu})

    assert process_settings([node("camera", 40, -1), node("controller", 45, -1)]) == {
        "realtime_priority": 45, "cpu": -1}
    assert process_settings([node("camera", 40, 1), node("controller", 0, -1)]) == {
        "realtime_priority": 40, "cpu": 1}
    assert process_settings([node("camera", 40, 1), node("controller", 45, 1)])["cpu"] == 1
    with pytest.raises(ValueError, match=r"name different CPUs \(camera 0, controller 1\)"):
        process_settings([node("camera", 40, 0), node("controller", 45, 1)])
    # each node's values checked as it would check them alone (not hidden by the maximum)
    with pytest.raises(ValueError, match=r"process\.realtime_priority: must be an integer"):
        process_settings([node("camera", -5, -1), node("controller", 45, -1)])


def test_loop_specs_composed_scopes_each_nodes_values() -> None:
    from bfr_tools.rig import LOOP_NODE, RigError, loop_specs  # noqa: PLC0415

    per = {"camera": ["-p", "use_sim_time:=true", "--params-file", "/x/rig.yaml",
                      "--params-file", "/x/camera.yaml", "-p", "input.frame_timeout:=1:30"],
           "controller": ["-p", "use_sim_time:=true", "--params-file", "/x/rig.yaml",
                          "-p", "loop.trigger:=observation", "-p", "process.cpu:=0"]}
    specs = loop_specs(per, composed=True, cpu=1)
    assert list(specs) == ["loop"]
    spec = specs["loop"]
    assert (spec.package, spec.executable) == LOOP_NODE and not spec.rename
    assert "__node:=" not in " ".join(spec.command())
    # each file once, the camera's first; each value scoped to its node (rcl's
    # -p node:name:=value), the values untouched (rcl parses them), the pin before the
    # node's own values so that they may override it
    assert spec.ros_args == [
        "--params-file", "/x/rig.yaml", "--params-file", "/x/camera.yaml",
        "-p", "camera:process.cpu:=1", "-p", "camera:use_sim_time:=true",
        "-p", "camera:input.frame_timeout:=1:30",
        "-p", "controller:process.cpu:=1", "-p", "controller:use_sim_time:=true",
        "-p", "controller:loop.trigger:=observation", "-p", "controller:process.cpu:=0"]
    two = loop_specs(per, composed=False, cpu=-1)
    assert list(two) == ["camera", "controller"]
    assert two["camera"].ros_args == per["camera"] and two["camera"].rename
    assert loop_specs(per, composed=False, cpu=0)["camera"].ros_args[:2] == [
        "-p", "process.cpu:=0"]
    # remaps reach the composed process once (each node's topics are its own)
    remapped = loop_specs({"camera": ["-r", "camera/image_raw:=/cam/image_raw"],
                           "controller": []}, composed=True, cpu=-1)
    assert remapped["loop"].ros_args[-2:] == ["-r", "camera/image_raw:=/cam/image_raw"]
    with pytest.raises(RigError, match="only -p NAME:=VALUE, --params-file FILE and -r"):
        loop_specs({"camera": ["--enclave", "/x"], "controller": []}, composed=True, cpu=-1)


def test_loop_layout() -> None:
    from bfr_tools.rig import loop_cpu_default, loop_layout  # noqa: PLC0415

    assert loop_layout("realtime") == (True, loop_cpu_default())
    assert loop_layout("lockstep") == (False, -1)
    assert loop_layout("lockstep", "composed", 0) == (True, 0)
    assert loop_layout("realtime", "separate", -1) == (False, -1)
    with pytest.raises(ValueError, match="loop: expected auto, composed or separate"):
        loop_layout("realtime", "compossed")


# -- rig: start on the orbit, the launch file ---------------------------------------------------
def test_set_autogroup_nice() -> None:
    if not Path("/proc/self/autogroup").exists():
        assert not set_autogroup_nice(os.getpid(), 5)  # no autogroups: says so
        return
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(10)"],
                             start_new_session=True)  # a session (autogroup) of its own
    try:
        assert set_autogroup_nice(child.pid, 5)  # raising niceness needs no privilege
        assert Path(f"/proc/{child.pid}/autogroup").read_text().split()[-1] == "5"
    finally:
        child.kill()
        child.wait()
    assert not set_autogroup_nice(child.pid, 5)  # gone: False, no exception


def test_orbit_start_is_on_the_controller_orbit() -> None:
    s = orbit_start(0.3, 0.0)
    assert s["initial.phi"] == pytest.approx(0.3)
    assert 1.5 < s["initial.phi_dot"] < 3.5
    s2 = orbit_start(0.3, 0.05)
    assert s2["initial.theta"] - s["initial.theta"] == pytest.approx(0.05)


def test_launch_file_names_existing_executables_and_files() -> None:
    path = REPO / "src" / "bfr_tools" / "launch" / "rig.launch.py"
    tree = ast.parse(path.read_text())
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str)}
    for exe in ("simulator_node", "camera_node", "controller_node", "recorder_node"):
        assert exe in strings
    for f in ("rig.yaml", "camera.yaml", "simulator_node.yaml", "controller_node.yaml",
              "hardware.yaml"):
        assert f in strings
        assert list(REPO.glob(f"src/*/config/{f}")), f
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
               for n in tree.body)


def test_the_simulator_runs_a_creeping_spin(params) -> None:  # noqa: ANN001
    """``ball.creep_time`` (the diagnosis writes it where the real ball creeps): the
    simulation carries the spin as a seventh state, its truth reports that spin's rate (not
    rolling's) and the energy with the spin's own, and the published state stays six
    entries."""
    p = params.replace(**{"ball.creep_time": 0.05})
    sim = RigSimulation(p, [-0.17, 0.3, 0.06, 2.3])
    assert sim.x.shape == (7,)
    sim.set_command([0.02])
    for _ in range(200):
        sim.step()
    tr = sim.truth()
    assert tr.x.shape == (6,) and tr.spin_rate == pytest.approx(float(sim.x[6]))
    rolling = float(sim.model.ball_spin_rate(sim.x[:4]))
    assert abs(tr.spin_rate - rolling) > 0.1  # the spin lags its rolling
    kin, _ = sim.model.energy(sim.x)
    assert tr.kinetic == pytest.approx(float(kin))


def test_joint_picker_takes_its_joint_and_says_what_came_without_it() -> None:
    """The frame's joint by name (any order), a nameless single-joint message as it; other
    joints' messages counted with their names, for the nodes' "no joint_states" warnings."""
    pick = JointPicker("frame_joint")
    assert pick.missing() == ""
    assert pick.index(["wheel", "frame_joint"], (1.0, 2.0)) == 1
    assert pick.index([], (3.0,)) == 0
    assert pick.index([], (3.0, 4.0)) is None
    assert pick.index(["joint1"], (5.0,)) is None
    assert pick.others == 2
    assert pick.missing() == ("2 message(s) arrived without joint 'frame_joint' (names "
                              "['joint1']): is the frame's joint named otherwise? (parameter "
                              "joint_name)")


def test_a_run_that_fell_behind_or_lost_messages_is_said() -> None:
    """bfr rig's summary: a clean run has no warning; messages not recorded, a camera node or
    a controller that fell behind its input (the encoder on hardware, the observations in a
    simulation), no encoder sample at all: each a line."""
    def summary(mode: str, **counts: int) -> dict:
        names = {"js": "/joint_states", "obs": "/ball_observation", "st": "/controller_state",
                 "info": "/cam/camera_info", "cmd": "/effort_controller/commands"}
        return {"mode": mode, "topics": {names[k]: {"count": v} for k, v in counts.items()},
                "published": {"/controller_state": counts["st"],
                              "/effort_controller/commands": counts["cmd"] + 1}}

    clean = summary("hardware", js=9500, obs=1990, st=9480, info=2000, cmd=9480)
    clean["published"]["/effort_controller/commands"] -= 1
    assert run_warnings(clean) == []
    assert run_warnings(summary("lockstep", js=3600, obs=1200, st=1200, info=1200,
                                cmd=1199)) == ["/effort_controller/commands: 1 of 1200 "
                                               "published message(s) not recorded (the "
                                               "bag's figures undercount the run)"]
    slow = run_warnings(summary("hardware", js=9470, obs=323, st=4417, info=1990, cmd=4418))
    assert slow[1:] == ["the camera node measured 323 of 1990 camera frames (16 %): it fell "
                        "behind the camera",
                        "the controller stepped on 4417 of 9470 encoder samples (47 %): it "
                        "fell behind"]
    sim = run_warnings(summary("realtime", js=3600, obs=1200, st=900, info=1200, cmd=899))
    assert sim[-1] == "the controller stepped on 900 of 1200 ball observations (75 %): it " \
                      "fell behind"
    assert "no /joint_states recorded" in run_warnings(summary("hardware", js=0, obs=0, st=0,
                                                               info=0, cmd=0))[-1]
    # the recorder outlives the loop nodes: their inputs count while they published
    hw = summary("hardware", js=12000, obs=1990, st=9480, info=2600, cmd=9480)
    hw["published"]["/effort_controller/commands"] -= 1
    assert len(run_warnings(hw)) == 2
    hw["loop_inputs"] = {"joint_states": 9500, "ball_observation": 1990, "camera_info": 2000}
    assert run_warnings(hw) == []
    hw["published"]["/clock"] = 12000  # published, not recorded by default: not a loss
    assert run_warnings(hw) == []
    del hw["topics"]["/controller_state"]  # the loop's, published, none recorded: a loss
    assert run_warnings(hw)[0].startswith("/controller_state: 9480 of 9480 published")


def test_a_parameter_section_that_misses_its_node_in_a_namespace_is_named(
        tmp_path: Path) -> None:
    """rcl applies a parameter file's node section to the node it names in full: a bare
    ``controller:`` does not reach /rig1/controller, silently. The node now says so; the
    shipped hardware.yaml's ``/**/controller`` reaches it in any namespace."""
    assert section_applies("/**", "/rig1/controller")
    assert section_applies("/**/controller", "/rig1/controller")
    assert section_applies("/**/controller", "/controller")
    assert section_applies("controller", "/controller")
    assert section_applies("/controller", "/controller")
    assert not section_applies("controller", "/rig1/controller")
    assert section_applies("/*/controller", "/rig1/controller")
    assert not section_applies("/*/controller", "/a/b/controller")
    assert not section_applies("/**/controller", "/rig1/camera")
    bare = tmp_path / "bare.yaml"
    bare.write_text("/**:\n  ros__parameters: {use_sim_time: false}\n"
                    "controller:\n  ros__parameters: {loop: {trigger: joint_states}}\n"
                    "camera:\n  ros__parameters: {markers: {rate: 0.0}}\n")
    hw = REPO / "src" / "bfr_control" / "config" / "hardware.yaml"
    argv = ["controller_node", "--ros-args", "-r", "__ns:=/rig1", "--params-file", str(bare),
            "--params-file", str(hw), "--", "--params-file", "not-a-ros-arg.yaml"]
    assert ros_params_files(argv) == [str(bare), str(hw)]
    lines = unapplied_sections(argv, "controller", "/rig1/controller")
    assert len(lines) == 1 and "section 'controller' is for /controller" in lines[0], lines
    assert "write '/**/controller:'" in lines[0]
    assert unapplied_sections(argv, "controller", "/controller") == []
    # another rig's sections in a shared file, a nested form, another node's: not reported
    shared = tmp_path / "shared.yaml"
    shared.write_text("/rig1/controller:\n  ros__parameters: {a: 1}\n"
                      "/rig2/controller:\n  ros__parameters: {a: 2}\n"
                      "/camera/camera:\n  ros__parameters: {b: 1}\n"
                      "/rig3:\n  controller:\n    ros__parameters: {a: 3}\n"
                      "/:\n  controller:\n    ros__parameters: {a: 4}\n")
    args = ["x", "--ros-args", "--params-file", str(shared)]
    assert unapplied_sections(args, "controller", "/rig1/controller") != []  # the "/:" one
    assert all("'controller' is for /controller" in x
               for x in unapplied_sections(args, "controller", "/rig1/controller"))
    assert unapplied_sections(args, "camera", "/camera/camera") == []
    assert unapplied_sections([*argv[:5], str(hw)], "camera", "/rig1/camera") == []


def test_the_camera_says_how_many_of_the_drivers_images_reached_it() -> None:
    """From the received stamps: 200 Hz for 5 s, all of the first half, a third of the
    second (a busy node keeping the newest): about 999 sent, 667 received (67 %)."""
    from collections import deque  # noqa: PLC0415

    from bfr_camera.camera_node import CameraNode  # noqa: PLC0415

    period = 5_000_000
    stamps = [k * period for k in range(500)] + [k * period for k in range(500, 1001, 3)]
    got = CameraNode._describe_received(SimpleNamespace(stamps=deque(stamps)))
    assert got == ("images received 667 of about 999 the driver sent over the last 5.0 s "
                   "(67 %, its period 5.00 ms from the stamps)"), got
    # host-stamped: +-0.5 ms of jitter on every stamp, every image received
    rng = np.random.default_rng(3)
    jittered = np.arange(1000) * period + rng.integers(-500_000, 500_001, 1000)
    got = CameraNode._describe_received(SimpleNamespace(stamps=deque(jittered.tolist())))
    share = float(got.split("(")[1].split(" %")[0])
    assert 99 <= share <= 101, got
    # Gaussian host-stamp jitter of 1 ms with 94 % received (a probe written apart read 3.10
    # ms and 60 % from the gaps), and of 2 ms, where the stamps cannot tell the period
    kept = np.sort(rng.choice(4000, 3760, replace=False))
    host = kept * period + np.rint(1e6 * rng.standard_normal(kept.size)).astype(np.int64)
    got = CameraNode._describe_received(SimpleNamespace(stamps=deque(host.tolist())))
    assert "its period 5.00 ms from the stamps" in got, got
    assert 93 <= float(got.split("(")[1].split(" %")[0]) <= 95, got
    host = kept * period + np.rint(2e6 * rng.standard_normal(kept.size)).astype(np.int64)
    got = CameraNode._describe_received(SimpleNamespace(stamps=deque(host.tolist())))
    assert got.startswith("images received 2000 over the last") and "cannot be told" in got, got
    few = CameraNode._describe_received(SimpleNamespace(stamps=deque(stamps[:5])))
    assert few == "images received: too few to judge"


def test_command_line_params_are_the_ros_args_assignments() -> None:
    """``-p`` / ``--param`` of every ``--ros-args`` block, in order, with a node prefix when
    given (``-p camera:markers.rate:=30.0``); the program's own arguments and other ROS
    arguments are not taken; values are read as rcl reads them (YAML)."""
    argv = ["node", "-p", "x:=1", "--ros-args", "-p", "markers.rate:=30.0", "--params-file",
            "f.yaml", "-r", "__ns:=/rig1", "--param", "camera:input.joint_name:=joint1", "--",
            "-p", "y:=2", "--ros-args", "-p", "loop.trigger:=observation", "-p", "broken"]
    assert command_line_params(argv) == [("", "markers.rate", "30.0"),
                                         ("camera", "input.joint_name", "joint1"),
                                         ("", "loop.trigger", "observation")]
    assert _command_line_value("30.0") == 30.0 and _command_line_value("30") == 30
    assert _command_line_value("true") is True and _command_line_value("[1.0, 2]") == [1.0, 2]
    assert _command_line_value("joint1") == "joint1" and _command_line_value("") == ""
    assert _command_line_value("{a: 1}") == "{a: 1}"


def test_joint_picker_names_the_nodes_parameter() -> None:
    """The hint names the parameter as the node has it (a probe read "(parameter
    joint_name)" where the parameters are loop.joint_name and input.joint_name)."""
    picker = JointPicker("frame_joint", "loop.joint_name")
    assert picker.index(["joint1"], (0.0,)) is None
    assert picker.missing().endswith("(parameter loop.joint_name)")
