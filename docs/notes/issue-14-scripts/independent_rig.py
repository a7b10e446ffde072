"""bfr diagnose and the PySINDy peer on logs of the independent rig (tests/independent/).

Truth that bfr did not make: another model structure (hybrid contact in the ball-centre
angle, Karnopp stick-slip), another controller (PFL on its own constraint with a speed
pump), another logger and sensor conventions (drawn per log). Each case conceals nothing
(clean) or one effect of log-uniform size in [0.1, 10] F (F of bfr_diagnose.limits.cases),
mapped onto the independent rig's own parameter; both tools run on the log as a user runs
them and are scored on the mechanisms they name (no parameter error: the rigs' parameters
are not defined alike).

    python docs/notes/issue-14-scripts/independent_rig.py --cases 16 --out runs/indep
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from bfr_diagnose.api import DiagnoseOptions, diagnose_recording
from bfr_diagnose.limits.cases import FLOOR
from bfr_diagnose.limits.peer import peer_diagnose
from bfr_diagnose.limits.stats import wilson
from bfr_model.io.rig_log import parse_rig_log
from bfr_model.params import load_params

# bfr effect -> the independent rig's parameter(s) for a size s (signs drawn)
EFFECTS = {
    "joint_coulomb_friction": lambda s, g: {"coulomb_pos": s, "coulomb_neg": s},
    "joint_viscous_friction": lambda s, g: {"viscous": s},
    "torque_offset": lambda s, g: {"torque_offset": g * s},
    "torque_gain": lambda s, g: {"motor_gain": 1.0 + g * s},
    "frame_inertia": lambda s, g: {"frame_inertia_scale": 1.0 + g * s},
    "frame_imbalance": lambda s, g: {"imbalance": s, "imbalance_angle": 1.0 + g},
    "rolling_resistance": lambda s, g: {"rolling_resistance": s},
    "ball_mass": lambda s, g: {"ball_mass": 3.0e-3 * (1.0 + g * s)},
    "ball_inertia": lambda s, g: {"ball_inertia_factor": 2.0 / 3.0 * (1.0 + g * s)},
    "plate_distance": lambda s, g: {"plate_gap": 25.5e-3 + g * s},
    "frame_contour": lambda s, g: {"contour_b": 0.04 + g * s},
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=16)
    ap.add_argument("--seed", type=int, default=14)
    ap.add_argument("--out", default="runs/indep")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = load_params()
    names = list(EFFECTS)
    rows = []
    for i in range(args.cases):
        path = out / f"case_{i:03d}.json"
        if path.is_file():
            rows.append(json.loads(path.read_text()))
            continue
        rng = np.random.default_rng([args.seed, i])
        eff = None if i % 4 == 0 else names[int(rng.integers(len(names)))]
        size = float(FLOOR[eff] * 10 ** rng.uniform(-1, 1)) if eff else 0.0
        sign = 1.0 if rng.random() < 0.5 else -1.0
        changes = EFFECTS[eff](size, sign) if eff else {}
        log = out / f"case_{i:03d}.txt"
        cmd = [sys.executable, "-m", "tests.independent.rig_log", "one", "--out", str(log),
               "--kind", "rolling", "--duration", "10", "--seed", str(1000 + i),
               "--drawn-sensors", *(f"--effect={k}={v!r}" for k, v in changes.items())]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        rl = parse_rig_log(log, warn=False)
        runs = [rl.recording(k) for k in range(len(rl.runs))]
        t1 = time.perf_counter()
        d = diagnose_recording(runs, base, DiagnoseOptions())
        t2 = time.perf_counter()
        p = peer_diagnose(d, base)
        row = {"index": i, "effect": eff, "size": size, "x": math.log10(size / FLOOR[eff])
               if eff else None, "changes": changes, "bfr_found": list(d.summary["effects"]),
               "peer_found": p.found, "t_gen": t1 - t0, "t_bfr": t2 - t1,
               "t_peer": time.perf_counter() - t2}
        path.write_text(json.dumps(row))
        rows.append(row)
        print(json.dumps(row), flush=True)
    for tool in ("bfr", "peer"):
        clean = [r for r in rows if not r["effect"]]
        eff = [r for r in rows if r["effect"]]
        fp = sum(bool(r[f"{tool}_found"]) for r in clean)
        hit = sum(r["effect"] in r[f"{tool}_found"] for r in eff)
        exact = sum(set(r[f"{tool}_found"]) == ({r["effect"]} if r["effect"] else set())
                    for r in rows)
        lo, hi = wilson(fp, len(clean))
        print(f"{tool}: false positives {fp}/{len(clean)} (Wilson [{lo:.2f}, {hi:.2f}]), "
              f"concealed effect found {hit}/{len(eff)}, exact set {exact}/{len(rows)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
