"""``bfr rig``: start the whole emulated rig with one command, record it, summarise the run.

Starts the four nodes as processes exactly as ``ros2 run`` would (the executables
``<prefix>/lib/<pkg>/<exe>`` found through the ament index, ``--ros-args`` for parameters):

1. ``bfr_sim recorder_node`` (unless ``--no-record``): the bag;
2. ``bfr_camera camera_node`` and ``bfr_control controller_node``; with ``--realtime`` both
   composed in one process, ``bfr_tools loop_node``, pinned to one CPU (``--loop``,
   ``--loop-cpu``: :func:`loop_specs`);
3. ``bfr_sim simulator_node``, which waits until the others subscribe, starts the ball on the
   controller's periodic orbit (``--phase``, ``--d-theta``), runs for ``--duration``
   simulated seconds and exits.

With ``--hardware`` the rig is real (docs/hardware.md): the simulator is not started; the
camera and controller nodes (composed, as with ``--realtime``) and the recorder run against
the hardware's topics (``/joint_states``, ``/effort_controller/commands``, the camera
driver's ``--image-topic`` and ``--camera-info-topic``) with hardware.yaml and
``use_sim_time:=false``, for ``--duration`` wall seconds or until Ctrl-C; then they are
stopped with SIGINT and the run is summarised from the bag, as in the emulated modes.

Otherwise every node runs with ``use_sim_time:=true`` (the simulator publishes ``/clock``). In
``--lockstep`` mode (the default) the simulator waits for the controller's answer to every
camera frame, so a run is repeatable whatever the machine's load; ``--realtime`` paces it by
the wall clock like the real rig. Each node's output goes to ``<log-dir>/<node>.log``. When
the simulator is done, or on Ctrl-C, the nodes are stopped with SIGINT (SIGTERM, then
SIGKILL after a grace period), recorder last, and the run's summary is printed from the bag
(:func:`summarize_bag`). A node that dies early stops the run with an error naming it, its
exit status and the end of its log.

Examples::

    scripts/bfr rig --duration 40
    scripts/bfr rig --realtime --duration 20 --record /tmp/run1
    scripts/bfr rig -p simulator:ball.mass:=3.1e-3 -p controller:loop.trigger:=joint_states
    scripts/bfr rig --hardware --camera-params my_camera.yaml --image-topic /cam/image_raw \
        --camera-info-topic /cam/camera_info --duration 60
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import IO, Any

import numpy as np
from bfr_control.constraint import VirtualConstraint
from bfr_control.controller import load_controller_config
from bfr_control.controller_node import CAMERA_MATCHED
from bfr_control.orbit import PeriodicOrbit
from bfr_model.dynamics import RigidModel
from bfr_model.io.bag import make_typestore, read_bag_messages
from bfr_model.param_file import config_path
from bfr_model.params import load_params
from bfr_ros.domain import claim_domain_id
from bfr_ros.node_common import parse_published

from bfr_tools.run import executable_path

__all__ = ["NodeSpec", "RigError", "format_summary", "main", "may_raise_priority", "orbit_start",
           "run_warnings", "set_autogroup_nice", "summarize_bag"]

_NS = 1_000_000_000
NODES = {  # name -> (package, executable)
    "recorder": ("bfr_sim", "recorder_node"),
    "camera": ("bfr_camera", "camera_node"),
    "controller": ("bfr_control", "controller_node"),
    "simulator": ("bfr_sim", "simulator_node"),
}


class RigError(RuntimeError):
    """The rig could not be run; the message says which node and why."""


def orbit_start(phase: float = 0.3, d_theta: float = 0.05, rig_params: str | None = None,
                controller_params: str | None = None) -> dict[str, float]:
    """The simulator's ``initial.*`` parameters for a ball on the controller's orbit.

    The state on the controller's periodic orbit at contact angle ``phase`` [rad], the frame
    then turned by ``d_theta`` [rad] (a small error the controller must remove), as the
    closed-loop harness (:func:`bfr_sim.closed_loop.orbit_initial_state`) starts it.

    Parameters
    ----------
    phase : float
        Contact angle phi at t = 0 [rad].
    d_theta : float
        Frame angle offset from the orbit [rad].
    rig_params, controller_params : str, optional
        rig.yaml and controller.yaml to use (default: the shipped ones).

    Returns
    -------
    dict
        ``{"initial.theta": ..., "initial.phi": ..., "initial.theta_dot": ...,
        "initial.phi_dot": ...}`` [rad, rad/s].
    """
    params = load_params(rig_params)
    cfg = load_controller_config(controller_params)
    model = RigidModel(params)
    orbit = PeriodicOrbit(model, VirtualConstraint(model, cfg.constraint), cfg.orbit)
    x = np.asarray(orbit.state(float(phase)), dtype=float)
    x[0] += float(d_theta)
    return dict(zip(("initial.theta", "initial.phi", "initial.theta_dot", "initial.phi_dot"),
                    (float(v) for v in x), strict=True))


# -- processes ---------------------------------------------------------------------------------
@dataclass
class NodeSpec:
    """One node process of the rig."""

    name: str
    package: str
    executable: str
    ros_args: list[str] = field(default_factory=list)
    process: subprocess.Popen | None = None
    log_path: Path | None = None
    log: IO[bytes] | None = None
    #: Name the process's node ``name`` (``-r __node:=``); False for a process of several
    #: nodes (the remap would give them all one name).
    rename: bool = True

    def command(self) -> list[str]:
        """Command line: the ament executable and its ``--ros-args``."""
        exe = executable_path(self.package, self.executable)
        name = ["-r", f"__node:={self.name}"] if self.rename else []
        return [str(exe), "--ros-args", *name, *self.ros_args]

    def start(self, log_dir: Path, env: dict[str, str], nice: int = 0) -> None:
        """Start the process with stdout and stderr into ``<log_dir>/<name>.log``.

        ``nice`` < 0 raises its scheduling priority before it runs (every thread it starts
        inherits it), where the system permits; else it runs at the normal priority. With a
        raised priority the node also runs in a session of its own whose autogroup gets the
        same niceness (:func:`set_autogroup_nice`): where the kernel groups processes by
        session (``/proc/sys/kernel/sched_autogroup_enabled``), a process's niceness ranks
        it only within its session, and another user's busy session shares the CPUs equally
        with the rig's whatever the nodes' niceness.
        """
        self.log_path = log_dir / f"{self.name}.log"
        self.log = self.log_path.open("wb")
        command = self.command()
        tool = shutil.which("nice") if nice else None
        if tool:  # nice(1) execs the node: same pid, signals reach it
            command = [tool, "-n", str(nice), *command]
        self.process = subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL,
                                        stdout=self.log, stderr=subprocess.STDOUT,
                                        start_new_session=nice < 0)
        if nice < 0:
            set_autogroup_nice(self.process.pid, nice)

    @property
    def returncode(self) -> int | None:
        """Exit status, or None while running."""
        return None if self.process is None else self.process.poll()

    def tail(self, lines: int = 25) -> str:
        """The last lines of the node's log."""
        if self.log_path is None or not self.log_path.exists():
            return "(no log)"
        if self.log is not None:
            self.log.flush()
        text = self.log_path.read_text(errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def stop(self, grace: float = 10.0) -> int | None:
        """SIGINT to the process, then SIGTERM and SIGKILL after ``grace`` seconds each."""
        p = self.process
        if p is None:
            return None
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
            if p.poll() is not None:
                break
            p.send_signal(sig)
            try:
                p.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue
        if self.log is not None:
            self.log.close()
            self.log = None
        return p.poll()


#: The composed loop: the camera and controller nodes in one process (bfr_tools/loop_node).
LOOP_NODE = ("bfr_tools", "loop_node")


def loop_cpu_default() -> int:
    """The CPU a real-time loop is pinned to: the last this process may use (-1 if only one).

    The other CPUs are left to the simulator (the plant), the recorder and the machine's
    other work; the loop's CPU is shared only when they need more than those.
    """
    cpus = sorted(os.sched_getaffinity(0))
    return cpus[-1] if len(cpus) > 1 else -1


def loop_layout(mode: str, loop: str = "auto", cpu: int | None = None) -> tuple[bool, int]:
    """How the camera and controller run: (composed in one process, CPU they are pinned to).

    ``loop`` ``auto``: composed in real-time mode (a deadline: docs/hardware.md,
    "Scheduling"), two processes in lock-step (no deadline; a test there stops the controller
    alone); ``composed`` or ``separate`` as said. ``cpu`` None: :func:`loop_cpu_default` in
    real-time mode, -1 (no pinning) in lock-step. The one rule for ``bfr rig``, the launch
    file and the bench.

    Raises
    ------
    ValueError
        If ``loop`` is not one of auto, composed, separate.
    """
    if loop not in ("auto", "composed", "separate"):
        raise ValueError(f"loop: expected auto, composed or separate, got {loop!r}")
    realtime = mode != "lockstep"
    composed = loop == "composed" or (loop == "auto" and realtime)
    if cpu is None:
        cpu = loop_cpu_default() if realtime else -1
    return composed, int(cpu)


def loop_specs(per: Mapping[str, Sequence[str]], *, composed: bool,
               cpu: int) -> dict[str, NodeSpec]:
    """The process(es) of the control loop: the camera and controller nodes.

    Parameters
    ----------
    per : mapping
        ``--ros-args`` of ``camera`` and ``controller`` as if each ran alone (``-p`` and
        ``--params-file`` only).
    composed : bool
        One process (``bfr_tools loop_node``, key ``loop``) instead of two (``camera``,
        ``controller``). Composed, each node's ``-p name:=value`` becomes
        ``-p <node>:name:=value`` (rcl gives it to that node only); every parameter file
        reaches both nodes (each accepts the other's names), each file once, the camera's
        first.
    cpu : int
        CPU both nodes are pinned to (``process.cpu``, before the given values, which may
        override it), -1 for none.

    Raises
    ------
    RigError
        If an argument is neither ``-p NAME:=VALUE`` nor ``--params-file FILE``.
    """
    pin = ["-p", f"process.cpu:={cpu}"] if cpu != -1 else []
    if not composed:
        return {n: NodeSpec(n, *NODES[n], [*pin, *per[n]]) for n in ("camera", "controller")}
    values: list[str] = []
    files: list[str] = []
    remaps: list[str] = []
    for n in ("camera", "controller"):
        args = [*pin, *per[n]]
        for flag, item in zip(args[::2], args[1::2], strict=False):
            if flag in ("-p", "--param") and ":=" in item:
                values += ["-p", f"{n}:{item}"]
            elif flag == "--params-file":
                files += [] if item in files else [item]
            elif flag in ("-r", "--remap") and ":=" in item:
                remaps += [] if item in remaps else [item]
            else:
                raise RigError(f"{n}: only -p NAME:=VALUE, --params-file FILE and -r FROM:=TO "
                               f"can be given to the composed loop, got {flag} {item}")
        if len(args) % 2:
            raise RigError(f"{n}: {args[-1]} without its value")
    args = [*(a for f in files for a in ("--params-file", f)), *values,
            *(a for r in remaps for a in ("-r", r))]
    return {"loop": NodeSpec("loop", *LOOP_NODE, args, rename=False)}


def _describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


#: The camera's and controller's topics the recorder must have matched before the simulation
#: starts (the simulator's own topics are held by its start gate, ``start.wait_*``).
RECORDER_MATCH_TOPICS = ("/ball_observation", "/controller_state", "/effort_controller/commands")


def _wait_recorder_matched(recorder: NodeSpec, topics: tuple[str, ...],
                           timeout: float = 30.0, then: str = "starting the simulation") -> bool:
    """Wait until the recorder's log says it matched a publisher on each of ``topics``.

    A reliable, volatile subscription gets nothing its publisher sent before the two matched,
    and matching can lag discovery by seconds: the recorder once missed the controller's first
    0.125 s (25 states) although it had subscribed 2 s before the simulation started
    (docs/notes/issue-17.md). The simulator starts only after this (or after ``timeout``
    seconds, with a note).
    """
    t0 = time.monotonic()
    want = [f"matched {t}:" for t in topics]
    while time.monotonic() - t0 < timeout:
        text = (recorder.log_path.read_text(errors="replace")
                if recorder.log_path is not None and recorder.log_path.exists() else "")
        if all(w in text for w in want):
            return True
        if recorder.returncode is not None:
            return False
        time.sleep(0.1)
    print(f"bfr rig: note: the recorder had not matched {', '.join(topics)} within "
          f"{timeout:g} s; {then} anyway (the bag may miss their start)", flush=True)
    return False


def set_autogroup_nice(pid: int, nice: int) -> bool:
    """Set the niceness of the scheduler autogroup of ``pid``'s session; False if not possible.

    On kernels with autogroup scheduling the CPU is shared first among sessions (autogroups),
    by the autogroup's niceness (``/proc/<pid>/autogroup``, 0 by default), and only then among
    the processes of a session by their own niceness. Lowering it needs the same permission
    as lowering a process's niceness. No autogroup file (kernel without autogroups): False.
    """
    try:
        Path(f"/proc/{pid}/autogroup").write_text(f"{int(nice)}\n")
    except OSError:
        return False
    return True


def may_raise_priority(nice: int) -> bool:
    """Whether this process may start children at niceness ``nice`` (< 0: CAP_SYS_NICE)."""
    try:
        return os.getpriority(os.PRIO_PROCESS, 0) + nice >= -20 and (
            os.geteuid() == 0 or nice >= 0)
    except OSError:
        return False


def published_counts(nodes: dict[str, NodeSpec]) -> dict[str, int]:
    """Messages each node says it published, per resolved topic (from their logs)."""
    out: dict[str, int] = {}
    for name, spec in nodes.items():
        if name == "recorder" or spec.log_path is None or not spec.log_path.exists():
            continue
        out.update(parse_published(spec.log_path.read_text(errors="replace")))
    return out


def _wall_stats(log_path: Path | None) -> tuple[float, float] | None:
    """(wall seconds, real-time factor) from the simulator's last log line, if present."""
    if log_path is None or not log_path.exists():
        return None
    found = re.findall(r"after ([0-9.]+) s wall \(real-time factor ([0-9.]+)\)",
                       log_path.read_text(errors="replace"))
    return (float(found[-1][0]), float(found[-1][1])) if found else None


# -- the bag's summary -------------------------------------------------------------------------
#: ``ControllerState.mode`` codes.
_MODE_NAMES = {0: "WAITING", 1: "ROLLING", 2: "BALL_LOST", 3: "FAULT"}
_ROLLING = 1


def _stamps(msgs: list[Any]) -> np.ndarray:
    """Header stamps of messages [s]."""
    return np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in msgs])


