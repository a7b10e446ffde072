"""The controller node: motor torque from the encoder and the camera, over topics.

A thin node over :class:`bfr_control.controller.OrbitalController` (estimator, transverse
coordinates, Riccati gains, PFL, supervisor):

- subscribes ``joint_states`` (``sensor_msgs/JointState``: the frame joint's position and
  velocity) and ``ball_observation`` (``bfr_interfaces/BallObservation``);
- publishes ``effort_controller/commands`` (``std_msgs/Float64MultiArray``, one element,
  reliable: the command topic of ros2_control's forward command controller) and
  ``controller_state`` (``bfr_interfaces/ControllerState``) at every control step.

When a step runs is ``loop.trigger``: on each observation (the camera rate; the default),
on each joint_states sample (the encoder rate), or on a timer at ``control.rate``. Encoder
samples between steps still go into the estimator's history (latency compensation). Unless
each sample runs a step, the node takes the samples from the subscription's queue when it
needs them (at each observation, timer step and watchdog check, and every
``loop.max_step_gap / 2`` of wall time): one C call per sample instead of a Python callback.

Safety, in the node whatever the core does:

- the torque is clamped to the actuator's ``actuator.torque_limit`` (rig.yaml, the one
  source: ``-p actuator.torque_limit:=0.05`` lowers it) and is exactly 0 unless the mode is
  ROLLING (WAITING, BALL_LOST and FAULT all command zero);
- BALL_LOST (no valid fix for ``supervisor.lost_timeout``, the ball stopped or far from the
  orbit) is latched: zero torque until the node is restarted or ``~/reset`` is called (a
  FAULT that comes and goes meanwhile does not re-arm it);
- with the observation trigger a joint_states sample ``loop.max_step_gap`` after the last
  step runs a step anyway (taken within ``max_step_gap / 2``), so a dead camera is noticed
  in time;
- no joint_states for ``safety.watchdog_timeout`` seconds of the node's clock (simulated
  time under ``use_sim_time``: dead driver or simulator), non-finite or malformed samples,
  or samples stamped more than ``safety.max_stamp_age`` away from the node's clock: zero
  torque, mode FAULT, an error log; the controller starts afresh (WAITING) when good
  samples return (but samples older than that within ``max_stamp_age`` of steady time from
  the first one that arrived with the node's clock running are the start-up backlog the
  subscription queued while the node set up: dropped, not used, counted in the "is
  arriving" line, or said once if one comes after a good sample);
- an exception in any callback (a bug, or input no check foresaw) never ends the node: it
  puts the controller in FAULT with zero torque, logged once with its reason (exception
  type, message and where), and the controller restarts in WAITING at the next step that
  runs without one;
- on shutdown (SIGINT/SIGTERM) a last zero command is published.

Actuation delay. The node measures, at every step, how far its clock has run past the
encoder sample the step answers (``now - t_sample``: camera processing, transport and
queueing), adds ``loop.actuation_delay`` (from publication to the moment the drive applies
the command) and hands the sum to the core as ``lead``, which predicts the state through
it (bfr_control.controller). The measured delay's median, 99th percentile and maximum are
logged on exit. Under lock-step simulation the clock waits for the controller, so the
measured part is 0.

A freshly started node picks up a rolling ball (WAITING -> ROLLING once it has seen it near
the orbit) or, if the ball is seen but stays off the orbit for ``safety.acquire_timeout``,
reports it lost (mode BALL_LOST in ``controller_state``, one warning) while it keeps
watching. It logs each change of the camera publishers matched to its ``ball_observation``
subscription (``/ball_observation: matched 1 publisher(s)``): from that line on it can see
the ball, and an operator (or a test) may release it.
"""

from __future__ import annotations

import functools
import math
import re
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NamedTuple

from bfr_model.param_file import check, config_path, nonnegative, one_of
from bfr_model.params import default_params_path, params_from_dict
from bfr_ros.node_common import (
    COMMAND_QOS,
    JOINT_STATES_POLLED_QOS,
    JOINT_STATES_QOS,
    STATE_QOS,
    CdrError,
    JointPicker,
    PolledSubscription,
    Throttle,
    declare_parameter_tree,
    format_published,
    load_yaml_parameters,
    parse_joint_state,
    place_process,
    read_parameter_tree,
    run_node,
    stamp_to_ns,
    turn_unwrapper,
    wrong_type_publishers,
)
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from bfr_control.controller import (
    BALL_LOST,
    ROLLING,
    WAITING,
    Command,
    ControllerConfig,
    OrbitalController,
    default_config_path,
)
from bfr_control.estimator import BallObservation
from bfr_interfaces.msg import BallObservation as BallObservationMsg
from bfr_interfaces.msg import ControllerState

