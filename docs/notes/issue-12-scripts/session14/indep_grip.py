"""The independent rig (tests/independent): clean rolling logs, their effects and grip verdict.

Usage from the repository root (scripts/env.sh, the source tree on PYTHONPATH):

    python docs/notes/issue-12-scripts/session14/indep_grip.py 0 8     # seeds 0..7
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, "tests")
from bfr_diagnose.api import diagnose_recordings
from bfr_model.io.rig_log import parse_rig_log
from bfr_model.params import load_params
from independent import physics, rig_log

for seed in range(int(sys.argv[1]), int(sys.argv[2])):
    rng = np.random.default_rng(seed)
    conv = rig_log.draw_conventions(rng)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"rig{seed}.txt"
        rig_log.write_log(path, physics.RigParams(), conv,
                          [rig_log.RunSpec(kind="rolling", duration=12.0)], seed)
        log = parse_rig_log(path, warn=False)
        runs = [log.recording(k) for k in range(len(log.runs))]
        s = diagnose_recordings([(path.name, runs)], load_params()).summary
    g = s["grip"]
    st = g.get("slip_test", {})
    print(seed, "effects", s["effects"], "grip", g["verdict"], "mu", st.get("mu"),
          "demand max", round(g["friction_demand"].get("max", float("nan")), 3),
          "held-out windows better / worse", st.get("windows_better"), st.get("windows_worse"),
          flush=True)
