"""Region of attraction and robustness figures of the controller: ``bfr control-eval``.

Every figure is the largest value of one perturbation for which *all* seeded closed-loop
trials succeed (bfr_sim.closed_loop: rigid plant, camera at 200 Hz with its latency and
noise; seed k starts at a random phase on the orbit with the perturbation's sign (-1)^k),
found by bisection between 0 and an upper limit (reported as ``>= limit`` when even the
limit succeeds). Trials are deterministic (seeded), so the figures can be compared
from one version to the next.

- ``y_max`` [rad]: the frame turned off the orbit by +-y at t = 0 (``theta = Theta(phi) + y``)
  at random phases; success = the ball keeps rolling for the whole trial and the transverse
  coordinates end small (over the last 2 s of the trial ``|y| < 0.05 rad`` and
  ``|z| < 0.5 rad/s``). Capped by the supervisor's ``max_abs_y``.
- ``z_max`` [rad/s]: the ball's speed off the orbit by +-z (``phi_dot = phi_dot*(phi) + z``,
  the frame's speed matching, ``y = y_dot = 0``), same success test.
- ``latency_max`` [s]: camera latency (exposure to delivery), nominal plant, start on the
  orbit with a 0.02 rad frame offset; success = keeps rolling.
- ``J_f`` and ``R`` [-]: relative error of the frame inertia and of the rolling radius
  (plant = (1 + e) x nominal, controller nominal), each sign separately; start as for the
  latency; success = keeps rolling. R is changed through the ball radius at a fixed plate
  distance, ``R_b = sqrt(R^2 + d_f^2 / 4)``, the ball's inertia unchanged.

The real rig's effects, each alone, in absolute units (issue 17: the ball must keep rolling
with joint dry friction 2 mN m, 0.56x frame inertia, 8 ms camera latency, a rolling radius
1 mm smaller, a contour 5 mm larger in mean radius); same start and success test as the
latency, with an actuation delay of ``--actuation-delay`` (default 5 ms: the torque acts
5 ms after the sample it answers, predicted through by the controller):

- ``coulomb_max`` [N m]: joint dry friction ``joint.coulomb_friction`` of the plant;
- ``inertia_min_ratio`` [-]: the smallest plant/controller frame-inertia ratio (reported
  as the ratio, bisected on ``1 - ratio``);
- ``rolling_radius_minus`` [m]: a rolling radius this much smaller;
- ``contour_plus`` [m]: a contour this much larger in mean radius (``frame.contour.a``);
- ``actuation_delay_max`` [s]: the delay from sample to torque, predicted through
  (``lead``), and ``actuation_delay_max_unpredicted`` without the prediction.

Example::

    bfr control-eval --json                 # default: 3 seeds, 6 bisection steps, 10 s trials
    bfr control-eval --seeds 4 --steps 7 --trial 20
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bfr_control.controller import OrbitalController, load_controller_config
from bfr_model.params import ParameterError, RigParams, load_params
from bfr_sim.closed_loop import SensorConfig, orbit_initial_state, run_closed_loop

__all__ = ["EvalSettings", "bisect_limit", "evaluate", "main", "scale_rolling_radius"]


@dataclass(frozen=True)
class EvalSettings:
    """How the figures are measured.

    Attributes
    ----------
    seeds : int
        Trials per tested value (random phase and sign of the perturbation, sensor noise).
    steps : int
        Bisection steps (resolution: limit / 2^steps).
    trial : float
        Simulated time per trial [s].
    tail : float
        Window at the end of a trial for the convergence test [s].
    y_tail, z_tail : float
        Convergence bounds on |y| [rad] and |z| [rad/s] over the tail.
    """

    seeds: int = 3
    steps: int = 6
    trial: float = 10.0
    tail: float = 2.0
    y_tail: float = 0.05
    z_tail: float = 0.5


def scale_rolling_radius(params: RigParams, factor: float) -> RigParams:
    """Parameters with the rolling radius R scaled by ``factor`` (ball radius adjusted)."""
    R = params.ball.rolling_radius * factor
    d = params.ball.plate_distance
    return params.replace(**{"ball.radius": math.sqrt(R * R + d * d / 4.0)})


def bisect_limit(ok: Callable[[float], bool], upper: float, steps: int) -> tuple[float, bool]:
    """Largest v in [0, upper] with ok(v), assuming monotonicity; (value, reached_upper)."""
    if ok(upper):
        return upper, True
    lo, hi = 0.0, upper
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo, False


def evaluate(params: RigParams, controller: OrbitalController, settings: EvalSettings,
             only: tuple[str, ...] = (), log: Callable[[str], None] | None = None,
             actuation_delay: float = 0.005) -> dict:
    """Measure the figures (module docstring); returns a JSON-ready dict.

    ``actuation_delay`` [s] is the delay of the real-rig effect figures.
    """
    st = settings
    trials = {"count": 0}

    def trial(plant: RigParams, x0: np.ndarray, sensors: SensorConfig, seed: int,
              converge: bool) -> bool:
        trials["count"] += 1
        res = run_closed_loop(controller, plant, st.trial, x0, sensors=sensors, seed=seed,
                              stop_on_failure=True)
        if res.failure_time is not None or res.t[-1] < st.trial - 1e-6:
            return False
        if not converge:
            return True
        tail = res.t >= res.t[-1] - st.tail
        tr = res.transverse[tail]
        return bool(np.max(np.abs(tr[:, 1])) < st.y_tail and np.max(np.abs(tr[:, 3])) < st.z_tail)

    def starts(seed: int) -> tuple[float, float]:
        rng = np.random.default_rng(1000 + seed)  # random phase, alternating sign
        return float(rng.uniform(0.0, controller.orbit.period)), (-1.0) ** seed

    def all_ok(make: Callable[[int], tuple[RigParams, np.ndarray, SensorConfig]],
               converge: bool) -> bool:
        for seed in range(st.seeds):
            plant, x0, sensors = make(seed)
            if not trial(plant, x0, sensors, seed, converge):
                return False
        return True

    nominal_sensors = SensorConfig()
    sup = controller.config.supervisor
    out: dict = {}
    figures: list[tuple[str, Callable[[float], bool], float, str]] = []

    def y_ok(v: float) -> bool:
        def make(seed: int) -> tuple:
            ph, sg = starts(seed)
            return params, orbit_initial_state(controller, ph, d_theta=sg * v), nominal_sensors
        return all_ok(make, True)

    def z_ok(v: float) -> bool:
        def make(seed: int) -> tuple:
            ph, sg = starts(seed)
            return params, orbit_initial_state(controller, ph, d_z=sg * v), nominal_sensors
        return all_ok(make, True)

    def small_start(seed: int) -> np.ndarray:
        ph, sg = starts(seed)
        return orbit_initial_state(controller, ph, d_theta=0.02 * sg)

    def latency_ok(v: float) -> bool:
        sensors = SensorConfig(camera_latency=v)
        return all_ok(lambda seed: (params, small_start(seed), sensors), False)

    def jf_ok(sign: float) -> Callable[[float], bool]:
        def ok(v: float) -> bool:
            plant = params.replace(**{"frame.inertia": params.frame.inertia * (1.0 + sign * v)})
            return all_ok(lambda seed: (plant, small_start(seed), nominal_sensors), False)
        return ok

    act = SensorConfig(actuation_delay=actuation_delay)

    def coulomb_ok(v: float) -> bool:
        plant = params.replace(**{"joint.coulomb_friction": v})
        return all_ok(lambda seed: (plant, small_start(seed), act), False)

    def inertia_ok(v: float) -> bool:
        plant = params.replace(**{"frame.inertia": params.frame.inertia * (1.0 - v)})
        return all_ok(lambda seed: (plant, small_start(seed), act), False)

    def radius_ok(v: float) -> bool:
        r = params.ball.rolling_radius
        try:
            plant = scale_rolling_radius(params, (r - v) / r)
        except ParameterError:
            return False
        return all_ok(lambda seed: (plant, small_start(seed), act), False)

    def contour_ok(v: float) -> bool:
        plant = params.replace(**{"frame.contour.a": params.frame.contour.a + v})
        return all_ok(lambda seed: (plant, small_start(seed), act), False)

    def delay_ok(predict: bool) -> Callable[[float], bool]:
        def ok(v: float) -> bool:
            sensors = SensorConfig(actuation_delay=v)
            for seed in range(st.seeds):
                trials["count"] += 1
                res = run_closed_loop(controller, params, st.trial, small_start(seed),
                                      sensors=sensors, seed=seed, stop_on_failure=True,
                                      predict_delay=predict)
                if res.failure_time is not None or res.t[-1] < st.trial - 1e-6:
                    return False
            return True
        return ok

    def r_ok(sign: float) -> Callable[[float], bool]:
        def ok(v: float) -> bool:
            try:
                plant = scale_rolling_radius(params, 1.0 + sign * v)
            except ParameterError:
                return False  # no such ball fits the frame
            return all_ok(lambda seed: (plant, small_start(seed), nominal_sensors), False)
        return ok

    figures = [
        ("y_max", y_ok, sup.max_abs_y, "rad"),
        ("z_max", z_ok, sup.max_abs_z, "rad/s"),
        ("latency_max", latency_ok, 0.1, "s"),
        ("J_f_plus", jf_ok(1.0), 2.0, "-"),
        ("J_f_minus", jf_ok(-1.0), 0.9, "-"),
        ("R_plus", r_ok(1.0), 0.5, "-"),
        ("R_minus", r_ok(-1.0), 0.5, "-"),
        ("coulomb_max", coulomb_ok, 0.02, "N m"),
        ("inertia_min_ratio", inertia_ok, 0.9, "-"),
        ("rolling_radius_minus", radius_ok, 4e-3, "m"),
        ("contour_plus", contour_ok, 0.02, "m"),
        ("actuation_delay_max", delay_ok(True), 0.1, "s"),
        ("actuation_delay_max_unpredicted", delay_ok(False), 0.1, "s"),
    ]
    for name, ok, upper, unit in figures:
        if only and not any(name.startswith(o) for o in only):
            continue
        t0 = time.perf_counter()
        n0 = trials["count"]
        value, capped = bisect_limit(ok, upper, st.steps)
        if name == "inertia_min_ratio":  # bisected on 1 - ratio: report the ratio
            value = 1.0 - value
        out[name] = {"value": value, "at_upper_limit": capped, "upper_limit": upper,
                     "resolution": upper / 2 ** st.steps, "unit": unit,
                     "trials": trials["count"] - n0,
                     "wall_time": round(time.perf_counter() - t0, 2)}
        if log:
            log(f"{name}: {'>= ' if capped else ''}{value:.4g} {unit} "
                f"({out[name]['trials']} trials, {out[name]['wall_time']} s)")
    return out


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bfr control-eval``."""
    p = argparse.ArgumentParser(
        prog="bfr control-eval",
        description="Region of attraction and robustness of the orbital stabilisation "
                    "controller in closed-loop simulation: largest initial |y| and |z| it "
                    "recovers from, largest camera latency, largest relative error of J_f and "
                    "R (plant vs controller model) with which the ball keeps rolling. Each "
                    "figure is a bisection over seeded trials (see the module docstring).",
        epilog="Example: bfr control-eval --json")
    p.add_argument("--seeds", type=int, default=EvalSettings.seeds,
                   help="trials per tested value (default %(default)s)")
    p.add_argument("--steps", type=int, default=EvalSettings.steps,
                   help="bisection steps (default %(default)s)")
    p.add_argument("--trial", type=float, default=EvalSettings.trial,
                   help="simulated seconds per trial (default %(default)s)")
    p.add_argument("--only", nargs="*", default=[],
                   help="only these figures (prefixes of y_max z_max latency_max J_f R "
                        "coulomb_max inertia_min_ratio rolling_radius_minus contour_plus "
                        "actuation_delay_max)")
    p.add_argument("--actuation-delay", type=float, default=0.005,
                   help="actuation delay [s] of the real-rig effect figures (default "
                        "%(default)s)")
    p.add_argument("--params", type=Path,
                   help="rig parameters (default: bfr_model's config/rig.yaml)")
    p.add_argument("--config", type=Path, help="controller.yaml (default: the shipped one)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``bfr control-eval``; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.seeds < 1 or args.steps < 0 or not args.trial > 2.5:
        print("bfr control-eval: error: need --seeds >= 1, --steps >= 0, --trial > 2.5",
              file=sys.stderr)
        return 2
    try:
        params = load_params(args.params)
        config = load_controller_config(args.config)
        start = time.perf_counter()
        controller = OrbitalController(params, config)
    except (ParameterError, ValueError, ArithmeticError, FileNotFoundError) as exc:
        print(f"bfr control-eval: error: {exc}", file=sys.stderr)
        return 2
    settings = EvalSettings(seeds=args.seeds, steps=args.steps, trial=args.trial)
    log = None if args.json else (lambda s: print(s, flush=True))
    if not 0.0 <= args.actuation_delay < 1.0:
        print("bfr control-eval: error: --actuation-delay must be in [0, 1) s", file=sys.stderr)
        return 2
    figures = evaluate(params, controller, settings, tuple(args.only), log,
                       actuation_delay=args.actuation_delay)
    result = {
        "figures": figures,
        "settings": {"seeds": settings.seeds, "steps": settings.steps,
                     "trial": settings.trial, "tail": settings.tail,
                     "y_tail": settings.y_tail, "z_tail": settings.z_tail,
                     "sensors": "camera 200 Hz, 5 ms latency, 0.1 mm noise; control "
                                f"{config.control.rate:g} Hz; plant RK4 1 kHz; real-rig effect "
                                f"figures with a {1e3 * args.actuation_delay:g} ms actuation "
                                f"delay"},
        "controller": controller.summary(),
        "wall_time": round(time.perf_counter() - start, 2),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"total {result['wall_time']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
