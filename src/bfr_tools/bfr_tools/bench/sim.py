"""``bfr bench`` section ``sim``: simulator speed as real-time factors, against scipy.

Rigid model
-----------
The trajectory is a closed-loop run of the controller on the rigid plant
(:func:`bfr_sim.closed_loop.run_closed_loop`, controller at the camera's 200 Hz, camera
latency 5 ms), so the ball rolls on the orbit throughout; its torque is then replayed, held
over each 5 ms control period, which reproduces the run's states bit for bit with the same
RK4. Measured on it:

- the simulator node's loop as written (``RigSimulation.step``: one compiled RK4 step of
  1 ms per call, the command set every 5 ms), budget >= 50x;
- RK4 at 1 kHz in chunks of 5 steps, one compiled call per 200 Hz camera frame plus the
  per-call Python of ``RigidModel.step``, budget >= 50x;
- the baselines: ``scipy.integrate.solve_ivp`` (RK45, DOP853) on the same compiled
  ``rigid_rhs`` through a Python wrapper, restarted every 5 ms from the run's state with the
  held torque (what a node would have to do); the ratio RK4 chunks / solve_ivp chunks is the
  figure that counts;
- for context: one long compiled RK4 call (u = 0 from the same start, 1 kHz) against one
  long solve_ivp call over the same horizon.

Matching accuracy: each solve_ivp tolerance is the loosest of ``rtol = atol = 1e-3, 1e-4,
..., 1e-12`` whose error is no larger than RK4 at 1 kHz, against a reference (RK4 at
10 microseconds): for the chunks, the largest state error after a 5 ms chunk over the first
second; for the long call, the largest error over the first second (sampled every 1 ms).

Contact model
-------------
The force-based contact model (:class:`bfr_model.contact.ContactModel`) at its configured
step (``contact.time_step`` of rig.yaml), called once per 1 ms with the torque held, in
closed loop with the nominal controller (1 kHz, camera 200 Hz with 5 ms latency) over the
perturbation study's row of sharp bumps (``contact_run.row_*`` of
perturbation_study.yaml: the seed's 30 bumps in 0.03 m of contour, on both halves of the
contour), placed ahead of the ball. The figure with the budget (>= 2x, issue 16) is the
real-time factor over the steps in which the ball is on the row (primary contact within the
row, ball within 1 mm of the track). By method, on the same row intervals from the run's
states: the shipped stepping, the same without free-flight steps
(``contact.max_flight_step = 0``), and the exhaustive reference (contact set searched and
every candidate evaluated at every step: the compiled closest point alone), with the mean
step the shipped stepping took. The baseline is solve_ivp (LSODA, Radau) on the same
equations (``ContactModel.rhs`` with the contact set following the state, as the
fixed-step integrator keeps it), over the same 1 ms intervals from the run's states,
tolerance matched the same way (error of the ball's velocity after 1 ms against the model
at a ten times smaller step).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_control.controller import OrbitalController
from bfr_control.estimator import BallObservation
from bfr_model.contact import ITH, ITHD, IX, IY
from bfr_model.dynamics import RigidModel, rigid_rhs
from bfr_model.params import RigParams, load_params
from bfr_model.perturbations import bump_row, load_study, with_asperities
from bfr_sim.closed_loop import orbit_initial_state, run_closed_loop
from bfr_sim.simulator_node import RigSimulation
from scipy.integrate import solve_ivp

from bfr_model import contact as cm
from bfr_tools.bench.common import (
    BenchOptions,
    Budget,
    Figure,
    FigureSpec,
    Progress,
    not_measured,
)

__all__ = ["SPECS", "run"]

_DT = 1e-3           # [s] RK4 step of the node
_CHUNK = 5           # steps per 200 Hz camera frame
_CHUNK_S = _CHUNK * _DT  # [s] one camera frame
_RTOLS = tuple(10.0 ** -k for k in range(3, 13))

SPECS: list[FigureSpec] = [
    FigureSpec("sim.rigid_rtf_node", "rigid RK4 1 kHz, simulator node loop (1 step/call)", "x",
               Budget(">=", 50.0)),
    FigureSpec("sim.rigid_rtf_chunked", "rigid RK4 1 kHz, 5 steps/call (1 call per frame)",
               "x", Budget(">=", 50.0)),
    FigureSpec("sim.rigid_rtf_rk45_chunked", "rigid solve_ivp RK45, 1 call per 5 ms (baseline)",
               "x"),
    FigureSpec("sim.rigid_rtf_dop853_chunked",
               "rigid solve_ivp DOP853, 1 call per 5 ms (baseline)", "x"),
    FigureSpec("sim.rigid_ratio_rk45_chunked", "ratio RK4 chunks / RK45 chunks", ""),
    FigureSpec("sim.rigid_ratio_dop853_chunked", "ratio RK4 chunks / DOP853 chunks", ""),
    FigureSpec("sim.rigid_rtf_compiled", "rigid RK4 1 kHz, one long compiled call (context)",
               "x"),
    FigureSpec("sim.rigid_rtf_rk45_long", "rigid solve_ivp RK45, one long call (context)", "x"),
    FigureSpec("sim.rigid_rtf_dop853_long", "rigid solve_ivp DOP853, one long call (context)",
               "x"),
    FigureSpec("sim.rigid_ratio_long", "ratio RK4 long / best solve_ivp long (context)", ""),
    FigureSpec("sim.contact_rtf_bumps", "contact model, node config, over the bump row", "x",
               Budget(">=", 2.0, "issue 16")),
    FigureSpec("sim.contact_rtf_run", "contact model, node config, whole closed-loop run",
               "x"),
    FigureSpec("sim.contact_rtf_smooth", "contact model, node config, no bumps (context)", "x"),
    FigureSpec("sim.contact_rtf_lsoda", "contact solve_ivp LSODA on the row (baseline)", "x"),
    FigureSpec("sim.contact_rtf_radau", "contact solve_ivp Radau on the row (baseline)", "x"),
    FigureSpec("sim.contact_ratio_lsoda", "ratio contact RK4 / LSODA, same intervals", ""),
    FigureSpec("sim.contact_ratio_radau", "ratio contact RK4 / Radau, same intervals", ""),
    FigureSpec("sim.contact_rtf_row_intervals", "contact, row intervals: as shipped", "x"),
    FigureSpec("sim.contact_rtf_row_noflight", "contact, row intervals: no free-flight steps",
               "x"),
    FigureSpec("sim.contact_rtf_row_exhaustive",
               "contact, row intervals: search + evaluate all, every step", "x"),
    FigureSpec("sim.contact_mean_step_row", "contact, row intervals: mean step taken", "us"),
]
_BY_KEY = {s.key: s for s in SPECS}
_ROW_KEYS = ("sim.contact_rtf_lsoda", "sim.contact_rtf_radau", "sim.contact_ratio_lsoda",
             "sim.contact_ratio_radau", "sim.contact_rtf_row_intervals",
             "sim.contact_rtf_row_noflight", "sim.contact_rtf_row_exhaustive",
             "sim.contact_mean_step_row")


def _fig(key: str, values: list[float], note: str = "", **extra: Any) -> Figure:
    return Figure(_BY_KEY[key], [float(v) for v in values], note=note, extra=dict(extra))


# -- rigid model ---------------------------------------------------------------------------------
def _reference_run(horizon: float) -> tuple[Any, Any, Any]:
    """Closed-loop reference run: (params, LoopResult, controller)."""
    params = load_params()
    ctrl = OrbitalController(params)
    x0 = orbit_initial_state(ctrl, 0.3, d_theta=0.02)
    lr = run_closed_loop(ctrl, params, horizon, x0, control_rate=1.0 / (_CHUNK * _DT))
    return params, lr, ctrl


def _solve(rhs: Callable, x0: np.ndarray, span: float, args: tuple, method: str, rtol: float,
           atol: float, t_eval: np.ndarray | None = None) -> Any:

    def f(t: float, x: np.ndarray) -> np.ndarray:
        return rhs(t, x, args)

    sol = solve_ivp(f, (0.0, span), x0, method=method, rtol=rtol, atol=atol, t_eval=t_eval)
    if not sol.success:
        raise RuntimeError(f"solve_ivp {method} failed: {sol.message}")
    return sol


@dataclass(frozen=True, kw_only=True)
class _Tolerance:
    """A solve_ivp tolerance matched to RK4's error.

    Attributes
    ----------
    rtol : float
        ``rtol = atol`` chosen: the loosest of :data:`_RTOLS` whose error is small enough.
    error : float
        Its error.
    matched : bool
        False if even the tightest tried was not accurate enough (then it is that one).
    """

    rtol: float
    error: float
    matched: bool

    @property
    def unmatched_note(self) -> str:
        """``""`` if matched, else the note that says it was not."""
        return "" if self.matched else ": NOT matched"


def _calibrate(errors_of: Callable[[float], float], target: float) -> _Tolerance:
    """Loosest rtol of :data:`_RTOLS` whose error <= target."""
    err = math.inf
    rtol = _RTOLS[-1]
    for rtol in _RTOLS:
        err = errors_of(rtol)
        if err <= target:
            return _Tolerance(rtol=rtol, error=err, matched=True)
    return _Tolerance(rtol=rtol, error=err, matched=False)


@dataclass(frozen=True, kw_only=True)
class _RigidTrajectory:
    """The rigid benchmark's trajectory: a closed-loop run, its torque held per 5 ms chunk.

    Attributes
    ----------
    params : RigParams
        rig.yaml.
    model : RigidModel
        The plant (compiled kernel loaded).
    x : ndarray, shape (n + 1, 6)
        The run's states at the chunk starts.
    u : ndarray, shape (n + 1,)
        The torque held over each chunk [N m].
    n : int
        Chunks of 5 ms.
    """

    params: RigParams
    model: RigidModel
    x: np.ndarray
    u: np.ndarray
    n: int

    @property
    def duration(self) -> float:
        """Simulated time of the n chunks [s]."""
        return self.n * _CHUNK * _DT


@dataclass(frozen=True, kw_only=True)
class _Accuracy:
    """RK4's error at 1 kHz against a fine reference, and the solve_ivp tolerances matching it.

    Attributes
    ----------
    rk4_error : float
        Largest state error of RK4 at 1 kHz.
    tolerances : dict of str to _Tolerance
        By solve_ivp method (``RK45``, ``DOP853``).
    """

    rk4_error: float
    tolerances: dict[str, _Tolerance]


def _rigid_trajectory(horizon: float) -> _RigidTrajectory:
    """The closed-loop reference run of ``horizon`` [s] as the trajectory to replay."""
    params, lr, _ = _reference_run(horizon)
    model = RigidModel(params)
    model.step(lr.x[0], 0.0, _DT, 1)        # load the compiled kernel
    return _RigidTrajectory(params=params, model=model, x=lr.x, u=lr.u, n=lr.x.shape[0] - 1)


def _chunk_accuracy(tr: _RigidTrajectory, quick: bool, say: Progress) -> _Accuracy:
    """Per-chunk state error over the first second against RK4 at 10 us; matched tolerances."""
    model, X, U = tr.model, tr.x, tr.u
    ncal = min(tr.n, 50 if quick else 200)
    ref = np.array([model.step(X[k], U[k], 1e-5, round(_CHUNK_S / 1e-5)) for k in range(ncal)])
    ours = np.array([model.step(X[k], U[k], _DT, _CHUNK) for k in range(ncal)])
    err_rk4 = float(np.max(np.abs(ours[:, :4] - ref[:, :4])))

    def chunk_error(method: str) -> Callable[[float], float]:
        def f(rtol: float) -> float:
            xs = np.array([_solve(rigid_rhs, X[k], _CHUNK_S, model.rhs_args(U[k]), method,
                                  rtol, rtol).y[:, -1] for k in range(ncal)])
            return float(np.max(np.abs(xs[:, :4] - ref[:, :4])))
        return f

    tols = {}
    for method in ("RK45", "DOP853"):
        tol = tols[method] = _calibrate(chunk_error(method), err_rk4)
        say(f"sim: {method} per 5 ms chunk: rtol = atol = {tol.rtol:g} (error {tol.error:.1e}, "
            f"RK4 {err_rk4:.1e}{'' if tol.matched else ', NOT matched: tightest tried'})")
    return _Accuracy(rk4_error=err_rk4, tolerances=tols)


def _long_accuracy(tr: _RigidTrajectory, say: Progress) -> _Accuracy:
    """One long call's error over the first second against RK4 at 10 us; matched tolerances.

    The long call starts from the run's first state with u = 0; errors are sampled every 1 ms.
    """
    model, x0 = tr.model, tr.x[0].copy()
    t_cal = np.arange(1, 1001) * _DT
    ref_long = np.empty((t_cal.size, 6))
    xr = x0.copy()
    for i in range(t_cal.size):
        xr = model.step(xr, 0.0, 1e-5, 100)
        ref_long[i] = xr
    xk = x0.copy()
    ours_long = np.empty_like(ref_long)
    for i in range(t_cal.size):
        xk = model.step(xk, 0.0, _DT, 1)
        ours_long[i] = xk
    err_rk4 = float(np.max(np.abs(ours_long[:, :4] - ref_long[:, :4])))

    def long_error(method: str) -> Callable[[float], float]:
        def f(rtol: float) -> float:
            sol = _solve(rigid_rhs, x0, 1.0, model.rhs_args(0.0), method, rtol, rtol,
                         t_eval=t_cal)
            return float(np.max(np.abs(sol.y[:4].T - ref_long[:, :4])))
        return f

    tols = {}
    for method in ("RK45", "DOP853"):
        tol = tols[method] = _calibrate(long_error(method), err_rk4)
        say(f"sim: {method} one call: rtol = atol = {tol.rtol:g} (error over 1 s "
            f"{tol.error:.1e}, RK4 {err_rk4:.1e}"
            f"{'' if tol.matched else ', NOT matched: tightest tried'})")
    return _Accuracy(rk4_error=err_rk4, tolerances=tols)


def _rigid_runs(tr: _RigidTrajectory, chunked_acc: _Accuracy, long_acc: _Accuracy
                ) -> dict[str, Callable[[int], None]]:
    """The timed integrations, by figure key; each simulates its first ``m`` chunks."""
    params, model, X, U = tr.params, tr.model, tr.x, tr.u
    x0 = X[0].copy()
    cmd_lists = [[float(u)] for u in U[:tr.n]]

    def node_loop(m: int) -> None:
        sim = RigSimulation(params, X[0, :4], _DT, 0.1)
        for k in range(m):
            sim.set_command(cmd_lists[k])
            for _ in range(_CHUNK):
                sim.step()

    def chunked(m: int) -> None:
        x = X[0].copy()
        for k in range(m):
            x = model.step(x, U[k], _DT, _CHUNK)

    def ivp_chunked(method: str) -> Callable[[int], None]:
        rtol = chunked_acc.tolerances[method].rtol

        def f(m: int) -> None:
            for k in range(m):
                _solve(rigid_rhs, X[k], _CHUNK_S, model.rhs_args(U[k]), method, rtol, rtol)
        return f

    def compiled(m: int) -> None:
        model.step(x0, 0.0, _DT, m * _CHUNK)

    def ivp_long(method: str) -> Callable[[int], None]:
        rtol = long_acc.tolerances[method].rtol

        def f(m: int) -> None:
            _solve(rigid_rhs, x0, m * _CHUNK_S, model.rhs_args(0.0), method, rtol, rtol)
        return f

    return {"node": node_loop, "chunked": chunked, "rk45c": ivp_chunked("RK45"),
            "dop853c": ivp_chunked("DOP853"), "compiled": compiled,
            "rk45l": ivp_long("RK45"), "dop853l": ivp_long("DOP853")}


def _time_runs(runs: dict[str, Callable[[int], None]], tr: _RigidTrajectory, repeats: int,
               say: Progress) -> dict[str, list[float]]:
    """Real-time factors of each run over the whole trajectory, per repeat (after a warm-up)."""
    v: dict[str, list[float]] = {k: [] for k in runs}
    for f in runs.values():  # warm-up (kernels loaded, caches warm), not timed
        f(min(tr.n, 40))
    for rep in range(repeats):
        say(f"sim: rigid model, repeat {rep + 1}/{repeats}")
        for key, f in runs.items():
            t0 = time.perf_counter()
            f(tr.n)
            v[key].append(tr.duration / (time.perf_counter() - t0))
    return v


def _rigid_figures(v: dict[str, list[float]], tr: _RigidTrajectory, chunked_acc: _Accuracy,
                   long_acc: _Accuracy, repeats: int) -> list[Figure]:
    """The ``sim.rigid_*`` figures from the timed real-time factors ``v``."""
    T, err_rk4, err_rk4_long = tr.duration, chunked_acc.rk4_error, long_acc.rk4_error
    traj = (f"closed-loop trajectory on the orbit, {T:g} s, torque held per 5 ms; "
            f"{repeats} repeat(s)")
    figs = []
    figs.append(_fig("sim.rigid_rtf_node", v["node"],
                     f"RigSimulation.step() per 1 ms, set_command every 5 ms; {traj}"))
    figs.append(_fig("sim.rigid_rtf_chunked", v["chunked"],
                     f"RigidModel.step(x, u, 1 ms, 5) per camera frame; {traj}; per-chunk "
                     f"error vs RK4 at 10 us {err_rk4:.1e}", error=err_rk4))
    for key, method, short in (("rk45c", "RK45", "rk45"), ("dop853c", "DOP853", "dop853")):
        tol = chunked_acc.tolerances[method]
        figs.append(_fig(f"sim.rigid_rtf_{short}_chunked", v[key],
                         f"rtol = atol = {tol.rtol:g}, loosest with per-chunk error <= RK4's "
                         f"({tol.error:.1e} vs {err_rk4:.1e}{tol.unmatched_note}); "
                         f"compiled rigid_rhs through a Python wrapper; restarted each 5 ms",
                         rtol=tol.rtol, atol=tol.rtol, error=tol.error, matched=tol.matched))
    for key, method, short in (("rk45c", "RK45", "rk45"), ("dop853c", "DOP853", "dop853")):
        ratios = [a / b for a, b in zip(v["chunked"], v[key], strict=True)]
        figs.append(_fig(f"sim.rigid_ratio_{short}_chunked", ratios,
                         f"RTF ratio within each repeat, same trajectory, same accuracy "
                         f"({method} rtol {chunked_acc.tolerances[method].rtol:g})"))
    figs.append(_fig("sim.rigid_rtf_compiled", v["compiled"],
                     f"model.step(x0, 0, 1 ms, {round(T / _DT)}), u = 0 from the same start; "
                     f"error over 1 s vs RK4 at 10 us {err_rk4_long:.1e}",
                     error=err_rk4_long))
    for key, method, short in (("rk45l", "RK45", "rk45"), ("dop853l", "DOP853", "dop853")):
        tol = long_acc.tolerances[method]
        figs.append(_fig(f"sim.rigid_rtf_{short}_long", v[key],
                         f"one solve_ivp call over {T:g} s, u = 0; rtol = atol = {tol.rtol:g} "
                         f"(error over 1 s {tol.error:.1e} vs RK4 {err_rk4_long:.1e}"
                         f"{tol.unmatched_note})", rtol=tol.rtol, atol=tol.rtol,
                         error=tol.error, matched=tol.matched))
    best = [max(a, b) for a, b in zip(v["rk45l"], v["dop853l"], strict=True)]
    figs.append(_fig("sim.rigid_ratio_long",
                     [a / b for a, b in zip(v["compiled"], best, strict=True)],
                     "one long compiled RK4 call / the faster of RK45 and DOP853 (one call), "
                     "within each repeat"))
    return figs


def _rigid(opts: BenchOptions, say: Progress) -> list[Figure]:
    """The rigid model's figures (module docstring): trajectory, accuracy, timing."""
    horizon = 1.0 if opts.quick else 10.0
    say(f"sim: rigid model, closed-loop reference run of {horizon:g} s")
    tr = _rigid_trajectory(horizon)
    chunked_acc = _chunk_accuracy(tr, opts.quick, say)
    long_acc = _long_accuracy(tr, say)
    v = _time_runs(_rigid_runs(tr, chunked_acc, long_acc), tr, opts.repeats, say)
    return _rigid_figures(v, tr, chunked_acc, long_acc, opts.repeats)


