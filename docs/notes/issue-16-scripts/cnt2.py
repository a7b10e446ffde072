import math, time, sys
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
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
_contact_loop(cm.ContactModel(p_row), ctrl, x0r, 0.01)
for margin in [float(v) for v in sys.argv[1:]]:
    out = []
    for r in range(2):
        m = cm.ContactModel(p_row, margin=margin)
        run = _contact_loop(m, ctrl, x0r, 2.0)
        a = np.mod(run["phi"] - lo + 0.02, math.pi)
        sel = (a <= hi - lo + 0.04) & (run["gap"] < 1e-3)
        out.append((sel.sum() * _DT / run["wall"][sel].sum(), m.sst[4] / 2000, m.sst[2] / 2000))
    o = np.array(out)
    print(f"M {margin:g}: row RTF (wall) {o[:,0].round(2)}, searches per ms {o[:,1].mean():.2f}, steps per ms {o[:,2].mean():.1f}")
