"""The library of physical effects the nominal model may leave out, and the sensor model.

Each **effect** maps a few parameters onto :class:`bfr_model.params.RigParams`, i.e. onto a
term of the model the simulator and the simulator node run (rig.yaml entry, validated
dataclass, kernel layout, rigid kernels). Values are in natural units; the optimiser works
on ``(value - start) / scale``. Each has an engineering floor (:data:`MIN_SIZE`, below which
it is never reported) and a plausibility range (:func:`plausibility`, outside which a fit is
a *suspect*: reported, never written into ``corrected_params.yaml``). The expected signature
of each is in docs/diagnosis.md.

=======================  ================================================  ==================
name                     parameters (unit)                                 model entry
=======================  ================================================  ==================
joint_coulomb_friction   T_c (N m)                                         joint.coulomb_fr.
joint_viscous_friction   c_v (N m s/rad)                                   joint.viscous_fr.
torque_offset            tau_0 (N m): the drive's torque at zero command   actuator.torque_off.
frame_imbalance          M_x, M_y (kg m): m_f e [sin, cos] theta_e         frame.imbalance(_a.)
frame_inertia            J_f (kg m^2)                                      frame.inertia
torque_gain              k_u (-)                                           actuator.torque_gain
rolling_resistance       mu_rol (-)                                        track.rolling_res.
track_bumps              phi_b (rad), h (m), w (rad): Gaussian bump        track.bump_*
ball_mass                m_b (kg), J_b scaled with it (the same shell)     ball.mass, .inertia
ball_inertia             J_b (kg m^2): the shell's thickness               ball.inertia
plate_distance           d_f (m): the groove, hence the rolling radius R   ball.plate_distance
frame_contour            a, b (m): mean radius and cos 2 phi amplitude     frame.contour.a, .b
frame_shape              c_k, s_k (m), k in SHAPE_ORDERS                   frame.contour.harm.
=======================  ================================================  ==================

The ball enters the ball's rows only through its rolling radius ``R = sqrt(R_b^2 - d_f^2 /
4)`` (the ball centre's distance from the track, and its spin ``lam / R``) and its inertia
relative to its mass ``J_b / m_b`` (the ball's row is homogeneous in m_b and J_b together):
two numbers. ``plate_distance`` moves the first, ``ball_inertia`` the second; the ball's own
radius (measured with a caliper) would move both and is not a separate effect (fitted alone
it is indistinguishable from the groove, the two explaining the same data to four digits).

Not in the library: a shaft pitched from horizontal (``environment.axis_misalignment``, a
term of the model). It lowers the in-plane gravity to ``g cos(eps)``, and in the ball's rows
that is the same as every length of the frame ``1 / cos(eps)`` times larger (the ball's
time scale is ``sqrt(length / g)``), which a camera of unknown scale sees as the nominal
frame; the frame's row sees the ball's weight times its distance, again the same product.
For a pitch a level can measure (below 0.2 rad: 2 % of g) the data cannot tell it from a
slightly larger frame and camera scale, so it is measured, not diagnosed.

Why a torque offset and not direction-dependent friction: at any speed above the Coulomb
term's smoothing velocity (1e-3 rad/s) the two are the same regressor (a constant that flips
or does not flip with the direction is indistinguishable from a symmetric friction plus a
constant), so the data cannot choose; the offset is one parameter, a known property of
current-controlled drives (an amplifier or current-sensor offset), and it keeps the
model's friction symmetric as a bearing's is. docs/diagnosis.md shows the NTNU friction runs
at +1, +5 and -1 rad/s fitted by it.

The **sensor model** (:data:`SENSOR_PARAMS`) is not an effect: a recording's sensor timing
and camera extrinsics are facts of that recording, fitted on every recording (its own
values, never shared), reported, and never selected or counted as missing physics:
camera latency, camera offset, rotation and scale, the encoder's zero against the frame's
shape, and the drive's timing against the logged torque (the logged velocity's lag is
measured in preprocessing, :func:`bfr_model.io.timing.velocity_lag`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from bfr_model.params import RigParams

from bfr_diagnose.preprocess import SensorCorrection

__all__ = ["BALL_INERTIA_RATIO", "CAMERA_PRIOR", "DESTINATION", "EFFECTS", "EFFECT_NAMES",
           "FRAME_ONLY_EFFECTS", "MIN_SIZE", "SENSOR_PARAMS", "SHAPE_ORDERS", "Effect",
           "SensorParam", "apply_effects", "display_values", "effect_size", "param_value",
           "plausibility", "possible_ball_inertia", "sensor_correction", "sensor_names_for",
           "shape_truth"]

#: Contour harmonic orders fitted by ``frame_shape`` (k = 1: frame off-centre on the shaft;
#: k = 2 is ``frame_contour``'s b; a sin 2 phi term is a turn of the contour, i.e. the
#: encoder's zero, a sensor correction).
SHAPE_ORDERS = (1, 3, 4, 5, 6, 7, 8)

#: [m] Largest bump height fitted, and where a bump stops being plausible: a local change of
#: the plate edge, at the manufacturing scale of the contour's harmonics (3 mm).
_BUMP_MAX = 3e-3
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
        Equation rows the effect enters (1: frame, 2: ball, 3: the ball's distance).
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
    rows: tuple[int, ...] = (1, 2, 3)

    @property
    def k(self) -> int:
        """Number of parameters."""
        return len(self.names)


def param_value(base: RigParams, key: str) -> float:
    """The scalar parameter ``key`` (dotted rig.yaml name, e.g. ``frame.inertia``) of base."""
    obj = base
    for part in key.split("."):
        obj = getattr(obj, part)
    return float(obj)


def shape_truth(k: int, c: float, s: float) -> tuple[dict[str, Any], list[float]]:
    """One contour harmonic ``c cos k phi + s sin k phi`` [m]: rig.yaml changes, true vector.

    The vector is ``frame_shape``'s parameters (the values a blind test scores against).
    """
    vec = [0.0] * (2 * len(SHAPE_ORDERS))
    i = SHAPE_ORDERS.index(k)
    vec[2 * i], vec[2 * i + 1] = c, s
    return ({"frame.contour.harmonic_orders": (k,), "frame.contour.harmonic_cos": (c,),
             "frame.contour.harmonic_sin": (s,)}, vec)


def _scalar(key: str) -> tuple[Callable, Callable]:
    def get(base: RigParams) -> tuple[float]:
        return (param_value(base, key),)

    def put(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
        return base.replace(**{key: float(v[0])}), _NONE

    return get, put


def _bump_start(base: RigParams) -> tuple[float, ...]:
    return (0.0, 0.0, 0.08)


def _bump_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    t = base.track
    phi_b = float(np.mod(v[0], 2.0 * np.pi))
    return base.replace(**{"track.bump_phi": (*t.bump_phi, phi_b),
                           "track.bump_height": (*t.bump_height, float(v[1])),
                           "track.bump_width": (*t.bump_width, float(v[2]))}), _NONE


def _harmonics(base: RigParams) -> dict[int, list[float]]:
    c = base.frame.contour
    return {k: [a, b] for k, a, b in zip(c.harmonic_orders, c.harmonic_cos, c.harmonic_sin,
                                         strict=True)}


def _shape_start(base: RigParams) -> tuple[float, ...]:
    h = _harmonics(base)
    return tuple(v for k in SHAPE_ORDERS for v in h.get(k, [0.0, 0.0]))


def _shape_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    coeffs = _harmonics(base)
    for i, k in enumerate(SHAPE_ORDERS):
        coeffs[k] = [float(v[2 * i]), float(v[2 * i + 1])]
    orders = tuple(sorted(k for k, (a, b) in coeffs.items() if a != 0.0 or b != 0.0))
    return base.replace(**{"frame.contour.harmonic_orders": orders,
                           "frame.contour.harmonic_cos": tuple(coeffs[k][0] for k in orders),
                           "frame.contour.harmonic_sin": tuple(coeffs[k][1] for k in orders)}
                        ), _NONE


def _contour_start(base: RigParams) -> tuple[float, float]:
    return (base.frame.contour.a, base.frame.contour.b)


def _contour_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    return base.replace(**{"frame.contour.a": float(v[0]),
                           "frame.contour.b": float(v[1])}), _NONE


def _imbalance_start(base: RigParams) -> tuple[float, float]:
    return base.frame.imbalance_moment


def _imbalance_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    mx, my = float(v[0]), float(v[1])
    return base.replace(**{"frame.imbalance": math.hypot(mx, my),
                           "frame.imbalance_angle": math.atan2(mx, my)}), _NONE


def _ball_mass_apply(base: RigParams, v: np.ndarray) -> tuple[RigParams, SensorCorrection]:
    m = float(v[0])
    b = base.ball
    return base.replace(**{"ball.mass": m, "ball.inertia": b.inertia * m / b.mass}), _NONE


def _make() -> dict[str, Effect]:
    eff: list[Effect] = []
    g, p = _scalar("joint.coulomb_friction")
    eff.append(Effect("joint_coulomb_friction",
                      "dry (Coulomb) friction torque in the frame's bearing/motor",
                      ("T_c",), ("N m",), (2e-4,), (0.0,), (0.05,), g, p, (1,)))
    g, p = _scalar("joint.viscous_friction")
    eff.append(Effect("joint_viscous_friction", "viscous friction in the frame's bearing/motor",
                      ("c_v",), ("N m s/rad",), (1e-4,), (0.0,), (0.05,), g, p, (1,)))
    g, p = _scalar("actuator.torque_offset")
    eff.append(Effect("torque_offset", "the drive's torque at zero command (at speed: dry "
                      "friction that depends on the direction of rotation)",
                      ("tau_0",), ("N m",), (2e-4,), (-0.05,), (0.05,), g, p, (1,)))
    eff.append(Effect("frame_imbalance", "the frame's centre of mass off the shaft: torque "
                      "m_f e g sin(theta - theta_e)", ("M_x", "M_y"), ("kg m", "kg m"),
                      (2e-5, 2e-5), (-0.02, -0.02), (0.02, 0.02), _imbalance_start,
                      _imbalance_apply, (1,)))
    g, p = _scalar("frame.inertia")
    eff.append(Effect("frame_inertia", "inertia of the frame and rotor J_f",
                      ("J_f",), ("kg m^2",), (1e-5,), (2e-4,), (0.05,), g, p, (1,)))
    g, p = _scalar("actuator.torque_gain")
    eff.append(Effect("torque_gain", "motor torque per commanded torque k_u",
                      ("k_u",), ("-",), (2e-3,), (0.2,), (5.0,), g, p, (1,)))
    g, p = _scalar("track.rolling_resistance")
    eff.append(Effect("rolling_resistance", "rolling resistance of the ball on the track",
                      ("mu_rol",), ("-",), (1e-3,), (0.0,), (0.3,), g, p, (2,)))
    eff.append(Effect("track_bumps", "a bump (or dent) on the track, Gaussian in phi",
                      ("phi_b", "h", "w"), ("rad", "m", "rad"), (0.05, 5e-5, 0.01),
                      (-4 * np.pi, -_BUMP_MAX, 0.03), (4 * np.pi, _BUMP_MAX, 0.6), _bump_start,
                      _bump_apply, (1, 2, 3)))
    g, _ = _scalar("ball.mass")
    eff.append(Effect("ball_mass", "the ball's mass m_b (its inertia with it: the same shell)",
                      ("m_b",), ("kg",), (3e-5,), (1e-4,), (0.05,), g, _ball_mass_apply, (1,)))
    g, p = _scalar("ball.inertia")
    eff.append(Effect("ball_inertia", "the ball's moment of inertia J_b (a shell's thickness)",
                      ("J_b",), ("kg m^2",), (5e-9,), (5e-8,), (5e-6,), g, p))
    g, p = _scalar("ball.plate_distance")
    eff.append(Effect("plate_distance", "the distance between the groove's plates d_f, hence "
                      "the rolling radius R = sqrt(R_b^2 - d_f^2 / 4)", ("d_f",), ("m",),
                      (5e-5,), (5e-3,), (32.5e-3,), g, p))
    eff.append(Effect("frame_contour", "the contour's mean radius a and its cos 2 phi "
                      "amplitude b", ("a", "b"), ("m", "m"), (5e-5, 5e-5), (0.08, 0.02),
                      (0.14, 0.06), _contour_start, _contour_apply))
    names = tuple(f"{cs}_{k}" for k in SHAPE_ORDERS for cs in ("c", "s"))
    eff.append(Effect("frame_shape", "contour harmonics of the frame, k = 1 and 3..8 (k = 1: "
                      "off-centre)", names, tuple("m" for _ in names),
                      tuple(5e-5 for _ in names), tuple(-8e-3 for _ in names),
                      tuple(8e-3 for _ in names), _shape_start, _shape_apply))
    return {e.name: e for e in eff}


#: The library, by name.
EFFECTS: dict[str, Effect] = _make()
#: Names in library order.
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: Effects that act on the frame's row alone (identifiable without a ball).
FRAME_ONLY_EFFECTS = tuple(n for n, e in EFFECTS.items() if e.rows == (1,)
                           and n != "ball_mass")
#: Where a fitted effect goes: the key of rig.yaml.
DESTINATION: dict[str, str] = {
    "joint_coulomb_friction": "rig.yaml joint.coulomb_friction",
    "joint_viscous_friction": "rig.yaml joint.viscous_friction",
    "torque_offset": "rig.yaml actuator.torque_offset",
    "frame_imbalance": "rig.yaml frame.imbalance, frame.imbalance_angle",
    "frame_inertia": "rig.yaml frame.inertia",
    "torque_gain": "rig.yaml actuator.torque_gain",
    "rolling_resistance": "rig.yaml track.rolling_resistance",
    "track_bumps": "rig.yaml track.bump_phi/height/width",
    "ball_mass": "rig.yaml ball.mass (ball.inertia with it)",
    "ball_inertia": "rig.yaml ball.inertia",
    "plate_distance": "rig.yaml ball.plate_distance",
    "frame_contour": "rig.yaml frame.contour.a, .b",
    "frame_shape": "rig.yaml frame.contour.harmonic_*",
}
#: Smallest size worth reporting, per effect (natural units; see :func:`effect_size`): an
#: engineering resolution, far below anything that matters on the rig and above the
#: processing's own floor (a noise-free simulation leaves micrometre "bumps").
MIN_SIZE: dict[str, float] = {
    "joint_coulomb_friction": 2e-5, "joint_viscous_friction": 2e-6, "torque_offset": 2e-5,
    "frame_imbalance": 1e-5, "frame_inertia": 2e-3, "torque_gain": 2e-3,
    "rolling_resistance": 2e-4, "track_bumps": 2e-5,
    "ball_mass": 2e-3, "ball_inertia": 2e-3, "plate_distance": 2e-5,
    "frame_contour": 2e-5, "frame_shape": 2e-5,
}


def effect_size(name: str, values: np.ndarray, base: RigParams) -> float:
    """Size of a fitted effect against the nominal model, in the units of :data:`MIN_SIZE`.

    Relative change for frame inertia, ball mass and inertia, and torque gain; bump height;
    largest contour change; norm of the imbalance moment; absolute change otherwise.
    """
    eff = EFFECTS[name]
    v = display_values(eff, np.asarray(values, float))
    v0 = display_values(eff, np.asarray(eff.start(base), float))
    if name == "track_bumps":
        return float(abs(v[1]))
    if name in ("frame_shape", "frame_contour"):
        return float(np.max(np.abs(v - v0)))
    if name == "frame_imbalance":
        return float(np.hypot(*(np.asarray(values, float)
                                - np.asarray(eff.start(base), float))))
    if name in ("frame_inertia", "ball_mass", "torque_gain", "ball_inertia"):
        return float(abs(v[0] / v0[0] - 1.0))
    return float(abs(v[0] - v0[0]))


#: [-] The ball's inertia over ``m_b R_b^2`` that a ball can have: a solid sphere 2/5, a thin
#: shell 2/3 (all of its mass at its radius: no ball of that mass and radius has more).
BALL_INERTIA_RATIO = (0.4, 2.0 / 3.0)


def possible_ball_inertia(base: RigParams, rel: float) -> float:
    """The nominal ball inertia changed by the relative amount ``rel``, as a real ball can be.

    ``J_b = J_b0 (1 + rel)``; where that is outside :data:`BALL_INERTIA_RATIO` times
    ``m_b R_b^2`` the change is mirrored (``1 - rel``), and clipped to the range if both are
    outside. The seed's ball is a thin shell (``J_b0`` = 0.663 ``m_b R_b^2``), so a heavier
    inertia is a ball that cannot exist (the shell's thickness can only lower it): blind tests
    draw their ball inertia through this, not beyond what any ball could be.
    """
    b = base.ball
    lo, hi = (r * b.mass * b.radius ** 2 for r in BALL_INERTIA_RATIO)
    for v in (b.inertia * (1.0 + rel), b.inertia * (1.0 - rel)):
        if lo <= v <= hi:
            return float(v)
    return float(np.clip(b.inertia * (1.0 + rel), lo, hi))


def plausibility(name: str, values: np.ndarray, base: RigParams) -> str | None:
    """Why fitted (display) values are physically implausible, or None.

    A fit far outside what the quantity can be on a real rig (a weighed ball, a measured
    radius, a frame machined to a millimetre, a frame whose inertia is known to a factor of
    two, ...) is a *suspect*: it most likely stands in for something outside the library.
    The ranges are deliberately wide; docs/diagnosis.md lists them.
    """
    v = np.asarray(values, float)
    rel = {"frame_inertia": (base.frame.inertia, 0.5, 2.0),
           "torque_gain": (base.actuator.torque_gain, 0.5, 2.0),
           "ball_mass": (base.ball.mass, 0.8, 1.2)}
    if name in rel:
        nom, lo, hi = rel[name]
        r = v[0] / nom
        if not lo <= r <= hi:
            return (f"{r:.2f} x nominal, outside [{lo:g}, {hi:g}] x (for a quantity known this "
                    "well, the fit most likely stands in for something outside the library)")
        return None
    absmax = {"joint_coulomb_friction": (0.02, "N m"), "joint_viscous_friction": (2e-3,
              "N m s/rad"), "rolling_resistance": (0.05, "-"), "torque_offset": (0.01, "N m")}
    if name in absmax:
        lim, unit = absmax[name]
        return None if abs(v[0]) <= lim else f"{v[0]:.3g} {unit} beyond {lim:g} {unit}"
    return _plausible_geometry(name, v, base)


def _plausible_geometry(name: str, v: np.ndarray, base: RigParams) -> str | None:
    """:func:`plausibility` of the ball's inertia, the groove, the contour and a bump."""
    b = base.ball
    if name == "ball_inertia":
        ratio = v[0] / (b.mass * b.radius ** 2)
        if not 0.38 <= ratio <= 0.70:
            return (f"J_b = {ratio:.2f} m_b R_b^2, outside [0.38, 0.70] (a solid sphere is 0.4, "
                    "a thin shell 2/3)")
        return None
    if name == "plate_distance":
        d = v[0] - b.plate_distance
        return None if abs(d) <= 3e-3 else (f"groove {v[0] * 1e3:.1f} mm, {d * 1e3:+.1f} mm "
                                             "from nominal: beyond 3 mm")
    if name == "frame_imbalance":
        return None if math.hypot(v[0], v[1]) <= 1e-3 else (
            f"m_f e = {math.hypot(v[0], v[1]) * 1e3:.2f} g m beyond 1 g m")
    if name == "frame_contour":
        c = base.frame.contour
        d = max(abs(v[0] - c.a), abs(v[1] - c.b))
        return None if d <= 5e-3 else (f"contour radius or cos 2 phi amplitude changed by "
                                       f"{d * 1e3:.1f} mm: beyond a frame's 5 mm")
    if name == "frame_shape" and np.max(np.abs(v)) > 3e-3:
        return f"contour harmonic of {np.max(np.abs(v)) * 1e3:.2f} mm beyond 3 mm"
    # a bump is a local change of the same plate edge as the contour's harmonics: the same
    # manufacturing scale (3 mm); a height at the fit's own bound (3 mm) is not identified
    if name == "track_bumps" and abs(v[1]) >= _BUMP_MAX * (1.0 - 1e-6):
        return f"bump height {v[1] * 1e3:.2f} mm at or beyond a plate edge's 3 mm"
    return None


def display_values(effect: Effect, values: np.ndarray) -> np.ndarray:
    """Natural reported values: a bump's position wrapped to [0, 2 pi)."""
    v = np.asarray(values, float).copy()
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


# -- the sensor model ------------------------------------------------------------------------


@dataclass(frozen=True)
class SensorParam:
    """One parameter of a recording's sensor model (a :class:`SensorCorrection` field).

    Attributes
    ----------
    name : str
        The field of :class:`~bfr_diagnose.preprocess.SensorCorrection`.
    unit : str
        Its unit.
    scale : float
        Typical resolution (optimiser scaling).
    lower, upper : float
        Bounds.
    needs : str
        Which recordings it applies to: ``"ball"`` (a rolling ball on a turning frame),
        ``"camera"`` (any ball: also a held frame), ``"torque"`` (a turning frame).
    description : str
        One line for the report.
    prior : float or None
        [unit] Width (one standard deviation) of the calibration prior about the nominal
        value (:class:`~bfr_diagnose.preprocess.SensorCorrection`'s default), or None: no
        prior (:data:`CAMERA_PRIOR`).
    """

    name: str
    unit: str
    scale: float
    lower: float
    upper: float
    needs: str
    description: str
    prior: float | None = None

    def __post_init__(self) -> None:
        if self.prior is not None and not (math.isfinite(self.prior) and self.prior > 0.0):
            raise ValueError(f"sensor parameter {self.name}: prior width must be a positive "
                             f"number, got {self.prior!r}")


#: The calibration prior of the camera's extrinsics and scale: one standard deviation about
#: the nominal (no correction), in the parameter's unit. A camera that reports the ball in
#: metres about the shaft has been calibrated by whoever built the rig (a checkerboard, or
#: the frame's known size in the image): its scale is known to a few per cent, the shaft's
#: image to a few millimetres, its rotation to a few degrees. Used as a MAP term (extra
#: residual rows, :meth:`bfr_diagnose.identify.Problem.fit`) that holds these parameters
#: where the data do not fix them: in closed-loop data the ball stays near the top of the
#: frame and the camera's scale against the contour's mean radius is a nearly flat
#: direction, which without a prior ran the scale to its 1.25 bound and the contour 14 mm
#: small on the NTNU logs. Widths, not the bounds: data that fix a parameter move it
#: freely (the report gives each value's pull against its prior and its posterior width
#: over the prior's). ``bfr diagnose --camera-prior F`` multiplies every width (0: none).
CAMERA_PRIOR: dict[str, float] = {"offset_x": 5e-3, "offset_y": 5e-3, "rotation": 0.05,
                                  "scale": 0.03}

#: The sensor model fitted on every recording (module docstring).
SENSOR_PARAMS: tuple[SensorParam, ...] = (
    SensorParam("latency", "s", 5e-4, -0.05, 0.1, "ball",
                "camera latency beyond the nominal: a fix shows the ball this much earlier"),
    SensorParam("offset_x", "m", 2e-4, -0.03, 0.03, "camera", "camera origin offset, x",
                CAMERA_PRIOR["offset_x"]),
    SensorParam("offset_y", "m", 2e-4, -0.03, 0.03, "camera", "camera origin offset, y",
                CAMERA_PRIOR["offset_y"]),
    SensorParam("rotation", "rad", 2e-3, -0.3, 0.3, "camera", "camera rotation",
                CAMERA_PRIOR["rotation"]),
    SensorParam("scale", "-", 1e-3, 0.8, 1.25, "camera", "camera scale",
                CAMERA_PRIOR["scale"]),
    SensorParam("theta_zero", "rad", 2e-3, -0.4, 0.4, "camera",
                "the encoder's zero against the frame's shape"),
    SensorParam("torque_delay", "s", 2e-4, -0.02, 0.02, "torque",
                "the drive applies the logged torque this much later"),
)
_SENSOR = {p.name: p for p in SENSOR_PARAMS}


def sensor_names_for(has_ball: bool, frame_held: bool) -> tuple[str, ...]:
    """The sensor parameters a recording of this kind determines.

    A rolling ball on a turning frame: all; a held frame: the camera's extrinsics and the
    encoder's zero (its timing is not seen: nothing moves but the ball); no ball: the
    torque's timing.
    """
    out = []
    for p in SENSOR_PARAMS:
        if p.needs == "ball" and has_ball and not frame_held:
            out.append(p.name)
        elif p.needs == "camera" and has_ball:
            out.append(p.name)
        elif p.needs == "torque" and not frame_held:
            out.append(p.name)
    return tuple(out)


def sensor_correction(names: tuple[str, ...], values: np.ndarray) -> SensorCorrection:
    """The :class:`SensorCorrection` of the named parameters (the rest at their defaults)."""
    return replace(_NONE, **{n: float(v) for n, v in zip(names, values, strict=True)})


def sensor_param(name: str) -> SensorParam:
    """The :class:`SensorParam` of a name."""
    return _SENSOR[name]
