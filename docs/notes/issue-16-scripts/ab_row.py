"""A/B CPU per 1 ms call on the row intervals and smooth: variant A (shipped) vs B (5 inline sites)."""
import math, time, sys, importlib.util
import numpy as np
sys.path.insert(0, "/tmp/p16/var/vb")
import contact_a, contact_b
from bfr_control.controller import OrbitalController
from bfr_model.params import load_params
from bfr_sim.closed_loop import orbit_initial_state
from bfr_tools.bench.sim import _row_params, _contact_loop, _DT
params = load_params()
p_row, bumps, desc = _row_params(params, 0.6)
ctrl = OrbitalController(params)
x0r = orbit_initial_state(ctrl, 0.3, d_theta=0.02)
run = _contact_loop(contact_a.ContactModel(p_row), ctrl, x0r, 1.5)
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
a = np.mod(run["phi"] - lo + 0.02, math.pi)
sel = np.nonzero((a <= hi - lo + 0.04) & (run["gap"] < 1e-3))[0]
models = {"A": contact_a.ContactModel(p_row), "B": contact_b.ContactModel(p_row)}
def T(m):
    t = time.process_time()
    for k in sel:
        m.restore(run["snaps"][k]); m.step(run["x"][k], run["u"][k], _DT)
    return (time.process_time() - t) / sel.size
for m in models.values(): T(m)
res = {k: [] for k in models}
for r in range(7):
    for k, m in models.items(): res[k].append(T(m))
for k, v in res.items(): print(k, "row CPU per call", 1e6*np.median(v), "us RTF", 1e-3/np.median(v))
