"""Rig logs of another Butterfly rig, in the NTNU terminal-log format, with truth sidecars.

Written apart from bfr. A run is simulated event by event: servo samples, control steps
(one log line each), camera exposures, fix arrivals and torque actuations, each at its own
time; the plant (physics.Plant) is advanced between events with the torque that acts.

Each data line reads (CRLF, numbers with ``digits`` significant digits like C++'s ostream)::

    [inf] t=<s>,torque=<N m>,theta=<rad>,phi=<rad>,dtheta=<rad/s>,dphi=<rad/s>,x=<m>,y=<m>

``t`` the logger's clock; ``torque`` the command of the step, which acts at
``t + torque_shift``; ``theta``, ``dtheta`` the servo's latest sample; ``x``, ``y`` the
latest camera fix (held between fixes; 0 before the first, after a loss 0 or held);
``phi = theta + atan2(x, y)`` formed by the rig software when a fix arrives, with the theta
of that line, and ``dphi`` its difference quotient between fixes (held). Around the data:
a script header, shell prompts with escape codes, build output, ``[inf] initializing
hardware..``/``done``/``stopped`` markers between runs, ``[obs]`` observer lines, ``^C``, a
last line cut short. Beside every log ``<name>.truth.json``: the seed, every effect's true
value, every sensor convention, each run's settings and what happened.

Usage::

    python -m tests.independent.rig_log set --out /tmp/indrig --seed 7          # a full set
    python -m tests.independent.rig_log set --out /tmp/indrig --seed 7 --quick  # short runs
    python -m tests.independent.rig_log one --out /tmp/r.txt --kind rolling --seed 3 \\
        --effect coulomb_pos=0.004 --sensor line_rate=500 --duration 20
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import controllers, physics, sensors

RUN_KINDS = ("rolling", "friction", "step", "held", "sine")


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """One run of the rig.

    Parameters
    ----------
    kind : str
        ``rolling`` (closed loop, ball), ``friction`` (frame speed tracking, no ball),
        ``step`` (torque step, no ball), ``held`` (frame braked, ball rolling free and
        settling, no torque), ``sine`` (sinusoidal torque, ball; it is usually lost).
    duration : float
        Length [s].
    speed_ref : float
        ``friction``: frame speed reference [rad/s].
    torque : float
        ``step`` level / ``sine`` amplitude [N m].
    frequency : float
        ``sine`` frequency [Hz].
    ball_speed : float
        ``rolling``: target half-lap mean ball speed [rad/s].
    ball_offset : float
        ``held``/``sine``: initial ball angle from the top of the waist [rad].
    ball_offset_dot : float
        ``held``: initial ball rate [rad/s].
    theta : float
        Initial frame angle [rad] (``rolling``/``held``/``sine`` start near a waist-up
        angle, a multiple of pi).
    """

    kind: str
    duration: float
    speed_ref: float = 1.0
    torque: float = 0.01
    frequency: float = 0.2
    ball_speed: float = 2.35
    ball_offset: float = 0.25
    ball_offset_dot: float = 0.0
    theta: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in RUN_KINDS:
            raise ValueError(f"run kind must be one of {', '.join(RUN_KINDS)}, got {self.kind!r}")
        if not (0.0 < self.duration <= 600.0):
            raise ValueError(f"run duration must be in (0, 600] s, got {self.duration}")
        if not (1.0 <= self.ball_speed <= 4.0):
            raise ValueError(f"ball_speed must be in [1, 4] rad/s, got {self.ball_speed}")
        if abs(self.torque) > 0.1:
            raise ValueError(f"torque must be within the 0.1 N m limit, got {self.torque}")


@dataclass
class RunResult:
    """A simulated run: the log's data rows, messages between them, and the truth.

    Parameters
    ----------
    rows : list of tuple
        ``(t, torque, theta, phi, dtheta, dphi, x, y)`` per line.
    messages : dict
        Line index -> text lines printed before that data line (``[obs]``, ``ball was lost``).
    truth : dict of numpy.ndarray
        True ``t_line, theta, theta_dot, ball_angle, ball_angle_dot, ball_x, ball_y,
        torque_acting, in_contact`` at each line.
    summary : dict
        What happened (for the sidecar).
    commands : list of tuple
        ``(t_action, torque)`` of every command, in run time [s, N m].
    """

    rows: list[tuple[float, ...]]
    messages: dict[int, list[str]] = field(default_factory=dict)
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    commands: list[tuple[float, float]] = field(default_factory=list)


def _initial_state(run: RunSpec, track: physics.Track,
                   constraint: controllers.Constraint | None) -> dict[str, Any]:
    if run.kind == "rolling":
        assert constraint is not None
        psi0 = math.pi * round(run.theta / math.pi)
        th, th1, _ = constraint.eval(psi0)
        v0 = 1.3 + 0.3 * (run.ball_speed - 2.0)
        return {"ball": True, "theta": th, "theta_dot": th1 * v0, "ball_angle": psi0,
                "ball_angle_dot": v0, "frame_locked": False}
    if run.kind in ("held", "sine"):
        th = math.pi * round(run.theta / math.pi)
        return {"ball": True, "theta": th, "theta_dot": 0.0,
                "ball_angle": th + run.ball_offset, "ball_angle_dot": run.ball_offset_dot,
                "frame_locked": run.kind == "held"}
    return {"ball": False, "theta": run.theta, "theta_dot": 0.0, "ball_angle": 0.0,
            "ball_angle_dot": 0.0, "frame_locked": False}


def simulate_run(rig: physics.RigParams, conv: sensors.SensorConventions, run: RunSpec,
                 rng: np.random.Generator, model: physics.RigParams | None = None,
                 track: physics.Track | None = None) -> RunResult:
    """Simulate one run event by event and produce its log rows.

    Parameters
    ----------
    rig : physics.RigParams
        The true rig.
    conv : sensors.SensorConventions
        Its sensors and logger.
    run : RunSpec
        The run.
    rng : numpy.random.Generator
        Seeded source of every random choice (jitter, noise).
    model : physics.RigParams, optional
        The controller's nominal model (default: the nominal rig).
    track : physics.Track, optional
        The true rig's prebuilt track.

    Returns
    -------
    RunResult
        Rows, messages and truth.
    """
    return _RunSimulator(rig, conv, run, rng, model, track).run()


class _RunSimulator:
    """The event loop of :func:`simulate_run` and the rig software's bookkeeping.

    Events, each at its own time: servo samples (``servo_rate``), camera exposures
    (jittered ``camera_rate``), fix arrivals (exposure + ``camera_latency``) into the rig
    software's mailbox, torque actuations (control step + ``actuation_delay``) and control
    steps (jittered ``line_rate``), which read the mailbox, form ``phi``/``dphi``, run the
    controller and print a line.
    """

    TRUTH = ("t_line", "theta", "theta_dot", "ball_angle", "ball_angle_dot", "ball_x",
             "ball_y", "torque_acting", "in_contact")

    def __init__(self, rig: physics.RigParams, conv: sensors.SensorConventions, run: RunSpec,
                 rng: np.random.Generator, model: physics.RigParams | None,
                 track: physics.Track | None) -> None:
        track = track if track is not None else physics.Track.build(rig)
        self.conv, self.spec, self.rng = conv, run, rng
        self.gains = controllers.StabiliserGains(speed_ref=run.ball_speed)
        self.stabiliser = controllers.BallStabiliser(model or physics.RigParams(), self.gains) \
            if run.kind == "rolling" else None
        self.init = _initial_state(run, track,
                                   self.stabiliser.constraint if self.stabiliser else None)
        self.plant = physics.Plant(rig, track=track, dt=5e-4, **self.init)
        self.servo = sensors.Servo(conv)
        self.camera = sensors.Camera(conv, rng)
        self.estimator = controllers.BallEstimator(latency=0.005)
        self.speed_pi = controllers.SpeedPI(speed_ref=run.speed_ref) \
            if run.kind == "friction" else None
        self.program = controllers.TorqueProgram(
            level=run.torque if run.kind == "step" else 0.0,
            amplitude=run.torque if run.kind == "sine" else 0.0, frequency=run.frequency)
        self.arrivals: list[tuple[float, tuple[float, float] | None]] = []
        self.actuations: list[tuple[float, float]] = []
        self.commands: list[tuple[float, float]] = [(-1.0, 0.0)]
        self.u_act = 0.0
        self.mailbox: tuple[float, float] | bool | None = False  # False: nothing new
        self.fix_xy = (0.0, 0.0)
        self.phi = self.dphi = 0.0
        self.phi_line_t: float | None = None
        self.last_fix_t: float | None = None
        self.seen = self.lost_logged = False
        self.lost_at: float | None = None
        self.rows: list[tuple[float, ...]] = []
        self.messages: dict[int, list[str]] = {}
        self.truth: dict[str, list[float]] = {k: [] for k in self.TRUTH}
        self.t_obs = 0.0
        if self.stabiliser is not None:  # the camera tracked the ball before the log starts
            self.estimator.prime(0.0, self.init["ball_angle"], self.init["ball_angle_dot"])
            self.last_fix_t = 0.0
        self.t_log0 = conv.t_start + float(rng.uniform(-0.1, 0.9))

    def run(self) -> RunResult:
        conv = self.conv
        t_line, t_servo, t_cam = 0.0, 0.0, 0.5 * self.camera.next_period()
        while True:
            t = min(t_line, t_servo, t_cam,
                    self.arrivals[0][0] if self.arrivals else math.inf,
                    self.actuations[0][0] if self.actuations else math.inf)
            if t > self.spec.duration:
                break
            self.plant.advance(t - self.plant.t, self.u_act)
            self.plant.t = t
            while self.actuations and self.actuations[0][0] <= t:
                self.u_act = self.actuations.pop(0)[1]
            if t_servo <= t:
                self.servo.sample(self.plant.theta, self.plant.theta_dot)
                self.estimator.frame_sample(t, self.servo.theta)
                t_servo += 1.0 / conv.servo_rate
            if t_cam <= t:
                x, y, _, _ = self.plant.ball_world()
                self.arrivals.append((t + conv.camera_latency, self.camera.measure(x, y)))
                t_cam += self.camera.next_period()
            while self.arrivals and self.arrivals[0][0] <= t:
                self.mailbox = self.arrivals.pop(0)[1]
            if t_line <= t:
                self._control_step(t)
                t_line += max(0.3, 1.0 + conv.line_jitter * float(self.rng.standard_normal())) \
                    / conv.line_rate
        return self._result()

    def _read_mailbox(self, t: float) -> None:
        """The rig software takes the newest fix: ``phi = theta + atan2(x, y)``, ``dphi``."""
        fix, self.mailbox = self.mailbox, False
        if fix is False:
            return
        if fix is None:
            if self.seen and self.conv.lost_fill == "zero":
                self.fix_xy, self.phi, self.dphi = (0.0, 0.0), 0.0, 0.0
            return
        assert isinstance(fix, tuple)
        new_phi = math.atan2(fix[0], fix[1])
        if not (self.spec.kind == "rolling" and t < self.conv.phi_lead_in):
            new_phi += self.servo.theta
        if self.seen and self.phi_line_t is not None and self.phi != 0.0:
            self.dphi = (new_phi - self.phi) / (t - self.phi_line_t)
        self.phi, self.fix_xy, self.phi_line_t, self.last_fix_t = new_phi, fix, t, t
        self.seen = True
        self.estimator.fix(t, *fix)

    def _control_step(self, t: float) -> None:
        self._read_mailbox(t)
        k = len(self.rows)
        fix_age = t - self.last_fix_t if self.last_fix_t is not None else math.inf
        if self.stabiliser is not None:
            psi_hat, psi_dot_hat = self.estimator.estimate(t)
            u = self.stabiliser.command(t, self.servo.theta, self.servo.velocity, psi_hat,
                                        psi_dot_hat, fix_age)
            if t >= self.t_obs:
                self.messages.setdefault(k, []).append(
                    f"[obs] psi_hat={psi_hat:.6g},dpsi_hat={psi_dot_hat:.6g},"
                    f"delta={self.stabiliser.delta:.4g},age={fix_age:.4g}")
                self.t_obs = t + 0.1
        elif self.speed_pi is not None:
            u = self.speed_pi.command(t, self.servo.velocity)
        else:
            u = self.program.command(t)
        u = max(-0.1, min(0.1, u))
        if self.init["ball"] and self.seen and not self.lost_logged and (
                (self.stabiliser is not None and self.stabiliser.lost) or fix_age > 0.1):
            self.messages.setdefault(k, []).append("[inf] ball was lost")
            self.lost_logged, self.lost_at = True, t
        t_act = t + self.conv.actuation_delay
        self.commands.append((t_act, u))
        self.actuations.append((t_act, u))
        logged_torque = _acting_at(self.commands, t + self.conv.torque_shift)
        self.rows.append((self.t_log0 + t, logged_torque, self.servo.theta, self.phi,
                          self.servo.velocity, self.dphi, *self.fix_xy))
        st = self.plant.state()
        for name, value in zip(self.TRUTH, (t, st.theta, st.theta_dot, st.ball_angle,
                                            st.ball_angle_dot, st.ball_x, st.ball_y,
                                            self.u_act, float(st.in_contact)), strict=True):
            self.truth[name].append(value)

    def _result(self) -> RunResult:
        rows, spec = self.rows, self.spec
        summary: dict[str, Any] = {
            "kind": spec.kind, "spec": asdict(spec), "lines": len(rows),
            "t_first": rows[0][0] if rows else None, "t_last": rows[-1][0] if rows else None,
            "logger_t_offset": self.t_log0, "initial_state": self.init,
            "final_mode": self.plant.mode, "ball_lost_at": self.lost_at,
            "energy_final": self.plant.state().energy,
        }
        if self.stabiliser is not None:
            speeds = self.stabiliser.half_lap_speeds
            summary["half_lap_speeds"] = [round(v, 4) for v in speeds]
            summary["mean_ball_speed"] = float(np.mean(speeds[1:])) if len(speeds) > 1 else None
            summary["controller"] = asdict(self.gains)
        if self.speed_pi is not None:
            summary["controller"] = {"speed_ref": self.speed_pi.speed_ref,
                                     "kp": self.speed_pi.kp, "ki": self.speed_pi.ki,
                                     "ramp": self.speed_pi.ramp}
        return RunResult(rows=rows, messages=self.messages,
                         truth={k: np.asarray(v) for k, v in self.truth.items()},
                         summary=summary, commands=self.commands[1:])


def _acting_at(commands: list[tuple[float, float]], t: float) -> float:
    """The command acting at ``t``: the last one with action time <= t."""
    for t_act, value in reversed(commands):
        if t_act <= t + 1e-12:
            return value
    return 0.0


# ------------------------------------------------------------------------- formatting
_ESC = "\x1b"


def _num(value: float, digits: int) -> str:
    """A number as C++'s ``operator<<`` prints it with ``setprecision(digits)`` (%g)."""
    if value == 0.0:
        return "0"
    text = f"{value:.{digits}g}"
    return text


