import numpy as np, math
from bfr_model.params import load_params
from bfr_model.contact import ContactModel, IY, IVY, IX, IVX, ITHD, IOM
P = load_params()
def roll(dt, T=0.05):
    m = ContactModel(P, time_step=dt)
    x = m.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    return m.step(x, 0.0, 1e-3, round(T/1e-3))
ref = roll(1.25e-6)
print("rolling:", [float(np.max(np.abs(roll(dt)[[IX, IY, IVX, IVY]] - ref[[IX, IY, IVX, IVY]]))) for dt in (8e-5, 4e-5, 2e-5, 1e-5, 5e-6)])
p = P.replace(**{"frame.inertia": 1e3})
def drop(dt, T=0.006):
    m = ContactModel(p, time_step=dt)
    x = m.state_from_rigid(np.array([0.0, 0.0, 0.0, 0.0]), preload=False)
    x[IY] += 2e-5
    m.reset(x, phi_guess=0.0)
    return m.step(x, 0.0, 1e-3, round(T/1e-3))
ref = drop(1.25e-6)
print("first impact:", [float(np.max(np.abs(drop(dt)[[IY, IVY]] - ref[[IY, IVY]]))) for dt in (8e-5, 4e-5, 2e-5, 1e-5, 5e-6)])