def _rate(t: np.ndarray) -> float:
    """Mean rate of sorted stamps ``t`` [s] over their own span [Hz] (0 for fewer than two)."""
    return float((t.size - 1) / (t[-1] - t[0])) if t.size > 1 and t[-1] > t[0] else 0.0


@dataclass(frozen=True, kw_only=True)
class _BagRun:
    """The decoded messages of a rig run that its summary reads (stamps in [s]).

    Attributes
    ----------
    truth, truth_t : list, ndarray
        ``SimTruth`` messages and their stamps.
    states, state_t : list, ndarray
        ``ControllerState`` messages and their stamps.
    mode : ndarray of int
        The controller's mode code per state message.
    obs, obs_t : list, ndarray
        ``BallObservation`` messages and their (exposure) stamps.
    t0, t1 : float
        First and last instant of the run (joint_states, truth, controller states; NaN if
        none of them was recorded).
    """

    truth: list[Any]
    truth_t: np.ndarray
    states: list[Any]
    state_t: np.ndarray
    mode: np.ndarray
    obs: list[Any]
    obs_t: np.ndarray
    t0: float
    t1: float

    @classmethod
    def decode(cls, by_topic: dict[str, list[Any]]) -> _BagRun:
        """Deserialise the summary's topics from the raw messages of each topic."""
        store = make_typestore()

        def decode(topic: str) -> list[Any]:
            return [store.deserialize_cdr(m.data, m.msgtype) for m in by_topic.get(topic, [])]

        truth, states, obs = (decode("sim_truth"), decode("controller_state"),
                              decode("ball_observation"))
        js_t = np.array([m.log_time for m in by_topic.get("joint_states", [])],
                        dtype=float) / _NS
        t_all = [a for a in (js_t, _stamps(truth), _stamps(states)) if a.size]
        return cls(truth=truth, truth_t=_stamps(truth), states=states,
                   state_t=_stamps(states), mode=np.array([s.mode for s in states], dtype=int),
                   obs=obs, obs_t=_stamps(obs),
                   t0=min(float(a.min()) for a in t_all) if t_all else math.nan,
                   t1=max(float(a.max()) for a in t_all) if t_all else math.nan)


