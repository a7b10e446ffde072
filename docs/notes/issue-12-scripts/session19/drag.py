"""Probe: aerodynamic drag on the ball, F = -k |v| v (world velocity), AW causal."""
import pickle, sys, time
import numpy as np
from numba import njit
from bfr_model.dynamics import forced_terms, curve_terms
from bfr_model.layout import I_CW, I_SW, I_R
from bfr_diagnose import grip as G
from bfr_diagnose.locate import causal_prediction_errors, prediction_errors

@njit
def rhs(x, u, inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7):
    rr = Pt[I_R]
    ct = curve_terms(x[1], Pt, g0, g1, g2, g3, g4, g5, g6, g7)
    px, py, p1x, p1y, lam = ct[0], ct[1], ct[2], ct[3], ct[8]
    c = Pt[I_CW]; sw = Pt[I_SW]
    qx = c * px; qy = py
    vx = -x[2] * qy + x[3] * c * p1x
    vy = x[2] * qx + x[3] * p1y
    vz = x[3] * sw * p1x
    sp = np.sqrt(vx * vx + vy * vy + vz * vz)
    fx = -kd * sp * vx; fy = -kd * sp * vy; fz = -kd * sp * vz
    f1 = -fx * qy + fy * qx
    f2 = fx * c * p1x + fy * p1y + fz * sw * p1x
    s = x[4] - (x[2] - lam * x[3] / rr)
    tau = -jb * inv_tau * s
    a = forced_terms(x[0], x[1], x[2], x[3], u, -tau + f1, lam * tau / rr + f2, Pt, g0, g1, g2,
                     g3, g4, g5, g6, g7)
    out = np.empty(5)
    out[0] = x[2]; out[1] = x[3]; out[2] = a[0]; out[3] = a[1]; out[4] = tau / jb
    return out

@njit
def roll(x0, u, dt, ns, inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7):
    n = u.shape[0]
    xs = np.full((n + 1, 5), np.nan)
    x = x0.copy(); xs[0, :] = x; h = dt / ns
    for k in range(n):
        for _ in range(ns):
            k1 = rhs(x, u[k], inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k2 = rhs(x + 0.5*h*k1, u[k], inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k3 = rhs(x + 0.5*h*k2, u[k], inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k4 = rhs(x + h*k3, u[k], inv_tau, jb, kd, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            x = x + (h/6.0)*(k1 + 2*k2 + 2*k3 + k4)
        if not (np.isfinite(x[1]) and abs(x[3]) < 1e3):
            return xs
        xs[k + 1, :] = x
    return xs

state = {"kd": 0.0}
def creep_rollout(model, x0, u, dt, tau_s):
    pf, pt, jb, rb, rr = G.slip_parameters(model)
    ns = G._substeps(dt, tau_s)
    lam = float(curve_terms(float(x0[1]), pf, *model.geom_args)[8])
    rel0 = float(x0[4]) if len(x0) > 4 else 0.0
    x = np.array([x0[0], x0[1], x0[2], x0[3], x0[2] - lam * x0[3] / rr + rel0], float)
    return roll(x, np.ascontiguousarray(u, float), dt, ns, 1.0 / tau_s, jb, state["kd"],
                pt, *model.geom_args)[:, :4]
G.creep_rollout = creep_rollout

name = sys.argv[1]
c = pickle.load(open(f"/tmp/s19/{name}.pkl", "rb"))
tau = float(sys.argv[3]) if len(sys.argv) > 3 else 0.1
K0 = 0.5 * 1.2 * 0.47 * np.pi * c["corrected"].ball.radius ** 2
print("k0 (sphere, Cd 0.47)", K0, "m_b", c["corrected"].ball.mass)
law = G.SlipLaw(kind="creep", value=tau)
for f in [float(v) for v in sys.argv[2].split(",")]:
    state["kd"] = f * K0
    t0 = time.time()
    r = causal_prediction_errors(c["prep"], c["corrected"], c["phi"], c["phi_dot"], c["sensor"],
                                 c["test_t"], slip=law)
    s = prediction_errors(c["prep"], c["corrected"], c["phi"], c["phi_dot"], c["sensor"],
                          c["test_t"], slip=law)
    print(f"kd {f:g} k0 tau {tau}: causal ball {r['rmse']['ball_angle']:.5f} theta {r['rmse']['theta']:.5f} smoothed {s['rmse']['ball_angle']:.5f} ({time.time()-t0:.1f}s)", flush=True)
