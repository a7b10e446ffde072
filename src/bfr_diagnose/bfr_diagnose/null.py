"""The noise-only null: what the residual and the fits look like when only noise is there.

**Noise injection into each recording itself** (:func:`part_noise`). The sensor noise of the
recording is estimated in preprocessing (camera: the fixes against the cubic through their
neighbours, across the ball's path and along it apart,
:func:`~bfr_diagnose.preprocess.fix_noise_path`; encoder: its resolution,
quantisation ``q / sqrt(12)``; a logged velocity: its high-frequency scatter). Fresh noise of
exactly that size is added to the raw measurements (each camera fix, theta, the logged
velocity), the noisy copy goes through the same preprocessing (the same pieces, the same
decisions: :func:`~bfr_diagnose.preprocess.prepare_pieces`), and the difference of the two
nominal residuals

    r_noise = r(data + noise) - r(data)

is the noise's own contribution to the equation error, propagated through the very
pipeline and along the recording's own trajectory (to first order in the noise, which is
what the filtered-momentum residual is). Nothing is simulated, so the null holds for any
excitation, controller or rig.

From ``R`` injections, per recording and row (frame, ball, ball's distance):

- ``sigma``: RMS noise of the row (the weights of the cost);
- ``msq``: the expected square of the noise residual at each sample (the noise is not
  stationary: it grows where the ball is fast), the scale of the chi-square tests of
  windows and regions in :mod:`~bfr_diagnose.locate`;
- ``tau``: integrated autocorrelation time of the noise residual [samples].

Over all recordings together (:func:`null_gains`), per effect: the held-out gain its fit
reaches on pure noise beyond what refitting every recording's sensor model reaches. The
fit is linearised: the effect's and the sensors' residual Jacobians at the nominal physics
with the stage-0 sensors (finite differences on the recordings; the same columns the
selection's first stage starts from) and the least-squares fit of the weighted noise on
them over the training blocks, scored on the held-out blocks exactly like the real fit
(:func:`~bfr_diagnose.identify.linear_gain`); a parameter bounded at its nominal value
(friction, rolling resistance, misalignment >= 0) is clipped there. Track bumps: the best of
a grid of bump positions (look-elsewhere effect included).

Processing term: the pipeline has a resolution of its own (the Savitzky-Golay smoothing
bends fast motion; on noise-free data this bias is all that is left in the residual and
would otherwise look significant). Each recording is preprocessed once more with all filter
widths (anti-alias, Savitzky-Golay windows) 1.4 times as long, and twice the change of the
nominal residual, ``2 (r(longer filters) - r(data))``, is added to every noise draw. The
null is then "noise plus what our own processing does", and nothing below the processing's
resolution counts as a mismatch. On real or noisy data this term is far below the noise.

Per recording (:func:`null_part_gains`, with several recordings): the same fits, each scored
on one recording's blocks alone, give each recording's own null gains, the noise level of
the selection's group test (an effect that shows in some of the recordings only).

The threshold of an effect is ``margin * max(null gains) + floor``. Gains are cost ratios,
so they do not depend on the noise level itself, only on the number of effectively
independent samples and on how many directions an effect can fit.
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
from bfr_diagnose.identify import LinearScreen, Part, Problem, autocorr_time
from bfr_diagnose.preprocess import Piece, PrepConfig, path_steps, prepare_pieces
from bfr_diagnose.residual import Residual, ResidualConfig, ResidualEvaluator

__all__ = ["NullCalibration", "PartNoise", "noisy_copy", "null_gains", "null_part_gains",
           "part_noise", "part_thresholds_of", "thresholds_of"]


FloatArray = NDArray[np.float64]


@dataclass(kw_only=True, eq=False)
class PartNoise:
    """The noise-only null of one recording (module docstring).

    Attributes
    ----------
    draws : list of ndarray
        Each injection's contribution to the nominal rows, shape ``(3, n)`` [N m, N m, m].
    sigma : ndarray
        RMS noise of rows 1-3 on the training blocks (1 where the row is unused).
    msq : ndarray
        Expected square of the noise residual at each sample, shape ``(3, n)``.
    tau : float
        Autocorrelation time of the noise residual [samples] (median over the draws).
    levels : dict
        Noise levels injected (camera [m] per axis, camera_across and camera_along [m]
        across and along the ball's path, theta [rad], theta_dot [rad/s]).
    processing : bool
        Whether the processing term was added.
    """

    draws: list[FloatArray]
    sigma: FloatArray
    msq: FloatArray
    tau: float
    levels: dict[str, float]
    processing: bool


@dataclass
class NullCalibration:
    """Noise scales and per-effect null gains of a diagnosis.

    Attributes
    ----------
    sigma : list of list of float
        Each recording's noise scale of rows 1-3 [N m, N m, m].
    gains : dict
        Held-out gain of each effect in each null draw.
    thresholds : dict
        Largest null gain times ``margin`` plus ``floor``, per effect.
    part_thresholds : dict
        The same of each recording alone (the group test's), per effect a list over the
        recordings (None where the effect does not enter); empty with one recording.
    tau : float
        Autocorrelation time of the noise residual [samples] (the largest recording's).
    runs : int
        Null draws per recording.
    noise : list of dict
        Noise levels injected per recording.
    source : str
        How the null was made.
    rms_null : list of list of float
        RMS of the noise residual of each recording's rows [N m, N m, m].
    msq : list of ndarray or None
        Each recording's expected square of the noise residual per sample, shape (3, n).
        Not in JSON.
    """

    sigma: list[list[float]]
    gains: dict[str, list[float]]
    thresholds: dict[str, float]
    tau: float
    runs: int
    noise: list[dict[str, float]]
    source: str
    rms_null: list[list[float]] = field(default_factory=list)
    part_thresholds: dict[str, list[float | None]] = field(default_factory=dict)
    msq: list[FloatArray] | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (without the per-sample ``msq``)."""
        d = asdict(self)
        d.pop("msq", None)
        return d


def _levels(prep: Any) -> dict[str, float]:
    """Noise levels to inject (module docstring)."""
    res = float(prep.info.get("theta_resolution", 0.0))
    th = max(res / math.sqrt(12.0), float(prep.noise.get("theta", 0.0)) if
             not prep.info.get("theta_coarse") else 0.0)
    cam = float(prep.noise.get("camera", float("nan")))
    cam = cam if math.isfinite(cam) else 0.0
    # across and along the ball's path, each at its own level (preprocess.fix_noise_path);
    # the per-axis level where they are not estimated
    across = float(prep.noise.get("camera_across", float("nan")))
    along = float(prep.noise.get("camera_along", float("nan")))
    return {"camera": cam, "camera_across": across if math.isfinite(across) else cam,
            "camera_along": along if math.isfinite(along) else cam, "theta": th,
            "theta_dot": (float(prep.noise.get("theta_dot", 0.0))
                          if prep.info.get("theta_coarse") else 0.0)}


def noisy_copy(rec: Recording, levels: dict[str, float], rng: np.random.Generator,
               resolution: float | None = None) -> Recording:
    """``rec`` with fresh sensor noise of the given levels added (module docstring).

    Camera: independent Gaussian noise per fix [m], held with the fix: across the ball's path
    (normal to the step between the fix's outer neighbours, the estimate's stencil,
    :func:`~bfr_diagnose.preprocess.path_steps`) of ``levels["camera_across"]`` and
    along it of ``levels["camera_along"]`` (each ``levels["camera"]`` when absent). theta:
    Gaussian of ``levels["theta"]`` [rad]. Logged velocity: Gaussian of
    ``levels["theta_dot"]`` [rad/s] per sample. ``resolution`` [rad] is kept as the copy's
    ``meta["theta_resolution"]`` so that preprocessing treats it like the original.
    """
    n = rec.n
    bx, by = rec.ball_x.copy(), rec.ball_y.copy()
    cam = levels.get("camera", 0.0)
    s_across = levels.get("camera_across", cam)
    s_along = levels.get("camera_along", cam)
    if max(s_across, s_along) > 0.0 and rec.ball_valid.any():
        new = rec.new_fix_mask()
        hold = np.cumsum(new) - 1
        nf = int(new.sum())
        ux, uy = _path_direction(rec.ball_x[new], rec.ball_y[new])
        a = s_across * rng.standard_normal(nf)
        b = s_along * rng.standard_normal(nf)
        ex = b * ux - a * uy
        ey = b * uy + a * ux
        v = rec.ball_valid & (hold >= 0)
        bx[v] += ex[hold[v]]
        by[v] += ey[hold[v]]
    theta = rec.theta + levels.get("theta", 0.0) * rng.standard_normal(n)
    thd = rec.theta_dot + levels.get("theta_dot", 0.0) * rng.standard_normal(n)
    meta = dict(rec.meta)
    meta["theta_resolution"] = (resolution if resolution is not None
                                else rec.meta.get("theta_resolution"))
    return Recording(t=rec.t, theta=theta, theta_dot=thd, torque=rec.torque, ball_x=bx,
                     ball_y=by, ball_valid=rec.ball_valid, phi=rec.phi, extra=dict(rec.extra),
                     meta=meta)


def _path_direction(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit vectors along the ball's path at each fix (:func:`~.preprocess.path_steps`).

    ``(1, 0)`` where the ball does not move or there is a single fix.
    """
    dx, dy = path_steps(x, y)
    v = np.hypot(dx, dy)
    on = v > 0
    v = np.where(on, v, 1.0)
    return np.where(on, dx / v, 1.0), np.where(on, dy / v, 0.0)


def _rows(res: Residual) -> FloatArray:
    return np.vstack([res.r1, res.r2, res.r3])


def part_noise(part: Part, pieces: list[Piece], base: RigParams, pcfg: PrepConfig,
               rcfg: ResidualConfig, *, runs: int = 6, rng: np.random.Generator,
               processing: bool = True) -> PartNoise:
    """The noise-only null of one recording (module docstring).

    Parameters
    ----------
    part : Part
        The recording in the problem (its evaluator and rows).
    pieces : list of Piece
        The pieces it was prepared from (noisy copies are prepared alike).
    base : RigParams
        Nominal parameters.
    pcfg, rcfg : PrepConfig, ResidualConfig
        The diagnosis's settings.
    runs : int
        Noise draws.
    rng : numpy.random.Generator
        The noise generator.
    processing : bool
        Add the processing term (module docstring).

    Raises
    ------
    RuntimeError
        The noise changed which samples are usable.
    """
    prep = part.ev.prep
    ev = part.ev
    levels = _levels(prep)
    rows0 = _rows(ev.evaluate(base))
    res = prep.info.get("theta_resolution")
    draws = []
    for _ in range(runs):
        noisy = [noisy_copy(pc.rec, levels, rng, res) for pc in pieces]
        p_n = prepare_pieces(pieces, pcfg, latency0=prep.latency0, recs=noisy)
        ev_n = ResidualEvaluator(p_n, replace(rcfg, half_width=ev.half_width))
        if not np.array_equal(ev_n.idx, ev.idx):
            raise RuntimeError("noise injection changed the usable samples")
        draws.append(_rows(ev_n.evaluate(base)) - rows0)
    term = _processing_term(pieces, prep, base, pcfg, rcfg, ev, rows0) if processing else None
    if term is not None:
        draws = [d + term for d in draws]
    sigma = np.ones(3)
    for r in part.rows:
        x = np.concatenate([d[r - 1][part.train] for d in draws])
        x = x[np.isfinite(x)]
        sigma[r - 1] = float(max(np.sqrt(np.mean(x ** 2)), 1e-15)) if x.size > 2 else 1.0
    msq = np.mean([d ** 2 for d in draws], axis=0)
    taus = [max(autocorr_time(d[r - 1][part.train] / sigma[r - 1]) for r in part.rows)
            for d in draws]
    return PartNoise(draws=draws, sigma=sigma, msq=msq, tau=float(np.median(taus)),
                     levels=levels, processing=term is not None)


def _processing_term(pieces: list[Piece], prep: Any, base: RigParams, pcfg: PrepConfig,
                     rcfg: ResidualConfig, ev: ResidualEvaluator, rows0: FloatArray
                     ) -> FloatArray | None:
    """The processing's own resolution, added to every draw (module docstring).

    Twice the change of the nominal rows when every filter width (anti-alias,
    Savitzky-Golay windows) is 1.4 times as long; None when the longer filters change which
    samples are usable, or leave none.
    """
    alt = replace(pcfg, width_factor=1.4 * pcfg.width_factor)
    try:
        ev_a = ResidualEvaluator(prepare_pieces(pieces, alt, latency0=prep.latency0),
                                 replace(rcfg, half_width=ev.half_width))
        if not np.array_equal(ev_a.idx, ev.idx):
            return None
        return 2.0 * (_rows(ev_a.evaluate(base)) - rows0)
    except DiagnoseError:
        return None


def null_gains(prob: Problem, noises: list[PartNoise], sensors0: list[FloatArray]
               ) -> dict[str, list[float]]:
    """Held-out gain of each candidate's linearised fit on each noise draw (module docstring).

    The Jacobians at the nominal physics with the stage-0 sensors are cached in ``prob``
    under the key the selection's first stage uses.
    """
    screen = LinearScreen(_null_sensor_columns(prob, sensors0), prob.train, prob.test)
    return {name: per[0] for name, per in
            _null_screen_gains(prob, noises, sensors0, [screen]).items()}


def null_part_gains(prob: Problem, noises: list[PartNoise], sensors0: list[FloatArray]
                    ) -> dict[str, list[list[float]]]:
    """Each recording's own null gains, per effect: ``gains[name][i]`` over the draws.

    The same linearised fits as :func:`null_gains`, each scored on one recording alone
    (its training and held-out blocks, its own sensor model): the noise level of the
    per-recording held-out gains that the group test of the selection compares with
    (:func:`~bfr_diagnose.identify.select_effects`). A recording the effect does not enter
    has no draws (an empty list).
    """
    D_s = _null_sensor_columns(prob, sensors0)
    screens = []
    for i in range(len(prob.parts)):
        mine = np.zeros(prob.train.size, bool)
        mine[prob.part_slice(i)] = True
        screens.append(LinearScreen(D_s, prob.train & mine, prob.test & mine))
    out = _null_screen_gains(prob, noises, sensors0, screens)
    return {name: [g if prob.parts[i].affected_by(EFFECTS[name]) else []
                   for i, g in enumerate(per)] for name, per in out.items()}


def _null_sensor_columns(prob: Problem, sensors0: list[FloatArray]) -> FloatArray:
    """The sensor columns at the nominal physics and the stage-0 sensors (cached)."""
    w0 = prob.weighted([], sensors0)
    return prob.sensor_jacobian([], sensors0, w0, key=("nominal",))


def _null_screen_gains(prob: Problem, noises: list[PartNoise], sensors0: list[FloatArray],
                       screens: list[LinearScreen]) -> dict[str, list[list[float]]]:
    """Every candidate's null gains under each screen: ``gains[name][screen][draw]``."""
    w0 = prob.weighted([], sensors0)
    key = ("nominal",)
    runs = min(len(n.draws) for n in noises)
    es = []
    for k in range(runs):
        parts = []
        for p, noise in zip(prob.parts, noises, strict=True):
            d = noise.draws[k]
            parts.append(np.concatenate([d[r - 1] * p.row_weight(r) for r in p.rows]))
        es.append(np.concatenate(parts))
    gains: dict[str, list[list[float]]] = {}
    for name in prob.candidates:
        eff = EFFECTS[name]
        if name == "track_bumps":
            cols = [c for _, c in prob.bump_columns([], sensors0, w0, key=key)]
            gains[name] = [[sc.gain(e, cols[sc.best_column(e, cols)][:, None])[0]
                            for e in es] if cols else [0.0 for _ in es] for sc in screens]
            continue
        x0 = np.asarray(eff.start(prob.base), float)
        D = prob.effect_jacobian([], sensors0, eff, x0, w0, key=key)
        clip0 = np.isclose(x0, np.asarray(eff.lower, float))
        gains[name] = [[sc.gain(e, D, clip0)[0] for e in es] for sc in screens]
    return gains


def part_thresholds_of(gains: dict[str, list[list[float]]], margin: float = 1.25,
                       floor: float = 0.02) -> dict[str, list[float | None]]:
    """Per effect and recording, ``margin * max(null gains) + floor`` (None: not entered)."""
    return {n: [float(margin * max(*g, 0.0) + floor) if g else None for g in per]
            for n, per in gains.items()}


def thresholds_of(gains: dict[str, list[float]], margin: float = 1.25,
                  floor: float = 0.02) -> dict[str, float]:
    """``margin * max(null gains) + floor`` per effect."""
    return {n: float(margin * max(*v, 0.0) + floor) for n, v in gains.items()}
