import pickle, sys
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]; every = int(sys.argv[2])
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
params, res, sensor = d.selection.params, pr.res_after, pr.sensor
model = RigidModel(params)
psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
ok = prep.ball_ok
X = []; Y = []
for i0 in range(nw, prep.n-nh-1, every):
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
    # in-frame error at the end of the horizon
    e = (model.curve.ball_angle(xs[-1,1]) - xs[-1,0] - psi_w[i0+nh]) + (xs[-1,0] - theta[i0+nh])
    s = slice(i0, i0+nh+1)
    thd = prep.theta_dot[s]; thdd = prep.theta_ddot[s]
    X.append([np.mean(thd**2), np.mean(thdd), np.mean(thd), np.mean(np.abs(thdd)), np.mean(u[s])]); Y.append(e)
X = np.array(X); Y = np.array(Y)
print(name, len(Y), "rms err %.4f" % np.sqrt(np.mean(Y**2)))
for k, lab in enumerate(["mean thd^2", "mean thdd", "mean thd", "mean |thdd|", "mean u"]):
    print(lab, "corr %.2f" % np.corrcoef(X[:,k], Y)[0,1], "corr |e| %.2f" % np.corrcoef(X[:,k], np.abs(Y))[0,1])
A = np.c_[np.ones(len(Y)), X]
c, *_ = np.linalg.lstsq(A, Y, rcond=None)
print("R2 linear", 1 - np.sum((Y - A@c)**2)/np.sum((Y-Y.mean())**2))
