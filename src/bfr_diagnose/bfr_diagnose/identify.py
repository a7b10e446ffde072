"""Fit, rank and select effects on one or several recordings of one rig; intervals.

Problem. One rig, any number of recordings (:class:`Part`: one recording, or the runs of one
log of one kind): the physics (the library's effects, :mod:`~bfr_diagnose.effects`) is
shared, each part keeps its own sensor model (camera latency, offset, rotation and scale,
the encoder's zero, the torque's timing: :data:`~bfr_diagnose.effects.SENSOR_PARAMS`),
fitted on every candidate together with the physics and never selected.

Cost. The weighted equation error of every part: its rows (frame torque, ball, ball's
distance; :mod:`~bfr_diagnose.residual`) each divided by its scale, the larger of its RMS
noise from the noise-only null (:mod:`~bfr_diagnose.null`) and its residual's robust scale,
and each sample weighted by Huber's weight at the stage's residual (:meth:`Problem.reweight`:
iteratively reweighted least squares, the weights frozen within a stage). The ball row is
divided by the candidate's ball mass over the nominal one: that row is homogeneous in the
ball's mass and inertia, so a lighter ball would otherwise shrink any misfit of it (a
trivial solution). The frame row likewise by the candidate's torque gain over the nominal
one: it is homogeneous in every torque and inertia it holds (``J_f``, ``k_u``, the ball's
mass, the friction, offset and imbalance), so a smaller gain with all of them scaled with it
shrank the row's misfit (limits case 449: a frame inertia +14 % taken for a torque gain
0.88 and a ball mass 0.87 x, whose frame row was 0.88 of the truth's). Alternating time blocks of
``block`` seconds of each part are training and held-out data (whole frame turns and whole
laps of the ball on the frame: :func:`bfr_diagnose.api.held_out_block`). Fits are bounded nonlinear
least squares on the training blocks (``scipy.optimize.least_squares``, trust-region
reflective) with a Jacobian that evaluates only the parts a column touches.

Statistics. ``gain = 1 - C_test(fit) / C_test(current)``, the held-out cost reduction; and
the BIC's change with every segment (one row of one part: frame torque, ball, ball's
distance) its own noise variance, the Gaussian likelihood profiled over each but never below
the null's noise: ``dBIC = sum_s N_eff,s (f(x_s(fit)) - f(x_s(current))) + k ln(N_eff)``,
``x_s`` the segment's training mean square in units of the null's noise, ``f(x) = ln x + 1``
for ``x >= 1`` and ``x`` below (:func:`_dbic`), ``N_eff = N / tau`` (``tau`` the integrated
autocorrelation time of the noise) and ``N_eff,s`` segment ``s``'s share of it. A pooled
``N_eff ln(C_train / C_train,current)`` scores a row by its share of the total cost: in
limits case 215 (contact-model truth, a 1.27 mN m dry friction) the friction, fitted to
0.05 %, removed 99.9 % of the frame row's cost, but the ball row held most of the cost
(model error of the compliant contact) and the pooled BIC fell by 0.5 only; per row it falls
by 196. The floor: a profiled variance let a row already below the null's noise claim more
precision than the noise has, and on the independent rig's clean logs (tests/independent) a
0.07-0.12 mm plate distance that took a third of such a ball row was selected in 2 of 12.
Where every row is below a null noise that overestimates the noise (the group test's
frame-only runs: a torque offset seen by two of eight) one variance for all rows is the
better noise model; the BIC is the stronger of the two, the pooled and the per-row one. An
effect
is significant when its held-out gain exceeds the null's largest gain for that effect
(x1.25 + 0.02), ``dBIC < -6``, its joint fit is not degenerate, and it is larger than its
engineering resolution (:data:`~bfr_diagnose.effects.MIN_SIZE`).

Group test (several recordings). The pooled gain is a share of every recording's cost, so
an effect that only some recordings can see (the friction's direction in the runs that turn
both ways) is diluted by the others. The same joint fit is therefore also scored per
recording: ``g_i = 1 - C_test,i(fit) / C_test,i(current)`` against that recording's own
null threshold ``t_i`` (the null's fits scored on the recording alone, x1.25 + 0.02,
:func:`~bfr_diagnose.null.null_part_gains`). The effect is significant in a group when the
recordings ``S = {i: g_i > t_i}`` are not empty, the group's held-out gain (its costs
pooled) exceeds the largest ``t_i`` of the group, the other recordings it enters are not
made worse beyond the pooled threshold (their pooled gain ``> -t``) and all of them together
not at all (the pooled gain ``> 0``: an effect that only stands in for another one in a few
recordings, a torque offset for the dry friction in runs that turn one way, is not taken),
the BIC on the group's
training cost falls (``dBIC_S``: the sum above over the group's segments alone, with
``k ln N_eff,S``, ``N_eff,S`` the group's share of the effective samples, ``< -6``), and the
fit is neither degenerate nor below its resolution. Each recording's test has the
false-positive level of the pooled one (the same margin over its own null), and the BIC on
the group guards against many small chance excesses. Candidates are fitted fully for it
when one recording's linearised gain reaches half its threshold (:func:`_screen_parts`).

Selection, greedy forward. Stage 0 fits the sensor model alone. At each stage every
candidate gets one Gauss-Newton step on top of the chosen effects with the sensor model
refitted with it (the linearised screening: the least-squares fit of the candidate's and
the sensors' Jacobian columns together); the two best (``screen_top``) and any within half
of its threshold are then fitted fully, jointly with the chosen effects and the sensors. Of
the significant ones (a plausible one before a suspect) the one with the strongest evidence,
the lowest dBIC (its group's for an effect the group test made significant), is added; it
stops when nothing is significant or after ``max_effects``. Not the largest held-out gain:
while two effects are missing, a flexible one (fourteen contour harmonics) takes a share of
the other's residual too and out-gains the true one, which the BIC's ``k ln N_eff`` charges
for (blind case 6: a bump's dBIC -68 against the harmonics' -63, their gains 0.60 against
0.75; taken by gain, the bump was then fitted 0.3 rad away).
Every stage's figures are kept, so the ranking shows at which stage each effect was selected
and what decided it.

Parsimony (:func:`_simplify`). Greedy stages can take a stand-in and later a second effect
that completes it: the frame row is unchanged by ``(J_f, k_u, m_b) -> (J_f, k_u, m_b) / s``
(the ball's row is homogeneous in its mass), so a frame inertia is a torque gain plus a ball
mass. After the last stage, each reported confounded partner ``c`` of a chosen ``a`` is tried
in place of ``a`` and one other chosen ``b``; the smaller set is taken when its BIC is lower,
the larger one's held-out cost is not lower by ``b``'s threshold, and ``c`` is plausible,
above its floor and not degenerate. Reported (kind ``replaced``).

Degenerate fits. A joint fit in which a parameter runs to a bound that its nominal value is
not at, or in which two parameters of different effects correlate beyond 0.995 while one of
them lies within five of its marginal standard deviations of its nominal value, is not
identifiable from these recordings: never added, reported. (Correlation alone is not the
test: a Coulomb friction and a torque offset correlate 0.999 when most of the data turn one
way, yet one run in the other direction fixes each of them to 1 %.) Confounded pairs: a runner-up
that explains nearly as much as the winner and correlates beyond 0.9 with it (or adds
nothing), and any physics parameter correlating beyond 0.9 with a sensor parameter (e.g.
the contour's radius with the camera's scale), are reported instead of guessed.

Calibration prior. The camera's offset, rotation and scale carry a Gaussian prior about
the nominal (widths ``sigma_j``, :data:`~bfr_diagnose.effects.CAMERA_PRIOR`, times
``prior_scale``): a MAP estimate, one extra residual row per parameter and part,
``r_j = sqrt(tau) (x_j - x_j0) / sigma_j``, appended to the training rows the optimiser sees
(never to the held-out cost). The data rows are weighted to unit variance and correlated over
``tau`` samples (:func:`effective_samples`), so they carry ``sum w^2 / tau`` of
log-likelihood; the ``sqrt(tau)`` puts the prior on the same footing, and a parameter the
data do not fix gets back its prior width in the intervals below.

Intervals. ``cov = s^2 (J^T J)^-1 tau`` at the optimum, 95 % intervals ``+- 1.96 sqrt(diag)``.
With several recordings, :func:`between_recordings` fits every selected effect on each
recording alone and widens the joint interval by the spread between them.
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
    MIN_SIZE,
    Effect,
    apply_effects,
    display_values,
    effect_size,
    plausibility,
    sensor_correction,
    sensor_param,
)
from bfr_diagnose.preprocess import SensorCorrection
from bfr_diagnose.residual import ResidualEvaluator

__all__ = ["DISAGREE_Z", "Fit", "LinearScreen", "Part", "Problem", "Selection", "at_bounds",
           "autocorr_time",
           "between_recordings", "effective_samples", "linear_gain", "select_effects"]

FloatArray = NDArray[np.float64]
Chosen = list[tuple[Effect, FloatArray]]
#: Huber's constant [-] (in units of a row's scale): 95 % efficiency under Gaussian noise.
HUBER_K = 1.345
_BAD = (ParameterError, ValueError, ZeroDivisionError, FloatingPointError)


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


@dataclass(kw_only=True, eq=False)
class Part:
    """One recording (or the runs of one log of one kind) in an identification problem.

    Attributes
    ----------
    name : str
        Label (the file, and the kind when a log holds several kinds).
    ev : ResidualEvaluator
        Its equation-error evaluator.
    rows : tuple of int
        Equation rows it contributes (1: frame, 2: ball, 3: ball's distance).
    sensor_names : tuple of str
        Its sensor model's parameters (:func:`~bfr_diagnose.effects.sensor_names_for`).
    sigma : ndarray
        The weights' scale of rows 1-3 [N m, N m, m]: the larger of the row's noise (the
        null's) and its current residual level (:meth:`Problem.reweight`); 1 for unused rows.
    sigma_null : ndarray
        RMS noise of rows 1-3 (the null's).
    huber : ndarray or None
        Shape ``(3, n)``: each sample's Huber weight's square root, ``sqrt(min(1, k / z))``
        with ``z = |r| / sigma`` at the stage's residual (:meth:`Problem.reweight`); None:
        all 1 (before the first reweighting).
    train, test : ndarray of bool
        Training and held-out residual samples (alternating blocks).
    kind : str
        ``rolling``, ``frame held`` or ``frame only``.
    """

    name: str
    ev: ResidualEvaluator
    rows: tuple[int, ...]
    sensor_names: tuple[str, ...]
    sigma: FloatArray
    train: NDArray[np.bool_]
    test: NDArray[np.bool_]
    kind: str
    sigma_null: FloatArray | None = None
    huber: FloatArray | None = None

    @classmethod
    def of(cls, name: str, ev: ResidualEvaluator, block: float,
           sensor_names: tuple[str, ...]) -> Part:
        """A part with alternating train/test blocks of ``block`` seconds, unit weights."""
        prep = ev.prep
        t = prep.t[ev.idx]
        blk = np.floor((t - t[0]) / block).astype(int)
        train = blk % 2 == 0
        if not prep.has_ball:
            rows, kind = (1,), "frame only"
        elif prep.frame_held:
            rows, kind = (2, 3), "frame held"
        else:
            rows, kind = (1, 2, 3), "rolling"
        return cls(name=name, ev=ev, rows=rows, sensor_names=sensor_names,
                   sigma=np.ones(3), train=train, test=~train, kind=kind)

    @property
    def n(self) -> int:
        """Residual samples per row."""
        return int(self.ev.idx.size)

    def affected_by(self, eff: Effect) -> bool:
        """Whether the effect enters one of this part's rows."""
        return any(r in self.rows for r in eff.rows)

    def scaled(self, params: RigParams, sensor: SensorCorrection, m_ref: float,
               k_ref: float) -> FloatArray:
        """The part's rows in their units, shape ``(len(rows), n)``.

        The frame row times ``k_ref / k_u``, the ball row times ``m_ref / m_b`` (module
        docstring: cost).
        """
        res = self.ev.evaluate(params, sensor)
        out = []
        for r in self.rows:
            row = res.rows[r - 1]
            if r == 1:
                row = row * (k_ref / params.actuator.torque_gain)
            elif r == 2:
                row = row * (m_ref / params.ball.mass)
            out.append(row)
        return np.vstack(out)

    def row_weight(self, r: int) -> FloatArray | float:
        """Row ``r``'s weight of each sample: the Huber weight's square root over sigma."""
        h = 1.0 if self.huber is None else self.huber[r - 1]
        return h / self.sigma[r - 1]

    def weighted(self, params: RigParams, sensor: SensorCorrection, m_ref: float,
                 k_ref: float) -> FloatArray:
        """The part's weighted rows, shape ``(len(rows), n)`` (module docstring: cost)."""
        x = self.scaled(params, sensor, m_ref, k_ref)
        return np.vstack([x[j] * self.row_weight(r) for j, r in enumerate(self.rows)])


@dataclass
class Fit:
    """One fitted candidate: the chosen effects (plus possibly one new one) and the sensors.

    Attributes
    ----------
    effects, values : list
        Effect names and their fitted values (natural units, internal form).
    sensors : list of ndarray
        Each part's sensor parameters (natural units, in the part's ``sensor_names`` order).
    cost_train, cost_test : float
        Weighted costs.
    cov : ndarray or None
        Covariance of all fitted parameters, effects first then sensors (natural units).
    n_params : int
        Effect parameters fitted (without the sensors).
    ok : bool
        The fit evaluated everywhere.
    part_costs : list of (float, float) or None
        Each part's (training, held-out) cost (a fit on all parts).
    segment_costs : ndarray or None
        Training cost of each (part, row) segment (a fit on all parts; the BIC's).
    """

    effects: list[str]
    values: list[FloatArray]
    sensors: list[FloatArray]
    cost_train: float
    cost_test: float
    cov: FloatArray | None = None
    n_params: int = 0
    ok: bool = True
    part_costs: list[tuple[float, float]] | None = None
    segment_costs: FloatArray | None = None

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
    tau: float
    params: RigParams
    sensors: list[SensorCorrection]
    parameters: list[dict[str, Any]] = field(default_factory=list)
    sensor_table: list[dict[str, Any]] = field(default_factory=list)

    @property
    def sensor(self) -> SensorCorrection:
        """The first part's sensor correction (single-recording callers)."""
        return self.sensors[0]


class Problem:
    """The identification problem of one rig's recordings (module docstring).

    Parameters
    ----------
    parts : list of Part
        The recordings.
    base : RigParams
        Nominal parameters.
    prior_scale : float
        Every calibration prior's width times this (0: no prior; module docstring).
    """

    def __init__(self, parts: list[Part], base: RigParams, prior_scale: float = 1.0
                 ) -> None:
        if not (math.isfinite(prior_scale) and prior_scale >= 0.0):
            raise ValueError(f"prior_scale must be a number >= 0, got {prior_scale!r}")
        self.parts = parts
        self.base = base
        self.prior_scale = prior_scale
        self.prior_tau = 1.0     # [samples] the residual's correlation (module docstring)
        self.m_ref = base.ball.mass
        self.k_ref = base.actuator.torque_gain
        self.n_eval = 0
        self._jac_cache: dict[tuple, Any] = {}
        # effect values -> (params, sensor correction) of apply_effects (:meth:`_model`)
        self._physics: dict[tuple, tuple[RigParams, SensorCorrection]] = {}
        self._set_masks()

    def _set_masks(self) -> None:
        tr, te = [], []
        for p in self.parts:
            tr.append(np.tile(p.train, len(p.rows)))
            te.append(np.tile(p.test, len(p.rows)))
        self.train = np.concatenate(tr)
        self.test = np.concatenate(te)
        sizes = [p.n * len(p.rows) for p in self.parts]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        # each entry's segment: one per (part, row), the BIC's variance groups
        seg, k = [], 0
        for p in self.parts:
            seg.append(np.repeat(np.arange(k, k + len(p.rows)), p.n))
            k += len(p.rows)
        self.segment = np.concatenate(seg).astype(int)
        self.n_segments = k

    # -- shapes and parameters -----------------------------------------------------------
    @property
    def has_ball(self) -> bool:
        """Whether some part has the ball rows."""
        return any(2 in p.rows for p in self.parts)

    @property
    def candidates(self) -> list[str]:
        """Effects that enter some part's rows."""
        return [n for n, e in EFFECTS.items() if any(p.affected_by(e) for p in self.parts)]

    def sensor_start(self) -> list[FloatArray]:
        """Each part's sensor parameters at their defaults (no correction)."""
        default = SensorCorrection()
        return [np.array([float(getattr(default, n)) for n in p.sensor_names])
                for p in self.parts]

    def set_weights(self, sigmas: list[FloatArray]) -> None:
        """Set each part's row noise (the null's); the weights start at it."""
        for p, s in zip(self.parts, sigmas, strict=True):
            p.sigma_null = np.asarray(s, float)
            p.sigma = p.sigma_null.copy()
            p.huber = None
        self._jac_cache.clear()

    def reweight(self, chosen: Chosen, sensors: list[FloatArray]) -> None:
        """Weights from the current residual of each row (iteratively reweighted LS).

        A row's scale ``sigma`` becomes the larger of its noise and the robust scale of its
        current residual on the training blocks (``1.4826 median |r|``): a row the model
        misses by 100 times its noise (model error, not noise) does not outweigh the others
        by a factor 10^4, which on real recordings let one row's model error drive every fit
        (the camera's ball distance, which a detector's bias misses by millimetres, pulled
        the sensor model and the contour to their bounds). On data the model fits, the
        weights stay the noise's.

        Each sample then gets Huber's weight ``min(1, k / z)``, ``z = |r| / sigma``,
        ``k = 1.345`` (95 % efficiency under Gaussian noise): the cost is Huber's loss
        (quadratic to ``k sigma``, linear beyond) with the weights frozen at the stage's
        residual, so a robust scale is paired with a bounded-influence loss (an
        M-estimator). A robust scale under the plain square let a heavy-tailed row's tails
        outweigh the others: in limits case 215 (contact-model truth, a 1.27 mN m dry
        friction) the ball row held 37 times the frame row's cost, and the friction,
        fitted to 0.3 %, removed 99.9 % of the frame row but gained 1.5 % of the total and
        was missed; with Huber's weights it gains 16 %. Jacobians cached under earlier
        weights are dropped.
        """
        for i, p in enumerate(self.parts):
            if p.sigma_null is None:
                continue
            x_all = self.part_scaled(i, chosen, sensors[i])
            huber = np.ones((3, p.n)) if p.huber is None else p.huber.copy()
            for j, r in enumerate(p.rows):
                x = x_all[j][p.train]
                x = x[np.isfinite(x)]
                if x.size < 10:
                    continue
                # about zero, not about the median (timing.robust_sd): a row's constant
                # misfit is misfit, and belongs in its scale
                level = 1.4826 * float(np.median(np.abs(x)))
                p.sigma[r - 1] = max(float(p.sigma_null[r - 1]), level)
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = HUBER_K * p.sigma[r - 1] / np.abs(x_all[j])
                huber[r - 1] = np.sqrt(np.fmin(1.0, ratio))  # fmin: NaN and 0 -> 1
            p.huber = huber
        self._jac_cache.clear()

    def prior_width(self, name: str) -> float | None:
        """The calibration prior's width of a sensor parameter (None: no prior)."""
        w = sensor_param(name).prior
        return None if w is None or self.prior_scale == 0.0 else w * self.prior_scale

    # -- evaluation ----------------------------------------------------------------------
    def _model(self, i: int, chosen: Chosen, sensor: FloatArray
               ) -> tuple[RigParams, SensorCorrection]:
        """Part ``i``'s parameters and sensor correction under ``chosen`` and ``sensor``.

        The physics of the last few effect sets is kept: a Jacobian's sensor columns, and
        every part of one evaluation, share the effects' values (building and validating a
        parameter set costs about 1 ms, a fifth of an evaluation).
        """
        key = tuple((e.name, np.asarray(v, float).tobytes()) for e, v in chosen)
        hit = self._physics.get(key)
        if hit is None:
            hit = apply_effects(self.base, chosen)
            if len(self._physics) >= 16:
                self._physics.pop(next(iter(self._physics)))
            self._physics[key] = hit
        params, extra = hit
        self.n_eval += 1
        return params, sensor_correction(self.parts[i].sensor_names, sensor) + extra

    def part_weighted(self, i: int, chosen: Chosen, sensor: FloatArray) -> FloatArray:
        """Part ``i``'s weighted rows, raveled."""
        params, corr = self._model(i, chosen, sensor)
        return self.parts[i].weighted(params, corr, self.m_ref, self.k_ref).ravel()

    def part_scaled(self, i: int, chosen: Chosen, sensor: FloatArray) -> FloatArray:
        """Part ``i``'s rows in their units, shape ``(len(rows), n)`` (:meth:`Part.scaled`)."""
        params, corr = self._model(i, chosen, sensor)
        return self.parts[i].scaled(params, corr, self.m_ref, self.k_ref)

    def weighted(self, chosen: Chosen, sensors: list[FloatArray]) -> FloatArray:
        """All parts' weighted rows, concatenated (the cost's residual vector)."""
        return np.concatenate([self.part_weighted(i, chosen, s)
                               for i, s in enumerate(sensors)])

    def cost(self, chosen: Chosen, sensors: list[FloatArray]) -> tuple[float, float, FloatArray]:
        """(train cost, test cost, weighted residual vector)."""
        w = self.weighted(chosen, sensors)
        return (float(np.nansum(w[self.train] ** 2)), float(np.nansum(w[self.test] ** 2)), w)

    def part_costs(self, w: FloatArray) -> list[tuple[float, float]]:
        """Each part's (training, held-out) cost of a residual vector."""
        out = []
        for i in range(len(self.parts)):
            sl = self.part_slice(i)
            x = w[sl]
            out.append((float(np.nansum(x[self.train[sl]] ** 2)),
                        float(np.nansum(x[self.test[sl]] ** 2))))
        return out

    def segment_costs(self, w: FloatArray, mask: NDArray[np.bool_] | None = None
                      ) -> FloatArray:
        """Cost of each (part, row) segment of a residual vector on ``mask`` (training).

        ``w`` is either the whole residual vector or its entries on ``mask`` alone.
        """
        mask = self.train if mask is None else mask
        x = w[mask] if w.size == mask.size else w
        x = np.where(np.isfinite(x), x, 0.0)
        return np.bincount(self.segment[mask], weights=x * x, minlength=self.n_segments)

    def segment_scale(self) -> FloatArray:
        """Each segment's ``(sigma / sigma_null)^2``: its cost in units of the null's noise."""
        out = []
        for p in self.parts:
            for r in p.rows:
                null = None if p.sigma_null is None else float(p.sigma_null[r - 1])
                out.append((float(p.sigma[r - 1]) / null) ** 2 if null else 1.0)
        return np.asarray(out)

    def segment_samples(self, w: FloatArray) -> FloatArray:
        """Training samples of each (part, row) segment where ``w`` is finite."""
        ok = self.train & np.isfinite(w)
        return np.bincount(self.segment[ok], minlength=self.n_segments).astype(float)

    def part_slice(self, i: int) -> slice:
        """Where part ``i`` sits in the residual vector."""
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def rows_of(self, w: FloatArray) -> list[dict[int, FloatArray]]:
        """Split a residual vector into each part's rows ``{row: samples}``."""
        out = []
        for i, p in enumerate(self.parts):
            seg = w[self.part_slice(i)].reshape(len(p.rows), p.n)
            out.append({r: seg[j] for j, r in enumerate(p.rows)})
        return out

    # -- Jacobians -----------------------------------------------------------------------
    def sensor_jacobian(self, chosen: Chosen, sensors: list[FloatArray], w0: FloatArray,
                        key: Any = None) -> FloatArray:
        """Columns of every part's sensor parameters (zero outside the part).

        Forward differences of one ``scale`` each (cached under ``key``).
        """
        if key is not None and ("sensors", key) in self._jac_cache:
            return self._jac_cache[("sensors", key)]
        cols = []
        for i, p in enumerate(self.parts):
            sl = self.part_slice(i)
            for j, name in enumerate(p.sensor_names):
                sp = sensor_param(name)
                h = sp.scale if sensors[i][j] + sp.scale <= sp.upper else -sp.scale
                x = np.array(sensors[i], float)
                x[j] += h
                col = np.zeros_like(w0)
                try:
                    col[sl] = (self.part_weighted(i, chosen, x) - w0[sl]) / h
                except _BAD:
                    pass
                cols.append(col)
        D = np.stack(cols, axis=1) if cols else np.zeros((w0.size, 0))
        D[~np.isfinite(D)] = 0.0
        if key is not None:
            self._jac_cache[("sensors", key)] = D
        return D

    def effect_jacobian(self, chosen: Chosen, sensors: list[FloatArray], eff: Effect,
                        x0: FloatArray, w0: FloatArray, key: Any = None) -> FloatArray:
        """Weighted residual Jacobian of ``eff`` at ``x0`` on top of ``chosen``.

        Forward differences of one ``scale`` per parameter (towards the inside of the
        bounds), evaluating only the parts the effect enters; cached under ``key``.
        """
        if key is not None and (eff.name, key) in self._jac_cache:
            return self._jac_cache[(eff.name, key)]
        cols = []
        for j in range(eff.k):
            h = float(eff.scales[j])
            if x0[j] + h > eff.upper[j]:
                h = -h
            x = np.array(x0, float)
            x[j] += h
            col = np.zeros_like(w0)
            for i, p in enumerate(self.parts):
                if not p.affected_by(eff):
                    continue
                sl = self.part_slice(i)
                try:
                    col[sl] = (self.part_weighted(i, [*chosen, (eff, x)], sensors[i])
                               - w0[sl]) / h
                except _BAD:
                    col[sl] = 0.0
            cols.append(col)
        D = np.stack(cols, axis=1)
        D[~np.isfinite(D)] = 0.0
        if key is not None:
            self._jac_cache[(eff.name, key)] = D
        return D

    def bump_columns(self, chosen: Chosen, sensors: list[FloatArray], w0: FloatArray,
                     n_grid: int = 48, width: float = 0.1, dh: float = 1e-4, key: Any = None
                     ) -> list[tuple[float, FloatArray]]:
        """Residual response to a unit bump height at each grid position (cached by key)."""
        if key is not None and ("bumps", key) in self._jac_cache:
            return self._jac_cache[("bumps", key)]
        eff = EFFECTS["track_bumps"]
        out = []
        for phi_c in np.linspace(0.0, 2.0 * np.pi, n_grid, endpoint=False):
            col = np.zeros_like(w0)
            try:
                for i, p in enumerate(self.parts):
                    if p.affected_by(eff):
                        sl = self.part_slice(i)
                        col[sl] = (self.part_weighted(
                            i, [*chosen, (eff, np.array([phi_c, dh, width]))], sensors[i])
                            - w0[sl]) / dh
            except _BAD:
                continue
            col[~np.isfinite(col)] = 0.0
            out.append((float(phi_c), col))
        if key is not None:
            self._jac_cache[("bumps", key)] = out
        return out

    # -- fitting -------------------------------------------------------------------------
    def fit(self, fixed: Chosen, new: Effect | None, start: FloatArray | None,
            sensors0: list[FloatArray], max_nfev: int = 40, only_part: int | None = None
            ) -> Fit:
        """Fit the fixed effects (refitted), ``new`` and every part's sensors jointly.

        Parameters
        ----------
        fixed : list
            Effects already chosen, with their current values (refitted).
        new : Effect or None
            The candidate added (None: refit ``fixed`` and the sensors).
        start : ndarray or None
            The candidate's starting values (default: its nominal).
        sensors0 : list of ndarray
            Each part's starting sensor values.
        max_nfev : int
            Largest number of cost evaluations of the optimiser.
        only_part : int, optional
            Fit on this part alone (the others' sensors are kept, their rows unused).
        """
        effs = [e for e, _ in fixed] + ([new] if new is not None else [])
        starts = [np.asarray(v, float) for _, v in fixed]
        if new is not None:
            starts.append(np.asarray(start if start is not None else new.start(self.base),
                                     float))
        parts = list(range(len(self.parts))) if only_part is None else [only_part]
        snames = [(i, n) for i in parts for n in self.parts[i].sensor_names]
        x0e = np.concatenate(starts) if starts else np.zeros(0)
        x0s = np.array([sensors0[i][self.parts[i].sensor_names.index(n)] for i, n in snames])
        lo = np.concatenate([np.asarray(e.lower, float) for e in effs]
                            + [np.array([sensor_param(n).lower for _, n in snames])])
        hi = np.concatenate([np.asarray(e.upper, float) for e in effs]
                            + [np.array([sensor_param(n).upper for _, n in snames])])
        scales = np.concatenate([np.asarray(e.scales, float) for e in effs]
                                + [np.array([sensor_param(n).scale for _, n in snames])])
        x0 = np.clip(np.concatenate([x0e, x0s]), lo + 0.5 * scales, hi - 0.5 * scales)
        ke = x0e.size
        cuts = np.cumsum([e.k for e in effs])[:-1] if effs else []
        ub = (hi - x0) / scales
        prior = _prior_rows([self.prior_width(n) for _, n in snames], [n for _, n in snames],
                            self.prior_tau, x0, scales, ke)
        fitter = _Fitter(self, effs, cuts, snames, sensors0, parts, x0, scales, ke, ub, prior)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OptimizeWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            sol = least_squares(fitter.fun, np.zeros(x0.size), jac=fitter.jac,
                                bounds=((lo - x0) / scales, ub), method="trf",
                                max_nfev=max_nfev, x_scale=1.0, ftol=1e-7, xtol=1e-7)
        chosen, sensors = fitter.unpack(sol.x)
        part_costs = seg_costs = None
        try:
            c_tr, c_te, w = self.cost(chosen, sensors) if only_part is None else \
                self._part_cost(only_part, chosen, sensors)
            ok = math.isfinite(c_tr) and math.isfinite(c_te)
            if only_part is None:
                part_costs = self.part_costs(w)
                seg_costs = self.segment_costs(w)
        except _BAD:
            c_tr = c_te = math.inf
            ok = False
        cov = None
        jac = sol.jac
        n = jac.shape[0]
        s2 = float(np.sum(sol.fun[:fitter.size] ** 2)) / max(n - prior.cols.size - x0.size, 1)
        try:
            cov = _covariance(jac, s2, scales)
        except (np.linalg.LinAlgError, ValueError):
            cov = None
        return Fit(effects=[e.name for e, _ in chosen], values=[v for _, v in chosen],
                   sensors=sensors, cost_train=c_tr, cost_test=c_te, cov=cov, n_params=ke,
                   ok=ok, part_costs=part_costs, segment_costs=seg_costs)

    def _part_cost(self, i: int, chosen: Chosen, sensors: list[FloatArray]
                   ) -> tuple[float, float, FloatArray]:
        w = self.part_weighted(i, chosen, sensors[i])
        sl = self.part_slice(i)
        return (float(np.nansum(w[self.train[sl]] ** 2)),
                float(np.nansum(w[self.test[sl]] ** 2)), w)


def _covariance(jac: FloatArray, s2: float, scales: FloatArray) -> FloatArray:
    """``s^2 (J^T J)^+`` in natural units; infinite variance where the data fix nothing.

    The pseudo-inverse gives a direction of ``J``'s null space zero variance, i.e. it would
    call a parameter the recording does not constrain (a camera offset and the frame's
    off-centre on a frame-held run, a timing at constant speed) exactly known. A parameter
    with a component in the null space (eigenvalues of ``J^T J`` below ``1e-15`` of the
    largest, numpy's ``pinv`` cut) gets an infinite variance and no covariance.
    """
    lam, vec = np.linalg.eigh(jac.T @ jac)
    null = lam <= 1e-15 * max(float(lam.max(initial=0.0)), 1e-300)
    kept = vec[:, ~null]
    cov = (kept / lam[~null]) @ kept.T * s2 * np.outer(scales, scales)  # the pseudo-inverse
    free = np.sum(vec[:, null] ** 2, axis=1) > 1e-6
    cov[free, :] = 0.0
    cov[:, free] = 0.0
    cov[free, free] = np.inf
    return cov


@dataclass(frozen=True, kw_only=True)
class _Prior:
    """The calibration prior's rows of one fit: ``r = a + B xn`` (module docstring).

    ``cols`` are the columns of the fit's normalised vector ``xn`` that carry a prior,
    ``a`` the rows at ``xn = 0`` and ``b`` each row's slope (``sqrt(tau) scale / sigma``).
    """

    cols: NDArray[np.int_]
    a: FloatArray
    b: FloatArray

    def rows(self, xn: FloatArray) -> FloatArray:
        """The prior's residual rows at ``xn``."""
        return self.a + self.b * xn[self.cols]


def _prior_rows(widths: list[float | None], names: list[str], tau: float, x0: FloatArray,
                scales: FloatArray, ke: int) -> _Prior:
    """The prior rows of a fit's sensor parameters ``names`` (columns ``ke`` on).

    Row ``r_j = sqrt(tau) (x_j - x_j0) / sigma_j`` with ``x_j = x0_j + xn_j scale_j``,
    ``x_j0`` the parameter's nominal (no correction, :class:`SensorCorrection`'s default)
    and ``sigma_j`` its width (``widths``; None: no prior row).
    """
    default = SensorCorrection()
    cols, a, b = [], [], []
    root = math.sqrt(max(tau, 1.0))
    for k, (name, width) in enumerate(zip(names, widths, strict=True)):
        if width is None:
            continue
        c = ke + k
        cols.append(c)
        a.append(root * (x0[c] - float(getattr(default, name))) / width)
        b.append(root * scales[c] / width)
    return _Prior(cols=np.array(cols, int), a=np.array(a, float), b=np.array(b, float))


class _Fitter:
    """The residual and its part-wise Jacobian of one joint fit (:meth:`Problem.fit`).

    The residual is the parts' training rows followed by the calibration prior's rows.
    """

    def __init__(self, prob: Problem, effs: list[Effect], cuts: Any,
                 snames: list[tuple[int, str]], sensors0: list[FloatArray], parts: list[int],
                 x0: FloatArray, scales: FloatArray, ke: int, ub: FloatArray,
                 prior: _Prior) -> None:
        self.prob, self.effs, self.cuts, self.snames = prob, effs, cuts, snames
        self.sensors0, self.parts, self.x0, self.scales, self.ke = (sensors0, parts, x0,
                                                                    scales, ke)
        self.ub = ub
        self.prior = prior
        self.mask = np.concatenate([prob.train[prob.part_slice(i)] for i in parts])
        self.size = int(self.mask.sum())
        self._last: tuple[FloatArray, list[FloatArray]] | None = None

    def unpack(self, xn: FloatArray) -> tuple[Chosen, list[FloatArray]]:
        x = self.x0 + xn * self.scales
        vals = np.split(x[:self.ke], self.cuts) if self.effs else []
        sensors = [np.array(s, float) for s in self.sensors0]
        for (i, name), v in zip(self.snames, x[self.ke:], strict=True):
            sensors[i][self.prob.parts[i].sensor_names.index(name)] = v
        return list(zip(self.effs, vals, strict=True)), sensors

    def _parts(self, chosen: Chosen, sensors: list[FloatArray],
               which: list[int]) -> list[FloatArray]:
        return [self.prob.part_weighted(i, chosen, sensors[i]) for i in which]

    def fun(self, xn: FloatArray) -> FloatArray:
        try:
            chosen, sensors = self.unpack(xn)
            ws = self._parts(chosen, sensors, self.parts)
        except _BAD:
            self._last = None
            return np.concatenate([np.full(self.size, 1e3), self.prior.rows(xn)])
        w = np.concatenate(ws)[self.mask]
        if not np.all(np.isfinite(w)):
            w = np.where(np.isfinite(w), w, 0.0)
        self._last = (np.array(xn), ws)
        return np.concatenate([w, self.prior.rows(xn)])

    def jac(self, xn: FloatArray) -> FloatArray:
        if self._last is None or not np.array_equal(self._last[0], xn):
            self.fun(xn)
        n_prior = self.prior.cols.size
        jp = np.zeros((n_prior, xn.size))
        jp[np.arange(n_prior), self.prior.cols] = self.prior.b
        if self._last is None:
            return np.vstack([np.zeros((self.size, xn.size)), jp])
        base = self._last[1]
        lens = [b.size for b in base]
        offs = np.concatenate([[0], np.cumsum(lens)]).astype(int)
        J = np.zeros((int(offs[-1]), xn.size))
        for col in range(xn.size):
            step = 1e-2 if xn[col] + 1e-2 <= self.ub[col] else -1e-2
            x = np.array(xn)
            x[col] += step
            ch, se = self.unpack(x)
            if col < self.ke:
                eff = self._effect_of(col)
                which = [k for k, i in enumerate(self.parts)
                         if self.prob.parts[i].affected_by(eff)]
            else:
                part = self.snames[col - self.ke][0]
                which = [self.parts.index(part)]
            for k in which:
                try:
                    w = self.prob.part_weighted(self.parts[k], ch, se[self.parts[k]])
                except _BAD:
                    continue
                J[offs[k]:offs[k + 1], col] = (w - base[k]) / step
        J[~np.isfinite(J)] = 0.0
        return np.vstack([J[self.mask], jp])

    def _effect_of(self, col: int) -> Effect:
        edges = np.concatenate([[0], np.cumsum([e.k for e in self.effs])])
        return self.effs[int(np.searchsorted(edges, col, side="right") - 1)]


# -- selection -------------------------------------------------------------------------------


def _dbic(c0: FloatArray, c1: FloatArray, n_seg: FloatArray, n_eff: float, k_new: int,
          use: NDArray[np.bool_] | None = None, scale: FloatArray | None = None) -> float:
    """The BIC's change with each (part, row) segment its own noise variance.

    ``dBIC = sum_s N_eff,s (f(x1_s) - f(x0_s)) + k ln(sum_s N_eff,s)`` over the segments
    ``use`` (all by default) with a cost; ``x_s = g_s C_s / n_s`` the mean square in units of
    the null's noise (``g_s = (sigma_s / sigma_null,s)^2``, ``scale``; 1 by default), ``n_s``
    the training samples, ``N_eff,s = N_eff n_s / sum(n)`` their share of the effective ones,
    and ``f(x) = ln x + 1`` for ``x >= 1``, ``x`` below: the Gaussian ``-2 ln L`` per sample
    with the segment's variance profiled but never below the null's noise. A row the model
    misses is judged against its own scale, a row already at the noise by the noise. The
    pooled ``N_eff,S ln(sum C1 / sum C0)`` (one variance for all the segments) is the other
    noise model; the change is the one with the stronger evidence (module docstring:
    statistics).
    """
    total = float(np.sum(n_seg))
    if total <= 0:
        return math.inf
    sel = (c0 > 0) & (n_seg > 0)
    if use is not None:
        sel &= use
    if not np.any(sel):
        return math.inf
    ne = n_eff * n_seg[sel] / total

    def f(x: FloatArray) -> FloatArray:
        return np.where(x >= 1.0, np.log(np.maximum(x, 1.0)) + 1.0, x)

    g = (np.ones_like(c0) if scale is None else scale)[sel] / n_seg[sel]
    x0, x1 = g * c0[sel], g * np.maximum(c1[sel], 0.0)
    penalty = k_new * math.log(max(float(ne.sum()), 2.0))
    per_row = float(np.sum(ne * (f(x1) - f(x0))))
    pooled = float(ne.sum()) * math.log(max(float(np.sum(c1[sel])), 1e-300)
                                        / float(np.sum(c0[sel])))
    return min(per_row, pooled) + penalty


def _stats(st: _Stage, fit: Fit, k_new: int) -> tuple[float, float]:
    """Held-out gain and BIC change of a full fit against the stage's baseline."""
    gain = 1.0 - fit.cost_test / st.cost_test if st.cost_test > 0 else 0.0
    if not fit.ok or fit.cost_train <= 0 or fit.segment_costs is None:
        return -math.inf, math.inf
    return float(gain), _dbic(st.seg_costs, fit.segment_costs, st.seg_n, st.n_eff, k_new,
                              scale=st.seg_scale)


@dataclass(frozen=True, kw_only=True)
class _Criteria:
    """What a candidate must reach, and how it is screened (see :func:`select_effects`)."""

    thresholds: dict[str, float]
    dbic_min: float
    confound_corr: float
    screen_top: int
    screen_frac: float
    degenerate_corr: float
    part_thresholds: dict[str, list[float | None]] = field(default_factory=dict)

    def threshold(self, name: str) -> float:
        """Held-out gain the effect ``name`` must exceed (0 when the null has none)."""
        return self.thresholds.get(name, 0.0)


@dataclass(frozen=True, kw_only=True)
class _Stage:
    """Where a stage of the selection starts: chosen effects, sensors and their costs."""

    index: int              # 0-based; reported 1-based
    chosen: Chosen
    sensors: list[FloatArray]
    cost_train: float
    cost_test: float
    w: FloatArray           # weighted residual vector
    n_eff: float            # effective number of training samples (for the BIC)
    seg_costs: FloatArray   # training cost of each (part, row) segment
    seg_n: FloatArray       # training samples of each segment
    seg_scale: FloatArray   # each segment's (sigma / sigma_null)^2 (its weights' unit)

    @property
    def chosen_names(self) -> list[str]:
        """Names of the chosen effects."""
        return [e.name for e, _ in self.chosen]


class LinearScreen:
    """Linearised fits of effect columns on top of refitted sensor columns.

    For a residual ``w`` and the sensor columns ``D_s`` (fixed for a stage), the
    least-squares fit of ``w + [D_s D_e] b`` on the training rows equals, by the
    Frisch-Waugh-Lovell theorem, the fit of the effect's columns with ``D_s`` projected out:
    ``E = (I - P_s) D_e``, ``w_perp = (I - P_s) w`` (``P_s`` the projection onto the training
    rows of ``D_s``, by a QR factorisation made once). The held-out cost is then evaluated
    with the full step (the sensors' part ``b_s = R^-1 Q^T (-w - D_e b_e)``).

    Parameters
    ----------
    D_s : ndarray
        Sensor columns, shape (n, s).
    train, test : ndarray of bool
        Training and held-out rows.
    """

    def __init__(self, D_s: FloatArray, train: NDArray[np.bool_],
                 test: NDArray[np.bool_]) -> None:
        self.D_s, self.train, self.test = D_s, train, test
        A = D_s[train]
        keep = np.linalg.norm(A, axis=0) > 0.0 if A.size else np.zeros(0, bool)
        self.cols = np.nonzero(keep)[0]
        if self.cols.size:
            self.Q, self.R = np.linalg.qr(A[:, self.cols])
            ok = np.abs(np.diag(self.R)) > 1e-12 * max(np.abs(np.diag(self.R)).max(), 1e-300)
            self.cols, self.Q, self.R = self.cols[ok], *np.linalg.qr(A[:, self.cols[ok]])
        else:
            self.Q = np.zeros((int(train.sum()), 0))
            self.R = np.zeros((0, 0))

    def _perp(self, X: FloatArray) -> FloatArray:
        return X - self.Q @ (self.Q.T @ X)

    def _sensor_step(self, rhs: FloatArray) -> FloatArray:
        b = np.zeros(self.D_s.shape[1])
        if self.cols.size:
            b[self.cols] = np.linalg.solve(self.R, self.Q.T @ rhs)
        return b

    def gain(self, w: FloatArray, D_e: FloatArray, clip0: NDArray[np.bool_] | None = None
             ) -> tuple[float, FloatArray, float]:
        """Held-out gain of the effect's columns ``D_e`` with the sensors refitted.

        ``1 - C_test(sensors and effect) / C_test(sensors only)``; ``clip0`` marks effect
        parameters bounded at their start (one-sided: a negative step is set to zero).

        Returns
        -------
        gain : float
        b_e : ndarray
            The effect's step.
        r_train : ndarray
            The training residual with the effect (the entries of ``w`` on ``train``).
        """
        w = np.where(np.isfinite(w), w, 0.0)
        tr, te = self.train, self.test
        wt = w[tr]
        b_s0 = self._sensor_step(-wt)
        c0 = float(np.sum((w[te] + self.D_s[te] @ b_s0) ** 2))
        E = self._perp(D_e[tr])
        wp = self._perp(wt)
        if np.any(E):
            b_e = np.linalg.lstsq(E, -wp, rcond=None)[0]
        else:
            b_e = np.zeros(D_e.shape[1])
        if clip0 is not None and D_e.shape[1] == 1 and clip0[0] and b_e[0] < 0.0:
            b_e = np.zeros(1)
        b_s = self._sensor_step(-wt - D_e[tr] @ b_e)
        c1 = float(np.sum((w[te] + self.D_s[te] @ b_s + D_e[te] @ b_e) ** 2))
        r_tr = wt + self.D_s[tr] @ b_s + D_e[tr] @ b_e
        return (1.0 - c1 / c0 if c0 > 0 else 0.0), b_e, r_tr

    def step(self, w: FloatArray, D_e: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The effect's step and the residual after it with the sensors refitted, everywhere.

        Returns
        -------
        b_e : ndarray
            The effect's step (unclipped).
        r : ndarray
            ``w + D_s b_s + D_e b_e`` on all rows (training and held-out).
        """
        w = np.where(np.isfinite(w), w, 0.0)
        tr = self.train
        E = self._perp(D_e[tr])
        b_e = (np.linalg.lstsq(E, -self._perp(w[tr]), rcond=None)[0] if np.any(E)
               else np.zeros(D_e.shape[1]))
        b_s = self._sensor_step(-w[tr] - D_e[tr] @ b_e)
        return b_e, w + self.D_s @ b_s + D_e @ b_e

    def best_column(self, w: FloatArray, cols: list[FloatArray]) -> int:
        """Index of the single column that lowers the training cost most.

        With the sensors refitted: the largest ``(E^T w_perp)^2 / |E|^2``.
        """
        w = np.where(np.isfinite(w), w, 0.0)
        wp = self._perp(w[self.train])
        C = self._perp(np.stack([c[self.train] for c in cols], axis=1))
        num = (C.T @ wp) ** 2
        den = np.sum(C * C, axis=0)
        score = np.where(den > 0, num / np.maximum(den, 1e-300), -1.0)
        return int(np.argmax(score))


def linear_gain(w: FloatArray, D_s: FloatArray, D_e: FloatArray, train: NDArray[np.bool_],
                test: NDArray[np.bool_], clip0: NDArray[np.bool_] | None = None
                ) -> tuple[float, FloatArray, float]:
    """Held-out gain of the linear fit ``w + [D_s D_e] b`` against ``w + D_s b_s``.

    A one-off :class:`LinearScreen`.
    """
    return LinearScreen(D_s, train, test).gain(w, D_e, clip0)


def select_effects(prob: Problem, thresholds: dict[str, float], sensors0: list[FloatArray],
                   tau_noise: float, max_effects: int = 3, dbic_min: float = -6.0,
                   confound_corr: float = 0.9,
                   only: list[str] | None = None, progress: Any = None, screen_top: int = 2,
                   screen_frac: float = 0.5, degenerate_corr: float = 0.995,
                   part_thresholds: dict[str, list[float | None]] | None = None
                   ) -> Selection:
    """Greedy forward selection of effects (module docstring).

    Parameters
    ----------
    prob : Problem
        The problem (weights set from the null).
    thresholds : dict
        Held-out gain an effect must exceed (from the noise-only null), by name.
    sensors0 : list of ndarray
        Each part's sensor model fitted with the nominal physics (stage 0).
    tau_noise : float
        Autocorrelation time of the noise's residual [samples] (the null's): the effective
        number of independent samples is the training samples over it. (The residual of a
        model that misses something is correlated by what it misses, which must not count
        against the evidence for it.)
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
    screen_top, screen_frac : int, float
        Candidates fitted fully: the ``screen_top`` best of the linearised screening and
        any whose linearised held-out gain reaches ``screen_frac`` of its threshold.
    degenerate_corr : float
        A joint fit is degenerate when a parameter ends at a bound its nominal value is not
        at, or two parameters of different effects correlate beyond this.
    part_thresholds : dict, optional
        Per effect, each recording's own null threshold (None where the effect does not
        enter): the group test (module docstring). None or empty: no group test.
    """
    crit = _Criteria(thresholds=thresholds, dbic_min=dbic_min, confound_corr=confound_corr,
                     screen_top=screen_top, screen_frac=screen_frac,
                     degenerate_corr=degenerate_corr, part_thresholds=part_thresholds or {})
    cands = [c for c in prob.candidates if only is None or c in only]
    chosen: Chosen = []
    sensors = [np.array(s, float) for s in sensors0]
    stages: list[dict[str, Any]] = []
    confounded: list[dict[str, Any]] = []
    for index in range(max_effects):
        if index:  # each stage's weights from its own residual (Problem.reweight), and the
            # chosen effects and sensors refitted under them: the stage's baseline
            chosen, sensors = _refit(prob, chosen, sensors)
        st, prob.prior_tau = _stage(prob, index, chosen, sensors, tau_noise)
        rows, fits = _assess_candidates(prob, st, cands, crit, progress)
        stages.append({"stage": index + 1, "candidates": rows,
                       "cost_train": st.cost_train, "cost_test": st.cost_test})
        _note_degenerate(confounded, st, rows)
        sig = [r for r in rows if r["significant"]]
        if not sig:
            break
        # a plausible explanation before a suspect (a fit outside its plausibility range
        # stands in for something else; a plausible one that is significant is preferred)
        plausible = [r for r in sig if r["plausible"]]
        best = min(plausible or sig, key=_evidence)
        best["selected"] = True
        _note_confounds(prob, confounded, st, rows, best, fits[best["effect"]],
                        crit.confound_corr)
        chosen, sensors = fits[best["effect"]].chosen(), fits[best["effect"]].sensors
    # the final model refitted with weights from its own residual: its intervals (and its
    # sensors') rest on the residual it leaves, not on the stage's weights
    chosen, sensors = _refit(prob, chosen, sensors)
    chosen, sensors = _simplify(prob, chosen, sensors, confounded, crit, tau_noise, progress)
    final = (prob.fit(chosen[:-1], chosen[-1][0], chosen[-1][1], sensors) if chosen
             else prob.fit([], None, None, sensors))
    chosen, sensors = final.chosen(), final.sensors
    _, _, w = prob.cost(chosen, sensors)
    tau, _ = effective_samples(prob, w, tau_noise)
    _note_sensor_confounds(prob, confounded, final, crit.confound_corr)
    params, _ = apply_effects(prob.base, chosen)
    return Selection(chosen=[e.name for e, _ in chosen], final=final, stages=stages,
                     ranking=_ranking(stages, cands), confounded=confounded, tau=tau,
                     params=params,
                     sensors=[sensor_correction(p.sensor_names, s)
                              for p, s in zip(prob.parts, final.sensors, strict=True)],
                     parameters=parameter_table(final, tau),
                     sensor_table=sensor_table(prob, final, tau))


def _stage(prob: Problem, index: int, chosen: Chosen, sensors: list[FloatArray],
           tau_noise: float) -> tuple[_Stage, float]:
    """The baseline of ``chosen`` under the current weights, and its residual's time.

    The time [samples] is :func:`effective_samples`'s (a stage's calibration prior uses it).
    """
    c_tr, c_te, w = prob.cost(chosen, sensors)
    tau, n_eff = effective_samples(prob, w, tau_noise)
    return _Stage(index=index, chosen=chosen, sensors=sensors, cost_train=c_tr, cost_test=c_te,
                  w=w, n_eff=n_eff, seg_costs=prob.segment_costs(w),
                  seg_n=prob.segment_samples(w), seg_scale=prob.segment_scale()), tau


def _simplify(prob: Problem, chosen: Chosen, sensors: list[FloatArray],
              confounded: list[dict[str, Any]], crit: _Criteria, tau_noise: float,
              progress: Any = None) -> tuple[Chosen, list[FloatArray]]:
    """Two chosen effects replaced by one, a reported partner of either, where that is better.

    Module docstring (selection, parsimony). The chosen set ``S`` against ``S' = S - {a, b} +
    {c}`` for every reported confounded pair ``(a, c)`` with ``a`` chosen and ``c`` not, and
    every other chosen ``b``: ``S'`` is taken when its BIC is lower (``dBIC(S -> S') < 0`` with
    ``k_c - k_a - k_b`` parameters), ``S``'s held-out cost is not lower than ``S'``'s by the
    threshold ``b`` had to beat, and ``c``'s fit is plausible and not degenerate. The
    reparametrisation it finds: the frame row ``J_f th'' + B(m_b) = k_u u + ...`` is the
    same with ``(J_f, k_u, m_b)`` and ``(J_f / s, k_u / s, m_b / s)`` (the ball's row is
    homogeneous in its mass), so a frame inertia is also a torque gain *and* a ball mass, one
    parameter more; greedy stages that took the gain first add the mass later. Once at most
    (the best replacement), and recorded in ``confounded`` (kind ``replaced``).
    """
    names = [e.name for e, _ in chosen]
    pairs = {(a, c) for entry in confounded if entry["kind"] == "pair"
             for a, c in (tuple(entry["pair"]), tuple(entry["pair"])[::-1])
             if a in names and c not in names and c in EFFECTS and c != "track_bumps"}
    if not pairs or len(chosen) < 2:
        return chosen, sensors
    st, _ = _stage(prob, len(chosen), chosen, sensors, tau_noise)
    best: tuple[float, str, str, str, Fit] | None = None
    for a, c in sorted(pairs):
        for b in names:
            if b == a:
                continue
            rest = [(e, v) for e, v in chosen if e.name not in (a, b)]
            fit = prob.fit(rest, EFFECTS[c], None, sensors, max_nfev=20)
            if not fit.ok or fit.segment_costs is None or fit.cost_test <= 0:
                continue
            dbic = _dbic(st.seg_costs, fit.segment_costs, st.seg_n, st.n_eff,
                         EFFECTS[c].k - EFFECTS[a].k - EFFECTS[b].k, scale=st.seg_scale)
            held = 1.0 - st.cost_test / fit.cost_test   # what S gains over S' on held-out
            vals = display_values(EFFECTS[c], fit.values[-1])
            if (dbic < 0.0 and held < crit.threshold(b)
                    and plausibility(c, vals, prob.base) is None
                    and effect_size(c, fit.values[-1], prob.base) >= MIN_SIZE.get(c, 0.0)
                    and _degenerate(prob, fit, crit.degenerate_corr) is None
                    and (best is None or dbic < best[0])):
                best = (dbic, a, b, c, fit)
    if best is None:
        return chosen, sensors
    dbic, a, b, c, fit = best
    note = (f"{a} and {b} replaced by {c}: one effect explains what the two did (dBIC "
            f"{dbic:.1f} for {EFFECTS[c].k - EFFECTS[a].k - EFFECTS[b].k:+d} parameter(s), "
            f"held-out cost {fit.cost_test / st.cost_test:.3f} x); {a} and {c} were reported as "
            "confounded")
    _add_confound(confounded, 0, [a, b, c], "replaced", float("nan"), note)
    if progress:
        progress(note)
    return _refit(prob, fit.chosen(), fit.sensors)


def _evidence(row: dict[str, Any]) -> float:
    """A significant candidate's dBIC: its group's where the group test made it significant."""
    d = row["group"]["dbic"] if row["significant_by"] == "group" else row["dbic"]
    return float(d) if d is not None and math.isfinite(d) else math.inf


def _refit(prob: Problem, chosen: Chosen, sensors: list[FloatArray], passes: int = 2
           ) -> tuple[Chosen, list[FloatArray]]:
    """Reweight from the current residual and refit the chosen effects and the sensors.

    Twice: the weights follow the refitted residual.
    """
    for _ in range(passes):
        prob.reweight(chosen, sensors)
        fit = (prob.fit(chosen[:-1], chosen[-1][0], chosen[-1][1], sensors, max_nfev=25)
               if chosen else prob.fit([], None, None, sensors, max_nfev=25))
        chosen, sensors = fit.chosen(), fit.sensors
    prob.reweight(chosen, sensors)
    return chosen, sensors


def effective_samples(prob: Problem, w: FloatArray, tau_noise: float
                      ) -> tuple[float, float]:
    """The residual's autocorrelation time [samples] and the effective training samples.

    The time is the larger of the noise's and of the current residual's (the intervals'
    inflation: a residual that is correlated beyond the noise makes its samples count
    less); the effective number is the training samples over the noise's time alone (the
    BIC's: see :func:`select_effects`).
    """
    tau = max(tau_noise, 1.0)
    for part, rows in zip(prob.parts, prob.rows_of(w), strict=True):
        for r in rows.values():
            tau = max(tau, autocorr_time(r[part.train]))
    n_train = int(np.sum(prob.train & np.isfinite(w)))
    return tau, n_train / max(tau_noise, 1.0)


def _screen(prob: Problem, st: _Stage, names: list[str]) -> dict[str, tuple]:
    """One Gauss-Newton step per candidate with the sensors refitted (the screening).

    At the first stage the Jacobians are those the null computed (cached under the same
    key).
    """
    key = ("stage", st.index) if st.index else ("nominal",)
    D_s = prob.sensor_jacobian(st.chosen, st.sensors, st.w, key=key)
    screen = LinearScreen(D_s, prob.train, prob.test)
    out = {}
    for name in names:
        eff = EFFECTS[name]
        if name == "track_bumps":
            out[name] = _screen_bump(prob, st, screen, key)
            continue
        chosen_names = st.chosen_names
        if name in chosen_names:
            continue
        x0 = np.asarray(eff.start(prob.base), float)
        D = prob.effect_jacobian(st.chosen, st.sensors, eff, x0, st.w, key=key)
        clip0 = np.isclose(x0, np.asarray(eff.lower, float))
        gain, b, r_tr = screen.gain(st.w, D, clip0)
        vals = np.clip(x0 + b, np.asarray(eff.lower, float), np.asarray(eff.upper, float))
        out[name] = (vals, gain, prob.segment_costs(r_tr))
    return out


def _screen_parts(prob: Problem, st: _Stage, names: list[str], crit: _Criteria
                  ) -> dict[str, list[float]]:
    """Each recording's linearised held-out gain of each candidate (the group test's screen).

    The pooled screen refits only the sensors, so an effect that shows in some recordings
    only, against an effect already chosen (a torque offset beside the Coulomb friction the
    one-way runs fitted), is screened at a gain near zero: its step is held back by the
    recordings where it only competes with the chosen effect. Here the chosen effects'
    columns are refitted with the sensors (a Gauss-Newton step of the joint fit) and the
    held-out cost of that one step is scored per recording.
    """
    key = ("stage", st.index) if st.index else ("nominal",)
    D_s = prob.sensor_jacobian(st.chosen, st.sensors, st.w, key=key)
    cols = [D_s]
    for k, (eff, v) in enumerate(st.chosen):
        for j in range(eff.k):
            h = float(eff.scales[j]) * (1.0 if v[j] + eff.scales[j] <= eff.upper[j] else -1.0)
            x = np.array(v, float)
            x[j] += h
            moved = [*st.chosen[:k], (eff, x), *st.chosen[k + 1:]]
            try:
                col = (prob.weighted(moved, st.sensors) - st.w) / h
            except _BAD:
                col = np.zeros_like(st.w)
            cols.append(np.where(np.isfinite(col), col, 0.0)[:, None])
    D_a = np.hstack(cols)
    cur = np.where(np.isfinite(st.w), st.w, 0.0)
    screen = LinearScreen(D_a, prob.train, prob.test)
    out = {}
    for name in names:
        eff = EFFECTS[name]
        if name == "track_bumps" or name in st.chosen_names or not crit.part_thresholds.get(name):
            continue
        x0 = np.asarray(eff.start(prob.base), float)
        D = prob.effect_jacobian(st.chosen, st.sensors, eff, x0, st.w, key=key)
        _, step = screen.step(cur, D)
        gains = []
        for i in range(len(prob.parts)):
            sl = prob.part_slice(i)
            te = prob.test[sl]
            c0 = float(np.sum(cur[sl][te] ** 2))
            c1 = float(np.sum(step[sl][te] ** 2))
            gains.append(1.0 - c1 / c0 if c0 > 0 else 0.0)
        out[name] = gains
    return out


def _screen_bump(prob: Problem, st: _Stage, screen: LinearScreen, key: Any) -> tuple:
    """The best single bump on a grid of positions (linear in its height), by training cost."""
    cols = prob.bump_columns(st.chosen, st.sensors, st.w, key=key)
    if not cols:
        return np.array([0.0, 0.0, 0.1]), 0.0, st.seg_costs
    j = screen.best_column(st.w, [c for _, c in cols])
    phi_c, col = cols[j]
    gain, b, r_tr = screen.gain(st.w, col[:, None])
    return (np.array([phi_c, float(np.clip(b[0], -1e-3, 1e-3)), 0.1]), gain,
            prob.segment_costs(r_tr))


def _assess_candidates(prob: Problem, st: _Stage, cands: list[str], crit: _Criteria,
                       progress: Any) -> tuple[list[dict[str, Any]], dict[str, Fit]]:
    """Screen every candidate of a stage, fit the promising ones fully, rate them all."""
    names = [n for n in cands if n not in st.chosen_names or n == "track_bumps"]
    screened = _screen(prob, st, names)
    names = [n for n in names if n in screened]
    top = sorted(names, key=lambda n: -screened[n][1])[:crit.screen_top]
    by_part = _screen_parts(prob, st, names, crit) if crit.part_thresholds else {}
    rows = []
    fits: dict[str, Fit] = {}
    for name in names:
        full = (name in top or screened[name][1] >= crit.screen_frac * crit.threshold(name)
                or any(t is not None and g >= crit.screen_frac * t for g, t in
                       zip(by_part.get(name, []), crit.part_thresholds.get(name, []),
                           strict=False)))
        row, fit = _assess(prob, st, name, screened[name], full, crit)
        if fit is not None:
            fits[name] = fit
        rows.append(row)
        if progress:
            progress(_describe(st.index, row))
    rows.sort(key=lambda r: -r["heldout_gain"])
    return rows, fits


def _assess(prob: Problem, st: _Stage, name: str, screened: tuple, full: bool,
            crit: _Criteria) -> tuple[dict[str, Any], Fit | None]:
    """Rate one candidate added to the chosen effects (full joint fit or linearised)."""
    eff = EFFECTS[name]
    thr = crit.threshold(name)
    degenerate = None
    fit = None
    vals0, gain0, seg0 = screened
    if full:
        start = np.clip(vals0, np.asarray(eff.lower) + 0.5 * np.asarray(eff.scales),
                        np.asarray(eff.upper) - 0.5 * np.asarray(eff.scales))
        fit = prob.fit(st.chosen, eff, start, st.sensors, max_nfev=20)
        gain, dbic = _stats(st, fit, eff.k)
        vals = display_values(eff, fit.values[-1])
        degenerate = _degenerate(prob, fit, crit.degenerate_corr)
        size = effect_size(name, fit.values[-1], prob.base)
    else:
        gain = gain0
        dbic = _dbic(st.seg_costs, seg0, st.seg_n, st.n_eff, eff.k, scale=st.seg_scale)
        vals = display_values(eff, vals0)
        size = effect_size(name, vals0, prob.base)
    big = size >= MIN_SIZE.get(name, 0.0)
    why = plausibility(name, vals, prob.base)
    pooled = bool(full and gain > thr and dbic < crit.dbic_min and degenerate is None and big)
    group = (_group_test(prob, st, eff, fit, crit) if fit is not None and
             crit.part_thresholds.get(name) else None)
    by_group = bool(not pooled and group is not None and group["significant"]
                    and gain > 0.0 and degenerate is None and big)
    row = {"effect": name, "stage": st.index + 1, "heldout_gain": gain, "dbic": dbic,
           "plausible": why is None, "implausible_because": why,
           "threshold": thr,
           "significant": pooled or by_group,
           "significant_by": "all recordings" if pooled else "group" if by_group else None,
           "group": group,
           "selected": False, "degenerate": degenerate,
           "size": size, "below_min_size": not big,
           "fit": "full" if full else "linearised (screened out)",
           "values": dict(zip(eff.names, map(float, vals), strict=True)),
           "units": dict(zip(eff.names, eff.units, strict=True))}
    return row, fit


def _group_test(prob: Problem, st: _Stage, eff: Effect, fit: Fit, crit: _Criteria
                ) -> dict[str, Any] | None:
    """The group test of a full joint fit: per-recording gains and the group's BIC.

    Module docstring (group test). None when the fit has no per-part costs.
    """
    if fit.part_costs is None or not fit.ok:
        return None
    thr = crit.part_thresholds[eff.name]
    cur = prob.part_costs(st.w)
    rows, group, rest = [], [], []
    for i, (p, t) in enumerate(zip(prob.parts, thr, strict=True)):
        if t is None or not p.affected_by(eff):
            continue
        g = 1.0 - fit.part_costs[i][1] / cur[i][1] if cur[i][1] > 0 else 0.0
        rows.append({"recording": p.name, "gain": float(g), "threshold": float(t)})
        (group if g > t else rest).append(i)
    out: dict[str, Any] = {"recordings": [prob.parts[i].name for i in group],
                           "per_recording": rows, "gain": None, "threshold": None,
                           "gain_rest": None, "dbic": None, "significant": False}
    if not group:
        return out

    def pooled_gain(idx: list[int]) -> float:
        c0 = sum(cur[i][1] for i in idx)
        return 1.0 - sum(fit.part_costs[i][1] for i in idx) / c0 if c0 > 0 else 0.0

    g_grp = pooled_gain(group)
    t_grp = max(float(thr[i]) for i in group)
    g_rest = pooled_gain(rest) if rest else 0.0
    in_group = np.zeros(prob.n_segments, bool)
    for i in group:
        in_group[np.unique(prob.segment[prob.part_slice(i)])] = True
    dbic = (_dbic(st.seg_costs, fit.segment_costs, st.seg_n, st.n_eff, eff.k, in_group,
                  st.seg_scale)
            if fit.segment_costs is not None else math.inf)
    out.update(gain=float(g_grp), threshold=t_grp, gain_rest=float(g_rest), dbic=float(dbic),
               significant=bool(g_grp > t_grp and g_rest > -crit.threshold(eff.name)
                                and dbic < crit.dbic_min))
    return out


def _describe(index: int, row: dict[str, Any]) -> str:
    """The progress line of one candidate's row (:func:`_assess`) at stage ``index``."""
    name = row["effect"]
    return (f"stage {index + 1}: {name:24s} held-out gain {row['heldout_gain']:+.4f} "
            f"(null {row['threshold']:.4f}) dBIC {row['dbic']:+.1f}"
            + ("" if row["fit"] == "full" else " [linearised]")
            + (f" [degenerate: {row['degenerate']}]" if row["degenerate"] else "")
            + (f" [significant in a group: {', '.join(row['group']['recordings'])}, dBIC "
               f"{row['group']['dbic']:+.1f}]" if row.get("significant_by") == "group"
               else "")
            + ("" if not row["below_min_size"]
               else f" [size {row['size']:.2g} below {MIN_SIZE[name]:g}]"))


