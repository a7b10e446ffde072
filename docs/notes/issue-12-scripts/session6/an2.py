import pickle, sys
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]; W = float(sys.argv[2]) if len(sys.argv) > 2 else 0.1
mode = sys.argv[3] if len(sys.argv) > 3 else "all4"
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = round(0.1/dt); step = round(0.2/dt); nw = round(W/dt)
test_t = np.interp(np.arange(prep.n), pr.res_before.idx, pr.test_mask.astype(float)) > 0.5
def run(params, res, sensor):
    model = RigidModel(params)
    psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
    ok = prep.ball_ok
    E = []; Es = []
    for i0 in range(nw, prep.n-nh-1, step):
        if not (ok[i0-nw:i0+nh+1].all() and test_t[i0:i0+nh+1].all()): continue
        j = i0 - nw
        if not (np.isfinite(res.phi[j]) and np.isfinite(res.phi_dot[j]) and np.isfinite(res.phi[i0]) and np.isfinite(res.phi_dot[i0])): continue
        def sim(z, n_end):
            x = np.array([z[0], z[1], z[2], z[3], 0, 0.])
            xs = [x[:4]]
            for k in range(n_end):
                x = model.step(x, u[j+k], dt, 1); xs.append(x[:4])
            return np.array(xs)
        def resid(z):
            xs = sim(z, nw)
            if not np.all(np.isfinite(xs)): return np.full(2*(nw+1), 1.0)
            bw = model.curve.ball_angle(xs[:,1]) - xs[:,0]
            r = [bw - psi_w[j:i0+1]]
            if mode == "all4": r.append(xs[:,0] - theta[j:i0+1])
            return np.concatenate(r)
        z0 = np.array([theta[j], res.phi[j], prep.theta_dot[j], res.phi_dot[j]])
        if mode == "all4":
            sol = least_squares(resid, z0, x_scale=[1e-3, 1e-3, 0.1, 0.1], method="lm")
            z = sol.x
        else:  # ball only: frame at measured
            f = lambda zb: resid(np.array([z0[0], zb[0], z0[2], zb[1]]))
            sol = least_squares(f, z0[[1,3]], x_scale=[1e-3, 0.1], method="lm")
            z = np.array([z0[0], sol.x[0], z0[2], sol.x[1]])
        xs = sim(z, nw + nh)
        bw = model.curve.ball_angle(xs[:,1]) - xs[:,0]
        E.append((bw - psi_w[j:i0+nh+1])[nw+1:])
        # smoothed-start reference
        x = np.array([theta[i0], res.phi[i0], prep.theta_dot[i0], res.phi_dot[i0], 0, 0.]); xs2=[]
        for k in range(nh):
            x = model.step(x, u[i0+k], dt, 1); xs2.append(x[:4])
        xs2 = np.array(xs2)
        Es.append(model.curve.ball_angle(xs2[:,1]) - xs2[:,0] - psi_w[i0+1:i0+nh+1])
    return np.array(E), np.array(Es)
Eb, Ebs = run(d.base, pr.res_before, pr.sensor0)
Ea, Eas = run(d.selection.params, pr.res_after, pr.sensor)
r = lambda E: np.sqrt(np.mean(E**2))
print(name, "W", W, mode, "windows", len(Eb))
print(f" fitted-start: before {r(Eb):.5f} after {r(Ea):.5f} ratio {r(Eb)/r(Ea):.2f}")
print(f" smooth-start: before {r(Ebs):.5f} after {r(Eas):.5f} ratio {r(Ebs)/r(Eas):.2f}")
for k in [4, 9, 24, 49]:
    print("  step", k+1, f"fit b {r(Eb[:,k]):.5f} a {r(Ea[:,k]):.5f} | smooth b {r(Ebs[:,k]):.5f} a {r(Eas[:,k]):.5f}")
