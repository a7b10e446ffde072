"""Probe: stage-1 fit of plate_distance from 8.8 mm with the R=16 world's sensors."""
import sys, time
import numpy as np
from bfr_diagnose import identify, cli
from bfr_diagnose.effects import EFFECTS
_orig = identify._assess
done = set()
R16 = {'latency': 0.01783, 'offset_x': 0.0111, 'offset_y': -0.00734, 'rotation': 0.05637,
       'scale': 1.06449, 'theta_zero': -0.0493, 'torque_delay': 0.00358}
def _assess(prob, st, name, screened, full, crit):
    if name == "plate_distance" and st.index not in done and st.index == 0:
        done.add(st.index)
        eff = EFFECTS[name]
        names = prob.parts[0].sensor_names
        print("sensor names", names, "stage sensors", st.sensors[0], flush=True)
        s16 = np.array([R16.get(n, v) for n, v in zip(names, st.sensors[0])])
        for d, sens, lab in [(17.27e-3, st.sensors, "nominal-world sensors"),
                             (8.8e-3, [s16], "R16 sensors"), (10e-3, [s16], "R16 sensors")]:
            for nfev in (20, 60):
                t = time.time()
                fit = prob.fit(st.chosen, eff, np.array([d]), sens, max_nfev=nfev)
                gain, dbic = identify._stats(st, fit, eff.k)
                print(f"  {lab} start {d*1e3:5.1f} nfev {nfev}: d_f {fit.values[-1][0]*1e3:6.2f} mm"
                      f" gain {gain:.4f} dbic {dbic:.0f} cost_test {fit.cost_test:.4g} "
                      f"sens {np.round(fit.sensors[0], 4)} ({time.time()-t:.0f} s)", flush=True)
            # cost at fixed values, no fit
            ch = [*st.chosen, (eff, np.array([d]))]
            c_tr, c_te, _ = prob.cost(ch, sens)
            print(f"  fixed {d*1e3:.2f} {lab}: cost_train {c_tr:.4g} cost_test {c_te:.4g}", flush=True)
        sys.exit(0)
    return _orig(prob, st, name, screened, full, crit)
identify._assess = _assess
rc = cli.main(["../shared/data/ntnu-rig/Actually_worked.txt", "--out-dir", "/tmp/s20/b",
               "--force", "--no-plots"])
