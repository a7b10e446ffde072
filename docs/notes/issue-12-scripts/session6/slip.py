import pickle, sys, time
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
from bfr_model.contact import ContactModel
name = sys.argv[1]; mus = [float(v) for v in sys.argv[2].split(",")]; every = int(sys.argv[3]) if len(sys.argv) > 3 else 50
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
params, res, sensor = d.selection.params, pr.res_after, pr.sensor
model = RigidModel(params)
psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
ok = prep.ball_ok
cms = {}
for mu in mus:
    p2 = params.replace(**{"contact.static_friction": mu*1.2, "contact.dynamic_friction": mu})
    cms[mu] = ContactModel(p2)
out = {k: [] for k in ["rigid", *mus]}; phs = []; slips = {mu: [] for mu in mus}
t0 = time.time()
for i0 in range(nw, prep.n-nh-1, every):
    if not ok[i0-nw:i0+nh+1].all(): continue
    j = i0-nw
    if not (np.isfinite(res.phi[j]) and np.isfinite(res.phi_dot[j])): continue
    def sim(z, n_end, j0):
        x = np.array([*z, 0, 0.]); xs=[x[:4]]
        for k in range(n_end):
            x = model.step(x, u[j0+k], dt, 1); xs.append(x[:4])
        return np.array(xs)
    def resid(z):
        xs = sim(z, nw, j)
        if not np.all(np.isfinite(xs)): return np.full(2*(nw+1), 1.0)
        return np.concatenate([model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[j:i0+1], xs[:,0]-theta[j:i0+1]])
    z0 = np.array([theta[j], res.phi[j], prep.theta_dot[j], res.phi_dot[j]])
    sol = least_squares(resid, z0, x_scale=[1e-3,1e-3,0.1,0.1], method="lm")
    xs = sim(sol.x, nw+nh, j)
    zi = xs[nw]  # fitted state at i0
    e = model.curve.ball_angle(xs[nw:,1]) - xs[nw:,0] - psi_w[i0:i0+nh+1]
    out["rigid"].append(e[1:]); phs.append(np.degrees(np.mod(zi[1], np.pi)))
    for mu, cm in cms.items():
        cm.reset(cm.state_from_rigid(zi, u[i0]))
        x = cm.state_from_rigid(zi, u[i0])
        cm.reset(x)
        rs = []
        s0 = x[[i for i in range(len(x))]][0]
        for k in range(nh):
            x = cm.step(x, u[i0+k], dt, 1)
            rs.append(x)
        rs = np.array(rs)
        rr = cm.rigid_state(rs, zi[1])
        ew = model.curve.ball_angle(rr[:,1]) - rr[:,0] - psi_w[i0+1:i0+nh+1]
        # world angle directly from ball centre
        ang = np.arctan2(rs[:,1], rs[:,0])
        out[mu].append(ew)
print("windows", len(phs), "time", time.time()-t0)
phs = np.array(phs)
r = lambda E: np.sqrt(np.mean(np.array(E)**2))
print("all", {k: round(r(v),5) for k,v in out.items()})
for b in range(0,180,30):
    s = (phs>=b)&(phs<b+30)
    if s.any(): print(b, s.sum(), {k: round(r(np.array(v)[s]),5) for k,v in out.items()})
