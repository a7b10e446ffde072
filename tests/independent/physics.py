"""Planar dynamics of an independent Butterfly rig (written apart from bfr; numpy only).

This is "another rig of the same design": its model is derived here from first principles
and shares no code with bfr. It differs from bfr's model in structure on purpose.

Conventions of this rig (written once; converted at the edges)
-------------------------------------------------------------
* World: origin on the frame's axis, x right, y up, z towards the camera; gravity in the
  frame's plane is ``-g cos(eps) y`` (``eps`` the shaft tilt). SI units, radians.
* ``theta`` [rad]: frame angle, counter-clockwise positive, accumulating over turns.
  World = Rot(theta) * frame coordinates.
* Contour of the plates, frame coordinates, ``phi`` clockwise from the frame's +y axis::

      delta(phi) = rho(phi) [sin phi, cos phi]
      rho(phi)   = a - b cos 2phi + sum_{k=1..8} (c_k cos k phi + s_k sin k phi)
                   + sum_j h_j exp(-wrap(phi - phi_j)^2 / (2 (w_j / a)^2))

  (Gaussian bumps of height ``h_j`` [m] and standard deviation ``w_j`` [m] along the track).
* Ball centre on the exact offset curve ``p = delta + R n`` (``n`` outward unit normal,
  ``R = sqrt(R_b^2 - d_f^2 / 4) + rolling_radius_delta``), written in **polar form in its
  own polar angle** ``psi`` (clockwise from the frame's +y axis)::

      p(psi) = r(psi) [sin psi, cos psi]

  ``psi`` is the generalised coordinate of the ball. It is exactly the NTNU logs'
  ``phi = theta + atan2(x, y)`` (the ball-centre angle), so the state of this rig is
  ``(theta, psi, theta_dot, psi_dot)``; bfr's model instead uses the contact-point angle.
  ``r(psi)`` is tabulated by inverting ``psi(phi)`` with Newton's method on a uniform grid,
  differentiated spectrally (FFT) and interpolated by C2 quintic Hermite pieces, so the
  equations below are exactly the Euler-Lagrange equations of the interpolated curve (the
  energy test holds to integrator accuracy).

Model structure
---------------
Hybrid, three modes for the ball (plus NONE, no ball on the rig):

* ``ROLLING``: bilateral rolling constraint, two degrees of freedom ``(theta, psi)``; the
  normal force is computed from the accelerations; when it would pull (``N < 0``) the ball
  lifts off.
* ``FLIGHT``: the ball is a free body (x, y, spin) under gravity; the frame turns alone. When
  the ball centre crosses the offset curve again the impact is perfectly plastic with
  sticking (generalised-momentum projection onto the rolling constraint).
* ``GONE``: the ball fell below the frame (out of the camera's view for good).

The frame joint has Coulomb friction that may differ by direction, with stick (Karnopp: the
frame sticks when its speed crosses zero and breaks away when the torque needed to hold it
exceeds the Coulomb level), viscous friction, a torque offset, a motor torque gain and an
imbalance ``m_f e``. Rolling resistance is a couple ``mu_rol |N| R`` opposing the ball's
rolling relative to the frame (its sign regularised by ``tanh(psi_dot / 0.01 rad/s)``).
Slip between ball and frame is not modelled (rolling whenever in contact).

Lagrangian (derived here; ``m`` ball mass, ``J_b`` ball inertia, ``J_f`` frame inertia)
-------------------------------------------------------------------------------------
With ``e = [sin psi, cos psi]``, ``f = de/dpsi = [cos psi, -sin psi]``, ``p = r e``,
``p' = r' e + r f``, ``l = |p'| = sqrt(r^2 + r'^2)`` (arc length of the ball-centre curve per
radian of ``psi``) and ``J`` the +90 degree rotation:

* ball centre velocity ``Rot(theta) (theta_dot J p + psi_dot p')``; since
  ``J p . p' = p x p' = -r^2``:
  ``|v|^2 = r^2 theta_dot^2 - 2 r^2 theta_dot psi_dot + l^2 psi_dot^2``;
* rolling without slip (contact point of the ball moves with the frame), ``s`` the arc
  length of the ball-centre curve, clockwise: ``omega_b = theta_dot - s_dot / R
  = theta_dot - l psi_dot / R`` (on a fixed circle of radius ``rc`` one lap gives
  ``(rc + R) / R`` turns);
* ``T = 1/2 J_f theta_dot^2 + 1/2 m |v|^2 + 1/2 J_b omega_b^2``,
  ``V = m g r cos(psi - theta) + m_f e g cos(theta - theta_e)`` (ball height
  ``r cos(psi - theta)``).

So ``M = [[J_f + m r^2 + J_b, -(m r^2 + J_b l / R)], [., l^2 (m + J_b / R^2)]]`` and::

    M11 th'' + M12 ps'' + M11' th' ps' + M12' ps'^2 + m g r sin(psi - theta)
        = k_u u + tau_0 + m_f e g sin(theta - theta_e) + tau_fric
    M12 th'' + M22 ps'' - 1/2 M11' th'^2 + 1/2 M22' ps'^2 + m g (r' cos - r sin)(psi - theta)
        = -mu_rol l |N| tanh(ps' / eps_r)

with ``M11' = 2 m r r'``, ``l' = r' (r + r'') / l``, ``M12' = -(2 m r r' + J_b l' / R)``,
``M22' = 2 l l' (m + J_b / R^2)``. The normal force (ball acceleration minus gravity, along
``n = (r e - r' f) / l``) is::

    N = m / l [ps'^2 (r r'' - r^2 - 2 r'^2) + 2 l^2 th' ps' - r^2 th'^2
               + g (r cos(psi - theta) + r' sin(psi - theta)) + r r' th'']

(on a fixed circle at the top: ``N = m (g - r ps'^2)``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np

#: Number of harmonics of the contour beyond cos 2phi (k = 1..8).
N_HARMONICS = 8
#: Regularisation speed of the rolling-resistance sign [rad/s].
ROLL_SIGN_SPEED = 1e-2
#: The ball counts as GONE when its centre falls this far below the axis [m].
GONE_DEPTH = 0.3

ROLLING, FLIGHT, GONE, NONE = "rolling", "flight", "gone", "none"


@dataclass(frozen=True, kw_only=True)
class Bump:
    """A Gaussian bump on the contour radius.

    Parameters
    ----------
    angle : float
        Position, contour angle ``phi`` clockwise from the frame's +y axis [rad].
    height : float
        Radial height, outward positive [m].
    width : float
        Standard deviation along the track [m].
    """

    angle: float
    height: float
    width: float

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.angle, self.height, self.width)):
            raise ValueError(f"bump values must be finite: {self}")
        if self.width <= 0.0:
            raise ValueError(f"bump width must be > 0 m, got {self.width}")


@dataclass(frozen=True, kw_only=True)
class RigParams:
    """Physical parameters and effects of the independent rig (nominal: seed Table 6.1).

    Every effect is zero (or one, for scales and gains) on the nominal rig.

    Parameters
    ----------
    ball_mass : float
        Ball mass ``m`` [kg].
    ball_radius : float
        Ball radius ``R_b`` [m].
    ball_inertia_factor : float
        ``J_b = factor m R_b^2`` [-] (2/3: thin hollow shell).
    plate_gap : float
        Distance between the two plates ``d_f`` [m].
    rolling_radius_delta : float
        Added to ``sqrt(R_b^2 - d_f^2 / 4)`` [m].
    frame_inertia : float
        Frame and rotor inertia ``J_f`` [kg m^2].
    frame_inertia_scale : float
        Multiplies ``frame_inertia`` [-].
    contour_a : float
        Contour mean radius ``a`` [m].
    contour_radius_delta : float
        Added to ``a`` [m].
    contour_b : float
        ``cos 2phi`` amplitude ``b`` [m].
    harmonics_cos, harmonics_sin : tuple of float
        ``c_k``, ``s_k`` for k = 1..8 [m] (contour angle convention above).
    bumps : tuple of Bump
        Gaussian track bumps.
    coulomb_pos, coulomb_neg : float
        Joint Coulomb friction level for ``theta_dot > 0`` and ``< 0`` [N m] (>= 0).
    viscous : float
        Joint viscous friction [N m s/rad].
    torque_offset : float
        Constant torque added to the motor's [N m].
    motor_gain : float
        Applied torque per commanded torque [-].
    imbalance : float
        Frame imbalance ``m_f e`` [kg m].
    imbalance_angle : float
        ``theta_e`` of the imbalance torque ``m_f e g sin(theta - theta_e)`` [rad].
    rolling_resistance : float
        ``mu_rol`` [-]: resisting couple ``mu_rol N R``.
    shaft_tilt : float
        ``eps`` [rad]: in-plane gravity ``g cos(eps)``.
    gravity : float
        ``g`` [m/s^2].
    """

    ball_mass: float = 3.00e-3
    ball_radius: float = 16.6e-3
    ball_inertia_factor: float = 2.0 / 3.0
    plate_gap: float = 25.5e-3
    rolling_radius_delta: float = 0.0
    frame_inertia: float = 1.58e-3
    frame_inertia_scale: float = 1.0
    contour_a: float = 0.1095
    contour_radius_delta: float = 0.0
    contour_b: float = 0.04
    harmonics_cos: tuple[float, ...] = (0.0,) * N_HARMONICS
    harmonics_sin: tuple[float, ...] = (0.0,) * N_HARMONICS
    bumps: tuple[Bump, ...] = ()
    coulomb_pos: float = 0.0
    coulomb_neg: float = 0.0
    viscous: float = 0.0
    torque_offset: float = 0.0
    motor_gain: float = 1.0
    imbalance: float = 0.0
    imbalance_angle: float = 0.0
    rolling_resistance: float = 0.0
    shaft_tilt: float = 0.0
    gravity: float = 9.81

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float | int) and not math.isfinite(value):
                raise ValueError(f"{f.name} must be finite, got {value}")
        for name in ("ball_mass", "ball_radius", "plate_gap", "frame_inertia",
                     "frame_inertia_scale", "contour_a", "ball_inertia_factor", "motor_gain"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("coulomb_pos", "coulomb_neg", "viscous", "rolling_resistance",
                     "imbalance", "contour_b"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("harmonics_cos", "harmonics_sin"):
            value = getattr(self, name)
            if len(value) != N_HARMONICS or not all(math.isfinite(v) for v in value):
                raise ValueError(f"{name} needs {N_HARMONICS} finite values [m], got {value}")
        if self.plate_gap >= 2.0 * self.ball_radius:
            raise ValueError("plate_gap must be < 2 ball_radius (the ball falls through)")
        if self.rolling_radius <= 0.0:
            raise ValueError(f"rolling radius must be > 0 m, got {self.rolling_radius}")
        if abs(self.shaft_tilt) >= math.pi / 2:
            raise ValueError(f"shaft_tilt must be within +-pi/2 rad, got {self.shaft_tilt}")
        if self.a_eff - self.contour_b - sum(map(abs, self.harmonics_cos)) \
                - sum(map(abs, self.harmonics_sin)) <= 0.0:
            raise ValueError("contour radius must stay > 0 (a too small for b and harmonics)")

    @property
    def rolling_radius(self) -> float:
        """``R = sqrt(R_b^2 - d_f^2 / 4) + rolling_radius_delta`` [m]."""
        return math.sqrt(self.ball_radius**2 - self.plate_gap**2 / 4.0) \
            + self.rolling_radius_delta

    @property
    def ball_inertia(self) -> float:
        """``J_b = factor m R_b^2`` [kg m^2]."""
        return self.ball_inertia_factor * self.ball_mass * self.ball_radius**2

    @property
    def frame_inertia_total(self) -> float:
        """``J_f * frame_inertia_scale`` [kg m^2]."""
        return self.frame_inertia * self.frame_inertia_scale

    @property
    def a_eff(self) -> float:
        """Contour mean radius with its delta [m]."""
        return self.contour_a + self.contour_radius_delta

    @property
    def g_plane(self) -> float:
        """In-plane gravity ``g cos(eps)`` [m/s^2]."""
        return self.gravity * math.cos(self.shaft_tilt)

    def lossless(self) -> RigParams:
        """The same rig without friction, offset, rolling resistance (for energy checks)."""
        return replace(self, coulomb_pos=0.0, coulomb_neg=0.0, viscous=0.0,
                       torque_offset=0.0, rolling_resistance=0.0)


def contour_radius(params: RigParams, phi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Contour radius and its first two derivatives.

    ``rho = a - b cos 2phi + sum (c_k cos k phi + s_k sin k phi) + bumps`` (module docstring).

    Parameters
    ----------
    params : RigParams
        The rig.
    phi : numpy.ndarray
        Contour angles, clockwise from the frame's +y axis [rad].

    Returns
    -------
    tuple of numpy.ndarray
        ``rho`` [m], ``rho'`` [m/rad], ``rho''`` [m/rad^2].
    """
    phi = np.asarray(phi, dtype=float)
    b = params.contour_b
    rho = params.a_eff - b * np.cos(2 * phi)
    d1 = 2 * b * np.sin(2 * phi)
    d2 = 4 * b * np.cos(2 * phi)
    for k in range(1, N_HARMONICS + 1):
        c, s = params.harmonics_cos[k - 1], params.harmonics_sin[k - 1]
        if c == 0.0 and s == 0.0:
            continue
        ck, sk = np.cos(k * phi), np.sin(k * phi)
        rho = rho + c * ck + s * sk
        d1 = d1 + k * (-c * sk + s * ck)
        d2 = d2 - k * k * (c * ck + s * sk)
    for bump in params.bumps:
        sigma = bump.width / params.a_eff
        u = np.angle(np.exp(1j * (phi - bump.angle)))
        gauss = bump.height * np.exp(-0.5 * (u / sigma) ** 2)
        rho = rho + gauss
        d1 = d1 - gauss * u / sigma**2
        d2 = d2 + gauss * (u**2 / sigma**4 - 1.0 / sigma**2)
    return rho, d1, d2


