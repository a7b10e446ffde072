"""The cases of the detection-limit run: one seeded draw per ``(seed, index)``.

A case is drawn from ``numpy.random.default_rng([seed, index])`` alone, so any case can be
rerun by itself and a longer run keeps the cases of a shorter one. Its **kind** follows a
fixed pattern of 20 (5 clean, 8 single, 5 pairs, 2 triples: a quarter of any run clean);
everything else is random:

- the truth's model structure: the rigid model (3 in 4) or the force-based contact model
  (:class:`bfr_model.contact.ContactModel`: free ball, compliant contact, friction-limited
  rolling; only the effects its frame and ball carry, :data:`CONTACT_EFFECTS`);
- the effects (distinct, uniform over the allowed ones) and each one's **size**,
  log-uniform in ``[0.1, 10] x FLOOR[effect]`` in the units of
  :func:`bfr_diagnose.effects.effect_size`; ``FLOOR = 10 x MIN_SIZE`` (the diagnosis's
  reporting floor), so sizes span 1 to 100 times the smallest size it ever reports; signs,
  phases and the bump's width at random;
- the sensors: :func:`bfr_diagnose.blindtest.draw_sensors` (velocity lag, torque timing,
  log rate, camera rate, latency, offset, scale, rotation, encoder; a quarter as bags with
  exposure stamps), and the camera's noise, log-uniform 50-300 um per axis;
- the controller (rigid truth): orbit speed ``mean_phi_dot`` in :data:`ORBIT_SPEEDS` and a
  gain scale in :data:`GAIN_SCALES` on the Riccati weights ``q_y, q_y_dot`` (a grid, so the
  orbit and gain tables of each controller are solved once and cached); the contact truth
  runs the nominal controller (``bfr_diagnose.synth.contact_recording`` builds its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.params import RigParams

from bfr_diagnose.blindtest import CONTACT_EFFECTS, SensorDraw, draw_sensors
from bfr_diagnose.effects import (
    EFFECT_NAMES,
    MIN_SIZE,
    SHAPE_ORDERS,
    param_value,
    possible_ball_inertia,
    shape_truth,
)

__all__ = ["FLOOR", "GAIN_SCALES", "KIND_PATTERN", "ORBIT_SPEEDS", "SCALAR_EFFECTS", "LimitCase",
           "draw_case", "effect_changes"]

#: Reference size of each effect [effect_size units]: ten times its reporting floor.
FLOOR: dict[str, float] = {name: 10.0 * MIN_SIZE[name] for name in EFFECT_NAMES}
#: Orbit speeds drawn for the rigid truth's controller [rad/s].
ORBIT_SPEEDS = (2.1, 2.4, 2.7)
#: Scale factors of the controller's Riccati weights q_y and q_y_dot [-].
GAIN_SCALES = (0.5, 1.0, 2.0)
#: Kind of case ``index % 20`` (number of concealed effects).
KIND_PATTERN = (0, 1, 2, 1, 0, 1, 3, 1, 0, 2, 1, 2, 0, 1, 2, 1, 0, 3, 2, 1)
#: Effects set by scalar parameters (a node's ``-p`` parameters).
SCALAR_EFFECTS = tuple(e for e in EFFECT_NAMES if e not in ("frame_shape", "track_bumps"))
CONTACT_SHARE = 0.25
NOISE_RANGE = (5e-5, 3e-4)       # [m] camera noise per axis, log-uniform


@dataclass(frozen=True, kw_only=True)
class LimitCase:
    """One drawn case (the hidden truth; never shown to either tool).

    Attributes
    ----------
    index, seed : int
        Position in the run and the run's seed (the case's rng is ``[seed, index]``).
    generator : str
        ``rigid`` or ``contact``: the truth's model structure.
    effects : tuple of str
        The concealed effects (empty: clean).
    sizes : tuple of float
        Their sizes [effect_size units].
    changes : dict
        ``RigParams`` dotted changes of the plant.
    truth : dict
        True parameter values per effect (the library's parameter order).
    sensors : SensorDraw
        Sensor conventions.
    camera_noise : float
        Camera noise per axis [m].
    orbit_speed : float or None
        The controller's mean contact-angle rate [rad/s] (None: controller.yaml's).
    gain_scale : float or None
        Scale of the Riccati weights q_y, q_y_dot [-] (None: controller.yaml's).
    noise_seed : int
        Seed of the recording's own noise and start phase.
    """

    index: int
    seed: int
    generator: str
    effects: tuple[str, ...]
    sizes: tuple[float, ...]
    changes: dict[str, Any]
    truth: dict[str, list[float]]
    sensors: SensorDraw
    camera_noise: float
    orbit_speed: float | None
    gain_scale: float | None
    noise_seed: int

    @property
    def kind(self) -> str:
        """``clean``, ``single``, ``pair`` or ``triple``."""
        return ("clean", "single", "pair", "triple")[len(self.effects)]


def _sign(rng: np.random.Generator) -> float:
    return 1.0 if rng.random() < 0.5 else -1.0


def effect_changes(name: str, size: float, base: RigParams, rng: np.random.Generator
                   ) -> tuple[dict[str, Any], list[float]]:
    """Plant changes and true parameter values of one effect of a given size.

    ``size`` is in the units of :func:`bfr_diagnose.effects.effect_size` (so that the
    diagnosis's own size of the true values is ``size``): absolute for friction, offset,
    rolling resistance and the groove; relative for frame inertia, torque gain, ball mass and
    inertia; the bump's height; the largest contour change; the imbalance moment's norm.
    Friction and rolling resistance only grow (they cannot be negative); the others take a
    random sign, the ball's inertia the one a real ball can have
    (:func:`~bfr_diagnose.effects.possible_ball_inertia`: the seed's ball is a thin shell).
    """
    if name in ("joint_coulomb_friction", "joint_viscous_friction", "rolling_resistance",
                "torque_offset"):
        key = {"joint_coulomb_friction": "joint.coulomb_friction",
               "joint_viscous_friction": "joint.viscous_friction",
               "rolling_resistance": "track.rolling_resistance",
               "torque_offset": "actuator.torque_offset"}[name]
        v = param_value(base, key) + (_sign(rng) if name == "torque_offset" else 1.0) * size
        return {key: v}, [v]
    if name == "ball_inertia":
        v = possible_ball_inertia(base, _sign(rng) * size)
        return {"ball.inertia": v}, [v]
    if name in ("frame_inertia", "torque_gain"):
        key = {"frame_inertia": "frame.inertia", "torque_gain": "actuator.torque_gain"}[name]
        v = param_value(base, key) * (1.0 + _sign(rng) * size)
        return {key: v}, [v]
    if name == "ball_mass":
        v = base.ball.mass * (1.0 + _sign(rng) * size)
        return {"ball.mass": v, "ball.inertia": base.ball.inertia * v / base.ball.mass}, [v]
    if name == "plate_distance":
        v = base.ball.plate_distance + _sign(rng) * size
        return {"ball.plate_distance": v}, [v]
    if name == "frame_imbalance":
        ang = float(rng.uniform(0.0, 2.0 * math.pi))
        return ({"frame.imbalance": size, "frame.imbalance_angle": ang},
                [size * math.sin(ang), size * math.cos(ang)])
    if name == "frame_contour":
        other = float(rng.uniform(0.0, 1.0)) * size
        da, db = (size, other) if rng.random() < 0.5 else (other, size)
        a = base.frame.contour.a + _sign(rng) * da
        b = base.frame.contour.b + _sign(rng) * db
        return {"frame.contour.a": a, "frame.contour.b": b}, [a, b]
    if name == "frame_shape":
        k = int(rng.choice(SHAPE_ORDERS))
        ang = float(rng.uniform(0.0, 2.0 * math.pi))
        amp = size / max(abs(math.cos(ang)), abs(math.sin(ang)))
        return shape_truth(k, amp * math.cos(ang), amp * math.sin(ang))
    if name == "track_bumps":
        h = _sign(rng) * size
        w = float(rng.uniform(0.09, 0.15))
        ph = float(rng.uniform(0.0, 2.0 * math.pi))
        return ({"track.bump_phi": (ph,), "track.bump_height": (h,), "track.bump_width": (w,)},
                [ph, h, w])
    raise ValueError(f"no draw for effect {name!r}")


def draw_case(seed: int, index: int, base: RigParams, truth: str | None = None) -> LimitCase:
    """The case ``index`` of the run ``seed`` (module docstring).

    ``truth`` names another recorder of the truth (e.g. ``nodes``: the node suite's
    simulator, camera and controller, :mod:`bfr_tools.limits`), which then replaces the
    drawn model structure; its effects are drawn from :data:`SCALAR_EFFECTS` (those a
    node parameter sets).
    """
    rng = np.random.default_rng([seed, index])
    n_eff = KIND_PATTERN[index % len(KIND_PATTERN)]
    generator = "contact" if rng.random() < CONTACT_SHARE else "rigid"
    pool = CONTACT_EFFECTS if generator == "contact" else EFFECT_NAMES
    if truth is not None:
        generator, pool = truth, SCALAR_EFFECTS
    effects: tuple[str, ...] = ()
    while len(effects) < n_eff:  # distinct; ball mass (which scales J_b) not with J_b
        e = str(rng.choice(pool))
        if e not in effects and not {"ball_mass", "ball_inertia"} <= {e, *effects}:
            effects = (*effects, e)
    sizes = tuple(float(FLOOR[e] * 10.0 ** rng.uniform(-1.0, 1.0)) for e in effects)
    changes: dict[str, Any] = {}
    truth: dict[str, list[float]] = {}
    for e, s in zip(effects, sizes, strict=True):
        ch, vals = effect_changes(e, s, base, rng)
        changes.update(ch)
        truth[e] = vals
    writer = "bag" if rng.random() < 0.25 else "rig_log"
    sensors = draw_sensors(rng, writer)
    noise = float(math.exp(rng.uniform(*np.log(NOISE_RANGE))))
    rigid = generator != "contact"
    speed = float(rng.choice(ORBIT_SPEEDS)) if rigid else None
    gain = float(rng.choice(GAIN_SCALES)) if rigid else None
    return LimitCase(index=index, seed=seed, generator=generator, effects=effects, sizes=sizes,
                     changes=changes, truth=truth, sensors=sensors, camera_noise=noise,
                     orbit_speed=speed, gain_scale=gain,
                     noise_seed=int(rng.integers(0, 2**31 - 1)))