def _ranking(stages: list[dict[str, Any]], cands: list[str]) -> list[dict[str, Any]]:
    """Every effect: its figures alone (stage 1) and, if selected, at its stage.

    Selected effects first in the order of selection, then by their gain alone.
    """
    first = {r["effect"]: r for r in stages[0]["candidates"]} if stages else {}
    out = []
    for name in cands:
        r1 = first.get(name)
        if r1 is None:
            continue
        sel = next((r for st in stages for r in st["candidates"]
                    if r["effect"] == name and r.get("selected")), None)
        out.append({
            "effect": name, "selected": sel is not None,
            "stage_selected": sel["stage"] if sel else None,
            "heldout_gain": r1["heldout_gain"], "threshold": r1["threshold"],
            "dbic": r1["dbic"], "fit": r1["fit"], "degenerate": r1["degenerate"],
            "gain_at_selection": sel["heldout_gain"] if sel else None,
            "threshold_at_selection": sel["threshold"] if sel else None,
            "dbic_at_selection": sel["dbic"] if sel else None,
            "significant_by": sel.get("significant_by") if sel else None,
            "group_at_selection": sel.get("group") if sel else None,
            "values_at_selection": sel["values"] if sel else None})
    out.sort(key=lambda r: (not r["selected"], r["stage_selected"] or 0, -r["heldout_gain"]))
    return out


