"""Force-based contact model of the ball on the frame (seed chapter 4, recommendations 1, 3).

The ball is a free body with spin, held to the frame by contact forces, so it can bounce,
lose contact and slip (seed Fig. 4.1-4.2). It rests in the groove between two plates d_f
apart, touching each plate's edge (a copy of the contour at ``z_e = +-d_f/2``); its centre
is at ``z`` between them. The in-plane distance from the centre to edge e's contour is
``d_e``, the 3-D distance to the edge ``sqrt(d_e^2 + (z - z_e)^2)``, so edge e touches when
``d_e < R_e(z) = sqrt(R_b^2 - (z - z_e)^2)`` (at z = 0 the rolling radius R).

*One edge* (``edges=1``, the default when every bump is on both edges): the two identical
edges act as one contact of the ball's in-plane disc of radius R, z = 0 (today's model).
*Two edges* (``edges=2``, seed recommendation 3; needed when ``track.asperity_edge`` puts a
bump on one plate only): each edge has its own contacts, normal forces, friction and stick
spring, each carrying the share ``s = 1/2`` of the one-edge law, and the ball moves in z.
With identical edges the two halves sum exactly (bit for bit, each edge summed apart) to
the one-edge model and z stays 0 (tested).

State (world coordinates, DEVELOPERS.md), ``x`` of length :data:`NX`::

    x, y         ball centre [m]                      vx, vy    its velocity [m/s]
    psi          ball spin angle, CCW [rad]           omega     its rate [rad/s]
    theta        frame angle [rad]                    theta_dot its rate [rad/s]
    xi           stick-spring extension at the primary contact (edge 0) [m]
    W_in         motor work [J]      W_diss  dissipated energy [J]
    slip         integral of the slip rate v_slip / R, mean over the edges [rad]
    W_hc         energy dissipated by the Hunt-Crossley damping alone [J]
    z, vz        lateral position of the centre, +z towards the front plate [m], [m/s]
    xi2          stick-spring extension at the primary contact of edge 1 [m]
    wpx, wpy     the ball's angular velocity in the frame's plane (world axes) [rad/s]

Equations of motion (seed eqs. 4.2-4.7, Newton-Euler):

    m r_ddot = sum_j F_j - m g_e y,   m z_ddot = sum_j F_z,j,   J_b psi_ddot = sum_j T_j,
    J_b w_p_dot = sum_j (z_e - z) F_t,j n_j,   J_f theta_ddot = k_u u + T_joint + sum_j T_frame,j

(a sphere: Euler's equations without gyroscopic terms).

Contacts j of an edge are the local minima of the distance d from the ball centre to its
contour (:mod:`bfr_model.closest_point`, exact Newton, warm-started) within reach; several
exist at the foot of a sharp bump. The penetration is ``w = R_e(z) + e(beta) - d`` with
``e`` the elliptic ball's radius variation (``e0 cos 2 beta``, beta the contact direction in
ball coordinates; 0 for a round ball). Normal force, Hunt and Crossley (seed eq. 4.15 with
p = n, q = 1):

    F_n = max(0, s k w^n (1 + alpha w_dot)),   w > 0,     n = 3/2

applied as the generalised force ``-F_n grad w`` on (centre, theta, psi, z). For a round
ball this is ``F_n n`` on the ball at the contact point, its reaction on the frame and the
lateral push ``F_n (z - z_e) / R_e`` (``dR_e/dz = -(z - z_e) / R_e``); the gradient form keeps
the elliptic ball's torques consistent. ``grad w`` uses the closest point's sensitivity:
with ``f' = |delta'|^2 + (delta - c) . delta''`` and ``kappa = n . delta'' / f'``,
``d alpha = kappa t . dc_f`` (alpha the normal's angle). The in-plane law is the
linearisation of the 3-D Hertz contact along each edge's normal, inclined by gamma
(``cos gamma = R_e / R_b``) to the plane: the 3-D penetration is ``w cos gamma`` to first
order in ``w / R`` (0.2 um in 10 mm), so the geometry is exact and the stiffness is that of
``params.contact_stiffness`` (k at z = 0; lateral shifts of a few 0.1 mm change cos gamma
by under 1 %, left out).

Stored elastic energy ``s k w^(n+1) / (n+1)``; the damping dissipates
``(F_n - s k w^n) w_dot >= 0`` (both when the force is ``s k w^n (1 + alpha w_dot)``, giving
``alpha s k w^n w_dot^2``, and when it is clipped to 0 on fast rebound, ``w_dot < 0``).

Tangential force at each edge's primary contact (its deepest one; replaces the seed's
discrete eqs. 4.23-4.28): a stick spring-damper, ``trial = s (k_t xi + c_t v_slip)``. The
friction coefficients in this in-plane law are the edges' ``mu`` times ``R_b / R_e``: each
edge presses with N along a line inclined by gamma to the plane, so its in-plane force is
``N cos gamma`` while the friction available is ``mu N`` (the wedge effect of the groove).
Stick while ``|trial| <= mu_s F_n`` (``F_t = -trial``, ``xi_dot = v_slip``); otherwise slide
with ``F_t = -mu_d F_n sgn(trial)``, the spring frozen while loading (``xi_dot = 0``) and
following the slip while unloading (``xi_dot = v_slip`` when ``xi v_slip < 0``). That rule
makes the dissipation ``-F_t v_slip - s k_t xi xi_dot`` non-negative in every case; after
each step a sliding spring is reset to ``mu_d F_n / (s k_t)`` (and a lost contact's to 0),
booking the released spring energy as dissipated. Secondary contacts (brief, at bump feet)
use regularised Coulomb friction ``-mu_d F_n tanh(v_slip / v_reg)``. The slip velocity of
the contact point (ball material point minus frame material point, along the tangent t) is

    v_slip = t . v + omega R_j - theta_dot (c_pt x t)_z + (z_e - z) w_p . n,
    R_j = R_e + e,  c_pt = c - R_j n

so that rolling without slip is ``omega = theta_dot - s_dot / R`` (DEVELOPERS.md). The
force ``F_t t`` acts on the ball, ``R_j F_t`` on its spin, ``(z_e - z) F_t n`` on its
rotation about the contact normal (yaw, w_p . n), ``-(c_pt x F_t t)_z`` on the frame. The
yaw is what lets the ball roll on two edges at different radii (one raised by a bump:
``R_1 - R_2 = (d_f / R) z`` to first order) without slipping on either; with identical edges
the two yaw torques cancel exactly. Friction across the edges (along z) is not modelled:
the ball slides sideways freely, held by the normal forces' lateral components.

Rolling resistance: a couple ``-mu_rol F_n R_j tanh(omega_rel / v_r)`` on the ball and its
reaction on the frame (``omega_rel = omega - theta_dot``; power ``mu_rol F_n |s_dot|`` as the
rigid model's). Joint friction as the rigid model's, with
``F_load = |sum_j F_j + m_f g_e y|`` explicit here.

Energy balance, checked by the tests: ``E_kin + E_pot + E_el - E(0) = W_in - W_diss`` with
``E_kin`` including ``m vz^2 / 2 + J_b |w_p|^2 / 2`` and
``E_el = sum_j s k w_j^(n+1) / (n+1) + sum_e s k_t xi_e^2 / 2``.

Integration (:func:`contact_steps`): the contact modes are near 1.5 kHz (Hertz stiffness
at the ball's weight, 3 kHz in a 0.1 m/s impact) and the stick spring near 1.4 kHz; a
compiled RK4 at ``contact.time_step`` (2e-5 s, about 30 steps per contact period, 8 per
impact) resolves them with an energy error far below the physical dissipation. Three
methods make it fast where the ball bounces over rows of sharp bumps (``bfr bench``,
docs/notes/issue-16.md):

- *Compiled closest point*: each edge's asperities in a sorted table, the few within 12
  widths of a point found by binary search (:func:`bfr_model.closest_point.rho012`); the
  search for contacts samples ``f`` in the window within reach
  (:func:`bfr_model.closest_point.local_minima`).
- *Event-based contact set*: any point's distance to the centre changes by at most the
  centre's travel relative to the frame, bounded over a step H by ``v H + a H^2 / 2``
  (:func:`_travel_rate`). So the set is searched anew only after the ball has travelled
  ``M / 2`` (reach margin M = 0.4 mm: the minima within ``R_e + |e0| + M``), a secondary
  candidate is re-solved only when its gap bound comes within 4 steps' travel, and it is
  evaluated in a step only if its gap bound is within that step's travel (otherwise its
  force is zero throughout: leaving it out changes nothing). Each edge's primary is its
  deepest candidate, re-ranked at every step.
- *Free flight*: with no stick spring loaded and every gap bound more than twice the
  travel, ``k`` steps are taken at once (at most ``contact.max_flight_step``, whole
  multiples of the step, so contacts still begin on the step grid); in flight the ball is
  ballistic (RK4 is exact for it) and the frame's motion smooth.

``exhaustive=True`` searches and evaluates every candidate at every step with no flight
steps: the reference, which the event-based stepping matches to 1e-12 m/s per 1 ms over
the bump row (tests). :meth:`ContactModel.rhs` also works with scipy's implicit solvers
for checks (:meth:`ContactModel.follow` keeps the contact set with the state).

Not modelled: the wobbling frame (``frame.wobble``; the contact model is planar, a shaft
pitch is the in-plane gravity ``g cos eps``, its lateral component ``g sin eps`` is left
out), friction across the edges, the elliptic ball's orientation beyond its spin angle.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from bfr_model.closest_point import (
    ContourData,
    closest_point,
    contour_data,
    contour_point_terms,
    local_minima,
    newton_closest,
    newton_inline,
)
from bfr_model.dynamics import RigidModel, curve_terms, rigid_terms
from bfr_model.geometry import OffsetCurve
from bfr_model.jit import njit, njit_inline
from bfr_model.layout import (
    I_CL,
    I_CT,
    I_CV,
    I_DAMP,
    I_EL,
    I_EXH,
    I_G,
    I_HFLY,
    I_JB,
    I_JF,
    I_K,
    I_KT,
    I_KU,
    I_M,
    I_MARGIN,
    I_MAXSTEP,
    I_MF,
    I_MUD,
    I_MUR,
    I_MUS,
    I_NEXP,
    I_PEXP,
    I_R,
    I_RB,
    I_TC,
    I_VC,
    I_VR,
    I_VREG,
    I_ZE,
    rigid_vector,
    with_contact,
)
from bfr_model.params import RigParams

__all__ = ["NX", "ContactModel", "ContactResult", "contact_eval", "contact_steps",
           "elastic_energy", "resolve_contacts", "search_contacts", "update_contacts"]

FloatArray = NDArray[np.float64]

# state layout (module docstring)
IX, IY, IPSI, ITH, IVX, IVY, IOM, ITHD, IXI, IWIN, IWD, ISLIP, IWHC, IZ, IVZ, IXI2 = range(16)
IWPX, IWPY = 16, 17
NX = 18
# parameter vector: the shared layout of bfr_model.layout (rigid entries + contact block)
NCMAX = 8  # at most this many simultaneous contact candidates per edge
# diagnostics layout (contact_eval's diag output); D_E* + e: the primary contact of edge e
D_FN, D_FN0, D_W0, D_VSLIP, D_NTOUCH, D_FT0, D_PHI0, D_D0, D_EEL = range(9)
D_EFN, D_EVS, D_EW, D_EFT = 9, 11, 13, 15
D_SIZE = 17
RESOLVE_GAP = 1e-7  # [m] candidates this close to touching (beyond the travel) are re-solved
SWAP_DEPTH = 1e-7  # [m] a secondary contact this much deeper than the primary takes its place


@njit_inline
def _edge_frame(E, e, z, CP):  # noqa: ANN001, ANN202
    """Force share s, in-plane radius R_e(z), dR_e/dz and lateral arm ``z_e - z`` of edge e.

    One edge (E = 1) is today's contact: the two identical edges acting together, s = 1,
    R_e = R, no arm. With two, edge 0 is the front plate (z_e = +d_f/2), edge 1 the back one
    (module docstring).
    """
    if E == 1:
        return 1.0, CP[I_R], 0.0, 0.0
    ze = CP[I_ZE] if e == 0 else -CP[I_ZE]
    dz = z - ze
    re = math.sqrt(CP[I_RB] * CP[I_RB] - dz * dz)
    return 0.5, re, -dz / re, -dz


@njit_inline
def _candidate_geometry(phi, x, CP, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw,  # noqa: ANN001, ANN202
                        span, iters):  # noqa: ANN001
    """Refine a candidate's contour angle by Newton; its contact geometry (frame coords)."""
    th_ = x[ITH]
    st = math.sin(th_)
    ct = math.cos(th_)
    cxf = ct * x[IX] + st * x[IY]
    cyf = -st * x[IX] + ct * x[IY]
    ms = CP[I_MAXSTEP]
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh,
                                                     bw, tphi, th, tw, span)
    fp = 1.0
    for _ in range(iters):  # Newton from the step's solution (module closest_point)
        ex = dx - cxf
        ey = dy - cyf
        f = ex * d1x + ey * d1y
        fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
        step = f / fp if fp > 0.0 else (ms if f > 0.0 else -ms)
        step = min(max(step, -ms), ms)
        phi -= step
        dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi,
                                                         bh, bw, tphi, th, tw, span)
    ex = dx - cxf
    ey = dy - cyf
    fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
    d = math.sqrt(ex * ex + ey * ey)
    nfx = -ex / d
    nfy = -ey / d
    kap = (nfx * d2x + nfy * d2y) / fp
    return phi, d, cxf, cyf, nfx, nfy, kap, st, ct


