"""The parameter vector of the compiled kernels: one named layout shared by every kernel.

The numba kernels (rigid dynamics and energies, the controller's feedback linearisation, the
diagnosis residual, the simulator's truth, the contact model) take the rig's scalar
parameters as one float64 vector ``P`` indexed by the names below; it is packed from a
:class:`bfr_model.params.RigParams` in one place, :func:`rigid_vector` (the contact model
adds its own block with :func:`with_contact`). A kernel reads ``P[I_M]``, never a bare index.

==============  ===========================================  ==============================
index           entry [unit]                                 source (rig.yaml)
==============  ===========================================  ==============================
``I_M``         ball mass m [kg]                             ball.mass
``I_JB``        ball inertia J_b [kg m^2]                    ball.inertia
``I_JF``        frame inertia J_f [kg m^2]                   frame.inertia
``I_R``         rolling radius R [m]                         ball.radius, ball.plate_distance
``I_G``         in-plane gravity g cos(eps) [m/s^2]          environment.*
``I_CV``        joint viscous friction c_v [N m s/rad]       joint.viscous_friction
``I_TC``        joint Coulomb friction T_c [N m]             joint.coulomb_friction
``I_VC``        its smoothing velocity v_c [rad/s]           joint.coulomb_smoothing
``I_MUR``       rolling resistance mu_rol [-]                track.rolling_resistance
``I_VR``        its smoothing velocity v_r [rad/s]           track.rolling_smoothing
``I_KU``        motor torque gain k_u [-]                    actuator.torque_gain
``I_CW, I_SW``  cos, sin of the frame's wobble [-]           frame.wobble
``I_CL``        load-dependent joint friction c_L [m]        joint.load_friction
``I_MF``        frame mass m_f [kg]                          frame.mass
``I_EL``        half the ball's ellipticity e0 [m]           ball.ellipticity
``I_EB0``       ellipse phase beta_0 [rad]                   ball.ellipse_phase
``I_SBAR``      mean arc-length rate of p(phi) [m/rad]       (elliptic ball only)
``I_NS``        number N of arc-length harmonics [-]         (elliptic ball only)
``I_K``         contact stiffness k [N/m^n]                  contact.* (contact model only)
``I_NEXP``      contact exponent n [-]                       contact.exponent
``I_DAMP``      contact damping d [N s/m^(p+1)]              from contact.restitution
``I_PEXP``      damping exponent p [-]                       contact.damping_exponent
``I_MUS``       static friction, in-plane [-]                contact.static_friction
``I_MUD``       dynamic friction, in-plane [-]               contact.dynamic_friction
``I_KT``        tangential stick stiffness [N/m]             contact.tangential_stiffness
``I_CT``        tangential stick damping [N s/m]             contact.tangential_damping
``I_VREG``      slip regularisation velocity [m/s]           (numerical)
``I_MARGIN``    contact-search margin [m]                    (numerical)
``I_MAXSTEP``   contact-search step [rad]                    (numerical)
``I_RB``        ball radius R_b [m] (two-edge contact)       ball.radius
``I_ZE``        half the plate distance d_f / 2 [m]          ball.plate_distance
``I_HFLY``      longest free-flight step [s]                 contact.max_flight_step
``I_EXH``       1: search and evaluate every contact at      (numerical; the reference of
                every step (no event-based shortcuts)        the tests)
``I_MEX``       frame's first mass moment, x [kg m]          frame.imbalance, _angle
``I_MEY``       frame's first mass moment, y [kg m]          (m_f e [sin, cos] theta_e)
``I_TAU0``      drive's torque offset tau_0 [N m]            actuator.torque_offset
``I_TS``        the ball's creep time tau_s [s] (0: rolls)   ball.creep_time
==============  ===========================================  ==============================

The last four are rigid-model entries appended after the contact block (so that the contact
block keeps its indices).

With an elliptic ball, ``2 N`` Fourier coefficients of the ball-centre curve's arc length
``s(phi)`` follow at ``P[P_SIZE:]`` (cosine terms, then sine terms; see
:func:`bfr_model.dynamics.curve_terms`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from bfr_model.params import RigParams

__all__ = [
    "I_CL", "I_CT", "I_CV", "I_CW", "I_DAMP", "I_EB0", "I_EL", "I_EXH", "I_G", "I_HFLY",
    "I_JB", "I_JF", "I_K", "I_KT", "I_KU", "I_M", "I_MARGIN", "I_MAXSTEP", "I_MEX", "I_MEY",
    "I_MF", "I_MUD", "I_MUR", "I_MUS", "I_NEXP", "I_NS", "I_PEXP", "I_R", "I_RB", "I_SBAR",
    "I_SW", "I_TAU0", "I_TC", "I_TS", "I_VC", "I_VR", "I_VREG", "I_ZE", "P_SIZE", "rigid_vector",
    "with_contact",
]

FloatArray = NDArray[np.float64]

# rigid model (and every kernel derived from it)
I_M, I_JB, I_JF, I_R, I_G, I_CV, I_TC, I_VC, I_MUR, I_VR, I_KU = range(11)
I_CW, I_SW, I_CL, I_MF, I_EL, I_EB0, I_SBAR, I_NS = range(11, 19)
# contact model (zero in a rigid model's vector)
I_K, I_NEXP, I_DAMP, I_PEXP, I_MUS, I_MUD, I_KT, I_CT, I_VREG, I_MARGIN, I_MAXSTEP = range(19, 30)
# contact model, two-edge contact and event-based stepping (issue 16)
I_RB, I_ZE, I_HFLY, I_EXH = range(30, 34)
# rigid model, appended: frame imbalance, the drive's torque offset, the ball's creep
I_MEX, I_MEY, I_TAU0, I_TS = range(34, 38)
P_SIZE = 38


def rigid_vector(params: RigParams) -> FloatArray:
    """The rigid model's entries of ``P`` (the contact block zero, no arc-length tail).

    The elliptic ball's arc-length series depends on the curve; the rigid model appends it
    (:class:`bfr_model.dynamics.RigidModel`).
    """
    P = np.zeros(P_SIZE)
    P[I_M] = params.ball.mass
    P[I_JB] = params.ball.inertia
    P[I_JF] = params.frame.inertia
    P[I_R] = params.ball.rolling_radius
    P[I_G] = params.environment.in_plane_gravity
    P[I_CV] = params.joint.viscous_friction
    P[I_TC] = params.joint.coulomb_friction
    P[I_VC] = params.joint.coulomb_smoothing
    P[I_MUR] = params.track.rolling_resistance
    P[I_VR] = params.track.rolling_smoothing
    P[I_KU] = params.actuator.torque_gain
    P[I_CW] = math.cos(params.frame.wobble)
    P[I_SW] = math.sin(params.frame.wobble)
    P[I_CL] = params.joint.load_friction
    P[I_MF] = params.frame.mass
    P[I_EL] = 0.5 * params.ball.ellipticity
    P[I_EB0] = params.ball.ellipse_phase if params.ball.ellipticity > 0.0 else 0.0
    P[I_MEX], P[I_MEY] = params.frame.imbalance_moment
    P[I_TAU0] = params.actuator.torque_offset
    P[I_TS] = params.ball.creep_time
    return P


def with_contact(P: FloatArray, params: RigParams, *, damping: float, search_step: float,
                 margin: float = 4e-4, exhaustive: bool = False) -> FloatArray:
    """A copy of ``P`` with the contact model's block filled.

    Parameters
    ----------
    P : ndarray
        A vector of this layout (:func:`rigid_vector`).
    params : RigParams
        ``contact.*`` and the ball's radii.
    damping : float
        The contact damping d [N s/m^(p+1)] (from the restitution; the contact model's).
    search_step : float
        Largest step of the contact search along the contour [rad].
    margin : float
        Reach margin M of the contact search [m]: contour minima within ``R + M`` of the
        ball centre are tracked, and the search runs again after the ball has travelled
        ``M / 2`` relative to the frame.
    exhaustive : bool
        Search and evaluate every contact at every step (the reference of the tests).
    """
    c = params.contact
    out = np.array(P, float)
    out[I_K] = params.contact_stiffness
    out[I_NEXP] = c.exponent
    out[I_PEXP] = c.damping_exponent
    out[I_DAMP] = damping
    # two edges pressing along lines inclined by gamma (cos gamma = R / R_b) to the plane: an
    # in-plane normal force F_n is 2 N cos(gamma), the friction available 2 mu N
    wedge = params.ball.radius / params.ball.rolling_radius
    out[I_MUS] = c.static_friction * wedge
    out[I_MUD] = c.dynamic_friction * wedge
    out[I_KT] = c.tangential_stiffness
    out[I_CT] = c.tangential_damping
    out[I_VREG] = 1e-3
    out[I_MARGIN] = margin
    out[I_MAXSTEP] = search_step
    out[I_RB] = params.ball.radius
    out[I_ZE] = 0.5 * params.ball.plate_distance
    out[I_HFLY] = params.contact.max_flight_step
    out[I_EXH] = 1.0 if exhaustive else 0.0
    return out
