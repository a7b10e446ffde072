"""Diagnose a rolling log of the independent rig (tests/independent), printing what was found.

Usage (in the workspace environment, from any folder; the log is written there)::

    python docs/notes/issue-12-scripts/independent_rig.py SEED [NAME=VALUE ...]

SEED draws the rig's sensor conventions (``rig_log.draw_conventions``); NAME=VALUE are
``physics.RigParams`` fields of the independent rig (e.g. ``contour_radius_delta=0.0015``,
``coulomb_pos=0.003 coulomb_neg=0.0045``). The body of
tests/test_diagnose_independent.py with printing (docs/notes/issue-12.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tests"))
from bfr_diagnose.api import diagnose_recordings
from bfr_model.io.rig_log import parse_rig_log
from bfr_model.params import load_params
from independent import physics, rig_log


def main() -> int:
    """Write the log, diagnose it, print the findings and the sensor model."""
    seed = int(sys.argv[1])
    effects = sys.argv[2:]
    rng = np.random.default_rng(seed)
    conv = rig_log.draw_conventions(rng)
    changes = {k: float(v) for k, v in (e.split("=") for e in effects)}
    path = Path(f"s{seed}_{'_'.join(effects) or 'clean'}.txt")
    t0 = time.time()
    rig_log.write_log(path, physics.RigParams(**changes), conv,
                      [rig_log.RunSpec(kind="rolling", duration=12.0)], seed)
    t1 = time.time()
    log = parse_rig_log(path, warn=False)
    runs = [log.recording(k) for k in range(len(log.runs))]
    out = diagnose_recordings([(path.name, runs)], load_params()).to_json()
    t2 = time.time()
    print(path.name, f"gen {t1 - t0:.1f}s diag {t2 - t1:.1f}s", "effects", out["effects"],
          "selected", out["effects_selected"], "suspects", out["suspects"])
    print("sensors", conv.velocity_mode, conv.velocity_lag, conv.line_rate, conv.camera_rate,
          conv.camera_latency, conv.torque_shift)
    for p in out["parameters"]:
        print("  ", p["effect"], p["name"], p["value"], p["ci95"])
    for s in out["sensor_timing"]:
        print("  S", s["name"], s["value"], s["ci95"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