# -- degenerate and confounded fits -----------------------------------------------------------


def _add_confound(out: list[dict[str, Any]], stage: int, effects: list[str], kind: str,
                  rho: float, note: str) -> None:
    """Record a confounded set once (the earliest note is kept)."""
    for c in out:
        if c["kind"] == kind and frozenset(c["effects"]) == frozenset(effects):
            return
        if kind == "degenerate" and effects[-1] in c["effects"] and (
                c["kind"] == "pair" or c["effects"][-1] == effects[-1]):
            return
    out.append({"stage": stage, "effects": effects, "pair": effects[-2:], "kind": kind,
                "correlation": rho, "note": note})


def _corr_matrix(fit: Fit) -> FloatArray | None:
    """Correlations of the fitted parameters; 0 for a parameter the data do not constrain.

    A parameter whose Jacobian column vanishes (a timing at constant speed, a value at its
    bound) has a variance at the pseudo-inverse's numerical zero: dividing by it gave
    "correlations" of 1e130 on the shipped logs. A valid covariance has ``|rho| <= 1``; a
    parameter with zero variance or a larger ratio has no correlation to report (its row
    and column are 0, its diagonal 1).
    """
    if fit.cov is None:
        return None
    var = np.diag(fit.cov)
    d = np.sqrt(np.maximum(var, 1e-300))
    with np.errstate(invalid="ignore"):  # inf / inf of an unconstrained parameter
        corr = fit.cov / np.outer(d, d)
    corr[var <= 0.0, :] = 0.0
    corr[:, var <= 0.0] = 0.0
    corr[~np.isfinite(corr)] = 2.0
    np.fill_diagonal(corr, 1.0)
    while True:  # the parameter in most impossible pairs first (its variance is the zero)
        count = np.sum(np.abs(corr) > 1.0 + 1e-6, axis=1)
        if not count.any():
            break
        worst = int(np.lexsort((var, -count))[0])
        corr[worst, :] = 0.0
        corr[:, worst] = 0.0
        corr[worst, worst] = 1.0
    return np.clip(corr, -1.0, 1.0)


