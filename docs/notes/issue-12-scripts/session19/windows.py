import pickle, sys, numpy as np
from bfr_diagnose import grip as G
from bfr_diagnose.locate import causal_prediction_errors, _predictor
c = pickle.load(open(f"/tmp/s19/{sys.argv[1]}.pkl", "rb"))
law = G.SlipLaw(kind="creep", value=0.1)
prep = c["prep"]
r = causal_prediction_errors(prep, c["corrected"], c["phi"], c["phi_dot"], c["sensor"], c["test_t"], slip=law, keep_traces=400)
pred = _predictor(prep, c["corrected"], c["sensor"], 0.1, 0.2, law)
t = prep.t
rows = []
for tr in r["traces"]:
    i0 = int(np.searchsorted(t, tr["t"][0] - 1e-9))
    seg = slice(i0, i0 + len(tr["t"]))
    e = np.array(tr["ball_angle"]) - pred.psi_w[seg]
    w = np.gradient(pred.psi_w[seg], 0.002)
    rows.append((np.sqrt(np.mean(e[1:] ** 2)), e[-1], np.mean(np.abs(prep.theta_dot[seg])), np.mean(np.abs(w)),
                 np.mean(np.abs(pred.u[seg]) > 0.095) + np.mean(np.abs(pred.u[seg] - 0.02) < 0.002), np.degrees(np.mean(c["phi"][seg]) % np.pi), t[i0]))
a = np.array(rows)
print("n", len(a), "rms", np.sqrt(np.mean(a[:, 0] ** 2)))
for k, n in ((2, "|thd|"), (3, "|psi_w dot|"), (4, "sat frac")):
    print(n, "corr with window rms", np.corrcoef(a[:, 0], a[:, k])[0, 1])
o = np.argsort(-a[:, 0])
print(" rms     end    |thd|  |wdot| sat  phi(mod180) t")
for i in o[:20]:
    print(" ".join(f"{v:7.4f}" if j < 2 else f"{v:6.2f}" for j, v in enumerate(a[i])))
print("share of MSE in top 10:", np.sum(a[o[:10], 0] ** 2) / np.sum(a[:, 0] ** 2))
