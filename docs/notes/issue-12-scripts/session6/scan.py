import pickle, sys
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]; every = int(sys.argv[2])
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
P0, res, sensor = d.selection.params, pr.res_after, pr.sensor
psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
ok = prep.ball_ok
starts = [i0 for i0 in range(nw, prep.n-nh-1, every) if ok[i0-nw:i0+nh+1].all() and np.isfinite(res.phi[i0-nw]) and np.isfinite(res.phi_dot[i0-nw])]
phs = np.degrees(np.mod(res.phi[starts], np.pi))
def score(params):
    model = RigidModel(params)
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
            return np.concatenate([model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[j:i0+1], (xs[:,0]-theta[j:i0+1])])
        z0 = np.array([theta[j], res.phi[j], prep.theta_dot[j], res.phi_dot[j]])
        sol = least_squares(resid, z0, x_scale=[1e-3,1e-3,0.1,0.1], method="lm")
        xs = sim(sol.x, nw+nh)[nw+1:]
        e = model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[i0+1:i0+nh+1]
        E.append(e if np.all(np.isfinite(e)) else np.full(nh, 0.1))
    E = np.array(E)
    hi = (phs >= 120) | (phs < 20)
    return "all %.5f  120-20deg %.5f  20-120deg %.5f" % (np.sqrt(np.mean(E**2)), np.sqrt(np.mean(E[hi]**2)), np.sqrt(np.mean(E[~hi]**2)))
print(name, len(starts), "P0:", P0.ball)
print("as fitted", score(P0))
for k, vals in [("ball.mass", [0.0015, 0.002, 0.0045, 0.006]), ("ball.inertia", [1.65e-7, 2.2e-7, 5e-7, 6.6e-7]), ("ball.plate_distance", [0.020, 0.023, 0.028, 0.030]), ("ball.radius", [0.0155, 0.0175])]:
    for v in vals:
        try:
            print(k, v, score(P0.replace(**{k: v})), flush=True)
        except Exception as e:
            print(k, v, "err", e)
