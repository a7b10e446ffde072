"""The library of physical effects the nominal model may leave out.

Each effect maps a few parameters onto :class:`bfr_model.params.RigParams` (the very code the
simulator and the simulator node run) or, for the two sensor effects ``camera_latency`` and
``camera_offset``, onto a :class:`~bfr_diagnose.preprocess.SensorCorrection` that
preprocessing applies to the camera's fixes (time shift; origin shift before the ball's
world angle is taken). Sensor corrections are reported as camera parameters, never written
into the physics YAML. Values are in natural units; the optimiser works on
``(value - start) / scale``.

=======================  ================================================  ==============
name                     parameters (unit)                                 model entry
=======================  ================================================  ==============
joint_coulomb_friction   T_c (N m)                                         joint.coulomb_friction
joint_viscous_friction   c_v (N m s/rad)                                   joint.viscous_friction
rolling_resistance       mu_rol (-)                                        track.rolling_resistance
track_bumps              phi_b (rad), h (m), w (rad): Gaussian bump        track.bump_*
frame_inertia            J_f (kg m^2)                                      frame.inertia
ball_radius              R_b (m)                                           ball.radius
ball_mass                m_b (kg)                                          ball.mass
frame_shape              c_k, s_k (m) for k in SHAPE_ORDERS                frame.contour.harmonic_*
axis_misalignment        eps (rad), fitted as 1 - cos(eps)                 environment.axis_mis...
camera_latency           L (s) added to the nominal latency                camera (sensor)
torque_gain              k_u (-)                                           actuator.torque_gain
camera_offset            c_x, c_y (m): camera reports true + (c_x, c_y)    camera (sensor)
=======================  ================================================  ==============
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from bfr_model.params import RigParams

from bfr_diagnose.preprocess import SensorCorrection

__all__ = ["DESTINATION", "EFFECTS", "EFFECT_NAMES", "FRAME_ONLY_EFFECTS", "MIN_SIZE",
           "SENSOR_EFFECTS", "SHAPE_ORDERS", "Effect", "apply_effects", "display_values",
           "effect_size", "plausibility"]

#: Contour harmonic orders fitted by ``frame_shape`` (k = 1: frame off-centre on the shaft).
SHAPE_ORDERS = (1, 3, 4, 6)
#: Effects that are sensor corrections (camera), not physics.
SENSOR_EFFECTS = ("camera_latency", "camera_offset")
_NONE = SensorCorrection()


@dataclass(frozen=True)
class Effect:
    """One candidate mechanism.

    Attributes
    ----------
    name : str
        Library name.
    description : str
        One line for the report.
    names, units : tuple of str
        Parameter names and units (natural).
    scales : tuple of float
        Typical resolution of each parameter (optimiser scaling).
    lower, upper : tuple of float
        Bounds (natural units; relative to nothing).
    start : callable
        ``start(base) -> tuple`` starting values given the current model.
    apply : callable
        ``apply(base, values) -> (RigParams, SensorCorrection)``.
    rows : tuple of int
        Equation rows the effect enters (1: frame, 2: ball).
    """

    name: str
    description: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    scales: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    start: Callable[[RigParams], tuple[float, ...]]
    apply: Callable[[RigParams, np.ndarray], tuple[RigParams, SensorCorrection]]
    rows: tuple[int, ...] = (1, 2)

    @property
    def k(self) -> int:
        """Number of parameters."""
        return len(self.names)


def _scalar(key: str) -> tuple[Callable, Callable]:
    group, name = key.rsplit(".", 1)

    def get(base: RigParams) -> tuple[float]:
        obj = base
        for part in key.split("."):
            obj = getattr(obj, part)
        return (float(obj),)

    def put(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
        return base.replace(**{key: float(v[0])}), _NONE

    del group, name
    return get, put


def _bump_start(base: RigParams) -> tuple[float, ...]:
    return (0.0, 0.0, 0.08)


def _bump_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    t = base.track
    phi_b = float(np.mod(v[0], 2.0 * np.pi))
    return base.replace(**{"track.bump_phi": (*t.bump_phi, phi_b),
                           "track.bump_height": (*t.bump_height, float(v[1])),
                           "track.bump_width": (*t.bump_width, float(v[2]))}), _NONE


def _shape_start(base: RigParams) -> tuple[float, ...]:
    return tuple(0.0 for _ in range(2 * len(SHAPE_ORDERS)))


def _shape_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    c = base.frame.contour
    coeffs = {k: [a, b] for k, a, b in zip(c.harmonic_orders, c.harmonic_cos, c.harmonic_sin,
                                           strict=True)}
    for i, k in enumerate(SHAPE_ORDERS):
        a, b = coeffs.get(k, [0.0, 0.0])
        coeffs[k] = [a + float(v[2 * i]), b + float(v[2 * i + 1])]
    orders = tuple(sorted(coeffs))
    return base.replace(**{"frame.contour.harmonic_orders": orders,
                           "frame.contour.harmonic_cos": tuple(coeffs[k][0] for k in orders),
                           "frame.contour.harmonic_sin": tuple(coeffs[k][1] for k in orders)}
                        ), _NONE


def _mis_start(base: RigParams) -> tuple[float]:
    return (1.0 - math.cos(base.environment.axis_misalignment),)


def _mis_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    s = min(max(float(v[0]), 0.0), 0.99)
    return base.replace(**{"environment.axis_misalignment": math.acos(1.0 - s)}), _NONE


def _lat_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    return base, SensorCorrection(latency=float(v[0]))


def _offset_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    return base, SensorCorrection(offset_x=float(v[0]), offset_y=float(v[1]))


def _make() -> dict[str, Effect]:
    eff: list[Effect] = []
    g, p = _scalar("joint.coulomb_friction")
    eff.append(Effect("joint_coulomb_friction",
                      "dry (Coulomb) friction torque in the frame's bearing/motor",
                      ("T_c",), ("N m",), (2e-4,), (0.0,), (0.05,), g, p, (1,)))
    g, p = _scalar("joint.viscous_friction")
    eff.append(Effect("joint_viscous_friction", "viscous friction in the frame's bearing/motor",
                      ("c_v",), ("N m s/rad",), (1e-4,), (0.0,), (0.05,), g, p, (1,)))
    g, p = _scalar("track.rolling_resistance")
    eff.append(Effect("rolling_resistance", "rolling resistance of the ball on the track",
                      ("mu_rol",), ("-",), (1e-3,), (0.0,), (0.3,), g, p, (2,)))
    eff.append(Effect("track_bumps", "a bump (or dent) on the track, Gaussian in phi",
                      ("phi_b", "h", "w"), ("rad", "m", "rad"), (0.05, 5e-5, 0.01),
                      (-4 * np.pi, -3e-3, 0.03), (4 * np.pi, 3e-3, 0.6), _bump_start,
                      _bump_apply, (2,)))
    g, p = _scalar("frame.inertia")
    eff.append(Effect("frame_inertia", "inertia of the frame and rotor J_f",
                      ("J_f",), ("kg m^2",), (1e-5,), (2e-4,), (0.05,), g, p, (1,)))
    g, p = _scalar("ball.radius")
    eff.append(Effect("ball_radius", "the ball's radius R_b (hence its rolling radius)",
                      ("R_b",), ("m",), (5e-5,), (12.9e-3,), (30e-3,), g, p))
    g, p = _scalar("ball.mass")
    eff.append(Effect("ball_mass", "the ball's mass m_b", ("m_b",), ("kg",), (3e-5,),
                      (1e-4,), (0.05,), g, p))
    names = tuple(f"{cs}_{k}" for k in SHAPE_ORDERS for cs in ("c", "s"))
    eff.append(Effect("frame_shape", "contour harmonics of the frame (k = 1: off-centre)",
                      names, tuple("m" for _ in names), tuple(5e-5 for _ in names),
                      tuple(-5e-3 for _ in names), tuple(5e-3 for _ in names), _shape_start,
                      _shape_apply))
    eff.append(Effect("axis_misalignment", "shaft pitched from horizontal: in-plane g cos(eps)",
                      ("eps",), ("rad",), (1e-3,), (0.0,), (0.6,), _mis_start, _mis_apply))
    eff.append(Effect("camera_latency", "camera delay beyond the nominal latency",
                      ("L",), ("s",), (5e-4,), (-0.03,), (0.08,), lambda b: (0.0,),
                      _lat_apply, (2,)))
    g, p = _scalar("actuator.torque_gain")
    eff.append(Effect("torque_gain", "motor torque per commanded torque k_u",
                      ("k_u",), ("-",), (2e-3,), (0.2,), (5.0,), g, p, (1,)))
    eff.append(Effect("camera_offset", "camera origin off the shaft axis (sensor extrinsic)",
                      ("c_x", "c_y"), ("m", "m"), (2e-4, 2e-4), (-0.02, -0.02), (0.02, 0.02),
                      lambda b: (0.0, 0.0), _offset_apply, (1, 2)))
    return {e.name: e for e in eff}


#: The library, by name.
EFFECTS: dict[str, Effect] = _make()
#: Names in library order.
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: Where a fitted effect goes: the key of rig.yaml (physics) or the camera (sensor).
DESTINATION: dict[str, str] = {
    "joint_coulomb_friction": "rig.yaml joint.coulomb_friction",
    "joint_viscous_friction": "rig.yaml joint.viscous_friction",
    "rolling_resistance": "rig.yaml track.rolling_resistance",
    "track_bumps": "rig.yaml track.bump_phi/height/width",
    "frame_inertia": "rig.yaml frame.inertia",
    "ball_radius": "rig.yaml ball.radius",
    "ball_mass": "rig.yaml ball.mass",
    "frame_shape": "rig.yaml frame.contour.harmonic_*",
    "axis_misalignment": "rig.yaml environment.axis_misalignment",
    "camera_latency": "camera: latency (camera_correction.yaml)",
    "torque_gain": "rig.yaml actuator.torque_gain",
    "camera_offset": "camera: origin offset (camera_correction.yaml)",
}
#: Smallest size worth reporting, per effect (natural units; see :func:`effect_size`): an
#: engineering resolution, far below anything that matters on the rig and above the
#: processing's own floor (a noise-free simulation leaves micrometre "bumps").
MIN_SIZE: dict[str, float] = {
    "joint_coulomb_friction": 2e-5, "joint_viscous_friction": 2e-6,
    "rolling_resistance": 2e-4, "track_bumps": 2e-5, "frame_inertia": 2e-3,
    "ball_radius": 2e-5, "ball_mass": 2e-3, "frame_shape": 2e-5, "axis_misalignment": 0.02,
    "camera_latency": 2e-4, "torque_gain": 2e-3, "camera_offset": 1e-4,
}


def effect_size(name: str, values: np.ndarray, base: RigParams) -> float:
    """Size of a fitted effect against the nominal model, in the units of :data:`MIN_SIZE`.

    Relative change for frame inertia, ball mass and torque gain; bump height; largest
    contour harmonic; norm of the camera offset; absolute change otherwise.
    """
    eff = EFFECTS[name]
    v = display_values(eff, np.asarray(values, float))
    v0 = display_values(eff, np.asarray(eff.start(base), float))
    if name == "track_bumps":
        return float(abs(v[1]))
    if name in ("frame_shape", "camera_offset"):
        d = v - v0
        return float(np.max(np.abs(d)) if name == "frame_shape" else np.hypot(d[0], d[1]))
    if name in ("frame_inertia", "ball_mass", "torque_gain"):
        return float(abs(v[0] / v0[0] - 1.0))
    return float(abs(v[0] - v0[0]))


def plausibility(name: str, values: np.ndarray, base: RigParams,
                 latency0: float = 0.0) -> str | None:
    """Why fitted (display) values are physically implausible, or None.

    A fit far outside what the quantity can be on a real rig (a weighed ball, a measured
    radius, a frame whose inertia is known to a factor of two, ...) is flagged: it most
    likely stands in for an effect outside the library. The ranges are deliberately wide.
    """
    v = np.asarray(values, float)
    rel = {"frame_inertia": (base.frame.inertia, 0.5, 2.0),
           "torque_gain": (base.actuator.torque_gain, 0.5, 2.0),
           "ball_mass": (base.ball.mass, 0.8, 1.2),
           "ball_radius": (base.ball.radius, 0.95, 1.05)}
    if name in rel:
        nom, lo, hi = rel[name]
        r = v[0] / nom
        if not lo <= r <= hi:
            return (f"{r:.2f} x nominal, outside [{lo:g}, {hi:g}] x (for a quantity known this "
                    "well, the fit most likely stands in for something outside the library)")
        return None
    absmax = {"joint_coulomb_friction": (0.02, "N m"), "joint_viscous_friction": (2e-3,
              "N m s/rad"), "rolling_resistance": (0.05, "-"),
              "axis_misalignment": (0.2, "rad")}
    if name in absmax:
        lim, unit = absmax[name]
        return None if abs(v[0]) <= lim else f"{v[0]:.3g} {unit} beyond {lim:g} {unit}"
    if name == "track_bumps" and abs(v[1]) > 1e-3:
        return f"bump height {v[1] * 1e3:.2f} mm beyond 1 mm"
    if name == "frame_shape" and np.max(np.abs(v)) > 1e-3:
        return f"contour harmonic of {np.max(np.abs(v)) * 1e3:.2f} mm beyond 1 mm"
    if name == "camera_latency" and not 0.0 <= latency0 + v[0] <= 0.04:
        return f"total camera latency {(latency0 + v[0]) * 1e3:.1f} ms outside [0, 40] ms"
    if name == "camera_offset" and float(np.hypot(v[0], v[1])) > 0.015:
        return f"camera offset {np.hypot(v[0], v[1]) * 1e3:.1f} mm beyond 15 mm"
    return None


#: Effects identifiable from a frame-only (no ball) recording.
FRAME_ONLY_EFFECTS = ("joint_coulomb_friction", "joint_viscous_friction", "frame_inertia",
                      "torque_gain")


def display_values(effect: Effect, values: np.ndarray) -> np.ndarray:
    """Natural reported values: axis_misalignment's internal 1 - cos(eps) becomes eps."""
    v = np.asarray(values, float).copy()
    if effect.name == "axis_misalignment":
        v[0] = math.acos(1.0 - min(max(v[0], 0.0), 0.99))
    if effect.name == "track_bumps":
        v[0] = float(np.mod(v[0], 2.0 * np.pi))
    return v


def apply_effects(base: RigParams, chosen: list[tuple[Effect, np.ndarray]]
                  ) -> tuple[RigParams, SensorCorrection]:
    """Apply several fitted effects in order; returns the params and the sensor correction."""
    params = base
    sensor = _NONE
    for eff, vals in chosen:
        params, sc = eff.apply(params, np.asarray(vals, float))
        sensor = sensor + sc
    return params, sensor
