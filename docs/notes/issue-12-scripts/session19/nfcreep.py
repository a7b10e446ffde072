"""Probe: linear creep saturating at Coulomb friction (creep-force law), AW causal."""
import pickle, sys, time
import numpy as np
from numba import njit
from bfr_model.dynamics import creep_terms, forced_terms, curve_terms
from bfr_diagnose import grip as G
from bfr_diagnose.locate import causal_prediction_errors, prediction_errors

FREF = float(sys.argv[4]) if len(sys.argv) > 4 else 0.1
NFMODE = len(sys.argv) > 4
MU = [float(v) for v in sys.argv[2].split(",")]

@njit
def sat_rhs(x, u, inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7):
    rr = Pt[9]
    a = creep_terms(x[0], x[1], x[2], x[3], x[4], u, inv_tau, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
    if rb < 0.0:  # normal-force dependent creep: inv_tau (Fn / FREF)^mu
        fac = (max(abs(a[5]), 1e-4) / FREF) ** mu
        a = creep_terms(x[0], x[1], x[2], x[3], x[4], u, inv_tau * fac, jb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
        out = np.empty(5)
        out[0] = x[2]; out[1] = x[3]; out[2] = a[0]; out[3] = a[1]; out[4] = a[2]
        return out
    tau = jb * a[2]
    lim = mu * abs(a[5]) * rb
    out = np.empty(5)
    out[0] = x[2]; out[1] = x[3]
    if abs(tau) <= lim:
        out[2] = a[0]; out[3] = a[1]; out[4] = a[2]
        return out
    tc = lim if tau > 0 else -lim
    lam = curve_terms(x[1], Pt, g0, g1, g2, g3, g4, g5, g6, g7)[8]
    b = forced_terms(x[0], x[1], x[2], x[3], u, -tc, lam * tc / rr, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
    out[2] = b[0]; out[3] = b[1]; out[4] = tc / jb
    return out

@njit
def sat_roll(x0, u, dt, ns, inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7):
    n = u.shape[0]
    xs = np.full((n + 1, 5), np.nan)
    x = x0.copy(); xs[0, :] = x; h = dt / ns
    for k in range(n):
        for _ in range(ns):
            k1 = sat_rhs(x, u[k], inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k2 = sat_rhs(x + 0.5*h*k1, u[k], inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k3 = sat_rhs(x + 0.5*h*k2, u[k], inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            k4 = sat_rhs(x + h*k3, u[k], inv_tau, jb, mu, rb, Pt, g0, g1, g2, g3, g4, g5, g6, g7)
            x = x + (h/6.0)*(k1 + 2*k2 + 2*k3 + k4)
        if not (np.isfinite(x[1]) and abs(x[3]) < 1e3):
            return xs
        xs[k + 1, :] = x
    return xs

state = {"mu": None}
_orig = G.creep_rollout
def creep_rollout(model, x0, u, dt, tau_s):
    if state["mu"] is None:
        return _orig(model, x0, u, dt, tau_s)
    pf, pt, jb, rb, rr = G.slip_parameters(model)
    ns = G._substeps(dt, tau_s)
    lam = float(curve_terms(float(x0[1]), pf, *model.geom_args)[8])
    rel0 = float(x0[4]) if len(x0) > 4 else 0.0
    x = np.array([x0[0], x0[1], x0[2], x0[3], x0[2] - lam * x0[3] / rr + rel0], float)
    return sat_roll(x, np.ascontiguousarray(u, float), dt, ns, 1.0 / tau_s, jb, state["mu"], -1.0 if NFMODE else rb,
                    pt, *model.geom_args)[:, :4]
G.creep_rollout = creep_rollout

c = pickle.load(open(f"/tmp/s19/{sys.argv[1]}.pkl", "rb"))
tau = float(sys.argv[3]) if len(sys.argv) > 3 else 0.1
law = G.SlipLaw(kind="creep", value=tau)
for mu in [None] + MU:
    state["mu"] = mu
    t0 = time.time()
    r = causal_prediction_errors(c["prep"], c["corrected"], c["phi"], c["phi_dot"], c["sensor"],
                                 c["test_t"], slip=law)
    s = prediction_errors(c["prep"], c["corrected"], c["phi"], c["phi_dot"], c["sensor"],
                          c["test_t"], slip=law)
    print(f"mu {mu} tau {tau}: causal ball {r['rmse']['ball_angle']:.5f} smoothed {s['rmse']['ball_angle']:.5f}  ({time.time()-t0:.1f}s)", flush=True)
