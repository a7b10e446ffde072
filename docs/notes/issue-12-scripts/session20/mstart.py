"""Probe: stage fits of plate_distance from several starts (Actually_worked)."""
import sys, time
import numpy as np
from bfr_diagnose import identify, cli
from bfr_diagnose.effects import EFFECTS
_orig = identify._assess
done = set()
def _assess(prob, st, name, screened, full, crit):
    if name == "plate_distance" and st.index not in done:
        done.add(st.index)
        eff = EFFECTS[name]
        print("stage", st.index + 1, "screened", screened[0], "gain", screened[1],
              "stage cost_test", st.cost_test, flush=True)
        for d in [float(screened[0][0]), 20e-3, 15e-3, 12e-3, 10e-3, 8.8e-3, 7e-3]:
            for nfev in (20,):
                t = time.time()
                fit = prob.fit(st.chosen, eff, np.array([d]), st.sensors, max_nfev=nfev)
                gain, dbic = identify._stats(st, fit, eff.k)
                print(f"  start {d*1e3:5.1f} mm nfev {nfev}: d_f {fit.values[-1][0]*1e3:6.2f} mm"
                      f" gain {gain:.4f} dbic {dbic:.0f} cost_test {fit.cost_test:.4g}"
                      f" ({time.time()-t:.0f} s)", flush=True)
    return _orig(prob, st, name, screened, full, crit)
identify._assess = _assess
name = sys.argv[1]
rc = cli.main([f"../shared/data/ntnu-rig/{name}.txt", "--out-dir", f"/tmp/s20/{name}",
               "--force", "--no-plots"] + sys.argv[2:])