@dataclass(frozen=True, kw_only=True)
class Terminal:
    """The terminal noise around the data of another rig's logs.

    Parameters
    ----------
    user, host, path : str
        Shell prompt parts.
    script : str
        The command that starts a run.
    header : bool
        Start with a ``Script started on ...`` line.
    build_output : bool
        Print build output before the first run.
    cut_last_line : bool
        The file ends in the middle of a data line.
    interrupt : bool
        Prefix the last run's first data line with ``^C`` (as a real log has).
    """

    user: str = "lab"
    host: str = "bfly-rig2"
    path: str = "~/rigs/bfly2/control"
    script: str = "./run_rig.sh"
    header: bool = True
    build_output: bool = True
    cut_last_line: bool = True
    interrupt: bool = False

    def prompt(self, command: str = "") -> str:
        """A bash prompt line with its title and colour escape codes."""
        who = f"{self.user}@{self.host}"
        return (f"{_ESC}]0;{who}: {self.path}\x07{_ESC}[01;32m{who}{_ESC}[00m:"
                f"{_ESC}[01;34m{self.path}{_ESC}[00m$ {command}")


def format_log(runs: list[RunResult], conv: sensors.SensorConventions, term: Terminal,
               rng: np.random.Generator) -> str:
    """Assemble the terminal log of one or more runs (CRLF line ends).

    Parameters
    ----------
    runs : list of RunResult
        The runs, in order (a restart marker between them).
    conv : sensors.SensorConventions
        For the number format.
    term : Terminal
        The terminal noise.
    rng : numpy.random.Generator
        Seeded choices (date, editing noise).

    Returns
    -------
    str
        The log text.
    """
    out: list[str] = []
    if term.header:
        day = ["mon", "tue", "wed", "thu", "fri", "sat", "sun"][int(rng.integers(7))]
        out.append(f"Script started on {day} {int(rng.integers(1, 29))} "
                   f"{['jan', 'feb', 'mar', 'apr', 'may', 'jun'][int(rng.integers(6))]} 2022 "
                   f"{int(rng.integers(8, 20)):02d}:{int(rng.integers(60)):02d}:"
                   f"{int(rng.integers(60)):02d}")
    out.append(term.prompt("cd ..") + f"{_ESC}[K")
    if term.build_output:
        out.append(term.prompt("./build.sh"))
        out += ["-- Configuring done", "-- Generating done",
                "[ 40%] Built target rigio", f"{_ESC}[35m{_ESC}[1mScanning dependencies of "
                f"target rig_control{_ESC}[0m", f"[ 80%] {_ESC}[32mBuilding CXX object "
                f"src/rig_control.cpp.o{_ESC}[0m", "[100%] Built target rig_control"]
    d = conv.digits
    for i, run in enumerate(runs):
        out.append(term.prompt(f"{_ESC}[A{term.script}") if i else term.prompt(term.script))
        out += ["[inf] initializing hardware..", "[inf] done"]
        for k, row in enumerate(run.rows):
            out += run.messages.get(k, [])
            line = ("[inf] t={},torque={},theta={},phi={},dtheta={},dphi={},x={},y={}"
                    .format(*(_num(v, d) for v in row)))
            if term.interrupt and i == len(runs) - 1 and k == 0:
                line = "^C" + line
            out.append(line)
        if i < len(runs) - 1 or not term.cut_last_line:
            out.append("[inf] stopped")
            out.append(term.prompt())
    text = "\r\n".join(out)
    if term.cut_last_line and runs and runs[-1].rows:
        last = text.rfind("\r\n")
        cut = last + 2 + int(rng.integers(12, 40))
        return text[:cut]
    return text + "\r\n"


