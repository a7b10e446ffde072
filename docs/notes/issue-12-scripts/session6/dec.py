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
R = []
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
    xs = sim(sol.x, nw+nh)[nw+1:]
    eth = xs[:,0] - theta[i0+1:i0+nh+1]
    ethd = xs[:,2] - prep.theta_dot[i0+1:i0+nh+1]
    eb = model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[i0+1:i0+nh+1]
    # in-frame ball angle error = eb + eth
    R.append((np.degrees(np.mod(sol.x[1], np.pi)), np.sqrt(np.mean(eb**2)), np.sqrt(np.mean(eth**2)), np.sqrt(np.mean((eb+eth)**2)), np.sqrt(np.mean(ethd**2)), np.max(np.abs(u[i0:i0+nh]))))
R = np.array(R)
print(name, len(R))
for b in range(0,180,30):
    s=(R[:,0]>=b)&(R[:,0]<b+30)
    print(b, s.sum(), "ball_w %.4f theta %.4f inframe %.4f thd %.3f  maxu %.3f" % tuple(np.sqrt(np.mean(R[s,1:5]**2,0)).tolist()+[np.median(R[s,5])]))
s = R[:,5] > 0.05
print("windows with |u|>0.05:", s.sum(), "ball_w %.4f theta %.4f inframe %.4f" % tuple(np.sqrt(np.mean(R[s,1:4]**2,0))), " others ball_w %.4f theta %.4f inframe %.4f" % tuple(np.sqrt(np.mean(R[~s,1:4]**2,0))))
