import sys, time, numpy as np
sys.path.insert(0, "/tmp/p16/old")
from numba import njit
from bfr_model.params import load_params
from bfr_model import contact as cn
from oldbfr import contact as co

@njit
def loop_eval_new(n, x, CP, E, cand, ncand, cact, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, diag, dxv):
    for i in range(n):
        cn.contact_eval(x, 0.0, CP, E, cand, ncand, cact, False, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, 2, diag, dxv)
    return dxv[0]

@njit
def loop_eval_old(n, x, CP, cand, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, diag, dxv):
    for i in range(n):
        co.contact_eval(x, 0.0, CP, cand, 1, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, 0, 2, diag, dxv)
    return dxv[0]

@njit
def loop_update_new(n, x, CP, E, cand, ncand, cact, cslack, cbase, sst, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, hmax, aspc, diag, dxv):
    b = 0.0
    for i in range(n):
        b += cn.update_contacts(x, CP, E, cand, ncand, cact, cslack, cbase, sst, rho0, orders, ccos, csin, bphi, bh, bw, tphi, th, tw, span, hmax, aspc, 1e-7, diag, dxv)
    return b

@njit
def loop_update_old(n, x, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, na, diag, dxv):
    b = 0.0
    for i in range(n):
        b += co.update_candidates(x, CP, cand, ncand, rho0, orders, ccos, csin, bphi, bh, bw, aphi, ah, aw, aidx, na, diag, dxv, False)
    return b

P = load_params()
mo, mn = co.ContactModel(P), cn.ContactModel(P)
xo = mo.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0])); xo = mo.step(xo, 0.0, 1e-3)
xn = mn.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0])); xn = mn.step(xn, 0.0, 1e-3)
dn, don = np.zeros(cn.D_SIZE), np.empty(cn.NX); do_, doo = np.zeros(co.D_SIZE), np.empty(co.NX)
N = 200000
def T(f, *a):
    f(10, *a); ts = []
    for r in range(5):
        t0 = time.process_time(); f(N, *a); ts.append((time.process_time() - t0) / N)
    return 1e9 * np.median(ts)
print("eval ns: old", T(loop_eval_old, xo, mo.CP, mo.cand, *mo._args, mo.aidx, do_, doo), "new", T(loop_eval_new, xn, mn.CP, 1, mn.cand, mn.ncand, mn.cact, *mn._geo, dn, don))
print("update ns: old", T(loop_update_old, xo, mo.CP, mo.cand, mo.ncand, *mo._args, mo.aidx, mo.na, do_, doo), "new", T(loop_update_new, xn, mn.CP, 1, *mn._set_arrays()[:3], mn.cslack, mn.cbase, mn.sst, *mn._geo, mn.hmax, mn.aspc, dn, don))
