"""Perturbation library of the Butterfly robot (seed chapter 2, section 2.2, Table 6.1).

Every perturbation is a change of the physics parameters (``config/rig.yaml``), so each is
switchable in the YAML and seen by every simulator path that loads it (the rigid model
:class:`bfr_model.dynamics.RigidModel`, the contact model :class:`bfr_model.contact.ContactModel`,
the simulator node). :data:`PERTURBATIONS` lists them with the seed's symbols;
:func:`perturbed` applies one at the study's magnitude (``config/perturbation_study.yaml``,
the seed's values by default).

============  ===================================  ==============================================
key           parameters                           physics (where it acts)
============  ===================================  ==============================================
mass          ball.mass, ball.inertia,             +1 % (seed E_mass, eq. 2.12): both models
              frame.inertia
radius        ball.radius                          rolling radius R* = 0.99 R (seed E_rot, 2.6)
rolling       track.rolling_resistance             mu_rol: force mu_rol F_n against the rolling
                                                   (seed E_rol, 2.4): both models
joint         joint.load_friction                  T = c F_load, F_load the bearing load (seed
                                                   E_joint, 2.5; Coulomb/viscous variants:
                                                   joint.coulomb_friction / viscous_friction)
wobble        frame.wobble                         frame plane tilted about its y axis: the ball
                                                   sways along z (seed E_tr, eqs. 2.7-2.9): rigid
pitch         environment.axis_misalignment        shaft pitched from horizontal: in-plane
                                                   gravity g cos(eps) (the seed's wording)
bump          track.bump_*                         one gentle Gaussian bump (seed E_pot, 2.10):
                                                   both models
ellipse       ball.ellipticity                     contact radius R + (e/2) cos 2 beta (seed
                                                   2.1.3, situation 2): both models
elastic       contact.stiffness                    compliance k_bt (seed E_ela, 2.11): the
                                                   contact model's Hunt-Crossley stiffness with
                                                   the same linearised stiffness at the ball's
                                                   weight; an analysis quantity for the rigid one
rough         track.asperity_*                     sharp bumps, a row or a seeded rough surface
                                                   (:func:`rough_track`): contact model
============  ===================================  ==============================================

Rough surfaces are drawn by :func:`rough_track` from a seeded ``numpy.random.Generator`` into
the YAML-able ``track.asperity_*`` arrays; :func:`write_params` writes the result as a
parameter file.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from bfr_model.geometry import OffsetCurve, contour_kernel
from bfr_model.param_file import check, positive
from bfr_model.params import ParameterError, RigParams, default_params_path, params_to_ros_yaml

__all__ = [
    "PERTURBATIONS",
    "Perturbation",
    "StudySettings",
    "TwoEdgeSettings",
    "bump_row",
    "contour_arc_to_phi",
    "hc_stiffness_from_linear",
    "load_study",
    "perturbed",
    "rough_track",
    "with_asperities",
    "write_params",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PerturbationMagnitudes:
    """``perturbations:`` group of the study file (units in the YAML comments)."""

    mass_increase: float = 0.01
    radius_decrease: float = 0.01
    bump_height: float = 5.0e-4
    rolling_resistance: float = 1.0e-3
    joint_load_friction: float = 1.0e-5
    misalignment: float = math.pi / 80.0
    elastic_stiffness: float = 1.0e6
    ellipticity: float = 5.0e-4
    smooth_bump_width: float = 0.05
    smooth_bump_phi: float = math.pi / 2.0


@dataclass(frozen=True)
class RunSettings:
    """``run:`` group: the closed-loop run the energy and bounce analyses evaluate."""

    duration: float = 10.0
    settle: float = 2.0
    phase: float = 0.3
    d_theta: float = 0.02
    camera_noise: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class BounceSettings:
    """``bounce:`` group: bump-height sweep and bump density of the discrete estimate."""

    bump_heights_min: float = 1.0e-5
    bump_heights_max: float = 1.0e-3
    bump_heights_count: int = 41
    bumps_per_metre: float = 1000.0


@dataclass(frozen=True)
class ContactRunSettings:
    """``contact_run:`` group: the closed loop with the contact model over a row of bumps."""

    duration: float = 8.0
    row_count: int = 30
    row_length: float = 0.03
    row_height: float = 5.0e-4
    row_width: float = 1.0e-4
    row_start_phi: float | None = None
    isolated_spacing: float = 0.008
    isolated_heights: tuple[float, ...] = (1.0e-4, 5.0e-4)
    time_step: float = 1.0e-5
    seed: int = 1


@dataclass(frozen=True)
class TwoEdgeSettings:
    """``two_edge:`` group: bumps on both plate edges (seed recommendation 3).

    Rows of ``row_length`` along the contour on both halves of it, centred at
    ``location`` (None: where the discrete model puts path B). Around the reference row
    (``spacing``, ``height``): a phase sweep of the back edge's row against the front one
    (in bump spacings), a spacing sweep and a height sweep, each with the front row alone,
    in phase (0) and interleaved (0.5).
    """

    duration: float = 8.0
    location: float | None = None
    row_length: float = 0.03
    width: float = 1.0e-4
    spacing: float = 1.0e-3
    height: float = 5.0e-4
    phases: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75)
    spacings: tuple[float, ...] = (2.0e-3, 4.0e-3, 8.0e-3)
    heights: tuple[float, ...] = (1.0e-4, 2.5e-4)
    time_step: float = 2.0e-5

    def __post_init__(self) -> None:
        for name in ("duration", "row_length", "width", "spacing", "height", "time_step"):
            positive(f"two_edge.{name}", getattr(self, name))
        for v in (*self.spacings, *self.heights):
            positive("two_edge.spacings/heights", v)
        for v in self.phases:
            check(0.0 <= v < 1.0, "two_edge.phases", f"{v} is not within [0, 1)")


@dataclass(frozen=True)
class StudySettings:
    """All settings of the perturbation study (``config/perturbation_study.yaml``)."""

    perturbations: PerturbationMagnitudes = field(default_factory=PerturbationMagnitudes)
    run: RunSettings = field(default_factory=RunSettings)
    bounce: BounceSettings = field(default_factory=BounceSettings)
    contact_run: ContactRunSettings = field(default_factory=ContactRunSettings)
    two_edge: TwoEdgeSettings = field(default_factory=TwoEdgeSettings)


def default_study_path() -> Path:
    """Path of the shipped ``perturbation_study.yaml`` (next to ``rig.yaml``)."""
    return default_params_path().parent / "perturbation_study.yaml"


def load_study(path: str | Path | None = None) -> StudySettings:
    """Load the study settings (default: the shipped file); unknown keys are errors."""
    p = Path(path) if path is not None else default_study_path()
    try:
        doc = yaml.safe_load(p.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"cannot read study file {p}: {exc}") from exc
    groups: dict[str, Any] = {}
    for f in fields(StudySettings):
        cls = f.default_factory  # type: ignore[misc]
        sub = doc.get(f.name, {}) or {}
        names = {g.name for g in fields(cls)}
        unknown = set(sub) - names
        if unknown:
            raise ParameterError(f"{p}: unknown entries {sorted(unknown)} in {f.name}")
        sub = {k: tuple(v) if isinstance(v, list) else v for k, v in sub.items()}
        try:
            groups[f.name] = cls(**sub)
        except TypeError as exc:
            raise ParameterError(f"{p}: {f.name}: {exc}") from exc
    unknown = set(doc) - set(groups)
    if unknown:
        raise ParameterError(f"{p}: unknown groups {sorted(unknown)}")
    return StudySettings(**groups)


def hc_stiffness_from_linear(k_lin: float, load: float, exponent: float = 1.5) -> float:
    """Hunt-Crossley k [N/m^n] whose linearised stiffness at ``load`` [N] is k_lin [N/m].

    ``F = k w^n``  =>  ``dF/dw = n k w^(n-1) = n k^(1/n) F^((n-1)/n)``, solved for k.
    """
    return (k_lin / (exponent * load ** ((exponent - 1.0) / exponent))) ** exponent


@dataclass(frozen=True)
class Perturbation:
    """One perturbation of the seed's set.

    Attributes
    ----------
    key : str
        Short name.
    symbol : str
        The seed's energy symbol (chapter 2).
    title : str
        One line.
    changes : callable
        ``changes(params, magnitudes) -> {dotted name: value}``.
    models : str
        Which models carry it ("rigid+contact", "rigid", "contact").
    """

    key: str
    symbol: str
    title: str
    changes: Callable[[RigParams, PerturbationMagnitudes], dict[str, Any]]
    models: str


def _mass(p: RigParams, m: PerturbationMagnitudes) -> dict[str, Any]:
    f = 1.0 + m.mass_increase
    return {"ball.mass": p.ball.mass * f, "ball.inertia": p.ball.inertia * f,
            "frame.inertia": p.frame.inertia * f}


def _radius(p: RigParams, m: PerturbationMagnitudes) -> dict[str, Any]:
    r_new = p.ball.rolling_radius * (1.0 - m.radius_decrease)
    return {"ball.radius": math.sqrt(r_new**2 + p.ball.plate_distance**2 / 4.0)}


def _elastic(p: RigParams, m: PerturbationMagnitudes) -> dict[str, Any]:
    load = p.ball.mass * p.environment.in_plane_gravity
    return {"contact.stiffness": hc_stiffness_from_linear(m.elastic_stiffness, load,
                                                          p.contact.exponent)}


PERTURBATIONS: dict[str, Perturbation] = {
    "mass": Perturbation("mass", "E_mass", "ball mass and inertia, frame inertia +1 %", _mass,
                         "rigid+contact"),
    "radius": Perturbation("radius", "E_rot", "rolling radius -1 %", _radius, "rigid+contact"),
    "rolling": Perturbation(
        "rolling", "E_rol", "rolling resistance mu_rol",
        lambda p, m: {"track.rolling_resistance": m.rolling_resistance}, "rigid+contact"),
    "joint": Perturbation(
        "joint", "E_joint", "joint friction T = c F_load",
        lambda p, m: {"joint.load_friction": m.joint_load_friction}, "rigid+contact"),
    "wobble": Perturbation(
        "wobble", "E_tr", "frame plane tilted by eps about its y axis (sway along z)",
        lambda p, m: {"frame.wobble": m.misalignment}, "rigid"),
    "pitch": Perturbation(
        "pitch", "E_g", "shaft pitched by eps (in-plane gravity g cos eps)",
        lambda p, m: {"environment.axis_misalignment": m.misalignment}, "rigid+contact"),
    "bump": Perturbation(
        "bump", "E_pot", "one gentle bump of height delta_h",
        lambda p, m: {"track.bump_phi": [m.smooth_bump_phi], "track.bump_height": [m.bump_height],
                      "track.bump_width": [m.smooth_bump_width]}, "rigid+contact"),
    "ellipse": Perturbation(
        "ellipse", "E_ell", "elliptic ball, peak-to-peak radius variation delta_h",
        lambda p, m: {"ball.ellipticity": m.ellipticity}, "rigid+contact"),
    "elastic": Perturbation("elastic", "E_ela", "ball-track compliance k_bt", _elastic,
                            "contact"),
}


def perturbed(params: RigParams, key: str, study: StudySettings | None = None) -> RigParams:
    """``params`` with perturbation ``key`` (:data:`PERTURBATIONS`) at the study's magnitude."""
    if key not in PERTURBATIONS:
        raise KeyError(f"unknown perturbation {key!r}; known: {sorted(PERTURBATIONS)}")
    m = (study or StudySettings()).perturbations
    return params.replace(**PERTURBATIONS[key].changes(params, m))


