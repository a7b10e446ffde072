import pickle, sys, time, dataclasses
import numpy as np
from scipy.optimize import least_squares
from bfr_model.dynamics import RigidModel
name = sys.argv[1]; every = int(sys.argv[2]); start_from = sys.argv[3]  # after|base
names = sys.argv[4].split(",")
d = pickle.load(open(f"/tmp/s7/{name}.pkl", "rb"))
pr = d.parts[0]; prep = pr.prep
dt = float(prep.t[1]-prep.t[0]); nh = 50; nw = 50
params0, res, sensor0 = ((d.selection.params, pr.res_after, pr.sensor) if start_from == "after" else (d.base, pr.res_before, pr.sensor0))
test_t = np.interp(np.arange(prep.n), pr.res_before.idx, pr.test_mask.astype(float)) > 0.5
ok = prep.ball_ok
def starts(mask_fn):
    return [i0 for i0 in range(nw, prep.n-nh-1, every) if ok[i0-nw:i0+nh+1].all() and mask_fn(i0) and np.isfinite(res.phi[i0-nw]) and np.isfinite(res.phi_dot[i0-nw])]
S_train = starts(lambda i0: not test_t[i0-nw:i0+nh+1].any())
S_test = starts(lambda i0: test_t[i0:i0+nh+1].all())
def get(params, sensor, n):
    if n == "latency": return sensor.latency
    if n == "torque_delay": return sensor.torque_delay
    if n == "rotation": return sensor.rotation
    obj = params
    for k in n.split("."): obj = getattr(obj, k)
    return obj
x0 = np.array([get(params0, sensor0, n) for n in names])
scale = np.where(np.abs(x0) > 0, np.abs(x0), 1e-3)
def build(z):
    x = x0 + z * scale * 0.1
    ch = {n: float(v) for n, v in zip(names, x) if n not in ("latency", "torque_delay", "rotation")}
    sch = {n: float(v) for n, v in zip(names, x) if n in ("latency", "torque_delay", "rotation")}
    return params0.replace(**ch) if ch else params0, dataclasses.replace(sensor0, **sch)
def errs(z, S):
    params, sensor = build(z)
    model = RigidModel(params)
    psi_w, _ = prep.psi_for(sensor); u = prep.u_for(sensor); theta = prep.theta + sensor.theta_zero
    E = []
    for i0 in S:
        j = i0-nw
        def sim(zz, n_end):
            x = np.array([*zz, 0, 0.]); xs=[x[:4]]
            for k in range(n_end):
                x = model.step(x, u[j+k], dt, 1); xs.append(x[:4])
            return np.array(xs)
        def resid(zz):
            xs = sim(zz, nw)
            if not np.all(np.isfinite(xs)): return np.full(2*(nw+1), 1.0)
            return np.concatenate([model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[j:i0+1], xs[:,0]-theta[j:i0+1]])
        z0 = np.array([theta[j], res.phi[j], prep.theta_dot[j], res.phi_dot[j]])
        sol = least_squares(resid, z0, x_scale=[1e-3,1e-3,0.1,0.1], method="lm", xtol=1e-12, ftol=1e-12)
        xs = sim(sol.x, nw+nh)[nw+1:]
        e = model.curve.ball_angle(xs[:,1]) - xs[:,0] - psi_w[i0+1:i0+nh+1]
        if not np.all(np.isfinite(e)): e = np.full(nh, 0.1)
        E.append(e)
    return np.concatenate(E)
r = lambda v: float(np.sqrt(np.mean(v**2)))
t0 = time.time()
print(name, start_from, "train", len(S_train), "test", len(S_test), "x0", dict(zip(names, x0)), flush=True)
print("start: train %.5f test %.5f" % (r(errs(np.zeros(len(names)), S_train)), r(errs(np.zeros(len(names)), S_test))), time.time()-t0, flush=True)
sol = least_squares(lambda z: errs(z, S_train), np.zeros(len(names)), diff_step=0.1, max_nfev=15, x_scale=1.0, verbose=0)
params, sensor = build(sol.x)
print("end: train %.5f test %.5f" % (r(errs(sol.x, S_train)), r(errs(sol.x, S_test))), "nfev", sol.nfev, time.time()-t0)
print("values", {n: get(params, sensor, n) for n in names})