# --------------------------------------------------------------------- sets of logs
#: Effects a concealed rig may carry: name -> sampler(rng) returning RigParams changes.
def _draw_effects(rng: np.random.Generator, count: int) -> dict[str, Any]:
    nominal = physics.RigParams()

    def sign() -> float:
        return 1.0 if rng.random() < 0.5 else -1.0

    def harmonics() -> dict[str, Any]:
        cos, sin = [0.0] * physics.N_HARMONICS, [0.0] * physics.N_HARMONICS
        for k in rng.choice(np.arange(1, 9), size=2, replace=False):
            cos[k - 1] = float(rng.uniform(-4e-4, 4e-4))
            sin[k - 1] = float(rng.uniform(-4e-4, 4e-4))
        return {"harmonics_cos": tuple(cos), "harmonics_sin": tuple(sin)}

    def friction() -> dict[str, Any]:
        f = float(rng.uniform(1e-3, 5e-3))
        return {"coulomb_pos": f, "coulomb_neg": f * float(rng.uniform(0.6, 1.5))}

    def bumps() -> dict[str, Any]:
        n = int(rng.integers(3, 9))
        return {"bumps": tuple(physics.Bump(angle=float(a), height=float(h), width=float(w))
                               for a, h, w in zip(rng.uniform(0, 2 * np.pi, n),
                                                  rng.uniform(1e-4, 3e-4, n),
                                                  rng.uniform(3e-3, 6e-3, n), strict=True))}

    library = {
        "joint_friction": friction,
        "viscous": lambda: {"viscous": float(rng.uniform(3e-5, 2e-4))},
        "torque_offset": lambda: {"torque_offset": sign() * float(rng.uniform(5e-4, 2e-3))},
        "motor_gain": lambda: {"motor_gain": float(rng.uniform(0.85, 1.15))},
        "frame_inertia": lambda: {"frame_inertia_scale": float(rng.uniform(0.85, 1.2))},
        "imbalance": lambda: {"imbalance": float(rng.uniform(1e-4, 4e-4)),
                              "imbalance_angle": float(rng.uniform(0, 2 * np.pi))},
        "contour_a": lambda: {"contour_radius_delta": sign() * float(rng.uniform(5e-4, 2e-3))},
        "contour_b": lambda: {"contour_b": nominal.contour_b
                              + sign() * float(rng.uniform(5e-4, 2e-3))},
        "harmonics": harmonics,
        "ball_radius": lambda: {"ball_radius": nominal.ball_radius
                                + sign() * float(rng.uniform(2e-4, 5e-4))},
        "ball_mass": lambda: {"ball_mass": nominal.ball_mass * float(rng.uniform(0.9, 1.2))},
        "rolling_resistance": lambda: {"rolling_resistance": float(rng.uniform(5e-4, 3e-3))},
        "shaft_tilt": lambda: {"shaft_tilt": float(rng.uniform(0.02, 0.06))},
        "bumps": bumps,
    }
    names = rng.choice(sorted(library), size=count, replace=False)
    changes: dict[str, Any] = {}
    for name in sorted(names):
        changes.update(library[name]())
    return changes


