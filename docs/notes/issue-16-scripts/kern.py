"""Time the contact kernels at states on the bump row (closed-loop run snapshots)."""
import math, time
import numpy as np
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
run = _contact_loop(model, ctrl, x0r, 1.0)
lo, hi = float(np.min(bumps[:30])), float(np.max(bumps[:30]))
a = np.mod(run["phi"] - lo + 0.02, math.pi)
sel = np.nonzero((a <= hi - lo + 0.04) & (run["gap"] < 1e-3))[0]
print("row steps", sel.size)
ks = sel[::max(1, sel.size // 20)]
diag = np.zeros(cm.D_SIZE); dxv = np.empty(cm.NX)
tot = {"step1ms": 0.0, "full": 0.0, "resolve": 0.0, "eval": 0.0}
nc = []; nas = []
for k in ks:
    model.restore(run["snaps"][k]); X = run["x"][k].copy(); U = run["u"][k]
    t0 = time.perf_counter(); model.step(X, U, _DT); tot["step1ms"] += time.perf_counter() - t0
    model.restore(run["snaps"][k])
    cm.update_candidates(X.copy(), model.CP, model.cand, model.ncand, *model._args, model.aidx, model.na, diag, dxv, True)
    nc.append(model.ncand[0]); nas.append(model.na[0])
    reps = 50
    t0 = time.perf_counter()
    for _ in range(reps):
        cm.update_candidates(X.copy(), model.CP, model.cand, model.ncand, *model._args, model.aidx, model.na, diag, dxv, True)
    tot["full"] += (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    for _ in range(reps):
        cm.update_candidates(X.copy(), model.CP, model.cand, model.ncand, *model._args, model.aidx, model.na, diag, dxv, False)
    tot["resolve"] += (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    for _ in range(reps * 10):
        cm.contact_eval(X, U, model.CP, model.cand, int(model.ncand[0]), *model._args, model.aidx, int(model.na[0]), 2, diag, dxv)
    tot["eval"] += (time.perf_counter() - t0) / reps / 10
n = len(ks)
print(f"samples {n}; mean candidates {np.mean(nc):.2f}, mean local asperities {np.mean(nas):.1f}")
for kk, v in tot.items():
    print(f"  {kk:8s} {1e6 * v / n:9.1f} us")
s = tot["step1ms"] / n
print(f"1 ms call: {1e3*s:.2f} ms; 7 full searches {7e3*tot['full']/n:.2f} ms; 43 resolves {43e3*tot['resolve']/n:.2f} ms; 250 evals {250e3*tot['eval']/n:.2f} ms")