# -- contact model -------------------------------------------------------------------------------
def _row_params(params: Any, phi_start: float) -> tuple[Any, np.ndarray, float]:
    """rig.yaml plus the study's dense row of bumps at phi_start and phi_start + pi."""
    cr = load_study().contact_run
    ph, h, w = bump_row(params, phi_start, cr.row_count, cr.row_length, cr.row_height,
                        cr.row_width)
    ph2 = np.concatenate([ph, ph + math.pi])
    p = with_asperities(params, ph2, np.concatenate([h, h]), np.concatenate([w, w]),
                        append=False)
    desc = (f"{cr.row_count} bumps of {1e3 * cr.row_height:g} mm (sigma "
            f"{1e3 * cr.row_width:g} mm) in {1e3 * cr.row_length:g} mm of contour from "
            f"phi = {phi_start:g} rad and phi + pi")
    return p, ph2, desc  # type: ignore[return-value]


def _contact_loop(model: Any, ctrl: Any, x0r: np.ndarray, duration: float) -> dict[str, Any]:
    """Closed loop on the contact plant, each 1 ms step timed; snapshots of the contact set."""
    ctrl.reset()
    x = model.state_from_rigid(x0r)
    n = round(duration / _DT)
    wall = np.zeros(n)
    xs = np.empty((n + 1, x.size))
    us = np.zeros(n)
    phi = np.full(n, np.nan)       # primary contact angle during step k (its start)
    gap = np.full(n, np.nan)       # distance of the ball from the track at the step's start
    snaps: list[tuple[np.ndarray, ...]] = []
    xs[0] = x
    pending: deque = deque()
    next_cam = 0.0
    for k in range(n):
        t = k * _DT
        if t >= next_cam - 1e-9:
            pending.append((t + 0.005, BallObservation(t, float(x[IX]), float(x[IY]), True)))
            next_cam += 1.0 / 200.0
        obs = []
        while pending and pending[0][0] <= t + 1e-9:
            obs.append(pending.popleft()[1])
        cmd = ctrl.step(t, float(x[ITH]), float(x[ITHD]), obs or None)
        d = model.diagnostics(x, cmd.torque)
        phi[k] = d["phi"]
        gap[k] = -d["penetration"]
        snaps.append(model.snapshot())
        t0 = time.perf_counter()
        x = model.step(x, cmd.torque, _DT)
        wall[k] = time.perf_counter() - t0
        us[k] = cmd.torque
        xs[k + 1] = x
        if not np.all(np.isfinite(x)):
            n = k + 1
            break
    return {"wall": wall[:n], "x": xs[:n + 1], "u": us[:n], "phi": phi[:n], "gap": gap[:n],
            "snaps": snaps[:n], "n": n}