def draw_conventions(rng: np.random.Generator) -> sensors.SensorConventions:
    """Another rig's sensors and logger, drawn within the ranges of the design.

    Parameters
    ----------
    rng : numpy.random.Generator
        Seeded source.

    Returns
    -------
    sensors.SensorConventions
        The conventions.
    """
    mode = str(rng.choice(sensors.VELOCITY_MODES))
    line_rate = float(rng.choice([float(rng.uniform(150, 1000)), 909.0, 500.0]))
    camera_rate = float(rng.uniform(150, 250))
    shift = float(rng.uniform(-2e-3, 2e-3))
    return sensors.SensorConventions(
        line_rate=line_rate, line_jitter=float(rng.uniform(0.0, 0.12)),
        servo_rate=float(max(line_rate, rng.choice([1000.0, 2000.0, 4000.0]))),
        counts_per_rev=int(rng.choice([4096, 16384, 65536])), velocity_mode=mode,
        velocity_lag=0.0 if mode == "true" else float(rng.uniform(0.0, 0.01)),
        torque_shift=shift, actuation_delay=max(0.0, shift) + float(rng.uniform(0, 1e-3)),
        camera_rate=camera_rate, camera_jitter=float(rng.uniform(0.0, 0.05 / camera_rate)),
        camera_latency=float(rng.uniform(0.002, 0.012)),
        camera_noise=float(rng.uniform(5e-5, 3e-4)),
        camera_offset=(float(rng.uniform(-1e-3, 1e-3)), float(rng.uniform(-1e-3, 1e-3))),
        camera_scale=float(rng.uniform(-0.01, 0.01)),
        camera_rotation=float(rng.uniform(-0.006, 0.006)),
        lost_fill=str(rng.choice(sensors.LOST_FILL)),
        phi_lead_in=float(rng.choice([0.0, 0.0, 0.3])),
        digits=int(rng.choice([6, 6, 6, 8])), t_start=float(rng.uniform(3.5, 5.0)))


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.floating | np.integer):
        return _jsonable(value.item())
    return value


