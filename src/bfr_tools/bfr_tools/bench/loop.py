"""``bfr bench`` section ``loop``: the node suite over DDS, every node in its own process.

Started as ``bfr rig --realtime`` starts them (the ament executables,
:class:`bfr_tools.rig.NodeSpec`; at nice -10, each in a session of its own with that
autogroup niceness, where permitted: other sessions' work on a shared machine then disturbs
the figures less), without the recorder, on a private graph (a ``ROS_DOMAIN_ID`` claimed
with the same lock files as the tests' helpers, ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``):

- ``simulator_node`` in real-time mode (``sim.mode:=realtime``; RK4 1 kHz, camera 200 Hz
  640x480 mono8, joint_states 1 kHz (``joint_states.rate:=1000``, the rig's encoder rate),
  sim_truth 200 Hz), the ball started on the controller's orbit
  (:func:`bfr_tools.rig.orbit_start`);
- the camera and controller nodes with ``use_sim_time:=true``, the controller triggered by
  each ball observation (``loop.trigger:=observation``: the camera's rate), as ``bfr rig
  --realtime`` starts them (:func:`bfr_tools.rig.loop_specs`): composed in one process
  (``bfr_tools loop_node``) pinned to one CPU (:func:`bfr_tools.rig.loop_cpu_default`),
  or with ``BenchOptions.loop_separate`` as two processes pinned to that CPU.

The bench process subscribes to ``sim_truth``, ``camera/camera_info``, ``ball_observation``,
``controller_state`` and ``effort_controller/commands`` (not to the images) and keeps, for
each message, its stamp and the DDS source and reception timestamps (``MessageInfo``; one
system clock on one machine). After the loop has been ROLLING for a settling time it
measures ``loop_duration`` seconds, split into ``loop_windows`` windows (each window is one
"repeat"), then stops every node with SIGINT to its own pid.

Per window:

- frames: simulator states/frames published (the 200 Hz stamps of ``sim_truth`` and
  ``camera_info``, by source time);
- camera node rate: ball observations received per wall-clock second;
- control rate: effort commands received per wall-clock second;
- latency: for each control step, the frame it answers is ``stamp - ball_age`` of its
  ``controller_state`` (the step's newest fix); latency = reception of the effort command
  published with that state (the command just before it, by source time) minus the
  publication of the frame's simulator state (the earliest source time of that stamp's
  ``sim_truth`` / ``camera_info``, published in the same simulator step as the image).
  Only the first answer of each frame counts; median and 99th percentile;
- dropped frames: frames without a ball observation of the same stamp; frames with an
  observation but no control step of their own (two observations merged into one step)
  are counted separately.

CPU use of each node process over the measurement (``/proc/<pid>/stat``) is reported in
the notes: it shows which process limits the loop. The budgeted CPU figure is the camera
and controller nodes' CPU time (user + system: the composed process, or both processes)
per *simulated* second, ``cpu / (t_sim_end - t_sim_start)`` [cores]: what the two nodes
would take of a machine at real time, whatever the simulator's pace on this one (a shared
machine that slows the simulator down does not make it look cheaper or dearer).
"""

from __future__ import annotations

import itertools
import math
import os
import re
import shutil
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from bfr_ros.domain import claim_domain_id
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from std_msgs.msg import Float64MultiArray

from bfr_interfaces.msg import BallObservation, ControllerState, SimTruth
from bfr_tools.bench.common import (
    BenchOptions,
    Budget,
    Figure,
    FigureSpec,
    Progress,
    not_measured,
)
from bfr_tools.rig import (
    LOOP_NODE,
    NODES,
    NodeSpec,
    loop_layout,
    loop_specs,
    may_raise_priority,
    orbit_start,
)
from bfr_tools.run import executable_path

__all__ = ["SPECS", "run"]

_NS = 1_000_000_000
_FRAME_NS = 5_000_000  # 200 Hz
_NICE = -10  # the nodes' niceness where permitted, as ``bfr rig --realtime`` starts them

