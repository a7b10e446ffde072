"""Bounce analysis: the seed's discrete impact model and the continuous contact model.

Discrete model (seed chapter 3), evaluated at every sample of a trajectory as if a bump of
height h stood just in front of the ball. Local frame of the track at the contact: tangent
t (direction of travel) and outward normal n; the ball rolls at ``v = s_dot`` (relative to
the frame) with spin ``psi_dot = v / R``. Gravity in that frame (eq. 3.5):
``g_t = -g t_y``, ``g_n = -g n_y`` (world y components).

* Impact as a hinge at the bump's top O, energy conserved (eqs. 3.1-3.2)::

      m |v|^2 + J_b psi_dot^2 = (J_b + m R^2) omega^2

  post-impact (3.3-3.4): ``psi_dot+ = omega`` (the ball pivots about O) and the centre moves
  perpendicular to O->centre, ``v+ = omega ((R - h), x_c)`` in (t, n) with
  ``x_c = sqrt(R^2 - (R - h)^2)``. (The seed prints ``psi+ = -omega`` and a minus on the
  normal component with its own axes; the magnitudes are these.) :func:`impact_momentum`
  gives the alternative where the angular momentum about O is conserved instead.
* Free flight from there (3.6-3.7): apex after ``t_max = v_n / |g_n|``, rise
  ``y_A = v_n^2 / (2 |g_n|)``. Path A (the ball clears the bump) if ``y_A > h``.
* Curvatures at the impact point (3.8, 3.13-3.14): the circle about O,
  ``y''_C = -R^2 / (R - h)^3`` (the seed prints ``-(R^2 / (R^2 - x^2))^(3/2)``, a
  dimensionless expression: ``d^2/dx^2 sqrt(R^2 - x^2) = -R^2 / (R^2 - x^2)^(3/2)``); the
  parabola, ``y''_B = (v_t g_n - v_n g_t) / v_t^3`` (for ``g_t = 0`` the seed's 3.14,
  ``g_n / v_t^2``). Path B (contact lost before the top) if ``y''_B > y''_C``; else C.
* Slip per bump (seed: "worst case", 3.15-3.16 with 3.11): in the air until the apex,
  ``t_air = t_max``; the ball spins at ``omega`` while the distance it travels along the
  track, ``ds = v_t t_air + g_t t_air^2 / 2``, would take ``ds / R`` of rolling:
  ``dpsi = omega t_air - ds / R``.

Per rotation of the frame the seed multiplies by the number of bumps in the region where
path B occurs (30 bumps in 0.03 m); here ``slip/rot = rho_b * int_B dpsi |s_dot| dt / N_rot``
with ``rho_b`` the bump density (``bounce.bumps_per_metre``).

Continuous model (seed recommendation 1): :func:`contact_row_runs` runs the controller
against :class:`bfr_model.contact.ContactModel` over rows of sharp bumps and measures the slip
directly, ``int v_slip / R dt`` (the contact model's ``slip`` state), per bump and per
rotation, next to the discrete estimate at the same passages.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from bfr_model.closest_point import closest_point, contour_data, taylor_closest_point
from bfr_model.contact import ContactModel
from bfr_model.dynamics import RigidModel, curve_terms, rigid_terms
from bfr_model.params import RigParams
from bfr_model.perturbations import StudySettings, bump_row, contour_arc_to_phi, with_asperities
from numpy.typing import NDArray

from bfr_tools.analysis.trajectory import (
    ContactLoopResult,
    Trajectory,
    closed_loop_contact,
    progress,
)

__all__ = [
    "SEED",
    "BounceEval",
    "bounce_along",
    "bounce_analysis",
    "classify",
    "contact_row_runs",
    "contact_rtf",
    "impact_energy",
    "impact_momentum",
    "plot_bounce",
    "taylor_error",
]

FloatArray = NDArray[np.float64]

#: The seed's reported results (Knol 2016, sections 3.2-3.3).
SEED = {
    "threshold_height": 1.6e-4,  # [m] path B for bumps higher than this
    "slip_per_bump": 0.004,  # [rad] at h = 5e-4 m, worst case
    "slip_region": 0.03,  # [m] where y''_B > y''_C
    "bumps_in_region": 30,
    "slip_per_rotation": 0.12,  # [rad]
    "path_A_occurs": False,
}


def impact_energy(v: FloatArray, psi_dot: FloatArray, m: float, jb: float, R: float,
                  h: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Seed eqs. 3.1-3.4: hinge impact at the bump top, kinetic energy conserved.

    Returns
    -------
    omega, v_t, v_n : ndarray
        Pivot rate [rad/s] (= the post-impact spin rate) and the centre's post-impact
        velocity along the track and along its normal [m/s].
    """
    omega = np.sqrt((m * v**2 + jb * psi_dot**2) / (jb + m * R**2))
    xc = math.sqrt(R**2 - (R - h) ** 2)
    return omega, (R - h) * omega, xc * omega


