import pickle, sys
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]; every = int(sys.argv[2]); which = sys.argv[3] if len(sys.argv) > 3 else "after"
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
if which == "after":
    params, res, sensor = d.selection.params, pr.res_after, pr.sensor
else:
    params, res, sensor = d.base, pr.res_before, pr.sensor0
model = RigidModel(params)
psi_w0, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
xy = prep.ball_xy[:2].T.copy()
print("xy range", np.nanmin(xy,0), np.nanmax(xy,0))
pd = np.gradient(psi_w0, dt)
xc = xy[:,0] - np.nanmean(xy[:,0]); yc = xy[:,1] - np.nanmean(xy[:,1])
ok = prep.ball_ok & np.isfinite(xc) & np.isfinite(yc)
starts = [i0 for i0 in range(nw, prep.n-nh-1, every) if ok[i0-nw:i0+nh+1].all() and np.isfinite(res.phi[i0-nw]) and np.isfinite(res.phi_dot[i0-nw])]
def score(Lx, Ly):
    psi_w = psi_w0 + (Lx*xc + Ly*yc) * pd
    E = []
    for i0 in starts:
        j = i0-nw
        def sim(z, n_end):
            x = np.array([*z, 0, 0.]); xs=[x[:4]]
            for k in range(n_end):
                x = model.step(x, u[j+k], dt, 1); xs.append(x[:4])
            return np.array(xs)
        def resid(z):
            xs = sim(z, nw)
            if not np.all(np.isfinite(xs)): return np.full(2*(nw+1), 1.0)
            return np.concatenate([model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[j:i0+1], xs[:,0]-theta[j:i0+1]])
        z0 = np.array([theta[j], res.phi[j], prep.theta_dot[j], res.phi_dot[j]])
        sol = least_squares(resid, z0, x_scale=[1e-3,1e-3,0.1,0.1], method="lm")
        xs = sim(sol.x, nw+nh)[nw+1:]
        E.append(model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[i0+1:i0+nh+1])
    return float(np.sqrt(np.mean(np.array(E)**2)))
print(name, which, "windows", len(starts))
for L in [(0,0), (0.05,0), (-0.05,0), (0,0.05), (0,-0.05), (0.1, 0), (0, 0.1), (0,-0.1), (-0.1,0)]:
    print(L, round(score(*L), 5))
