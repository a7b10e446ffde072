"""Probe: the frame-held run's ball oscillation against the rigid model (closed form)."""
import numpy as np
from bfr_model.io.rig_log import read_rig_log
from bfr_model.params import load_params
from bfr_diagnose.preprocess import plan_parts
runs = read_rig_log("../shared/data/ntnu-rig/rolling_data.txt", run=None)
runs = runs if isinstance(runs, list) else [runs]
parts, notes = plan_parts(runs)
kind, pieces, p = parts[0]
print(kind, p.t.size, p.t[0], p.t[-1], "theta", np.nanmean(p.theta))
ok = p.ball_ok
t = p.t[ok]; psi = p.psi_w[ok]; rho = p.rho[ok]
print("psi range", np.degrees(np.nanmin(psi)), np.degrees(np.nanmax(psi)), "rho", np.nanmin(rho), np.nanmax(rho))
np.savez("/tmp/s20/held.npz", t=t, psi=psi, rho=rho, theta=p.theta[ok], xy=p.ball_xy[:, ok])
# crude: zero crossings of psi - mean
x = psi - np.median(psi[-2000:])
z = np.where(np.diff(np.sign(x)) != 0)[0]
print("n crossings", z.size)
per = 2 * np.diff(t[z])
for i in range(0, z.size - 1, max(1, z.size // 25)):
    j = z[i]; k = z[min(i + 2, z.size - 1)]
    print(f"t {t[j]:6.2f} half-period {t[z[i+1]]-t[j]:.3f} s amp {np.degrees(np.max(np.abs(x[j:k]))):6.2f} deg rho {np.mean(rho[j:k])*1e3:.2f} mm")
