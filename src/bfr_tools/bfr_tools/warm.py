"""``bfr warm``: compile and cache everything a node would otherwise compile at start.

A node's first start after set-up used to take 46-80 s before its first message: numba
compiles the physics, estimator, PFL and detector kernels on first call (``cache=True``
keeps the result next to the sources, so only the first process pays), and the controller
solves the periodic Riccati equation for its gains (cached per parameter set in
``$BFR_CACHE_DIR``). ``scripts/setup`` runs this module after every build whose sources
changed, so that every node publishes within seconds of a cold start. It exercises the
nodes' own code paths with the shipped parameters:

- the controller core (:class:`bfr_control.controller.OrbitalController`): gains, orbit,
  estimator, PFL and the prediction through the actuation delay;
- the simulator's plant (:class:`bfr_sim.simulator_node.RigSimulation`) and renderer;
- the camera: the ball's track (:func:`bfr_camera.camera_node.ball_track`) and the
  detector's compiled loops on a rendered frame.

and then the analysis a researcher runs next, which compiled for a minute or two in its
first run on a fresh machine: ``bfr diagnose`` (:func:`bfr_diagnose.api.diagnose_recording`)
of a short synthetic recording with a concealed joint friction (the equation error's
kernels, the fits, the prediction rollouts, the ball's grip), then of a ball whose spin
creeps (the slip test's laws and the prediction with them, which on the first real log
whose ball slips had compiled for 15 s) and the rigid model's functions of whole
trajectories and single states (energy, forces, matrices); and, in a second process
beside all of these (numba compiles on one core; the machine's second was idle meanwhile),
the force-based contact model (:func:`bfr_diagnose.synth.contact_recording`: the free ball,
compliant contact, friction-limited rolling) in bfr's closed loop.

Usage: ``bfr warm [--quiet] [--jobs N]``; exit status 0, or 1 with the failing step named.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from bfr_camera.calibration import load_camera
from bfr_camera.camera_node import ball_track
from bfr_camera.detector import BallDetector, load_detector_config
from bfr_control.controller import OrbitalController, load_controller_config
from bfr_control.estimator import BallObservation
from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.grip import SlipLaw
from bfr_diagnose.preprocess import prepare
from bfr_diagnose.residual import ResidualEvaluator
from bfr_diagnose.synth import SynthConfig, contact_recording, stabilised_recording
from bfr_model.dynamics import RigidModel
from bfr_model.params import load_params
from bfr_sim.render import FrameRenderer, RenderOptions, rig_scene
from bfr_sim.simulator_node import RigSimulation

__all__ = ["main", "warm"]


def _controller() -> None:
    params = load_params()
    ctrl = OrbitalController(params, load_controller_config())
    x = ctrl.orbit_state(0.3)
    pos = ctrl.model.ball_position(x)
    for k in range(12):
        t = 0.005 * k
        ctrl.step(t, float(x[0]) + float(x[2]) * t, float(x[2]),
                  BallObservation(t, float(pos[0]), float(pos[1]), True), lead=0.002)


def _simulator() -> None:
    params = load_params()
    sim = RigSimulation(params, [0.0, 0.3, 0.0, 2.3])
    for _ in range(3):
        sim.step()
    sim.truth()


def _camera() -> None:
    params = load_params()
    cam = load_camera()
    scene = rig_scene(params)
    renderer = FrameRenderer(cam, scene.outline, RenderOptions(plate_z=scene.plate_z,
                                                               noise_sigma=1.0))
    det = BallDetector(cam, params.ball.radius, load_detector_config())
    det.set_track(*ball_track(params))
    rng = np.random.default_rng(0)
    for k in range(3):
        theta = 0.01 * k
        img = renderer.render(theta, scene.ball_centre(theta, 0.3 + 0.01 * k),
                              scene.ball_radius, rng=rng)
        det.detect(img, theta)


def _contact() -> None:
    base = load_params()
    rec = contact_recording(base, base, SynthConfig(duration=0.3, phase=0.4),
                            np.random.default_rng(0))
    if rec.t.size < 10:
        raise RuntimeError("the contact model's closed loop produced no samples")


def _diagnosis() -> None:
    base = load_params()
    plant = base.replace(**{"joint.coulomb_friction": 2e-3})
    rec = stabilised_recording(plant, base, SynthConfig(duration=4.0),
                               np.random.default_rng(0))
    diagnose_recording(rec, base, DiagnoseOptions(max_effects=1, block=1.5))


def _slip() -> None:
    """The slip test's laws, and the rigid model's functions of trajectories and states.

    A ball that creeps, diagnosed (the slip test's rollouts under each law it tries); the
    laws' coupled rollouts, the creep in the equation error, whatever that test chose (its
    choice is the diagnosis's business, not set-up's); energies, forces and matrices of
    whole trajectories and single states, rolling and creeping. On the first real log
    whose ball slips these had compiled for 15 s inside ``bfr diagnose``.
    """
    base = load_params().replace(**{"ball.creep_time": 0.0})  # whatever rig.yaml says
    creeping = base.replace(**{"ball.creep_time": 0.02})
    rec = stabilised_recording(creeping, base, SynthConfig(duration=10.0),
                               np.random.default_rng(3))
    diagnose_recording(rec, base, DiagnoseOptions(max_effects=0))
    ResidualEvaluator(prepare(rec)).evaluate(base, creep=0.02)
    model = RigidModel(base)
    x = np.tile([0.1, 0.3, 2.0, 2.4], (8, 1))
    u = np.zeros(8)
    for law in (SlipLaw(kind="coulomb", value=0.3), SlipLaw(kind="creep", value=0.02)):
        law.rollout(model, x[0], u, 0.002)
    for m, states in ((model, x), (RigidModel(creeping), np.column_stack([x, np.zeros((8, 3))]))):
        m.energy(states)
        m.normal_force(states, u)
        m.normal_force(states[0])
        m.accelerations(states[0])
        m.mass_matrix(float(states[0, 1]))
        m.mass_matrix(states[:, 1])
        m.gravity_vector(float(states[0, 0]), float(states[0, 1]))


#: The steps, in groups that run side by side (one process each), the nodes' first. Cold,
#: on this project's 2-CPU machine: the nodes about 105 s, the diagnosis 31 s and the slip
#: 34 s more; the contact model alone about 110 s (178 s in all, measured beside nothing).
GROUPS: dict[str, dict[str, Callable[[], None]]] = {
    "nodes, then the diagnosis": {
        "controller (gains, estimator, PFL, prediction)": _controller,
        "simulator (RK4 plant, truth)": _simulator,
        "camera (track, detector, renderer)": _camera,
        "diagnosis (equation error, fits, rollouts, grip)": _diagnosis,
        "slip (creep and Coulomb rollouts, trajectories' energy and forces)": _slip,
    },
    "contact model": {
        "contact model (closed loop)": _contact,
    },
}


class WarmError(RuntimeError):
    """A step failed: its name, the exception's type and message."""