@njit_inline
def _penetration(x, CP, Re, dRe, d, cxf, cyf, nfx, nfy, kap, st, ct):  # noqa: ANN001, ANN202
    """w, the contact radius R_j, world normal/tangent, contact point, grad w.

    ``w = R_e(z) + e(beta) - d``; its gradient on (centre, theta, psi, z) uses the closest
    point's sensitivity (module docstring): ``d alpha = kappa t . dc_f``.
    """
    tfx = nfy
    tfy = -nfx
    nx = ct * nfx - st * nfy
    ny = st * nfx + ct * nfy
    tx = ny
    ty = -nx
    e = 0.0
    e1 = 0.0
    e0 = CP[I_EL]
    if e0 != 0.0:  # elliptic ball: e(beta), beta = (angle of -n) - psi
        beta = math.atan2(-ny, -nx) - x[IPSI]
        e = e0 * math.cos(2.0 * beta)
        e1 = -2.0 * e0 * math.sin(2.0 * beta)
    rj = Re + e
    w = rj - d
    cpx = x[IX] - rj * nx
    cpy = x[IY] - rj * ny
    njc = nfx * (-cyf) + nfy * cxf
    tjc = tfx * (-cyf) + tfy * cxf
    gcx = -nx + e1 * kap * tx
    gcy = -ny + e1 * kap * ty
    gth = njc + e1 * (1.0 - kap * tjc)
    return w, rj, tx, ty, cpx, cpy, gcx, gcy, gth, -e1, dRe


