"""The ball's measured distance from the shaft against the nominal ball-centre curve.

The residual ``rho - |p(phi)|`` (camera fixes as logged, no sensor model, the contact angle
``phi`` of the nominal curve at the ball's angle in the frame) is split into what is fixed in
the frame (harmonics of the ball's angle in the frame, ``psi``) and what is fixed in the
camera (harmonics of its world angle, ``beta``). Run from the repository root (issue-12
note): ``python docs/notes/issue-12-scripts/ball_distance_frame_vs_world.py``.
"""

from __future__ import annotations

import numpy as np
from bfr_model.geometry import OffsetCurve
from bfr_model.io import read_runs
from bfr_model.params import load_params

LOGS = ("fin", "Actually_worked", "rolling_data")
ORDERS = 8


def harmonics(angles: list[np.ndarray], k_max: int = ORDERS) -> np.ndarray:
    """Columns 1, cos k a, sin k a (k = 1..k_max) for every angle array ``a``."""
    cols = [np.ones_like(angles[0])]
    for a in angles:
        for k in range(1, k_max + 1):
            cols += [np.cos(k * a), np.sin(k * a)]
    return np.column_stack(cols)


def explained(e: np.ndarray, angles: list[np.ndarray]) -> float:
    """Share of the variance of ``e`` that the harmonics of ``angles`` explain."""
    a = harmonics(angles)
    coef = np.linalg.lstsq(a, e, rcond=None)[0]
    return float(1.0 - np.var(e - a @ coef) / np.var(e))


def distances(name: str, curve: OffsetCurve) -> tuple[np.ndarray, ...]:
    """``(rho, beta, psi, e)`` of a log's new camera fixes (the longest run).

    ``rho`` the fix's distance from the shaft [m], ``beta`` its world angle (clockwise from
    +y), ``psi = theta + beta`` its angle in the frame, ``e = rho - |p(phi(psi))|`` [m].
    """
    run = max(read_runs(f"../shared/data/ntnu-rig/{name}.txt"), key=lambda r: r.n)
    ok = run.ball_valid.astype(bool) & np.asarray(run.new_fix_mask(), bool)
    x, y, theta = run.ball_x[ok], run.ball_y[ok], run.theta[ok]
    rho = np.hypot(x, y)
    beta = np.arctan2(x, y)
    psi = theta + beta
    e = rho - np.linalg.norm(curve.point(curve.phi_from_ball_angle(psi)), axis=-1)
    return rho, beta, psi, e


def main() -> None:
    """Print one line per log."""
    curve = OffsetCurve.from_params(load_params())
    for name in LOGS:
        _, beta, psi, e = distances(name, curve)
        print(f"{name:16s} n={e.size:5d} mean(rho-model)={e.mean() * 1e3:+.2f} mm "
              f"rms={e.std() * 1e3:.2f} mm | var explained: frame-fixed(psi) "
              f"{explained(e, [psi]):.2f}, world-fixed(beta) {explained(e, [beta]):.2f}, "
              f"both {explained(e, [psi, beta]):.2f}; beta range "
              f"{np.degrees(beta.min()):.0f}..{np.degrees(beta.max()):.0f} deg")


if __name__ == "__main__":
    main()
