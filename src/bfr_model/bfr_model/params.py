"""Physical parameters of the Butterfly robot rig.

One frozen dataclass per parameter set, SI units in every field, validated on creation.
They are loaded from ``config/rig.yaml`` (ROS 2 parameter-file format), which is also the
simulator node's parameter file, so the physics has exactly one source.

Nominal values are those of Knol (2016), Table 6.1 ("the seed"); the effective rolling radius
is derived, ``R = sqrt(R_b^2 - d_f^2 / 4)`` (the seed prints ``sqrt(R_b - d_f^2/4)``, a typo;
its quoted 1.08e-2 m does not follow from its own R_b and d_f, which give 1.063e-2 m).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bfr_model.geometry import OffsetCurve
from bfr_model.param_file import (
    ParameterError,
    check,
    config_path,
    finite,
    load_ros_parameters,
    nonnegative,
    positive,
)

__all__ = [
    "MIN_CREEP_TIME",
    "ActuatorParams",
    "BallParams",
    "ContactParams",
    "ContourParams",
    "EnvironmentParams",
    "FrameParams",
    "JointParams",
    "ParameterError",
    "RigParams",
    "TrackParams",
    "default_params_path",
    "load_params",
    "params_from_dict",
    "params_to_ros_yaml",
]


#: Shortest creep time of the ball's spin [s] (``ball.creep_time``): with it the relative spin
#: relaxes at up to about 2.6 / tau_s = 520 1/s, 0.52 per 1 ms step of the simulator's RK4
#: (its stability limit is 2.8).
MIN_CREEP_TIME = 5e-3


@dataclass(frozen=True)
class BallParams:
    """The hollow ball.

    Attributes
    ----------
    mass : float
        m_b [kg].
    inertia : float
        J_b [kg m^2], about the ball's centre.
    radius : float
        R_b [m], the ball's own radius.
    plate_distance : float
        d_f [m], the distance between the two plates the ball rolls on.
    ellipticity : float
        [m] peak-to-peak variation of the ball's contact radius (an elliptic ball, seed
        section 2.1.3): the ball centre stands ``R + (ellipticity / 2) cos 2 beta`` off the
        track, beta the contact direction in ball-fixed coordinates (0 = round ball).
    ellipse_phase : float
        [rad] beta at arc length s = 0 of the ball-centre curve, relative to the normal's
        angle (the ball's orientation when the rigid model's arc length starts).
    creep_time : float
        tau_s [s], the ball's spin creeps: it relaxes to rolling over this time instead of
        rolling (linear creep at the plate edges, ``J_b omega_b' = -(J_b / tau_s) (omega_b -
        omega_roll)``; :mod:`bfr_model.dynamics`). 0: the ball rolls without slipping.
        Otherwise at least :data:`MIN_CREEP_TIME`: a faster creep is rolling to within the
        integrators' steps.
    """

    mass: float = 3.00e-3
    inertia: float = 5.48e-7
    radius: float = 16.6e-3
    plate_distance: float = 25.5e-3
    ellipticity: float = 0.0
    ellipse_phase: float = 0.0
    creep_time: float = 0.0

    def __post_init__(self) -> None:
        positive("ball.mass", self.mass)
        positive("ball.inertia", self.inertia)
        positive("ball.radius", self.radius)
        positive("ball.plate_distance", self.plate_distance)
        check(self.plate_distance < 2.0 * self.radius, "ball.plate_distance",
               f"{self.plate_distance} m must be smaller than the ball's diameter "
               f"{2 * self.radius} m, or the ball falls through the groove")
        nonnegative("ball.ellipticity", self.ellipticity)
        check(self.ellipticity < self.rolling_radius, "ball.ellipticity",
               f"{self.ellipticity} m must stay below the rolling radius")
        finite("ball.ellipse_phase", self.ellipse_phase)
        nonnegative("ball.creep_time", self.creep_time)
        check(self.creep_time == 0.0 or self.creep_time >= MIN_CREEP_TIME, "ball.creep_time",
              f"{self.creep_time} s: 0 (the ball rolls) or at least {MIN_CREEP_TIME} s (a "
              "faster creep is rolling to within the integrators' steps)")

    @property
    def rolling_radius(self) -> float:
        """R = sqrt(R_b^2 - d_f^2 / 4) [m]: distance from the ball centre to the track edge."""
        return math.sqrt(self.radius**2 - self.plate_distance**2 / 4.0)


@dataclass(frozen=True)
class ContourParams:
    """Polar contour of the frame, rho(phi) [m].

    ``rho(phi) = a - b cos(2 phi) + sum_k (c_k cos(k phi) + s_k sin(k phi))`` with
    ``harmonic_orders = k``, ``harmonic_cos = c_k`` [m], ``harmonic_sin = s_k`` [m].
    """

    a: float = 0.1095
    b: float = 0.04
    harmonic_orders: tuple[int, ...] = ()
    harmonic_cos: tuple[float, ...] = ()
    harmonic_sin: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        positive("frame.contour.a", self.a)
        finite("frame.contour.b", self.b)
        n = len(self.harmonic_orders)
        check(len(self.harmonic_cos) == n and len(self.harmonic_sin) == n,
               "frame.contour.harmonic_*",
               "harmonic_orders, harmonic_cos and harmonic_sin must have equal lengths")
        for k in self.harmonic_orders:
            check(isinstance(k, int) and k >= 1, "frame.contour.harmonic_orders",
                   f"orders must be integers >= 1, got {k!r}")
        for c in (*self.harmonic_cos, *self.harmonic_sin):
            finite("frame.contour.harmonic_cos/sin", c)
        amp = abs(self.b) + sum(abs(c) + abs(s) for c, s in
                                zip(self.harmonic_cos, self.harmonic_sin, strict=True))
        check(amp < self.a, "frame.contour",
               f"harmonic amplitudes ({amp} m) must stay below a ({self.a} m): rho > 0")


@dataclass(frozen=True)
class FrameParams:
    """The rotating frame: inertia J_f [kg m^2] (with rotor), mass m_f [kg], contour.

    ``wobble`` [rad] tilts the frame's plane about the frame's own y axis, so that the plane
    is not perpendicular to the shaft: a frame point ``(x, y)`` sits at ``(x cos w, y,
    x sin w)`` in the shaft's coordinates and the ball sways along z by ``x sin w`` (the
    seed's eqs. 2.7-2.9). A pitched shaft is ``environment.axis_misalignment`` instead.

    ``imbalance`` = m_f e [kg m] and ``imbalance_angle`` = theta_e [rad]: the frame's centre
    of mass sits at ``e [sin theta_e, cos theta_e]`` in frame coordinates (theta_e clockwise
    from the frame's +y axis, like phi), so its potential energy is
    ``V_f = m_f e g cos(theta - theta_e)`` and gravity puts the torque
    ``m_f e g sin(theta - theta_e)`` on the frame (a once-per-turn ripple of the torque).
    """

    inertia: float = 1.58e-3
    mass: float = 0.1
    contour: ContourParams = field(default_factory=ContourParams)
    wobble: float = 0.0
    imbalance: float = 0.0
    imbalance_angle: float = 0.0

    def __post_init__(self) -> None:
        positive("frame.inertia", self.inertia)
        nonnegative("frame.mass", self.mass)
        finite("frame.wobble", self.wobble)
        check(abs(self.wobble) < math.pi / 4, "frame.wobble", "must be within (-pi/4, pi/4)")
        nonnegative("frame.imbalance", self.imbalance)
        finite("frame.imbalance_angle", self.imbalance_angle)

    @property
    def imbalance_moment(self) -> tuple[float, float]:
        """First mass moment of the frame about the shaft in frame coordinates [kg m].

        ``m_f e (sin theta_e, cos theta_e)``: the kernels' form (a frame point's convention).
        """
        return (self.imbalance * math.sin(self.imbalance_angle),
                self.imbalance * math.cos(self.imbalance_angle))


@dataclass(frozen=True)
class EnvironmentParams:
    """Gravity g [m/s^2] and the shaft's pitch from horizontal, axis_misalignment [rad].

    A shaft pitched by eps tilts the frame's plane; in that plane gravity is g cos(eps).
    """

    gravity: float = 9.81
    axis_misalignment: float = 0.0

    def __post_init__(self) -> None:
        positive("environment.gravity", self.gravity)
        finite("environment.axis_misalignment", self.axis_misalignment)
        check(abs(self.axis_misalignment) < math.pi / 2, "environment.axis_misalignment",
               "must be within (-pi/2, pi/2)")

    @property
    def in_plane_gravity(self) -> float:
        """In-plane gravity g cos(eps) [m/s^2], gravity's component in the frame's plane."""
        return self.gravity * math.cos(self.axis_misalignment)


@dataclass(frozen=True)
class JointParams:
    """Friction in the frame's bearing.

    Torque on the frame: ``-viscous_friction * theta_dot
    - (coulomb_friction + load_friction * F_load) * tanh(theta_dot / coulomb_smoothing)``, in
    [N m s/rad], [N m], [m], [rad/s]. ``F_load`` [N] is the bearing load, the magnitude of the
    ball's contact force on the frame plus the frame's weight (seed section 2.2:
    ``T_joint = 1e-5 F_load``, a rolling bearing of bore 0.01 m).
    """

    viscous_friction: float = 0.0
    coulomb_friction: float = 0.0
    coulomb_smoothing: float = 1.0e-3
    load_friction: float = 0.0

    def __post_init__(self) -> None:
        nonnegative("joint.viscous_friction", self.viscous_friction)
        nonnegative("joint.coulomb_friction", self.coulomb_friction)
        positive("joint.coulomb_smoothing", self.coulomb_smoothing)
        nonnegative("joint.load_friction", self.load_friction)


@dataclass(frozen=True)
class ActuatorParams:
    """Motor: applied torque = torque_gain [-] * command + torque_offset [N m].

    The command is clamped to torque_limit [N m]. ``torque_offset`` is what the drive applies
    at zero command (an amplifier or current-sensor offset); at speed it acts like dry
    friction that depends on the direction of rotation (docs/diagnosis.md).
    """

    torque_gain: float = 1.0
    torque_limit: float = 0.1
    torque_offset: float = 0.0

    def __post_init__(self) -> None:
        positive("actuator.torque_gain", self.torque_gain)
        positive("actuator.torque_limit", self.torque_limit)
        finite("actuator.torque_offset", self.torque_offset)
        check(abs(self.torque_offset) < self.torque_limit, "actuator.torque_offset",
              f"{self.torque_offset} N m must be smaller than the torque limit "
              f"{self.torque_limit} N m")


@dataclass(frozen=True)
class TrackParams:
    """Imperfections of the track the ball rolls on.

    Attributes
    ----------
    rolling_resistance : float
        mu_rol [-]: a force ``mu_rol * F_n`` opposing the ball's rolling (seed eq. 2.4).
    rolling_smoothing : float
        [rad/s] regularisation velocity of the rolling direction's sign.
    bump_phi, bump_height, bump_width : tuple of float
        Gaussian bumps added to the contour radius:
        ``rho += h exp(-d^2 / (2 w^2))`` with d the wrapped angle distance to ``bump_phi``
        [rad], ``h = bump_height`` [m], ``w = bump_width`` [rad]. Both models see them; the
        rigid model needs them gentle (no cusp of the ball-centre curve).
    asperity_phi, asperity_height, asperity_width : tuple of float
        Sharp bumps of the same form (single bumps, a row, a rough surface drawn by
        :func:`bfr_model.perturbations.rough_track`) that only the contact model
        (:mod:`bfr_model.contact`) resolves; the rigid model leaves them out.
    asperity_edge : tuple of int
        [-] the plate edge each sharp bump sits on (seed recommendation 3): 0 both edges,
        1 the front plate (z = +d_f/2, towards the camera), 2 the back plate (z = -d_f/2).
        Empty, or all zeros of any length (the file's ``[0]``), means every asperity is on
        both edges; otherwise one entry per asperity. Bumps on one edge only need the
        contact model's two-edge contact (:class:`bfr_model.contact.ContactModel`).
    """

    rolling_resistance: float = 0.0
    rolling_smoothing: float = 1.0e-3
    bump_phi: tuple[float, ...] = ()
    bump_height: tuple[float, ...] = ()
    bump_width: tuple[float, ...] = ()
    asperity_phi: tuple[float, ...] = ()
    asperity_height: tuple[float, ...] = ()
    asperity_width: tuple[float, ...] = ()
    asperity_edge: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        nonnegative("track.rolling_resistance", self.rolling_resistance)
        positive("track.rolling_smoothing", self.rolling_smoothing)
        n = len(self.bump_phi)
        check(len(self.bump_height) == n and len(self.bump_width) == n, "track.bump_*",
               "bump_phi, bump_height and bump_width must have equal lengths")
        for v in self.bump_phi:
            finite("track.bump_phi", v)
        for v in self.bump_height:
            finite("track.bump_height", v)
        for v in self.bump_width:
            positive("track.bump_width", v)
        n = len(self.asperity_phi)
        check(len(self.asperity_height) == n and len(self.asperity_width) == n,
               "track.asperity_*",
               "asperity_phi, asperity_height and asperity_width must have equal lengths")
        for v in (*self.asperity_phi, *self.asperity_height):
            finite("track.asperity_phi/height", v)
        for v in self.asperity_width:
            positive("track.asperity_width", v)
        check(len(self.asperity_edge) in (0, n), "track.asperity_edge",
              f"needs one entry per asperity ({n}), got {len(self.asperity_edge)}")
        for v in self.asperity_edge:
            check(v in (0, 1, 2), "track.asperity_edge",
                  f"{v!r} is not an edge (0 both, 1 front, 2 back)")

    def asperity_edges(self) -> tuple[int, ...]:
        """The edge of every asperity (0 both, 1 front, 2 back), zeros when not given."""
        return self.asperity_edge or (0,) * len(self.asperity_phi)


@dataclass(frozen=True)
class ContactParams:
    """Force-based contact of the ball with the track (seed chapter 4; bfr_model.contact).

    The ball touches the two plate edges; in the frame's plane it is a disc of the rolling
    radius R pressed onto the contour. Normal force (seed eq. 4.15 with q = 1)
    ``F_n = k w^n + d w^p w_dot``, ``w`` the penetration [m], clipped at 0 (Hunt-Crossley for
    p = n); tangential force a stick spring-damper bounded by ``static_friction * F_n`` that
    slides at ``dynamic_friction * F_n``.

    Attributes
    ----------
    stiffness : float
        k [N/m^n]; 0 derives it from Hertz (seed eq. 4.16 with the Poisson factors), a solid
        sphere of radius R_b on each of the two edges, whose normals are inclined by
        ``acos(R / R_b)`` to the plane: ``k = 2 cos^(5/2)(gamma) 4/3 E* sqrt(R_b)``.
    exponent : float
        n [-], 3/2 for Hertz contact.
    ball_modulus, frame_modulus : float
        Young's moduli [Pa] (a hollow ABS/celluloid ball, aluminium plates).
    ball_poisson, frame_poisson : float
        Poisson ratios [-].
    restitution : float
        Coefficient of restitution [-] of a normal impact at ``restitution_speed`` [m/s];
        the damping coefficient d is solved for it (bfr_model.contact.damping_for_restitution).
    damping_exponent : float
        p [-] of the damping term ``d w^p w_dot`` (seed eq. 4.15). ``p = n`` is Hunt and
        Crossley's law (restitution ~ 1 - 1.5 (1 - e) v / v_e: near 1 for slow impacts, so
        a bouncing ball never settles); ``p = n / 2 - 1/2`` (1/4 for n = 3/2, Tsuji et al.
        1992) gives a restitution independent of the impact speed (the default).
    static_friction, dynamic_friction : float
        mu_s, mu_d [-] of the ball on a plate edge (the in-plane law uses ``mu R_b / R``:
        the groove's wedge effect, bfr_model.contact).
    tangential_stiffness : float
        [N/m] of the stick spring at the contact (Mindlin: about 0.8 of the normal one).
    tangential_damping : float
        [N s/m] of the stick damper.
    time_step : float
        [s] fixed step of the compiled contact integrator (contact modes near 1-2 kHz).
    max_flight_step : float
        [s] longest step while no contact can begin (free flight, a bound on the ball's
        travel against the gap: bfr_model.contact); a whole multiple of ``time_step`` is
        taken. Below ``2 time_step`` every step is ``time_step``.
    """

    stiffness: float = 0.0
    exponent: float = 1.5
    ball_modulus: float = 2.3e9
    ball_poisson: float = 0.35
    frame_modulus: float = 70.0e9
    frame_poisson: float = 0.33
    restitution: float = 0.85
    restitution_speed: float = 0.1
    damping_exponent: float = 0.25
    static_friction: float = 0.6
    dynamic_friction: float = 0.5
    tangential_stiffness: float = 1.5e5
    tangential_damping: float = 20.0
    time_step: float = 2.0e-5
    max_flight_step: float = 2.5e-4

    def __post_init__(self) -> None:
        nonnegative("contact.stiffness", self.stiffness)
        positive("contact.exponent", self.exponent)
        positive("contact.ball_modulus", self.ball_modulus)
        positive("contact.frame_modulus", self.frame_modulus)
        for name in ("ball_poisson", "frame_poisson"):
            v = getattr(self, name)
            finite(f"contact.{name}", v)
            check(-1.0 < v < 0.5, f"contact.{name}", "must be within (-1, 0.5)")
        finite("contact.restitution", self.restitution)
        check(0.0 < self.restitution <= 1.0, "contact.restitution", "must be within (0, 1]")
        positive("contact.restitution_speed", self.restitution_speed)
        nonnegative("contact.damping_exponent", self.damping_exponent)
        nonnegative("contact.static_friction", self.static_friction)
        nonnegative("contact.dynamic_friction", self.dynamic_friction)
        check(self.dynamic_friction <= self.static_friction, "contact.dynamic_friction",
               "must not exceed static_friction")
        positive("contact.tangential_stiffness", self.tangential_stiffness)
        nonnegative("contact.tangential_damping", self.tangential_damping)
        positive("contact.time_step", self.time_step)
        check(self.time_step <= 1e-3, "contact.time_step", "must be <= 1e-3 s (stiff contact)")
        nonnegative("contact.max_flight_step", self.max_flight_step)
        check(self.max_flight_step <= 1e-3, "contact.max_flight_step", "must be <= 1e-3 s")

    def effective_modulus(self) -> float:
        """E* = 1 / ((1 - nu_b^2) / E_b + (1 - nu_f^2) / E_f) [Pa] (Hertz)."""
        return 1.0 / ((1.0 - self.ball_poisson**2) / self.ball_modulus
                      + (1.0 - self.frame_poisson**2) / self.frame_modulus)


@dataclass(frozen=True)
class RigParams:
    """All physical parameters of the rig."""

    ball: BallParams = field(default_factory=BallParams)
    frame: FrameParams = field(default_factory=FrameParams)
    environment: EnvironmentParams = field(default_factory=EnvironmentParams)
    joint: JointParams = field(default_factory=JointParams)
    actuator: ActuatorParams = field(default_factory=ActuatorParams)
    track: TrackParams = field(default_factory=TrackParams)
    contact: ContactParams = field(default_factory=ContactParams)

    def __post_init__(self) -> None:
        self.check_rigid()

    def check_rigid(self) -> None:
        """Raise :class:`ParameterError` if the rigid model cannot represent the track.

        The rigid model needs a ball-centre curve without cusps: every concave part of the
        track, ``track.bump_*`` included, must be gentler than the rolling radius. Sharp
        bumps that only the contact model (bfr_model.contact) can roll over belong in
        ``track.asperity_*``, which this check (and the rigid model) leaves out.
        """
        c, t = self.frame.contour, self.track
        key = (c.a, c.b, c.harmonic_orders, c.harmonic_cos, c.harmonic_sin, t.bump_phi,
               t.bump_height, t.bump_width, self.ball.rolling_radius)
        lam_min = _RIGID_CHECKS.get(key)
        if lam_min is None:  # the same curve is checked once (fits change other entries)
            lam_min = OffsetCurve.from_params(self).speed_floor()
            if len(_RIGID_CHECKS) > 1024:
                _RIGID_CHECKS.clear()
            _RIGID_CHECKS[key] = lam_min
        check(lam_min > 0.0, "frame.contour / track.bump_*",
               "the ball-centre curve has a cusp (a concave part of the track is sharper "
               f"than the rolling radius R = {self.ball.rolling_radius:.4g} m; |p'| down to "
               f"{lam_min:.3g} m/rad): widen the bumps or use the contact model")

    @property
    def contact_stiffness(self) -> float:
        """Hunt-Crossley stiffness k [N/m^n]: ``contact.stiffness``, or Hertz if that is 0.

        Hertz (seed eq. 4.16, with the Poisson factors): each of the two plate edges presses
        on the ball along a line inclined by gamma, ``cos gamma = R / R_b``, to the frame's
        plane; an in-plane penetration w compresses each contact by ``w cos gamma``, so the
        in-plane force is ``2 cos gamma k_H (w cos gamma)^(3/2)`` with
        ``k_H = 4/3 E* sqrt(R_b)`` (sphere on a locally flat edge).
        """
        if self.contact.stiffness > 0.0:
            return self.contact.stiffness
        cos_g = self.ball.rolling_radius / self.ball.radius
        k_h = 4.0 / 3.0 * self.contact.effective_modulus() * math.sqrt(self.ball.radius)
        return 2.0 * cos_g ** (1.0 + self.contact.exponent) * k_h

    def replace(self, **changes: Any) -> RigParams:
        """Return a copy with dotted-name changes, e.g. ``replace(**{"ball.mass": 3e-3})``.

        Scalars, and tuples of numbers that leave the lists in the form
        :func:`params_from_dict` gives them (:func:`_canonical`: integer orders, float
        amplitudes, no all-zero entries), are set by nested ``dataclasses.replace`` (every
        ``__post_init__`` check still runs); anything else goes through the parameter
        dictionary, which converts and drops zero entries (a fit's 14 harmonics: 0.03 ms
        instead of 0.09 ms, the curve's rigid check aside).
        """
        if changes and all(not isinstance(v, (list, tuple, dict)) for v in changes.values()):
            return _replace_scalars(self, changes)
        if changes and all(_plain(v) for v in changes.values()):
            try:
                out = _replace_scalars(self, changes)
            except ParameterError:
                out = None  # e.g. an order 3.0, which the dictionary makes an integer
            if out is not None and _canonical(out):
                return out
        d = params_to_dict(self)
        for key, value in changes.items():
            node = d
            parts = key.split(".")
            for p in parts[:-1]:
                if p not in node or not isinstance(node[p], dict):
                    raise ParameterError(f"parameter {key}: unknown group {p!r}")
                node = node[p]
            if parts[-1] not in node:
                raise ParameterError(f"parameter {key}: unknown name {parts[-1]!r}")
            node[parts[-1]] = value
        return params_from_dict(d)


def _plain(value: Any) -> bool:
    """A scalar, or a tuple of plain numbers (no list, dict or nested tuple)."""
    if isinstance(value, tuple):
        return all(type(v) in (int, float) for v in value)
    return not isinstance(value, (list, dict))


def _canonical(params: RigParams) -> bool:
    """Whether ``params`` is what :func:`params_from_dict` builds from its own dictionary.

    Its lists are the normalised ones: integer harmonic orders with float amplitudes, no
    harmonic whose amplitudes are both zero, no bump or asperity of zero height, asperity
    edges not all zero.
    """
    c, t = params.frame.contour, params.track
    floats = (*c.harmonic_cos, *c.harmonic_sin, *t.bump_phi, *t.bump_height, *t.bump_width,
              *t.asperity_phi, *t.asperity_height, *t.asperity_width)
    return (all(type(k) is int for k in c.harmonic_orders)
            and all(type(v) is float for v in floats)
            and all(a != 0.0 or b != 0.0 for a, b in zip(c.harmonic_cos, c.harmonic_sin,
                                                         strict=False))
            and all(h != 0.0 for h in (*t.bump_height, *t.asperity_height))
            and not (t.asperity_edge and all(v == 0 for v in t.asperity_edge)))


#: Smallest arc-length rate of each ball-centre curve checked (:meth:`RigParams.check_rigid`).
_RIGID_CHECKS: dict[tuple, float] = {}


def _replace_scalars(params: Any, changes: dict[str, Any]) -> Any:
    """:meth:`RigParams.replace` for scalar values: nested ``dataclasses.replace``.

    Every dataclass on the way is rebuilt, so every check of its ``__post_init__`` runs.
    """
    here: dict[str, Any] = {}
    deeper: dict[str, dict[str, Any]] = {}
    for key, value in changes.items():
        head, _, rest = key.partition(".")
        names = {f.name for f in dataclasses.fields(params)}
        if head not in names:
            what = "group" if rest else "name"
            raise ParameterError(f"parameter {key}: unknown {what} {head!r}")
        if rest:
            if not dataclasses.is_dataclass(getattr(params, head)):
                raise ParameterError(f"parameter {key}: unknown group {head!r}")
            deeper.setdefault(head, {})[rest] = value
        else:
            if dataclasses.is_dataclass(getattr(params, head)):
                raise ParameterError(f"parameter {key}: {head!r} is a group, not a value")
            here[head] = value
    for head, sub in deeper.items():
        here[head] = _replace_scalars(getattr(params, head), sub)
    try:
        return dataclasses.replace(params, **here)
    except TypeError as exc:
        raise ParameterError(f"parameter {sorted(changes)}: {exc}") from exc


def default_params_path() -> Path:
    """Path of the shipped ``rig.yaml`` (bfr_model's ``config/``; see ``config_path``)."""
    return config_path("bfr_model", "rig.yaml")


def _group(d: Mapping[str, Any], name: str) -> dict[str, Any]:
    g = d.get(name, {})
    if not isinstance(g, Mapping):
        raise ParameterError(f"parameter {name}: expected a group, got {g!r}")
    return dict(g)


def _build(cls: type, d: Mapping[str, Any], prefix: str) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = set(d) - names
    if unknown:
        raise ParameterError(f"parameter {prefix}: unknown entries {sorted(unknown)}")
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name not in d:
            continue
        v = d[f.name]
        if isinstance(v, list):
            v = tuple(v)
        kwargs[f.name] = v
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ParameterError(f"parameter {prefix}: {exc}") from exc


def _drop_zero_entries(orders_or_pos: tuple, *values: tuple) -> tuple[tuple, ...]:
    """Drop list entries whose amplitudes are all zero (ROS lists cannot be empty)."""
    keep = [i for i in range(len(orders_or_pos)) if any(v[i] != 0.0 for v in values)]
    return (tuple(orders_or_pos[i] for i in keep), *(tuple(v[i] for i in keep) for v in values))


def params_from_dict(d: Mapping[str, Any]) -> RigParams:
    """Build :class:`RigParams` from the nested ``ros__parameters`` mapping."""
    known = {"ball", "frame", "environment", "joint", "actuator", "track", "contact"}
    unknown = set(d) - known
    if unknown:
        raise ParameterError(f"unknown parameter groups {sorted(unknown)}")
    frame = _group(d, "frame")
    contour = _group(frame, "contour")
    orders = tuple(int(k) for k in contour.get("harmonic_orders", ()))
    ccos = tuple(float(c) for c in contour.get("harmonic_cos", ()))
    csin = tuple(float(c) for c in contour.get("harmonic_sin", ()))
    if len(ccos) == len(orders) == len(csin):
        orders, ccos, csin = _drop_zero_entries(orders, ccos, csin)
    contour.update(harmonic_orders=orders, harmonic_cos=ccos, harmonic_sin=csin)
    frame["contour"] = _build(ContourParams, contour, "frame.contour")
    track = _group(d, "track")
    pos = tuple(float(v) for v in track.get("bump_phi", ()))
    hgt = tuple(float(v) for v in track.get("bump_height", ()))
    wid = tuple(float(v) for v in track.get("bump_width", ()))
    if len(pos) == len(hgt) == len(wid):
        pos, hgt, wid = (tuple(pos[i] for i in range(len(pos)) if hgt[i] != 0.0),
                         tuple(h for h in hgt if h != 0.0),
                         tuple(wid[i] for i in range(len(pos)) if hgt[i] != 0.0))
    track.update(bump_phi=pos, bump_height=hgt, bump_width=wid)
    pos = tuple(float(v) for v in track.get("asperity_phi", ()))
    hgt = tuple(float(v) for v in track.get("asperity_height", ()))
    wid = tuple(float(v) for v in track.get("asperity_width", ()))
    edge = tuple(track.get("asperity_edge", ()))
    if edge and all(v == 0 for v in edge):
        edge = ()  # all zeros (the file's [0]): every asperity on both edges
    if len(pos) == len(hgt) == len(wid):
        keep = [i for i in range(len(pos)) if hgt[i] != 0.0]
        if len(edge) == len(pos):
            edge = tuple(edge[i] for i in keep)
        pos, hgt, wid = (tuple(pos[i] for i in keep), tuple(hgt[i] for i in keep),
                         tuple(wid[i] for i in keep))
    track.update(asperity_phi=pos, asperity_height=hgt, asperity_width=wid,
                 asperity_edge=edge)
    return RigParams(
        ball=_build(BallParams, _group(d, "ball"), "ball"),
        frame=_build(FrameParams, frame, "frame"),
        environment=_build(EnvironmentParams, _group(d, "environment"), "environment"),
        joint=_build(JointParams, _group(d, "joint"), "joint"),
        actuator=_build(ActuatorParams, _group(d, "actuator"), "actuator"),
        track=_build(TrackParams, track, "track"),
        contact=_build(ContactParams, _group(d, "contact"), "contact"),
    )


def load_params(path: str | Path | None = None) -> RigParams:
    """Load rig parameters from a ROS 2 parameter YAML file (default: the shipped rig.yaml).

    Raises
    ------
    ParameterError
        If the file is missing, is not a parameter file, or a value is invalid.
    """
    p = Path(path) if path is not None else default_params_path()
    d = load_ros_parameters(p, ParameterError)
    try:
        return params_from_dict(d)
    except ParameterError as exc:
        raise ParameterError(f"{p}: {exc}") from exc


def params_to_dict(params: RigParams) -> dict[str, Any]:
    """Nested plain-dict form of the parameters (tuples as lists)."""

    def conv(obj: Any) -> Any:
        if dataclasses.is_dataclass(obj):
            return {f.name: conv(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
        if isinstance(obj, tuple):
            return [conv(v) for v in obj]
        return obj

    return conv(params)


def params_to_ros_yaml(params: RigParams, header: str = "") -> str:
    """Serialise parameters as a ROS 2 parameter file loadable by :func:`load_params`.

    Empty lists become one zero entry, since ROS 2 cannot type an empty list.
    """
    d = params_to_dict(params)
    c = d["frame"]["contour"]
    if not c["harmonic_orders"]:
        c.update(harmonic_orders=[4], harmonic_cos=[0.0], harmonic_sin=[0.0])
    t = d["track"]
    if not t["bump_phi"]:
        t.update(bump_phi=[0.0], bump_height=[0.0], bump_width=[0.05])
    if not t["asperity_phi"]:
        t.update(asperity_phi=[0.0], asperity_height=[0.0], asperity_width=[0.005])
    if not t["asperity_edge"]:
        t.update(asperity_edge=[0])
    body = yaml.safe_dump({"/**": {"ros__parameters": d}}, sort_keys=False)
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    return "\n".join([*lines, body])