def _offsets(fit: Fit) -> FloatArray:
    return np.concatenate([[0], np.cumsum([EFFECTS[n].k for n in fit.effects])]).astype(int)


#: [-] Two parameters of different effects that correlate beyond ``degenerate_corr`` are
#: still identified when each lies this many marginal standard deviations (their
#: correlation included) from its nominal value (:func:`_degenerate`).
RESOLVED_Z = 5.0


def at_bounds(prob: Problem, fit: Fit) -> dict[str, str]:
    """Each effect with a parameter at a fit bound it did not start at, and why (the first).

    Such a value is where the fit stopped, not a measurement: the data would have it further.
    """
    out: dict[str, str] = {}
    for name, vals in zip(fit.effects, fit.values, strict=True):
        eff = EFFECTS[name]
        x0 = np.asarray(eff.start(prob.base), float)
        lo, hi = np.asarray(eff.lower, float), np.asarray(eff.upper, float)
        tol = 1e-3 * (hi - lo)
        for j, v in enumerate(np.asarray(vals, float)):
            if v - lo[j] < tol[j] and x0[j] - lo[j] >= tol[j]:
                out[name] = f"{name}.{eff.names[j]} at its lower bound {lo[j]:.3g}"
            elif hi[j] - v < tol[j] and hi[j] - x0[j] >= tol[j]:
                out[name] = f"{name}.{eff.names[j]} at its upper bound {hi[j]:.3g}"
            else:
                continue
            break
    return out


