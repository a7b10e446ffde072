import math, time, sys
import numpy as np
from bfr_control.controller import OrbitalController
from bfr_model.params import load_params
from bfr_model import contact as cm
from bfr_model.layout import I_HFLY
from bfr_sim.closed_loop import orbit_initial_state
from bfr_tools.bench.sim import _row_params, _contact_loop, _DT
params = load_params()
p_row, bumps, desc = _row_params(params, 0.6)
ctrl = OrbitalController(params)
x0r = orbit_initial_state(ctrl, 0.3, d_theta=0.02)
model = cm.ContactModel(p_row)
run = _contact_loop(model, ctrl, x0r, 1.5)
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
a = np.mod(run["phi"] - lo + 0.02, math.pi)
sel = np.nonzero((a <= hi - lo + 0.04) & (run["gap"] < 1e-3))[0]
smooth_k = np.nonzero(~((a <= hi - lo + 0.04)))[0][:200]
def timeit(m, ks, reps=5):
    best = []
    for r in range(reps):
        t = 0.0
        for k in ks:
            m.restore(run["snaps"][k])
            t0 = time.perf_counter(); m.step(run["x"][k], run["u"][k], _DT); t += time.perf_counter() - t0
        best.append(t / len(ks))
    return np.median(best)
ev = cm.ContactModel(p_row)
nofly = cm.ContactModel(p_row); nofly.CP[I_HFLY] = 0.0
ex = cm.ContactModel(p_row, exhaustive=True)
timeit(ev, sel[:3], 1); timeit(nofly, sel[:3], 1); timeit(ex, sel[:3], 1)
for name, m in (("event+flight", ev), ("event, no flight", nofly), ("exhaustive", ex)):
    t_row = timeit(m, sel); t_off = timeit(m, smooth_k)
    print(f"{name:18s} per 1 ms call: on the row {1e6*t_row:8.1f} us (RTF {1e-3/t_row:6.2f}), off the row {1e6*t_off:7.1f} us (RTF {1e-3/t_off:6.2f})")