@njit_inline
def _tangential(x, CP, ixi, s, mus, mud, fn, v_slip, primary):  # noqa: ANN001, ANN202
    """Tangential force ``F_t``, the stick spring's rate and the friction's dissipation.

    Primary contact: the stick spring-damper (share s of k_t, c_t), sliding at ``mu_d F_n``
    (module docstring); secondary ones: regularised Coulomb friction.
    """
    if primary:
        trial = s * (CP[I_KT] * x[ixi] + CP[I_CT] * v_slip)
        if abs(trial) <= mus * fn:
            ft = -trial
            xid = v_slip
        else:
            ft = -mud * fn if trial > 0.0 else mud * fn
            xid = v_slip if x[ixi] * v_slip < 0.0 else 0.0
        return ft, xid, -ft * v_slip - s * CP[I_KT] * x[ixi] * xid
    ft = -mud * fn * math.tanh(v_slip / CP[I_VREG])
    return ft, 0.0, -ft * v_slip


@njit_inline
def _powers(w, n, p):  # noqa: ANN001, ANN202
    """``(w^n, w^p)`` for w > 0, by square roots for Hertz's n = 3/2 and p = 1/4 or 3/2."""
    r = math.sqrt(w)
    wn = w * r if n == 1.5 else w ** n
    if p == 0.25:
        wp = math.sqrt(r)
    elif p == n:
        wp = wn
    else:
        wp = w ** p
    return wn, wp


@njit_inline
def _edge_sums(e, x, CP, E, cand, ncand, cact, allc, rho0, orders, ccos, csin, bphi, bh, bw,  # noqa: ANN001, ANN202
               tphi, th, tw, span, iters, diag):  # noqa: ANN001
    """One edge's contacts: their sums of forces, torques, powers and energies.

    Returns ``(fx, fy, fz, tb, tf, tpx, tpy, diss, diss_hc, fn_tot, ntouch, e_el, slip,
    xi_dot)``: force on the ball [N], torques on the ball (about z, and in the plane: the
    yaw about the contact normals) and on the frame [N m], dissipated powers (all, and the
    normal damping's) [W], normal force [N], touching contacts, elastic energy [J], the
    primary's slip rate ``v_slip / R_j`` [rad/s] and its stick spring's rate [m/s]. Summed
    per edge, so that two identical edges (each term an exact half) give exactly the sums
    of one (their yaw torques cancel exactly).
    """
    vx = x[IVX]
    vy = x[IVY]
    om = x[IOM]
    thd = x[ITHD]
    k = CP[I_K]
    nexp = CP[I_NEXP]
    s, Re, dRe, arm = _edge_frame(E, e, x[IZ], CP)
    ixi = IXI if e == 0 else IXI2
    ratio = 1.0 if E == 1 else CP[I_R] / Re  # in-plane friction mu R_b / R_e(z)
    mus = CP[I_MUS] * ratio
    mud = CP[I_MUD] * ratio
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tb = 0.0
    tf = 0.0
    tpx = 0.0
    tpy = 0.0
    diss = 0.0
    diss_hc = 0.0
    fn_tot = 0.0
    ntouch = 0.0
    slip = 0.0
    xid0 = 0.0
    e_el = 0.5 * s * CP[I_KT] * x[ixi] * x[ixi]
    diag[D_EFN + e] = 0.0
    diag[D_EFT + e] = 0.0
    tp = tphi[e]
    tt = th[e]
    tv = tw[e]
    sp = span[e]
    for j in range(ncand[e]):
        if j > 0 and not allc and cact[e, j] == 0:
            continue
        phi, d, cxf, cyf, nfx, nfy, kap, st, ct = _candidate_geometry(
            cand[e, j], x, CP, rho0, orders, ccos, csin, bphi, bh, bw, tp, tt, tv, sp, iters)
        w, rj, tx, ty, cpx, cpy, gcx, gcy, gth, gps, gz = _penetration(
            x, CP, Re, dRe, d, cxf, cyf, nfx, nfy, kap, st, ct)
        # slip velocity: ball material point minus frame material point, along t (the yaw
        # about the normal n = (-t_y, t_x) moves a contact off the mid-plane along t)
        v_slip = (tx * vx + ty * vy + om * rj - thd * (cpx * ty - cpy * tx)
                  + arm * (tx * x[IWPY] - ty * x[IWPX]))
        if j == 0:
            slip = v_slip / rj
            diag[D_EW + e] = w
            diag[D_EVS + e] = v_slip
            if e == 0:
                diag[D_PHI0] = phi
                diag[D_D0] = d
        if w <= 0.0:
            continue
        # normal force (Hunt-Crossley family), applied as -F_n grad w
        wdot = gcx * vx + gcy * vy + gth * thd + gps * om + gz * x[IVZ]
        wn, wp = _powers(w, nexp, CP[I_PEXP])
        kw = s * k * wn
        fn = kw + s * CP[I_DAMP] * wp * wdot
        if fn < 0.0:
            fn = 0.0
        e_el += s * k * (wn * w) / (nexp + 1.0)
        fx -= fn * gcx
        fy -= fn * gcy
        fz -= fn * gz
        tf -= fn * gth
        tb -= fn * gps
        dh = (fn - kw) * wdot
        diss_hc += dh
        diss += dh
        fn_tot += fn
        ntouch += 1.0
        ft, xid, dfr = _tangential(x, CP, ixi, s, mus, mud, fn, v_slip, j == 0)
        diss += dfr
        if j == 0:
            xid0 = xid
            diag[D_EFN + e] = fn
            diag[D_EFT + e] = ft
        fx += ft * tx
        fy += ft * ty
        tb += rj * ft
        tpx -= arm * ft * ty
        tpy += arm * ft * tx
        tf -= ft * (cpx * ty - cpy * tx)
        # rolling resistance couple
        om_rel = om - thd
        mr = -CP[I_MUR] * fn * rj * math.tanh(om_rel / CP[I_VR])
        tb += mr
        tf -= mr
        diss -= mr * om_rel
    return fx, fy, fz, tb, tf, tpx, tpy, diss, diss_hc, fn_tot, ntouch, e_el, slip, xid0


@njit
def contact_eval(x, u, CP, E, cand, ncand, cact, allc, rho0, orders, ccos, csin, bphi, bh, bw,  # noqa: ANN001, ANN201
                 tphi, th, tw, span, iters, diag, dxv):  # noqa: ANN001
    """Time derivative of the state into ``dxv`` (:func:`_rhs`, compiled on its own)."""
    return _rhs(x, u, CP, E, cand, ncand, cact, allc, rho0, orders, ccos, csin, bphi, bh, bw,
                tphi, th, tw, span, iters, diag, dxv)