def _at_bound(prob: Problem, fit: Fit) -> tuple[str, str] | None:
    """The first effect with a parameter at a bound it did not start at, and why, or None."""
    return next(iter(at_bounds(prob, fit).items()), None)


def _degenerate(prob: Problem, fit: Fit, max_corr: float) -> str | None:
    """Why a joint fit is not identifiable, or None (see :func:`select_effects`)."""
    bound = _at_bound(prob, fit)
    if not fit.ok:  # the model not finite where the fit ended (a contour with a cusp, say)
        return ("fit failed: the model could not be evaluated at the fitted values"
                + (f" ({bound[1]})" if bound is not None else ""))
    if bound is not None:
        return bound[1]
    if fit.cov is not None:  # a direction of the Jacobian's null space (see _covariance)
        free = np.nonzero(np.isinf(np.diag(fit.cov))[:fit.n_params])[0]
        if free.size:
            offs = _offsets(fit)
            k = int(np.searchsorted(offs, free[0], side="right") - 1)
            eff = EFFECTS[fit.effects[k]]
            return (f"{eff.name}.{eff.names[free[0] - offs[k]]} not fixed by these data "
                    "(it moves together with other parameters: only a combination is known)")
    corr = _corr_matrix(fit)
    if corr is not None and len(fit.effects) > 1:
        offs = _offsets(fit)
        z = _resolution(prob, fit)
        for i, a in enumerate(fit.effects):
            for j in range(i + 1, len(fit.effects)):
                block = corr[offs[i]:offs[i + 1], offs[j]:offs[j + 1]]
                for p, q in zip(*np.nonzero(np.abs(block) > max_corr), strict=True):
                    rho = float(abs(block[p, q]))
                    if not np.isfinite(rho):
                        continue
                    zpq = min(z[offs[i] + p], z[offs[j] + q])
                    if zpq >= RESOLVED_Z:
                        continue  # they move together, but the data fix each one apart
                    return (f"{a} and {fit.effects[j]} correlate {rho:.3f} (resolved to "
                            f"{zpq:.1f} standard deviations; {RESOLVED_Z:g} needed)")
    return None


