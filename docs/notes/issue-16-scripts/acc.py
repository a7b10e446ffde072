"""Per-interval accuracy on the row: event-based vs exhaustive vs fine exhaustive (h/10)."""
import math, sys, time
import numpy as np
from bfr_control.controller import OrbitalController
from bfr_model.params import load_params
from bfr_model import contact as cm
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
ev = cm.ContactModel(p_row)
ex = cm.ContactModel(p_row, exhaustive=True)
fine = cm.ContactModel(p_row, time_step=2e-6, exhaustive=True)
vel = [cm.IVX, cm.IVY, cm.IOM]
e_ev, e_ex, e_evex = [], [], []
for k in sel:
    X, U = run["x"][k], run["u"][k]
    out = []
    for m in (ev, ex, fine):
        m.restore(run["snaps"][k])
        out.append(m.step(X, U, _DT))
    e_ev.append(np.max(np.abs(out[0][[4,5]] - out[2][[4,5]])))
    e_ex.append(np.max(np.abs(out[1][[4,5]] - out[2][[4,5]])))
    e_evex.append(np.max(np.abs(out[0][[4,5]] - out[1][[4,5]])))
for name, e in (("event vs fine", e_ev), ("exhaustive vs fine", e_ex), ("event vs exhaustive", e_evex)):
    e = np.array(e)
    print(f"{name:22s} velocity error after 1 ms [m/s]: median {np.median(e):.2e}, p90 {np.percentile(e,90):.2e}, max {e.max():.2e}  (n={e.size})")
