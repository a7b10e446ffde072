import numpy as np, math, time
from bfr_model.params import load_params
from bfr_model.perturbations import load_study
from bfr_model.contact import ContactModel, ITH, ITHD, IX, IY, IWD, IWIN
from bfr_model.recording import Recording
from bfr_tools.analysis.trajectory import closed_loop_contact
from bfr_tools.analysis.recorded import analyze_recording
P = load_params(); S = load_study()
for tc, cv in ((1e-3, 0.0), (5e-4, 2e-5)):
    plant = P.replace(**{"joint.coulomb_friction": tc, "joint.viscous_friction": cv, "track.rolling_resistance": 2e-3})
    m = ContactModel(plant)
    t0 = time.time()
    res = closed_loop_contact(m, P, S, 8.0, seed=1)
    print("wall", time.time()-t0, "rolling until", res.rolling_until, "n", res.t.size, "dt", res.t[1]-res.t[0])
    t = res.t; x = res.x
    k = np.arange(t.size); fix = (k % max(1, round(0.005/(t[1]-t[0])))) == 0
    idx = np.maximum.accumulate(np.where(fix, k, 0))
    bx, by = x[idx, IX], x[idx, IY]
    th = x[:, ITH]
    phi = x[idx, ITH] + np.arctan2(bx, by)
    rec = Recording(t=t, theta=th, theta_dot=x[:, ITHD], torque=res.u, ball_x=bx, ball_y=by, ball_valid=np.ones(t.size, bool), phi=phi, meta={"source": "contact"})
    r = analyze_recording(rec, P, S, plant, label="contact")
    f = r.figures
    n, c = f["nominal"], f["corrected"]
    # the generator's own dissipation per turn over the analysed span
    ta = r.nominal.t[0]; i0, i1 = np.searchsorted(t, [ta[0], ta[-1]])
    wd = x[i1, IWD] - x[i0, IWD]; win = x[i1, IWIN] - x[i0, IWIN]; turns = (th[i1] - th[i0]) / (2*np.pi)
    print(f"Tc {tc}: nominal D/turn {n['rate']['discrepancy']['mean']:.5f} +- {n['rate']['discrepancy']['std']}, generator W_diss/turn {wd/turns:.5f}, motor {n['rate']['motor_work']['mean']:.5f} vs gen W_in/turn {win/turns:.5f}; corrected D/turn {c['rate']['discrepancy']['mean']:.6f} share {c['share_left']:.3f}; Tc_eq {n['equivalent']['joint_coulomb_torque']}")
