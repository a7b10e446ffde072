import numpy as np
from bfr_model.params import load_params
from bfr_model.contact import ContactModel
from bfr_model.dynamics import RigidModel
from bfr_model.simulate import simulate
P = load_params()
xr = np.array([0.0, 0.3, 0.0, 0.0])
rr = simulate(RigidModel(P), xr, 1.5, 0.0, dt=1e-3)
for kmul in (1.0, 10.0):
    p = P.replace(**{"contact.stiffness": P.contact_stiffness * kmul})
    for edges in (1, 2):
        cm = ContactModel(p, edges=edges)
        res = cm.simulate(cm.state_from_rigid(xr), 1.5, 0.0, dt=1e-3)
        d = np.abs(res.rigid - rr.x[:, :4]).max(axis=0)
        print(kmul, edges, "max |dphi|", d[1], "dphidot", d[3], "bal", np.max(np.abs(res.balance_error)), "rtf", res.real_time_factor)