@njit_inline
def _rhs(x, u, CP, E, cand, ncand, cact, allc, rho0, orders, ccos, csin, bphi, bh, bw,  # noqa: ANN001, ANN202
         tphi, th, tw, span, iters, diag, dxv):  # noqa: ANN001
    """Time derivative of the state into ``dxv`` (module docstring); fills ``diag``.

    ``cand[e, :ncand[e]]`` are edge e's contact candidates (``cand[e, 0]`` its primary),
    refined here by ``iters`` Newton iterations each (from the step's exact solution: two
    reach 1e-15 rad). Secondary candidates with ``cact[e, j] == 0`` are left out unless
    ``allc``: the stepper clears the flag only where the contact cannot begin within the
    step (their force is zero throughout), so leaving them out changes nothing.
    """
    m = CP[I_M]
    g = CP[I_G]
    thd = x[ITHD]
    fx = fy = fz = tb = tf = tpx = tpy = diss = diss_hc = fn_tot = ntouch = e_el = slip = 0.0
    dxv[IXI2] = 0.0
    for e in range(E):
        (pfx, pfy, pfz, ptb, ptf, ptpx, ptpy, pdiss, pdhc, pfn, pnt, peel, pslip,
         xid) = _edge_sums(e, x, CP, E, cand, ncand, cact, allc, rho0, orders, ccos, csin,
                           bphi, bh, bw, tphi, th, tw, span, iters, diag)
        fx += pfx
        fy += pfy
        fz += pfz
        tb += ptb
        tf += ptf
        tpx += ptpx
        tpy += ptpy
        diss += pdiss
        diss_hc += pdhc
        fn_tot += pfn
        ntouch += pnt
        e_el += peel
        slip += pslip
        dxv[IXI if e == 0 else IXI2] = xid
    # joint friction (bearing load: contact force on the ball plus the frame's weight)
    lx = fx
    ly = fy + CP[I_MF] * g
    f_load = math.sqrt(lx * lx + ly * ly)
    sg = math.tanh(thd / CP[I_VC])
    tj = -(CP[I_CV] * thd + (CP[I_TC] + CP[I_CL] * f_load) * sg)
    diss -= tj * thd
    dxv[IX] = x[IVX]
    dxv[IY] = x[IVY]
    dxv[IPSI] = x[IOM]
    dxv[ITH] = thd
    dxv[IVX] = fx / m
    dxv[IVY] = fy / m - g
    dxv[IOM] = tb / CP[I_JB]
    dxv[ITHD] = (CP[I_KU] * u + tj + tf) / CP[I_JF]
    dxv[IWIN] = CP[I_KU] * u * thd
    dxv[IWD] = diss
    dxv[ISLIP] = slip / E
    dxv[IWHC] = diss_hc
    dxv[IZ] = x[IVZ]
    dxv[IVZ] = fz / m
    dxv[IWPX] = tpx / CP[I_JB]
    dxv[IWPY] = tpy / CP[I_JB]
    # diagnostics: totals, the deepest primary, the primaries' mean slip and sums
    diag[D_FN] = fn_tot
    diag[D_NTOUCH] = ntouch
    diag[D_EEL] = e_el
    diag[D_W0] = diag[D_EW]
    diag[D_VSLIP] = diag[D_EVS]
    diag[D_FN0] = diag[D_EFN]
    diag[D_FT0] = diag[D_EFT]
    if E == 2:
        diag[D_W0] = max(diag[D_EW], diag[D_EW + 1])
        diag[D_VSLIP] = 0.5 * (diag[D_EVS] + diag[D_EVS + 1])
        diag[D_FN0] += diag[D_EFN + 1]
        diag[D_FT0] += diag[D_EFT + 1]
    return dxv


@njit
def elastic_energy(x, CP, E, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th,  # noqa: ANN001, ANN201
                   tw, span, iters):  # noqa: ANN001
    """``E_el`` [J] of the contact set at x (the sums of :func:`_edge_sums`, in its order).

    Every candidate's ``s k w^(n+1) / (n+1)`` and the stick springs' ``s k_t xi^2 / 2``.
    """
    total = 0.0
    nexp = CP[I_NEXP]
    for e in range(E):
        s, Re, dRe, _ = _edge_frame(E, e, x[IZ], CP)
        ixi = IXI if e == 0 else IXI2
        e_el = 0.5 * s * CP[I_KT] * x[ixi] * x[ixi]
        for j in range(ncand[e]):
            _, d, cxf, cyf, nfx, nfy, kap, st, ct = _candidate_geometry(
                cand[e, j], x, CP, rho0, orders, ccos, csin, bphi, bh, bw, tphi[e], th[e],
                tw[e], span[e], iters)
            w = _penetration(x, CP, Re, dRe, d, cxf, cyf, nfx, nfy, kap, st, ct)[0]
            if w > 0.0:
                wn = _powers(w, nexp, CP[I_PEXP])[0]
                e_el += s * CP[I_K] * (wn * w) / (nexp + 1.0)
        total += e_el
    return total


@njit
def _wrap(a):  # noqa: ANN001, ANN202
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit_inline
def _frame_centre(x):  # noqa: ANN001, ANN202
    """Ball centre in frame coordinates [m]."""
    st = math.sin(x[ITH])
    ct = math.cos(x[ITH])
    return ct * x[IX] + st * x[IY], -st * x[IX] + ct * x[IY]


@njit
def search_contacts(x, CP, E, cand, ncand, cslack, cbase, rho0, orders, ccos, csin, bphi, bh,  # noqa: ANN001, ANN201
                    bw, tphi, th, tw, span, hmax, aspc):  # noqa: ANN001
    """The contact set at x, searched anew.

    Every local minimum of each edge's distance within ``R_e + |e0| + M``
    (:func:`bfr_model.closest_point.local_minima`), deepest first; ``cslack`` their gaps
    ``d - R_e - |e0|`` [m].
    """
    cxf, cyf = _frame_centre(x)
    e0 = abs(CP[I_EL])
    dist = np.empty(NCMAX)
    for e in range(E):
        _, Re, _, _ = _edge_frame(E, e, x[IZ], CP)
        n, pb = local_minima(cxf, cyf, cbase[e], Re + e0 + CP[I_MARGIN], hmax[e], aspc[e],
                             CP[I_MAXSTEP], rho0, orders, ccos, csin, bphi, bh, bw, tphi[e],
                             th[e], tw[e], span[e], cand[e], dist)
        cbase[e] = pb
        ncand[e] = n
        for j in range(n):
            cslack[e, j] = dist[j] - Re - e0


@njit_inline
def resolve_contacts(x, CP, E, cand, ncand, cslack, travel, rho0, orders, ccos, csin, bphi,  # noqa: ANN001, ANN201
                     bh, bw, tphi, th, tw, span):  # noqa: ANN001
    """Re-solve the candidates that may be needed (warm-started Newton).

    Each edge's primary, and every other one whose gap bound ``cslack`` is below
    ``4 travel + RESOLVE_GAP`` (``travel < 0``: all). Returns False if one lost its minimum
    or two met (then the set is searched anew).
    """
    cxf, cyf = _frame_centre(x)
    e0 = abs(CP[I_EL])
    ms = CP[I_MAXSTEP]
    for e in range(E):
        _, Re, _, _ = _edge_frame(E, e, x[IZ], CP)
        for j in range(ncand[e]):
            if j > 0 and travel >= 0.0 and cslack[e, j] > 4.0 * travel + RESOLVE_GAP:
                continue
            phi, d, f, fp, _ = newton_inline(cxf, cyf, cand[e, j], 8, 1e-14, ms, rho0, orders,
                                             ccos, csin, bphi, bh, bw, tphi[e], th[e], tw[e],
                                             span[e])
            if not (fp > 0.0 and abs(f / fp) < 1e-12):
                return False
            cand[e, j] = phi
            cslack[e, j] = d - Re - e0
        for a in range(ncand[e]):  # two candidates on one minimum would count it twice
            for b in range(a):
                if abs(_wrap(cand[e, a] - cand[e, b])) < 1e-7:
                    return False
    return True


@njit_inline
def _rank_primaries(x, CP, E, cand, ncand, cslack, travel):  # noqa: ANN001, ANN202
    """Make each edge's deepest candidate its primary (the one with the stick spring).

    A secondary takes the primary's place when it is closer while the primary is apart, or
    deeper by ``SWAP_DEPTH`` while both touch; the primary's stick spring then starts anew:
    its energy is returned (booked as dissipation by the caller). Only candidates re-solved
    at this step compete (gap bound within ``4 travel + RESOLVE_GAP``: exact).
    """
    booked = 0.0
    near = 4.0 * travel + RESOLVE_GAP
    for e in range(E):
        best = 0
        for j in range(1, ncand[e]):
            if cslack[e, j] <= near and cslack[e, j] < cslack[e, best]:
                best = j
        if best == 0:
            continue
        if cslack[e, 0] <= 0.0 and cslack[e, best] > cslack[e, 0] - SWAP_DEPTH:
            continue
        p = cand[e, 0]
        g = cslack[e, 0]
        cand[e, 0] = cand[e, best]
        cslack[e, 0] = cslack[e, best]
        cand[e, best] = p
        cslack[e, best] = g
        ixi = IXI if e == 0 else IXI2
        s = 1.0 if E == 1 else 0.5
        booked += 0.5 * s * CP[I_KT] * x[ixi] * x[ixi]
        x[ixi] = 0.0
    return booked


