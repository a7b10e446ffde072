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
run = _contact_loop(cm.ContactModel(p_row), ctrl, x0r, 1.5)
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
a = np.mod(run["phi"] - lo + 0.02, math.pi)
sel = np.nonzero((a <= hi - lo + 0.04) & (run["gap"] < 1e-3))[0]
for margin in [float(v) for v in sys.argv[1:]] or [2e-4]:
    m = cm.ContactModel(p_row, margin=margin)
    st = se = 0; cpu = []
    for r in range(5):
        t = time.process_time()
        for k in sel:
            m.restore(run["snaps"][k]); s0, q0 = m.sst[2], m.sst[4]
            m.step(run["x"][k], run["u"][k], _DT)
            if r == 0: st += m.sst[2] - s0; se += m.sst[4] - q0
        cpu.append((time.process_time() - t) / sel.size)
    print(f"M {margin:g}: per 1 ms: steps {st/sel.size:.1f}, searches {se/sel.size:.2f}; CPU {1e6*np.median(cpu):.0f} us (RTF {1e-3/np.median(cpu):.2f})")