__all__ = ["ControllerNode", "main", "node_defaults"]

_NS = 1_000_000_000
#: The line :meth:`ControllerNode._on_camera_matched` logs once a camera's publisher has
#: matched the ``ball_observation`` subscription, as a pattern (the count may be any, the
#: name the resolved topic's): from then on the node can see the ball; ``bfr rig`` and the
#: tests wait for it before the ball is released.
CAMERA_MATCHED = re.compile(r"ball_observation: matched [1-9][0-9]* publisher")
_PAUSE_S = 0.03  # [s] wall time between observations worth a warning (6 frames at 200 Hz)
MODE_CODES = {WAITING: ControllerState.WAITING, ROLLING: ControllerState.ROLLING,
              BALL_LOST: ControllerState.BALL_LOST}
_RIG_GROUPS = ("ball", "frame", "environment", "joint", "actuator", "track", "contact")
_CTRL_GROUPS = ("constraint", "orbit", "riccati", "control", "estimator", "supervisor")
#: Logged before the gains and the compiled kernels load (bfr_ros.startup: a signal stops
#: this at once).
SETTING_UP = ("setting up: gains and compiled kernels (with a cold numba cache they compile: "
              "about a minute; bfr warm fills it); Ctrl-C stops this at once")


def default_files() -> list[Path]:
    """The node's shipped parameter files, in order: rig.yaml, controller.yaml, this node's."""
    return [Path(default_params_path()), Path(default_config_path()),
            Path(config_path("bfr_control", "controller_node.yaml"))]


def node_defaults() -> dict[str, Any]:
    """Defaults: rig.yaml (the model), controller.yaml, controller_node.yaml."""
    d: dict[str, Any] = {}
    for path in default_files():
        d.update(load_yaml_parameters(path))
    return d


class SampleFault(NamedTuple):
    """A joint_states sample that puts the controller in FAULT (but see ``stale``), and why.

    ``t_ns`` is the sample's stamp (the measurement's time: the FAULT state is stamped with
    it), or the node's clock at its arrival when the message cannot be read; ``theta`` and
    ``theta_dot`` are its values as received (NaN where missing).
    """

    why: str
    t_ns: int
    theta: float = math.nan
    theta_dot: float = math.nan
    #: Stamped more than ``safety.max_stamp_age`` before the node's clock (not after it):
    #: start-up backlog within that time of the first sample's arrival
    #: (:meth:`ControllerNode._start_backlog`).
    stale: bool = False


def guarded(where: str) -> Callable:
    """Run a callback of :class:`ControllerNode` so that an exception puts it in FAULT.

    Parameters
    ----------
    where : str
        Name of the callback for the log line.
    """
    def wrap(fn: Callable) -> Callable:
        @functools.wraps(fn)
        def run(self: ControllerNode, *args: Any) -> Any:
            try:
                return fn(self, *args)
            except Exception as exc:  # noqa: BLE001 - any error: zero torque, not a crash
                self._on_exception(where, exc)
                return args[-1] if where == "reset" else None
        return run
    return wrap