def _topic_summary(by_topic: dict[str, list[Any]]) -> dict[str, dict[str, Any]]:
    """Per topic (with its leading ``/``): message count, rate [Hz] of its log times, type."""
    topics: dict[str, dict[str, Any]] = {}
    for topic, msgs in sorted(by_topic.items()):
        t = np.sort(np.array([m.log_time for m in msgs], dtype=float)) / _NS
        topics["/" + topic] = {"count": len(msgs), "rate": _rate(t), "type": msgs[0].msgtype}
    return topics


def _loop_inputs(by_topic: dict[str, list[Any]]) -> dict[str, int]:
    """Messages of each loop node's inputs recorded while it was publishing.

    ``joint_states`` and ``ball_observation`` within the span of ``controller_state``,
    camera_info within that of ``ball_observation`` (by log time): the recorder runs before
    and after the nodes, so the whole bag's counts would hold samples no node could answer.
    """
    def span(topic: str) -> tuple[int, int] | None:
        t = [m.log_time for m in by_topic.get(topic, [])]
        return (min(t), max(t)) if t else None

    def within(msgs: list[Any], sp: tuple[int, int] | None) -> int:
        return 0 if sp is None else sum(sp[0] <= m.log_time <= sp[1] for m in msgs)

    info = [m for t, msgs in by_topic.items() if t.endswith("camera_info") for m in msgs]
    states, seen = span("controller_state"), span("ball_observation")
    return {"joint_states": within(by_topic.get("joint_states", []), states),
            "ball_observation": within(by_topic.get("ball_observation", []), states),
            "camera_info": within(info, seen)}


