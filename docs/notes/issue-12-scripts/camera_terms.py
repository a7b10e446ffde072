"""Which camera-fixed term the ball's distances support, beyond the frame-fixed contour.

The residual ``e = rho - |p(phi)|`` of the raw camera fixes against the nominal ball-centre
curve (as ``ball_distance_frame_vs_world.py``) is fitted by the frame-fixed harmonics of the
ball's angle in the frame (``psi``, k <= 8) plus what the sensor model already has (an
offset: ``cos beta``, ``sin beta``; a scale: ``rho``); then each candidate camera term is
added alone and the share of the remaining variance it explains is printed:

- radial (k1, a lens's barrel or pincushion about the shaft's image): ``rho^3``;
- tilt (the image plane not parallel to the frame: a perspective scale that grows across the
  image): ``rho^2 cos beta``, ``rho^2 sin beta``;
- aspect (pixels not square, or a shear): ``rho cos 2 beta``, ``rho sin 2 beta``.

Run from the repository root: ``python docs/notes/issue-12-scripts/camera_terms.py``.
"""

from __future__ import annotations

import numpy as np
from ball_distance_frame_vs_world import distances  # this folder's other script
from bfr_model.geometry import OffsetCurve
from bfr_model.params import load_params

LOGS = ("fin", "Actually_worked", "rolling_data")


def _fit_rest(a: np.ndarray, e: np.ndarray) -> np.ndarray:
    return e - a @ np.linalg.lstsq(a, e, rcond=None)[0]


def main() -> None:
    """Print one line per log."""
    curve = OffsetCurve.from_params(load_params())
    for name in LOGS:
        rho, beta, psi, e = distances(name, curve)
        r = rho / 0.1
        cols = [np.ones_like(e), np.cos(beta), np.sin(beta), r]
        for k in range(1, 9):
            cols += [np.cos(k * psi), np.sin(k * psi)]
        base = np.column_stack(cols)
        rest = _fit_rest(base, e)
        terms = {"radial k1": [r ** 3], "tilt": [r ** 2 * np.cos(beta), r ** 2 * np.sin(beta)],
                 "aspect": [r * np.cos(2 * beta), r * np.sin(2 * beta)]}
        out = []
        for label, extra in terms.items():
            r2 = _fit_rest(np.column_stack([base, *extra]), e)
            out.append(f"{label} {1.0 - np.var(r2) / np.var(rest):.3f}")
        print(f"{name:16s} rms after contour+offset+scale {rest.std() * 1e3:.3f} mm "
              f"(of {e.std() * 1e3:.2f}); rho {rho.min() * 1e3:.0f}..{rho.max() * 1e3:.0f} mm, "
              f"beta {np.degrees(beta.min()):.0f}..{np.degrees(beta.max()):.0f} deg | "
              "share of the rest explained: " + ", ".join(out))


if __name__ == "__main__":
    main()