def rig_truth(rig: physics.RigParams) -> dict[str, Any]:
    """Every physical parameter of a rig, derived values, and the effects (non-nominal)."""
    nominal = physics.RigParams()
    values = {f.name: getattr(rig, f.name) for f in fields(rig)}
    values["bumps"] = [asdict(b) for b in rig.bumps]
    effects = {f.name: values[f.name] for f in fields(rig)
               if getattr(rig, f.name) != getattr(nominal, f.name)}
    return {"parameters": values, "effects": effects,
            "derived": {"rolling_radius": rig.rolling_radius, "ball_inertia": rig.ball_inertia,
                        "frame_inertia_total": rig.frame_inertia_total,
                        "contour_a_effective": rig.a_eff, "in_plane_gravity": rig.g_plane}}


CONVENTION_TEXT = {
    "columns": "t [s] logger clock; torque [N m] commanded; theta [rad] servo angle "
               "(quantised, latest servo sample); phi [rad] = theta + atan2(x, y) formed at "
               "the control step that first sees a new fix, with that step's theta; "
               "dtheta [rad/s] servo velocity; dphi [rad/s] = (phi - previous phi) / "
               "(time between the two steps); x, y [m] newest camera fix, held; before the "
               "first fix x = y = phi = dphi = 0; after the ball is lost: lost_fill 'zero' "
               "sets x = y = phi = dphi = 0, 'hold' keeps the last values",
    "torque_timing": "the torque printed on a line acts on the frame from t_line + "
                     "torque_shift until the next command's action",
    "fix_model": "fix = (1 + camera_scale) Rot(camera_rotation) p_true + camera_offset + "
                 "N(0, camera_noise^2); available camera_latency after the exposure",
    "velocity": "difference: (q_k - q_{k-w}) / (w / servo_rate), w = velocity_window; "
                "filter: first-order low-pass (time constant velocity_lag) of the one-sample "
                "difference; true: the exact rate",
    "ball_angle": "clockwise from the frame's +y axis (phi convention), in frame coordinates",
}