class ControllerNode(Node):
    """ROS 2 wrapper of :class:`OrbitalController` (module docstring)."""

    def __init__(self, accepted: Iterable[str] = (), place: bool = True) -> None:
        """Start the node.

        Parameters
        ----------
        accepted : iterable of str
            Names of parameters that other nodes of this process use (a ``-p`` reaches every
            node of a process); accepted here without being declared.
        place : bool
            False when a process hosting several nodes applies ``process.realtime_priority``
            and ``process.cpu`` itself (:mod:`bfr_tools.loop_node`), after every node's
            warm-up; True: this node applies its own.
        """
        super().__init__("controller")
        self.defaults = node_defaults()
        declare_parameter_tree(self, self.defaults, accepted)
        p = read_parameter_tree(self, self.defaults)
        self.process = p["process"]
        model = params_from_dict({k: p[k] for k in _RIG_GROUPS})
        config = ControllerConfig.from_dict({k: p[k] for k in _CTRL_GROUPS})
        t0 = time.perf_counter()
        self.get_logger().info(SETTING_UP)
        self.ctrl = OrbitalController(model, config)
        self._warm_up()
        # after the warm-up: a cold compile does not hold a CPU at real-time priority
        self.scheduling = (place_process(self.process, self.get_logger()) if place
                           else "process placed by its host")
        setup = time.perf_counter() - t0
        loop, safety = p["loop"], p["safety"]
        self.trigger = str(loop["trigger"]).lower()
        one_of("loop.trigger", self.trigger, ("observation", "joint_states", "timer"))
        self.joint_name = str(loop["joint_name"])
        self.joints = JointPicker(self.joint_name, "loop.joint_name")
        self.max_gap_ns = round(float(loop["max_step_gap"]) * _NS)
        self.actuation_delay = float(loop["actuation_delay"])
        nonnegative("loop.actuation_delay", self.actuation_delay)
        self.predict = bool(loop["predict_delay"])
        self.watchdog_timeout = float(safety["watchdog_timeout"])
        check(self.watchdog_timeout > 0, "safety.watchdog_timeout",
              f"must be > 0 s, got {self.watchdog_timeout}")
        self.max_age_ns = round(float(safety["max_stamp_age"]) * _NS)
        self.acquire_timeout = float(safety["acquire_timeout"])
        self.limit = self.ctrl.torque_limit
        ceiling = float(safety["max_torque"])
        check(0.0 < self.limit <= ceiling, "actuator.torque_limit",
              f"{self.limit:g} N m is above the node's ceiling safety.max_torque = {ceiling:g} "
              f"N m (raise that only for a stronger motor)")
        self.cmd_pub = self.create_publisher(Float64MultiArray, "effort_controller/commands",
                                             COMMAND_QOS)
        self.state_pub = self.create_publisher(ControllerState, "controller_state", STATE_QOS)
        # joint_states arrive serialized and are parsed here (parse_joint_state): no Python
        # message object per encoder sample at the encoder's rate. Unless every sample runs a
        # step, they are taken from the subscription's queue when the node needs them (an
        # observation, the timer, the watchdog, a take timer), not one callback each
        self.js_sub: Any
        if self.trigger == "joint_states":
            self.js_sub = self.create_subscription(JointState, "joint_states", self._on_joints,
                                                   JOINT_STATES_QOS, raw=True)
        else:
            self.js_sub = PolledSubscription(self, JointState, "joint_states",
                                             JOINT_STATES_POLLED_QOS)
        self.obs_sub = self.create_subscription(
            BallObservationMsg, "ball_observation", self._on_ball, STATE_QOS,
            event_callbacks=SubscriptionEventCallbacks(matched=self._on_camera_matched))
        self.create_service(Trigger, "~/reset", self._on_reset)
        # timeouts on the node's clock: simulated time under use_sim_time
        self.create_timer(min(0.1, self.watchdog_timeout / 2.0), self._watchdog)
        if self.trigger == "timer":
            self.create_timer(1.0 / config.control.rate, self._on_timer)
        elif self.trigger == "observation":
            # without observations (a dead camera) the samples are still taken: steps without
            # a fix (max_step_gap), faults. On the steady clock, so that a bad sample is
            # answered at once even while a simulation's clock stands still
            self.create_timer(max(float(loop["max_step_gap"]) / 2.0, 1e-3), self.take_joints,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.js: tuple[int, float, float] | None = None  # newest good sample
        self.js_clock_ns = self.get_clock().now().nanoseconds  # node clock at its arrival
        self.first_js_ns: int | None = None
        # the steady clock at the first sample's arrival (good or not) with the node's clock
        # running, and the stale samples dropped as the start-up backlog (:meth:`_start_backlog`)
        self.first_arrival_ns: int | None = None
        self.backlog_after_good = False  # a backlog sample came after a good one (said once)
        # a driver's within-a-turn angle made accumulating
        self.turns = turn_unwrapper(self, self.js_sub.topic_name)
        self.backlog_dropped = 0
        self.last_step_ns: int | None = None
        self.pending: list[BallObservation] = []
        self.fault = ""  # why the node is in FAULT (empty: not)
        self.exception_fault = False  # the FAULT is an exception's (cleared by a good step)
        self.reported_exceptions: set[str] = set()
        self.delays: deque[float] = deque(maxlen=20000)  # measured now - t_sample [s]
        self.reported_mode = -1
        self.off_orbit_since: float | None = None
        self.reported_lost = False
        self.stats = {"steps": 0, "observations": 0, "rolling_steps": 0, "faults": 0,
                      "saturated": 0, "exceptions": 0, "commands": 0, "states": 0}
        self.executor_ref: Any = None
        self.throttle = Throttle()
        self.obs_wall: float | None = None  # wall clock and thread CPU at the last observation
        self.obs_cpu = 0.0
        self.pauses = 0
        self.worst_pause = (0.0, 0.0)  # (wall [s], CPU of this thread meanwhile [s])
        # the same between two joint_states samples taken (:meth:`_watch_encoder`), and when
        # the longest gap ended [s, system clock]
        self.js_wall: float | None = None
        self.js_cpu = 0.0
        self.worst_js_gap = (0.0, 0.0, 0.0)
        self.get_logger().info(
            f"controller: {self.js_sub.topic_name} + {self.obs_sub.topic_name} -> "
            f"{self.cmd_pub.topic_name}, trigger {self.trigger}, torque limit {self.limit:g} "
            f"N m, lost timeout {self.ctrl.config.supervisor.lost_timeout:g} s, actuation delay "
            f"{'measured + ' if self.predict else 'not predicted; '}"
            f"{1e3 * self.actuation_delay:g} ms, orbit mean phi_dot "
            f"{self.ctrl.orbit.summary().get('mean_phi_dot', float('nan')):.3g} rad/s, "
            f"set up in {setup:.2f} s; mode WAITING (no ball yet); {self.scheduling}")

    def _warm_up(self) -> None:
        """Run the core on a ball rolling along its orbit (:meth:`OrbitalController.warm_up`).

        The compiled kernels (estimator, prediction, PFL) load on first use, which takes
        tens of milliseconds: better here than in the first rolling step of a real run (a
        warm-up whose ball never rolled had left the pick-up step 25-48 ms long).
        """
        if self.ctrl.warm_up() == 0:
            self.get_logger().warn("warm-up: the synthetic ball was never picked up; the "
                                   "first rolling step loads the rolling path's kernels")

    # -- inputs ----------------------------------------------------------------------------
    def _parse_joints(self, raw: bytes, now: int) -> tuple[int, float, float] | SampleFault | None:
        """(t_ns, theta, theta_dot), a :class:`SampleFault`, or None (another joint's message).

        ``now`` is the node's clock [ns] at the message's arrival (or take).
        """
        try:
            t_ns, names, position, velocity, _ = parse_joint_state(raw)
        except CdrError as exc:
            return SampleFault(f"malformed message on {self.js_sub.topic_name}: {exc}", now)
        j = self.joints.index(names, position)
        if j is None:
            return None
        if j >= len(position) or j >= len(velocity):
            return SampleFault(
                f"joint_states for {self.joint_name!r} lack position or velocity "
                f"({len(position)} positions, {len(velocity)} velocities)", t_ns,
                float(position[j]) if j < len(position) else math.nan,
                float(velocity[j]) if j < len(velocity) else math.nan)
        theta, theta_dot = float(position[j]), float(velocity[j])
        if not (math.isfinite(theta) and math.isfinite(theta_dot)):
            return SampleFault(f"non-finite joint_states sample (theta {theta}, theta_dot "
                               f"{theta_dot})", t_ns, theta, theta_dot)
        if now > 0 and abs(now - t_ns) > self.max_age_ns:
            return SampleFault(
                f"joint_states stamped {(now - t_ns) / _NS:+.3f} s from the node's clock "
                f"(> {self.max_age_ns / _NS:g} s): stale data or a clock mismatch "
                f"(use_sim_time must match the publisher's clock)", t_ns, theta, theta_dot,
                stale=now - t_ns > self.max_age_ns)
        return t_ns, self.turns(theta, t_ns / _NS, theta_dot), theta_dot

    def _on_exception(self, where: str, exc: Exception) -> None:
        """An exception in a callback: FAULT with zero torque, logged once per reason."""
        self.stats["exceptions"] += 1
        frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        at = f" at {frame.filename.rsplit('/', 1)[-1]}:{frame.lineno}" if frame else ""
        why = f"{type(exc).__name__} in {where}: {exc}{at}"
        key = f"{type(exc).__name__}{at}"
        if key not in self.reported_exceptions:
            self.reported_exceptions.add(key)
            self.get_logger().error(f"exception ({why}); the controller is in FAULT with zero "
                                    f"torque until a step runs cleanly again")
        try:
            self.ctrl.reset(keep_lost=True)  # a latched BALL_LOST outlives the FAULT
            self.pending.clear()
            self.last_step_ns = None
        finally:
            self._enter_fault(why, None, log=False)
            self.exception_fault = True

    def take_joints(self) -> None:
        """Take the queued encoder samples (one :meth:`_on_joints` each, oldest first)."""
        if isinstance(self.js_sub, PolledSubscription):
            taken = self.js_sub.take()
            if taken:
                now = self.get_clock().now().nanoseconds  # one clock read for them all
                for raw in taken:
                    self._on_joints(raw, now)

    @guarded("joint_states")
    def _on_joints(self, raw: bytes, now: int | None = None) -> None:
        if now is None:  # a callback (loop.trigger joint_states)
            now = self.get_clock().now().nanoseconds
        self._watch_encoder(now)
        if self.first_arrival_ns is None and now > 0:  # ages are judged from now on
            self.first_arrival_ns = time.monotonic_ns()
        got = self._parse_joints(raw, now)
        if got is None:
            return
        if isinstance(got, SampleFault):
            if got.stale and self._start_backlog():
                self.backlog_dropped += 1
                if self.first_js_ns is not None and not self.backlog_after_good:
                    self.backlog_after_good = True
                    self.get_logger().info(
                        f"{self.js_sub.topic_name}: stale samples of the start-up backlog "
                        f"after the first good one ({got.why}): dropped, not a FAULT, for "
                        f"{self.max_age_ns / _NS:g} s of wall time from the first sample")
                return
            self._enter_fault(got.why, got.t_ns, got.theta, got.theta_dot)
            return
        self.js_clock_ns = now
        if self.fault and not self.exception_fault:
            # a latched BALL_LOST outlives the fault: only ~/reset or a restart re-arms
            latched = self.ctrl.mode == BALL_LOST
            self.get_logger().info(f"{self.js_sub.topic_name} good again after: {self.fault}; "
                                   + (_STAYS_LOST if latched
                                      else "controller restarts in WAITING"))
            self.fault = ""
            self.ctrl.reset(keep_lost=True)
            self.pending.clear()
            self.last_step_ns = None
        if self.js is not None and got[0] <= self.js[0]:
            return  # repeated or out-of-order sample
        self.js = got
        t_ns = got[0]
        if self.first_js_ns is None:
            self.first_js_ns = t_ns
            dropped = (f" (the first {self.backlog_dropped} sample(s), queued while the node "
                       f"set up, dropped: stamped over safety.max_stamp_age ago)"
                       if self.backlog_dropped else "")
            self.get_logger().info(f"{self.js_sub.topic_name} is arriving{dropped}")
        ref = self.last_step_ns if self.last_step_ns is not None else self.first_js_ns
        if self.trigger == "joint_states":
            self._step()
        elif self.trigger == "observation" and (
                any(o.t * _NS <= t_ns + 1 for o in self.pending)
                or t_ns - ref >= self.max_gap_ns):
            self._step()
        else:
            self.ctrl.estimator.record(t_ns / _NS, got[1], got[2])

    def _start_backlog(self) -> bool:
        """Whether a stale sample (stamped too long ago) arriving now is start-up backlog.

        The subscription queues samples from its creation on, and the node sets up (and, in
        a composed process, the other nodes set up) before it takes the first: those come
        oldest first, stamped up to the queue's length ago, and while the node drains them
        their age hovers about the time it took to set up, so a good one may come before the
        last stale one. Within ``safety.max_stamp_age`` of steady (wall) time from the first
        sample's arrival (the backlog is drained in real time, whatever a simulation's clock
        does) a stale sample is dropped and counted (said with the "is arriving" line, and
        once if after a good one), not a FAULT; after that, stale is a FAULT (a clock
        mismatch never ends within that time). A dropped sample is not used.
        """
        return self.first_arrival_ns is not None and (
            time.monotonic_ns() - self.first_arrival_ns <= self.max_age_ns)

    def _on_camera_matched(self, status: Any) -> None:
        """Log each change of the camera's publishers matched to ``ball_observation``.

        A reliable, volatile subscription gets nothing published before the match, and the
        match can lag the camera's start by seconds on a busy machine: this line is when the
        controller can first see the ball (an operator, or a test, releases it after), and
        when it can no longer (the camera node went away).
        """
        n = int(status.current_count)
        what = f"{n} publisher(s)" if n else "no publisher (the camera went away)"
        self.get_logger().info(f"{self.obs_sub.topic_name}: matched {what}")

    @guarded("ball_observation")
    def _on_ball(self, msg: BallObservationMsg) -> None:
        self._watch_pause()
        self.take_joints()  # the encoder samples that arrived before this observation
        self.stats["observations"] += 1
        t_ns = stamp_to_ns(msg.header.stamp)
        valid = bool(msg.valid) and msg.status == BallObservationMsg.FOUND
        self.pending.append(BallObservation(t_ns / _NS, float(msg.x), float(msg.y), valid))
        if len(self.pending) > 50:  # no joint_states to fuse them with: keep the newest
            del self.pending[:-50]
        if self.trigger == "observation" and self.js is not None and self.js[0] >= t_ns \
                and (not self.fault or self.exception_fault):
            self._step()

    def _watch_encoder(self, now: int) -> None:
        """Note the longest wall-time gap between two joint_states samples taken here.

        With the CPU this thread used meanwhile and when it ended (the system clock, the
        stamps' clock on the rig): a gap with little CPU is a driver that paused or a node that
        was not scheduled (a stopped process, a CPU taken away); much CPU, the node busy
        itself. Said in the exit line, where a test or an operator can put it beside the
        samples the loop left unanswered.
        """
        wall, cpu = time.monotonic(), time.thread_time()
        if self.js_wall is not None and wall - self.js_wall > self.worst_js_gap[0]:
            self.worst_js_gap = (wall - self.js_wall, cpu - self.js_cpu, time.time())
        self.js_wall, self.js_cpu = wall, cpu

    def _watch_pause(self) -> None:
        """Note a pause in the observations (wall clock) and whether this node was busy.

        A pause of ``_PAUSE_S`` or more between two observation callbacks is logged
        (throttled) with the CPU time this thread used meanwhile: little CPU means the
        observations did not come (camera, transport) or the node was not scheduled (a busy
        machine); much means the node itself was busy. The longest pause is in the exit log.
        """
        wall, cpu = time.monotonic(), time.thread_time()
        if self.obs_wall is not None:
            gap, used = wall - self.obs_wall, cpu - self.obs_cpu
            if gap >= _PAUSE_S:
                self.pauses += 1
                if gap > self.worst_pause[0]:
                    self.worst_pause = (gap, used)
                if self.throttle("pause", 5.0):
                    self.get_logger().warn(
                        f"no observation for {1e3 * gap:.0f} ms of wall time (this node used "
                        f"{1e3 * used:.1f} ms of CPU meanwhile: "
                        f"{'busy itself' if used > 0.5 * gap else 'waiting or not scheduled'})")
        self.obs_wall, self.obs_cpu = wall, cpu

    @guarded("timer")
    def _on_timer(self) -> None:
        self.take_joints()
        if self.js is not None and (not self.fault or self.exception_fault) and (
                self.last_step_ns is None or self.js[0] > self.last_step_ns):
            self._step()

    @guarded("reset")
    def _on_reset(self, request: Any, response: Any) -> Any:
        self.ctrl.reset()
        self.pending.clear()
        self.reported_lost = False
        self.off_orbit_since = None
        self.get_logger().warn("reset requested: controller back in WAITING")
        response.success = True
        response.message = "controller reset to WAITING"
        return response

    # -- the control step --------------------------------------------------------------------
    def _lead(self, t_ns: int) -> float:
        """Time from the encoder sample to the moment this step's command acts [s]."""
        now = self.get_clock().now().nanoseconds
        delay = max(now - t_ns, 0) / _NS if now > 0 else 0.0
        self.delays.append(delay)
        return delay + self.actuation_delay if self.predict else 0.0

    def _step(self) -> None:
        if self.js is None:
            return
        t_ns, theta, theta_dot = self.js
        t = t_ns / _NS
        due = [o for o in self.pending if o.t <= t + 1e-9]
        if due:
            self.pending = [o for o in self.pending if o.t > t + 1e-9]
        cmd = self.ctrl.step(t, theta, theta_dot, due or None, lead=self._lead(t_ns))
        self.last_step_ns = t_ns
        self.stats["steps"] += 1
        if self.exception_fault:  # a clean step: out of the exception's FAULT
            self.get_logger().info(f"a control step ran cleanly again after: {self.fault}; "
                                   + (_STAYS_LOST if self.ctrl.mode == BALL_LOST
                                      else "controller restarts in WAITING"))
            self.fault = ""
            self.exception_fault = False
        # the core clamps to the actuator's limit; the node only refuses a non-finite value
        torque = cmd.torque if (cmd.mode == ROLLING and math.isfinite(cmd.torque)) else 0.0
        mode = MODE_CODES[cmd.mode]
        reason = cmd.reason
        # a ball seen but staying off the orbit is reported lost (the core keeps watching)
        est = self.ctrl.estimator
        acq = self.ctrl.config.supervisor.acquire_frames
        if cmd.mode == WAITING and est.initialized and est.frames >= acq:
            if self.off_orbit_since is None:
                self.off_orbit_since = t
            elif t - self.off_orbit_since > self.acquire_timeout:
                mode = ControllerState.BALL_LOST
                reason = (f"ball seen but off the orbit for {t - self.off_orbit_since:.2f} s: "
                          f"not picked up ({cmd.reason})")
                if not self.reported_lost:
                    self.get_logger().warn(f"BALL_LOST: {reason}")
                    self.reported_lost = True
        else:
            self.off_orbit_since = None
        if cmd.mode == ROLLING:
            self.stats["rolling_steps"] += 1
            self.reported_lost = False
        self._publish(t_ns, torque, mode, theta, theta_dot, cmd)
        if mode != self.reported_mode:
            self._log_mode(mode, t, reason, cmd)
            self.reported_mode = mode

    def _log_mode(self, mode: int, t: float, reason: str, cmd: Command) -> None:
        log = self.get_logger()
        if mode == ControllerState.ROLLING:
            log.info(f"ROLLING at t = {t:.3f} s: ball picked up at phi = {cmd.phi:.3f} rad, "
                     f"phi_dot = {cmd.phi_dot:.3f} rad/s")
        elif mode == ControllerState.BALL_LOST and cmd.mode == BALL_LOST:
            log.error(f"BALL_LOST at t = {t:.3f} s: {reason}; torque 0 (latched: restart the "
                      f"node or call ~/reset); last lead {1e3 * cmd.lead:.1f} ms")
        elif mode == ControllerState.WAITING:
            log.info(f"WAITING at t = {t:.3f} s: {reason}")

    def _publish(self, t_ns: int, torque: float, mode: int, theta: float, theta_dot: float,
                 cmd: Command | None) -> None:
        out = Float64MultiArray()
        out.data = [float(torque)]
        self.cmd_pub.publish(out)
        self.stats["commands"] += 1
        st = ControllerState()
        st.header.stamp.sec, st.header.stamp.nanosec = t_ns // _NS, t_ns % _NS
        st.mode = mode
        st.theta, st.theta_dot = float(theta), float(theta_dot)
        nan = math.nan
        if cmd is not None:
            st.phi, st.phi_dot = float(cmd.phi), float(cmd.phi_dot)
            st.y, st.y_dot, st.z = float(cmd.y), float(cmd.y_dot), float(cmd.z)
            st.phase = float(cmd.phi) % math.pi if math.isfinite(cmd.phi) else nan
            st.torque_unsaturated = float(cmd.torque_unsat) if mode == ControllerState.ROLLING \
                else 0.0
            last_fix = self.ctrl.estimator.last_fix_t
            st.ball_age = float(t_ns / _NS - last_fix) if math.isfinite(last_fix) else math.inf
        else:
            st.phi = st.phi_dot = st.y = st.y_dot = st.z = st.phase = nan
            st.torque_unsaturated = 0.0
            st.ball_age = math.inf
        st.torque = float(torque)
        st.saturated = st.torque != st.torque_unsaturated
        self.stats["saturated"] += int(st.saturated)
        self.state_pub.publish(st)
        self.stats["states"] += 1

    # -- faults ----------------------------------------------------------------------------
    def _enter_fault(self, why: str, t_ns: int | None, theta: float | None = None,
                     theta_dot: float | None = None, log: bool = True) -> None:
        """FAULT with zero torque; one ``controller_state`` stamped ``t_ns``.

        ``t_ns``: the time of the measurement the fault derives from (a bad sample's stamp,
        the node's clock at a watchdog check); None for an exception in a step: the sample
        that step answered (the node's clock if none yet). ``theta``, ``theta_dot``: the
        values to report (None: those of the newest good sample).
        """
        logger = self.get_logger()
        if not self.fault:
            self.stats["faults"] += 1
            was = self.ctrl.mode
            if log:
                logger.error(f"FAULT: {why}; torque 0" + (
                    " (the ball was rolling: it is lost)" if was == ROLLING else ""))
        elif log and why != self.fault:
            logger.error(f"FAULT: {why}", throttle_duration_sec=2.0)
        self.fault = why
        self.exception_fault = False
        if t_ns is None:
            t_ns = self.js[0] if self.js is not None else self.get_clock().now().nanoseconds
        if theta is None or theta_dot is None:
            theta, theta_dot = (self.js[1], self.js[2]) if self.js is not None else (
                math.nan, math.nan)
        self._publish(t_ns, 0.0, ControllerState.FAULT, theta, theta_dot, None)
        self.reported_mode = ControllerState.FAULT

    @guarded("watchdog")
    def _watchdog(self) -> None:
        self.take_joints()
        now = self.get_clock().now().nanoseconds
        if now < self.js_clock_ns:  # the clock went back (a simulation restarted)
            self.js_clock_ns = now
        gap = (now - self.js_clock_ns) / _NS
        if self.first_js_ns is None:  # not armed before the first sample
            if gap > 5.0 and not self.fault:
                dropped = (f" ({self.backlog_dropped} stale sample(s) dropped as start-up "
                           f"backlog)" if self.backlog_dropped else "")
                other = self.joints.missing() or wrong_type_publishers(
                    self, self.js_sub.topic_name, "sensor_msgs/msg/JointState")
                self.get_logger().warn(f"no joint_states received yet on "
                                       f"{self.js_sub.topic_name}{dropped}"
                                       + (f"; {other}" if other else ""),
                                       throttle_duration_sec=10.0)
            return
        if gap > self.watchdog_timeout:  # stamped now: the check is the measurement
            self._enter_fault(f"no {self.js_sub.topic_name} for {gap:.2f} s of the node's "
                              f"clock: encoder driver or simulator dead", now, math.nan,
                              math.nan)

    def on_shutdown(self) -> None:
        """Publish a last zero command and log the counts."""
        out = Float64MultiArray()
        out.data = [0.0]
        self.cmd_pub.publish(out)
        s = self.stats
        est = self.ctrl.estimator
        d = sorted(self.delays)
        delay = (f"measured delay sample -> publication median {1e3 * d[len(d) // 2]:.2f} ms, "
                 f"p99 {1e3 * d[min(len(d) - 1, int(0.99 * len(d)))]:.2f} ms, max "
                 f"{1e3 * d[-1]:.2f} ms" if d else "no delay measured")
        self.get_logger().info(
            f"controller: {s['steps']} steps ({s['rolling_steps']} rolling, {s['saturated']} "
            f"saturated), {s['observations']} observations, {s['faults']} fault(s), "
            f"{s['exceptions']} exception(s); gate: {est.rejected['radial']} + "
            f"{est.rejected['innovation']} fixes rejected, restarts {est.restarts}; camera "
            f"stamps' jitter {1e3 * est.stamp_jitter:.2f} ms (from their intervals, weighed "
            f"into each fix's variance); {delay}; "
            f"pauses between observations >= {1e3 * _PAUSE_S:.0f} ms of wall time: "
            f"{self.pauses} (longest {1e3 * self.worst_pause[0]:.0f} ms, "
            f"{1e3 * self.worst_pause[1]:.1f} ms CPU); longest gap between joint_states "
            f"samples {1e3 * self.worst_js_gap[0]:.0f} ms ({1e3 * self.worst_js_gap[1]:.1f} ms "
            f"CPU), ended at {self.worst_js_gap[2]:.3f} s (system clock); zero torque "
            f"published on exit")
        self.get_logger().info(format_published({self.cmd_pub.topic_name: s["commands"] + 1,
                                                 self.state_pub.topic_name: s["states"]}))
        if isinstance(self.js_sub, PolledSubscription):
            self.js_sub.destroy()


#: What the node says when a fault ends while the ball's loss is latched.
_STAYS_LOST = "the controller stays BALL_LOST (latched: restart the node or call ~/reset)"


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ros2 run bfr_control controller_node``."""
    return run_node(ControllerNode, argv)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