def run_group(group: str, say: Callable[[str], None] | None = None) -> list[str]:
    """Run one group's steps in order; their lines (``warm: <step>: <s> s``).

    Each line goes to ``say`` as its step ends (if given) and is returned. A failing step
    raises :class:`WarmError` naming it (picklable: a worker's reaches the parent).
    """
    lines = []
    for name, step in GROUPS[group].items():
        t0 = time.perf_counter()
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - named and raised again, one line
            raise WarmError(f"{name}: {type(exc).__name__}: {exc}") from None
        lines.append(f"warm: {name}: {time.perf_counter() - t0:.1f} s")
        if say is not None:
            say(lines[-1])
    return lines


def warm(say: Callable[[str], None] = print, jobs: int = 2) -> None:
    """Run every group (module docstring), ``jobs`` of them at once.

    With ``jobs`` > 1 the groups after the first run in worker processes (spawned: numba's
    compiled caches are files, shared by every process) while this one runs the first and
    says each step as it ends; the workers' lines follow. Raises :class:`WarmError`.
    """
    names = list(GROUPS)
    workers = min(jobs, len(names)) - 1
    if workers < 1:
        for g in names:
            run_group(g, say)
        return
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        others = [pool.submit(run_group, g) for g in names[1:]]
        run_group(names[0], say)
        for fut in others:
            for line in fut.result():
                say(line)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bfr warm``."""
    p = argparse.ArgumentParser(prog="bfr warm", description=__doc__.splitlines()[0])
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                   help="groups compiled at once, one process each (default: 2, or 1 on a "
                        "single CPU)")
    args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.jobs < 1:
        p.error(f"--jobs {args.jobs}: expected 1 or more")
    try:
        warm((lambda s: None) if args.quiet else (lambda s: print(s, flush=True)), args.jobs)
    except WarmError as exc:
        print(f"bfr warm: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - a worker lost (killed, no memory): one line
        print(f"bfr warm: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
