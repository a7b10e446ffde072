"""The ball's grip on the plates: the friction its rolling needs, and a slip test.

Method
------
The rigid model (:mod:`bfr_model.dynamics`) lets the ball roll without slipping: its spin is
``omega_b = theta_dot - lam(phi) phi_dot / R``, R the rolling radius and ``lam`` the contact
point's speed along the contour per unit phi, and its kinetic energy holds
``J_b omega_b^2 / 2``. Whatever changes the spin is friction at the two plate edges. The
edges carry the in-plane normal force ``F_n`` as ``F_n R_b / R`` between them (the groove's
wedge), each friction force at the lever R from the ball's centre, so rolling holds while

    |J_b omega_b'| <= mu F_n R_b                                                    (1)

(the contact model's in-plane law ``mu R_b / R``, :mod:`bfr_model.contact`), mu the ball's
friction coefficient on a plate edge.

1. **Friction demand.** Along the recording, at the measured frame motion and the ball's
   measured contact angle and rate (the residual evaluator's), the corrected model's
   ``mu_req = |J_b omega_b'| / (F_n R_b)``: its percentiles, where the largest is, and the
   share of samples whose normal force is not positive (the ball would leave the edge).
2. **Slip test.** The ball alone under the measured frame motion: the rigid model's
   accelerations are affine in the torque, so the torque that gives the measured
   ``theta_ddot`` gives the ball's ``phi_ddot`` (the ball's row of the rigid model at the
   measured theta, theta_dot, theta_ddot). With friction-limited rolling the spin is a
   state: while (1) holds the ball rolls; once the demand exceeds ``mu F_n R_b`` it slips,
   ``J_b omega_b' = tau_f = -mu F_n R_b sgn(omega_b - omega_roll)``, the translation is the
   rigid model's row with ``J_b = 0`` plus the friction's generalized force ``(lam / R)
   tau_f`` (rolling gives back the rigid model's row: ``M22 = M22(J_b = 0) + J_b lam^2 /
   R^2``), until the relative spin crosses zero and the ball rolls again (Coulomb friction,
   one mu for sticking and sliding). Steps of at most :data:`MAX_STEP`, the frame motion
   interpolated linearly, the midpoint rule (second order while the ball rolls or slides;
   the switches between the two are resolved to a step). Each window's start
   ``(phi, phi_dot)`` is fitted to the ball's world angle over the horizon before it, the
   window's ``horizon`` is predicted and scored (the causal measure of
   :func:`bfr_diagnose.locate.causal_prediction_errors`, with the frame's measured motion
   instead of its simulated one, so the figure is the ball's alone). The law is chosen on
   the training windows among rolling, Coulomb friction over :data:`MU_GRID` (values the
   demand never reaches act as rolling and are skipped) and linear creep (5) over
   :data:`TAU_GRID`; the held-out windows score rolling against the chosen law,
   and a one-sided sign-flip randomisation test of the windows' paired differences (each
   window's squared error rolling minus slipping; under no difference each sign is as
   likely, :data:`FLIPS` random flips, a fixed seed) says whether slipping predicts the
   ball better than chance would. It weighs each window by how much it changes: a few
   braking windows mended and many gentle ones slightly worse count as what they are.
   Creep needs no coefficient the demand reaches (its spin lags whatever the demand), so
   it is tried even where rolling needs less than every mu of the grid (no Coulomb is
   tried there).
3. **Verdict.** ``slips`` when the held-out RMS improves by at least :data:`MIN_GAIN` and the
   randomisation test's p-value is below :data:`ALPHA`; ``rolls`` otherwise (the report then gives
   the largest coefficient the training windows rejected: mu is above it).

4. **Frame and ball together, slipping** (:func:`coupled_rollout`: the short-horizon
   predictions of :mod:`bfr_diagnose.locate` with ``slip``). The spin as a fifth state
   with the rolling constraint ``omega_b = theta_dot - lam phi_dot / R`` replaced by its
   Lagrange multiplier, the friction torque tau_f on the spin: ``J_b omega_b' = tau_f`` and
   the generalised forces ``(-tau_f, lam tau_f / R)`` on ``(theta, phi)`` of the model
   without the spin's inertia (:func:`~bfr_model.dynamics.forced_terms` with ``J_b = 0``).
   Rolling (``tau_f = J_b omega_b'`` of the constrained motion) gives back the rigid model's
   ``M`` exactly; sliding, ``tau_f = -sgn(omega_b - omega_roll) mu F_n R_b`` with F_n, which
   depends on tau_f through the accelerations, solved together with it (both are affine in
   tau_f). The friction's power ``tau_f (omega_b - omega_roll)`` is never positive. The frame
   feels the slip: the ball's spin no longer loads it. Without wobble (``frame.wobble``).
   Checked against the force-based contact model (another structure) and by the energy of
   a frictionless ball (tests/test_diagnose_grip.py).
5. **Linear creep** (:func:`creep_rollout`, :func:`_creep_ball_rollout`). Coulomb's law lets
   the spin catch up with the rolling the moment friction can: sliding ends within a few
   milliseconds once the demand falls. A contact that creeps (Kalker's linear theory of
   rolling contact, Johnson 1985 ch. 8: a tangential force proportional to the slip while
   it is small) lets the slip persist: ``tau_f = -(J_b / tau_s) (omega_b - omega_roll)``,
   ``J_b omega_b' = tau_f``, and on the translation ``(lam / R) tau_f`` as in (4), so that
   without the frame the relative spin relaxes as ``exp(-t (1 + J_b lam^2 / (R^2 M22_t)) /
   tau_s)`` (``M22_t`` the translation's inertia). ``tau_s -> 0`` is rolling, ``tau_s ->
   inf`` the spinless ball of mu = 0. The spin is a fifth state at every instant: each
   window's start fits the relative spin beside ``(phi, phi_dot)`` (from 0), the coupled
   predictions fit it as a fifth start state (:func:`bfr_diagnose.locate.
   causal_prediction_errors`); a smoothed start takes the spin the law implies: the spin is
   a first-order lag of the rolling rate, ``omega_b' = -(omega_b - omega_roll) / tau_s``,
   so the measured rolling rate before the start gives it (:meth:`SlipLaw.spin`). The same
   lag puts the law into the equation error (:mod:`bfr_diagnose.residual`, a creeping ball:
   no start, no integration), which the diagnosis reports beside the windows' verdict: the
   ball's row rolling and creeping, held out, and the tau_s its training samples choose
   (another method, the same law). Classical RK4 (coupled) and the midpoint rule (ball
   alone) in steps of at most :data:`MAX_STEP` and a quarter of tau_s (:func:`_substeps`:
   the relaxation time at the grid's smallest tau_s, 0.02 s, is 7.6 ms, under four 2-ms
   steps, still 2.5e-5 rad from a 20-fold finer step). The rigid model the simulator runs
   has the law (``ball.creep_time``, :func:`bfr_model.dynamics.creep_terms`, the kernel
   these rollouts use): where the ball creeps as a contact creeps (6) the diagnosis writes
   tau_s there. The
   contact model (Coulomb at the edges, a stiff stick spring) does not have it. The friction's
   power ``tau_f (omega_b - omega_roll) = -(J_b / tau_s) (omega_b - omega_roll)^2`` is
   never positive.

6. **Is the creep a contact's creep?** (:func:`creep_slip`, nineteenth round). Kalker's
   linear law holds while the slip is small: a contact's tangential force grows with the
   creepage ``xi = v_slip / v_roll`` only until it reaches the friction limit, at creepages
   of ``mu F_n / (G c^2 C11)`` (Johnson 1985, ch. 8; ``c`` the Hertz contact's radius, ``G``
   the shear modulus, ``C11`` about 4): for this ball's normal forces (0.01-0.1 N) about
   0.06 % for a hard plastic or metal and about 2 % even for a rubber, and beyond it the
   contact slides at ``mu F_n`` (Coulomb, which the test tries too). So a creep law is a
   contact's creep only where the slip it implies stays small. Along the recording the
   law's own spin (:meth:`SlipLaw.spin`, the lag of the measured rolling rate) gives the
   relative spin ``r``; the ball rolls relative to the frame at ``lam phi_dot / R``, so the
   slip ratio is ``|r| R / |lam phi_dot|`` (samples whose ball centre moves along the track
   at least :data:`MIN_TRACK_SPEED`) and the slip speed at the edges ``|r| R``. Where the
   median slip ratio exceeds :data:`MAX_CREEP_SLIP` (2.5 times a rubber's saturation) the
   law is a *suspect*: the ball's row then wants less of the spin's inertia at short time
   scales than a rolling ball has, and a creep that slow stands in for it (a larger rolling
   radius or a lighter ball fit the same rows; docs/diagnosis.md, "What the creep stands
   in for"); the report says so and ``corrected_params.yaml`` does not carry it. A creep
   whose slip cannot be measured (no sample moves along the track) is not written either.
   The test is necessary, not sufficient: Kalker's creep has no constant time (its
   ``tau = J_b v / (2 G c^2 C11 R^2)`` grows with the rolling speed v) and is well under a
   millisecond for any ball material here, so every tau_s the grid can see (>= 20 ms) is
   slower than a dry contact's; the 5 % only separates a slow creep-like contact (a
   lubricated edge, a spin inertia that follows the shell loosely) that the test cannot
   rule out from one that slides outright.

Each grid is walked away from rolling (mu down, tau_s up) and stops once the training cost
has risen after a fall, or twice without one (the costs are unimodal in every case seen).

Coulomb slip is not a term of the rigid model the simulator runs; it is one of the contact
model (``contact.static_friction`` and ``contact.dynamic_friction``), which the report names;
creep is one of the rigid model (``ball.creep_time``), written only where it is a contact's
creep (6). The diagnosis's predictions carry it (4): where the ball slips, the plausible
effects (those ``corrected_params.yaml`` holds) with the law predict the ball beside the
selection's model. The test needs a ball on a turning frame; a held frame or a frame alone
is not tested.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.dynamics import (
    I_CL,
    I_JB,
    I_R,
    RigidModel,
    creep_terms,
    curve_terms,
    forced_terms,
    mass_terms,
    rigid_rk4_steps,
    rigid_terms,
)
from bfr_model.jit import njit
from bfr_model.params import RigParams
from numpy.typing import NDArray
from scipy.optimize import least_squares

from bfr_diagnose.preprocess import Prepared, SensorCorrection

__all__ = ["ALPHA", "FLIPS", "MAX_CREEP_SLIP", "MAX_STEP", "MIN_GAIN", "MIN_TRACK_SPEED",
           "MU_GRID", "STATE_SCALE", "TAU_GRID", "SlipLaw", "coupled_rollout",
           "creep_is_contact", "creep_is_suspect", "creep_lag", "creep_rollout", "creep_slip",
           "grip", "slip_parameters"]

FloatArray = NDArray[np.float64]

#: Largest median slip ratio of a creep law taken as a contact's creep [-] (module docstring,
#: 6): elastic creep saturates at creepages of about 0.06 % (hard plastic, metal) to 2 %
#: (rubber) at this ball's normal forces; beyond, a contact slides at its friction limit.
MAX_CREEP_SLIP = 0.05

#: Slowest ball-centre speed along the track whose slip ratio :func:`creep_slip` takes [m/s]
#: (slower, the ratio divides by nearly nothing).
MIN_TRACK_SPEED = 0.01

#: Friction coefficients of the ball on a plate edge tried by the slip test [-] (factor 1.5).
MU_GRID = (0.05, 0.075, 0.11, 0.17, 0.25, 0.38, 0.57)

#: Relaxation times of the spin under linear creep tried by the slip test [s] (factor 1.5,
#: from a ball that nearly rolls to one whose spin follows its rolling over a lap's part).
TAU_GRID = (0.02, 0.03, 0.045, 0.067, 0.1, 0.15, 0.22, 0.33)

#: Held-out improvement of the ball's prediction that slipping must reach to be reported.
MIN_GAIN = 1.1

#: Level of the one-sided randomisation test over held-out windows.
ALPHA = 0.01

#: Random sign flips of the randomisation test (seeded: the same data, the same p).
FLIPS = 20000

#: Longest step of the ball's integration [s] (a grid step longer than this is cut into equal
#: sub-steps). Halving it moves the slip test's figures on the NTNU logs by < 1 %.
MAX_STEP = 0.002

#: Scale of each state in a start's fit: theta, phi [rad], theta_dot, phi_dot [rad/s] and (under
#: creep) the ball's relative spin [rad/s] (``x_scale`` of the solver; here and in
#: :func:`bfr_diagnose.locate.causal_prediction_errors`).
STATE_SCALE = np.array([1e-3, 1e-3, 0.1, 0.1, 1.0])

#: ... of a window's start of the ball alone: phi, phi_dot, relative spin.
_START_SCALE = STATE_SCALE[[1, 3, 4]]

#: Spacing of the training windows [s] (the held-out ones are the predictions' spacing).
_TRAIN_EVERY = 0.4

#: Share of a frame-held recording's usable samples whose measured ball path needs a normal
#: force <= 0 beyond which it is flagged: the ball passed under the frame's edge, where the
#: rolling-on-top model (the rigid model's bilateral contact) cannot hold. One in a hundred,
#: so that no single noisy sample flags a run; a ball resting or rolling on top is pressed
#: on with about m g and never comes near.
UNDER_EDGE_SHARE = 0.01


@njit
def _ball_acc(th, ph, thd, phd, thdd, P, g0, g1, g2, g3, g4, g5, g6, g7):  # noqa: ANN001, ANN202
    """``(phi_ddot, F_n)`` of the rigid model at a measured ``theta_ddot``.

    The accelerations are affine in the command u (:func:`~bfr_model.dynamics.rigid_terms`
    without load-dependent bearing friction): the u that gives ``thdd`` gives the ball's.
    """
    a0, c0, _, _, f0 = rigid_terms(th, ph, thd, phd, 0.0, P, g0, g1, g2, g3, g4, g5, g6, g7)
    a1, c1, _, _, f1 = rigid_terms(th, ph, thd, phd, 1.0, P, g0, g1, g2, g3, g4, g5, g6, g7)
    s = (thdd - a0) / (a1 - a0)
    return c0 + (c1 - c0) * s, f0 + (f1 - f0) * s


@njit
def _rolling_torque(jb, rr, thdd, lam, lam1, phd, phdd):  # noqa: ANN001, ANN202
    """``J_b omega_b'`` of a rolling ball [N m] (module docstring, 1).

    ``omega_b = theta_dot - lam phi_dot / R``, so ``omega_b' = theta_ddot - (lam' phi_dot^2 +
    lam phi_ddot) / R``.
    """
    return jb * (thdd - (lam1 * phd * phd + lam * phdd) / rr)


@njit
def _rollout(ph, phd, j, n, th, thd, thdd, mu, dt, ns, Pf, Pt, g0, g1, g2, g3, g4, g5, g6,  # noqa: ANN001, ANN202
             g7, jb, rb, rr):  # noqa: ANN001
    """The contact angle at grid samples ``j .. j + n`` under the measured frame motion.

    ``mu < 0``: rolling without slip; else friction-limited rolling (module docstring, 2),
    rolling at the start. ``Pf``: the model's parameter vector, ``Pt``: the same with
    ``J_b = 0`` (the translation alone). NaN after a non-finite step.
    """
    out = np.full(n + 1, np.nan)
    out[0] = ph
    rolling = True
    w = 0.0
    h = dt / ns
    for k in range(j, j + n):
        for s in range(ns):
            f = s / ns
            t_ = th[k] + f * (th[k + 1] - th[k])
            td = thd[k] + f * (thd[k + 1] - thd[k])
            tdd = thdd[k] + f * (thdd[k + 1] - thdd[k])
            a_r, fn = _ball_acc(t_, ph, td, phd, tdd, Pf, g0, g1, g2, g3, g4, g5, g6, g7)
            lam = cap = tau = 0.0
            if mu >= 0.0:
                c = curve_terms(ph, Pf, g0, g1, g2, g3, g4, g5, g6, g7)
                lam = c[8]
                cap = mu * max(fn, 0.0) * rb
                tau = _rolling_torque(jb, rr, tdd, lam, c[9], phd, a_r)
            if mu < 0.0 or (rolling and abs(tau) <= cap):
                # rolling: the midpoint rule (second order), the frame at the half step
                fm = f + 0.5 / ns
                a_m = _ball_acc(th[k] + fm * (th[k + 1] - th[k]), ph + 0.5 * h * phd,
                                thd[k] + fm * (thd[k + 1] - thd[k]), phd + 0.5 * h * a_r,
                                thdd[k] + fm * (thdd[k + 1] - thdd[k]), Pf, g0, g1, g2, g3,
                                g4, g5, g6, g7)[0]
                ph += h * (phd + 0.5 * h * a_r)
                phd += h * a_m
                continue
            if rolling:
                rolling = False
                w = td - lam * phd / rr
                tau = cap if tau > 0.0 else -cap
                rel = 0.0
            else:
                rel = w - (td - lam * phd / rr)
                tau = -cap if rel > 0.0 else cap
            # slipping: the translation alone plus friction's generalized force, midpoint rule
            # with the friction torque held over the step
            m22 = mass_terms(ph, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[2]
            a_t = (_ball_acc(t_, ph, td, phd, tdd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[0]
                   + lam / rr * tau / m22)
            fm = f + 0.5 / ns
            ph_m = ph + 0.5 * h * phd
            phd_m = phd + 0.5 * h * a_t
            lam_m = curve_terms(ph_m, Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8]
            m22_m = mass_terms(ph_m, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[2]
            a_m = (_ball_acc(th[k] + fm * (th[k + 1] - th[k]), ph_m,
                             thd[k] + fm * (thd[k + 1] - thd[k]), phd_m,
                             thdd[k] + fm * (thdd[k + 1] - thdd[k]), Pt, g0, g1, g2, g3, g4, g5,
                             g6, g7)[0]
                   + lam_m / rr * tau / m22_m)
            w += h * tau / jb
            ph += h * phd_m
            phd += h * a_m
            if rel != 0.0:
                lam1 = curve_terms(ph, Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8]
                if rel * (w - (td + h * tdd - lam1 * phd / rr)) <= 0.0:
                    rolling = True
        if not (np.isfinite(ph) and abs(phd) < 1e3):
            return out
        out[k - j + 1] = ph
    return out


@njit
def _creep_ball_rollout(ph, phd, rel0, j, n, th, thd, thdd, inv_tau, dt, ns, Pf, Pt, g0, g1,  # noqa: ANN001, ANN202
                        g2, g3, g4, g5, g6, g7, jb, rr):  # noqa: ANN001
    """The contact angle at grid samples ``j .. j + n`` under linear creep (module docstring, 5).

    The ball alone under the measured frame motion, its spin a state: ``tau_f = -(J_b /
    tau_s) (omega_b - omega_roll)`` (``inv_tau = 1 / tau_s``) on the spin, ``(lam / R) tau_f``
    on the translation (the rigid model's row with ``J_b = 0``), as the sliding branch of
    :func:`_rollout` with this friction in place of Coulomb's. ``rel0``: the relative spin
    ``omega_b - omega_roll`` at j [rad/s]. The midpoint rule, the frame at the half step.
    NaN after a non-finite step.
    """
    out = np.full(n + 1, np.nan)
    out[0] = ph
    w = thd[j] - curve_terms(ph, Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8] * phd / rr + rel0
    h = dt / ns
    for k in range(j, j + n):
        for s in range(ns):
            f = s / ns
            t_ = th[k] + f * (th[k + 1] - th[k])
            td = thd[k] + f * (thd[k + 1] - thd[k])
            tdd = thdd[k] + f * (thdd[k + 1] - thdd[k])
            lam = curve_terms(ph, Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8]
            tau = -jb * inv_tau * (w - (td - lam * phd / rr))
            m22 = mass_terms(ph, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[2]
            a_t = (_ball_acc(t_, ph, td, phd, tdd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[0]
                   + lam / rr * tau / m22)
            fm = f + 0.5 / ns
            t_m = th[k] + fm * (th[k + 1] - th[k])
            td_m = thd[k] + fm * (thd[k + 1] - thd[k])
            tdd_m = thdd[k] + fm * (thdd[k + 1] - thdd[k])
            ph_m = ph + 0.5 * h * phd
            phd_m = phd + 0.5 * h * a_t
            w_m = w + 0.5 * h * tau / jb
            lam_m = curve_terms(ph_m, Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8]
            tau_m = -jb * inv_tau * (w_m - (td_m - lam_m * phd_m / rr))
            m22_m = mass_terms(ph_m, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[2]
            a_m = (_ball_acc(t_m, ph_m, td_m, phd_m, tdd_m, Pt, g0, g1, g2, g3, g4, g5, g6,
                             g7)[0]
                   + lam_m / rr * tau_m / m22_m)
            w += h * tau_m / jb
            ph += h * phd_m
            phd += h * a_m
        if not (np.isfinite(ph) and abs(phd) < 1e3):
            return out
        out[k - j + 1] = ph
    return out


@njit
def _sliding_acc(th, ph, thd, phd, u, sgn, mu, Pt, g0, g1, g2, g3, g4, g5, g6, g7, rb, rr):  # noqa: ANN001, ANN202
    """``(theta_ddot, phi_ddot, tau_f)`` of the frame and a sliding ball (module docstring, 4).

    The model without the ball's spin (``Pt``: ``J_b = 0``) plus the friction torque's
    generalised forces ``(-tau_f, lam tau_f / R)``; ``tau_f = -sgn mu F_n R_b`` with sgn the
    sign of the relative spin. The accelerations and F_n are affine in tau_f, so the
    friction and the normal force it depends on are solved together exactly; without
    contact (``F_n <= 0``) there is no friction.
    """
    lam = curve_terms(ph, Pt, g0, g1, g2, g3, g4, g5, g6, g7)[8]
    a0 = forced_terms(th, ph, thd, phd, u, 0.0, 0.0, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
    a1 = forced_terms(th, ph, thd, phd, u, -1.0, lam / rr, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
    k = -sgn * mu * rb
    tau = k * a0[4] / (1.0 - k * (a1[4] - a0[4]))
    if tau * sgn > 0.0:  # F_n <= 0: the ball is not pressed on the edges
        tau = 0.0
    return a0[0] + (a1[0] - a0[0]) * tau, a0[1] + (a1[1] - a0[1]) * tau, tau


@njit
def _coupled_rollout(x0, u, dt, ns, mu, Pf, Pt, g0, g1, g2, g3, g4, g5, g6, g7, jb, rb, rr):  # noqa: ANN001, ANN202
    """States ``[theta, phi, theta_dot, phi_dot]`` (n + 1, 4) of frame and ball, open loop.

    The coupled model with friction-limited rolling (module docstring, 4) along the torque
    record u (``u[k]`` held over a grid step of dt). While the ball rolls, one RK4 step of
    the rigid model per grid step (:func:`~bfr_model.dynamics.rigid_rk4_steps`, as
    :func:`bfr_diagnose.locate._rigid_rollout`: ``mu < 0`` or a demand that never reaches
    the bound gives its states to the last bit); the demand (1) is checked at each grid
    step's start. Sliding: ``ns`` midpoint steps per grid step with the spin as a fifth
    state, until the relative spin crosses zero; the rest of that grid step rolls (RK4).
    """
    n = u.shape[0]
    xs = np.empty((n + 1, 4))
    x = np.zeros(6)
    x[:4] = x0[:4]
    xs[0, :] = x[:4]
    rolling = True
    w = 0.0
    sgn = 0.0
    h = dt / ns
    for k in range(n):
        args = (u[k], Pf, g0, g1, g2, g3, g4, g5, g6, g7)
        s0 = 0
        if rolling:
            if mu >= 0.0:
                thdd, phdd, _, _, fn = rigid_terms(x[0], x[1], x[2], x[3], u[k], Pf, g0, g1,
                                                   g2, g3, g4, g5, g6, g7)
                c = curve_terms(x[1], Pf, g0, g1, g2, g3, g4, g5, g6, g7)
                tau = _rolling_torque(jb, rr, thdd, c[8], c[9], x[3], phdd)
                if abs(tau) > mu * max(fn, 0.0) * rb:
                    rolling = False
                    w = x[2] - c[8] * x[3] / rr
                    sgn = -1.0 if tau > 0.0 else 1.0
            if rolling:
                x = rigid_rk4_steps(x, 0.0, dt, 1, args)
                xs[k + 1, :] = x[:4]
                if not (np.isfinite(x[1]) and abs(x[3]) < 1e3):
                    xs[k + 1:, :] = np.nan
                    return xs
                continue
        while s0 < ns and not rolling:
            th, ph, thd, phd = x[0], x[1], x[2], x[3]
            a_t, a_p, tau = _sliding_acc(th, ph, thd, phd, u[k], sgn, mu, Pt, g0, g1, g2, g3,
                                         g4, g5, g6, g7, rb, rr)
            thm, phm = th + 0.5 * h * thd, ph + 0.5 * h * phd
            thdm, phdm = thd + 0.5 * h * a_t, phd + 0.5 * h * a_p
            a_t, a_p, tau = _sliding_acc(thm, phm, thdm, phdm, u[k], sgn, mu, Pt, g0, g1, g2,
                                         g3, g4, g5, g6, g7, rb, rr)
            x[0] += h * thdm
            x[1] += h * phdm
            x[2] += h * a_t
            x[3] += h * a_p
            w += h * tau / jb
            s0 += 1
            lam = curve_terms(x[1], Pf, g0, g1, g2, g3, g4, g5, g6, g7)[8]
            if sgn * (w - (x[2] - lam * x[3] / rr)) <= 0.0:  # the relative spin crossed zero
                rolling = True
        if s0 < ns:
            x = rigid_rk4_steps(x, 0.0, h, ns - s0, args)
        xs[k + 1, :] = x[:4]
        if not (np.isfinite(x[1]) and abs(x[3]) < 1e3):
            xs[k + 1:, :] = np.nan
            return xs
    return xs


@njit
def _creep_rhs(x, u, inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7):  # noqa: ANN001, ANN202
    """``d/dt [theta, phi, theta_dot, phi_dot, omega_b]`` under linear creep (docstring, 5).

    The rigid model's own creep (:func:`bfr_model.dynamics.creep_terms`, the simulator's).
    """
    a = creep_terms(x[0], x[1], x[2], x[3], x[4], u, inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5,
                    g6, g7)
    out = np.empty(5)
    out[0] = x[2]
    out[1] = x[3]
    out[2] = a[0]
    out[3] = a[1]
    out[4] = a[2]
    return out


@njit
def _creep_coupled_rollout(x0, u, dt, ns, inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7):  # noqa: ANN001, ANN202
    """States ``[theta, phi, theta_dot, phi_dot, omega_b]`` (n + 1, 5) under creep.

    ``x0`` the same five at the start; ``ns`` classical RK4 steps per grid step of dt,
    ``u[k]`` held over it (module docstring, 5). NaN from a non-finite step on.
    """
    n = u.shape[0]
    xs = np.full((n + 1, 5), np.nan)
    x = x0.copy()
    xs[0, :] = x
    h = dt / ns
    for k in range(n):
        for _ in range(ns):
            k1 = _creep_rhs(x, u[k], inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k2 = _creep_rhs(x + 0.5 * h * k1, u[k], inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5,
                            g6, g7)
            k3 = _creep_rhs(x + 0.5 * h * k2, u[k], inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5,
                            g6, g7)
            k4 = _creep_rhs(x + h * k3, u[k], inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if not (np.isfinite(x[1]) and abs(x[3]) < 1e3):
            return xs
        xs[k + 1, :] = x
    return xs


def _substeps(dt: float, tau_s: float | None = None) -> int:
    """Integration steps per grid step of dt: steps of at most :data:`MAX_STEP`.

    Under creep also at most a quarter of tau_s: the relative spin relaxes at up to about
    ``2.6 / tau_s`` (module docstring, 5; the seed's ball), and the explicit steps stay well
    inside their stability limits (RK4 2.8, the midpoint rule 2) at ``h 2.6 / tau_s <= 0.65``.
    Every tau_s of :data:`TAU_GRID` keeps MAX_STEP.
    """
    h = MAX_STEP if tau_s is None else min(MAX_STEP, 0.25 * tau_s)
    return max(int(np.ceil(dt / h - 1e-9)), 1)


def slip_parameters(model: RigidModel) -> tuple[FloatArray, FloatArray, float, float, float]:
    """``(Pf, Pt, J_b, R_b, R)`` of a model for :func:`coupled_rollout`.

    ``Pt`` is the model's parameter vector without the ball's spin inertia (``J_b = 0``).
    """
    return (model.P, model.translation_vector, float(model.P[I_JB]), model.params.ball.radius,
            float(model.P[I_R]))


def coupled_rollout(model: RigidModel, x0: FloatArray, u: FloatArray, dt: float,
                    mu: float) -> FloatArray:
    """Frame and ball open loop under a torque record, the ball rolling or sliding.

    Parameters
    ----------
    model : RigidModel
        The rigid model (its ball's spin inertia and radius give the slip's terms).
    x0 : ndarray
        Start ``[theta, phi, theta_dot, phi_dot]`` [rad, rad/s]; the ball rolls at the start.
    u : ndarray
        Torque command of each grid step [N m] (held over the step).
    dt : float
        Grid step [s]; sliding is integrated in steps of at most :data:`MAX_STEP`.
    mu : float
        Friction coefficient of the ball on a plate edge [-]; < 0: rolling without slip
        (the rigid model's RK4 rollout to the last bit).

    Returns
    -------
    ndarray
        States (len(u) + 1, 4); NaN from a non-finite step on.
    """
    pf, pt, jb, rb, rr = slip_parameters(model)
    ns = _substeps(dt)
    x = np.zeros(6)
    x[:4] = x0[:4]
    # u copied (writable, contiguous): one compiled signature for read-only and writable u
    return _coupled_rollout(x, np.array(u, dtype=float), dt, ns, mu, pf, pt,
                            *model.geom_args, jb, rb, rr)


def creep_rollout(model: RigidModel, x0: FloatArray, u: FloatArray, dt: float,
                  tau_s: float) -> FloatArray:
    """Frame and ball open loop under a torque record, the ball's spin relaxing by creep.

    Parameters
    ----------
    model : RigidModel
        The rigid model (its ball's spin inertia and rolling radius give the creep's terms).
    x0 : ndarray
        Start ``[theta, phi, theta_dot, phi_dot]`` [rad, rad/s], and optionally the relative
        spin ``omega_b - omega_roll`` [rad/s] (0, rolling, when absent).
    u : ndarray
        Torque command of each grid step [N m] (held over the step).
    dt : float
        Grid step [s]; integrated in RK4 steps of at most :data:`MAX_STEP`.
    tau_s : float
        Relaxation time of the spin [s] (module docstring, 5).

    Returns
    -------
    ndarray
        States (len(u) + 1, 4); NaN from a non-finite step on.
    """
    pf, pt, jb, _, rr = slip_parameters(model)
    ns = _substeps(dt, tau_s)
    lam = float(curve_terms(float(x0[1]), pf, *model.geom_args)[8])
    rel0 = float(x0[4]) if len(x0) > 4 else 0.0
    x = np.array([x0[0], x0[1], x0[2], x0[3], x0[2] - lam * x0[3] / rr + rel0], float)
    # u copied (writable, contiguous): one compiled signature for read-only and writable u
    return _creep_coupled_rollout(x, np.array(u, dtype=float), dt, ns, 1.0 / tau_s, jb,
                                  pt, *model.geom_args)[:, :4]


@njit
def creep_lag(w, ok, dt, tau_s):  # noqa: ANN001, ANN201
    """The relative spin ``r = omega_b - omega_roll`` of a creeping ball [rad/s].

    From its rolling rate ``w = omega_roll`` on a grid of step dt [s], usable where ``ok``
    (each usable stretch starts rolling); tau_s [s] the spin's relaxation time. The exact
    recursion of :meth:`SlipLaw.spin` (its docstring).
    """
    a = np.exp(-dt / tau_s)
    b = -np.expm1(-dt / tau_s) * tau_s / dt  # (1 - a) tau_s / dt without cancellation
    out = np.full(w.size, np.nan)
    r = 0.0
    for k in range(w.size):
        if not ok[k]:
            continue
        r = a * r - b * (w[k] - w[k - 1]) if k > 0 and ok[k - 1] else 0.0
        out[k] = r
    return out


@dataclass(frozen=True, kw_only=True)
class SlipLaw:
    """How a slipping ball's spin follows its rolling: Coulomb friction or linear creep.

    ``kind`` ``"coulomb"``: ``value`` is mu [-] (module docstring, 2 and 4); ``"creep"``:
    ``value`` is the spin's relaxation time tau_s [s] (5).
    """

    kind: str
    value: float

    def __post_init__(self) -> None:
        if self.kind not in ("coulomb", "creep"):
            raise ValueError(f"slip law {self.kind!r}: 'coulomb' or 'creep'")
        if not (np.isfinite(self.value) and (self.value > 0.0 or (
                self.kind == "coulomb" and self.value == 0.0))):
            raise ValueError(f"slip law {self.kind}: value {self.value} must be > 0 "
                             "(mu >= 0)")

    @classmethod
    def of(cls, slip_test: dict[str, Any] | None) -> SlipLaw | None:
        """The law a slip test chose (None: rolling, or no test)."""
        if not slip_test or slip_test.get("law") is None:
            return None
        key = "mu" if slip_test["law"] == "coulomb" else "tau_s"
        return cls(kind=slip_test["law"], value=float(slip_test[key]))

    @property
    def states(self) -> int:
        """Start states a rollout takes: the relative spin is a fifth one under creep."""
        return 5 if self.kind == "creep" else 4

    def spin(self, model: RigidModel, theta_dot: FloatArray, phi: FloatArray,
             phi_dot: FloatArray, usable: NDArray[np.bool_], dt: float) -> FloatArray | None:
        """The ball's relative spin along a recording from its measured rolling rate (creep).

        Under creep (module docstring, 5) the spin obeys ``omega_b' = -(omega_b -
        omega_roll) / tau_s`` whatever moves the frame and the ball: it is a first-order lag
        of the rolling rate ``omega_roll = theta_dot - lam(phi) phi_dot / R``, so the
        relative spin ``r = omega_b - omega_roll`` at any sample follows from the measured
        rolling rate before it. Exact for a rolling rate linear between grid samples::

            r_{k+1} = a r_k - tau_s (1 - a) (w_{k+1} - w_k) / dt,   a = exp(-dt / tau_s)

        Each usable stretch (finite rates, ``usable``) starts rolling (``r = 0``); that
        start is forgotten as ``exp(-t / tau_s)``. The smoothed start of a creeping ball
        (:func:`bfr_diagnose.locate.prediction_errors`): the state a smoother measures plus
        the spin the law implies.

        Parameters
        ----------
        model : RigidModel
            The model (its curve's ``lam`` and rolling radius R).
        theta_dot, phi, phi_dot : ndarray
            Frame rate [rad/s], contact angle [rad] and its rate [rad/s] on the grid (NaN
            where unknown).
        usable : ndarray of bool
            Grid samples to use.
        dt : float
            Grid step [s].

        Returns
        -------
        ndarray or None
            ``r`` on the grid [rad/s] (NaN where not usable); None under Coulomb friction,
            whose spin no measured rate fixes.
        """
        if self.kind != "creep":
            return None
        ok = usable & np.isfinite(theta_dot) & np.isfinite(phi) & np.isfinite(phi_dot)
        w = np.full(phi.size, np.nan)
        zero = np.zeros(int(ok.sum()))
        w[ok] = model.ball_spin_rate(np.stack([zero, phi[ok], theta_dot[ok], phi_dot[ok]], -1))
        return creep_lag(w, ok, dt, self.value)

    def text(self) -> str:
        """``mu = 0.17`` or ``creep, tau_s = 0.1 s``."""
        return (f"mu = {self.value:.2g}" if self.kind == "coulomb"
                else f"creep, tau_s = {self.value:.2g} s")

    def rollout(self, model: RigidModel, x0: FloatArray, u: FloatArray, dt: float
                ) -> FloatArray:
        """Frame and ball open loop under this law (coupled_rollout, creep_rollout)."""
        if self.kind == "coulomb":
            return coupled_rollout(model, x0[:4], u, dt, self.value)
        return creep_rollout(model, x0, u, dt, self.value)


@dataclass(frozen=True, kw_only=True, eq=False)
class _Ball:
    """One model's ball under one recording's measured frame motion."""

    model: RigidModel
    pf: FloatArray
    pt: FloatArray
    jb: float
    rb: float
    rr: float
    th: FloatArray
    thd: FloatArray
    thdd: FloatArray
    dt: float

    @classmethod
    def of(cls, params: RigParams, prep: Prepared, sensor: SensorCorrection) -> _Ball:
        """The ball of ``params`` under the frame motion of ``prep`` (encoder zero applied)."""
        model = RigidModel(params)
        pf = model.P.copy()
        pf[I_CL] = 0.0  # the bearing's load friction acts on the frame only
        pt = pf.copy()
        pt[I_JB] = 0.0
        return cls(model=model, pf=pf, pt=pt, jb=float(pf[I_JB]),
                   rb=params.ball.radius, rr=float(pf[I_R]),
                   th=np.ascontiguousarray(prep.theta + sensor.theta_zero),
                   thd=np.ascontiguousarray(prep.theta_dot),
                   thdd=np.ascontiguousarray(prep.theta_ddot),
                   dt=float(prep.t[1] - prep.t[0]))

    def roll(self, z: FloatArray, j: int, n: int, law: SlipLaw | None) -> FloatArray:
        """Contact angle at ``j .. j + n`` from ``z`` at j (``law`` None: rolling).

        ``z = (phi, phi_dot[, omega_b - omega_roll])``: the relative spin only under creep.
        """
        if law is not None and law.kind == "creep":
            return _creep_ball_rollout(z[0], z[1], z[2] if len(z) > 2 else 0.0, j, n, self.th,
                                       self.thd, self.thdd, 1.0 / law.value, self.dt,
                                       _substeps(self.dt, law.value), self.pf, self.pt,
                                       *self.model.geom_args, self.jb, self.rr)
        return _rollout(z[0], z[1], j, n, self.th, self.thd, self.thdd,
                        -1.0 if law is None else law.value, self.dt, _substeps(self.dt),
                        self.pf, self.pt, *self.model.geom_args, self.jb, self.rb, self.rr)

    def in_frame(self, phi: FloatArray) -> FloatArray:
        """The ball's polar angle in the frame [rad] at contact angles phi."""
        return self.model.curve.ball_angle(phi)

    def window_error(self, meas: FloatArray, guess: FloatArray, j: int, nw: int, nh: int,
                     law: SlipLaw | None) -> float | None:
        """Squared ball-angle error summed over the horizon after a start fitted before it.

        ``meas``: the measured in-frame ball angle on ``[j, j + nw + nh]``; the start
        ``(phi, phi_dot)`` at j (and under creep the relative spin, from 0) is fitted to its
        first ``nw + 1`` samples. None when the fit or the rollout fails.
        """
        creep = law is not None and law.kind == "creep"
        z0 = np.r_[guess, 0.0] if creep else np.asarray(guess, float)

        def fun(z: FloatArray) -> FloatArray:
            r = self.in_frame(self.roll(z, j, nw, law)) - meas[:nw + 1]
            return np.where(np.isfinite(r), r, 1.0)

        sol = least_squares(fun, z0, x_scale=_START_SCALE[:z0.size], method="lm",
                            max_nfev=30 * z0.size)
        phi = self.roll(sol.x, j, nw + nh, law)
        e = self.in_frame(phi[nw + 1:]) - meas[nw + 1:]
        return float(np.sum(e ** 2)) if np.all(np.isfinite(e)) else None


@njit
def _demand_kernel(idx, th, thd, thdd, phi, phi_dot, Pf, g0, g1, g2, g3, g4, g5, g6, g7, jb,  # noqa: ANN001, ANN202
                   rr, rb):  # noqa: ANN001
    """``(mu_req, F_n)`` at the grid samples idx (mu_req NaN where F_n <= 0)."""
    mu_req = np.full(idx.size, np.nan)
    fns = np.empty(idx.size)
    for q in range(idx.size):
        k = idx[q]
        a_r, fn = _ball_acc(th[k], phi[k], thd[k], phi_dot[k], thdd[k], Pf, g0, g1, g2, g3, g4,
                            g5, g6, g7)
        c = curve_terms(phi[k], Pf, g0, g1, g2, g3, g4, g5, g6, g7)
        tau = _rolling_torque(jb, rr, thdd[k], c[8], c[9], phi_dot[k], a_r)
        fns[q] = fn
        if fn > 0.0:
            mu_req[q] = abs(tau) / (fn * rb)
    return mu_req, fns


def _demand(ball: _Ball, prep: Prepared, phi: FloatArray, phi_dot: FloatArray
            ) -> dict[str, Any]:
    """The friction coefficient rolling needs along the recording (module docstring, 1)."""
    ok = prep.usable & np.isfinite(phi) & np.isfinite(phi_dot)
    idx = np.flatnonzero(ok)
    if idx.size < 10:
        return {"samples": int(idx.size)}
    mu_req, fns = _demand_kernel(idx, ball.th, ball.thd, ball.thdd,
                                 np.ascontiguousarray(phi, float),
                                 np.ascontiguousarray(phi_dot, float), ball.pf,
                                 *ball.model.geom_args, ball.jb, ball.rr, ball.rb)
    good = np.isfinite(mu_req)
    off = fns <= 0.0
    lift = ({"lift_off_t_first": float(prep.t[idx[np.argmax(off)]]),
             "lift_off_phi_deg_first": float(np.degrees(np.mod(phi[idx[np.argmax(off)]],
                                                               2 * np.pi)))}
            if off.any() else {})
    if not good.any():
        return {"samples": int(idx.size), "normal_force_min": float(np.min(fns)),
                "lift_off_fraction": float(np.mean(off)), **lift}
    q_max = int(np.nanargmax(mu_req))
    pct = np.percentile(mu_req[good], [50, 90, 99])
    return {"samples": int(idx.size), "p50": float(pct[0]), "p90": float(pct[1]),
            "p99": float(pct[2]), "max": float(mu_req[q_max]),
            "t_max": float(prep.t[idx[q_max]]),
            "phi_max_deg": float(np.degrees(np.mod(phi[idx[q_max]], 2 * np.pi))),
            "normal_force_min": float(np.min(fns)),
            "lift_off_fraction": float(np.mean(off)), **lift}


def _starts(prep: Prepared, mask: NDArray[np.bool_], phi: FloatArray, phi_dot: FloatArray,
            nw: int, nh: int, step: int) -> list[int]:
    """Window starts i0: ``[i0 - nw, i0 + nh]`` usable, ``[i0, i0 + nh]`` in ``mask``."""
    ok = prep.usable & np.isfinite(phi) & np.isfinite(phi_dot)
    return [i0 for i0 in range(nw, prep.n - nh - 1, step)
            if ok[i0 - nw:i0 + nh + 1].all() and mask[i0:i0 + nh + 1].all()]


def _scores(ball: _Ball, starts: list[int], meas: FloatArray, phi: FloatArray,
            phi_dot: FloatArray, nw: int, nh: int, law: SlipLaw | None) -> FloatArray:
    """Each window's squared error over the horizon (NaN where the fit failed)."""
    out = np.full(len(starts), np.nan)
    for q, i0 in enumerate(starts):
        j = i0 - nw
        e = ball.window_error(meas[j:i0 + nh + 1], np.array([phi[j], phi_dot[j]]), j, nw, nh,
                              law)
        if e is not None:
            out[q] = e
    return out


def _flip_test(d: FloatArray) -> float:
    """One-sided p of ``sum(d) > 0`` under random signs of d (a sign-flip randomisation)."""
    d = d[d != 0.0]
    if d.size == 0:
        return 1.0
    signs = np.random.default_rng(0).choice((-1.0, 1.0), size=(FLIPS, d.size))
    return float((1 + np.sum(signs @ d >= d.sum())) / (1 + FLIPS))


def _held_frame_contact(prep: Prepared, corrected: RigParams, sensor: SensorCorrection,
                        phi: FloatArray, phi_dot: FloatArray) -> dict[str, Any]:
    """A frame-held recording: no slip test, but whether the ball stayed on the edge.

    The normal force the measured ball path needs (the friction demand's ``F_n``): where it
    is not positive the ball passed under the frame's edge and only a bilateral contact
    (the rigid model's) could hold it there; past :data:`UNDER_EDGE_SHARE` of the usable
    samples ``under_edge`` says how much and where first.
    """
    demand = _demand(_Ball.of(corrected, prep, sensor), prep, phi, phi_dot)
    out: dict[str, Any] = {"verdict": "not tested",
                           "meaning": "needs a ball on a turning frame",
                           "friction_demand": demand}
    share = float(demand.get("lift_off_fraction", 0.0))
    if share > UNDER_EDGE_SHARE:
        out["under_edge"] = {
            "fraction": share, "normal_force_min": demand["normal_force_min"],
            "t_first": demand["lift_off_t_first"],
            "phi_deg_first": demand["lift_off_phi_deg_first"],
            "meaning": (f"the ball's measured path needs a normal force <= 0 on "
                        f"{100 * share:.1f} % of the usable samples (down to "
                        f"{demand['normal_force_min']:.3g} N; first at t = "
                        f"{demand['lift_off_t_first']:.2f} s, phi = "
                        f"{demand['lift_off_phi_deg_first']:.0f} deg): the ball passed under "
                        "the frame's edge, where the rolling-on-top model cannot hold (a "
                        "real ball falls off or is held by something the model lacks); "
                        "what was fitted there is not this model's physics")}
    return out


def grip(prep: Prepared, corrected: RigParams, nominal: RigParams, sensor: SensorCorrection,
         phi: FloatArray, phi_dot: FloatArray, test_mask_t: NDArray[np.bool_],
         horizon: float = 0.1, every: float = 0.2) -> dict[str, Any]:
    """Friction demand and slip test of one recording (module docstring).

    Parameters
    ----------
    prep : Prepared
        Preprocessed recording with a ball on a turning frame.
    corrected, nominal : RigParams
        The corrected model (suspects left out) and the nominal one.
    sensor : SensorCorrection
        The corrected model's sensor correction.
    phi, phi_dot : ndarray
        Contact angle [rad] and rate [rad/s] on the grid (the corrected model's residual).
    test_mask_t : ndarray of bool
        Held-out grid samples.
    horizon, every : float
        Prediction horizon (and fit window) and the held-out windows' spacing [s].

    Returns
    -------
    dict
        ``friction_demand`` (percentiles of mu_req, its maximum's time [s] and place [deg],
        the smallest normal force [N], the share without contact), ``slip_test`` (the grids,
        training costs, the chosen ``law`` (None, ``"coulomb"`` or ``"creep"``) with its
        ``mu`` [-] or ``tau_s`` [s], held-out RMS of the ball's in-frame angle [rad] rolling
        and slipping and the nominal model's rolling, windows better and worse, the
        randomisation test's p; under creep ``creep_slip``, the slip it implies,
        :func:`creep_slip`), ``verdict`` and ``meaning``.
    """
    if not prep.has_ball:
        return {"verdict": "not tested",
                "meaning": "needs a ball on a turning frame"}
    if prep.frame_held:
        return _held_frame_contact(prep, corrected, sensor, phi, phi_dot)
    ball = _Ball.of(corrected, prep, sensor)
    demand = _demand(ball, prep, phi, phi_dot)
    out: dict[str, Any] = {"friction_demand": demand}
    dt = ball.dt
    nw = nh = max(round(horizon / dt), 1)
    psi_w = prep.ball_for(sensor)[0]
    meas = psi_w + ball.th
    train = _starts(prep, ~test_mask_t, phi, phi_dot, nw, nh, max(round(_TRAIN_EVERY / dt), 1))
    held = _starts(prep, test_mask_t, phi, phi_dot, nw, nh, max(round(every / dt), 1))
    top = demand.get("max", 0.0)
    grid = [m for m in MU_GRID if m < top]
    if len(held) < 10 or len(train) < 5:
        out.update(verdict="not tested", meaning=f"too few windows ({len(train)} training, "
                   f"{len(held)} held out)")
        return out
    costs: dict[str, FloatArray] = {"rolling": _scores(ball, train, meas, phi, phi_dot, nw, nh,
                                                        None)}
    laws: dict[str, SlipLaw | None] = {"rolling": None}

    def walk(steps: list[SlipLaw]) -> None:
        """Away from rolling along one law's grid, until the cost rose (module docstring)."""
        last, fell, rose = float(np.nansum(costs["rolling"])), False, 0
        for law in steps:
            key = _key(law)
            costs[key], laws[key] = _scores(ball, train, meas, phi, phi_dot, nw, nh, law), law
            c = float(np.nansum(costs[key]))
            rose += c > last
            if (fell and c > last) or rose >= 2:
                break
            fell, last = fell or c < last, c

    walk([SlipLaw(kind="coulomb", value=m) for m in reversed(grid)])
    walk([SlipLaw(kind="creep", value=t) for t in TAU_GRID])
    both = np.all([np.isfinite(c) for c in costs.values()], axis=0)
    train_cost = {k: float(np.sum(c[both])) for k, c in costs.items()}
    law = laws[min(train_cost, key=train_cost.get)]
    rejected = [v.value for k, v in laws.items()
                if v is not None and v.kind == "coulomb" and train_cost[k] > train_cost["rolling"]]
    roll_h = _scores(ball, held, meas, phi, phi_dot, nw, nh, None)
    nom_h = _scores(_Ball.of(nominal, prep, sensor), held, meas, phi, phi_dot, nw, nh, None)
    slip_h = roll_h if law is None else _scores(ball, held, meas, phi, phi_dot, nw, nh, law)
    ok = np.isfinite(roll_h) & np.isfinite(slip_h) & np.isfinite(nom_h)
    n = int(ok.sum())

    def rms(x: FloatArray) -> float:
        return float(np.sqrt(np.sum(x[ok]) / max(n * nh, 1)))

    better = int(np.sum(slip_h[ok] < roll_h[ok]))
    worse = int(np.sum(slip_h[ok] > roll_h[ok]))
    p = _flip_test(roll_h[ok] - slip_h[ok])
    gain = rms(roll_h) / max(rms(slip_h), 1e-300)
    out["slip_test"] = {
        "mu_grid": [v.value for v in laws.values() if v is not None and v.kind == "coulomb"],
        "tau_grid": [v.value for v in laws.values() if v is not None and v.kind == "creep"],
        "train_cost": train_cost,
        "law": None if law is None else law.kind,
        "mu": law.value if law is not None and law.kind == "coulomb" else None,
        "tau_s": law.value if law is not None and law.kind == "creep" else None,
        "mu_rejected_up_to": max(rejected) if rejected else None,
        "windows_train": int(both.sum()), "windows_heldout": n,
        "ball_rmse_rolling": rms(roll_h), "ball_rmse_slipping": rms(slip_h),
        "ball_rmse_nominal_rolling": rms(nom_h), "improvement": gain,
        "improvement_vs_nominal": rms(nom_h) / max(rms(slip_h), 1e-300),
        "windows_better": better, "windows_worse": worse, "p_value": p,
        "horizon": nh * dt, "unit": "rad (the ball's angle in the frame)"}
    held_out = (f"predicts the ball {gain:.2f}x better on held-out windows ({better} of "
                f"{better + worse} better, randomisation test p = {p:.1g})")
    if law is not None and gain >= MIN_GAIN and p < ALPHA and law.kind == "coulomb":
        out.update(verdict="slips", meaning=(
            f"the ball slips on the plate edges where rolling needs more than mu = "
            f"{law.value:.2g} (up to {top:.2f} at t = {demand['t_max']:.2f} s): "
            f"friction-limited rolling {held_out}; the rigid model cannot slip, the contact "
            f"model can (contact.static_friction = contact.dynamic_friction = "
            f"{law.value:.2g})"))
    elif law is not None and gain >= MIN_GAIN and p < ALPHA:
        cs = creep_slip(ball.model, law, ball.thd, phi, phi_dot, prep.usable, dt)
        out["slip_test"]["creep_slip"] = cs
        coulomb = [k for k in train_cost if laws[k] is not None and laws[k].kind == "coulomb"]
        best_mu = min(coulomb, key=train_cost.get) if coulomb else None
        tried = (f"Coulomb's best on the training windows, mu = {best_mu}, costs "
                 f"{train_cost[best_mu] / train_cost[_key(law)]:.1f}x the creep's"
                 if best_mu is not None else "no Coulomb coefficient the demand reaches")
        out.update(verdict="slips", meaning=(
            f"the ball slips on the plate edges, its spin lagging its rolling and catching "
            f"up over about {law.value:.2g} s: "
            f"linear creep at the plate edges (J_b omega_b' = -(J_b / tau_s) (omega_b - "
            f"omega_roll), tau_s = {law.value:.2g} s) {held_out}, "
            + (f"better than any Coulomb coefficient on the training windows (rolling "
               f"needs up to {top:.2f})" if grid else
               f"where rolling needs mu <= {top:.2g} (below every Coulomb coefficient "
               f"tried, {MU_GRID[0]})")
            + (f"; the rigid model runs it with ball.creep_time = {law.value:.2g} s"
               if cs["plausible"] else _creep_meaning(cs, tried))))
    else:
        tried = "rolling" if law is None else law.text()
        bound = (f"; the data reject mu <= {max(rejected):.2g}" if rejected else "")
        out.update(verdict="rolls", meaning=(
            f"no slip seen: the training windows chose {tried}; held out, slipping "
            f"{gain:.2f}x ({better} of {better + worse} windows better, p = {p:.1g}); "
            f"rolling needs mu up to {top:.2f}{bound}"))
    return out


def creep_slip(model: RigidModel, law: SlipLaw, theta_dot: FloatArray, phi: FloatArray,
               phi_dot: FloatArray, usable: NDArray[np.bool_], dt: float) -> dict[str, Any]:
    """The slip a creep law implies along a recording, and whether it is a contact's creep.

    Module docstring, 6: the law's relative spin ``r`` (:meth:`SlipLaw.spin`), the slip
    ratio ``|r| R / |lam phi_dot|`` over the samples whose ball centre moves along the track
    at least :data:`MIN_TRACK_SPEED`, and the slip speed ``|r| R`` at the plate edges.

    Parameters
    ----------
    model : RigidModel
        The model (its curve's ``lam`` and rolling radius R).
    law : SlipLaw
        A creep law.
    theta_dot, phi, phi_dot : ndarray
        Frame rate [rad/s], contact angle [rad] and its rate [rad/s] on the grid.
    usable : ndarray of bool
        Grid samples to use.
    dt : float
        Grid step [s].

    Returns
    -------
    dict
        ``samples``; ``slip_ratio`` (median, 90th percentile) [-] and ``slip_speed`` (median,
        90th percentile) [m/s], each a dict ``{"p50", "p90"}``; ``plausible`` (the median
        ratio at most :data:`MAX_CREEP_SLIP`) and ``limit``.
    """
    r = law.spin(model, theta_dot, phi, phi_dot, usable, dt)
    rr = float(model.P[I_R])
    ok = np.isfinite(r) if r is not None else np.zeros(phi.size, bool)
    v = np.full(phi.size, np.nan)  # the ball centre's speed along the track [m/s]
    x = np.stack([np.zeros(int(ok.sum())), phi[ok], theta_dot[ok], phi_dot[ok]], -1)
    v[ok] = np.abs(theta_dot[ok] - model.ball_spin_rate(x)) * rr  # lam |phi_dot|
    take = ok & (v >= MIN_TRACK_SPEED)
    out: dict[str, Any] = {"samples": int(take.sum()), "limit": MAX_CREEP_SLIP,
                           "unit": "slip ratio [-], slip speed [m/s]"}
    if not take.any():
        return {**out, "plausible": None}
    ratio = np.abs(r[take]) * rr / v[take]
    speed = np.abs(r[take]) * rr
    out["slip_ratio"] = {"p50": float(np.median(ratio)), "p90": float(np.quantile(ratio, 0.9))}
    out["slip_speed"] = {"p50": float(np.median(speed)), "p90": float(np.quantile(speed, 0.9))}
    out["plausible"] = bool(out["slip_ratio"]["p50"] <= MAX_CREEP_SLIP)
    return out


def creep_is_contact(slip_test: dict[str, Any]) -> bool:
    """Whether a slip test's creep is a contact's creep (module docstring, 6).

    True for a creep law whose measured slip stays within :data:`MAX_CREEP_SLIP`; False for
    any other law, a creep beyond it (a suspect) or one whose slip was not measured.
    """
    if slip_test.get("law") != "creep":
        return False
    return slip_test.get("creep_slip", {}).get("plausible") is True


def creep_is_suspect(slip_test: dict[str, Any]) -> bool:
    """Whether a slip test chose a creep that is not a contact's creep (a suspect, 6)."""
    return slip_test.get("law") == "creep" and not creep_is_contact(slip_test)


def _creep_meaning(cs: dict[str, Any], tried: str) -> str:
    """The verdict's words on a creep whose slip is beyond a contact's creep (docstring, 6)."""
    if cs["plausible"] is None:
        return ("; its slip could not be measured (no sample moves along the track): not "
                "written into corrected_params.yaml")
    sr, sv = cs["slip_ratio"], cs["slip_speed"]
    return (f"; but that creep is not a contact's creep: the spin lags its rolling by a "
            f"median {100 * sr['p50']:.0f} % ({100 * sr['p90']:.0f} % at the 90th "
            f"percentile; slip speeds {sv['p50']:.2g}-{sv['p90']:.2g} m/s at the edges), where "
            f"a contact's elastic creep saturates below about 2 % and it slides at its friction "
            f"limit ({tried}): a suspect, standing in for something the rolling model lacks "
            f"(less of the spin's inertia in the ball's motion: a larger rolling radius or a "
            f"lighter ball fit the same rows); not written into corrected_params.yaml")


def _key(law: SlipLaw) -> str:
    """A law's key in the slip test's training costs: ``0.17`` (mu) or ``tau_s 0.1``."""
    return str(law.value) if law.kind == "coulomb" else f"tau_s {law.value}"
