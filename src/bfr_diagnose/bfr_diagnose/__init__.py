"""``bfr diagnose``: locate, name, model and show the physics a nominal model leaves out.

Pure numpy/scipy core (no ``rclpy``). Pipeline (docs/diagnosis.md):

1. :mod:`~bfr_diagnose.preprocess` - resample onto a 2 ms grid, one anti-alias filter
   for the frame angle, the torque and the ball's angle, fuse a coarse encoder with the
   logged velocity, estimate the sensor noise, Savitzky-Golay smoothing; several runs of
   one log are stitched with unusable gaps.
2. :mod:`~bfr_diagnose.residual` - equation error of both rows of
   ``M q_ddot + c + G = Q`` in filtered-momentum form (a ``cos^4`` kernel; never diverges
   on the unstable system; the same filter on both sides of the equation).
3. :mod:`~bfr_diagnose.effects` - the library of 12 effects, each mapped onto
   :class:`bfr_model.params.RigParams` (the simulator's own code) or onto a camera correction
   (latency, origin offset); engineering floors and plausibility ranges.
4. :mod:`~bfr_diagnose.null` - the noise-only null by noise injection into the
   recording itself, plus the processing's own resolution.
5. :mod:`~bfr_diagnose.identify` - linearised screening, joint fits, held-out ranking,
   BIC, greedy selection of several effects, degenerate and confounded fits, intervals.
6. :mod:`~bfr_diagnose.locate` - windows and state regions where the residual exceeds
   the noise; short-horizon prediction and whiteness.
7. :mod:`~bfr_diagnose.report` and :mod:`~bfr_diagnose.cli` - outputs.
"""

from __future__ import annotations

__all__ = ["DiagnoseError"]


class DiagnoseError(ValueError):
    """Diagnosis cannot proceed; the message names the problem (bad input, no usable data)."""