def _resolution(prob: Problem, fit: Fit) -> FloatArray:
    """Each effect parameter's distance from its nominal in marginal standard deviations.

    ``|v - v_0| / sigma`` from the fit's covariance (0 where the variance is not finite).
    """
    vals = np.concatenate([np.asarray(v, float) for v in fit.values])
    nominal = np.concatenate([np.asarray(EFFECTS[n].start(prob.base), float)
                              for n in fit.effects])
    var = np.diag(fit.cov)[:vals.size] if fit.cov is not None else np.full(vals.size, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(vals - nominal) / np.sqrt(var)
    return np.where(np.isfinite(z) & (var > 0.0), z, 0.0)


def _corr_between(fit: Fit, a: str, b: str) -> float:
    """Largest |correlation| between a parameter of effect a and one of effect b."""
    corr = _corr_matrix(fit)
    if corr is None:
        return float("nan")
    offs = _offsets(fit)
    ia, ib = fit.effects.index(a), fit.effects.index(b)
    block = corr[offs[ia]:offs[ia + 1], offs[ib]:offs[ib + 1]]
    return float(np.max(np.abs(block))) if block.size else float("nan")


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
        pair_fit = prob.fit(best_fit.chosen(), e_b, None, best_fit.sensors, max_nfev=25)
        rho = _corr_between(pair_fit, best["effect"], other["effect"])
        extra_gain = (1.0 - pair_fit.cost_test / best_fit.cost_test
                      if best_fit.cost_test > 0 else 0.0)
        if rho > confound_corr or extra_gain < 0.1 * best["heldout_gain"]:
            _add_confound(confounded, st.index + 1, [best["effect"], other["effect"]], "pair",
                          rho, f"{best['effect']} and {other['effect']} explain the same "
                          f"residual (held-out gains {best['heldout_gain']:.3f} vs "
                          f"{other['heldout_gain']:.3f}, parameter correlation "
                          f"{rho:.2f}): the data cannot tell them apart; "
                          f"{best['effect']} is kept (the stage's choice: significant, "
                          f"plausible first, lowest dBIC; dBIC {_evidence(best):.1f} vs "
                          f"{other['dbic']:.1f})")


def _note_sensor_confounds(prob: Problem, confounded: list[dict[str, Any]], fit: Fit,
                           confound_corr: float) -> None:
    """Report physics parameters that correlate beyond ``confound_corr`` with a sensor's."""
    corr = _corr_matrix(fit)
    if corr is None or not fit.effects:
        return
    offs = _offsets(fit)
    names = [(i, n) for i, p in enumerate(prob.parts) for n in p.sensor_names]
    for k, eff in enumerate(fit.effects):
        for c in range(offs[k], offs[k + 1]):
            for j, (i, sname) in enumerate(names):
                rho = abs(float(corr[c, fit.n_params + j]))
                if rho > confound_corr:
                    pname = EFFECTS[eff].names[c - offs[k]]
                    _add_confound(confounded, 0, [eff, f"sensor:{sname}"], "sensor", rho,
                                  f"{eff}.{pname} correlates {rho:.2f} with the sensor model's "
                                  f"{sname} of {prob.parts[i].name}: they are only known "
                                  "together from these recordings")


# -- tables ----------------------------------------------------------------------------------


def parameter_table(fit: Fit, tau: float) -> list[dict[str, Any]]:
    """Fitted effect values with 95 % intervals (covariance inflated by the autocorrelation)."""
    out = []
    if not fit.effects:
        return out
    i = 0
    for name, vals in zip(fit.effects, fit.values, strict=True):
        eff = EFFECTS[name]
        disp = display_values(eff, vals)
        for j, pname in enumerate(eff.names):
            var = float(fit.cov[i + j, i + j]) * tau if fit.cov is not None else float("nan")
            sd = math.sqrt(var) if var >= 0 else float("nan")
            out.append({"effect": name, "name": pname, "unit": eff.units[j],
                        "value": float(disp[j]), "ci95": [float(disp[j] - 1.96 * sd),
                                                          float(disp[j] + 1.96 * sd)],
                        "std": sd})
        i += eff.k
    return out


def sensor_table(prob: Problem, fit: Fit, tau: float) -> list[dict[str, Any]]:
    """Each part's fitted sensor model with 95 % intervals.

    ``at_bound`` is the bound a value ran to (within 0.1 % of its range), else None: such a
    value is not identified by the recording (:func:`bfr_diagnose.api` notes it). A
    parameter with a calibration prior has ``prior`` (its nominal and width), ``pull``
    (``(value - nominal) / width``: beyond 2 the data moved it against the prior) and
    ``posterior_over_prior`` (its posterior sd over the prior's width: near 1 the data say
    nothing about it, the prior holds it; well under 1 the data fix it).
    """
    out = []
    default = SensorCorrection()
    j = fit.n_params
    for p, vals in zip(prob.parts, fit.sensors, strict=True):
        for name, v in zip(p.sensor_names, vals, strict=True):
            var = (float(fit.cov[j, j]) * tau if fit.cov is not None and j < fit.cov.shape[0]
                   else float("nan"))
            sd = math.sqrt(var) if var >= 0 else float("nan")
            sp = sensor_param(name)
            margin = 1e-3 * (sp.upper - sp.lower)
            bound = (sp.lower if v - sp.lower <= margin else
                     sp.upper if sp.upper - v <= margin else None)
            row = {"recording": p.name, "name": name, "unit": sp.unit, "value": float(v),
                   "ci95": [float(v - 1.96 * sd), float(v + 1.96 * sd)], "std": sd,
                   "description": sp.description, "at_bound": bound, "prior": None}
            width = prob.prior_width(name)
            if width is not None:
                nominal = float(getattr(default, name))
                row.update(prior={"nominal": nominal, "width": width},
                           pull=float((v - nominal) / width),
                           posterior_over_prior=float(sd / width))
            out.append(row)
            j += 1
    return out


# -- one rig, many recordings -----------------------------------------------------------------


def between_recordings(prob: Problem, sel: Selection) -> dict[str, Any]:
    """Per-recording values of the selected effects and intervals that include their spread.

    Every selected effect that enters a recording's rows is fitted on that recording alone
    (with its sensors, from the joint values). For each parameter the per-recording values
    ``y_i +- s_i`` are combined as a random-effects mean (DerSimonian and Laird): the
    between-recording variance ``tau^2 = max(0, (Q - (k - 1)) / (S1 - S2 / S1))`` with
    ``Q = sum w_i (y_i - y_w)^2``, ``w_i = 1 / s_i^2``, ``S1 = sum w_i``, ``S2 = sum w_i^2``,
    and the joint value's interval is widened to
    ``+- 1.96 sqrt(s_joint^2 + 1 / sum(1 / (s_i^2 + tau^2)) - 1 / sum(1 / s_i^2))``, i.e. by
    what the spread between recordings adds to the uncertainty of their mean. A
    recording whose own fit is degenerate (a parameter at a bound, two that move together:
    its value is kept, its interval is ``None``, its std NaN) or leaves a parameter
    undetermined (standard error above the joint value's range) does not count. Where one
    effect runs to a bound (the recording cannot fix it: a bump it never shows), the others
    are refitted on that recording without it and count with their intervals.

    Each used recording is also set against the others (:func:`_disagreement`): its value
    minus the others' random-effects mean, over the root of its variance, that mean's and
    the others' spread ``tau^2``. Beyond :data:`DISAGREE_Z` the parameter is listed in
    ``disagree``: the recordings do not measure one value (two rigs, a part changed between
    them, or a model that fits each differently); the joint value is then a compromise.

    Returns
    -------
    dict
        ``per_recording`` (rows: recording, effect, parameter, value, std, used),
        ``joint`` (per parameter: value, ci95 of the joint fit, tau, ci95 with the spread,
        recordings used) and ``disagree`` (per parameter whose recordings disagree: the
        recording farthest from the others, its z, every used recording's value and std).
    """
    if len(prob.parts) < 2 or not sel.chosen:
        return {"per_recording": [], "joint": [], "disagree": []}
    rows: list[dict[str, Any]] = []
    chosen = sel.final.chosen()
    for i, part in enumerate(prob.parts):
        mine = [(e, v) for e, v in chosen if part.affected_by(e)]
        if not mine:
            continue
        fit = prob.fit(mine[:-1], mine[-1][0], mine[-1][1], sel.final.sensors, max_nfev=25,
                       only_part=i)
        w = prob.part_weighted(i, fit.chosen(), fit.sensors[i]).reshape(len(part.rows), -1)
        tau = max(autocorr_time(r[part.train]) for r in w)
        degenerate = _degenerate(prob, fit, 0.995)
        table = parameter_table(fit, tau)
        why = {r["effect"]: degenerate for r in table}
        bound = _at_bound(prob, fit) if degenerate is not None else None
        rest = [(e, v) for e, v in mine if bound is None or e.name != bound[0]]
        if bound is not None and rest:
            # one effect this recording cannot fix (a parameter at its bound): the others are
            # refitted without it and keep their intervals if that fit is identifiable
            refit = prob.fit(rest[:-1], rest[-1][0], rest[-1][1], sel.final.sensors,
                             max_nfev=25, only_part=i)
            if _degenerate(prob, refit, 0.995) is None:
                table = parameter_table(refit, tau) + [r for r in table
                                                       if r["effect"] == bound[0]]
                why = {r["effect"]: bound[1] if r["effect"] == bound[0] else None
                       for r in table}
        for r in table:
            if why[r["effect"]] is not None:
                # A parameter at a bound or two that move together: the curvature there says
                # nothing of the value's spread, so the recording has no interval.
                r.update(ci95=[None, None], std=float("nan"))
            rows.append({"recording": part.name, **r, "degenerate": why[r["effect"]]})
    joint, disagree = [], []
    for p in sel.parameters:
        mine = [r for r in rows if r["effect"] == p["effect"] and r["name"] == p["name"]]
        joint.append(_random_effects(p, mine))
        d = _disagreement(p, [r for r in mine if r["used"]])
        if d is not None:
            disagree.append(d)
    disagree.sort(key=lambda d: -d["z"])
    return {"per_recording": rows, "joint": joint, "disagree": disagree}


#: A recording's value this many standard deviations (its own, the others' mean's and their
#: spread) from the others' flags the parameter (:func:`between_recordings`). Two-sided
#: p = 6e-7 for one parameter of an honest interval: far beyond chance, and beyond what the
#: NTNU rig's two rolling logs (fin, Actually_worked: one rig) show at most, 3.3 (the
#: contour's a).
DISAGREE_Z = 5.0


def _tau2(y: FloatArray, s2: FloatArray) -> tuple[float, float]:
    """DerSimonian-Laird between-recording variance of values ``y`` with variances ``s2``.

    Returns ``(tau^2, Q)``, Cochran's Q the weighted squares about the fixed-effect mean
    (``(0, 0)`` for fewer than two values).
    """
    if y.size < 2:
        return 0.0, 0.0
    w = 1.0 / s2
    yw = float(np.sum(w * y) / np.sum(w))
    q = float(np.sum(w * (y - yw) ** 2))
    s1, s2w = float(np.sum(w)), float(np.sum(w ** 2))
    return max(0.0, (q - (y.size - 1)) / max(s1 - s2w / s1, 1e-300)), q


def _disagreement(p: dict[str, Any], use: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The recording of ``use`` farthest from the others' mean, if beyond :data:`DISAGREE_Z`.

    Leave one out: the others' random-effects mean ``m`` (their spread ``tau^2`` from
    :func:`_tau2`, 0 for a single other) and ``z = |y_i - m| / sqrt(s_i^2 + var(m) +
    tau^2)``. None with fewer than two recordings or no z beyond the limit.
    """
    if len(use) < 2:
        return None
    y = np.array([r["value"] for r in use], float)
    s2 = np.array([r["std"] for r in use], float) ** 2
    zs = []
    for i in range(y.size):
        o = np.arange(y.size) != i
        t2 = _tau2(y[o], s2[o])[0]
        w = 1.0 / (s2[o] + t2)
        m = float(np.sum(w * y[o]) / np.sum(w))
        zs.append(abs(y[i] - m) / math.sqrt(s2[i] + 1.0 / float(np.sum(w)) + t2))
    k = int(np.argmax(zs))
    if zs[k] <= DISAGREE_Z:
        return None
    return {"effect": p["effect"], "name": p["name"], "joint_value": p["value"],
            "z": float(zs[k]), "recording": use[k]["recording"],
            "values": [{"recording": r["recording"], "value": r["value"], "std": r["std"]}
                       for r in use]}


def _random_effects(p: dict[str, Any], mine: list[dict[str, Any]]) -> dict[str, Any]:
    """DerSimonian-Laird between-recording spread of one parameter (:func:`between_recordings`)."""
    sd_joint = p["std"] if math.isfinite(p["std"]) else 0.0
    span = max(abs(p["value"]), 10.0 * sd_joint, 1e-12)
    use = [r for r in mine if r["degenerate"] is None and math.isfinite(r["std"])
           and 0.0 < r["std"] < span]
    for r in mine:
        r["used"] = r in use
    out = {"effect": p["effect"], "name": p["name"], "value": p["value"],
           "ci95_joint": p["ci95"], "recordings_used": len(use), "tau": 0.0,
           "ci95": p["ci95"]}
    if len(use) < 2:
        return out
    y = np.array([r["value"] for r in use])
    s2 = np.array([r["std"] for r in use]) ** 2
    tau2, q = _tau2(y, s2)
    s1 = float(np.sum(1.0 / s2))
    extra = 1.0 / float(np.sum(1.0 / (s2 + tau2))) - 1.0 / s1
    half = 1.96 * math.sqrt(sd_joint ** 2 + max(extra, 0.0))
    out.update(tau=math.sqrt(tau2), q=q, random_effects_mean=float(
        np.sum(y / (s2 + tau2)) / np.sum(1.0 / (s2 + tau2))),
        ci95=[p["value"] - half, p["value"] + half])
    return out