@njit
def update_contacts(x, CP, E, cand, ncand, cact, cslack, cbase, sst, rho0, orders, ccos, csin,  # noqa: ANN001, ANN201
                    bphi, bh, bw, tphi, th, tw, span, hmax, aspc, travel, diag, dxv):  # noqa: ANN001
    """Bring the contact set up to state x before a step whose travel bound is ``travel``.

    Event-based (module docstring): a search when requested (``sst[1]``), when the ball
    has travelled ``M / 2`` since the last one (``sst[0]`` plus this step's bound), when a
    re-solve fails, or at every step in exhaustive mode; otherwise only the candidates that
    may be needed are re-solved and the primaries ranked. Returns the elastic energy removed
    by a change of the contact set at fixed state (booked as dissipation by the caller):
    the stick spring of a primary that moved to another minimum, contacts that vanished.
    """
    search = CP[I_EXH] > 0.0 or sst[1] > 0.0 or (
        sst[0] + travel >= 0.5 * CP[I_MARGIN] and (span[0] > 0.0 or span[E - 1] > 0.0))
    if not search:
        search = not resolve_contacts(x, CP, E, cand, ncand, cslack, travel, rho0, orders,
                                      ccos, csin, bphi, bh, bw, tphi, th, tw, span)
    if not search:
        return _rank_primaries(x, CP, E, cand, ncand, cslack, travel)
    # elastic energy of the contact set the last step integrated (as its stages saw it)
    e_old = elastic_energy(x, CP, E, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, tphi,
                           th, tw, span, 2)
    old = np.empty(2)
    cxf, cyf = _frame_centre(x)
    for e in range(E):  # the old primary's minimum at x
        old[e] = newton_closest(cxf, cyf, cand[e, 0], 60, 1e-14, CP[I_MAXSTEP], rho0, orders,
                                ccos, csin, bphi, bh, bw, tphi[e], th[e], tw[e], span[e])[0]
    search_contacts(x, CP, E, cand, ncand, cslack, cbase, rho0, orders, ccos, csin, bphi, bh,
                    bw, tphi, th, tw, span, hmax, aspc)
    sst[0] = 0.0
    sst[1] = 0.0
    sst[4] += 1.0
    for e in range(E):  # the primary moved to another local minimum: its spring starts anew
        if abs(_wrap(cand[e, 0] - old[e])) > 1e-8:
            x[IXI if e == 0 else IXI2] = 0.0
    return e_old - elastic_energy(x, CP, E, cand, ncand, rho0, orders, ccos, csin, bphi, bh,
                                  bw, tphi, th, tw, span, 3)


@njit_inline
def _travel_rate(x, dx, E, CP):  # noqa: ANN001, ANN202
    """Bounds ``(v, a)`` of how fast the gaps can close.

    The ball centre's speed relative to the frame [m/s] and a bound of its rate [m/s^2],
    plus the edges' radii through z.

    With ``c_f = Rot(-theta) c``: ``|c_f'| = |c' - theta' J c|`` and
    ``|c_f''| <= |c''| + |theta''| |c| + 2 |theta'| |c'| + theta'^2 |c|`` (dx: a recent
    derivative; doubled, plus 20 m/s^2). Any point's distance changes by at most the
    centre's travel ``v H + a H^2 / 2`` over a step H (distance is 1-Lipschitz).
    """
    cx = x[IX]
    cy = x[IY]
    thd = x[ITHD]
    vrx = x[IVX] + thd * cy
    vry = x[IVY] - thd * cx
    v = math.sqrt(vrx * vrx + vry * vry)
    rc = math.sqrt(cx * cx + cy * cy)
    sp = math.sqrt(x[IVX] * x[IVX] + x[IVY] * x[IVY])
    a = (math.sqrt(dx[IVX] * dx[IVX] + dx[IVY] * dx[IVY]) + abs(dx[ITHD]) * rc
         + 2.0 * abs(thd) * sp + thd * thd * rc)
    if E == 2:  # |dR_e/dz| <= (d_f/2 + |z|) / R_e
        dz = CP[I_ZE] + abs(x[IZ])
        re = math.sqrt(max(CP[I_RB] * CP[I_RB] - dz * dz, 0.25 * CP[I_RB] * CP[I_RB]))
        kz = dz / re
        v += kz * abs(x[IVZ])
        a += kz * abs(dx[IVZ]) + CP[I_RB] * CP[I_RB] / (re * re * re) * x[IVZ] * x[IVZ]
    return v, 2.0 * a + 20.0


@njit_inline
def _flight_steps(x, CP, E, ncand, cslack, sst, v, a, h, left):  # noqa: ANN001, ANN202
    """Steps of h to take at once: more than one only in free flight (module docstring).

    No stick spring loaded, every candidate apart, and the ball's travel over the long
    step at most half of every gap and of the search budget ``M / 2 - sst[0]``.
    """
    if CP[I_EXH] > 0.0 or CP[I_HFLY] < 2.0 * h or left < 2:
        return 1
    if x[IXI] != 0.0 or x[IXI2] != 0.0:
        return 1
    bound = 0.5 * CP[I_MARGIN] - sst[0]
    for e in range(E):
        for j in range(ncand[e]):
            bound = min(bound, 0.5 * cslack[e, j])
    if bound <= 0.0:
        return 1
    H = 2.0 * bound / (v + math.sqrt(v * v + 2.0 * a * bound))  # v H + a H^2 / 2 = bound
    k = int(min(H, CP[I_HFLY]) / h)
    return max(1, min(k, left))


@njit_inline
def _stick_projection(x, CP, E, diag):  # noqa: ANN001, ANN202
    """After a step: a sliding primary's spring back to ``mu_d F_n / k_t``.

    A lost contact's spring goes to 0 (module docstring); the released energy is booked as
    dissipated.
    """
    released = 0.0
    for e in range(E):
        ixi = IXI if e == 0 else IXI2
        xi = x[ixi]
        if xi == 0.0:  # nothing to project (exactly: the rule keeps a zero spring)
            continue
        s, Re, _, _ = _edge_frame(E, e, x[IZ], CP)
        ratio = 1.0 if E == 1 else CP[I_R] / Re
        fn0 = diag[D_EFN + e]
        if fn0 <= 0.0:
            xi_new = 0.0
        else:
            trial = s * (CP[I_KT] * xi + CP[I_CT] * diag[D_EVS + e])
            lim = CP[I_MUD] * ratio * fn0 / (s * CP[I_KT])
            xi_new = xi
            if abs(trial) > CP[I_MUS] * ratio * fn0 and abs(xi) > lim:
                xi_new = lim if xi > 0.0 else -lim
        if xi_new != xi:
            released += 0.5 * s * CP[I_KT] * (xi * xi - xi_new * xi_new)
            x[ixi] = xi_new
    x[IWD] += released


@njit
def _rk4_step(x, u, H, CP, E, cand, ncand, cact, rho0, orders, ccos, csin, bphi, bh, bw,  # noqa: ANN001, ANN202
              tphi, th, tw, span, diag, K, xs):  # noqa: ANN001
    """One classical RK4 step of x over H [s] with this contact set (in place).

    Stages ``K[0:4]``; then, with a stick spring loaded, the derivative at the new state into
    ``K[4]`` (its ``diag`` serves the projection) and True; else ``K[4] = K[3]`` and False.
    One evaluation site in a stage loop (:func:`_rhs` inlined once).
    """
    for stage in range(5):
        if stage == 0:
            for i in range(NX):
                xs[i] = x[i]
        elif stage < 4:
            c = H if stage == 3 else 0.5 * H
            for i in range(NX):
                xs[i] = x[i] + c * K[stage - 1, i]
        else:
            h6 = H / 6.0
            for i in range(NX):
                x[i] += h6 * (K[0, i] + 2.0 * K[1, i] + 2.0 * K[2, i] + K[3, i])
            if x[IXI] == 0.0 and x[IXI2] == 0.0:
                for i in range(NX):
                    K[4, i] = K[3, i]
                return False
            for i in range(NX):
                xs[i] = x[i]
        _rhs(xs, u, CP, E, cand, ncand, cact, False, rho0, orders, ccos, csin, bphi, bh, bw,
             tphi, th, tw, span, 2, diag, K[stage])
    return True