def write_log(path: Path, rig: physics.RigParams, conv: sensors.SensorConventions,
              runs: list[RunSpec], seed: int, term: Terminal | None = None,
              truth_series: bool = False, label: str = "") -> dict[str, Any]:
    """Simulate runs of one rig and write ``path`` and ``path.truth.json`` beside it.

    Parameters
    ----------
    path : pathlib.Path
        Log file (``.txt``).
    rig : physics.RigParams
        The true rig.
    conv : sensors.SensorConventions
        Its sensors.
    runs : list of RunSpec
        Runs, in order, in one file.
    seed : int
        Seed of this log's noise.
    term : Terminal, optional
        Terminal noise (default drawn from the seed).
    truth_series : bool
        Also write ``path.truth.csv`` (the true state at every line).
    label : str
        A name for the rig, stored in the sidecar.

    Returns
    -------
    dict
        The sidecar's content.
    """
    rng = np.random.default_rng(seed)
    track = physics.Track.build(rig)
    if term is None:
        term = Terminal(interrupt=bool(rng.random() < 0.3),
                        cut_last_line=bool(rng.random() < 0.7))
    results = []
    theta = runs[0].theta
    for spec in runs:
        results.append(simulate_run(rig, conv, replace(spec, theta=theta), rng, track=track))
        theta = float(results[-1].truth["theta"][-1]) + float(rng.uniform(0.0, 0.4)) \
            if results[-1].truth["theta"].size else theta
    text = format_log(results, conv, term, rng)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode())
    sidecar = {
        "log": path.name, "seed": seed, "rig_label": label,
        "rig": rig_truth(rig),
        "sensors": {**asdict(conv), "velocity_window": conv.velocity_window,
                    "effective_velocity_lag": conv.effective_velocity_lag},
        "conventions": CONVENTION_TEXT, "terminal": asdict(term),
        "runs": [r.summary for r in results],
    }
    path.with_suffix(".truth.json").write_text(json.dumps(_jsonable(sidecar), indent=1) + "\n")
    if truth_series:
        names = list(results[0].truth)
        data = np.concatenate([np.column_stack([np.full(len(r.rows), i)]
                                               + [r.truth[n] for n in names])
                               for i, r in enumerate(results)])
        np.savetxt(path.with_suffix(".truth.csv"), data, delimiter=",",
                   header=",".join(["run", *names]), comments="", fmt="%.9g")
    return sidecar