def offset_curve(params: RigParams, phi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Contour point, ball-centre point and the offset's regularity factor at contour angles.

    ``delta = rho e``, ``delta' = rho' e + rho f``, ``delta'' = rho'' e + 2 rho' f - rho e``,
    ``n = J delta' / |delta'|``, ``p = delta + R n``; curvature (positive where convex)
    ``kappa = (delta'' x delta') / |delta'|^3`` and ``p' = (1 + R kappa) delta'``.

    Parameters
    ----------
    params : RigParams
        The rig.
    phi : numpy.ndarray
        Contour angles [rad].

    Returns
    -------
    tuple of numpy.ndarray
        ``delta`` (n, 2) [m], ``p`` (n, 2) [m], ``p'`` (n, 2) [m/rad], ``1 + R kappa`` [-].
    """
    phi = np.asarray(phi, dtype=float)
    rho, r1, r2 = contour_radius(params, phi)
    e = np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    f = np.stack([np.cos(phi), -np.sin(phi)], axis=-1)
    d = rho[:, None] * e
    d1 = r1[:, None] * e + rho[:, None] * f
    d2 = r2[:, None] * e + 2 * r1[:, None] * f - rho[:, None] * e
    speed = np.hypot(d1[:, 0], d1[:, 1])
    n = np.stack([-d1[:, 1], d1[:, 0]], axis=-1) / speed[:, None]
    kappa = (d2[:, 0] * d1[:, 1] - d2[:, 1] * d1[:, 0]) / speed**3
    factor = 1.0 + params.rolling_radius * kappa
    p = d + params.rolling_radius * n
    return d, p, factor[:, None] * d1, factor


@dataclass(frozen=True)
class PeriodicTable:
    """A smooth 2 pi-periodic function as C2 quintic Hermite pieces on a uniform grid.

    From samples ``f_i = f(2 pi i / n)``: ``f'`` and ``f''`` by FFT (spectral derivatives);
    each interval's quintic matches ``f, f', f''`` at both ends; in the local variable
    ``t in [0, 1]`` with ``A = f1 - f0 - d0 - s0 / 2``, ``B = d1 - d0 - s0``, ``C = s1 - s0``
    (``d = h f'``, ``s = h^2 f''``) its coefficients are ``f0, d0, s0 / 2,
    10A - 4B + C/2, -15A + 7B - C, 6A - 3B + C/2``. The interpolant's own derivatives are
    returned, so equations of motion built on it are exactly consistent.

    Parameters
    ----------
    n : int
        Number of uniform intervals over ``[0, 2 pi)``.
    coeffs : numpy.ndarray
        (n, 6) polynomial coefficients per interval.
    """

    n: int
    coeffs: np.ndarray = field(repr=False)
    _rows: tuple = field(repr=False, compare=False, default=())

    @staticmethod
    def from_samples(values: np.ndarray) -> PeriodicTable:
        """Build the table from ``n`` uniform samples over one period.

        Parameters
        ----------
        values : numpy.ndarray
            ``f(2 pi i / n)``, i = 0..n-1.

        Returns
        -------
        PeriodicTable
            The interpolant.
        """
        f = np.asarray(values, dtype=float)
        n = len(f)
        k = np.fft.rfftfreq(n, d=1.0 / n)
        spec = np.fft.rfft(f)
        d1_spec = 1j * k * spec
        if n % 2 == 0:
            d1_spec[-1] = 0.0
        f1 = np.fft.irfft(d1_spec, n)
        f2 = np.fft.irfft(-(k**2) * spec, n)
        h = 2 * np.pi / n
        y0, y1 = f, np.roll(f, -1)
        d0, dd1 = f1 * h, np.roll(f1, -1) * h
        s0, s1 = f2 * h * h, np.roll(f2, -1) * h * h
        A = y1 - y0 - d0 - s0 / 2
        B = dd1 - d0 - s0
        C = s1 - s0
        coeffs = np.stack([y0, d0, s0 / 2, 10 * A - 4 * B + C / 2, -15 * A + 7 * B - C,
                           6 * A - 3 * B + C / 2], axis=1)
        return PeriodicTable(n=n, coeffs=coeffs, _rows=tuple(map(tuple, coeffs.tolist())))

    def eval(self, x: float) -> tuple[float, float, float]:
        """``f(x)``, ``f'(x)``, ``f''(x)`` at one point (scalar fast path; any period)."""
        u = x * self.n / (2 * math.pi)
        i = math.floor(u)
        t = u - i
        c0, c1, c2, c3, c4, c5 = self._rows[i % self.n]
        inv_h = self.n / (2 * math.pi)
        f = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
        f1 = c1 + t * (2 * c2 + t * (3 * c3 + t * (4 * c4 + t * 5 * c5)))
        f2 = 2 * c2 + t * (6 * c3 + t * (12 * c4 + t * 20 * c5))
        return f, f1 * inv_h, f2 * inv_h * inv_h

    def eval_array(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """Vectorised :meth:`eval`."""
        u = np.asarray(x, dtype=float) * self.n / (2 * np.pi)
        i = np.floor(u)
        t = u - i
        c = self.coeffs[i.astype(np.int64) % self.n]
        inv_h = self.n / (2 * np.pi)
        f = c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * (c[..., 3] + t * (
            c[..., 4] + t * c[..., 5]))))
        f1 = c[..., 1] + t * (2 * c[..., 2] + t * (3 * c[..., 3] + t * (4 * c[..., 4]
                                                                      + t * 5 * c[..., 5])))
        f2 = 2 * c[..., 2] + t * (6 * c[..., 3] + t * (12 * c[..., 4] + t * 20 * c[..., 5]))
        return f, f1 * inv_h, f2 * inv_h**2


@dataclass(frozen=True)
class Track:
    """The ball-centre curve ``r(psi)`` of one rig (a :class:`PeriodicTable`).

    Build it with :meth:`Track.build`. ``eval`` is the scalar fast path used by the
    integrator; ``eval_array`` the vectorised one.

    Parameters
    ----------
    table : PeriodicTable
        ``r(psi)`` [m].
    """

    table: PeriodicTable

    @staticmethod
    def build(params: RigParams, n: int = 4096) -> Track:
        """Tabulate ``r(psi)`` for a rig.

        ``psi(phi) = atan2(p_x, p_y)`` is inverted on the uniform grid ``psi_i = 2 pi i / n``
        by Newton's method (``dpsi/dphi = -(p x p') / |p|^2``), from a dense-table guess;
        then :meth:`PeriodicTable.from_samples`.

        Parameters
        ----------
        params : RigParams
            The rig.
        n : int
            Intervals (a power of two; 4096 resolves bumps of a few mm).

        Returns
        -------
        Track
            The table.

        Raises
        ------
        ValueError
            If the offset curve is not regular (a concave part tighter than ``R``, or a
            bump too narrow for the ball) or not star-shaped about the axis.
        """
        dense = np.linspace(0.0, 2 * np.pi, 16 * n, endpoint=False)
        _, p, dp, factor = offset_curve(params, dense)
        if factor.min() <= 0.05:
            raise ValueError(
                "ball-centre curve not regular: the contour has a concave part tighter than "
                f"the rolling radius (min 1 + R kappa = {factor.min():.3f}); "
                "widen or lower the bumps")
        dpsi = -(p[:, 0] * dp[:, 1] - p[:, 1] * dp[:, 0]) / np.sum(p * p, axis=1)
        if dpsi.min() <= 0.0:
            raise ValueError("ball-centre curve is not star-shaped about the axis")
        psi_dense = np.unwrap(np.arctan2(p[:, 0], p[:, 1]))
        psi_dense -= 2 * np.pi * np.floor(psi_dense[0] / (2 * np.pi) + 0.5)
        target = 2 * np.pi * np.arange(n) / n
        phi = np.interp(target, np.r_[psi_dense, psi_dense[0] + 2 * np.pi],
                        np.r_[dense, 2 * np.pi])
        for _ in range(8):
            _, pp, dpp, _ = offset_curve(params, phi)
            err = np.angle(np.exp(1j * (np.arctan2(pp[:, 0], pp[:, 1]) - target)))
            slope = -(pp[:, 0] * dpp[:, 1] - pp[:, 1] * dpp[:, 0]) / np.sum(pp * pp, axis=1)
            phi = phi - err / slope
            if np.max(np.abs(err)) < 1e-14:
                break
        _, pp, _, _ = offset_curve(params, phi)
        return Track(table=PeriodicTable.from_samples(np.hypot(pp[:, 0], pp[:, 1])))

    def eval(self, psi: float) -> tuple[float, float, float]:
        """``r(psi)`` [m], ``r'(psi)`` [m/rad], ``r''(psi)`` [m/rad^2] at one angle [rad]."""
        return self.table.eval(psi)

    def eval_array(self, psi: np.ndarray) -> tuple[np.ndarray, ...]:
        """Vectorised :meth:`eval`."""
        return self.table.eval_array(psi)

    def point(self, psi: float) -> tuple[float, float]:
        """Ball-centre point ``p(psi) = r [sin psi, cos psi]`` in frame coordinates [m]."""
        r = self.table.eval(psi)[0]
        return r * math.sin(psi), r * math.cos(psi)

    def tangent_angle(self, psi: float) -> tuple[float, float, float]:
        """World-free angle of the clockwise tangent ``p'`` and its first two derivatives.

        ``p' = r' e + r f``; its angle from the frame's +x axis (counter-clockwise) is
        ``alpha = atan2(r' cos psi - r sin psi, r' sin psi + r cos psi) = -psi + atan2(r', r)``
        (so ``alpha = -psi`` on a circle); ``beta = atan2(r', r)`` has
        ``beta' = (r r'' - r'^2) / (r^2 + r'^2)`` and
        the second derivative comes from a central difference of ``beta'``.

        Parameters
        ----------
        psi : float
            Ball-centre angle [rad].

        Returns
        -------
        tuple of float
            ``alpha`` [rad] (continuous in psi), ``alpha'`` [-], ``alpha''`` [1/rad].
        """
        r, r1, r2 = self.table.eval(psi)
        beta = math.atan2(r1, r)
        d_beta = (r * r2 - r1 * r1) / (r * r + r1 * r1)
        eps = 1e-4
        ra, ra1, ra2 = self.table.eval(psi + eps)
        rb, rb1, rb2 = self.table.eval(psi - eps)
        dd_beta = ((ra * ra2 - ra1 * ra1) / (ra * ra + ra1 * ra1)
                   - (rb * rb2 - rb1 * rb1) / (rb * rb + rb1 * rb1)) / (2 * eps)
        return -psi + beta, -1.0 + d_beta, dd_beta


@dataclass(frozen=True, kw_only=True)
class PlantState:
    """One sample of the independent rig's true state.

    Parameters
    ----------
    t : float
        Simulated time [s].
    theta, theta_dot : float
        Frame angle [rad] and rate [rad/s].
    mode : str
        ``rolling``, ``flight``, ``gone`` or ``none``.
    ball_x, ball_y : float
        Ball centre in the world [m] (NaN when gone or none).
    ball_angle, ball_angle_dot : float
        Ball-centre angle clockwise from the frame's +y axis [rad] and its rate [rad/s]
        (NaN when gone or none).
    spin, spin_rate : float
        Ball rotation angle about +z [rad] and rate [rad/s] (NaN when gone or none).
    normal_force : float
        Contact normal force [N] (0 unless rolling).
    torque : float
        Torque the motor applies, ``k_u u + tau_0`` [N m].
    friction_torque : float
        Joint friction torque acting on the frame [N m].
    energy : float
        Kinetic plus potential energy of frame and ball [J].
    work_motor, work_friction, work_rolling, impact_loss : float
        Work of the motor, of the joint friction, of the rolling resistance, and energy
        lost in impacts, since the start [J].
    """

    t: float
    theta: float
    theta_dot: float
    mode: str
    ball_x: float
    ball_y: float
    ball_angle: float
    ball_angle_dot: float
    spin: float
    spin_rate: float
    normal_force: float
    torque: float
    friction_torque: float
    energy: float
    work_motor: float
    work_friction: float
    work_rolling: float
    impact_loss: float

    @property
    def in_contact(self) -> bool:
        """Whether the ball touches the frame."""
        return self.mode == ROLLING


class Plant:
    """The independent rig as a hybrid dynamical system, advanced by fixed RK4 steps.

    Parameters
    ----------
    params : RigParams
        The rig.
    ball : bool
        Whether a ball is on the frame.
    theta, theta_dot : float
        Initial frame angle [rad] and rate [rad/s].
    ball_angle, ball_angle_dot : float
        Initial ball-centre angle (clockwise from the frame's +y axis) [rad] and its rate
        [rad/s]; the ball starts rolling on the track.
    frame_locked : bool
        Brake the frame (it never moves; the ball rolls on a still frame).
    lift_off : bool
        Let the ball leave the track when the normal force would pull (False: a bilateral
        constraint, for analysis).
    dt : float
        Integration step [s]; :meth:`advance` splits its interval into such steps.
    track : Track, optional
        A prebuilt track of ``params`` (built when omitted).
    """

    def __init__(self, params: RigParams, *, ball: bool = True, theta: float = 0.0,
                 theta_dot: float = 0.0, ball_angle: float = 0.0,
                 ball_angle_dot: float = 0.0, frame_locked: bool = False,
                 lift_off: bool = True, dt: float = 5e-4, track: Track | None = None) -> None:
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt}")
        for name, v in (("theta", theta), ("theta_dot", theta_dot),
                        ("ball_angle", ball_angle), ("ball_angle_dot", ball_angle_dot)):
            if not math.isfinite(v):
                raise ValueError(f"initial {name} must be finite, got {v}")
        self.params = params
        self.track = track if track is not None else Track.build(params)
        self.dt = dt
        self.frame_locked = frame_locked
        self.lift_off = lift_off
        self.t = 0.0
        self.theta, self.theta_dot = float(theta), 0.0 if frame_locked else float(theta_dot)
        self.mode = ROLLING if ball else NONE
        self.psi, self.psi_dot = float(ball_angle), float(ball_angle_dot)
        self.spin = 0.0
        r, r1, _ = self.track.eval(self.psi)
        self.spin_rate = self.theta_dot - math.hypot(r, r1) * self.psi_dot / params.rolling_radius
        self.bx = self.by = self.bvx = self.bvy = 0.0
        self.direction = 0 if self.theta_dot == 0.0 else (1 if self.theta_dot > 0 else -1)
        self.stuck = frame_locked or self.theta_dot == 0.0
        self.w_motor = self.w_fric = self.w_roll = self.impact_loss = 0.0
        self.normal_force = 0.0
        self.u_applied = 0.0
        self.fric_torque = 0.0
        self._m = params.ball_mass
        self._Jb = params.ball_inertia
        self._Jf = params.frame_inertia_total
        self._R = params.rolling_radius
        self._g = params.g_plane
        if self.mode == ROLLING:
            self.normal_force = self._contact_rhs(self.theta, self.psi, self.theta_dot,
                                                  self.psi_dot, 0.0)[2]
            if self.normal_force < 0.0 and lift_off:
                self._lift_off()

    # ----------------------------------------------------------------- rolling mode
    def _contact_rhs(self, th: float, ps: float, thd: float, psd: float,
                     u_a: float) -> tuple[float, float, float, float, float, float]:
        """Accelerations in contact (module docstring equations).

        Returns ``(theta_ddot, psi_ddot, N, Q_psi, tau_fric, l)``; ``tau_fric`` is the joint
        friction (while stuck: the torque that holds the frame), ``l = |p'|``.
        """
        m, Jb, R, g = self._m, self._Jb, self._R, self._g
        P = self.params
        r, r1, r2 = self.track.eval(ps)
        ell = math.sqrt(r * r + r1 * r1)
        dell = r1 * (r + r2) / ell
        mu = m + Jb / (R * R)
        M11 = self._Jf + m * r * r + Jb
        M12 = -(m * r * r + Jb * ell / R)
        M22 = ell * ell * mu
        dM11 = 2 * m * r * r1
        dM12 = -(2 * m * r * r1 + Jb * dell / R)
        dM22 = 2 * ell * dell * mu
        s, c = math.sin(ps - th), math.cos(ps - th)
        tau_imb = P.imbalance * g * math.sin(th - P.imbalance_angle) if P.imbalance else 0.0
        h1 = dM11 * thd * psd + dM12 * psd * psd + m * g * r * s
        h2 = -0.5 * dM11 * thd * thd + 0.5 * dM22 * psd * psd + m * g * (r1 * c - r * s)
        n0 = (m / ell) * (psd * psd * (r * r2 - r * r - 2 * r1 * r1) + 2 * ell * ell * thd * psd
                          - r * r * thd * thd + g * (r * c + r1 * s))
        n_th = (m / ell) * r * r1
        roll = P.rolling_resistance * ell * math.tanh(psd / ROLL_SIGN_SPEED)
        if self.stuck:
            N = n0
            q = -roll * abs(N)
            psdd = (q - h2) / M22
            tau_f = M12 * psdd + h1 - u_a - tau_imb
            return 0.0, psdd, N, q, tau_f, ell
        tau_f = -(P.coulomb_pos if self.direction > 0 else P.coulomb_neg) * self.direction \
            - P.viscous * thd
        b1 = u_a + tau_imb + tau_f - h1
        q = 0.0
        det = M11 * M22 - M12 * M12
        for _ in range(2 if roll else 1):
            b2 = q - h2
            thdd = (b1 * M22 - M12 * b2) / det
            psdd = (M11 * b2 - M12 * b1) / det
            N = n0 + n_th * thdd
            q = -roll * abs(N)
        return thdd, psdd, N, q, tau_f, ell

    def _step_rolling(self, h: float) -> None:
        u_a = self.u_applied
        if self.stuck and not self.frame_locked:
            tau_need = self._contact_rhs(self.theta, self.psi, 0.0, self.psi_dot, u_a)[4]
            self._maybe_break_away(tau_need)

        R = self._R

        def f(y: tuple[float, ...]) -> tuple[float, ...]:
            th, ps, thd, psd = y[0], y[1], y[2], y[3]
            thdd, psdd, _, q, tau_f, ell = self._contact_rhs(th, ps, thd, psd, u_a)
            omega = thd - ell * psd / R
            return (thd, psd, thdd, psdd, omega, u_a * thd, tau_f * thd, q * psd)

        y0 = (self.theta, self.psi, self.theta_dot, self.psi_dot, self.spin,
              self.w_motor, self.w_fric, self.w_roll)
        y1 = _rk4(f, y0, h)
        self.theta, self.psi, self.theta_dot, self.psi_dot, self.spin = y1[:5]
        self.w_motor, self.w_fric, self.w_roll = y1[5:]
        self._stop_if_reversed()
        _, _, N, _, tau_f, ell = self._contact_rhs(self.theta, self.psi, self.theta_dot,
                                                   self.psi_dot, u_a)
        self.normal_force, self.fric_torque = N, tau_f
        self.spin_rate = self.theta_dot - ell * self.psi_dot / R
        if N < 0.0 and self.lift_off:
            self._lift_off()

    def rolling_accelerations(self, theta: float, psi: float, theta_dot: float,
                              psi_dot: float, torque: float) -> tuple[float, float, float]:
        """Accelerations and normal force in contact, the frame free to turn.

        For a model-based controller: joint friction, stick and the motor's gain and
        offset of this plant's parameters apply as they are (a lossless copy has none).

        Parameters
        ----------
        theta, psi : float
            Frame and ball-centre angles [rad].
        theta_dot, psi_dot : float
            Their rates [rad/s].
        torque : float
            Torque applied to the frame [N m].

        Returns
        -------
        tuple of float
            ``theta''`` [rad/s^2], ``psi''`` [rad/s^2], normal force [N].
        """
        stuck, direction = self.stuck, self.direction
        self.stuck = False
        self.direction = 1 if theta_dot >= 0.0 else -1
        try:
            thdd, psdd, N = self._contact_rhs(theta, psi, theta_dot, psi_dot, torque)[:3]
        finally:
            self.stuck, self.direction = stuck, direction
        return thdd, psdd, N

    # ------------------------------------------------------------------ frame joint
    def _maybe_break_away(self, tau_need: float) -> None:
        """Karnopp: leave stick when the holding torque exceeds the Coulomb level."""
        P = self.params
        if tau_need > P.coulomb_neg:
            self.stuck, self.direction = False, -1
        elif tau_need < -P.coulomb_pos:
            self.stuck, self.direction = False, 1

    def _stop_if_reversed(self) -> None:
        """Stick when the frame speed crossed zero within the step (friction stops it).

        The kinetic energy removed with the frame's speed is booked to the friction work.
        """
        P = self.params
        if self.frame_locked or self.stuck or (P.coulomb_pos == 0.0 and P.coulomb_neg == 0.0):
            return
        if self.theta_dot * self.direction > 0.0:
            return
        before = self.kinetic_energy()
        self.theta_dot = 0.0
        self.stuck = True
        self.w_fric += self.kinetic_energy() - before

    def _frame_rhs(self, th: float, thd: float, u_a: float) -> tuple[float, float]:
        """Frame alone (ball in flight, gone or none): ``J_f th'' = torques``."""
        P = self.params
        tau_imb = P.imbalance * self._g * math.sin(th - P.imbalance_angle) \
            if P.imbalance else 0.0
        if self.stuck:
            return 0.0, -(u_a + tau_imb)
        tau_f = -(P.coulomb_pos if self.direction > 0 else P.coulomb_neg) * self.direction \
            - P.viscous * thd
        return (u_a + tau_imb + tau_f) / self._Jf, tau_f

    def _step_frame(self, h: float) -> None:
        u_a = self.u_applied
        if self.stuck and not self.frame_locked:
            self._maybe_break_away(self._frame_rhs(self.theta, 0.0, u_a)[1])

        def f(y: tuple[float, ...]) -> tuple[float, ...]:
            thdd, tau_f = self._frame_rhs(y[0], y[1], u_a)
            return (y[1], thdd, u_a * y[1], tau_f * y[1])

        y1 = _rk4(f, (self.theta, self.theta_dot, self.w_motor, self.w_fric), h)
        self.theta, self.theta_dot, self.w_motor, self.w_fric = y1
        self._stop_if_reversed()
        self.fric_torque = self._frame_rhs(self.theta, self.theta_dot, u_a)[1]

    # ------------------------------------------------------------------- flight mode
    def _contact_map(self, th: float, ps: float) -> tuple[tuple[float, float, float, float],
                                                          tuple[float, float, float, float]]:
        """Columns of ``v = A q_dot``: ``v = (theta_dot, vx, vy, omega)``, q = (theta, psi)."""
        r, r1, _ = self.track.eval(ps)
        ell = math.hypot(r, r1)
        sp, cp, st, ct = math.sin(ps), math.cos(ps), math.sin(th), math.cos(th)
        px, py = r * sp, r * cp
        dpx, dpy = r1 * sp + r * cp, r1 * cp - r * sp
        jx, jy = -py, px
        col_th = (1.0, ct * jx - st * jy, st * jx + ct * jy, 1.0)
        col_ps = (0.0, ct * dpx - st * dpy, st * dpx + ct * dpy, -ell / self._R)
        return col_th, col_ps

    def _lift_off(self) -> None:
        """Leave the rolling constraint with the same velocities (``N < 0``)."""
        col_th, col_ps = self._contact_map(self.theta, self.psi)
        px, py = self.track.point(self.psi)
        st, ct = math.sin(self.theta), math.cos(self.theta)
        self.bx, self.by = ct * px - st * py, st * px + ct * py
        self.bvx = col_th[1] * self.theta_dot + col_ps[1] * self.psi_dot
        self.bvy = col_th[2] * self.theta_dot + col_ps[2] * self.psi_dot
        self.spin_rate = self.theta_dot + col_ps[3] * self.psi_dot
        self.mode = FLIGHT
        self.normal_force = 0.0

    def _flight_gap(self) -> tuple[float, float]:
        """Ball-centre angle in the frame and its radial gap ``rho_b - r(psi_b)`` [rad, m]."""
        st, ct = math.sin(self.theta), math.cos(self.theta)
        qx, qy = ct * self.bx + st * self.by, -st * self.bx + ct * self.by
        psi_b = math.atan2(qx, qy)
        psi_b += 2 * math.pi * round((self.psi - psi_b) / (2 * math.pi))
        return psi_b, math.hypot(qx, qy) - self.track.eval(psi_b)[0]

    def _step_flight(self, h: float) -> None:
        """Frame by RK4, ball ballistic (exact); on crossing the track, land at the
        interpolated crossing instant of the gap."""
        gap0 = self._flight_gap()[1]
        ball0 = (self.bx, self.by, self.bvx, self.bvy, self.spin)
        self._step_frame(h)
        g = self._g
        self.bx += self.bvx * h
        self.by += self.bvy * h - 0.5 * g * h * h
        self.bvy -= g * h
        self.spin += self.spin_rate * h
        psi_b, gap = self._flight_gap()
        self.psi = psi_b
        if gap <= 0.0:
            x, y, vx, vy, spin = ball0
            tau = h * gap0 / (gap0 - gap) if gap0 > 0.0 else 0.0
            self.bx, self.by = x + vx * tau, y + vy * tau - 0.5 * g * tau * tau
            self.bvx, self.bvy, self.spin = vx, vy - g * tau, spin + self.spin_rate * tau
            self._impact(self._flight_gap()[0])
        elif self.by < -GONE_DEPTH:
            self.mode = GONE

    def _impact(self, psi: float) -> None:
        """Plastic impact with sticking: ``q_dot+ = (A^T M A)^-1 A^T M v-``."""
        before = self.kinetic_energy()
        col_th, col_ps = self._contact_map(self.theta, psi)
        m, Jb = self._m, self._Jb
        v = (self.theta_dot, self.bvx, self.bvy, self.spin_rate)
        w = (self._Jf, m, m, Jb)
        mv = [wi * vi for wi, vi in zip(w, v, strict=True)]
        a_th = sum(ci * mi for ci, mi in zip(col_th, mv, strict=True))
        a_ps = sum(ci * mi for ci, mi in zip(col_ps, mv, strict=True))
        M11 = sum(wi * ci * ci for wi, ci in zip(w, col_th, strict=True))
        M12 = sum(wi * ci * di for wi, ci, di in zip(w, col_th, col_ps, strict=True))
        M22 = sum(wi * di * di for wi, di in zip(w, col_ps, strict=True))
        self.mode = ROLLING
        self.psi = psi
        if self.stuck:
            self.theta_dot, self.psi_dot = 0.0, a_ps / M22
        else:
            det = M11 * M22 - M12 * M12
            self.theta_dot = (a_th * M22 - M12 * a_ps) / det
            self.psi_dot = (M11 * a_ps - M12 * a_th) / det
        self.spin_rate = self.theta_dot + col_ps[3] * self.psi_dot
        self.impact_loss += before - self.kinetic_energy()

    # --------------------------------------------------------------------- public API
    def advance(self, duration: float, command: float) -> None:
        """Advance by ``duration`` with the commanded torque held (zero-order hold).

        Parameters
        ----------
        duration : float
            Interval [s] (split into steps of at most ``dt``).
        command : float
            Commanded motor torque [N m]; the motor applies ``k_u command + tau_0``.
        """
        if duration <= 0.0:
            return
        self.u_applied = self.params.motor_gain * command + self.params.torque_offset
        steps = max(1, math.ceil(duration / self.dt - 1e-9))
        h = duration / steps
        for _ in range(steps):
            if self.mode == ROLLING:
                self._step_rolling(h)
            elif self.mode == FLIGHT:
                sub = 4
                for _ in range(sub):
                    self._step_flight(h / sub)
                    if self.mode != FLIGHT:
                        break
            else:
                self._step_frame(h)
            self.t += h

    def kinetic_energy(self) -> float:
        """Kinetic energy of frame and ball [J]."""
        T = 0.5 * self._Jf * self.theta_dot**2
        if self.mode == ROLLING:
            r, r1, _ = self.track.eval(self.psi)
            ell = math.hypot(r, r1)
            v2 = r * r * self.theta_dot**2 - 2 * r * r * self.theta_dot * self.psi_dot \
                + ell * ell * self.psi_dot**2
            omega = self.theta_dot - ell * self.psi_dot / self._R
            T += 0.5 * self._m * v2 + 0.5 * self._Jb * omega**2
        elif self.mode == FLIGHT:
            T += 0.5 * self._m * (self.bvx**2 + self.bvy**2) + 0.5 * self._Jb * self.spin_rate**2
        return T

    def potential_energy(self) -> float:
        """Potential energy (ball height times weight, frame imbalance) [J]."""
        P = self.params
        V = P.imbalance * self._g * math.cos(self.theta - P.imbalance_angle)
        if self.mode == ROLLING:
            V += self._m * self._g * self.track.eval(self.psi)[0] * math.cos(
                self.psi - self.theta)
        elif self.mode == FLIGHT:
            V += self._m * self._g * self.by
        return V

    def ball_world(self) -> tuple[float, float, float, float]:
        """Ball centre position [m] and velocity [m/s] in the world (NaN without a ball)."""
        if self.mode == ROLLING:
            col_th, col_ps = self._contact_map(self.theta, self.psi)
            px, py = self.track.point(self.psi)
            st, ct = math.sin(self.theta), math.cos(self.theta)
            return (ct * px - st * py, st * px + ct * py,
                    col_th[1] * self.theta_dot + col_ps[1] * self.psi_dot,
                    col_th[2] * self.theta_dot + col_ps[2] * self.psi_dot)
        if self.mode == FLIGHT:
            return self.bx, self.by, self.bvx, self.bvy
        nan = float("nan")
        return nan, nan, nan, nan

    def state(self) -> PlantState:
        """The current true state as a record."""
        x, y, vx, vy = self.ball_world()
        has_ball = self.mode in (ROLLING, FLIGHT)
        if self.mode == FLIGHT:
            st, ct = math.sin(self.theta), math.cos(self.theta)
            qx, qy = ct * x + st * y, -st * x + ct * y
            rel_vx = vx + self.theta_dot * y
            rel_vy = vy - self.theta_dot * x
            qvx, qvy = ct * rel_vx + st * rel_vy, -st * rel_vx + ct * rel_vy
            psi_dot = (qvx * qy - qx * qvy) / (qx * qx + qy * qy)
        else:
            psi_dot = self.psi_dot
        nan = float("nan")
        return PlantState(
            t=self.t, theta=self.theta, theta_dot=self.theta_dot, mode=self.mode,
            ball_x=x, ball_y=y, ball_angle=self.psi if has_ball else nan,
            ball_angle_dot=psi_dot if has_ball else nan,
            spin=self.spin if has_ball else nan, spin_rate=self.spin_rate if has_ball else nan,
            normal_force=self.normal_force if self.mode == ROLLING else 0.0,
            torque=self.u_applied, friction_torque=self.fric_torque,
            energy=self.kinetic_energy() + self.potential_energy(), work_motor=self.w_motor,
            work_friction=self.w_fric, work_rolling=self.w_roll, impact_loss=self.impact_loss)


def _rk4(f: Callable[[tuple[float, ...]], tuple[float, ...]], y: tuple[float, ...],
         h: float) -> tuple[float, ...]:
    """One classical Runge-Kutta step ``y + h/6 (k1 + 2 k2 + 2 k3 + k4)`` on tuples."""
    k1 = f(y)
    k2 = f(tuple(a + 0.5 * h * b for a, b in zip(y, k1, strict=True)))
    k3 = f(tuple(a + 0.5 * h * b for a, b in zip(y, k2, strict=True)))
    k4 = f(tuple(a + h * b for a, b in zip(y, k3, strict=True)))
    return tuple(a + h / 6.0 * (b + 2 * c + 2 * d + e)
                 for a, b, c, d, e in zip(y, k1, k2, k3, k4, strict=True))