# -- bumps ----------------------------------------------------------------------------------


def contour_arc_to_phi(params: RigParams, phi0: float, length: float | FloatArray,
                       n: int = 4096) -> FloatArray:
    """Contour angle reached from phi0 after an arc length ``length`` [m] along the contour.

    Integrates ``|delta'(phi)| = sqrt(rho^2 + rho'^2)`` of the bump-free contour (trapezoid
    on n points per turn) and inverts it by interpolation; negative lengths go backwards.
    """
    curve = OffsetCurve.from_params(params)
    phis = phi0 + np.linspace(-2.0 * np.pi, 2.0 * np.pi, 2 * n + 1)
    c = curve.arrays

    r0, r1 = contour_kernel(phis, c.rho0, c.orders, c.ccos, c.csin, c.bump_phi, c.bump_h,
                            c.bump_w)[:2]
    speed = np.sqrt(r0 * r0 + r1 * r1)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(phis))])
    s -= s[n]
    return np.interp(np.asarray(length, float), s, phis)


def bump_row(params: RigParams, phi_start: float, count: int, length: float, height: float,
             width: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A regular row of ``count`` equal bumps over ``length`` [m] of contour from phi_start.

    Heights [m]; ``width`` is the Gaussian standard deviation along the contour [m],
    converted to angle at each bump. Returns ``(phi, height, width)`` arrays in the units
    of ``track.asperity_*`` ([rad], [m], [rad]).
    """
    if count < 1:
        raise ValueError("count must be >= 1")
    s = (np.arange(count) + 0.5) * length / count
    phi = contour_arc_to_phi(params, phi_start, s)
    dphi = contour_arc_to_phi(params, phi_start, s + width) - phi
    return phi, np.full(count, float(height)), np.abs(dphi)


def rough_track(params: RigParams, rng: np.random.Generator, count: int,
                phi_range: tuple[float, float] = (0.0, 2.0 * np.pi),
                height: tuple[float, float] = (1e-4, 5e-4),
                width: tuple[float, float] = (5e-5, 2e-4)
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Draw a rough surface: ``count`` asperities with seeded random positions and sizes.

    Positions uniform in ``phi_range`` [rad] (sorted), heights uniform in ``height`` [m],
    widths (Gaussian standard deviation along the contour) uniform in ``width`` [m],
    converted to angle. The same generator state gives the same surface.

    Returns
    -------
    phi, h, w : ndarray
        ``track.asperity_*`` arrays ([rad], [m], [rad]).
    """
    if count < 0:
        raise ValueError("count must be >= 0")
    phi = np.sort(rng.uniform(phi_range[0], phi_range[1], count))
    h = rng.uniform(height[0], height[1], count)
    w_m = rng.uniform(width[0], width[1], count)
    w = np.empty(count)
    for i in range(count):
        w[i] = abs(float(contour_arc_to_phi(params, float(phi[i]), w_m[i])) - phi[i])
    return phi, h, w


def with_asperities(params: RigParams, phi: FloatArray, height: FloatArray, width: FloatArray,
                    append: bool = True, edge: int | FloatArray = 0) -> RigParams:
    """``params`` with the given sharp bumps in ``track.asperity_*`` (added or replacing).

    ``edge``: the plate edge of the new bumps (0 both, 1 front, 2 back; one value or one per
    bump), into ``track.asperity_edge``.
    """
    t = params.track
    n = len(phi)
    new_edge = [int(v) for v in np.broadcast_to(np.asarray(edge, int), (n,))]
    ph = [*t.asperity_phi, *phi] if append else list(phi)
    hh = [*t.asperity_height, *height] if append else list(height)
    ww = [*t.asperity_width, *width] if append else list(width)
    ee = [*t.asperity_edges(), *new_edge] if append else new_edge
    return params.replace(**{"track.asperity_phi": [float(v) for v in ph],
                             "track.asperity_height": [float(v) for v in hh],
                             "track.asperity_width": [float(v) for v in ww],
                             "track.asperity_edge": ee if any(ee) else []})


def write_params(params: RigParams, path: str | Path, header: str = "") -> Path:
    """Write ``params`` as a ROS 2 parameter file (loadable by ``load_params``)."""
    p = Path(path)
    p.write_text(params_to_ros_yaml(params, header=header))
    return p