def standard_set(out: Path, seed: int, quick: bool = False, truth_series: bool = False,
                 progress: bool = True) -> list[dict[str, Any]]:
    """Write a set of logs: a clean rig and a rig with concealed effects, every run kind.

    Each rig gets its own drawn sensor conventions; its files: ``rolling`` (one run),
    ``rolling_pair`` (two runs in one file), ``friction_1``, ``friction_5``,
    ``friction_negative_1``, ``step_pair`` (two torque steps), ``held``, ``sine``.

    Parameters
    ----------
    out : pathlib.Path
        Output folder (created).
    seed : int
        Seed of the whole set.
    quick : bool
        Short runs (seconds instead of tens of seconds).
    truth_series : bool
        Also write the true state at every line.
    progress : bool
        Report each file on stderr.

    Returns
    -------
    list of dict
        The sidecars.
    """
    rng = np.random.default_rng(seed)
    scale = 0.12 if quick else 1.0
    rigs = {"clean": physics.RigParams(),
            "effects": physics.RigParams(**_draw_effects(rng, int(rng.integers(2, 6))))}
    plans = {
        "rolling": [RunSpec(kind="rolling", duration=25.0 * scale,
                            ball_speed=float(rng.uniform(2.15, 2.55)))],
        "rolling_pair": [RunSpec(kind="rolling", duration=15.0 * scale,
                                 ball_speed=float(rng.uniform(2.15, 2.55)))] * 2,
        "friction_1": [RunSpec(kind="friction", duration=30.0 * scale, speed_ref=1.0)],
        "friction_5": [RunSpec(kind="friction", duration=20.0 * scale, speed_ref=5.0)],
        "friction_negative_1": [RunSpec(kind="friction", duration=30.0 * scale,
                                        speed_ref=-1.0)],
        "step_pair": [RunSpec(kind="step", duration=max(1.0, 5.0 * scale), torque=0.01)] * 2,
        "held": [RunSpec(kind="held", duration=20.0 * scale,
                         ball_offset=float(rng.uniform(0.1, 0.25)),
                         ball_offset_dot=float(rng.uniform(-1.5, 1.5)))],
        "sine": [RunSpec(kind="sine", duration=30.0 * scale, torque=0.01, frequency=0.2)],
    }
    sidecars = []
    for label, rig in rigs.items():
        conv = draw_conventions(rng)
        for name, runs in plans.items():
            file_seed = int(rng.integers(2**31))
            path = out / label / f"{name}.txt"
            sidecar = write_log(path, rig, conv, list(runs), file_seed,
                                truth_series=truth_series, label=label)
            sidecars.append(sidecar)
            if progress:
                lines = sum(r["lines"] for r in sidecar["runs"])
                lost = [r["ball_lost_at"] for r in sidecar["runs"]]
                print(f"rig_log: {path} ({lines} lines, ball lost at {lost})",
                      file=sys.stderr, flush=True)
    index = [{"log": f"{s['rig_label']}/{s['log']}", "runs": [r["kind"] for r in s["runs"]],
              "effects": sorted(s["rig"]["effects"])} for s in sidecars]
    (out / "index.json").write_text(json.dumps({"seed": seed, "quick": quick, "logs": index},
                                               indent=1) + "\n")
    return sidecars


