"""The ball's measured distance from the shaft against the nominal ball-centre curve, split
into what is fixed in the frame (harmonics of the ball's angle in the frame, psi) and what is
fixed in the camera (harmonics of its world angle, beta). Run from the repository root:
``python docs/notes/issue-12-scripts/ball_distance_frame_vs_world.py`` (issue-12 note).
"""
import numpy as np
from bfr_model.io import read_runs
from bfr_model.geometry import OffsetCurve
from bfr_model.params import load_params
P=load_params(); c=OffsetCurve.from_params(P)
for f in ['fin','Actually_worked','rolling_data']:
    runs=read_runs(f'../shared/data/ntnu-rig/{f}.txt')
    r=max(runs, key=lambda x: x.n)
    ok=r.ball_valid.astype(bool) & np.asarray(r.new_fix_mask(), bool)
    x,y,th=r.ball_x[ok], r.ball_y[ok], r.theta[ok]
    rho=np.hypot(x,y); beta=np.arctan2(x,y)            # world angle, clockwise from +y
    psi=th+beta                                         # ball angle in the frame
    phi=c.phi_from_ball_angle(psi)
    model=np.linalg.norm(c.point(phi),axis=-1)
    e=rho-model
    def explained(ang, K=8):
        A=np.column_stack([np.ones_like(ang)]+[f(k*ang) for k in range(1,K+1) for f in (np.cos,np.sin)])
        coef,*_=np.linalg.lstsq(A,e,rcond=None); res=e-A@coef
        return 1-np.var(res)/np.var(e), coef
    ef,cf=explained(psi); ew,cw=explained(beta); 
    A=np.column_stack([np.ones_like(psi)]+[f(k*a) for a in (psi,beta) for k in range(1,9) for f in (np.cos,np.sin)])
    coef,*_=np.linalg.lstsq(A,e,rcond=None); eb=1-np.var(e-A@coef)/np.var(e)
    print(f"{f:16s} n={ok.sum():5d} mean(rho-model)={e.mean()*1e3:+.2f} mm rms={e.std()*1e3:.2f} mm | var explained: frame-fixed(psi) {ef:.2f}, world-fixed(beta) {ew:.2f}, both {eb:.2f}; beta range {np.degrees(beta.min()):.0f}..{np.degrees(beta.max()):.0f} deg")