@njit
def contact_steps(x0, u, h, nsteps, CP, E, cand, ncand, cact, cslack, cbase, sst, rho0,  # noqa: ANN001, ANN201
                  orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, hmax, aspc):  # noqa: ANN001
    """Advance the contact model by ``nsteps`` steps of ``h`` [s] under command u.

    Before every step the contact set is brought up to date (:func:`update_contacts`); in
    free flight several steps are taken at once (:func:`_flight_steps`), always whole
    multiples of h; after a step a sliding or lost primary's stick spring is projected
    (:func:`_stick_projection`). Energy removed by contact-set changes and projections is
    added to ``W_diss``. ``sst[2]`` counts the steps taken, ``sst[3]`` the time they covered
    [s], ``sst[4]`` the searches. Returns the final state; the contact set arrays are updated
    in place.
    """
    x = x0.copy()
    xs = np.empty(NX)
    K = np.empty((5, NX))
    diag = np.zeros(D_SIZE)
    contact_eval(x, u, CP, E, cand, ncand, cact, True, rho0, orders, ccos, csin, bphi, bh, bw,
                 tphi, th, tw, span, 2, diag, K[4])
    done = 0
    while done < nsteps:
        v, a = _travel_rate(x, K[4], E, CP)
        x[IWD] += update_contacts(x, CP, E, cand, ncand, cact, cslack, cbase, sst, rho0,
                                  orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, hmax,
                                  aspc, v * h + 0.5 * a * h * h, diag, xs)
        k = _flight_steps(x, CP, E, ncand, cslack, sst, v, a, h, nsteps - done)
        H = k * h
        travel = v * H + 0.5 * a * H * H
        for e in range(E):
            for j in range(ncand[e]):
                cact[e, j] = 1 if (CP[I_EXH] > 0.0 or cslack[e, j] <= travel) else 0
        if _rk4_step(x, u, H, CP, E, cand, ncand, cact, rho0, orders, ccos, csin, bphi, bh,
                     bw, tphi, th, tw, span, diag, K, xs):
            _stick_projection(x, CP, E, diag)
        for e in range(E):
            for j in range(ncand[e]):
                cslack[e, j] -= travel
        sst[0] += travel
        sst[2] += 1.0
        sst[3] += H
        done += k
    return x


def restitution(d: float, k: float, n: float, p: float, m: float, v: float) -> float:
    """Coefficient of restitution of a normal impact at speed v [m/s] (1-DOF, exact).

    Integrates ``m w_dd = -max(0, k w^n + d w^p w_dot)`` from ``w = 0``, ``w_dot = v`` until
    the ball separates (w back to 0, or the force vanishing while w shrinks, then the
    remaining free rebound); returns ``-w_dot_out / v``.
    """

    def f(_t: float, y: FloatArray) -> FloatArray:
        w = max(y[0], 0.0)
        fn = k * w**n + d * w**p * y[1] if w > 0.0 else 0.0
        return np.array([y[1], -max(fn, 0.0) / m])

    def out(_t: float, y: FloatArray) -> float:
        return y[0]

    out.terminal = True
    out.direction = -1
    t_c = 3.0 * (m / k) ** (1.0 / (n + 1.0)) * v ** ((1.0 - n) / (n + 1.0)) * 4.0
    sol = solve_ivp(f, (0.0, t_c * 20), [0.0, v], events=out, rtol=1e-10, atol=1e-18,
                    max_step=t_c / 200)
    w_dot = sol.y_events[0][0][1] if sol.t_events[0].size else sol.y[1, -1]
    return float(-w_dot / v)


@functools.lru_cache(maxsize=64)
def damping_for_restitution(k: float, n: float, p: float, m: float, e: float, v: float
                            ) -> float:
    """Damping coefficient d of ``F = k w^n + d w^p w_dot`` giving restitution e at speed v.

    Bisection in log d on :func:`restitution` (decreasing in d), to 1e-6 relative; 0 for
    e = 1. For ``p = (n - 1) / 2`` the restitution is the same at every impact speed.
    """
    if e >= 1.0:
        return 0.0
    hi = 1.0
    while restitution(hi, k, n, p, m, v) > e:
        hi *= 10.0
        if hi > 1e40:
            raise ValueError("cannot reach the restitution with this damping law")
    lo = hi / 10.0
    while restitution(lo, k, n, p, m, v) < e:
        lo /= 10.0
        if lo < 1e-40:
            return 0.0
    while hi / lo > 1.0 + 1e-6:
        mid = math.sqrt(lo * hi)
        if restitution(mid, k, n, p, m, v) > e:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