def _assignments(items: list[str], kind: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise ValueError(f"--{kind} needs NAME=VALUE, got {item!r}")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text
        out[name.strip()] = tuple(value) if isinstance(value, list) else value
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: ``set`` writes a standard set, ``one`` a single log.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (``sys.argv[1:]`` when omitted).

    Returns
    -------
    int
        0 on success, 2 on bad input.
    """
    parser = argparse.ArgumentParser(
        prog="python -m tests.independent.rig_log",
        description="Rig logs of an independent Butterfly rig (NTNU terminal-log format) "
                    "with truth sidecars.")
    sub = parser.add_subparsers(dest="command", required=True)
    p_set = sub.add_parser("set", help="a clean rig and a rig with concealed effects, "
                                       "every run kind, singles and pairs")
    p_set.add_argument("--out", type=Path, required=True, help="output folder")
    p_set.add_argument("--seed", type=int, default=0, help="seed of the whole set")
    p_set.add_argument("--quick", action="store_true", help="short runs (for tests)")
    p_set.add_argument("--truth-series", action="store_true",
                       help="also write <log>.truth.csv, the true state at every line")
    p_one = sub.add_parser("one", help="one log of one rig")
    p_one.add_argument("--out", type=Path, required=True, help="log file (.txt)")
    p_one.add_argument("--kind", choices=RUN_KINDS, required=True)
    p_one.add_argument("--runs", type=int, default=1, help="runs in the file")
    p_one.add_argument("--duration", type=float, default=10.0, help="each run [s]")
    p_one.add_argument("--seed", type=int, default=0)
    p_one.add_argument("--speed-ref", type=float, default=1.0, help="friction run [rad/s]")
    p_one.add_argument("--torque", type=float, default=0.01, help="step/sine [N m]")
    p_one.add_argument("--ball-speed", type=float, default=2.35, help="rolling [rad/s]")
    p_one.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                       help="a physics.RigParams field, e.g. coulomb_pos=0.004")
    p_one.add_argument("--sensor", action="append", default=[], metavar="NAME=VALUE",
                       help="a sensors.SensorConventions field, e.g. line_rate=500")
    p_one.add_argument("--drawn-sensors", action="store_true",
                       help="draw the sensor conventions from the seed (before --sensor)")
    p_one.add_argument("--truth-series", action="store_true")
    args = parser.parse_args(argv)
    try:
        if args.command == "set":
            if args.out.exists() and any(args.out.iterdir()):
                raise ValueError(f"{args.out} exists and is not empty (nothing overwritten)")
            standard_set(args.out, args.seed, quick=args.quick,
                         truth_series=args.truth_series)
            print(f"rig_log: set written to {args.out} (index.json)", file=sys.stderr)
            return 0
        if args.out.exists():
            raise ValueError(f"{args.out} exists (nothing overwritten)")
        if args.runs < 1:
            raise ValueError("--runs must be >= 1")
        rig = physics.RigParams(**_assignments(args.effect, "effect"))
        base = draw_conventions(np.random.default_rng(args.seed + 7919)) \
            if args.drawn_sensors else sensors.SensorConventions()
        conv = replace(base, **_assignments(args.sensor, "sensor"))
        spec = RunSpec(kind=args.kind, duration=args.duration, speed_ref=args.speed_ref,
                       torque=args.torque, ball_speed=args.ball_speed)
        physics.Track.build(rig)
        sidecar = write_log(args.out, rig, conv, [spec] * args.runs, args.seed,
                            truth_series=args.truth_series, label="one")
        for r in sidecar["runs"]:
            print(f"rig_log: {args.out}: {r['kind']} {r['lines']} lines, final ball mode "
                  f"{r['final_mode']}, ball lost at {r['ball_lost_at']}", file=sys.stderr)
        return 0
    except (ValueError, TypeError, OSError) as exc:
        print(f"rig_log: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