def _mode_summary(run: _BagRun) -> dict[str, Any]:
    """Steps per mode, the final mode, the control-loop rate and the first ROLLING step."""
    mode, ts = run.mode, run.state_t
    rolling = np.nonzero(mode == _ROLLING)[0]
    return {
        "modes": {_MODE_NAMES.get(k, str(k)): int(np.sum(mode == k)) for k in np.unique(mode)},
        "final_mode": _MODE_NAMES.get(int(mode[-1]), "?") if mode.size else None,
        "loop_rate": _rate(ts),
        "rolling_from": float(ts[rolling[0]]) if rolling.size else None,
    }


def _rolling_until(run: _BagRun, start: float) -> float:
    """End of the rolling that began at ``start`` [s].

    The first later non-ROLLING step or true ``phi_dot <= 0``, whichever comes first; the
    run's end if neither.
    """
    ts = run.state_t
    until = run.t1
    left = np.nonzero((ts > start) & (run.mode != _ROLLING))[0]
    if left.size:
        until = float(ts[left[0]])
    if run.truth:
        tt = run.truth_t
        stopped = np.nonzero((tt > start) & (np.array([s.phi_dot for s in run.truth]) <= 0))[0]
        if stopped.size:
            until = min(until, float(tt[stopped[0]]))
    return until


def _mean_phi_dot(run: _BagRun, start: float, until: float) -> dict[str, Any]:
    """Mean phi_dot [rad/s] over [start, until]: the truth's, else the controller's estimate."""
    if run.truth:
        tt = run.truth_t
        ph = np.array([s.phi for s in run.truth])
        w = (tt >= start) & (tt <= until)
        mean = (float((ph[w][-1] - ph[w][0]) / (tt[w][-1] - tt[w][0]))
                if np.count_nonzero(w) > 1 else math.nan)
        return {"mean_phi_dot": mean, "mean_phi_dot_source": "sim_truth"}
    ts = run.state_t
    sel = (ts >= start) & (ts <= until)
    pd = np.array([s.phi_dot for s in run.states])
    return {"mean_phi_dot": float(np.nanmean(pd[sel])) if sel.any() else math.nan,
            "mean_phi_dot_source": "controller estimate"}


def _rolling_summary(run: _BagRun, rolling_from: float | None) -> dict[str, Any]:
    """How long the ball rolled under control from ``rolling_from`` [s], how well, how fast.

    RMS of y [rad] and z [rad/s] over the last half of the rolling time; without a ROLLING
    step the figures are empty (0 s, NaN).
    """
    if rolling_from is None:
        return {"rolling_until": None, "rolling_time": 0.0, "kept_rolling": False,
                "mean_phi_dot": math.nan, "rms_y": math.nan, "rms_z": math.nan}
    start = rolling_from
    until = _rolling_until(run, start)
    ts = run.state_t
    half = (ts >= start) & (ts <= until) & (ts >= start + 0.5 * (until - start))
    y = np.array([s.y for s in run.states])
    z = np.array([s.z for s in run.states])
    return {
        "rolling_until": until,
        "rolling_time": until - float(start),
        "kept_rolling": bool(until >= run.t1 - 1e-6 and run.mode[-1] == _ROLLING),
        "rms_y": float(np.sqrt(np.nanmean(y[half] ** 2))) if half.any() else math.nan,
        "rms_z": float(np.sqrt(np.nanmean(z[half] ** 2))) if half.any() else math.nan,
        **_mean_phi_dot(run, start, until),
    }


def _camera_summary(run: _BagRun) -> dict[str, Any]:
    """The camera's figures: observation rate [Hz], frames, valid fraction, processing time.

    The processing time is the median [ms]; with a truth, the median error [mm] of the valid
    fixes against it at the same exposure stamps is added.
    """
    obs, ot = run.obs, run.obs_t
    out: dict[str, Any] = {
        "camera_rate": _rate(ot),
        "camera_frames": len(obs),
        "camera_valid_fraction": float(np.mean([o.valid for o in obs])) if obs else 0.0,
        "camera_processing_ms": (float(np.median([o.processing_time for o in obs])) * 1e3
                                 if obs else math.nan),
    }
    if run.truth and obs:  # camera accuracy against the truth at the same exposure stamps
        tt, truth = run.truth_t, run.truth
        idx = np.searchsorted(tt, ot)
        ok = (idx < tt.size) & np.array([o.valid for o in obs])
        ok[ok] &= np.abs(tt[idx[ok]] - ot[ok]) < 1e-6
        if ok.any():
            err = [math.hypot(obs[i].x - truth[idx[i]].ball_x, obs[i].y - truth[idx[i]].ball_y)
                   for i in np.nonzero(ok)[0]]
            out["camera_error_mm_median"] = 1e3 * float(np.median(err))
    return out


def summarize_bag(path: str | Path) -> dict[str, Any]:
    """What happened in a rig run, from its bag (simulated time throughout).

    Returns
    -------
    dict
        ``topics`` (per topic: ``count``, ``rate`` [Hz] over its own span of stamps), the
        run's ``duration`` [s], ``rolling_from`` (first ROLLING step) and ``rolling_until``
        [s] (first time after it that the true phi_dot <= 0 or the controller left
        ROLLING; the end if never), ``rolling_time`` [s], ``kept_rolling``,
        ``mean_phi_dot`` [rad/s] (true contact-angle rate over the rolling time, else the
        controller's estimate), ``loop_rate`` [Hz] (control steps), ``camera_rate`` [Hz]
        (ball observations), ``camera_valid_fraction``, ``camera_processing_ms`` (median),
        ``modes`` (steps per mode), ``final_mode``, ``rms_y`` [rad] and ``rms_z`` [rad/s]
        over the last half of the rolling time, ``max_abs_torque`` [N m].
    """
    contents = read_bag_messages(path)
    by_topic: dict[str, list[Any]] = {}
    for m in contents.messages:
        by_topic.setdefault(m.topic.lstrip("/"), []).append(m)
    run = _BagRun.decode(by_topic)
    out: dict[str, Any] = {"bag": str(path), "complete": contents.complete,
                           "topics": _topic_summary(by_topic), "warnings": contents.warnings,
                           "duration": run.t1 - run.t0}
    out["loop_inputs"] = _loop_inputs(by_topic)
    out.update(_mode_summary(run))
    out.update(_rolling_summary(run, out["rolling_from"]))
    torque = np.array([s.torque for s in run.states]) if run.states else np.zeros(0)
    out["max_abs_torque"] = float(np.max(np.abs(torque))) if torque.size else 0.0
    out.update(_camera_summary(run))
    return out


