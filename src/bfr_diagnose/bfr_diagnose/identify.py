"""Fit, rank and select effects; confidence intervals; confounded and degenerate fits.

Cost. The weighted equation error ``e = [r1 / s1, r2 / s2]`` (rows of
:mod:`~bfr_diagnose.residual`, ``s_i`` the RMS noise of each row from the noise-only
null, :mod:`~bfr_diagnose.null`) on time blocks: alternating blocks of ``block`` seconds
are training and held-out data. Fits are bounded nonlinear least squares on the training
blocks (``scipy.optimize.least_squares``, trust-region reflective).

Statistics. ``gain = 1 - C_test(fit) / C_test(current)``, the held-out cost reduction; and
``dBIC = N_eff ln(C_train(fit) / C_train(current)) + k ln(N_eff)`` with
``N_eff = N / tau`` (``tau`` the integrated autocorrelation time of the nominal residual,
since the filtered residual is correlated). An effect is significant when its held-out gain
exceeds the null's largest gain for that effect (x1.25 + 0.02), ``dBIC < -6`` (strong
evidence), its joint fit is not degenerate, and it is larger than its engineering
resolution (:data:`~bfr_diagnose.effects.MIN_SIZE`: a 20-um bump, a 0.1-mm camera
offset, a 0.2 % inertia change, ...; a noise-free simulation must not produce micrometre
"bumps").

Selection, greedy forward. At each stage every candidate gets one Gauss-Newton step on
top of the effects chosen so far (the linearised screening; at the first stage the
Jacobians are those the null already computed); the three best and any within half of its
threshold are then fitted fully, jointly with the chosen effects (all refitted, so an
effect can show its worth once the others move with it). The best significant one is
added; it stops when nothing is significant or after ``max_effects``. So two effects
present are found as two.

Degenerate fits. A joint fit in which a parameter runs to a bound that its nominal value is
not at (e.g. the frame inertia to its floor while the Coulomb friction grows to the constant
command: the equation error's trivial solution), or in which two parameters of different
effects correlate beyond 0.995, is not identifiable from this recording: never added,
reported. Confounded pairs: when the runner-up explains nearly as much as the winner and
their joint fit correlates beyond 0.9 (or adds nothing), the pair is reported instead of
guessed.

Intervals. ``cov = s^2 (J^T J)^-1 tau`` at the optimum (``s^2`` the residual variance per
sample, ``tau`` the autocorrelation inflation), 95 % intervals ``+- 1.96 sqrt(diag)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_model.params import ParameterError, RigParams
from numpy.typing import NDArray
from scipy.optimize import OptimizeWarning, least_squares

from bfr_diagnose.effects import (
    EFFECTS,
    FRAME_ONLY_EFFECTS,
    MIN_SIZE,
    Effect,
    apply_effects,
    display_values,
    effect_size,
)
from bfr_diagnose.preprocess import SensorCorrection
from bfr_diagnose.residual import ResidualEvaluator

__all__ = ["Fit", "Problem", "Selection", "autocorr_time", "select_effects"]

FloatArray = NDArray[np.float64]
Chosen = list[tuple[Effect, FloatArray]]


def autocorr_time(x: FloatArray, max_lag: int = 60) -> float:
    """Integrated autocorrelation time ``1 + 2 sum rho_k`` [samples], summed while rho > 0.05."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size < 10:
        return 1.0
    x = x - x.mean()
    v = float(np.dot(x, x))
    if v <= 0:
        return 1.0
    tau = 1.0
    for k in range(1, min(max_lag, x.size // 4)):
        rho = float(np.dot(x[:-k], x[k:]) / v)
        if rho < 0.05:
            break
        tau += 2.0 * rho
    return float(min(tau, max_lag))


@dataclass
class Fit:
    """One fitted candidate (the chosen effects plus possibly one new one)."""

    effects: list[str]
    values: list[FloatArray]
    cost_train: float
    cost_test: float
    cov: FloatArray | None = None
    n_params: int = 0
    ok: bool = True

    def chosen(self) -> Chosen:
        """``(Effect, values)`` pairs."""
        return [(EFFECTS[n], v) for n, v in zip(self.effects, self.values, strict=True)]


@dataclass(frozen=True, kw_only=True)
class Selection:
    """Result of the greedy selection (see module docstring)."""

    chosen: list[str]
    final: Fit
    stages: list[dict[str, Any]]
    ranking: list[dict[str, Any]]
    confounded: list[dict[str, Any]]
    weights: tuple[float, float]
    tau: float
    params: RigParams
    sensor: SensorCorrection
    parameters: list[dict[str, Any]] = field(default_factory=list)


class Problem:
    """The identification problem of one prepared recording.

    Parameters
    ----------
    evaluator : ResidualEvaluator
        Equation-error evaluator.
    base : RigParams
        Nominal parameters.
    block : float
        Length of the alternating train/test blocks [s].
    """

    def __init__(self, evaluator: ResidualEvaluator, base: RigParams, block: float) -> None:
        self.ev = evaluator
        self.base = base
        t = evaluator.prep.t[evaluator.idx]
        blk = np.floor((t - t[0]) / block).astype(int)
        self.train = blk % 2 == 0
        self.test = ~self.train
        self.has_ball = evaluator.prep.has_ball
        self.s = (1.0, 1.0)
        self.n_eval = 0
        self._jac_cache: dict[tuple, Any] = {}

    @property
    def candidates(self) -> list[str]:
        """Effects that apply to this recording."""
        return list(EFFECTS) if self.has_ball else list(FRAME_ONLY_EFFECTS)

    def rows(self, chosen: Chosen) -> tuple[FloatArray, FloatArray]:
        """Unweighted rows (r1, r2) [N m] of the base with the chosen effects applied."""
        params, sensor = apply_effects(self.base, chosen)
        self.n_eval += 1
        res = self.ev.evaluate(params, sensor)
        return res.r1, res.r2

    def weighted(self, chosen: Chosen) -> FloatArray:
        """Weighted residual over all kept samples, shape (rows, n)."""
        r1, r2 = self.rows(chosen)
        if self.has_ball:
            return np.vstack([r1 / self.s[0], r2 / self.s[1]])
        return (r1 / self.s[0])[None, :]

    def set_weights(self, chosen: Chosen) -> None:
        """Robust scales of the rows of ``chosen`` on the training blocks."""
        r1, r2 = self.rows(chosen)

        def scale(r: FloatArray) -> float:
            r = r[self.train]
            r = r[np.isfinite(r)]
            return float(max(1.4826 * np.median(np.abs(r - np.median(r))), 1e-12))

        self.s = (scale(r1), scale(r2) if self.has_ball else 1.0)

    def cost(self, chosen: Chosen) -> tuple[float, float, FloatArray]:
        """(train cost, test cost, weighted residual)."""
        w = self.weighted(chosen)
        return float(np.sum(w[:, self.train] ** 2)), float(np.sum(w[:, self.test] ** 2)), w

    def fit(self, fixed: Chosen, new: Effect | None, start: FloatArray | None = None,
            max_nfev: int = 60, frozen: Chosen | None = None) -> Fit:
        """Fit the fixed effects (refitted) plus ``new`` jointly on the training blocks.

        ``frozen`` effects are applied first with their values held (not fitted).
        """
        frozen = list(frozen or [])
        effs = [e for e, _ in fixed] + ([new] if new is not None else [])
        starts = [np.asarray(v, float) for _, v in fixed]
        if new is not None:
            starts.append(np.asarray(start if start is not None else new.start(self.base),
                                     float))
        scales = np.concatenate([np.asarray(e.scales) for e in effs])
        lo = np.concatenate([np.asarray(e.lower) for e in effs])
        hi = np.concatenate([np.asarray(e.upper) for e in effs])
        x0n = np.clip(np.concatenate(starts), lo + 0.5 * scales, hi - 0.5 * scales)
        sizes = [e.k for e in effs]
        cuts = np.cumsum(sizes)[:-1]

        def unpack(xn: FloatArray) -> Chosen:
            vals = np.split(x0n + xn * scales, cuts)
            return frozen + list(zip(effs, vals, strict=True))

        n_rows = 2 if self.has_ball else 1
        bad_len = n_rows * int(self.train.sum())

        def fun(xn: FloatArray) -> FloatArray:
            try:
                w = self.weighted(unpack(xn))
            except (ParameterError, ValueError, ZeroDivisionError):
                return np.full(bad_len, 1e3)
            out = w[:, self.train].ravel()
            if not np.all(np.isfinite(out)):
                return np.full(bad_len, 1e3)
            return out

        lb = (lo - x0n) / scales
        ub = (hi - x0n) / scales
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OptimizeWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            sol = least_squares(fun, np.zeros(x0n.size), bounds=(lb, ub), method="trf",
                                diff_step=1e-2, max_nfev=max_nfev, x_scale=1.0)
        chosen = unpack(sol.x)
        try:
            c_tr, c_te, _ = self.cost(chosen)
            ok = math.isfinite(c_tr) and math.isfinite(c_te)
        except (ParameterError, ValueError):
            c_tr = c_te = math.inf
            ok = False
        cov = None
        try:
            jac = sol.jac
            n = jac.shape[0]
            s2 = 2.0 * sol.cost / max(n - x0n.size, 1)
            jtj = jac.T @ jac
            cov_n = np.linalg.pinv(jtj) * s2
            cov = cov_n * np.outer(scales, scales)
        except (np.linalg.LinAlgError, ValueError):
            cov = None
        return Fit(effects=[e.name for e, _ in chosen], values=[v for _, v in chosen],
                   cost_train=c_tr, cost_test=c_te, cov=cov, n_params=int(x0n.size), ok=ok)

    def _key(self, chosen: Chosen, what: str) -> tuple | None:
        """Cache key of a Jacobian: only for the nominal model (nothing chosen)."""
        return None if chosen else (what, self.s)

    def jacobian(self, chosen: Chosen, eff: Effect, x0: FloatArray,
                 w0: FloatArray) -> FloatArray:
        """Weighted residual Jacobian of ``eff`` at ``x0`` on top of ``chosen``.

        Forward differences of one ``scale`` per parameter (towards the inside of the
        bounds); shape ``(rows * n, k)``, rows stacked as in :meth:`weighted`. ``w0`` is the
        raveled weighted residual of ``chosen`` (with ``eff`` at ``x0``, i.e. its start).
        Cached for the nominal model (the null computes the same columns).
        """
        key = self._key(chosen, eff.name)
        if key is not None and key in self._jac_cache:
            return self._jac_cache[key]
        cols = []
        for j in range(eff.k):
            h = float(eff.scales[j])
            if x0[j] + h > eff.upper[j]:
                h = -h
            x = np.array(x0, float)
            x[j] += h
            try:
                w = self.weighted([*chosen, (eff, x)]).ravel()
                cols.append((w - w0) / h)
            except (ParameterError, ValueError, ZeroDivisionError):
                cols.append(np.zeros_like(w0))
        D = np.stack(cols, axis=1)
        D[~np.isfinite(D)] = 0.0
        if key is not None:
            self._jac_cache[key] = D
        return D

    def bump_columns(self, chosen: Chosen, n_grid: int = 48, width: float = 0.1,
                     dh: float = 1e-4) -> list[tuple[float, FloatArray]]:
        """Residual response to a unit bump height at each grid position (cached if nominal).

        ``(phi_c, column)`` pairs: the weighted residual change per metre of a Gaussian bump
        of the given width at ``phi_c`` (the residual is close to linear in the height).
        """
        key = self._key(chosen, "track_bumps/grid")
        if key is not None and key in self._jac_cache:
            return self._jac_cache[key]
        eff = EFFECTS["track_bumps"]
        w0 = self.weighted(chosen).ravel()
        out = []
        for phi_c in np.linspace(0.0, 2.0 * np.pi, n_grid, endpoint=False):
            try:
                w1 = self.weighted([*chosen, (eff, np.array([phi_c, dh, width]))]).ravel()
            except (ParameterError, ValueError):
                continue
            col = (w1 - w0) / dh
            col[~np.isfinite(col)] = 0.0
            out.append((float(phi_c), col))
        if key is not None:
            self._jac_cache[key] = out
        return out

    def rows_mask(self, which: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The per-sample mask ``which`` (train/test) tiled over the rows of :meth:`weighted`."""
        return np.tile(which, 2 if self.has_ball else 1)

    def bump_start(self, fixed: Chosen, n_grid: int = 48, width: float = 0.1,
                   e: FloatArray | None = None) -> FloatArray:
        """Starting bump (phi_b, h, w): best single-bump position on a grid (linear in h).

        ``e`` is the raveled weighted residual to explain (default: that of ``fixed``).
        """
        tr = self.rows_mask(self.train)
        w0 = (self.weighted(fixed).ravel() if e is None else e)[tr]
        best = (-1.0, 0.0, 0.0)
        for phi_c, col in self.bump_columns(fixed, n_grid, width):
            d = col[tr]
            dd = float(np.dot(d, d))
            if dd <= 0:
                continue
            gain = float(np.dot(w0, d)) ** 2 / dd
            if gain > best[0]:
                best = (gain, phi_c, -float(np.dot(w0, d)) / dd)
        h = float(np.clip(best[2], -1e-3, 1e-3))
        return np.array([best[1], h, width])

    def linear_fit(self, chosen: Chosen, eff: Effect, w: FloatArray
                   ) -> tuple[FloatArray, float, float]:
        """One Gauss-Newton step for ``eff`` on top of ``chosen`` (the linearised fit).

        Returns the parameter values (bounded), and the training and held-out costs of the
        linearised residual ``w + D b``. ``w`` is the raveled weighted residual of ``chosen``.
        """
        tr = self.rows_mask(self.train)
        te = self.rows_mask(self.test)
        if eff.name == "track_bumps":
            x0 = self.bump_start(chosen, e=w)
            cols = dict(self.bump_columns(chosen))
            D = cols.get(x0[0], np.zeros_like(w))[:, None]
            b = np.array([x0[1]])
            vals = x0
        else:
            x0 = np.asarray(eff.start(self.base), float)
            D = self.jacobian(chosen, eff, x0, w)
            A = D[tr]
            if not np.any(A):
                b = np.zeros(eff.k)
            else:
                b = np.linalg.lstsq(A, -w[tr], rcond=None)[0]
            vals = np.clip(x0 + b, np.asarray(eff.lower, float), np.asarray(eff.upper, float))
            b = vals - x0
        c_tr = float(np.sum((w[tr] + D[tr] @ b) ** 2))
        c_te = float(np.sum((w[te] + D[te] @ b) ** 2))
        return vals, c_tr, c_te


def _stats(prob: Problem, cur: tuple[float, float], fit: Fit, n_eff: float,
           k_new: int) -> tuple[float, float]:
    gain = 1.0 - fit.cost_test / cur[1] if cur[1] > 0 else 0.0
    if not fit.ok or fit.cost_train <= 0:
        return -math.inf, math.inf
    dbic = n_eff * math.log(fit.cost_train / cur[0]) + k_new * math.log(max(n_eff, 2.0))
    return float(gain), float(dbic)


def _add_confound(out: list[dict[str, Any]], stage: int, effects: list[str], kind: str,
                  rho: float, note: str) -> None:
    """Record a confounded set once (the earliest note is kept).

    A degenerate fit is recorded once per added effect, and not at all when that effect is
    already reported confounded with one of the chosen ones.
    """
    for c in out:
        if c["kind"] == kind and frozenset(c["effects"]) == frozenset(effects):
            return
        if kind == "degenerate" and effects[-1] in c["effects"] and (
                c["kind"] == "pair" or c["effects"][-1] == effects[-1]):
            return
    out.append({"stage": stage, "effects": effects, "pair": effects[-2:], "kind": kind,
                "correlation": rho, "note": note})


def _degenerate(prob: Problem, fit: Fit, max_corr: float) -> str | None:
    """Why a joint fit is not identifiable, or None (see :func:`select_effects`)."""
    if not fit.ok:
        return "fit failed"
    for name, vals in zip(fit.effects, fit.values, strict=True):
        eff = EFFECTS[name]
        x0 = np.asarray(eff.start(prob.base), float)
        lo, hi = np.asarray(eff.lower, float), np.asarray(eff.upper, float)
        tol = 1e-3 * (hi - lo)
        for j, v in enumerate(np.asarray(vals, float)):
            if v - lo[j] < tol[j] and x0[j] - lo[j] >= tol[j]:
                return f"{name}.{eff.names[j]} at its lower bound {lo[j]:.3g}"
            if hi[j] - v < tol[j] and hi[j] - x0[j] >= tol[j]:
                return f"{name}.{eff.names[j]} at its upper bound {hi[j]:.3g}"
    if fit.cov is not None and len(fit.effects) > 1:
        for i, a in enumerate(fit.effects):
            for b in fit.effects[i + 1:]:
                if a == b:
                    continue
                rho = _corr_between(fit, a, b)
                if np.isfinite(rho) and rho > max_corr:
                    return f"{a} and {b} correlate {rho:.3f}"
    return None


def _corr_between(fit: Fit, a: str, b: str) -> float:
    """Largest |correlation| between a parameter of effect a and one of effect b."""
    if fit.cov is None:
        return float("nan")
    sizes = [EFFECTS[n].k for n in fit.effects]
    offs = np.concatenate([[0], np.cumsum(sizes)])
    ia = fit.effects.index(a)
    ib = fit.effects.index(b)
    d = np.sqrt(np.maximum(np.diag(fit.cov), 1e-300))
    corr = fit.cov / np.outer(d, d)
    block = corr[offs[ia]:offs[ia + 1], offs[ib]:offs[ib + 1]]
    return float(np.max(np.abs(block))) if block.size else float("nan")


@dataclass(frozen=True, kw_only=True)
class _Criteria:
    """What a candidate must reach, and how it is screened (see :func:`select_effects`)."""

    thresholds: dict[str, float]
    dbic_min: float
    confound_corr: float
    screen_top: int
    screen_frac: float
    degenerate_corr: float

    def threshold(self, name: str) -> float:
        """Held-out gain the effect ``name`` must exceed (0 when the null has none)."""
        return self.thresholds.get(name, 0.0)


@dataclass(frozen=True, kw_only=True)
class _Screened:
    """A candidate's linearised fit: one Gauss-Newton step (:meth:`Problem.linear_fit`)."""

    values: FloatArray      # the stepped parameter values (bounded)
    gain: float             # held-out gain of the linearised residual
    cost_train: float       # training cost of the linearised residual


@dataclass(frozen=True, kw_only=True)
class _Stage:
    """Where a stage of the selection starts: the chosen effects and their costs."""

    index: int              # 0-based; reported 1-based
    chosen: Chosen
    cost_train: float
    cost_test: float
    w: FloatArray           # weighted residual of the chosen effects, shape (rows, n)
    n_eff: float            # effective number of training samples (for the BIC)

    @property
    def costs(self) -> tuple[float, float]:
        """(training cost, held-out cost) of the chosen effects."""
        return self.cost_train, self.cost_test

    @property
    def chosen_names(self) -> list[str]:
        """Names of the chosen effects."""
        return [e.name for e, _ in self.chosen]


def select_effects(prob: Problem, thresholds: dict[str, float], max_effects: int = 3,
                   dbic_min: float = -6.0, confound_corr: float = 0.9,
                   only: list[str] | None = None, progress: Any = None,
                   weights: tuple[float, float] | None = None, screen_top: int = 3,
                   screen_frac: float = 0.5, degenerate_corr: float = 0.995) -> Selection:
    """Greedy forward selection of effects (module docstring).

    Parameters
    ----------
    prob : Problem
        The problem.
    thresholds : dict
        Held-out gain an effect must exceed (from the noise-only null), by name.
    max_effects : int
        Largest number of effects to add.
    dbic_min : float
        BIC decrease required.
    confound_corr : float
        Parameter correlation above which two competing effects are confounded.
    only : list of str, optional
        Restrict the candidates.
    progress : callable, optional
        ``progress(str)`` for messages.
    weights : (float, float), optional
        Noise scales of the rows [N m] (from the null); default: robust scales of the
        nominal residual.
    screen_top, screen_frac : int, float
        Candidates fitted fully: the ``screen_top`` best of the linearised screening and
        any whose linearised held-out gain reaches ``screen_frac`` of its threshold; the
        others are reported with their linearised fit (they cannot be significant).
    degenerate_corr : float
        A joint fit is degenerate (not identifiable, never added) when a parameter ends at
        a bound its nominal value is not at, or two parameters of different effects
        correlate beyond this.
    """
    crit = _Criteria(thresholds=thresholds, dbic_min=dbic_min, confound_corr=confound_corr,
                     screen_top=screen_top, screen_frac=screen_frac,
                     degenerate_corr=degenerate_corr)
    cands = [c for c in prob.candidates if only is None or c in only]
    chosen: Chosen = []
    if weights is None:
        prob.set_weights(chosen)
    else:
        prob.s = (float(weights[0]), float(weights[1]))
    c_tr, c_te, w = prob.cost(chosen)
    tau, n_eff = _effective_samples(prob, w)
    stages: list[dict[str, Any]] = []
    ranking: list[dict[str, Any]] = []
    confounded: list[dict[str, Any]] = []
    final = Fit(effects=[], values=[], cost_train=c_tr, cost_test=c_te, n_params=0)
    for index in range(max_effects):
        st = _Stage(index=index, chosen=chosen, cost_train=c_tr, cost_test=c_te, w=w,
                    n_eff=n_eff)
        rows, fits = _assess_candidates(prob, st, cands, crit, progress)
        stages.append({"stage": index + 1, "candidates": rows,
                       "cost_train": c_tr, "cost_test": c_te})
        if index == 0:
            ranking = rows
        _note_degenerate(confounded, st, rows)
        sig = [r for r in rows if r["significant"]]
        if not sig:
            break
        best = sig[0]
        _note_confounds(prob, confounded, st, rows, best, fits[best["effect"]],
                        crit.confound_corr)
        final = fits[best["effect"]]
        chosen = final.chosen()
        c_tr, c_te, w = prob.cost(chosen)
        final.cost_train, final.cost_test = c_tr, c_te
    params, sensor = apply_effects(prob.base, chosen)
    return Selection(chosen=[e.name for e, _ in chosen], final=final, stages=stages,
                     ranking=ranking, confounded=confounded, weights=prob.s, tau=tau,
                     params=params, sensor=sensor,
                     parameters=parameter_table(final, tau, prob.has_ball))


def _effective_samples(prob: Problem, w: FloatArray) -> tuple[float, float]:
    """Autocorrelation time and effective number of training samples of ``w``.

    ``tau`` [samples]: of the weighted residual ``w`` on the training blocks, the larger of
    the rows; the effective number is the training samples of all rows over ``tau``.
    """
    tau = autocorr_time(w[0, prob.train])
    if prob.has_ball:
        tau = max(tau, autocorr_time(w[1, prob.train]))
    n_train = w.shape[0] * int(prob.train.sum())
    return tau, n_train / tau


def _screen(prob: Problem, st: _Stage, names: list[str]) -> dict[str, _Screened]:
    """One Gauss-Newton step per candidate on top of the chosen effects (the screening).

    At the first stage the nominal Jacobians are shared with the null.
    """
    wv = st.w.ravel()
    cur_test = st.cost_test
    out = {}
    for name in names:
        vals, l_tr, l_te = prob.linear_fit(st.chosen, EFFECTS[name], wv)
        out[name] = _Screened(values=vals, gain=1.0 - l_te / cur_test if cur_test > 0 else 0.0,
                              cost_train=l_tr)
    return out


def _assess_candidates(prob: Problem, st: _Stage, cands: list[str], crit: _Criteria,
                       progress: Any) -> tuple[list[dict[str, Any]], dict[str, Fit]]:
    """Screen every candidate of a stage, fit the promising ones fully, rate them all.

    Returns
    -------
    rows : list of dict
        One row per candidate (:func:`_assess`), best held-out gain first.
    fits : dict
        The full joint fits, by the name of the candidate added.
    """
    chosen_names = st.chosen_names
    names = [n for n in cands if n not in chosen_names or n == "track_bumps"]
    screened = _screen(prob, st, names)
    top = sorted(names, key=lambda n: -screened[n].gain)[:crit.screen_top]
    rows = []
    fits: dict[str, Fit] = {}
    for name in names:
        full = name in top or screened[name].gain >= crit.screen_frac * crit.threshold(name)
        row, fit = _assess(prob, st, name, screened[name], full, crit)
        if fit is not None:
            fits[name] = fit
        rows.append(row)
        if progress:
            progress(_describe(st.index, row))
    rows.sort(key=lambda r: -r["heldout_gain"])
    return rows, fits


def _assess(prob: Problem, st: _Stage, name: str, screened: _Screened, full: bool,
            crit: _Criteria) -> tuple[dict[str, Any], Fit | None]:
    """Rate one candidate added to the chosen effects.

    Parameters
    ----------
    prob : Problem
        The problem.
    st : _Stage
        The stage (chosen effects, their costs, the effective sample size).
    name : str
        The candidate.
    screened : _Screened
        Its linearised fit.
    full : bool
        Fit it fully, jointly with the chosen effects (all refitted, started from the
        screening step: an effect may only show its worth once the others move with it);
        otherwise it is rated by its linearised fit.
    crit : _Criteria
        Thresholds and limits.

    Returns
    -------
    row : dict
        Held-out gain, dBIC, threshold, significance, degeneracy, size, fitted values.
    fit : Fit or None
        The full joint fit (None when only linearised).
    """
    eff = EFFECTS[name]
    thr = crit.threshold(name)
    degenerate = None
    fit = None
    if full:
        start = np.clip(screened.values,
                        np.asarray(eff.lower) + 0.5 * np.asarray(eff.scales),
                        np.asarray(eff.upper) - 0.5 * np.asarray(eff.scales))
        fit = prob.fit(st.chosen, eff, start, max_nfev=40)
        gain, dbic = _stats(prob, st.costs, fit, st.n_eff, eff.k)
        vals = display_values(eff, fit.values[-1])
        degenerate = _degenerate(prob, fit, crit.degenerate_corr)
        size = effect_size(name, fit.values[-1], prob.base)
    else:
        gain = screened.gain
        dbic = (st.n_eff * math.log(max(screened.cost_train, 1e-300) / st.cost_train)
                + eff.k * math.log(max(st.n_eff, 2.0)))
        vals = display_values(eff, screened.values)
        size = effect_size(name, screened.values, prob.base)
    big = size >= MIN_SIZE.get(name, 0.0)
    row = {"effect": name, "heldout_gain": gain, "dbic": dbic,
           "threshold": thr,
           "significant": bool(full and gain > thr and dbic < crit.dbic_min
                               and degenerate is None and big),
           "degenerate": degenerate,
           "size": size, "below_min_size": not big,
           "fit": "full" if full else "linearised (screened out)",
           "values": dict(zip(eff.names, map(float, vals), strict=True)),
           "units": dict(zip(eff.names, eff.units, strict=True))}
    return row, fit


def _describe(index: int, row: dict[str, Any]) -> str:
    """The progress line of one candidate's row (:func:`_assess`) at stage ``index``."""
    name = row["effect"]
    return (f"stage {index + 1}: {name:24s} held-out gain {row['heldout_gain']:+.4f} "
            f"(null {row['threshold']:.4f}) dBIC {row['dbic']:+.1f}"
            + ("" if row["fit"] == "full" else " [linearised]")
            + (f" [degenerate: {row['degenerate']}]" if row["degenerate"] else "")
            + ("" if not row["below_min_size"]
               else f" [size {row['size']:.2g} below {MIN_SIZE[name]:g}]"))


def _note_degenerate(confounded: list[dict[str, Any]], st: _Stage,
                     rows: list[dict[str, Any]]) -> None:
    """Report the candidates that beat their threshold but whose joint fit is degenerate."""
    names_chosen = st.chosen_names
    for r in rows:
        if r["degenerate"] and r["heldout_gain"] > r["threshold"]:
            _add_confound(confounded, st.index + 1, [*names_chosen, r["effect"]],
                          "degenerate", float("nan"),
                          (f"{r['effect']} cannot be fitted together with "
                           f"{', '.join(names_chosen)}: {r['degenerate']} (the data "
                           "fix only a combination of them); not added") if names_chosen
                          else (f"{r['effect']} alone is degenerate: {r['degenerate']} "
                                "(it can only reduce the residual by running to a bound);"
                                " not added at this stage"))


def _note_confounds(prob: Problem, confounded: list[dict[str, Any]], st: _Stage,
                    rows: list[dict[str, Any]], best: dict[str, Any], best_fit: Fit,
                    confound_corr: float) -> None:
    """Report the runners-up that explain the same residual as the stage's best.

    A runner-up within 80 % of the best's held-out gain is fitted jointly with it; the pair
    is confounded when their parameters correlate beyond ``confound_corr`` or the
    runner-up adds less than a tenth of the best's gain.
    """
    for other in rows:
        if (other is best or other["effect"] == best["effect"] or other["degenerate"]
                or other["heldout_gain"] < 0.8 * best["heldout_gain"]
                or other["heldout_gain"] <= 0):
            continue
        e_b = EFFECTS[other["effect"]]
        pair_fit = prob.fit(best_fit.chosen(), e_b, None, max_nfev=40)
        rho = _corr_between(pair_fit, best["effect"], other["effect"])
        extra_gain = 1.0 - pair_fit.cost_test / best_fit.cost_test
        if rho > confound_corr or extra_gain < 0.1 * best["heldout_gain"]:
            _add_confound(confounded, st.index + 1, [best["effect"], other["effect"]], "pair",
                          rho, f"{best['effect']} and {other['effect']} explain the same "
                          f"residual (held-out gains {best['heldout_gain']:.3f} vs "
                          f"{other['heldout_gain']:.3f}, parameter correlation "
                          f"{rho:.2f}): the data cannot tell them apart; "
                          f"{best['effect']} is kept as the larger")


def parameter_table(fit: Fit, tau: float, has_ball: bool) -> list[dict[str, Any]]:
    """Fitted values with 95 % intervals (covariance inflated by the autocorrelation)."""
    out = []
    if not fit.effects:
        return out
    cov = fit.cov if fit.cov is not None else None
    i = 0
    for name, vals in zip(fit.effects, fit.values, strict=True):
        eff = EFFECTS[name]
        disp = display_values(eff, vals)
        for j, pname in enumerate(eff.names):
            var = float(cov[i + j, i + j]) * tau if cov is not None else float("nan")
            sd = math.sqrt(var) if var >= 0 else float("nan")
            if name == "axis_misalignment":
                eps = disp[0]
                sd = sd / max(math.sin(eps), 1e-6) if eps > 0 else math.sqrt(2 * max(sd, 0))
            out.append({"effect": name, "name": pname, "unit": eff.units[j],
                        "value": float(disp[j]), "ci95": [float(disp[j] - 1.96 * sd),
                                                          float(disp[j] + 1.96 * sd)],
                        "std": sd})
        i += eff.k
    return out