@dataclass
class ContactResult:
    """A contact-model trajectory sampled at the output interval.

    Attributes
    ----------
    t : ndarray
        Times [s], shape (n,).
    x : ndarray
        Contact states (module docstring), shape (n, NX).
    u : ndarray
        Command held from t [N m].
    rigid : ndarray
        Rigid-equivalent states ``[theta, phi, theta_dot, phi_dot]`` (closest point), (n, 4).
    normal_force : ndarray
        Total normal force [N].
    penetration : ndarray
        Penetration w of the primary contact [m] (< 0: no contact).
    slip_velocity : ndarray
        Slip velocity at the primary contact [m/s].
    energy : ndarray
        ``E_kin + E_pot + E_el`` [J].
    wall_time : float
        Integration wall time [s].
    info : dict
        Step size, steps, notes.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    rigid: FloatArray
    normal_force: FloatArray
    penetration: FloatArray
    slip_velocity: FloatArray
    energy: FloatArray
    wall_time: float
    info: dict = field(default_factory=dict)

    @property
    def balance_error(self) -> FloatArray:
        """``E(t) - E(0) - (W_in - W_diss)`` [J]: zero up to the integration error."""
        return self.energy - self.energy[0] - (self.x[:, IWIN] - self.x[:, IWD]
                                               - (self.x[0, IWIN] - self.x[0, IWD]))

    @property
    def real_time_factor(self) -> float:
        """Simulated time per wall time [-]."""
        return float((self.t[-1] - self.t[0]) / max(self.wall_time, 1e-12))


class ContactModel:
    """The force-based contact model of one parameter set (module docstring).

    Parameters
    ----------
    params : RigParams
        Physical parameters; ``contact.*`` sets the contact law and the steps,
        ``track.asperity_*`` adds sharp bumps the rigid model cannot carry, on one plate edge
        or both (``track.asperity_edge``).
    time_step : float, optional
        Override of ``contact.time_step`` [s].
    edges : int, optional
        1: the two identical plate edges act as one contact (the ball's in-plane disc of
        radius R); 2: each edge its own contacts and the ball's lateral position z (module
        docstring). Default: 2 when an asperity sits on one edge only, else 1.
    exhaustive : bool
        Search the contact set and evaluate every candidate at every step, no free-flight
        steps: the reference the event-based stepping is tested against.
    margin : float
        Reach margin M of the contact search [m] (:func:`bfr_model.layout.with_contact`).
    """

    def __init__(self, params: RigParams, time_step: float | None = None, *,
                 edges: int | None = None, exhaustive: bool = False,
                 margin: float = 4e-4) -> None:
        if params.frame.wobble != 0.0:
            raise ValueError("the contact model is planar: frame.wobble is not supported "
                             "(use the rigid model for the wobbling frame)")
        one_sided = any(e != 0 for e in params.track.asperity_edges())
        if edges is None:
            edges = 2 if one_sided else 1
        if edges not in (1, 2):
            raise ValueError(f"edges must be 1 or 2, got {edges!r}")
        if edges == 1 and one_sided:
            raise ValueError("asperities on one plate edge only (track.asperity_edge) need "
                             "the two-edge contact (edges=2)")
        self.params = params
        self.edges = int(edges)
        self.datas: list[ContourData] = ([contour_data(params)] if edges == 1 else
                                         [contour_data(params, 1), contour_data(params, 2)])
        self.data: ContourData = self.datas[0]
        self.curve = OffsetCurve.from_params(params)  # bumps, no asperities: conversions
        c = params.contact
        damping = damping_for_restitution(params.contact_stiffness, c.exponent,
                                          c.damping_exponent, params.ball.mass,
                                          c.restitution, c.restitution_speed)
        w_min = min(*(d.min_width for d in self.datas), 0.2)
        self.CP = with_contact(rigid_vector(params), params, damping=damping,
                               search_step=0.25 * w_min, margin=margin,
                               exhaustive=exhaustive)
        self.time_step = float(time_step or c.time_step)
        # per-edge asperity tables (two rows always; one used with one edge)
        rows = [*self.datas, self.datas[-1]][:2]
        n = max(d.tphi.size for d in rows)
        self.tphi = np.full((2, n), np.inf)
        self.th = np.zeros((2, n))
        self.tw = np.ones((2, n))
        for e, d in enumerate(rows):
            self.tphi[e, :d.tphi.size] = d.tphi
            self.th[e, :d.th.size] = d.th
            self.tw[e, :d.tw.size] = d.tw
        self.span = np.array([d.span for d in rows])
        self.hmax = np.array([d.asperity_height for d in rows])
        self.aspc = np.array([0.25 * min(d.asperity_min_width, 4.0) for d in rows])
        # the contact set (module docstring)
        self.cand = np.zeros((2, NCMAX))
        self.cslack = np.zeros((2, NCMAX))
        self.cact = np.ones((2, NCMAX), dtype=np.int8)
        self.ncand = np.zeros(2, dtype=np.int64)
        self.cbase = np.zeros(2)
        self.sst = np.zeros(5)
        d0 = self.data
        self._geo = (d0.rho0, d0.orders, d0.ccos, d0.csin, d0.bphi, d0.bh, d0.bw, self.tphi,
                     self.th, self.tw, self.span)

    # -- contact set -----------------------------------------------------------------------
    def _set_arrays(self) -> tuple:
        return (self.cand, self.ncand, self.cact, self.cslack, self.cbase, self.sst)

    def reset(self, x: ArrayLike, phi_guess: float | None = None) -> None:
        """Initialise the contact set for state x (global closest point if no guess).

        Each edge starts from its closest point; the next step searches the set anew.
        """
        x = np.asarray(x, float)
        st, ct = math.sin(x[ITH]), math.cos(x[ITH])
        cf = np.array([ct * x[IX] + st * x[IY], -st * x[IX] + ct * x[IY]])
        self.cand[:] = 0.0
        self.cslack[:] = 0.0
        self.ncand[:] = 0
        for e, data in enumerate(self.datas):
            phi, d = closest_point(data, cf, phi0=phi_guess)
            self.cand[e, 0] = phi
            self.cbase[e] = phi
            self.ncand[e] = 1
            self.cslack[e, 0] = d - self._edge_radius(e, float(x[IZ])) - abs(self.CP[I_EL])
        self.sst[:2] = (0.0, 1.0)

    def _edge_radius(self, e: int, z: float) -> float:
        if self.edges == 1:
            return float(self.CP[I_R])
        ze = self.CP[I_ZE] if e == 0 else -self.CP[I_ZE]
        return math.sqrt(self.CP[I_RB] ** 2 - (z - ze) ** 2)

    def snapshot(self) -> tuple[np.ndarray, ...]:
        """A copy of the contact set (to restart a step from the same state)."""
        return tuple(a.copy() for a in self._set_arrays())

    def restore(self, snap: tuple[np.ndarray, ...]) -> None:
        """Restore a contact set taken by :meth:`snapshot`."""
        for a, b in zip(self._set_arrays(), snap, strict=True):
            a[...] = b

    def follow(self, x: ArrayLike, search: bool = False) -> float:
        """Bring the contact set up to state x: every candidate re-solved, or searched anew.

        Returns the elastic energy a search removed (as the stepper books it); x itself is
        not changed. For scipy's solvers on :meth:`rhs`, whose contact set must follow the
        state (the bench's baselines).
        """
        xx = np.array(x, float)
        if self.ncand[0] == 0:
            self.reset(xx)
        if not search and resolve_contacts(xx, self.CP, self.edges, self.cand, self.ncand,
                                           self.cslack, -1.0, *self._geo):
            return 0.0
        self.sst[1] = 1.0
        diag = np.zeros(D_SIZE)
        return float(update_contacts(xx, self.CP, self.edges, self.cand, self.ncand,
                                     self.cact, self.cslack, self.cbase, self.sst,
                                     *self._geo, self.hmax, self.aspc, 0.0, diag,
                                     np.empty(NX)))

    # -- conversions -----------------------------------------------------------------------
    def state_from_rigid(self, xr: ArrayLike, u: float = 0.0, preload: bool = True
                         ) -> FloatArray:
        """Contact state of the ball rolling on the track at rigid state xr.

        ``xr = [theta, phi, theta_dot, phi_dot]``; the ball centre and its velocity are the
        rigid model's (:func:`bfr_model.dynamics.curve_terms`, elliptic ball included, its spin
        angle chosen so that both models' ``beta`` agree). With ``preload`` the ball is
        pressed in by the static penetration ``(F_n / k)^(1/n)`` of the rigid model's
        normal force and the stick spring carries the rigid model's tangential force, so
        the contact starts in equilibrium. Also resets the contact candidates.
        """
        xr = np.asarray(xr, float)
        th, ph, thd, phd = (float(v) for v in xr[:4])
        rp = self.params.replace(**{"track.asperity_phi": [], "track.asperity_height": [],
                                    "track.asperity_width": [], "track.asperity_edge": []})
        rm = RigidModel(rp)
        px, py, p1x, p1y, p2x, p2y, nx, ny, lam, _ = (
            float(v) for v in curve_terms(ph, *rm.kernel_args))
        p = np.array([px, py])
        p1 = np.array([p1x, p1y])
        p2 = np.array([p2x, p2y])
        nf = np.array([nx, ny])
        R = self.CP[I_R]
        w0 = 0.0
        xi0 = 0.0
        if preload:
            thdd, phdd, _, _, fn = (float(v) for v in
                                    rigid_terms(th, ph, thd, phd, float(u), *rm.kernel_args))
            if fn > 0.0:
                w0 = (fn / self.CP[I_K]) ** (1.0 / self.CP[I_NEXP])
            # tangential force of the rigid model: t . m (r_dd + g y) (frame coordinates)
            acc = (thdd * np.array([-p[1], p[0]]) - thd**2 * p
                   + 2 * thd * phd * np.array([-p1[1], p1[0]]) + p2 * phd**2 + p1 * phdd)
            gy = self.CP[I_G] * np.array([math.sin(th), math.cos(th)])
            tf = np.array([nf[1], -nf[0]])
            ft = float(tf @ (self.CP[I_M] * (acc + gy)))
            xi0 = -ft / self.CP[I_KT]
        st, ct = math.sin(th), math.cos(th)
        rot = np.array([[ct, -st], [st, ct]])
        c = rot @ (p - w0 * nf)
        v = thd * np.array([-c[1], c[0]]) + rot @ (p1 * phd)
        x = np.zeros(NX)
        x[IX], x[IY] = c
        x[IVX], x[IVY] = v
        x[ITH] = th
        x[ITHD] = thd
        x[IOM] = thd - lam * phd / R
        x[IXI] = xi0
        if self.edges == 2:  # each edge's spring carries half the force at half the stiffness
            x[IXI2] = xi0
        if self.CP[I_EL] != 0.0:
            # rigid: beta = beta0 + s(phi) / R + nu(phi); contact: beta = theta + nu + pi - psi
            x[IPSI] = (th + math.pi - self.params.ball.ellipse_phase
                       - float(self.curve.arc_length(ph)) / R)
        self.reset(x, phi_guess=ph)
        return x

    def _ellipse_offset(self, x: FloatArray, nf: FloatArray) -> float:
        """Elliptic ball's e(beta) [m] for contact normal nf (frame coordinates) at state x."""
        e0 = self.CP[I_EL]
        if e0 == 0.0:
            return 0.0
        beta = x[ITH] + math.atan2(-nf[1], -nf[0]) - x[IPSI]
        return float(e0 * math.cos(2.0 * beta))

    def rigid_state(self, x: ArrayLike, phi0: float | None = None) -> FloatArray:
        """Rigid-equivalent ``[theta, phi, theta_dot, phi_dot]`` of contact state(s) x.

        phi is the closest contour point's angle (exact solve, warm-started from the
        previous row, the first row from ``phi0`` or the current primary contact), unwrapped
        along the rows; phi_dot the ball centre's velocity relative to the frame along the
        tangent, over ``lam = ds/dphi``.
        """
        xs = np.atleast_2d(np.asarray(x, float))
        out = np.empty((xs.shape[0], 4))
        guess = phi0 if phi0 is not None else (
            float(self.cand[0, 0]) if self.ncand[0] > 0 else None)
        for i, xi in enumerate(xs):
            st, ct = math.sin(xi[ITH]), math.cos(xi[ITH])
            cf = np.array([ct * xi[IX] + st * xi[IY], -st * xi[IX] + ct * xi[IY]])
            phi, _ = closest_point(self.data, cf, phi0=guess)
            # unwrap phi next to the guess
            if guess is not None:
                phi = guess + (phi - guess + math.pi) % (2 * math.pi) - math.pi
            guess = phi
            vrel = np.array([xi[IVX] + xi[ITHD] * xi[IY], xi[IVY] - xi[ITHD] * xi[IX]])
            vf = np.array([ct * vrel[0] + st * vrel[1], -st * vrel[0] + ct * vrel[1]])
            tf = self.curve.tangent(phi)
            lam = float(self.curve.speed(phi))
            out[i] = (xi[ITH], phi, xi[ITHD], float(tf @ vf) / lam)
        return out[0] if np.ndim(x) == 1 else out

    # -- dynamics --------------------------------------------------------------------------
    def _eval(self, x: FloatArray, u: float) -> tuple[FloatArray, FloatArray]:
        diag = np.zeros(D_SIZE)
        dx = np.empty(NX)
        x = np.asarray(x, float)
        if self.ncand[0] == 0:
            self.reset(x)
        contact_eval(x, float(u), self.CP, self.edges, self.cand, self.ncand, self.cact, True,
                     *self._geo, 3, diag, dx)
        return dx, diag

    def rhs(self, t: float, x: FloatArray, u: float) -> FloatArray:
        """Time derivative at x with the current contact set (for scipy's solvers)."""
        return self._eval(x, u)[0]

    def diagnostics(self, x: ArrayLike, u: float = 0.0) -> dict:
        """Normal force, penetration, slip velocity, contact count and elastic energy at x.

        ``penetration`` is the deepest primary's w (< 0: apart); ``edge_*`` lists give each
        edge's primary contact (one entry with one edge).
        """
        _, d = self._eval(np.asarray(x, float), u)
        ed = range(self.edges)
        return {"normal_force": d[D_FN], "primary_normal_force": d[D_FN0],
                "penetration": d[D_W0], "slip_velocity": d[D_VSLIP],
                "contacts": int(d[D_NTOUCH]), "tangential_force": d[D_FT0], "phi": d[D_PHI0],
                "distance": d[D_D0], "elastic_energy": d[D_EEL],
                "edge_normal_force": [float(d[D_EFN + e]) for e in ed],
                "edge_penetration": [float(d[D_EW + e]) for e in ed],
                "edge_slip_velocity": [float(d[D_EVS + e]) for e in ed]}

    def energy(self, x: ArrayLike) -> tuple[float, float, float]:
        """(kinetic, potential, elastic) energy [J] at state x (current contact set)."""
        x = np.asarray(x, float)
        p = self.params
        kin = 0.5 * (p.ball.mass * (x[IVX] ** 2 + x[IVY] ** 2 + x[IVZ] ** 2)
                     + p.ball.inertia * (x[IOM] ** 2 + x[IWPX] ** 2 + x[IWPY] ** 2)
                     + p.frame.inertia * x[ITHD] ** 2)
        pot = p.ball.mass * self.CP[I_G] * x[IY]
        return kin, pot, self.diagnostics(x)["elastic_energy"]

    def step(self, x: ArrayLike, u: float, dt: float, n: int = 1) -> FloatArray:
        """Advance x by n intervals of dt [s] under a held command u [N m].

        Steps of at most ``time_step`` (several at once in free flight); the contact set is
        initialised on first use.
        """
        x = np.asarray(x, float)
        if self.ncand[0] == 0:
            self.reset(x)
        m = max(1, math.ceil(dt / self.time_step - 1e-9))
        return contact_steps(x, float(u), dt / m, int(n * m), self.CP, self.edges,
                             *self._set_arrays(), *self._geo, self.hmax, self.aspc)

    def record(self, x: ArrayLike, u: float = 0.0) -> tuple[float, float, float, float]:
        """Diagnostics at x with the current contact set (call right after :meth:`step`).

        Returns
        -------
        tuple
            normal force [N], penetration [m], slip velocity [m/s], E_kin + E_pot + E_el [J].
        """
        d = self.diagnostics(x, u)
        kin, pot, _ = self.energy(x)
        return (d["normal_force"], d["penetration"], d["slip_velocity"],
                kin + pot + d["elastic_energy"])

    def simulate(self, x0: ArrayLike, duration: float, torque: object = 0.0,
                 dt: float = 1e-3) -> ContactResult:
        """Open-loop run from contact state x0 under ``torque`` (float or ``u(t)``).

        Output every dt [s]; the command is held over each dt.
        """
        n = round(duration / dt)
        t = np.arange(n + 1) * dt
        u_of_t = torque if callable(torque) else (lambda _t, _u=float(torque): _u)
        u = np.array([float(u_of_t(ti)) for ti in t])
        xs = np.empty((n + 1, NX))
        rec = np.empty((n + 1, 4))
        xs[0] = x0
        if self.ncand[0] == 0:
            self.reset(xs[0])
        phi_start = float(self.cand[0, 0])
        rec[0] = self.record(xs[0], u[0])
        wall = 0.0
        for i in range(n):
            start = time.perf_counter()
            xs[i + 1] = self.step(xs[i], u[i], dt)
            wall += time.perf_counter() - start
            rec[i + 1] = self.record(xs[i + 1], u[i])
        return ContactResult(t=t, x=xs, u=u, rigid=self.rigid_state(xs, phi0=phi_start),
                             normal_force=rec[:, 0], penetration=rec[:, 1],
                             slip_velocity=rec[:, 2], energy=rec[:, 3], wall_time=wall,
                             info={"time_step": self.time_step,
                                   "stiffness": float(self.CP[I_K])})
