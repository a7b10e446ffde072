"""The peer: PySINDy's sparse regression of the nominal model's residual on physical terms.

Set up as a system-identification user of PySINDy would, everything fixed before any case
was run (this module is the whole setup; docs/diagnosis.md repeats it):

1. **Data.** The peer starts from what bfr's preprocessing gives (the same smoothed signals,
   the same sensor model fitted with the nominal physics, stage 0 of the diagnosis), so it
   sees the same clean data bfr does: this favours the peer, never bfr. The targets are the
   nominal model's equation errors in filtered-momentum form (:mod:`bfr_diagnose.residual`:
   ``r1`` frame torque [N m], ``r2`` ball row [N m], ``r3`` ball distance [m]), the
   features the same kernel ``k`` applied to each library term (``D`` marks the kernel's
   derivative ``k'``, i.e. the term's time derivative), at the same samples.
2. **Library** (:data:`LIBRARY`, per row; ``th`` the frame angle, ``w`` its rate, ``u`` the
   torque command, ``psi`` the ball centre's angle on the frame, ``psi_w`` in the world,
   ``v`` its rate; ``tanh`` with the nominal model's smoothing speeds):

   - row 1: ``1, tanh(w/v_c), w, D w, u, sin th, cos th, sin psi_w``;
   - row 2: ``1, tanh(v/v_r), v, D v, D w, sin psi_w, cos k psi, sin k psi (k = 1..8)``;
   - row 3: ``1, cos k psi, sin k psi (k = 1..8)``.

3. **Sparse regression**: :class:`pysindy.STLSQ` (sequentially thresholded least squares,
   ridge ``alpha = 1e-6``, unbiased refit) on columns and target scaled to unit RMS. The
   threshold is chosen by **held-out error**: 5 contiguous blocks, 5-fold cross-validation
   over 12 thresholds ``1e-3 .. 1`` (log-spaced), the largest threshold whose held-out MSE
   is within one standard error of the best (the one-standard-error rule), then a fit on
   all samples with it.
4. **Mapping** of terms to mechanisms (:data:`MAPPING`), fixed in advance; an intercept of
   rows 1-2 maps to nothing but row 1's (the drive's offset). Track bumps have no term (a
   global library holds no localised bump): the peer cannot name them.
5. **Parameters** where a term's coefficient is the parameter's change (row 1's scalar
   terms: ``tau_0 = beta_1``, ``T_c = -beta_tanh``, ``c_v = -beta_w``, ``J_f = J_f0 -
   beta_Dw``, ``k_u = k_u0 + beta_u``); no parameter otherwise (NaN).

The mechanisms found are ordered by their largest scaled coefficient (the peer's top-1).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from bfr_model.params import RigParams
from numpy.typing import NDArray

from bfr_diagnose.api import Diagnosis, PartResult
from bfr_diagnose.residual import ResidualConfig, ResidualEvaluator

__all__ = ["LIBRARY", "MAPPING", "PeerResult", "peer_diagnose", "sparse_fit"]

FloatArray = NDArray[np.float64]
_K = tuple(range(1, 9))
LIBRARY: dict[int, tuple[str, ...]] = {
    1: ("1", "tanh(w/v_c)", "w", "D w", "u", "sin th", "cos th", "sin psi_w"),
    2: ("1", "tanh(v/v_r)", "v", "D v", "D w", "sin psi_w",
        *(f"{f} {k} psi" for k in _K for f in ("cos", "sin"))),
    3: ("1", *(f"{f} {k} psi" for k in _K for f in ("cos", "sin"))),
}
_SHAPE = {f"{f} {k} psi": "frame_shape" for k in _K if k != 2 for f in ("cos", "sin")}
_CONTOUR = {"cos 2 psi": "frame_contour", "sin 2 psi": "frame_contour"}
#: (row, term) -> mechanism, fixed in advance (module docstring, step 4); None: no mechanism.
MAPPING: dict[tuple[int, str], str | None] = {
    (1, "1"): "torque_offset", (1, "tanh(w/v_c)"): "joint_coulomb_friction",
    (1, "w"): "joint_viscous_friction", (1, "D w"): "frame_inertia", (1, "u"): "torque_gain",
    (1, "sin th"): "frame_imbalance", (1, "cos th"): "frame_imbalance",
    (1, "sin psi_w"): "ball_mass",
    (2, "1"): None, (2, "tanh(v/v_r)"): "rolling_resistance", (2, "v"): "rolling_resistance",
    (2, "D v"): "ball_inertia", (2, "D w"): "ball_inertia", (2, "sin psi_w"): "ball_mass",
    **{(2, t): m for t, m in {**_SHAPE, **_CONTOUR}.items()},
    (3, "1"): "plate_distance", **{(3, t): m for t, m in {**_SHAPE, **_CONTOUR}.items()},
}
THRESHOLDS = np.logspace(-3.0, 0.0, 12)
N_BLOCKS = 5
RIDGE = 1e-6


@dataclass(frozen=True, kw_only=True)
class PeerResult:
    """The peer's answer on one case.

    Attributes
    ----------
    found : list of str
        Mechanisms named, strongest first.
    parameters : dict
        Estimated parameter value per mechanism where the mapping gives one.
    terms : dict
        Surviving terms per row with their coefficients (natural units).
    thresholds : dict
        Chosen threshold per row.
    """

    found: list[str]
    parameters: dict[str, float] = field(default_factory=dict)
    terms: dict[int, dict[str, float]] = field(default_factory=dict)
    thresholds: dict[int, float] = field(default_factory=dict)


def sparse_fit(X: FloatArray, y: FloatArray, thresholds: FloatArray = THRESHOLDS,
               n_blocks: int = N_BLOCKS) -> tuple[FloatArray, float]:
    """STLSQ with the threshold chosen by blocked cross-validation (one-SE rule).

    Columns and target are scaled to unit RMS; the threshold acts on scaled coefficients.

    Returns
    -------
    coef : ndarray
        Coefficients of the unscaled columns (natural units).
    threshold : float
        The threshold chosen.
    """
    import pysindy as ps  # noqa: PLC0415 - optional heavy dependency (scikit-learn)

    cs = np.sqrt(np.mean(X * X, axis=0))
    cs[cs == 0.0] = 1.0
    ys = float(np.sqrt(np.mean(y * y))) or 1.0
    Xs, yt = X / cs, y / ys
    blocks = np.minimum((np.arange(y.size) * n_blocks) // y.size, n_blocks - 1)

    def fit(A: FloatArray, b: FloatArray, lam: float) -> FloatArray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt = ps.STLSQ(threshold=float(lam), alpha=RIDGE, unbias=True)
            opt.fit(A, b)
        return np.asarray(opt.coef_, float).ravel()

    mse = np.empty((thresholds.size, n_blocks))
    for b in range(n_blocks):
        tr, te = blocks != b, blocks == b
        for i, lam in enumerate(thresholds):
            c = fit(Xs[tr], yt[tr], lam)
            mse[i, b] = float(np.mean((yt[te] - Xs[te] @ c) ** 2))
    mean = mse.mean(axis=1)
    best = int(np.argmin(mean))
    se = float(mse[best].std(ddof=1) / np.sqrt(n_blocks))
    ok = np.nonzero(mean <= mean[best] + se)[0]
    lam = float(thresholds[int(ok.max())])
    return fit(Xs, yt, lam) * ys / cs, lam


def _filtered(ev: ResidualEvaluator, x: FloatArray, derivative: bool) -> FloatArray:
    """The residual's kernel (or its derivative) applied to a grid signal, at its samples."""
    q = max(int(ev.cfg.quad_step), 1)
    xs = np.nan_to_num(x[::q], nan=0.0)
    kern = ev.kd if derivative else ev.k
    return np.convolve(xs, kern, mode="valid")[ev.idx // q - ev.J]


def _features(pr: PartResult, base: RigParams, cfg: ResidualConfig
              ) -> dict[int, tuple[FloatArray, FloatArray]]:
    """Per row: (feature matrix, target) at the residual's samples (finite rows only)."""
    prep, s = pr.prep, pr.sensor0
    ev = ResidualEvaluator(prep, cfg)
    res = pr.res_before
    if ev.idx.size != res.idx.size or np.any(ev.idx != res.idx):
        raise ValueError("peer: the residual's samples differ from the evaluator's")
    th = prep.theta + s.theta_zero
    w = prep.theta_dot
    u = prep.u_for(s)
    psi_w, v_w, _ = prep.ball_for(s)
    psi = th + psi_w
    v = w + v_w
    vc = base.joint.coulomb_smoothing
    vr = base.track.rolling_smoothing
    one = np.ones(prep.n)
    point = {"1": one, "tanh(w/v_c)": np.tanh(w / vc), "w": w, "u": u, "sin th": np.sin(th),
             "cos th": np.cos(th), "sin psi_w": np.sin(psi_w), "tanh(v/v_r)": np.tanh(v / vr),
             "v": v}
    for k in _K:
        point[f"cos {k} psi"] = np.cos(k * psi)
        point[f"sin {k} psi"] = np.sin(k * psi)
    deriv = {"D w": w, "D v": v}
    out = {}
    for row, target in ((1, res.r1), (2, res.r2), (3, res.r3)):
        cols = [(_filtered(ev, deriv[t], True) if t in deriv else _filtered(ev, point[t], False))
                for t in LIBRARY[row]]
        X = np.column_stack(cols)
        ok = np.isfinite(target) & np.all(np.isfinite(X), axis=1)
        if prep.has_ball or row == 1:
            out[row] = (X[ok], np.asarray(target)[ok])
    return out


def peer_diagnose(d: Diagnosis, base: RigParams, min_samples: int = 64) -> PeerResult:
    """The peer on the recordings bfr diagnosed in ``d`` (module docstring)."""
    cfg = ResidualConfig()
    rows: dict[int, list[tuple[FloatArray, FloatArray]]] = {1: [], 2: [], 3: []}
    for pr in d.parts:
        if pr.kind != "rolling":
            continue
        for row, xy in _features(pr, base, cfg).items():
            rows[row].append(xy)
    strength: dict[str, float] = {}
    terms: dict[int, dict[str, float]] = {}
    lams: dict[int, float] = {}
    params: dict[str, float] = {}
    for row, pieces in rows.items():
        if not pieces:
            continue
        X = np.vstack([p[0] for p in pieces])
        y = np.concatenate([p[1] for p in pieces])
        if y.size < min_samples:
            continue
        coef, lams[row] = sparse_fit(X, y)
        scale = np.sqrt(np.mean(X * X, axis=0)) / (float(np.sqrt(np.mean(y * y))) or 1.0)
        terms[row] = {}
        for name, c, sc in zip(LIBRARY[row], coef, scale, strict=True):
            if c == 0.0:
                continue
            terms[row][name] = float(c)
            mech = MAPPING[(row, name)]
            if mech is not None:
                strength[mech] = max(strength.get(mech, 0.0), abs(c) * sc)
    t1 = terms.get(1, {})
    nominal = {"torque_offset": base.actuator.torque_offset,
               "joint_coulomb_friction": base.joint.coulomb_friction,
               "joint_viscous_friction": base.joint.viscous_friction,
               "frame_inertia": base.frame.inertia, "torque_gain": base.actuator.torque_gain}
    sign = {"torque_offset": ("1", 1.0), "joint_coulomb_friction": ("tanh(w/v_c)", -1.0),
            "joint_viscous_friction": ("w", -1.0), "frame_inertia": ("D w", -1.0),
            "torque_gain": ("u", 1.0)}
    for mech, (term, sg) in sign.items():
        if term in t1:
            params[mech] = nominal[mech] + sg * t1[term]
    found = sorted(strength, key=lambda m: -strength[m])
    return PeerResult(found=found, parameters=params, terms=terms, thresholds=lams)


def peer_summary(p: PeerResult) -> dict[str, Any]:
    """JSON-ready form of a :class:`PeerResult`."""
    return {"found": p.found, "parameters": p.parameters,
            "terms": {str(k): v for k, v in p.terms.items()},
            "thresholds": {str(k): v for k, v in p.thresholds.items()}}