def _restore(model: Any, snap: tuple[np.ndarray, ...]) -> None:
    model.restore(snap)


def _contact(opts: BenchOptions, say: Progress) -> list[Figure]:


    params = load_params()
    phase, phi_row = 0.3, 0.6
    duration = 0.35 if opts.quick else 2.0
    repeats = max(1, min(opts.repeats, 1 if opts.quick else 3))
    p_row, bumps, desc = _row_params(params, phi_row)
    ts = float(params.contact.time_step)
    ctrl = OrbitalController(params)
    x0r = orbit_initial_state(ctrl, phase, d_theta=0.02)
    lo, hi = float(np.min(bumps[: bumps.size // 2])), float(np.max(bumps[: bumps.size // 2]))
    pad = 0.02

    def on_row(phi: np.ndarray, gap: np.ndarray) -> np.ndarray:
        a = np.mod(phi - lo + pad, math.pi)  # both halves (the row repeats after pi)
        return (a <= hi - lo + 2 * pad) & (gap < 1e-3)

    say("sim: contact model, warm-up (compiling or loading the cached kernels)")
    warm = cm.ContactModel(p_row)
    _contact_loop(warm, ctrl, x0r, 0.01)
    v: dict[str, list[float]] = {k: [] for k in ("bumps", "run", "smooth")}
    run: dict[str, Any] = {}
    rows_k = np.zeros(0, int)
    touching = np.zeros(0, int)
    for rep in range(repeats):
        say(f"sim: contact model over the bump row, closed loop {duration:g} s, repeat "
            f"{rep + 1}/{repeats}")
        model = cm.ContactModel(p_row)
        run = _contact_loop(model, ctrl, x0r, duration)
        sel = on_row(run["phi"], run["gap"])
        rows_k = np.nonzero(sel)[0]
        touching = np.nonzero(sel & (run["gap"] <= 0.0))[0]
        if rows_k.size:
            v["bumps"].append(rows_k.size * _DT / float(np.sum(run["wall"][sel])))
        v["run"].append(run["n"] * _DT / float(np.sum(run["wall"])))
        say(f"sim: contact model without bumps, repeat {rep + 1}/{repeats}")
        smooth = cm.ContactModel(params)
        s = _contact_loop(smooth, ctrl, x0r, duration)
        v["smooth"].append(s["n"] * _DT / float(np.sum(s["wall"])))
    gap = run["gap"]
    left = np.nonzero(gap > 1e-3)[0]
    fate = ("the ball stayed within 1 mm of the track" if not left.size else
            f"the ball left the track (gap > 1 mm) at t = {left[0] * _DT:.3f} s")
    setting = (f"contact.time_step {ts:g} s (rig.yaml), 1 call per 1 ms, closed loop with the "
               f"nominal controller (1 kHz), camera 200 Hz + 5 ms")
    figs: list[Figure] = []
    if v["bumps"]:
        figs.append(_fig("sim.contact_rtf_bumps", v["bumps"],
                         f"{setting}; row: {desc}; {rows_k.size} steps of 1 ms on the row, "
                         f"{touching.size} of them starting in contact (last repeat); {fate}",
                         steps_on_row=int(rows_k.size), steps_in_contact=int(touching.size)))
    else:
        figs.append(not_measured(_BY_KEY["sim.contact_rtf_bumps"],
                                 f"the ball never reached the row ({fate})"))
    figs.append(_fig("sim.contact_rtf_run", v["run"], f"{duration:g} s from phi = {phase}; "
                     f"{fate}"))
    figs.append(_fig("sim.contact_rtf_smooth", v["smooth"],
                     f"same closed loop, rig.yaml without bumps, {duration:g} s"))
    if not rows_k.size:
        for key in _ROW_KEYS:
            figs.append(not_measured(_BY_KEY[key], "no steps on the bump row"))
        return figs
    try:
        figs += _contact_methods(say, p_row, run, rows_k, repeats)
    except Exception as exc:  # noqa: BLE001 - the fixed-step figures stand on their own
        figs += [not_measured(_BY_KEY[k], f"{type(exc).__name__}: {exc}")
                 for k in _ROW_KEYS[4:]]
    try:
        figs += _contact_baselines(opts, say, p_row, ts, run,
                                   touching if touching.size else rows_k)
    except Exception as exc:  # noqa: BLE001 - the fixed-step figures stand on their own
        have = {f.spec.key for f in figs}
        for key in _ROW_KEYS:
            if key not in have:
                figs.append(not_measured(_BY_KEY[key], f"{type(exc).__name__}: {exc}"))
    return figs


def _contact_baselines(opts: BenchOptions, say: Progress, p_row: Any, ts: float,
                       run: dict[str, Any], rows_k: np.ndarray) -> list[Figure]:
    """solve_ivp (LSODA, Radau) on the same 1 ms intervals of the row as the fixed-step run."""
    nint = 4 if opts.quick else 12
    ncal = min(3, nint)
    repeats = 1 if opts.quick else max(1, min(opts.repeats, 3))
    ks = rows_k[np.linspace(0, rows_k.size - 1, min(nint, rows_k.size)).round().astype(int)]
    ks = np.unique(ks)
    model = cm.ContactModel(p_row)
    fine = cm.ContactModel(p_row, time_step=ts / 10.0)
    X, U, snaps = run["x"], run["u"], run["snaps"]
    vel = [cm.IVX, cm.IVY]
    ref = []
    ours_err = 0.0
    for k in ks[:ncal]:
        _restore(fine, snaps[k])
        ref.append(fine.step(X[k], U[k], _DT))
        _restore(model, snaps[k])
        y = model.step(X[k], U[k], _DT)
        ours_err = max(ours_err, float(np.max(np.abs(y[vel] - ref[-1][vel]))))

    def integrate(k: int, method: str, rtol: float) -> np.ndarray:
        _restore(model, snaps[k])
        u = float(U[k])
        model.follow(X[k], search=True)  # one search for new contacts per interval

        def f(t: float, y: np.ndarray) -> np.ndarray:
            model.follow(y)  # the contact set follows the state, as in contact_steps
            return model.rhs(t, y, u)

        sol = solve_ivp(f, (0.0, _DT), X[k], method=method, rtol=rtol, atol=rtol * 1e-3)
        if not sol.success:
            raise RuntimeError(f"solve_ivp {method} failed: {sol.message}")
        return sol.y[:, -1]

    # below ~1e-12 m/s the errors are round-off (free flight between bumps): no target there
    target = max(ours_err, 1e-12)
    tols: dict[str, _Tolerance] = {}
    grid = tuple(10.0 ** -k for k in range(3, 10))
    for method in ("LSODA", "Radau"):
        err = math.inf
        rtol = grid[-1]
        ok = False
        for rtol in grid:
            err = max(float(np.max(np.abs(integrate(k, method, rtol)[vel] - r[vel])))
                      for k, r in zip(ks[:ncal], ref, strict=False))
            if err <= target:
                ok = True
                break
        tols[method] = _Tolerance(rtol=rtol, error=err, matched=ok)
        say(f"sim: contact {method}: rtol = {rtol:g}, atol = {rtol * 1e-3:g} (velocity error "
            f"{err:.1e} m/s, RK4 {ours_err:.1e}{'' if ok else ', NOT matched: tightest tried'})")
    v: dict[str, list[float]] = {"ours": [], "LSODA": [], "Radau": []}
    span = ks.size * _DT
    for rep in range(repeats):
        say(f"sim: contact baselines on {ks.size} intervals of the row, repeat "
            f"{rep + 1}/{repeats}")
        wall = 0.0
        for k in ks:
            _restore(model, snaps[k])
            t0 = time.perf_counter()
            model.step(X[k], U[k], _DT)
            wall += time.perf_counter() - t0
        v["ours"].append(span / wall)
        for method in ("LSODA", "Radau"):
            t0 = time.perf_counter()
            for k in ks:
                integrate(int(k), method, tols[method].rtol)
            v[method].append(span / (time.perf_counter() - t0))
    figs = []
    for method in ("LSODA", "Radau"):
        r, e, ok = tols[method].rtol, tols[method].error, tols[method].matched
        figs.append(_fig(f"sim.contact_rtf_{method.lower()}", v[method],
                         f"{ks.size} intervals of 1 ms on the row from the run's states; "
                         f"rtol {r:g}, atol {r * 1e-3:g}: loosest with velocity error <= the "
                         f"fixed step's ({e:.1e} vs {ours_err:.1e} m/s"
                         f"{'' if ok else ': NOT matched'}); contact set re-solved at every "
                         f"evaluation, searched for new contacts once per interval (the "
                         f"model's own stepping searches after M/2 of travel)",
                         rtol=r, atol=r * 1e-3, error=e, matched=ok))
    for method in ("LSODA", "Radau"):
        figs.append(_fig(f"sim.contact_ratio_{method.lower()}",
                         [a / b for a, b in zip(v["ours"], v[method], strict=True)],
                         f"fixed-step RK4 ({ts:g} s) on the same intervals: RTF "
                         f"{float(np.median(v['ours'])):.3g} x (median)"))
    return figs


def _contact_methods(say: Progress, p_row: Any, run: dict[str, Any], ks: np.ndarray,
                     repeats: int) -> list[Figure]:
    """The row intervals stepped as shipped, without free flight, and exhaustively."""
    models = {"intervals": cm.ContactModel(p_row),
              "noflight": cm.ContactModel(p_row.replace(**{"contact.max_flight_step": 0.0})),
              "exhaustive": cm.ContactModel(p_row, exhaustive=True)}
    X, U, snaps = run["x"], run["u"], run["snaps"]
    v: dict[str, list[float]] = {k: [] for k in models}
    steps = 0.0
    span = ks.size * _DT
    for rep in range(repeats):
        say(f"sim: contact stepping by method on {ks.size} row intervals, repeat "
            f"{rep + 1}/{repeats}")
        for name, model in models.items():
            wall = 0.0
            for k in ks:
                model.restore(snaps[k])
                n0 = model.sst[2]
                t0 = time.perf_counter()
                model.step(X[k], U[k], _DT)
                wall += time.perf_counter() - t0
                if name == "intervals":
                    steps += model.sst[2] - n0
            v[name].append(span / wall)
    mean_step = 1e6 * span * repeats / max(steps, 1.0)
    note = (f"all {ks.size} intervals of 1 ms on the row from the run's states, each from its "
            f"saved contact set; contact.time_step {p_row.contact.time_step:g} s")
    return [_fig("sim.contact_rtf_row_intervals", v["intervals"],
                 note + f"; contact.max_flight_step {p_row.contact.max_flight_step:g} s"),
            _fig("sim.contact_rtf_row_noflight", v["noflight"],
                 note + "; contact.max_flight_step = 0 (every step the fixed step)"),
            _fig("sim.contact_rtf_row_exhaustive", v["exhaustive"],
                 note + "; ContactModel(exhaustive=True): contact set searched and every "
                 "candidate evaluated at every step, no flight steps (the compiled closest "
                 "point alone)"),
            _fig("sim.contact_mean_step_row", [mean_step],
                 note + f"; {steps / repeats:.0f} steps per repeat")]


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``sim`` section (module docstring); figures in :data:`SPECS` order."""
    figs: list[Figure] = []
    try:
        figs += _rigid(opts, say)
    except Exception as exc:  # noqa: BLE001 - a failed part is reported, not fatal
        reason = f"{type(exc).__name__}: {exc}"
        figs += [not_measured(s, reason) for s in SPECS if s.key.startswith("sim.rigid")]
    try:
        figs += _contact(opts, say)
    except ImportError as exc:
        figs += [not_measured(s, f"contact model missing ({exc})") for s in SPECS
                 if s.key.startswith("sim.contact")]
    except Exception as exc:  # noqa: BLE001
        reason = f"{type(exc).__name__}: {exc}"
        have = {f.spec.key for f in figs}
        figs += [not_measured(s, reason) for s in SPECS
                 if s.key.startswith("sim.contact") and s.key not in have]
    order = {s.key: i for i, s in enumerate(SPECS)}
    return sorted(figs, key=lambda f: order[f.spec.key])
