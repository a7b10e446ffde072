"""Force-based contact model of the ball on the frame (seed chapter 4, recommendation 1).

The ball is a free planar body with spin, held to the frame by contact forces, so it can
bounce, lose contact and slip (seed Fig. 4.1-4.2). In the frame's plane the ball touches
the two plate edges at the rolling radius R, so it is a disc of radius R on the contour.

State (world coordinates, DEVELOPERS.md), ``x`` of length :data:`NX`::

    x, y         ball centre [m]                      vx, vy    its velocity [m/s]
    psi          ball spin angle, CCW [rad]           omega     its rate [rad/s]
    theta        frame angle [rad]                    theta_dot its rate [rad/s]
    xi           stick-spring extension at the primary contact [m]
    W_in         motor work [J]      W_diss  dissipated energy [J]
    slip         integral of the slip rate v_slip / R [rad]
    W_hc         energy dissipated by the Hunt-Crossley damping alone [J]

Equations of motion (seed eqs. 4.2-4.7, Newton-Euler):

    m r_ddot = sum_j F_j - m g_e y,   J_b psi_ddot = sum_j T_j,
    J_f theta_ddot = k_u u + T_joint + sum_j T_frame,j

Contacts j are the local minima of the distance d from the ball centre to the contour
(:mod:`bfr_model.closest_point`, exact Newton, warm-started) within reach; several exist at
the foot of a sharp bump. The penetration is ``w = R + e(beta) - d`` with ``e`` the elliptic
ball's radius variation (``e0 cos 2 beta``, beta the contact direction in ball coordinates;
0 for a round ball). Normal force, Hunt and Crossley (seed eq. 4.15 with p = n, q = 1):

    F_n = max(0, k w^n (1 + alpha w_dot)),   w > 0,     n = 3/2

applied as the generalised force ``-F_n grad w`` on (centre, theta, psi). For a round ball
this is ``F_n n`` on the ball at the contact point and its reaction on the frame; the
gradient form keeps the elliptic ball's torques consistent. ``grad w`` uses the closest
point's sensitivity: with ``f' = |delta'|^2 + (delta - c) . delta''`` and
``kappa = n . delta'' / f'``, ``d alpha = kappa t . dc_f`` (alpha the normal's angle).

Stored elastic energy ``k w^(n+1) / (n+1)``; the damping dissipates
``(F_n - k w^n) w_dot >= 0`` (both when the force is ``k w^n (1 + alpha w_dot)``, giving
``alpha k w^n w_dot^2``, and when it is clipped to 0 on fast rebound, ``w_dot < 0``).

Tangential force at the primary contact (the deepest one; replaces the seed's discrete
eqs. 4.23-4.28): a stick spring-damper, ``trial = k_t xi + c_t v_slip``. The friction
coefficients in this in-plane law are the edges' ``mu`` times ``R_b / R``: each edge presses
with N along a line inclined by gamma (``cos gamma = R / R_b``) to the plane, so
``F_n = 2 N cos gamma`` while the friction available is ``2 mu N`` (the wedge effect of the
groove). Stick while ``|trial| <= mu_s F_n`` (``F_t = -trial``, ``xi_dot = v_slip``);
otherwise slide with
``F_t = -mu_d F_n sgn(trial)``, the spring frozen while loading (``xi_dot = 0``) and
following the slip while unloading (``xi_dot = v_slip`` when ``xi v_slip < 0``). That rule
makes the dissipation ``-F_t v_slip - k_t xi xi_dot`` non-negative in every case; after each
step a sliding spring is reset to ``mu_d F_n / k_t`` (and a lost contact's to 0), booking
the released spring energy as dissipated. Secondary contacts (brief, at bump feet) use
regularised Coulomb friction ``-mu_d F_n tanh(v_slip / v_reg)``. The slip velocity of the
contact point (ball material point minus frame material point, along the tangent t) is

    v_slip = t . v + omega R_j - theta_dot (c_pt x t)_z,   R_j = R + e,  c_pt = c - R_j n

so that rolling without slip is ``omega = theta_dot - s_dot / R`` (DEVELOPERS.md). The
force ``F_t t`` acts on the ball, ``R_j F_t`` on its spin, ``-(c_pt x F_t t)_z`` on the frame.

Rolling resistance: a couple ``-mu_rol F_n R_j tanh(omega_rel / v_r)`` on the ball and its
reaction on the frame (``omega_rel = omega - theta_dot``; power ``mu_rol F_n |s_dot|`` as the
rigid model's). Joint friction as the rigid model's, with
``F_load = |sum_j F_j + m_f g_e y|`` explicit here.

Energy balance, checked by the tests: ``E_kin + E_pot + E_el - E(0) = W_in - W_diss`` with
``E_el = sum_j k w_j^(n+1) / (n+1) + k_t xi^2 / 2``.

Integration: the contact modes are near 1.5 kHz (Hertz stiffness at the ball's weight) and
the stick spring near 1.4 kHz; a compiled fixed-step RK4 at ``contact.time_step`` (2e-5 s,
about 30 steps per contact period) resolves them with an energy error far below the
physical dissipation, at several times real time (``bfr analyze bounce`` reports the
factor). :meth:`ContactModel.rhs` also works with scipy's implicit solvers for checks.

Not modelled: the wobbling frame (``frame.wobble``; the contact model is planar, a shaft
pitch is the in-plane gravity ``g cos eps``), and the two edges' individual contacts (they
act together, seed recommendation 3).
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
    newton_closest,
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
    I_G,
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
    I_TC,
    I_VC,
    I_VR,
    I_VREG,
    rigid_vector,
    with_contact,
)
from bfr_model.params import RigParams

__all__ = ["NX", "ContactModel", "ContactResult", "contact_eval", "contact_steps"]

FloatArray = NDArray[np.float64]

# state layout
IX, IY, IPSI, ITH, IVX, IVY, IOM, ITHD, IXI, IWIN, IWD, ISLIP, IWHC = range(13)
NX = 13
# parameter vector: the shared layout of bfr_model.layout (rigid entries + contact block)
NCMAX = 8  # at most this many simultaneous contact candidates
# diagnostics layout (contact_eval's diag output)
D_FN, D_FN0, D_W0, D_VSLIP, D_NTOUCH, D_FT0, D_PHI0, D_D0, D_EEL = range(9)
D_SIZE = 9


@njit_inline
def _candidate_geometry(j, x, cand, CP, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,  # noqa: ANN001, ANN202
                        aidx, na, iters):  # noqa: ANN001
    """Refine candidate j by Newton and return its contact geometry (world frame)."""
    th = x[ITH]
    st = math.sin(th)
    ct = math.cos(th)
    cxf = ct * x[IX] + st * x[IY]
    cyf = -st * x[IX] + ct * x[IY]
    ms = CP[I_MAXSTEP]
    phi = cand[j]
    dx, dy, d1x, d1y, d2x, d2y = contour_point_terms(phi, rho0, orders, ccos, csin, bphi, bh,
                                                     bw, aphi, ah, aw, aidx, na)
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
                                                         bh, bw, aphi, ah, aw, aidx, na)
    ex = dx - cxf
    ey = dy - cyf
    fp = d1x * d1x + d1y * d1y + ex * d2x + ey * d2y
    d = math.sqrt(ex * ex + ey * ey)
    nfx = -ex / d
    nfy = -ey / d
    tfx = nfy
    tfy = -nfx
    kap = (nfx * d2x + nfy * d2y) / fp
    return phi, d, cxf, cyf, nfx, nfy, tfx, tfy, kap, st, ct


@njit
def contact_eval(x, u, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,  # noqa: ANN001, ANN201
                 aidx, na, iters, diag, dxv):  # noqa: ANN001
    """Time derivative of the state into ``dxv`` (module docstring); fills ``diag``.

    ``cand[:ncand]`` are the contact candidates' contour angles (``cand[0]`` the primary),
    refined here by ``iters`` Newton iterations each (from the step's exact solution: two
    iterations reach 1e-15 rad, the step moving phi by about 1e-4 rad).
    """
    m = CP[I_M]
    R = CP[I_R]
    g = CP[I_G]
    k = CP[I_K]
    nexp = CP[I_NEXP]
    e0 = CP[I_EL]
    vx = x[IVX]
    vy = x[IVY]
    om = x[IOM]
    thd = x[ITHD]
    fx = 0.0
    fy = 0.0
    tb = 0.0
    tf = 0.0
    diss = 0.0
    diss_hc = 0.0
    xi_dot = 0.0
    slip_rate = 0.0
    fn_tot = 0.0
    ntouch = 0.0
    e_el = 0.5 * CP[I_KT] * x[IXI] * x[IXI]
    for j in range(ncand):
        phi, d, cxf, cyf, nfx, nfy, tfx, tfy, kap, st, ct = _candidate_geometry(
            j, x, cand, CP, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, na,
            iters)
        # world normal and tangent
        nx = ct * nfx - st * nfy
        ny = st * nfx + ct * nfy
        tx = ny
        ty = -nx
        # elliptic ball: e(beta), beta = (angle of -n) - psi
        e = 0.0
        e1 = 0.0
        if e0 != 0.0:
            beta = math.atan2(-ny, -nx) - x[IPSI]
            e = e0 * math.cos(2.0 * beta)
            e1 = -2.0 * e0 * math.sin(2.0 * beta)
        Rj = R + e
        w = Rj - d
        # contact point and slip velocity
        cpx = x[IX] - Rj * nx
        cpy = x[IY] - Rj * ny
        v_slip = tx * vx + ty * vy + om * Rj - thd * (cpx * ty - cpy * tx)
        if j == 0:
            slip_rate = v_slip / Rj
            diag[D_W0] = w
            diag[D_VSLIP] = v_slip
            diag[D_PHI0] = phi
            diag[D_D0] = d
            diag[D_FN0] = 0.0
            diag[D_FT0] = 0.0
        if w <= 0.0:
            continue
        # gradient of w: d/dc (world), d/dtheta, d/dpsi
        njc = nfx * (-cyf) + nfy * cxf
        tjc = tfx * (-cyf) + tfy * cxf
        gcx = -nx + e1 * kap * tx
        gcy = -ny + e1 * kap * ty
        gth = njc + e1 * (1.0 - kap * tjc)
        gps = -e1
        wdot = gcx * vx + gcy * vy + gth * thd + gps * om
        kw = k * w ** nexp
        fn = kw + CP[I_DAMP] * w ** CP[I_PEXP] * wdot
        if fn < 0.0:
            fn = 0.0
        e_el += k * w ** (nexp + 1.0) / (nexp + 1.0)
        fx -= fn * gcx
        fy -= fn * gcy
        tf -= fn * gth
        tb -= fn * gps
        dh = (fn - kw) * wdot
        diss_hc += dh
        diss += dh
        fn_tot += fn
        ntouch += 1.0
        # tangential force
        if j == 0:
            trial = CP[I_KT] * x[IXI] + CP[I_CT] * v_slip
            if abs(trial) <= CP[I_MUS] * fn:
                ft = -trial
                xi_dot = v_slip
            else:
                ft = -CP[I_MUD] * fn if trial > 0.0 else CP[I_MUD] * fn
                xi_dot = v_slip if x[IXI] * v_slip < 0.0 else 0.0
            diss += -ft * v_slip - CP[I_KT] * x[IXI] * xi_dot
            diag[D_FN0] = fn
            diag[D_FT0] = ft
        else:
            ft = -CP[I_MUD] * fn * math.tanh(v_slip / CP[I_VREG])
            diss += -ft * v_slip
        fx += ft * tx
        fy += ft * ty
        tb += Rj * ft
        tf -= ft * (cpx * ty - cpy * tx)
        # rolling resistance couple
        om_rel = om - thd
        mr = -CP[I_MUR] * fn * Rj * math.tanh(om_rel / CP[I_VR])
        tb += mr
        tf -= mr
        diss -= mr * om_rel
    # joint friction (bearing load: contact force on the ball plus the frame's weight)
    lx = fx
    ly = fy + CP[I_MF] * g
    f_load = math.sqrt(lx * lx + ly * ly)
    sg = math.tanh(thd / CP[I_VC])
    tj = -(CP[I_CV] * thd + (CP[I_TC] + CP[I_CL] * f_load) * sg)
    diss -= tj * thd
    dxv[IX] = vx
    dxv[IY] = vy
    dxv[IPSI] = om
    dxv[ITH] = thd
    dxv[IVX] = fx / m
    dxv[IVY] = fy / m - g
    dxv[IOM] = tb / CP[I_JB]
    dxv[ITHD] = (CP[I_KU] * u + tj + tf) / CP[I_JF]
    dxv[IXI] = xi_dot
    dxv[IWIN] = CP[I_KU] * u * thd
    dxv[IWD] = diss
    dxv[ISLIP] = slip_rate
    dxv[IWHC] = diss_hc
    diag[D_FN] = fn_tot
    diag[D_NTOUCH] = ntouch
    diag[D_EEL] = e_el
    return dxv


@njit
def _wrap(a):  # noqa: ANN001, ANN202
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit
def update_candidates(x, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah,  # noqa: ANN001, ANN202
                      aw, aidx, na, diag, dxv, full):  # noqa: ANN001
    """Re-solve the contact candidates at state x, add new ones at nearby asperities.

    Keeps the local minima of the distance within reach (``d < R + e0 + margin``; at least
    the closest one), the deepest as ``cand[0]`` (the primary). Updates the local asperity
    list ``aidx[:na[0]]``. Returns the elastic energy removed by a change of the contact set
    at fixed state (booked as dissipation by the caller): the primary's stick spring when
    the primary moves to another local minimum, and contacts that disappear. Without
    asperities and with a single candidate, or unless ``full``, it only re-solves the
    existing candidates exactly (warm-started Newton); the search for new contacts runs
    when ``full`` (every few steps: a new contact enters the reach margin of 1 mm long
    before it can touch).
    """
    R = CP[I_R]
    reach = R + abs(CP[I_EL]) + CP[I_MARGIN]
    n_old = ncand[0]
    th = x[ITH]
    cxf = math.cos(th) * x[IX] + math.sin(th) * x[IY]
    cyf = -math.sin(th) * x[IX] + math.cos(th) * x[IY]
    ms = CP[I_MAXSTEP]
    nasp = aphi.shape[0]
    if (nasp == 0 and n_old == 1) or not full:
        ok = True
        ref = np.empty(n_old)
        for j in range(n_old):
            phi, _, f, fp, _ = newton_closest(cxf, cyf, cand[j], 8, 1e-14, ms, rho0, orders,
                                              ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx,
                                              na[0])
            ref[j] = phi
            ok = ok and fp > 0.0 and abs(f / fp) < 1e-12
        for a in range(n_old):  # two candidates on one minimum would count it twice
            for b in range(a):
                if abs(_wrap(ref[a] - ref[b])) < 1e-7:
                    ok = False
        if ok or nasp == 0:
            for j in range(n_old):
                cand[j] = ref[j]
            return 0.0
    # elastic energy of the contact set the last step integrated (as its stages evaluate it)
    contact_eval(x, 0.0, CP, cand, n_old, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                 aidx, na[0], 2, diag, dxv)
    e_old = diag[D_EEL]
    # local asperity list around the primary
    half = 0.0
    if nasp > 0:
        rb = math.sqrt(cxf * cxf + cyf * cyf)
        half = 1.5 * (reach + 2e-3) / max(rb - reach, 1e-3)
        cnt = 0
        p0 = cand[0]
        for i in range(nasp):
            if abs(_wrap(aphi[i] - p0)) < half + 12.0 * aw[i]:
                aidx[cnt] = i
                cnt += 1
        na[0] = cnt
    # re-solve the old candidates (warm start), then seeds at nearby asperities
    nbuf = NCMAX + 3 + 3 * max(na[0], 1)
    buf = np.empty(nbuf)
    dist = np.empty(nbuf)
    src = np.empty(nbuf, dtype=np.int64)
    nb = 0
    for j in range(n_old):
        phi, d, f, fp, _ = newton_closest(cxf, cyf, cand[j], 60, 1e-14, ms, rho0, orders, ccos,
                                          csin, bphi, bh, bw, aphi, ah, aw, aidx, na[0])
        if fp > 0.0 and abs(f / fp) < 1e-12:
            buf[nb] = phi
            dist[nb] = d
            src[nb] = j
            nb += 1
    if na[0] > 0:
        # the smooth track's closest point (asperities left out), then refined with them: the
        # track beside and between asperities
        pb, _, _, _, _ = newton_closest(cxf, cyf, cand[0], 60, 1e-14, ms, rho0, orders, ccos,
                                        csin, bphi, bh, bw, aphi, ah, aw, aidx, 0)
        for off in (0.0, -0.5, 0.5):
            seed = pb + off * half
            phi, d, f, fp, _ = newton_closest(cxf, cyf, seed, 200, 1e-14, ms, rho0, orders,
                                              ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx,
                                              na[0])
            if fp > 0.0 and abs(f / fp) < 1e-12 and d < reach:
                buf[nb] = phi
                dist[nb] = d
                src[nb] = -1
                nb += 1
    for jj in range(na[0]):
        i = aidx[jj]
        if abs(_wrap(aphi[i] - cand[0])) > half:
            continue
        for off in (-1.5, 0.0, 1.5):
            seed = cand[0] + _wrap(aphi[i] + off * aw[i] - cand[0])
            phi, d, f, fp, _ = newton_closest(cxf, cyf, seed, 60, 1e-14, ms, rho0, orders,
                                              ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx,
                                              na[0])
            if fp > 0.0 and abs(f / fp) < 1e-12 and d < reach:
                buf[nb] = phi
                dist[nb] = d
                src[nb] = -1
                nb += 1
    # deduplicate (keep the first: old candidates come first) and keep those within reach
    keep = np.zeros(nb, dtype=np.bool_)
    best = -1
    for a in range(nb):
        dup = False
        for b in range(a):
            if keep[b] and abs(_wrap(buf[a] - buf[b])) < 1e-8:
                dup = True
                break
        if dup:
            continue
        if dist[a] < reach:
            keep[a] = True
        if best < 0 or dist[a] < dist[best]:
            best = a
    # primary first, then the others
    nn = 0
    new_src0 = -2
    if best >= 0:
        keep[best] = True
        cand[0] = buf[best]
        new_src0 = src[best]
        nn = 1
    order = np.argsort(dist[:nb])  # the nearest first, should there be more than NCMAX
    for a in order:
        if keep[a] and a != best and nn < NCMAX:
            cand[nn] = buf[a]
            nn += 1
    if nn == 0:  # nothing converged (should not happen): keep the old primary
        nn = 1
    ncand[0] = nn
    same = nn == n_old and new_src0 == 0
    if same:  # the same contacts, re-solved: nothing to book
        for a in range(1, nn):
            found = False
            for b in range(nb):
                if src[b] >= 0 and abs(_wrap(buf[b] - cand[a])) < 1e-8:
                    found = True
            same = same and found
    if same:
        return 0.0
    if new_src0 != 0:  # the primary moved to another local minimum: its spring starts anew
        x[IXI] = 0.0
    contact_eval(x, 0.0, CP, cand, nn, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                 aidx, na[0], 3, diag, dxv)
    return e_old - diag[D_EEL]


@njit
def contact_steps(x0, u, h, nsteps, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw,  # noqa: ANN001, ANN201
                  aphi, ah, aw, aidx, na):  # noqa: ANN001
    """Advance the contact model by ``nsteps`` RK4 steps of ``h`` [s] under command u.

    Before every step the contact candidates are re-solved, every 8th step (and the first)
    searched anew (:func:`update_candidates`); after
    it a sliding or lost contact's stick spring is reset (module docstring). Energy removed
    by these resets is added to ``W_diss``. Returns the final state; ``cand``/``ncand``/
    ``aidx``/``na`` are updated in place.
    """
    x = x0.copy()
    xs = np.empty(NX)
    k1 = np.empty(NX)
    k2 = np.empty(NX)
    k3 = np.empty(NX)
    k4 = np.empty(NX)
    diag = np.zeros(D_SIZE)
    h2 = 0.5 * h
    h6 = h / 6.0
    for step in range(nsteps):
        booked = update_candidates(x, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw,
                                   aphi, ah, aw, aidx, na, diag, k1, step % 8 == 0)
        x[IWD] += booked
        nc = ncand[0]
        nl = na[0]
        contact_eval(x, u, CP, cand, nc, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                     aidx, nl, 2, diag, k1)
        for i in range(NX):
            xs[i] = x[i] + h2 * k1[i]
        contact_eval(xs, u, CP, cand, nc, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                     aidx, nl, 2, diag, k2)
        for i in range(NX):
            xs[i] = x[i] + h2 * k2[i]
        contact_eval(xs, u, CP, cand, nc, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                     aidx, nl, 2, diag, k3)
        for i in range(NX):
            xs[i] = x[i] + h * k3[i]
        contact_eval(xs, u, CP, cand, nc, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                     aidx, nl, 2, diag, k4)
        for i in range(NX):
            x[i] += h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        # stick-spring projection at the primary contact
        contact_eval(x, u, CP, cand, nc, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw,
                     aidx, nl, 2, diag, xs)
        fn0 = diag[D_FN0]
        xi = x[IXI]
        if fn0 <= 0.0:
            xi_new = 0.0
        else:
            trial = CP[I_KT] * xi + CP[I_CT] * diag[D_VSLIP]
            lim = CP[I_MUD] * fn0 / CP[I_KT]
            xi_new = xi
            if abs(trial) > CP[I_MUS] * fn0 and abs(xi) > lim:
                xi_new = lim if xi > 0.0 else -lim
        if xi_new != xi:
            x[IWD] += 0.5 * CP[I_KT] * (xi * xi - xi_new * xi_new)
            x[IXI] = xi_new
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
        Physical parameters; ``contact.*`` sets the contact law and the step,
        ``track.asperity_*`` adds sharp bumps the rigid model cannot carry.
    time_step : float, optional
        Override of ``contact.time_step`` [s].
    """

    def __init__(self, params: RigParams, time_step: float | None = None) -> None:
        if params.frame.wobble != 0.0:
            raise ValueError("the contact model is planar: frame.wobble is not supported "
                             "(use the rigid model for the wobbling frame)")
        self.params = params
        self.data: ContourData = contour_data(params)
        self.curve = OffsetCurve.from_params(params)  # bumps, no asperities: conversions
        c = params.contact
        damping = damping_for_restitution(params.contact_stiffness, c.exponent,
                                          c.damping_exponent, params.ball.mass,
                                          c.restitution, c.restitution_speed)
        CP = with_contact(rigid_vector(params), params, damping=damping,
                          search_step=0.25 * min(self.data.min_width, 0.2))
        self.CP = CP
        self.time_step = float(time_step or c.time_step)
        self.cand = np.zeros(NCMAX)
        self.ncand = np.zeros(1, dtype=np.int64)
        self.aidx = np.zeros(max(self.data.aphi.size, 1), dtype=np.int64)
        self.na = np.zeros(1, dtype=np.int64)
        self._args = (self.data.rho0, self.data.orders, self.data.ccos, self.data.csin,
                      self.data.bphi, self.data.bh, self.data.bw, self.data.aphi,
                      self.data.ah, self.data.aw)

    # -- contact set -----------------------------------------------------------------------
    def reset(self, x: ArrayLike, phi_guess: float | None = None) -> None:
        """Initialise the contact candidates for state x (global closest point if no guess)."""
        x = np.asarray(x, float)
        st, ct = math.sin(x[ITH]), math.cos(x[ITH])
        cf = np.array([ct * x[IX] + st * x[IY], -st * x[IX] + ct * x[IY]])
        if phi_guess is None:
            phi, _ = closest_point(self.data, cf)
        else:
            phi, _ = closest_point(self.data, cf, phi0=phi_guess)
        self.cand[:] = 0.0
        self.cand[0] = phi
        self.ncand[0] = 1
        self.na[0] = 0

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
                                    "track.asperity_width": []})
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
            float(self.cand[0]) if self.ncand[0] > 0 else None)
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
        contact_eval(np.asarray(x, float), float(u), self.CP, self.cand, int(self.ncand[0]),
                     *self._args, self.aidx, int(self.na[0]), 3, diag, dx)
        return dx, diag

    def rhs(self, t: float, x: FloatArray, u: float) -> FloatArray:
        """Time derivative at x with the current contact set (for scipy's solvers)."""
        return self._eval(x, u)[0]

    def diagnostics(self, x: ArrayLike, u: float = 0.0) -> dict:
        """Normal force, penetration, slip velocity, contact count and elastic energy at x."""
        _, d = self._eval(np.asarray(x, float), u)
        return {"normal_force": d[D_FN], "primary_normal_force": d[D_FN0],
                "penetration": d[D_W0], "slip_velocity": d[D_VSLIP],
                "contacts": int(d[D_NTOUCH]), "tangential_force": d[D_FT0], "phi": d[D_PHI0],
                "distance": d[D_D0], "elastic_energy": d[D_EEL]}

    def energy(self, x: ArrayLike) -> tuple[float, float, float]:
        """(kinetic, potential, elastic) energy [J] at state x (current contact set)."""
        x = np.asarray(x, float)
        p = self.params
        kin = 0.5 * (p.ball.mass * (x[IVX] ** 2 + x[IVY] ** 2) + p.ball.inertia * x[IOM] ** 2
                     + p.frame.inertia * x[ITHD] ** 2)
        pot = p.ball.mass * self.CP[I_G] * x[IY]
        return kin, pot, self.diagnostics(x)["elastic_energy"]

    def step(self, x: ArrayLike, u: float, dt: float, n: int = 1) -> FloatArray:
        """Advance x by n intervals of dt [s] under a held command u [N m].

        Inner steps of at most ``time_step``; the contact set is initialised on first use.
        """
        x = np.asarray(x, float)
        if self.ncand[0] == 0:
            self.reset(x)
        m = max(1, math.ceil(dt / self.time_step - 1e-9))
        return contact_steps(x, float(u), dt / m, int(n * m), self.CP, self.cand, self.ncand,
                             *self._args, self.aidx, self.na)

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
        phi_start = float(self.cand[0])
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
