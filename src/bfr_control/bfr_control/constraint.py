"""Virtual holonomic constraint ``theta = Theta(phi)`` of the Butterfly robot.

The controller makes the frame angle a function of the contact angle (Shiriaev, Perram,
Canudas-de-Wit, IEEE TAC 2005; for the Butterfly robot Surov, Shiriaev, Freidovich, Gusev,
Paramonov, ICRA 2015). The published family sets the world inclination of the frame's
tangent at the contact point to ``atan(c sin 2 phi)``, a tilt of at most atan(c) (under two
degrees for c = 0.03) that keeps the ball near a local top of the track and pushes it on.

Conventions (DEVELOPERS.md): the contour is ``delta(phi) = rho(phi) [sin phi, cos phi]`` in
frame coordinates and world = Rot(theta) frame. The unit tangent ``t(phi) = delta'/|delta'|``
(direction of increasing phi, i.e. of the ball's motion) has the frame-coordinate angle
``alpha_t(phi)`` (from +x, counter-clockwise): ``alpha_t(0) = 0`` and, since phi runs
clockwise, ``alpha_t`` decreases by 2 pi per turn. Frenet for this orientation gives
``t' = -K n`` (bfr_model.geometry), so

    alpha_t' = -K,    alpha_t'' = -K',    K = kappa |delta'|,

and K' follows exactly from the offset curve's third derivative,
``p''' = (lam'' - lam K^2) t - (2 lam' K + lam K') n``, i.e.
``K' = -(p'''.n + 2 lam' K) / lam``. The world inclination of the tangent is
``theta + alpha_t(phi)``; the constraint

    Theta(phi) = atan(c sin 2 phi) - alpha_t(phi)
                 + sum_k (a_k cos 2 k phi + b_k sin 2 k phi)               (optional terms)

    Theta'  = 2 c cos 2 phi / (1 + c^2 sin^2 2 phi) + K + ...
    Theta'' = -4 c sin 2 phi (1 + c^2 sin^2 2 phi + 2 c^2 cos^2 2 phi)
              / (1 + c^2 sin^2 2 phi)^2 + K' + ...

satisfies ``Theta(phi + P) = Theta(phi) + P`` with P = pi for a point-symmetric frame (the
rig's: only even harmonics, no bumps) and P = 2 pi otherwise.

Sign of c: in these conventions the rig's logs (``../data/ntnu-rig``; frame angle minus ball
angle, and the speed profile with its dip just after the waist) fit c > 0; c = +0.03 is the
default (see docs/notes/issue-4.md). With c > 0 the ball climbs a tilt of up to atan(c) after
passing the waist top and is pushed downhill before the next one.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from bfr_model.dynamics import RigidModel
from bfr_model.geometry import offset_kernel
from bfr_model.param_file import check, finite, integer
from numpy.typing import ArrayLike, NDArray

__all__ = ["ConstraintSpec", "VirtualConstraint", "contour_period"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConstraintSpec:
    """Parameters of the constraint family.

    Attributes
    ----------
    c : float
        Tangent-inclination amplitude [-]: world inclination ``atan(c sin 2 phi)``.
    fourier_orders : tuple of int
        Orders k >= 1 of optional extra terms ``a_k cos 2 k phi + b_k sin 2 k phi`` [-].
    fourier_cos, fourier_sin : tuple of float
        a_k, b_k [rad].
    """

    c: float = 0.03
    fourier_orders: tuple[int, ...] = ()
    fourier_cos: tuple[float, ...] = ()
    fourier_sin: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        finite("constraint.c", self.c)
        n = len(self.fourier_orders)
        check(len(self.fourier_cos) == n and len(self.fourier_sin) == n, "constraint.fourier_*",
              "fourier_orders, fourier_cos and fourier_sin must have equal lengths")
        for k in self.fourier_orders:
            integer("constraint.fourier_orders", k, minimum=1)
        for v in (*self.fourier_cos, *self.fourier_sin):
            finite("constraint.fourier_cos/sin", v)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ConstraintSpec:
        """Build from the ``constraint`` group of controller.yaml (zero terms dropped)."""
        orders = [int(k) for k in d.get("fourier_orders", ())]
        fc = [float(v) for v in d.get("fourier_cos", ())]
        fs = [float(v) for v in d.get("fourier_sin", ())]
        if len(orders) == len(fc) == len(fs):
            keep = [i for i in range(len(orders)) if fc[i] != 0.0 or fs[i] != 0.0]
            orders, fc, fs = ([orders[i] for i in keep], [fc[i] for i in keep],
                              [fs[i] for i in keep])
        unknown = set(d) - {"c", "fourier_orders", "fourier_cos", "fourier_sin"}
        if unknown:
            raise ValueError(f"constraint: unknown entries {sorted(unknown)}")
        return cls(c=float(d.get("c", cls.c)), fourier_orders=tuple(orders),
                   fourier_cos=tuple(fc), fourier_sin=tuple(fs))

    def to_json(self) -> str:
        """Canonical JSON (cache keys)."""
        return json.dumps(asdict(self), sort_keys=True)


def contour_period(model: RigidModel) -> float:
    """Symmetry period P of the model's track: pi if point-symmetric, else 2 pi [rad].

    ``rho(phi + pi) = rho(phi)`` holds when every harmonic with a non-zero amplitude has an
    even order and there is no bump.
    """
    a = model.curve.arrays
    odd = [k for k, cc, ss in zip(a.orders, a.ccos, a.csin, strict=True)
           if (cc != 0.0 or ss != 0.0) and round(k) % 2 == 1]
    bumps = bool(np.any(np.asarray(a.bump_h) != 0.0))
    return 2.0 * math.pi if odd or bumps else math.pi


@dataclass
class VirtualConstraint:
    """``Theta(phi)`` and its derivatives on one model's track (module docstring).

    Parameters
    ----------
    model : RigidModel
        The controller's (nominal) model: only its geometry is used here.
    spec : ConstraintSpec
        The member of the family.
    """

    model: RigidModel
    spec: ConstraintSpec = field(default_factory=ConstraintSpec)

    def __post_init__(self) -> None:
        self.period = contour_period(self.model)
        self._orders = 2.0 * np.asarray(self.spec.fourier_orders, float)
        self._fc = np.asarray(self.spec.fourier_cos, float)
        self._fs = np.asarray(self.spec.fourier_sin, float)

    def tangent_angle(self, phi: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(alpha_t, alpha_t', alpha_t'')`` of the contour's unit tangent [rad, -, 1/rad].

        alpha_t is unwrapped about ``-phi`` (the tangent of a circle), which is exact as long
        as the tangent stays within 90 degrees of the circle's, true of any star-shaped
        contour.
        """
        phi = np.asarray(phi, float)
        g = offset_kernel(phi, *self.model.geom_args)
        p3x, p3y, nx, ny, lam, lam1, K = g[6], g[7], g[8], g[9], g[10], g[11], g[12]
        tx, ty = ny, -nx
        at = -phi + np.mod(np.arctan2(ty, tx) + phi + np.pi, 2.0 * np.pi) - np.pi
        K1 = -(p3x * nx + p3y * ny + 2.0 * lam1 * K) / lam
        return at, -K, -K1

    def evaluate(self, phi: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(Theta, Theta', Theta'')`` at phi [rad, -, 1/rad], exact (module docstring)."""
        phi = np.asarray(phi, float)
        c = self.spec.c
        s2 = np.sin(2.0 * phi)
        c2 = np.cos(2.0 * phi)
        den = 1.0 + c * c * s2 * s2
        f0 = np.arctan(c * s2)
        f1 = 2.0 * c * c2 / den
        f2 = -4.0 * c * s2 * (1.0 + c * c * s2 * s2 + 2.0 * c * c * c2 * c2) / (den * den)
        at, at1, at2 = self.tangent_angle(phi)
        th0 = f0 - at
        th1 = f1 - at1
        th2 = f2 - at2
        for k, a, b in zip(self._orders, self._fc, self._fs, strict=True):
            ck = np.cos(k * phi)
            sk = np.sin(k * phi)
            th0 = th0 + a * ck + b * sk
            th1 = th1 + k * (-a * sk + b * ck)
            th2 = th2 - k * k * (a * ck + b * sk)
        return th0, th1, th2

    def __call__(self, phi: ArrayLike) -> FloatArray:
        """Theta(phi) [rad]."""
        return self.evaluate(phi)[0]
