import math, numpy as np
from bfr_control.controller import OrbitalController
from bfr_model.params import load_params
from bfr_model import contact as cm
from bfr_sim.closed_loop import orbit_initial_state
from bfr_tools.bench.sim import _row_params, _contact_loop, _restore, _DT
params = load_params()
p_row, bumps, desc = _row_params(params, 0.6)
ctrl = OrbitalController(params)
x0r = orbit_initial_state(ctrl, 0.3, d_theta=0.02)
model = cm.ContactModel(p_row)
run = _contact_loop(model, ctrl, x0r, 2.0)
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
a = np.mod(run["phi"] - lo + 0.02, math.pi)
sel = np.nonzero((a <= hi - lo + 0.04) & (run["gap"] < 1e-3))[0]
# fine sampling of gap inside the row: step with 20 us and record min over candidates
gaps=[]; vrel=[]
R = model.CP[cm.I_R]
for k in sel[::3]:
    _restore(model, run["snaps"][k]); x = run["x"][k].copy(); u = run["u"][k]
    for i in range(50):
        x = model.step(x, u, 2e-5)
        # min gap over candidates
        th = x[cm.ITH]; st, ct = math.sin(th), math.cos(th)
        cf = (ct*x[0]+st*x[1], -st*x[0]+ct*x[1])
        vr = np.array([x[cm.IVX] + x[cm.ITHD]*x[1], x[cm.IVY] - x[cm.ITHD]*x[0]])
        from bfr_model.closest_point import newton_closest
        g = 1.0
        for j in range(model.ncand[0]):
            phi, d, f, fp, it = newton_closest(cf[0], cf[1], model.cand[j], 20, 1e-14, model.CP[cm.I_MAXSTEP], *model._args, model.aidx, model.na[0])
            g = min(g, d - R)
        gaps.append(g); vrel.append(np.hypot(*vr))
gaps = np.array(gaps); vrel = np.array(vrel)
print("samples", gaps.size, "in contact", np.mean(gaps <= 0))
air = gaps > 0
tt = gaps[air] / vrel[air]
print("gap percentiles um", np.percentile(gaps[air]*1e6, [5, 25, 50, 75, 95]))
print("vrel median", np.median(vrel))
print("gap/vrel percentiles us", np.percentile(tt*1e6, [5, 25, 50, 75, 95]))
print("mean of min(gap/vrel, 250us) in us:", np.mean(np.minimum(tt, 250e-6))*1e6)