def format_summary(s: dict[str, Any], wall: tuple[float, float] | None = None) -> str:
    """Human-readable summary of :func:`summarize_bag` (plus the simulator's wall time)."""
    lines = [f"bag: {s['bag']} ({'complete' if s['complete'] else 'INCOMPLETE'})"]
    dur = s["duration"]
    if s.get("rolling_from") is None:
        verdict = "the controller never started rolling control"
    elif s["kept_rolling"]:
        verdict = (f"the ball kept rolling for {s['rolling_time']:.1f} s (from t = "
                   f"{s['rolling_from']:.2f} s to the end)")
    else:
        verdict = (f"the ball rolled for {s['rolling_time']:.1f} s (t = {s['rolling_from']:.2f}"
                   f" to {s['rolling_until']:.2f} s), then was lost; final mode "
                   f"{s['final_mode']}")
    hardware = s.get("mode") == "hardware"
    clock = "on the rig's clock" if hardware else "simulated"
    lines.append(f"run: {dur:.2f} s {clock}; {verdict}")
    src = s.get("mean_phi_dot_source", "")
    lines.append(f"mean phi_dot: {s['mean_phi_dot']:.3f} rad/s ({src})"
                 f"; RMS over the last half of the rolling time: y {s['rms_y']:.2e} rad, "
                 f"z {s['rms_z']:.2e} rad/s; max |torque| {s['max_abs_torque']:.3f} N m")
    rtf = wall[1] if wall is not None else None

    def wall_rate(rate: float) -> str:
        return f" = {rate * rtf:.0f} Hz of wall time" if rtf else ""

    lines.append(f"control loop: {s['loop_rate']:.1f} Hz "
                 f"{'of the rig' if hardware else 'in simulated time'}"
                 f"{wall_rate(s['loop_rate'])}; modes "
                 + ", ".join(f"{k} {v}" for k, v in s["modes"].items()))
    cam = (f"camera: {s['camera_rate']:.1f} Hz{wall_rate(s['camera_rate'])}, "
           f"{100 * s['camera_valid_fraction']:.1f} % valid, median processing "
           f"{s['camera_processing_ms']:.2f} ms")
    if "camera_error_mm_median" in s:
        cam += f", median error vs truth {s['camera_error_mm_median']:.3f} mm"
    lines.append(cam)
    if wall is not None:
        lines.append(f"simulator: {dur:.1f} s simulated in {wall[0]:.1f} s of wall time "
                     f"(real-time factor {wall[1]:.2f})")
    published = s.get("published", {})
    lines.append("topics (recorded / published, rate "
                 f"{'on the rig' + chr(39) + 's clock' if hardware else 'in simulated time'}):")
    for topic, d in s["topics"].items():
        pub = published.get(topic)
        both = f"{d['count']:>7} / {pub if pub is not None else '?':>7}"
        flag = ("" if pub is None or pub == d["count"]
                else f"  ({pub - d['count']:+d} not recorded)")
        lines.append(f"  {topic:<30} {both}  {d['rate']:8.1f} Hz  {d['type']}{flag}")
    lines += [f"warning: {w}" for w in s.get("warnings", [])]
    return "\n".join(lines)