def impact_momentum(v: FloatArray, psi_dot: FloatArray, m: float, jb: float, R: float,
                    h: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hinge impact conserving the angular momentum about O (a plastic impact, not the seed's).

    ``(J_b + m R^2) omega = J_b psi_dot + m v (R - h)``; velocities as in
    :func:`impact_energy`. Loses the kinetic energy the seed's model keeps.
    """
    omega = (jb * psi_dot + m * v * (R - h)) / (jb + m * R**2)
    xc = math.sqrt(R**2 - (R - h) ** 2)
    return omega, (R - h) * omega, xc * omega


def classify(v_t: FloatArray, v_n: FloatArray, g_t: FloatArray, g_n: FloatArray, R: float,
             h: float) -> dict[str, FloatArray]:
    """Paths A/B/C after the impact (module docstring, eqs. 3.5-3.14).

    Returns
    -------
    dict
        ``y_A`` apex rise [m], ``t_max`` [s], ``ypp_B``, ``ypp_C`` [1/m], ``path``
        (0 = A, 1 = B, 2 = C).
    """
    gn = np.minimum(g_n, -1e-12)
    t_max = v_n / -gn
    y_a = v_n * t_max + 0.5 * gn * t_max**2
    with np.errstate(divide="ignore", invalid="ignore"):
        ypp_b = np.where(v_t > 0.0, (v_t * g_n - v_n * g_t) / v_t**3, -np.inf)
    ypp_c = np.full_like(np.asarray(v_t, float), -(R**2) / (R - h) ** 3)
    path = np.where(y_a > h, 0, np.where(ypp_b > ypp_c, 1, 2))
    return {"y_A": y_a, "t_max": t_max, "ypp_B": ypp_b, "ypp_C": ypp_c, "path": path}


@dataclass
class BounceEval:
    """The discrete model along a trajectory for one bump height."""

    h: float
    s: FloatArray
    s_dot: FloatArray
    omega: FloatArray
    y_A: FloatArray  # noqa: N815 (the seed's notation)
    ypp_B: FloatArray  # noqa: N815
    ypp_C: FloatArray  # noqa: N815
    path: NDArray[np.int64]
    t_air: FloatArray
    slip: FloatArray


def _local_frame(model: RigidModel, traj: Trajectory) -> dict[str, FloatArray]:
    th, ph, thd, phd = traj.x.T
    g = curve_terms(ph, *model.kernel_args)
    px, py, nx, ny, lam = g[0], g[1], g[6], g[7], g[8]
    st, ct = np.sin(th), np.cos(th)
    n_y = st * nx + ct * ny
    t_y = st * ny - ct * nx  # t = (n_y, -n_x) in frame coordinates
    grav = model.params.environment.in_plane_gravity
    thdd = rigid_terms(th, ph, thd, phd, traj.u, *model.kernel_args)[0]
    return {"s_dot": lam * phd, "g_t": -grav * t_y, "g_n": -grav * n_y, "px": px, "py": py,
            "nx": nx, "ny": ny, "st": st, "ct": ct, "thd": thd, "thdd": thdd, "g": grav}


def _apparent_gravity(loc: dict, v_t: FloatArray, v_n: FloatArray
                      ) -> tuple[FloatArray, FloatArray]:
    """Acceleration of a free ball relative to the turning frame, in (t, n) [m/s^2].

    ``a = -g y + th'^2 r - th'' z x r - 2 th' z x v_rel`` at the ball centre r with the
    post-impact relative velocity (frame coordinates; gravity ``-g (sin th, cos th)``).
    """
    nx, ny = loc["nx"], loc["ny"]
    tx, ty = ny, -nx
    px, py, thd, thdd = loc["px"], loc["py"], loc["thd"], loc["thdd"]
    vx = v_t * tx + v_n * nx
    vy = v_t * ty + v_n * ny
    ax = -loc["g"] * loc["st"] + thd**2 * px + thdd * py + 2.0 * thd * vy
    ay = -loc["g"] * loc["ct"] + thd**2 * py - thdd * px - 2.0 * thd * vx
    return ax * tx + ay * ty, ax * nx + ay * ny


def bounce_along(model: RigidModel, traj: Trajectory, h: float, momentum: bool = False,
                 rotating: bool = False) -> BounceEval:
    """Evaluate the discrete model at every sample of ``traj`` for a bump of height h [m].

    ``momentum``: the angular-momentum hinge (:func:`impact_momentum`) instead of the
    seed's energy hinge. ``rotating``: beyond the seed, the flight feels the turning frame
    (centrifugal, Euler and Coriolis accelerations, :func:`_apparent_gravity`) besides
    gravity; the seed's ramp is at rest.
    """
    p = model.params
    m, jb, R = p.ball.mass, p.ball.inertia, p.ball.rolling_radius
    loc = _local_frame(model, traj)
    v = np.abs(loc["s_dot"])
    imp = impact_momentum if momentum else impact_energy
    omega, v_t, v_n = imp(v, v / R, m, jb, R, h)
    if rotating:
        loc["g_t"], loc["g_n"] = _apparent_gravity(loc, v_t, v_n)
    c = classify(v_t, v_n, loc["g_t"], loc["g_n"], R, h)
    t_air = c["t_max"]
    ds = v_t * t_air + 0.5 * loc["g_t"] * t_air**2
    slip = np.where(c["path"] <= 1, omega * t_air - ds / R, 0.0)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(traj.t))])
    return BounceEval(h=h, s=s, s_dot=v, omega=omega, y_A=c["y_A"], ypp_B=c["ypp_B"],
                      ypp_C=c["ypp_C"], path=c["path"], t_air=t_air, slip=slip)


def bounce_analysis(traj: Trajectory, params: RigParams, study: StudySettings) -> dict:
    """The seed's chapter 3 along ``traj``: paths, threshold height, slip per bump/rotation."""
    model = RigidModel(params)
    b = study.bounce
    h0 = study.perturbations.bump_height
    late = traj.t >= min(study.run.settle, 0.5 * (traj.t[0] + traj.t[-1]))
    ev = bounce_along(model, traj, h0)
    evm = bounce_along(model, traj, h0, momentum=True)
    evr = bounce_along(model, traj, h0, rotating=True)
    hs = np.geomspace(b.bump_heights_min, b.bump_heights_max, b.bump_heights_count)
    margin_b = np.array([np.max((e.ypp_B - e.ypp_C)[late]) for e in
                         (bounce_along(model, traj, h) for h in hs)])
    margin_a = np.array([np.max((e.y_A - h)[late]) for h, e in
                         zip(hs, (bounce_along(model, traj, h) for h in hs), strict=True)])

    def threshold(momentum: bool = False, rotating: bool = False) -> float | None:
        """Smallest h with y''_B > y''_C somewhere (0: below the sweep, None: above it)."""
        def f(h: float) -> float:
            e = bounce_along(model, traj, h, momentum, rotating)
            return float(np.max((e.ypp_B - e.ypp_C)[late]))

        lo, hi = b.bump_heights_min, b.bump_heights_max
        if f(hi) <= 0.0:
            return None
        if f(lo) > 0.0:
            return 0.0
        for _ in range(60):
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if f(mid) <= 0.0 else (lo, mid)
        return hi

    n_rot = (traj.theta[-1] - traj.theta[late][0]) / (2.0 * math.pi)
    dt = np.gradient(traj.t)

    def per_rotation(e: BounceEval) -> dict:
        in_b = late & (e.path == 1)
        in_a = late & (e.path == 0)
        length_b = float(np.sum((e.s_dot * dt)[in_b]) / n_rot)
        length_a = float(np.sum((e.s_dot * dt)[in_a]) / n_rot)
        slip_rot = float(b.bumps_per_metre * np.sum((e.slip * e.s_dot * dt)[in_b]) / n_rot)
        slip_rot_ab = float(b.bumps_per_metre * np.sum((e.slip * e.s_dot * dt)[in_a | in_b])
                            / n_rot)
        return {"path_A_fraction": float(np.mean(in_a[late])),
                "path_B_fraction": float(np.mean(in_b[late])),
                "region_A_per_rotation": length_a,
                "region_B_per_rotation": length_b,
                "bumps_in_region": b.bumps_per_metre * length_b,
                "slip_per_bump_max": float(np.max(e.slip[in_b])) if in_b.any() else 0.0,
                "slip_per_bump_mean_B": float(np.mean(e.slip[in_b])) if in_b.any() else 0.0,
                "slip_per_bump_mean_A": float(np.mean(e.slip[in_a])) if in_a.any() else 0.0,
                "slip_per_rotation": slip_rot,
                "slip_per_rotation_A_and_B": slip_rot_ab}

    # where on the contour path B occurs most, and where the ball is slowest (path C), in
    # 36 bins of phi mod pi: the places for the contact model's rows of bumps
    phi_mod = np.mod(traj.phi, math.pi)
    bins = np.minimum((phi_mod / math.pi * 36).astype(int), 35)
    in_b = late & (ev.path == 1)
    count_b = np.bincount(bins[in_b], minlength=36)
    speed = np.array([np.mean(ev.s_dot[late & (bins == k)]) if np.any(late & (bins == k))
                      else np.inf for k in range(36)])
    phi_b = float((np.argmax(count_b) + 0.5) * math.pi / 36) if in_b.any() else None
    phi_c = float((np.argmin(speed) + 0.5) * math.pi / 36)
    R = params.ball.rolling_radius
    g = params.environment.in_plane_gravity
    v_crit = math.sqrt(g * (R - h0))
    return {
        "bump_height": h0,
        "threshold_height": threshold(),
        "threshold_height_momentum": threshold(momentum=True),
        "threshold_height_rotating": threshold(rotating=True),
        "critical_speed": v_crit,
        "fraction_above_critical_speed": float(np.mean(ev.s_dot[late] > v_crit)),
        "s_dot_max": float(np.max(ev.s_dot[late])),
        "s_dot_mean": float(np.mean(ev.s_dot[late])),
        "energy_hinge": per_rotation(ev),
        "momentum_hinge": per_rotation(evm),
        "rotating_frame": per_rotation(evr),
        "path_A_occurs": bool(np.any(late & (ev.path == 0))),
        "phi_B_region_mod_pi": phi_b,
        "phi_C_region_mod_pi": phi_c,
        "rotations": float(n_rot),
        "sweep": {"h": hs.tolist(), "max_ypp_B_minus_C": margin_b.tolist(),
                  "max_yA_minus_h": margin_a.tolist()},
        "_eval": ev,
    }


def taylor_error(traj: Trajectory, params: RigParams, stride: int = 5) -> dict:
    """The seed's Taylor closest point (eqs. 4.33-4.37) against the exact one along traj.

    The ball centre on the offset curve, ``c = p(phi)``, has the exact closest contour
    point phi; the Taylor estimate starts from the centre's own polar angle.
    """
    model = RigidModel(params)
    data = contour_data(params)
    phis = traj.phi[::stride]
    g = curve_terms(phis, *model.kernel_args)
    err = np.empty(phis.size)
    for i, (cx, cy, ph) in enumerate(zip(g[0], g[1], phis, strict=True)):
        pt = taylor_closest_point(data, (cx, cy))
        err[i] = (pt - ph + math.pi) % (2 * math.pi) - math.pi
    # check the exact solve itself on a few samples (global bracket)
    ex = []
    for cx, cy, ph in list(zip(g[0], g[1], phis, strict=True))[:: max(1, phis.size // 20)]:
        pe, _ = closest_point(data, (cx, cy))
        ex.append(abs((pe - ph + math.pi) % (2 * math.pi) - math.pi))
    c = model.curve
    r0 = c.rho(phis)
    arc = np.abs(err) * r0  # contour arc length error, approximately rho dphi
    return {"max_abs_error_rad": float(np.max(np.abs(err))),
            "rms_error_rad": float(np.sqrt(np.mean(err**2))),
            "max_arc_error_m": float(np.max(arc)),
            "exact_solve_max_error_rad": float(np.max(ex)),
            "samples": int(phis.size), "_err": err, "_phi": phis}


def _row_params(params: RigParams, study: StudySettings, kind: str, phi_start: float,
                height: float) -> tuple[RigParams, FloatArray]:
    """Parameters with a row of sharp bumps (both point-symmetric halves of the contour).

    ``dense``: the seed's ``row_count`` bumps in ``row_length``; ``isolated``: bumps
    ``isolated_spacing`` apart (more than the ball's chord over a bump, so it meets one at a
    time) over the same length. Gaussian width ``row_width`` along the contour.
    """
    cr = study.contact_run
    if kind == "dense":
        n, length = cr.row_count, cr.row_length
    else:
        n = max(1, round(cr.row_length / cr.isolated_spacing) + 1)
        length = n * cr.isolated_spacing
    ph, h, w = bump_row(params, phi_start, n, length, height, cr.row_width)
    ph = np.concatenate([ph, ph + math.pi])
    h = np.concatenate([h, h])
    w = np.concatenate([w, w])
    p = with_asperities(params, ph, h, w, append=False)
    return p.replace(**{"contact.time_step": cr.time_step}), ph


def _row_passages(res: ContactLoopResult, lo: float, hi: float, start: float, until: float
                  ) -> list[tuple[int, int]]:
    """Index ranges in which the contact angle crosses [lo, hi] (mod pi), after start."""
    phi = res.rigid[:, 1]
    out = []
    k0 = math.floor((phi[0] - hi) / math.pi)
    k1 = math.floor((phi[-1] - lo) / math.pi) + 1
    for k in range(k0, k1 + 1):
        a, b = lo + k * math.pi, hi + k * math.pi
        i0 = int(np.searchsorted(phi, a))
        i1 = int(np.searchsorted(phi, b))
        if 0 < i0 < i1 < phi.size and res.t[i0] >= start and res.t[i1] <= until:
            out.append((i0, i1))
    return out


def contact_row_runs(params: RigParams, study: StudySettings, locations: dict[str, float]
                     ) -> dict:
    """Recommendation 1: the contact model over rows of bumps, closed loop, slip measured.

    Runs of ``contact_run.duration`` with the nominal controller against the contact plant:
    no bumps (the baseline), the seed's dense row (``row_count`` bumps of ``row_height`` in
    ``row_length``) and rows of isolated bumps (``isolated_spacing`` apart) of each height
    in ``isolated_heights``, on both halves of the contour, centred at each of
    ``locations`` (name -> contour angle, e.g. where the discrete model predicts path B and
    where it predicts C; ``contact_run.row_start_phi`` overrides with one location). Slip is
    the contact model's
    ``int v_slip / R dt``: per passage of the row (from a ball radius before its first bump
    to one after its last) less the baseline rate, divided by the bumps in the row; per
    rotation of the frame over the run. The discrete estimate (energy hinge) is evaluated
    from the run's own states at the moments the ball passes each bump.
    """
    cr = study.contact_run
    if cr.row_start_phi is not None:
        locations = {"given": cr.row_start_phi}
    model_r = RigidModel(params)
    R = params.ball.rolling_radius
    half = 0.5 * cr.row_length
    starts = {k: float(contour_arc_to_phi(params, v, -half)) for k, v in locations.items()}
    out: dict = {"locations": locations, "row_starts": starts, "runs": {}}
    cases = [("baseline", "none", 0.0, "", 0.0)]
    for loc, phi_start in starts.items():
        cases.append((f"{loc}: dense", "dense", cr.row_height, loc, phi_start))
        cases += [(f"{loc}: isolated {h:g}", "isolated", h, loc, phi_start)
                  for h in cr.isolated_heights]
    base_rate = 0.0
    for name, kind, h, loc, phi_start in cases:
        if kind == "none":
            p = params.replace(**{"contact.time_step": cr.time_step})
            bumps = np.zeros(0)
        else:
            p, bumps = _row_params(params, study, kind, phi_start, h)
        progress(f"contact model, closed loop, {name} ({bumps.size} bumps), "
                 f"{cr.duration:g} s at dt = {cr.time_step:g} s")
        model = ContactModel(p)
        t0 = time.perf_counter()
        res = closed_loop_contact(model, params, study, cr.duration, seed=study.run.seed,
                                  stop_after_lost=0.2)
        wall = time.perf_counter() - t0
        settle = study.run.settle
        until = res.rolling_until
        sel = (res.t >= settle) & (res.t <= until)
        run: dict = {"kind": kind, "location": loc, "height": h, "bumps": int(bumps.size),
                     "rolling_until": until,
                     "ball_kept_rolling": bool(until >= cr.duration - 1e-6),
                     "wall_time": wall, "plant_wall_time": res.wall_time,
                     "plant_real_time_factor": float((res.t[-1] - res.t[0])
                                                     / max(res.wall_time, 1e-9)),
                     "_res": res}
        out["runs"][name] = run
        if sel.sum() < 2:
            continue
        theta = res.x[:, 3]
        n_rot = (theta[sel][-1] - theta[sel][0]) / (2 * math.pi)
        slip = res.slip
        dur = res.t[sel][-1] - res.t[sel][0]
        run.update({
            "rotations": float(n_rot),
            "slip_per_rotation": float((slip[sel][-1] - slip[sel][0]) / n_rot),
            "airborne_fraction": float(np.mean(res.penetration[sel] < 0.0)),
            "max_gap": float(max(0.0, -np.min(res.penetration[sel]))),
            "mean_phi_dot": float((res.rigid[sel][-1, 1] - res.rigid[sel][0, 1]) / dur)})
        if kind == "none":
            base_rate = float((slip[sel][-1] - slip[sel][0]) / dur)
            run["slip_rate"] = base_rate
            continue
        n_row = bumps.size // 2
        row = np.sort(np.mod(bumps[:n_row], math.pi))
        margin = 1.5 * R / float(model_r.curve.rho(row[0]))
        pas = _row_passages(res, float(row.min() - margin), float(row.max() + margin),
                            settle, until)
        per_bump, disc = [], []
        for i0, i1 in pas:
            per_bump.append((slip[i1] - slip[i0] - base_rate * (res.t[i1] - res.t[i0]))
                            / n_row)
            # the discrete estimate at each bump of this passage
            lo = row.min() - margin
            ii = np.unique([min(int(np.searchsorted(res.rigid[:, 1], res.rigid[i0, 1] + b - lo)),
                                res.t.size - 1) for b in row])
            if ii.size < 3:
                continue
            ev = bounce_along(model_r, Trajectory(res.t[ii], res.rigid[ii], res.u[ii]), h)
            disc.append(float(np.mean(np.where(ev.path <= 1, ev.slip, 0.0))))
        pb = np.asarray(per_bump)
        run.update({
            "row_passages": len(pas),
            "slip_per_bump_mean": float(np.mean(np.abs(pb))) if pb.size else None,
            "slip_per_bump_signed_mean": float(np.mean(pb)) if pb.size else None,
            "discrete_slip_per_bump_mean": float(np.mean(disc)) if disc else None,
            "excess_slip_per_rotation": float(run["slip_per_rotation"]
                                              - base_rate * dur / n_rot)})
    return out


def contact_rtf(params: RigParams, duration: float = 2.0, control_dt: float = 1e-3) -> dict:
    """Real-time factor of the contact model in the simulator node's configuration.

    The node steps the plant once per control period (``control_dt``, the held command)
    with the shipped ``contact.time_step``; the ball rolls on the nominal track (the
    orbit's start state, a constant small torque). Wall time of the ``step`` calls only.
    """
    model = ContactModel(params)
    x = model.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    x = model.step(x, 0.0, control_dt)  # compile / warm up
    x = model.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    n = round(duration / control_dt)
    t0 = time.perf_counter()
    c0 = time.process_time()
    for _ in range(n):
        x = model.step(x, 0.0, control_dt)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    return {"time_step": model.time_step, "control_dt": control_dt, "duration": duration,
            "wall_time": wall, "cpu_time": cpu, "real_time_factor": duration / wall,
            "real_time_factor_cpu": duration / cpu}


def plot_bounce(rep: dict, traj: Trajectory, out_dir: Path, taylor: dict | None = None,
                rows: dict | None = None) -> list[Path]:
    """Figures like the seed's 3.3-3.4 (and the contact runs), PNG files in out_dir."""
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    ev: BounceEval = rep["_eval"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].plot(ev.s, ev.y_A, lw=0.7, label="y_A: apex of the free flight")
    ax[0].axhline(ev.h, color="k", ls="--", lw=0.8, label=f"y_C = h = {ev.h:g} m")
    ax[0].set(xlabel="travelled distance s [m]", ylabel="height [m]",
              title="(a) bounce height vs bump height")
    ax[0].legend(fontsize=8)
    ax[1].plot(ev.s, ev.ypp_B, lw=0.7, label="y''_B (free flight)")
    ax[1].plot(ev.s, ev.ypp_C, lw=0.9, label="y''_C (circle about the bump top)")
    ax[1].set(xlabel="travelled distance s [m]", ylabel="y'' [1/m]",
              title="(b) curvature at the impact point")
    ax[1].legend(fontsize=8)
    fig.suptitle(f"Fig. 3.3: bounce prediction along the closed-loop run (h = {ev.h:g} m)")
    fig.tight_layout()
    paths.append(out_dir / "fig_3_3_bounce_prediction.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    sw = rep["sweep"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].semilogx(sw["h"], sw["max_yA_minus_h"])
    ax[0].axhline(0.0, color="k", lw=0.6)
    ax[0].set(xlabel="bump height h [m]", ylabel="max (y_A - y_C) [m]",
              title="(a) path A when > 0")
    ax[1].semilogx(sw["h"], sw["max_ypp_B_minus_C"])
    ax[1].axhline(0.0, color="k", lw=0.6)
    if rep.get("threshold_height"):
        ax[1].axvline(rep["threshold_height"], color="r", ls="--", lw=0.8,
                      label=f"threshold {rep['threshold_height']:.3g} m")
        ax[1].legend(fontsize=8)
    ax[1].set(xlabel="bump height h [m]", ylabel="max (y''_B - y''_C) [1/m]",
              title="(b) path B when > 0")
    fig.suptitle("Fig. 3.4: influence of the bump height")
    fig.tight_layout()
    paths.append(out_dir / "fig_3_4_bump_height.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    if taylor is not None:
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(np.mod(taylor["_phi"], 2 * np.pi), taylor["_err"], ".", ms=1.5)
        ax.set(xlabel="contact angle phi mod 2 pi [rad]", ylabel="phi_Taylor - phi [rad]",
               title="Seed's Taylor closest point (eqs. 4.33-4.37) vs exact")
        fig.tight_layout()
        paths.append(out_dir / "fig_4_taylor_closest_point_error.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    if rows is not None:
        fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
        for kind, run in rows["runs"].items():
            res = run["_res"]
            ok = res.t <= run["rolling_until"]  # up to where the ball was lost
            label = kind if run["ball_kept_rolling"] else f"{kind} (lost)"
            ax[0].plot(res.t[ok], res.slip[ok], lw=0.8, label=label)
            ax[1].plot(res.t[ok], np.maximum(-res.penetration[ok], 0.0) * 1e3, lw=0.5,
                       label=label)
        ax[0].set(xlabel="t [s]", ylabel="slip angle int v_slip / R dt [rad]",
                  title="(a) slip, contact model, closed loop")
        ax[1].set(xlabel="t [s]", ylabel="gap between ball and track [mm]",
                  title="(b) loss of contact")
        ax[0].legend(fontsize=8)
        fig.suptitle("Contact model over rows of bumps (seed recommendation 1)")
        fig.tight_layout()
        paths.append(out_dir / "fig_contact_rows_slip.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths

