"""The noise-only null: what the residual and the fits look like when only noise is there.

Default: **noise injection on the recording itself** (:func:`calibrate_null`). The sensor
noise of the recording is estimated in preprocessing (camera: the fixes against the cubic
through their neighbours, :func:`~bfr_diagnose.preprocess.fix_noise`; encoder: its
resolution, quantisation ``q / sqrt(12)``; a logged velocity: its high-frequency scatter).
Fresh noise of exactly that size is added to the raw measurements (each camera fix, theta,
the logged velocity), the noisy copy goes through the same preprocessing, and the
difference of the two nominal residuals

    r_noise = r(data + noise) - r(data)

is the noise's own contribution to the equation error, propagated through the very
pipeline and along the recording's own trajectory (to first order in the noise, which is
what the filtered-momentum residual is). Nothing is simulated, so the null holds for any
excitation, controller or rig (the old approach simulated nominal runs under a stand-in
controller whose trajectory differed from the recording's).

From ``R`` injections:

- ``sigma``: RMS noise of each equation row (the weights of the cost);
- ``msq``: the expected square of the noise residual at each sample (the noise is not
  stationary: it grows where the ball is fast), the scale of the chi-square tests of
  windows and regions in :mod:`~bfr_diagnose.locate`;
- ``tau``: integrated autocorrelation time of the noise residual [samples];
- per effect, the held-out gain its fit reaches on pure noise. The fit is linearised: the
  effect's residual Jacobian ``D`` at the nominal model (finite differences on the
  recording, the same columns the real fit starts from) and the least-squares coefficient of
  ``r_noise`` on ``D`` over the training blocks, scored on the held-out blocks exactly like
  the real fit; a parameter bounded at its nominal value (friction, rolling resistance,
  misalignment >= 0) is clipped there. Track bumps: the best of a grid of bump positions
  (training) is scored (look-elsewhere effect included).

Processing term: the pipeline has a resolution of its own (the Savitzky-Golay smoothing
bends fast motion; on noise-free data, e.g. a simulator's true trajectory, this bias is all
that is left in the residual and would otherwise look significant). The recording is
preprocessed once more with all filter widths (anti-alias, Savitzky-Golay windows) 1.4 times
as long, and twice the change of the nominal residual, ``2 (r(longer filters) - r(data))``,
is added to every noise draw (the change is one to three times the filters' own bias, which
grows with the width squared to the fourth power; the factor 2 covers the part of the floor
that does not move with the widths: on the simulator's noise-free closed loop the ball row
still sat at 2x the unscaled term where the ball is fastest). The null is then "noise plus
what our own processing does", and nothing below the processing's resolution counts as a
mismatch. On real or noisy data this term is far below the noise.

The threshold of an effect is ``margin * max(null gains) + floor``. Gains are cost ratios,
so they do not depend on the noise level itself, only on the number of effectively
independent samples and on how many directions an effect can fit.

Alternative (``null_recordings``): nominal recordings given by the caller are diagnosed
with every single-effect fit (an empirical null; slower).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from bfr_model.params import RigParams
from bfr_model.recording import Recording
from numpy.typing import NDArray

from bfr_diagnose import DiagnoseError
from bfr_diagnose.effects import EFFECTS
from bfr_diagnose.identify import Problem, _stats, autocorr_time
from bfr_diagnose.preprocess import Prepared, PrepConfig, prepare, prepare_runs
from bfr_diagnose.residual import Residual, ResidualConfig, ResidualEvaluator

__all__ = ["NullCalibration", "calibrate_null", "noisy_copy"]

FloatArray = NDArray[np.float64]


@dataclass
class NullCalibration:
    """Noise scales and per-effect null gains.

    Attributes
    ----------
    sigma : list of float
        Noise scale of rows 1 and 2 [N m] (robust, median over the injections).
    gains : dict
        Held-out gain of each effect in each null draw.
    thresholds : dict
        Largest null gain times ``margin`` plus ``floor``, per effect.
    tau : float
        Autocorrelation time of the noise residual [samples].
    runs : int
        Null draws used.
    noise : dict
        Noise levels injected (camera [m], theta [rad], theta_dot [rad/s]).
    source : str
        How the null was made.
    rms_null : list of float
        RMS of the noise residual of rows 1, 2 [N m].
    msq : list of ndarray or None
        Expected square of the noise residual at each kept sample, rows 1 and 2 [N^2 m^2]
        (mean over the injections): the noise is not stationary (it depends on the ball's
        place and speed), so the window and region tests of
        :mod:`~bfr_diagnose.locate` compare with this, not with ``sigma^2``. Not in JSON.
    """

    sigma: list[float]
    gains: dict[str, list[float]]
    thresholds: dict[str, float]
    tau: float
    runs: int
    noise: dict[str, float]
    source: str
    rms_null: list[float] = field(default_factory=list)
    msq: list[FloatArray] | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (without the per-sample ``msq``)."""
        d = asdict(self)
        d.pop("msq", None)
        return d


def _levels(prep: Prepared) -> dict[str, float]:
    """Noise levels to inject (module docstring)."""
    res = float(prep.info.get("theta_resolution", 0.0))
    th = max(res / math.sqrt(12.0), float(prep.noise.get("theta", 0.0)) if
             not prep.info.get("theta_coarse") else 0.0)
    cam = float(prep.noise.get("camera", float("nan")))
    return {"camera": cam if math.isfinite(cam) else 0.0, "theta": th,
            "theta_dot": (float(prep.noise.get("theta_dot", 0.0))
                          if prep.info.get("theta_coarse") else 0.0)}


def noisy_copy(rec: Recording, levels: dict[str, float], rng: np.random.Generator,
               resolution: float | None = None) -> Recording:
    """``rec`` with fresh sensor noise of the given levels added (module docstring).

    Camera: independent Gaussian noise per fix and axis [m], held with the fix. theta:
    Gaussian of ``levels["theta"]`` [rad]. Logged velocity: Gaussian of
    ``levels["theta_dot"]`` [rad/s] per sample. ``resolution`` [rad] is kept as the copy's
    ``meta["theta_resolution"]`` so that preprocessing treats it like the original.
    """
    n = rec.n
    bx, by = rec.ball_x.copy(), rec.ball_y.copy()
    if levels.get("camera", 0.0) > 0.0 and rec.ball_valid.any():
        new = rec.new_fix_mask()
        hold = np.cumsum(new) - 1
        nf = int(new.sum())
        ex = levels["camera"] * rng.standard_normal(nf)
        ey = levels["camera"] * rng.standard_normal(nf)
        v = rec.ball_valid & (hold >= 0)
        bx[v] += ex[hold[v]]
        by[v] += ey[hold[v]]
    theta = rec.theta + levels.get("theta", 0.0) * rng.standard_normal(n)
    thd = rec.theta_dot + levels.get("theta_dot", 0.0) * rng.standard_normal(n)
    meta = dict(rec.meta)
    meta["theta_resolution"] = (resolution if resolution is not None
                                else rec.meta.get("theta_resolution"))
    return Recording(t=rec.t, theta=theta, theta_dot=thd, torque=rec.torque, ball_x=bx,
                     ball_y=by, ball_valid=rec.ball_valid, phi=rec.phi, meta=meta)


def _linear_gain(D: FloatArray, e: FloatArray, train: NDArray[np.bool_],
                 test: NDArray[np.bool_], clip0: NDArray[np.bool_]) -> float:
    """Held-out gain of the least-squares fit ``e + D b`` (b fitted on the training rows)."""
    A = D[train]
    y = e[train]
    ok = np.isfinite(y) & np.all(np.isfinite(A), axis=1)
    if ok.sum() < D.shape[1] + 2 or not np.any(A[ok]):
        return 0.0
    b = np.linalg.lstsq(A[ok], -y[ok], rcond=None)[0]
    if D.shape[1] == 1 and clip0[0] and b[0] < 0.0:
        b[0] = 0.0
    et = e[test]
    rt = et + D[test] @ b
    m = np.isfinite(rt)
    c0 = float(np.sum(et[m] ** 2))
    return 1.0 - float(np.sum(rt[m] ** 2)) / c0 if c0 > 0 else 0.0


def _row_scale(rs: list[FloatArray]) -> float:
    """RMS of pure-noise residuals (the scale a sum of squares is compared with)."""
    r = np.concatenate(rs)
    r = r[np.isfinite(r)]
    if r.size < 3:
        return 1.0
    return float(max(np.sqrt(np.mean(r ** 2)), 1e-15))


def calibrate_null(prep: Prepared, base: RigParams, pcfg: PrepConfig, rcfg: ResidualConfig,
                   block: float, *, rec: Recording | list[Recording] | None = None,
                   runs: int = 6,
                   seed: int = 0, null_recordings: list[Recording] | None = None,
                   margin: float = 1.25, floor: float = 0.02, progress: Any = None,
                   evaluator: ResidualEvaluator | None = None,
                   problem: Problem | None = None, processing: bool = True
                   ) -> NullCalibration:
    """Calibrate the null for a prepared recording (module docstring).

    Parameters
    ----------
    prep : Prepared
        The recording under diagnosis, preprocessed.
    base : RigParams
        Nominal parameters.
    pcfg, rcfg : PrepConfig, ResidualConfig
        The same settings as the diagnosis.
    block : float
        Train/test block length [s].
    rec : Recording or list of Recording, optional
        The raw recording (needed for noise injection, the default); several runs are
        injected separately and stitched like the prepared data.
    runs : int
        Noise draws.
    seed : int
        Seed of the noise generator.
    null_recordings : list of Recording, optional
        Nominal recordings to use instead (empirical null: every single-effect fit on each).
    margin, floor : float
        Threshold = ``margin * max(null gain) + floor``.
    progress : callable, optional
        ``progress(str)``.
    evaluator : ResidualEvaluator, optional
        The recording's evaluator (reused).
    problem : Problem, optional
        The recording's identification problem: its weights are set to the null's sigma and
        its nominal Jacobians are computed here and reused by the selection.
    processing : bool
        Add the processing term to every draw (module docstring).
    """
    if null_recordings is not None:
        return _empirical_null(null_recordings, prep, base, pcfg, rcfg, block, margin, floor,
                               progress)
    if rec is None:
        raise ValueError("calibrate_null needs the raw recording for noise injection")
    rng = np.random.default_rng(seed)
    recs = list(rec) if isinstance(rec, (list, tuple)) else [rec]
    levels = _levels(prep)
    prob = (problem if problem is not None
            else Problem(evaluator or ResidualEvaluator(prep, rcfg), base, block))
    ev = prob.ev
    rows0 = ev.evaluate(base)
    draws = _noise_draws(recs, prep, base, pcfg, rcfg, ev, rows0, levels, runs, rng)
    proc_note = ""
    if processing:
        term = _processing_term(recs, prep, base, pcfg, rcfg, ev, rows0)
        if term is not None:
            draws = [d + term for d in draws]
            proc_note = ("; plus twice the residual's change with the filter widths "
                         "(x1.4), the processing's own resolution")
    has_ball = prep.has_ball
    s1, s2, taus = _set_weights(prob, draws)
    if progress:
        rows = f"{s1:.3g}, {s2:.3g} N m" if has_ball else f"{s1:.3g} N m (frame row)"
        progress(f"null: {runs} noise injections (camera {levels['camera'] * 1e3:.3f} mm, "
                 f"theta {levels['theta']:.2g} rad, theta_dot {levels['theta_dot']:.2g} "
                 f"rad/s): row noise {rows}")
    gains = _null_gains(prob, base, draws)
    thresholds = {n: float(margin * max(*v, 0.0) + floor) for n, v in gains.items()}
    msq, rms = _expected_squares(draws, has_ball)
    return NullCalibration(
        sigma=[s1, s2], gains=gains, thresholds=thresholds, tau=float(np.median(taus)),
        runs=runs, noise=levels, rms_null=rms, msq=msq,
        source=(f"{runs} noise injections into the recording itself (camera "
                f"{levels['camera'] * 1e3:.3g} mm per axis, theta {levels['theta']:.2g} rad, "
                f"logged theta_dot {levels['theta_dot']:.2g} rad/s){proc_note}"))


@dataclass(frozen=True, kw_only=True, eq=False)
class _Draw:
    """One draw of the noise residual: its contribution to the nominal rows 1, 2 [N m]."""

    r1: FloatArray
    r2: FloatArray

    def __add__(self, other: _Draw) -> _Draw:
        return _Draw(r1=self.r1 + other.r1, r2=self.r2 + other.r2)


def _noise_draws(recs: list[Recording], prep: Prepared, base: RigParams, pcfg: PrepConfig,
                 rcfg: ResidualConfig, ev: ResidualEvaluator, rows0: Residual,
                 levels: dict[str, float], runs: int, rng: np.random.Generator
                 ) -> list[_Draw]:
    """``r(data + noise) - r(data)`` of ``runs`` noise injections (module docstring).

    Parameters
    ----------
    recs : list of Recording
        The raw runs (each gets its own noise; prepared and stitched like ``prep``).
    prep : Prepared
        The recording, preprocessed.
    base : RigParams
        Nominal parameters.
    pcfg, rcfg : PrepConfig, ResidualConfig
        The diagnosis's settings.
    ev : ResidualEvaluator
        The recording's evaluator.
    rows0 : Residual
        Its nominal residual.
    levels : dict
        Noise levels to inject (:func:`_levels`).
    runs : int
        Number of draws.
    rng : numpy.random.Generator
        The noise generator.

    Raises
    ------
    RuntimeError
        The noise changed which samples are usable.
    """
    draws = []
    for _ in range(runs):
        res = prep.info.get("theta_resolution")
        p_n = prepare_runs([noisy_copy(r, levels, rng, res) for r in recs], pcfg,
                           latency0=prep.latency0)
        ev_n = ResidualEvaluator(p_n, rcfg)
        if ev_n.idx.size != ev.idx.size or not np.array_equal(ev_n.idx, ev.idx):
            raise RuntimeError("noise injection changed the usable samples")
        r = ev_n.evaluate(base)
        draws.append(_Draw(r1=r.r1 - rows0.r1, r2=r.r2 - rows0.r2))
    return draws


def _processing_term(recs: list[Recording], prep: Prepared, base: RigParams,
                     pcfg: PrepConfig, rcfg: ResidualConfig, ev: ResidualEvaluator,
                     rows0: Residual) -> _Draw | None:
    """The processing's own resolution, added to every draw (module docstring).

    Twice the change of the nominal residual when every filter width (anti-alias,
    Savitzky-Golay windows) is 1.4 times as long; None when the longer filters change which
    samples are usable, or leave none.
    """
    alt = replace(pcfg, sg_theta=1.4 * pcfg.sg_theta, sg_ball=1.4 * pcfg.sg_ball,
                  antialias=1.4 * pcfg.antialias)
    try:
        ev_a = ResidualEvaluator(prepare_runs(recs, alt, latency0=prep.latency0), rcfg)
        if not np.array_equal(ev_a.idx, ev.idx):
            return None
        r = ev_a.evaluate(base)
    except DiagnoseError:
        return None
    return _Draw(r1=2.0 * (r.r1 - rows0.r1), r2=2.0 * (r.r2 - rows0.r2))


def _set_weights(prob: Problem, draws: list[_Draw]) -> tuple[float, float, list[float]]:
    """Set the problem's row weights to the noise's RMS on the training blocks.

    Returns
    -------
    s1, s2 : float
        RMS noise of rows 1 and 2 [N m] (``s2`` is 1 without a ball).
    taus : list of float
        Autocorrelation time of each draw [samples] (the larger of the two rows).
    """
    has_ball = prob.has_ball
    s1 = _row_scale([d.r1[prob.train] for d in draws])
    s2 = _row_scale([d.r2[prob.train] for d in draws]) if has_ball else 1.0
    prob.s = (s1, s2)
    taus = []
    for d in draws:
        t = autocorr_time(d.r1[prob.train] / s1)
        if has_ball:
            t = max(t, autocorr_time(d.r2[prob.train] / s2))
        taus.append(t)
    return s1, s2, taus


def _expected_squares(draws: list[_Draw], has_ball: bool
                      ) -> tuple[list[FloatArray], list[float]]:
    """Mean square of the draws at each sample, rows 1 and 2 [N^2 m^2], and their RMS [N m].

    The RMS of row 2 is NaN without a ball.
    """
    msq = [np.mean([d.r1 ** 2 for d in draws], axis=0),
           np.mean([d.r2 ** 2 for d in draws], axis=0)]
    rms = [float(np.sqrt(np.nanmean(msq[0]))),
           float(np.sqrt(np.nanmean(msq[1]))) if has_ball else float("nan")]
    return msq, rms


def _null_gains(prob: Problem, base: RigParams, draws: list[_Draw]) -> dict[str, list[float]]:
    """Held-out gain of each candidate effect's linearised fit on each noise draw.

    The effect's residual Jacobian at the nominal model (cached in ``prob``, reused by the
    selection) against the weighted draw; a bump: the best grid position
    (:func:`_bump_null_gains`). Needs the weights set (:func:`_set_weights`).
    """
    s1, s2 = prob.s
    tr = prob.rows_mask(prob.train)
    te = prob.rows_mask(prob.test)
    w0 = prob.weighted([]).ravel()
    es = [np.concatenate([d.r1 / s1, d.r2 / s2]) if prob.has_ball else d.r1 / s1
          for d in draws]
    gains: dict[str, list[float]] = {}
    for name in prob.candidates:
        eff = EFFECTS[name]
        if name == "track_bumps":
            gains[name] = _bump_null_gains(prob, es, tr, te)
            continue
        x0 = np.asarray(eff.start(base), float)
        D = prob.jacobian([], eff, x0, w0)
        clip0 = np.isclose(x0, np.asarray(eff.lower, float))
        gains[name] = [_linear_gain(D, e, tr, te, clip0) for e in es]
    return gains


def _bump_null_gains(prob: Problem, es: list[FloatArray], tr: NDArray[np.bool_],
                     te: NDArray[np.bool_]) -> list[float]:
    """Null gains of a bump: best grid position on the training rows, scored held out."""
    cols = [c for _, c in prob.bump_columns([])]
    out = []
    for e in es:
        best, best_c = -1.0, None
        for c in cols:
            a = c[tr]
            den = float(np.dot(a, a))
            if den <= 0:
                continue
            g = float(np.dot(a, e[tr])) ** 2 / den
            if g > best:
                best, best_c = g, c
        out.append(0.0 if best_c is None else
                   _linear_gain(best_c[:, None], e, tr, te, np.array([False])))
    return out


def _empirical_null(recs: list[Recording], prep: Prepared, base: RigParams, pcfg: PrepConfig,
                    rcfg: ResidualConfig, block: float, margin: float, floor: float,
                    progress: Any) -> NullCalibration:
    """Every single-effect fit on nominal recordings given by the caller."""
    gains: dict[str, list[float]] = {}
    sig1, sig2, taus, rms1, rms2 = [], [], [], [], []
    for k, rec in enumerate(recs):
        if progress:
            progress(f"null: fitting every effect on nominal recording {k + 1}/{len(recs)}")
        p = prepare(rec, pcfg, latency0=prep.latency0)
        prob = Problem(ResidualEvaluator(p, rcfg), base, block)
        prob.set_weights([])
        c_tr, c_te, w = prob.cost([])
        tau = autocorr_time(w[0, prob.train])
        n_eff = w.shape[0] * prob.train.sum() / tau
        for name in prob.candidates:
            eff = EFFECTS[name]
            start = prob.bump_start([]) if name == "track_bumps" else None
            fit = prob.fit([], eff, start)
            gains.setdefault(name, []).append(_stats(prob, (c_tr, c_te), fit, n_eff, eff.k)[0])
        r1, r2 = prob.rows([])
        sig1.append(prob.s[0])
        sig2.append(prob.s[1])
        taus.append(tau)
        rms1.append(float(np.sqrt(np.nanmean(r1 ** 2))))
        rms2.append(float(np.sqrt(np.nanmean(r2 ** 2))) if p.has_ball else float("nan"))
    thresholds = {n: float(margin * max(*v, 0.0) + floor) for n, v in gains.items()}
    return NullCalibration(
        sigma=[float(np.median(sig1)), float(np.median(sig2))], gains=gains,
        thresholds=thresholds, tau=float(np.median(taus)), runs=len(recs),
        noise={k: float(v) for k, v in prep.noise.items()},
        source=f"{len(recs)} nominal recording(s) given by the caller",
        rms_null=[float(np.median(rms1)), float(np.nanmedian(rms2))
                  if np.isfinite(rms2).any() else float("nan")])
