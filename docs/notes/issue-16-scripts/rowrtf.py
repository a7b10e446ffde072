"""Bench's contact row figure, standalone: RTF on the row, whole run, smooth."""
import math, sys, time
import numpy as np
from bfr_control.controller import OrbitalController
from bfr_model.params import load_params
from bfr_model import contact as cm
from bfr_sim.closed_loop import orbit_initial_state
from bfr_tools.bench.sim import _row_params, _contact_loop, _DT

dur = float(sys.argv[1]) if len(sys.argv) > 1 else 2.0
reps = int(sys.argv[2]) if len(sys.argv) > 2 else 1
params = load_params()
p_row, bumps, desc = _row_params(params, 0.6)
ctrl = OrbitalController(params)
x0r = orbit_initial_state(ctrl, 0.3, d_theta=0.02)
lo, hi = float(np.min(bumps[: bumps.size // 2])), float(np.max(bumps[: bumps.size // 2]))
pad = 0.02
warm = cm.ContactModel(p_row); _contact_loop(warm, ctrl, x0r, 0.01)
for rep in range(reps):
    model = cm.ContactModel(p_row)
    c0 = time.process_time()
    run = _contact_loop(model, ctrl, x0r, dur)
    cpu = time.process_time() - c0
    a = np.mod(run["phi"] - lo + pad, math.pi)
    sel = (a <= hi - lo + 2 * pad) & (run["gap"] < 1e-3)
    rows = np.nonzero(sel)[0]
    print(f"row: {rows.size} steps, RTF {rows.size*_DT/np.sum(run['wall'][sel]):.3f}; whole {run['n']*_DT/np.sum(run['wall']):.3f}; "
          f"in contact {np.sum(sel & (run['gap']<=0))}; max gap {np.max(run['gap'])*1e3:.3f} mm; n={run['n']}; cpu {cpu:.1f}s")
    x = run["x"]
    print("final state", x[-1][:8], "slip", x[-1][cm.ISLIP])