# -- the command ---------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bfr rig", description="Run the emulated rig (simulator, camera, controller and "
        "recorder nodes as processes, like ros2 run) and summarise the run from its bag.")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="the simulator waits for the controller's answer to each camera "
                           "frame: repeatable whatever the load (default)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="pace the simulation by the wall clock, like the real rig")
    mode.add_argument("--hardware", dest="mode", action="store_const", const="hardware",
                      help="the real rig (docs/hardware.md): no simulator; the camera and "
                           "controller (and recorder) against the drivers' topics, "
                           "hardware.yaml, use_sim_time false, for --duration wall seconds "
                           "or until Ctrl-C")
    p.set_defaults(mode="lockstep")
    p.add_argument("--duration", type=float, default=40.0,
                   help="simulated seconds [s] (default 40); with --hardware wall seconds")
    p.add_argument("--image-topic", default="/camera/image_raw",
                   help="--hardware: the camera driver's image topic (default "
                        "/camera/image_raw)")
    p.add_argument("--camera-info-topic", default="/camera/camera_info",
                   help="--hardware: the camera driver's camera_info topic (default "
                        "/camera/camera_info)")
    p.add_argument("--record", type=Path, default=None,
                   help="bag directory to write (default: <log-dir>/bag)")
    p.add_argument("--no-record", action="store_true", help="run without the recorder")
    p.add_argument("--phase", type=float, default=0.3,
                   help="contact angle on the orbit at t = 0 [rad]")
    p.add_argument("--d-theta", type=float, default=0.05,
                   help="frame angle offset from the orbit at t = 0 [rad]")
    p.add_argument("--rig-params", default=None,
                   help="rig.yaml for the simulator (and the controller's model, the camera's "
                        "ball radius)")
    p.add_argument("--camera-params", default=None, help="camera.yaml (simulator and camera)")
    p.add_argument("--controller-params", default=None, help="controller.yaml")
    p.add_argument("-p", "--param", action="append", default=[], metavar="NODE:NAME:=VALUE",
                   help="a parameter of one node (simulator, camera, controller, recorder), "
                        "e.g. simulator:ball.mass:=3.1e-3; repeatable")
    p.add_argument("--log-dir", type=Path, default=None,
                   help="folder for the node logs (default: log/rig/<date>_<time>)")
    p.add_argument("--wall-timeout", type=float, default=None,
                   help="give up after this many wall seconds (default: generous)")
    p.add_argument("--domain", default=None, metavar="auto|ID",
                   help="ROS_DOMAIN_ID for the nodes: a number, or 'auto' for a free one with "
                        "localhost-only discovery (default: the environment's)")
    p.add_argument("--nice", type=int, default=-10, metavar="N",
                   help="realtime: start the nodes at this niceness, each in a session of "
                        "its own with that autogroup niceness (default -10: above the "
                        "machine's other work, as a real-time control loop runs; needs the "
                        "permission to raise priorities, else normal priority with a note)")
    p.add_argument("--loop", choices=("auto", "composed", "separate"), default="auto",
                   help="the camera and controller nodes in one process (composed: "
                        "bfr_tools loop_node) or two; auto: composed with --realtime, "
                        "separate in lock-step (default: auto)")
    p.add_argument("--loop-cpu", type=int, default=None, metavar="N",
                   help="pin the camera and controller to CPU N (-1: no pinning; default: "
                        "the last CPU with --realtime on a machine of two or more, else -1)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    return p


def _node_args(args: argparse.Namespace, log_dir: Path, bag: Path | None,
               start: dict[str, float]) -> dict[str, list[str]]:
    # the simulator is the clock (it publishes /clock); every other node follows it
    per: dict[str, list[str]] = {n: ["-p", "use_sim_time:=true"] for n in NODES
                                 if n != "simulator"}
    per["simulator"] = []
    for n in ("simulator", "camera", "controller"):
        if args.rig_params:
            per[n] += ["--params-file", str(args.rig_params)]
    for n in ("simulator", "camera"):
        if args.camera_params:
            per[n] += ["--params-file", str(args.camera_params)]
    if args.controller_params:
        per["controller"] += ["--params-file", str(args.controller_params)]
    rec = int(bag is not None)
    # the simulator starts when every subscriber is there: camera, controller and recorder
    # on joint_states, camera and recorder on camera_info, the recorder on sim_truth, and the
    # controller has finished loading (its controller_state publisher is up)
    per["simulator"] += ["-p", f"sim.mode:={args.mode}", "-p", f"sim.duration:={args.duration}",
                         "-p", f"start.wait_subscribers:={2 + rec}",
                         "-p", f"start.wait_info_subscribers:={1 + rec}",
                         "-p", f"start.wait_truth_subscribers:={rec}",
                         "-p", "start.wait_controller:=true",
                         "-p", f"start.wait_observation_subscribers:={1 + rec}",
                         "-p", f"start.settle:={2.0 if rec else 0.5}"]
    per["simulator"] += [a for k, v in start.items() for a in ("-p", f"{k}:={v!r}")]
    per["controller"] += ["-p", "loop.trigger:=observation"]
    # wall-clock watchdogs: in lock-step a gap only means a slow machine, and this command
    # watches the processes itself (it stops the others as soon as the simulator is done)
    per["controller"] += ["-p", "safety.watchdog_timeout:=5.0"]
    per["camera"] += ["-p", "input.frame_timeout:=5.0"]
    if args.mode == "lockstep":  # no wall-clock deadline: the normal scheduler (the
        # simulator keeps it by itself in lock-step; real-time priority made the lock-step
        # ping-pong 10-60 % slower here, each answer a wake on the other vCPU)
        for n in ("camera", "controller", "recorder"):
            per[n] += ["-p", "process.realtime_priority:=0"]
    return _user_params(per, args, bag, "")


def _user_params(per: dict[str, list[str]], args: argparse.Namespace, bag: Path | None,
                 why: str) -> dict[str, list[str]]:
    """``per`` with the bag's path and the user's ``-p NODE:NAME:=VALUE`` added.

    ``why``: said after the nodes a ``-p`` may name when it names another.
    """
    if bag is not None:
        per["recorder"] += ["-p", f"recorder.path:={bag}"]
    for item in args.param:
        node, sep, assignment = item.partition(":")
        if not sep or node not in per or ":=" not in assignment:
            raise RigError(f"-p {item!r}: expected NODE:NAME:=VALUE with NODE one of "
                           f"{', '.join(per)}{why}")
        per[node] += ["-p", assignment]
    return per


def _hardware_args(args: argparse.Namespace, bag: Path | None) -> dict[str, list[str]]:
    """``--ros-args`` of the camera, controller and recorder on the real rig.

    As docs/hardware.md starts them: the camera's file, rig.yaml, the controller's file, then
    hardware.yaml (later files override earlier ones), ``use_sim_time:=false``, the camera
    driver's topics remapped (for the recorder too: it records them under those names).
    """
    hw = ["--params-file", str(config_path("bfr_control", "hardware.yaml"))]

    def files(*paths: str | None) -> list[str]:
        return [a for f in paths if f for a in ("--params-file", str(f))]

    remaps = ["-r", f"camera/image_raw:={args.image_topic}",
              "-r", f"camera/camera_info:={args.camera_info_topic}"]
    wall = ["-p", "use_sim_time:=false"]
    per = {"camera": [*files(args.camera_params, args.rig_params), *hw, *wall, *remaps],
           "controller": [*files(args.rig_params, args.controller_params), *hw, *wall],
           "recorder": [*hw, *wall, *remaps]}
    return _user_params(per, args, bag, " (--hardware: no simulator)")


def _environment(args: argparse.Namespace) -> dict[str, str]:
    """The nodes' environment: this one, unbuffered, plain logs, ``--domain`` applied."""
    env = dict(os.environ)
    env.update(PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0")
    if args.domain == "auto":
        env.update(ROS_DOMAIN_ID=str(claim_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        env.pop("ROS_STATIC_PEERS", None)
    elif args.domain is not None:
        if not args.domain.isdigit():
            raise RigError(f"--domain {args.domain!r}: expected 'auto' or a number")
        env["ROS_DOMAIN_ID"] = args.domain
    return env


def _nice(args: argparse.Namespace) -> int:
    """The nodes' niceness: ``--nice`` with a wall-clock deadline where permitted, else 0."""
    nice = args.nice if args.mode in ("realtime", "hardware") else 0
    if nice < 0 and not may_raise_priority(nice):
        print(f"bfr rig: note: raising the nodes' priority (nice {nice}) is not permitted "
              f"here; they run at normal priority and a busy machine may slow the "
              f"simulation down", flush=True)
        nice = 0
    return nice


def _start(node: NodeSpec, log_dir: Path, env: dict[str, str], nice: int) -> None:
    """Start one node and say so (its package, executable and pid)."""
    node.start(log_dir, env, nice)
    print(f"bfr rig: started {node.name} ({node.package}/{node.executable}, pid "
          f"{node.process.pid})", flush=True)  # type: ignore[union-attr]


def _death(node: NodeSpec) -> str:
    """The one-line cause and log tail of a node that died."""
    return (f"{node.name} node died ({_describe_exit(node.returncode or 0)}); its log "
            f"({node.log_path}) ends with:\n{node.tail()}")


def _bag_summary(bag: Path | None, mode: str, interrupted: bool,
                 nodes: dict[str, NodeSpec]) -> dict[str, Any] | None:
    """The run's summary from its bag (None without one), with how it ran."""
    if bag is None or not (bag / "metadata.yaml").exists():
        return None
    summary = summarize_bag(bag)
    summary.update(mode=mode, interrupted=interrupted, published=published_counts(nodes))
    summary["warnings"] = [*summary["warnings"], *run_warnings(summary)]
    return summary


#: Share of its input below which a node is said to have fallen behind (the camera node's
#: observations per camera frame, the controller's steps per sample of its trigger).
KEPT_UP = 0.9


def run_warnings(s: dict[str, Any]) -> list[str]:
    """What made a run's figures less than the whole run (``s``: a run's summary).

    Messages published but not recorded (the bag's figures undercount), a camera node that
    measured under :data:`KEPT_UP` of the camera's frames, a controller that stepped on
    under that share of its trigger's samples (encoder samples on hardware, observations
    in a simulation), no encoder sample at all. Each a line; none for a run that kept up.
    A topic absent from the bag counts only among the loop's (:data:`RECORDER_MATCH_TOPICS`).
    The inputs are counted while the node that answers them published
    (``s["loop_inputs"]``, :func:`summarize_bag`), else over the bag. A driver that
    publishes each joint in a message of its own, or a controller triggered otherwise
    (``-p controller:loop.trigger:=...``), would read as a controller that fell behind.
    """
    topics, published = s["topics"], s.get("published", {})
    # a topic missing from the bag counts only if it is one the recorder must have (the
    # loop's): images and /clock are not recorded by default, and a user may leave out more
    out = [f"{topic}: {pub - topics.get(topic, {}).get('count', 0)} of {pub} published "
           f"message(s) not recorded (the bag's figures undercount the run)"
           for topic, pub in sorted(published.items())
           if (topic in topics or topic in RECORDER_MATCH_TOPICS)
           and topics.get(topic, {}).get("count", 0) < pub]

    def count(topic: str) -> int:
        return int(topics.get(topic, {}).get("count", 0))

    # the inputs recorded while the loop nodes ran (the recorder runs before and after them)
    inputs = s.get("loop_inputs") or {
        "joint_states": count("/joint_states"), "ball_observation": count("/ball_observation"),
        "camera_info": max((d["count"] for t, d in topics.items() if t.endswith("camera_info")),
                           default=0)}
    if not count("/joint_states"):
        out.append("no /joint_states recorded: no encoder sample reached the recorder")
    frames, seen = inputs["camera_info"], count("/ball_observation")
    if frames and seen < KEPT_UP * frames:
        out.append(f"the camera node measured {seen} of {frames} camera frames "
                   f"({100 * seen / frames:.0f} %): it fell behind the camera")
    trigger = "joint_states" if s.get("mode") == "hardware" else "ball_observation"
    samples, steps = inputs[trigger], count("/controller_state")
    if samples and steps < KEPT_UP * samples:
        what = "encoder samples" if trigger == "joint_states" else "ball observations"
        out.append(f"the controller stepped on {steps} of {samples} {what} "
                   f"({100 * steps / samples:.0f} %): it fell behind")
    return out


#: What the camera and controller nodes log once they are up (their start-up lines; and the
#: controller's match to the camera, :data:`bfr_control.controller_node.CAMERA_MATCHED`).
LOOP_READY = ("camera: images ", "mode WAITING (no ball yet)")
#: The controller's line on its first encoder sample: on the rig the loop is closed from then
#: (its start-up backlog, samples queued while the node set up, is behind it).
JOINTS_ARRIVING = " is arriving"
#: Each line waited for, in words (for the note when one is missing).
_READY_WORDS = {"camera: images ": "the camera node up",
                "mode WAITING (no ball yet)": "the controller node up",
                JOINTS_ARRIVING: "an encoder sample at the controller (joint_states)"}


def _wait_loop_ready(nodes: dict[str, NodeSpec], timeout: float = 180.0,
                     also: tuple[str, ...] = ()) -> None:
    """Wait until the camera and controller have logged that they are up.

    A cold numba cache takes a minute: ``--duration`` counts the time they run. ``also``:
    more lines to wait for (on the rig, :data:`JOINTS_ARRIVING`). Raises RigError if one dies
    meanwhile; after ``timeout`` seconds, says which lines did not come and goes on.
    """
    t0 = time.monotonic()
    logs = [nodes[n] for n in ("loop", "camera", "controller") if n in nodes]
    missing: list[str] = []
    while time.monotonic() - t0 < timeout:
        text = "".join(n.log_path.read_text(errors="replace") for n in logs
                       if n.log_path is not None and n.log_path.exists())
        missing = [_READY_WORDS.get(m, repr(m)) for m in (*LOOP_READY, *also) if m not in text]
        if not CAMERA_MATCHED.search(text):
            missing.append("the controller matched to the camera (ball_observation)")
        if not missing:
            return
        for n in logs:
            if n.returncode is not None:
                raise RigError(_death(n))
        time.sleep(0.1)
    print(f"bfr rig: note: not within {timeout:g} s: {'; '.join(missing)}; timing the run "
          f"from now", flush=True)


def run_hardware(args: argparse.Namespace, log_dir: Path, bag: Path | None
                 ) -> tuple[dict[str, Any] | None, Path, Path | None, None]:
    """``bfr rig --hardware``: the loop (and recorder) on the real rig; see the docstring."""
    per = _hardware_args(args, bag)
    env = _environment(args)
    composed, cpu = loop_layout("realtime", args.loop, args.loop_cpu)
    loop = loop_specs(per, composed=composed, cpu=cpu)
    order = [*(["recorder"] if bag is not None else []), *loop]
    nodes = {n: loop[n] if n in loop else NodeSpec(n, *NODES[n], per[n]) for n in order}
    nice = _nice(args)
    print(f"bfr rig: hardware (no simulator), {args.duration:g} s of wall time, images "
          f"{args.image_topic}, ROS_DOMAIN_ID {env.get('ROS_DOMAIN_ID', '0')}; logs in "
          f"{log_dir}" + (f"; bag {bag}" if bag else ""), flush=True)
    failure: str | None = None
    interrupted = False
    timed_from: float | None = None  # [s] this computer's clock, the stamps' on the rig
    try:
        for n in order:
            _start(nodes[n], log_dir, env, nice)
        _wait_loop_ready(nodes, also=(JOINTS_ARRIVING,))
        if "recorder" in nodes:
            # and the drivers' topics: the run is timed from when the bag gets them all
            drivers = ("/joint_states", "/" + args.camera_info_topic.lstrip("/"))
            _wait_recorder_matched(nodes["recorder"], (*RECORDER_MATCH_TOPICS, *drivers),
                                   timeout=60.0, then="timing the run from now")
        t_run, timed_from = time.monotonic(), time.time()
        print(f"bfr rig: running for {args.duration:g} s (Ctrl-C stops it sooner)", flush=True)
        while time.monotonic() - t_run < args.duration:
            time.sleep(0.2)
            dead = [n for n in order if nodes[n].returncode is not None]
            if dead:
                n = dead[0]
                failure = _death(nodes[n])
                break
    except KeyboardInterrupt:
        interrupted = True
        print("bfr rig: interrupted; stopping the nodes", flush=True)
    finally:
        for n in ("loop", "controller", "camera", "recorder"):
            if n in nodes:
                nodes[n].stop()
    if failure is not None:
        raise RigError(failure)
    summary = _bag_summary(bag, "hardware", interrupted, nodes)
    if summary is not None:
        summary["timed_from"] = timed_from
    return summary, log_dir, bag, None


def run_rig(args: argparse.Namespace) -> tuple[dict[str, Any] | None, Path, Path | None,
                                               tuple[float, float] | None]:
    """Run the rig (see the module docstring); returns (summary, log dir, bag, wall stats)."""
    stamp = datetime.now().strftime("%Y%m%d_%H%M%S")
    log_dir = args.log_dir or Path("log") / "rig" / stamp
    log_dir.mkdir(parents=True, exist_ok=True)
    bag = None if args.no_record else (args.record or log_dir / "bag")
    if bag is not None and bag.exists():
        raise RigError(f"{bag} exists already: choose a new --record directory")
    if args.mode == "hardware":
        return run_hardware(args, log_dir, bag)
    start = orbit_start(args.phase, args.d_theta, args.rig_params, args.controller_params)
    per = _node_args(args, log_dir, bag, start)
    env = _environment(args)
    composed, cpu = loop_layout(args.mode, args.loop, args.loop_cpu)
    loop = loop_specs(per, composed=composed, cpu=cpu)
    order = [n for n in ("recorder", *loop, "simulator") if n != "recorder" or bag is not None]
    nice = _nice(args)
    nodes = {n: loop[n] if n in loop else NodeSpec(n, *NODES[n], per[n]) for n in order}
    wall_limit = args.wall_timeout or (
        120.0 + (args.duration * 10.0 if args.mode == "lockstep" else args.duration * 2.0))
    print(f"bfr rig: {args.mode}, {args.duration:g} s simulated, ROS_DOMAIN_ID "
          f"{env.get('ROS_DOMAIN_ID', '0')}; logs in {log_dir}"
          + (f"; bag {bag}" if bag else ""), flush=True)
    print("bfr rig: initial state on the orbit: "
          + ", ".join(f"{k.split('.')[1]} {v:+.4f}" for k, v in start.items()), flush=True)
    t_start = time.monotonic()
    failure: str | None = None
    interrupted = False
    try:
        for n in order:
            if n == "simulator" and "recorder" in nodes:
                _wait_recorder_matched(nodes["recorder"], RECORDER_MATCH_TOPICS)
            _start(nodes[n], log_dir, env, nice)
        sim = nodes["simulator"]
        while True:
            time.sleep(0.2)
            rc = sim.returncode
            if rc is not None:
                if rc != 0:
                    failure = (f"simulator ended early ({_describe_exit(rc)}); its log "
                               f"({sim.log_path}) ends with:\n{sim.tail()}")
                break
            dead = [n for n in order if n != "simulator" and nodes[n].returncode is not None]
            if dead:
                n = dead[0]
                failure = _death(nodes[n])
                break
            if time.monotonic() - t_start > wall_limit:
                failure = (f"the run did not finish within {wall_limit:.0f} s of wall time; the "
                           f"simulator's log ends with:\n{sim.tail()}")
                break
    except KeyboardInterrupt:
        interrupted = True
        print("bfr rig: interrupted; stopping the nodes", flush=True)
    finally:
        for n in ("simulator", "loop", "controller", "camera", "recorder"):
            if n in nodes:
                nodes[n].stop()
    wall = _wall_stats(nodes["simulator"].log_path)
    if failure is not None:
        raise RigError(failure)
    summary = _bag_summary(bag, args.mode, interrupted, nodes)
    if summary is not None and wall is not None:
        summary["wall_time"], summary["real_time_factor"] = wall
    return summary, log_dir, bag, wall


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``bfr rig`` (module docstring)."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    if not (math.isfinite(args.duration) and args.duration > 0):
        print("bfr rig: error: --duration must be > 0", file=sys.stderr)
        return 2
    try:
        summary, log_dir, _, wall = run_rig(args)
    except RigError as exc:
        print(f"bfr rig: error: {exc}", file=sys.stderr)
        return 1
    except (ValueError, LookupError, OSError) as exc:
        print(f"bfr rig: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    if summary is None:
        print(f"bfr rig: done (no bag recorded); logs in {log_dir}")
        return 0
    if args.json:
        print(json.dumps(summary, default=float))
    else:
        print(format_summary(summary, wall))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