SPECS: list[FigureSpec] = [
    FigureSpec("loop.latency_median_ms",
               "loop latency state -> torque, median (camera 200 Hz)", "ms", Budget("<", 5.0)),
    FigureSpec("loop.latency_p99_ms", "loop latency state -> torque, 99th percentile", "ms"),
    FigureSpec("loop.dropped_frames", "dropped frames (no observation), 200 Hz mono8", "count",
               Budget("==", 0.0)),
    FigureSpec("loop.merged_frames", "frames without a control step of their own", "count"),
    FigureSpec("loop.camera_rate_hz", "camera node sustained frame rate (observations)", "Hz"),
    FigureSpec("loop.control_rate_hz", "sustained control rate (effort commands)", "Hz"),
    FigureSpec("loop.frame_rate_hz", "simulator frames published (real-time mode)", "Hz"),
    FigureSpec("loop.rolling_pct", "control steps with the ball under control (ROLLING)", "%"),
    FigureSpec("loop.cpu_camera_controller",
               "camera + controller CPU per simulated second (200 Hz camera, 1 kHz encoder)",
               "cores", Budget("<", 0.5, source="issue 17")),
    FigureSpec("loop.cpu_camera", "camera node CPU per simulated second", "cores"),
    FigureSpec("loop.cpu_controller", "controller node CPU per simulated second", "cores"),
    FigureSpec("loop.cpu_simulator", "simulator node CPU per simulated second", "cores"),
    FigureSpec("loop.real_time_factor", "simulated / wall time over the measurement", "x"),
]
_BY_KEY = {s.key: s for s in SPECS}


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process [s] (NaN if gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return math.nan


class _Recorder:
    """The bench's own participant: subscriptions that keep stamps and DDS timestamps."""

    def __init__(self) -> None:


        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("bfr_bench", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
        self.recording = False
        self.data: dict[str, list[tuple]] = {k: [] for k in ("truth", "obs", "state", "cmd")}
        self.modes: list[int] = []

        def stamp(msg: Any) -> int:
            return int(msg.header.stamp.sec) * _NS + int(msg.header.stamp.nanosec)

        def on_state(msg: Any, info: Any) -> None:
            self.modes.append(int(msg.mode))
            if self.recording:
                self.data["state"].append((int(info["source_timestamp"]),
                                           int(info["received_timestamp"]), stamp(msg),
                                           float(msg.ball_age), int(msg.mode)))

        def raw_stamp(name: str) -> Callable[[bytes, Any], None]:
            store = self.data[name]

            def cb(data: bytes, info: Any) -> None:
                if self.recording:  # CDR: 4-byte encapsulation, then header.stamp sec, nsec
                    sec, nsec = struct.unpack_from("<iI", data, 4)
                    store.append((int(info["source_timestamp"]),
                                  int(info["received_timestamp"]), sec * _NS + nsec))
            return cb

        def on_cmd(data: bytes, info: Any) -> None:
            if self.recording:
                self.data["cmd"].append((int(info["source_timestamp"]),
                                         int(info["received_timestamp"])))

        n = self.node
        self.subs = {
            "truth": n.create_subscription(SimTruth, "sim_truth", raw_stamp("truth"), deep,
                                           raw=True),
            "obs": n.create_subscription(BallObservation, "ball_observation", raw_stamp("obs"),
                                         deep, raw=True),
            "state": n.create_subscription(ControllerState, "controller_state", on_state, deep),
            "cmd": n.create_subscription(Float64MultiArray, "effort_controller/commands",
                                         on_cmd, deep, raw=True),
        }

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, pred: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not pred():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def matched(self) -> dict[str, int]:
        return {k: s.get_publisher_count() for k, s in self.subs.items()}

    def close(self) -> None:

        self.executor.shutdown()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)


def _window_figures(d: dict[str, list[tuple]], w0: int, w1: int) -> dict[str, Any]:
    """The loop's figures over the wall-clock window [w0, w1) (system-clock ns).

    ``d`` holds, per topic, tuples ``(source ns, received ns, ...)``: ``truth`` and ``obs``
    with the stamp, ``state`` with stamp, ball_age [s] and mode, ``cmd`` sorted by source.
    """
    span = (w1 - w0) / _NS
    frames = {st: src for src, _, st in d["truth"] if w0 <= src < w1}
    sim_span = (max(frames) - min(frames)) / _NS if len(frames) > 1 else math.nan
    obs_stamps = {o[2] for o in d["obs"]}
    dropped = sum(1 for st in frames if st not in obs_stamps)
    n_obs = sum(1 for o in d["obs"] if w0 <= o[1] < w1)
    cmd = d["cmd"]
    n_cmd = sum(1 for c in cmd if w0 <= c[1] < w1)
    cmd_src = np.array([c[0] for c in cmd], dtype=np.int64)
    cmd_rcv = np.array([c[1] for c in cmd], dtype=np.int64)
    answered: dict[int, tuple[int, int]] = {}
    modes = []
    for src, _, st, age, mode in d["state"]:
        if w0 <= src < w1:
            modes.append(mode)
        if not math.isfinite(age):
            continue
        fs = round((st - round(age * _NS)) / 1e6) * 1_000_000  # frames lie on the 1 ms grid
        if fs not in frames or fs in answered:
            continue
        i = int(np.searchsorted(cmd_src, src, side="right")) - 1
        if i < 0 or src - cmd_src[i] > 5_000_000:
            continue
        answered[fs] = (int(cmd_rcv[i]), mode)
    lat = np.array([(answered[st][0] - frames[st]) / 1e6 for st in answered])
    lat_roll = np.array([(answered[st][0] - frames[st]) / 1e6 for st in answered
                         if answered[st][1] == 1])
    merged = sum(1 for st in frames if st in obs_stamps and st not in answered)
    return {
        "frame_rate_hz": len(frames) / span,
        "camera_rate_hz": n_obs / span,
        "control_rate_hz": n_cmd / span,
        "dropped_frames": float(dropped),
        "merged_frames": float(merged),
        "latency_median_ms": float(np.median(lat)) if lat.size else math.nan,
        "latency_p99_ms": float(np.percentile(lat, 99)) if lat.size else math.nan,
        "latency_rolling_median_ms": float(np.median(lat_roll)) if lat_roll.size else math.nan,
        "rolling_pct": 100.0 * float(np.mean(np.array(modes) == 1)) if modes else 0.0,
        "latency_count": float(lat.size),
        "frames": float(len(frames)),
        "sim_span": sim_span,
        "real_time_factor": sim_span / span if span > 0 else math.nan,
        "_lat": lat,
    }


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``loop`` section (module docstring)."""
    try:
        for pkg, exe in (NODES["simulator"], NODES["camera"], NODES["controller"], LOOP_NODE):
            executable_path(pkg, exe)
    except Exception as exc:  # noqa: BLE001
        return [not_measured(s, f"node suite missing ({type(exc).__name__}: {exc})")
                for s in SPECS]
    domain = claim_domain_id()
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    env = dict(os.environ)
    env.update(PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0")
    log_dir = (Path(opts.keep) / "loop" if opts.keep
               else Path(tempfile.mkdtemp(prefix="bfr-bench-")))
    log_dir.mkdir(parents=True, exist_ok=True)
    start = orbit_start(0.3, 0.05)
    sim_args = ["-p", "sim.mode:=realtime", "-p", "start.wait_subscribers:=2",
                "-p", "truth.publish:=true", "-p", "joint_states.rate:=1000.0"]
    sim_args += [a for k, v in start.items() for a in ("-p", f"{k}:={v!r}")]
    spec_cls = NodeSpec
    if opts.profile:
        Path(opts.profile).mkdir(parents=True, exist_ok=True)
        prof_dir = Path(opts.profile).resolve()

        class _Profiled(NodeSpec):  # the same command under cProfile, timed by CPU time
            def command(self) -> list[str]:
                return [sys.executable, "-m", "bfr_tools.bench.cpu_profile",
                        str(prof_dir / f"{self.name}.prof"), *super().command()]

        spec_cls = _Profiled
    composed, cpu = loop_layout("realtime", "separate" if opts.loop_separate else "auto")
    loop = loop_specs({"camera": ["-p", "use_sim_time:=true"],
                       "controller": ["-p", "use_sim_time:=true",
                                      "-p", "loop.trigger:=observation"]},
                      composed=composed, cpu=cpu)
    nodes = {n: spec_cls(n, s.package, s.executable, s.ros_args, rename=s.rename)
             for n, s in loop.items()}
    nodes["simulator"] = spec_cls("simulator", *NODES["simulator"], sim_args)
    loop_names = list(loop)
    rec = None
    try:
        nice = _NICE if may_raise_priority(_NICE) else 0
        say(f"loop: ROS_DOMAIN_ID {domain}; starting the camera and controller nodes "
            f"({'composed' if composed else 'two processes'}, "
            f"{f'CPU {cpu}' if cpu >= 0 else 'unpinned'}, nice {nice}"
            f"{', sessions of their own' if nice else ''})")
        rec = _Recorder()
        for name in loop_names:
            nodes[name].start(log_dir, env, nice)
        return _measure(opts, say, rec, nodes, nice, cpu)
    finally:
        for spec in reversed(list(nodes.values())):  # the simulator first
            spec.stop()
        if rec is not None:
            rec.close()
        if not opts.keep:
            shutil.rmtree(log_dir, ignore_errors=True)


def _dead(nodes: dict[str, Any]) -> str:
    for name, spec in nodes.items():
        if spec.process is not None and spec.returncode is not None:
            return f"{name} node exited ({spec.returncode}): {spec.tail(8)}"
    return ""


def _measure(opts: BenchOptions, say: Progress, rec: _Recorder,
             nodes: dict[str, Any], nice: int, cpu: int) -> list[Figure]:
    # the simulator starts only once the camera and controller nodes are up (their
    # publishers matched), so that the ball is not left alone while they load
    ready = rec.spin_until(lambda: (rec.matched()["obs"] > 0 and rec.matched()["state"] > 0
                                    and rec.matched()["cmd"] > 0) or bool(_dead(nodes)), 90.0)
    if not ready or _dead(nodes):
        why = _dead(nodes) or f"camera/controller not up within 90 s: {rec.matched()}"
        return [not_measured(s, why) for s in SPECS]
    rec.spin_for(1.0)
    say("loop: camera and controller up; starting the simulator (real time)")
    log_dir = next(iter(nodes.values())).log_path.parent
    nodes["simulator"].start(log_dir, dict(os.environ, PYTHONUNBUFFERED="1"), nice)
    flowing = rec.spin_until(lambda: (min(rec.matched().values()) > 0 and len(rec.modes) > 10)
                             or bool(_dead(nodes)), 90.0)
    if not flowing or _dead(nodes):
        why = _dead(nodes) or f"no control steps within 90 s (matched: {rec.matched()})"
        return [not_measured(s, why) for s in SPECS]
    rec.spin_for(1.0 if opts.quick else 2.0)  # settle
    pids = {n: s.process.pid for n, s in nodes.items()}
    cpu_marks: list[tuple[int, dict[str, float]]] = []  # (wall ns, cpu seconds per node)
    cpu0 = {n: _cpu_seconds(p) for n, p in pids.items()}
    bench_cpu0 = time.process_time()
    load0 = os.getloadavg()[0]
    say(f"loop: measuring {opts.loop_duration:g} s in {opts.loop_windows} window(s)")
    rec.recording = True
    w0 = time.time_ns()
    cpu_marks.append((w0, cpu0))
    edges_wall = np.linspace(0.0, opts.loop_duration, opts.loop_windows + 1)[1:]
    for e in edges_wall:  # CPU marks at the window edges
        rec.spin_for(max(0.0, w0 / _NS + e - time.time_ns() / _NS))
        cpu_marks.append((time.time_ns(), {n: _cpu_seconds(p) for n, p in pids.items()}))
    w1 = time.time_ns()
    cpu1 = {n: _cpu_seconds(p) for n, p in pids.items()}
    bench_cpu = time.process_time() - bench_cpu0
    rec.spin_for(0.5)  # late observations / commands of frames inside the window
    rec.recording = False
    died = _dead(nodes)
    for spec in reversed(list(nodes.values())):  # the simulator first
        spec.stop()
    sim_log = nodes["simulator"].log_path.read_text(errors="replace")
    behind = len(re.findall(r"behind real time", sim_log))
    composed = "loop" in nodes
    pinned = f"pinned to CPU {cpu}" if cpu >= 0 else "unpinned"
    ctrl_log = nodes["loop" if composed else "controller"].log_path.read_text(errors="replace")
    events = [(m, t) for wall, m, t in re.findall(
        r"\[(\d+\.\d+)\] \[controller\]: (ROLLING|BALL_LOST|FAULT)(?: at t = ([0-9.]+) s)?",
        ctrl_log) if float(wall) * _NS < w1]  # up to the end of the measurement
    history = ", ".join(f"{m} at t = {t} s" if t else m for m, t in events[:6]) or "none"
    d = dict(rec.data)
    d["cmd"] = sorted(rec.data["cmd"], key=lambda c: c[0])
    edges = [m[0] for m in cpu_marks]
    wins = [_window_figures(d, int(a), int(b)) for a, b in itertools.pairwise(edges)]
    for w, (c0, c1) in zip(wins, itertools.pairwise([m[1] for m in cpu_marks]), strict=True):
        for n in nodes:
            w[f"cpu_{n}"] = (c1[n] - c0[n]) / w["sim_span"]
        if composed:  # one process: the two nodes' shares are not told apart
            w["cpu_camera_controller"] = w.pop("cpu_loop")
        else:
            w["cpu_camera_controller"] = w["cpu_camera"] + w["cpu_controller"]
    allw = _window_figures(d, int(w0), int(w1))
    span = (w1 - w0) / _NS
    cpu = {n: 100.0 * (cpu1[n] - cpu0[n]) / span for n in pids}
    cpu["bench"] = 100.0 * bench_cpu / span
    cpu_txt = ", ".join(f"{n} {c:.0f} %" for n, c in cpu.items())
    common = (f"{opts.loop_duration:g} s wall in {opts.loop_windows} window(s); load "
              f"{load0:.2f} at start; nodes at nice {nice}"
              + (" in sessions of their own (as bfr rig --realtime)" if nice else "")
              + f"; CPU (% of one core): {cpu_txt}"
              + (f"; the simulator warned {behind}x that it fell behind real time"
                 if behind else "")
              + (f"; NOTE {died}" if died else "")
              + ("; UNDER cProfile (slower than normal; main-thread CPU time)"
                 if opts.profile else ""))
    lat = allw.pop("_lat")
    for w in wins:
        w.pop("_lat")
    extra = {"windows": wins, "pooled": allw, "cpu_percent": cpu,
             "latency_ms_pooled_quantiles": {
                 str(q): float(np.percentile(lat, q)) for q in (1, 10, 50, 90, 99, 100)}
             if lat.size else {}}
    notes = {
        "latency_median_ms": (
            f"{int(allw['latency_count'])} answered frames; pooled median "
            f"{allw['latency_median_ms']:.2f} ms, p99 {allw['latency_p99_ms']:.2f} ms, "
            + (f"while ROLLING {allw['latency_rolling_median_ms']:.2f} ms; "
               if math.isfinite(allw["latency_rolling_median_ms"])
               else "never ROLLING in the window (the ball was lost: the steps skip only the "
                    "compiled PFL torque, a few microseconds); ")
            + f"effort command "
            f"received (bench) - publication of the frame's simulator state (sim_truth, "
            f"same step as the image); {common}"),
        "dropped_frames": (f"per window; {int(allw['frames'])} frames in total, "
                           f"{int(allw['dropped_frames'])} without a ball observation"),
        "camera_rate_hz": "ball observations received per wall-clock second (nominal 200 Hz)",
        "control_rate_hz": "controller stepped on each observation (loop.trigger observation)",
        "rolling_pct": ("share of control steps in mode ROLLING; 100 % = the ball was under "
                        "control all along (the other figures hold either way); controller "
                        f"mode changes since the start (simulated time): {history}"),
        "cpu_camera_controller": (
            "user + system CPU seconds of the "
            + ("camera and controller composed in one process (bfr_tools loop_node)"
               if composed else "camera and controller processes")
            + f" (/proc) per simulated second of the window (sim_truth stamps), {pinned} as bfr "
            f"rig --realtime runs them; joint_states 1 kHz, camera "
            f"200 Hz 640x480 mono8; load {load0:.2f} at start; the nodes at their default "
            f"process.realtime_priority (SCHED_FIFO where permitted; unpinned, separate and "
            f"normal-scheduled figures: docs/notes/issue-17.md)"),
        **({"cpu_camera": ("not told apart from the controller's: composed in one process "
                           "(bfr bench --loop-separate measures each)"),
            "cpu_controller": "not told apart from the camera's: composed in one process"}
           if composed else {}),
        "real_time_factor": "simulated seconds (sim_truth stamps) per wall-clock second",
    }
    figs = []
    for spec in SPECS:
        key = spec.key.split(".", 1)[1]
        if composed and key in ("cpu_camera", "cpu_controller"):
            figs.append(not_measured(spec, notes[key]))
            continue
        figs.append(Figure(spec, [w[key] for w in wins], note=notes.get(key, ""),
                           extra=extra if key == "latency_median_ms" else {}))
    return figs
