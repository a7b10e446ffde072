r"""``bfr simulate``: the rigid model offline, open loop or closed by the controller.

Open loop from an initial state under a torque command that is constant or read from a CSV
of ``(t, u)`` rows (bfr_model.simulate); with ``--controller`` the orbital stabilisation
controller closes the loop through the sensor models of :mod:`bfr_sim.closed_loop`. Writes a
trajectory file (CSV; an ``.mcap`` extension writes a ROS 2 bag) and optionally prints a JSON
summary.

Example::

    scripts/bfr simulate --theta 0.3 --phi 1.2 --theta-dot 0.5 --phi-dot 2.0 --torque 0 \\
        --duration 3 --out run.csv --json
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from bfr_control.controller import OrbitalController, load_controller_config
from bfr_model.dynamics import RigidModel
from bfr_model.integrators import IntegrationError
from bfr_model.io.bag import write_recording_bag
from bfr_model.io.output import OutputError, atomic_dir, atomic_file, check_new
from bfr_model.params import ParameterError, RigParams, load_params
from bfr_model.recording import Recording, RecordingError
from bfr_model.simulate import simulate, torque_from_csv, write_csv

from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop

__all__ = ["build_parser", "main", "simulate_with_controller"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr simulate``."""
    p = argparse.ArgumentParser(
        prog="bfr simulate",
        description="Simulate the Butterfly robot's rigid model (frame + ball rolling without "
                    "slipping) from an initial state under a torque command, and write the "
                    "trajectory. Angles follow DEVELOPERS.md: theta the frame angle (CCW), phi "
                    "the contact point's contour angle (clockwise from the frame's +y axis).",
        epilog="Example: bfr simulate --theta 0.3 --phi 1.2 --theta-dot 0.5 --phi-dot 2.0 "
               "--torque 0 --duration 3 --out run.csv --json")
    p.add_argument("--theta", type=float, default=0.0, help="initial frame angle [rad]")
    p.add_argument("--phi", type=float, default=0.0, help="initial contact angle [rad]")
    p.add_argument("--theta-dot", type=float, default=0.0, help="initial frame speed [rad/s]")
    p.add_argument("--phi-dot", type=float, default=0.0, help="initial contact-angle rate [rad/s]")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--torque", type=float, default=0.0,
                     help="constant commanded torque [N m] (default 0)")
    src.add_argument("--torque-csv", type=Path, help="CSV of 't, u' rows [s, N m], held")
    p.add_argument("--duration", type=float, default=3.0, help="simulated time [s]")
    p.add_argument("--dt", type=float, default=1e-3, help="step / output interval [s]")
    p.add_argument("--integrator", default="rk4",
                   help="rk4 (fixed step, default) or a scipy method: DOP853, Radau, LSODA")
    p.add_argument("--params", type=Path, help="parameter YAML (default: bfr_sim rig.yaml)")
    p.add_argument("--out", type=Path, help="trajectory file: .csv, or .mcap for a ROS 2 bag "
                   "(the bag folder is the path without .mcap); written atomically")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out (default: refuse)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    cl = p.add_argument_group(
        "closed loop (bfr_control)",
        "With --controller the orbital stabilisation controller closes the loop, seeing only "
        "the encoder and the camera. The ball starts on the controller's orbit at contact "
        "angle --phi; --theta, --theta-dot, --phi-dot are offsets from the orbit's state.")
    cl.add_argument("--controller", action="store_true",
                    help="close the loop with bfr_control's controller")
    cl.add_argument("--controller-config", type=Path,
                    help="controller.yaml (default: bfr_control's)")
    cl.add_argument("--controller-params", type=Path,
                    help="the controller's model parameters (default: same as --params)")
    cl.add_argument("--camera-rate", type=float, default=200.0, help="camera rate [Hz]")
    cl.add_argument("--camera-latency", type=float, default=0.005,
                    help="camera delay from exposure to delivery [s]")
    cl.add_argument("--camera-noise", type=float, default=1e-4,
                    help="camera position noise per axis [m]")
    cl.add_argument("--control-rate", type=float,
                    help="control rate [Hz] (default: controller.yaml's)")
    cl.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    return p


