"""The recording of a drawn case, as a user's file: simulate, log, write, read back.

Two truths of different model structure, both closed loops with the node suite's real
controller (:class:`bfr_control.controller.OrbitalController` on the nominal model):

- ``rigid``: the rigid model (:func:`bfr_sim.closed_loop.run_closed_loop`), the controller
  built with the case's orbit speed and Riccati weights (:func:`controller_config`);
- ``contact``: the force-based contact model through
  :func:`bfr_diagnose.synth.contact_recording` (its controller is controller.yaml's).

Both are logged by :func:`bfr_diagnose.synth.log_recording` with the case's sensor
conventions, then written as a rig's terminal log or a ROS 2 bag and read back through
:func:`bfr_model.io.read_recording` / :func:`bfr_model.io.rig_log.parse_rig_log`.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
from bfr_control.controller import ControllerConfig, OrbitalController, load_controller_config
from bfr_model.dynamics import RigidModel
from bfr_model.io import read_recording
from bfr_model.io.bag import write_recording_bag
from bfr_model.io.rig_log import parse_rig_log, write_rig_log
from bfr_model.params import RigParams
from bfr_model.recording import Recording
from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop

from bfr_diagnose.limits.cases import LimitCase
from bfr_diagnose.synth import SynthConfig, TrueRun, contact_recording, log_recording

__all__ = ["case_recording", "controller_config", "read_back"]

_PLANT_DT_MAX = 1e-3   # [s] largest plant step of the rigid loop (as bfr_diagnose.synth)


def controller_config(case: LimitCase) -> ControllerConfig:
    """controller.yaml with the case's orbit speed and Riccati weight scale."""
    cfg = load_controller_config()
    if case.orbit_speed is None and case.gain_scale is None:
        return cfg
    orbit = replace(cfg.orbit, mean_phi_dot=case.orbit_speed or cfg.orbit.mean_phi_dot,
                    phi_dot_0=None)
    g = case.gain_scale or 1.0
    ric = replace(cfg.riccati, q_y=cfg.riccati.q_y * g, q_y_dot=cfg.riccati.q_y_dot * g)
    return cfg.replace(orbit=orbit, riccati=ric)


def _rigid(case: LimitCase, plant: RigParams, base: RigParams, cfg: SynthConfig,
           rng: np.random.Generator) -> Recording:
    """The rigid closed loop with the case's controller, logged (module docstring)."""
    ctrl = OrbitalController(base, controller_config(case))
    phase = float(rng.uniform(0.0, math.pi))
    rate = float(cfg.log.log_rate or ctrl.config.control.rate)
    plant_dt = 1.0 / rate / math.ceil(1.0 / rate / _PLANT_DT_MAX - 1e-9)
    sensors = SensorConfig(camera_rate=cfg.camera_rate, camera_noise=cfg.camera_noise,
                           camera_latency=cfg.camera_latency,
                           encoder_counts=cfg.log.encoder_counts)
    res = run_closed_loop(ctrl, plant, cfg.duration, orbit_initial_state(ctrl, phase), sensors,
                          seed=int(rng.integers(2**31)), plant_dt=plant_dt, control_rate=rate)
    summary = res.summary()
    run = TrueRun(t=res.t, x=res.x[:, :4], u=res.u, cam_t=res.cam_t, cam_x=res.cam_x,
                  cam_y=res.cam_y, cam_valid=res.cam_valid,
                  ball_xy=RigidModel(plant).ball_position(res.x[:, :4]), summary=summary)
    rec = log_recording(run, cfg.camera_latency, cfg.log, f"limits case {case.index}")
    rec.meta.update(ball_rolled=bool(summary["ball_rolling"]), loop=summary,
                    plant_model="rigid")
    return rec


def case_recording(case: LimitCase, base: RigParams, duration: float) -> Recording:
    """Simulate and log one case (the truth's recording, before it is written).

    Raises
    ------
    ValueError
        When the plant cannot be simulated (a parameter change the model rejects).
    """
    plant = base.replace(**case.changes) if case.changes else base
    s = case.sensors
    cfg = SynthConfig(duration=duration, phase=None, camera_rate=s.camera_rate,
                      camera_noise=case.camera_noise, camera_latency=s.camera_latency,
                      log=s.log())
    rng = np.random.default_rng(case.noise_seed)
    if case.generator == "contact":
        return contact_recording(plant, base, cfg, rng, source=f"limits case {case.index}")
    if case.generator == "rigid":
        return _rigid(case, plant, base, cfg, rng)
    raise ValueError(f"unknown truth generator {case.generator!r}")


def read_back(rec: Recording, writer: str) -> list[Recording]:
    """Write ``rec`` as a rig log (``rig_log``) or a bag (``bag``) and read it back.

    As a user's file is read: the runs of the log, or the bag's recording.
    """
    with tempfile.TemporaryDirectory(prefix="bfr_limits_") as tmp:
        folder = Path(tmp)
        if writer == "bag":
            write_recording_bag(folder / "case_bag", rec)
            return [read_recording(folder / "case_bag")]
        log = parse_rig_log(write_rig_log(folder / "case.txt", rec), warn=False)
        return [log.recording(k) for k in range(len(log.runs))]
