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

Usage: ``bfr warm [--quiet]``; exit status 0, or 1 with the failing step named.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence

import numpy as np
from bfr_camera.calibration import load_camera
from bfr_camera.camera_node import ball_track
from bfr_camera.detector import BallDetector, load_detector_config
from bfr_control.controller import OrbitalController, load_controller_config
from bfr_control.estimator import BallObservation
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


STEPS: dict[str, Callable[[], None]] = {
    "controller (gains, estimator, PFL, prediction)": _controller,
    "simulator (RK4 plant, truth)": _simulator,
    "camera (track, detector, renderer)": _camera,
}


def warm(say: Callable[[str], None] = print) -> None:
    """Run every step (module docstring); raises what a step raises."""
    for name, step in STEPS.items():
        t0 = time.perf_counter()
        step()
        say(f"warm: {name}: {time.perf_counter() - t0:.1f} s")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bfr warm``."""
    p = argparse.ArgumentParser(prog="bfr warm", description=__doc__.splitlines()[0])
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        warm((lambda s: None) if args.quiet else (lambda s: print(s, flush=True)))
    except Exception as exc:  # noqa: BLE001 - name the failing step, one line
        print(f"bfr warm: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