def simulate_with_controller(args: Any) -> int:
    """``bfr simulate --controller``: the closed loop from the parsed simulate arguments.

    The ball starts on the controller's orbit at contact angle ``--phi``; ``--theta``,
    ``--theta-dot`` and ``--phi-dot`` are offsets from the orbit's state there. The plant's
    physics is ``--params``, the controller's model ``--controller-params`` (default: the
    same file), its settings ``--controller-config``. Prints the run's summary (JSON with
    ``--json``) and writes the true trajectory with ``--out`` like the open-loop command.
    """
    if args.integrator != "rk4":
        print("bfr simulate: error: --controller runs the plant with --integrator rk4",
              file=sys.stderr)
        return 2
    if args.torque_csv is not None or args.torque != 0.0:
        print("bfr simulate: error: --controller computes the torque; drop --torque/--torque-csv",
              file=sys.stderr)
        return 2
    try:
        plant = load_params(args.params)
        cparams = load_params(args.controller_params) if args.controller_params else plant
        config = load_controller_config(args.controller_config)
        controller = OrbitalController(cparams, config)
        sensors = SensorConfig(camera_rate=args.camera_rate, camera_latency=args.camera_latency,
                               camera_noise=args.camera_noise)
        x0 = orbit_initial_state(controller, args.phi, d_theta=args.theta,
                                 d_theta_dot=args.theta_dot, d_phi_dot=args.phi_dot)
        res = run_closed_loop(controller, plant, args.duration, x0, sensors, seed=args.seed,
                              plant_dt=args.dt, control_rate=args.control_rate)
    except (ParameterError, ValueError, ArithmeticError, FileNotFoundError) as exc:
        print(f"bfr simulate: error: {exc}", file=sys.stderr)
        return 2
    if args.out is not None:
        code = _write_out(args, res.to_sim_result(RigidModel(plant)), RigidModel(plant))
        if code:
            return code
    summary = res.summary()
    summary["controller"] = controller.summary()
    if args.json:
        print(json.dumps(summary))
    else:
        why = summary["failure"] or ""
        if summary["lost_reason"]:
            why += f": {summary['lost_reason']}"
        state = ("kept rolling" if summary["ball_rolling"] else
                 f"stopped rolling at t = {summary['rolling_until']:.3f} s ({why})")
        print(f"closed loop {summary['duration']:.3f} s ({summary['wall_time']:.2f} s wall): "
              f"the ball {state}; mean phi_dot {summary['mean_phi_dot']:.4f} rad/s; RMS over "
              f"the last half y {summary['rms_y']:.2e} rad, y_dot {summary['rms_y_dot']:.2e} "
              f"rad/s, z {summary['rms_z']:.2e} rad/s, I {summary['rms_I']:.2e} rad^2/s^2; "
              f"torque saturated {100 * summary['saturation_fraction']:.1f} % of the time")
    return 0


def _out_target(args: argparse.Namespace) -> Path:
    """The path ``--out`` writes: the file, or for ``.mcap`` the bag folder."""
    return args.out.with_suffix("") if args.out.suffix == ".mcap" else args.out


def _write_out(args: argparse.Namespace, res: Any, model: RigidModel) -> int:
    """Write the trajectory to ``--out`` atomically; 0, or 2 with one line on stderr."""
    try:
        if args.out.suffix == ".mcap":
            with atomic_dir(_out_target(args), args.force, create=False) as tmp:
                write_recording_bag(tmp, Recording.from_sim(res, model))
                # the bag's file is named after its folder
                (tmp / f"{tmp.name}.mcap").rename(tmp / f"{args.out.stem}.mcap")
                meta = tmp / "metadata.yaml"
                meta.write_text(meta.read_text().replace(f"{tmp.name}.mcap",
                                                         f"{args.out.stem}.mcap"))
        else:
            with atomic_file(args.out, args.force) as tmp:
                write_csv(tmp, res)
    except (OSError, OutputError, RecordingError) as exc:
        print(f"bfr simulate: error: cannot write {args.out}: {exc}", file=sys.stderr)
        return 2
    return 0


def _check_out(args: argparse.Namespace) -> int:
    """Refuse an existing ``--out`` before simulating; 0, or 2 with one line."""
    if args.out is None:
        return 0
    try:
        check_new(_out_target(args), args.force)
    except OutputError as exc:
        print(f"bfr simulate: error: {exc}", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``bfr simulate``; returns the process exit code."""
    args = build_parser().parse_args(argv)
    if _check_out(args):
        return 2
    if args.controller:
        return simulate_with_controller(args)
    try:
        params: RigParams = load_params(args.params)
        model = RigidModel(params)
        torque: Callable[[float], float] | float = (
            torque_from_csv(args.torque_csv) if args.torque_csv else args.torque)
        x0 = np.array([args.theta, args.phi, args.theta_dot, args.phi_dot])
        res = simulate(model, x0, args.duration, torque, dt=args.dt,
                       integrator=args.integrator)
    except (ParameterError, ValueError, IntegrationError) as exc:
        print(f"bfr simulate: error: {exc}", file=sys.stderr)
        return 2
    if args.out is not None:
        code = _write_out(args, res, model)
        if code:
            return code
    summary = res.summary()
    if args.json:
        print(json.dumps(summary))
    else:
        state = "stayed on the frame" if summary["ball_on_frame"] else (
            f"left the frame at t = {summary['left_frame_at']:.3f} s")
        print(f"simulated {summary['duration']:.3f} s in {summary['steps']} steps "
              f"({summary['wall_time']:.3f} s wall, {summary['real_time_factor']:.0f}x real "
              f"time); energy balance drift {summary['energy_drift_rel']:.2e}; the ball {state}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
