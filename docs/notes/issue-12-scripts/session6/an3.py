import pickle, sys
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
params, res, sensor = d.selection.params, pr.res_after, pr.sensor
model = RigidModel(params)
psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
ok = prep.ball_ok
rows = []
for i0 in range(nw, prep.n-nh-1, 25):
    if not ok[i0-nw:i0+nh+1].all(): continue
    j = i0-nw
    if not (np.isfinite(res.phi[j]) and np.isfinite(res.phi_dot[j])): continue
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
    xs = sim(sol.x, nw+nh)
    e = model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[j:i0+nh+1]
    fitres = np.sqrt(np.mean(e[:nw+1]**2)); pe = np.sqrt(np.mean(e[nw+1:]**2))
    rows.append((prep.t[i0], np.degrees(np.mod(res.phi[i0], np.pi)), res.phi_dot[i0], prep.theta_dot[i0], fitres, pe))
R = np.array(rows)
print(name, "windows", len(R), "fit-window rms median %.5f, pred rms median %.5f"%(np.median(R[:,4]), np.median(R[:,5])))
for b in range(0,180,20):
    s=(R[:,1]>=b)&(R[:,1]<b+20)
    if s.any(): print("phi %3d-%3d n %3d fitres %.5f pred %.5f phidot %.2f"%(b,b+20,s.sum(),np.median(R[s,4]),np.sqrt(np.mean(R[s,5]**2)),np.median(np.abs(R[s,2]))))
np.save(f"/tmp/s7/{name}_win.npy", R)
