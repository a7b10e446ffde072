"""Noise floor of the causal 100 ms measure on AW: the corrected creep model as its own truth."""
import pickle, sys, dataclasses, numpy as np
from bfr_diagnose import grip as G
from bfr_diagnose.locate import _predictor, _fit_start
c = pickle.load(open("/tmp/s19/Actually_worked.pkl", "rb"))
prep = c["prep"]
law = G.SlipLaw(kind="creep", value=0.1)
pred = _predictor(prep, c["corrected"], c["sensor"], 0.1, 0.2, law)
spin = law.spin(pred.model, prep.theta_dot, c["phi"], c["phi_dot"], pred.usable, pred.dt)
nw = nh = pred.nh
sig_cam = float(sys.argv[1]) if len(sys.argv) > 1 else prep.noise["camera_along"]
rng = np.random.default_rng(1)
e_real, e_syn, worst = [], [], []
for i0 in pred.starts(c["test_t"], lead=nw):
    j = i0 - nw
    g = np.array([pred.theta[j], c["phi"][j], prep.theta_dot[j], c["phi_dot"][j],
                  spin[j] if np.isfinite(spin[j]) else 0.0])
    fit = _fit_start(pred, g, j, nw)
    if fit is None:
        continue
    xs = pred.rollout(fit.state, j, nw + nh)
    er = pred.ball_angle(xs)[nw + 1:] - pred.psi_w[i0 + 1:i0 + nh + 1]
    # synthetic truth: this rollout, measured with noise at the camera's fix rate
    th = xs[:, 0] + rng.normal(0, prep.noise["theta"], xs.shape[0])
    rho = np.nanmedian(pred.rho[j:i0 + nh + 1])
    k = np.arange(0, xs.shape[0] + 3, 3)
    nz = np.interp(np.arange(xs.shape[0]), k, rng.normal(0, sig_cam / rho, k.size))
    psi = pred.ball_angle(xs) + nz
    theta_s = pred.theta.copy(); psi_s = pred.psi_w.copy()
    theta_s[j:j + xs.shape[0]] = th; psi_s[j:j + xs.shape[0]] = psi
    ps = dataclasses.replace(pred, theta=theta_s, psi_w=psi_s)
    fs = _fit_start(ps, g, j, nw)
    if fs is None:
        continue
    ys = ps.rollout(fs.state, j, nw + nh)
    es = ps.ball_angle(ys)[nw + 1:] - pred.ball_angle(xs)[nw + 1:]
    e_real.append(er); e_syn.append(es)
    worst.append((np.sqrt(np.mean(er**2)), np.sqrt(np.mean(es**2)), prep.t[i0]))
rm = lambda e: np.sqrt(np.mean(np.concatenate(e) ** 2))
print(f"windows {len(e_real)}  real causal {rm(e_real):.5f}  noise floor (model as truth, sigma {sig_cam:.2e} m) {rm(e_syn):.5f}")
w = sorted(worst, reverse=True)[:8]
for a in w: print(f"  t {a[2]:6.2f} real {a[0]:.4f} floor {a[1]:.4f}")
print("frame share in the worst windows:")
