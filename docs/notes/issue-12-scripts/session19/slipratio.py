import pickle, sys, numpy as np
from bfr_diagnose import grip as G
from bfr_diagnose.locate import _predictor
name = sys.argv[1]; tau = float(sys.argv[2])
c = pickle.load(open(f"/tmp/s19/{name}.pkl", "rb"))
prep = c["prep"]
law = G.SlipLaw(kind="creep", value=tau)
pred = _predictor(prep, c["corrected"], c["sensor"], 0.1, 0.2, law)
m = pred.model
s = law.spin(m, prep.theta_dot, c["phi"], c["phi_dot"], pred.usable, pred.dt)
x = np.column_stack([prep.theta_dot * 0, c["phi"], prep.theta_dot, c["phi_dot"]])
w_roll = m.ball_spin_rate(x)
# rolling speed of the ball centre relative to the frame: lam phi_dot (m/s) -> spin relative to frame
lam = m.curve.speed(c["phi"])
v_rel = np.abs(lam * c["phi_dot"])            # ball centre speed along the track [m/s]
spin_rel = np.abs(lam * c["phi_dot"] / m.P[3])  # rolling spin relative to the frame [rad/s]
ok = np.isfinite(s) & np.isfinite(v_rel) & (spin_rel > 1.0)
ratio = np.abs(s[ok]) / spin_rel[ok]
slipv = np.abs(s[ok]) * m.P[3]
print(name, "tau", tau, "samples", ok.sum())
print(" slip ratio |s| / |w_rel| percentiles 50/90/99:", np.percentile(ratio, [50, 90, 99]).round(3))
print(" slip speed |s| R [m/s] 50/90/99:", np.percentile(slipv, [50, 90, 99]).round(3))
print(" |s| rad/s 50/90/99", np.percentile(np.abs(s[ok]), [50, 90, 99]).round(2), " rolling spin rel 50/90", np.percentile(spin_rel[ok], [50, 90]).round(1))
th = prep.theta + c["sensor"].theta_zero
xx = np.column_stack([th, c["phi"], prep.theta_dot, c["phi_dot"]])
fn = m.normal_force(xx[ok], prep.u[ok] if hasattr(prep, "u") else 0.0)
T = m.P[1] * np.abs(s[ok]) / tau
mu_eff = T / (np.abs(fn) * m.params.ball.radius)
print(" creep torque / (F_n R_b) 50/90/99:", np.percentile(mu_eff, [50, 90, 99]).round(3), " F_n 50/10:", np.percentile(fn, [50, 10]).round(4))
