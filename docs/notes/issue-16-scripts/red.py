import math, numpy as np
from bfr_model.params import load_params
from bfr_model import contact as cm
P = load_params()
ROUGH = P.replace(**{"track.asperity_phi": [0.1, -0.12, 0.105], "track.asperity_height": [5e-4, 3e-4, 2e-4], "track.asperity_width": [0.003, 0.004, 0.002]})
for name, p, ts in (("nominal", P, None), ("rough", ROUGH, 1e-5)):
    a = cm.ContactModel(p, time_step=ts); b = cm.ContactModel(p, time_step=ts, edges=2)
    xa = a.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0])); xb = b.state_from_rigid(np.array([0.0, 0.3, 0.0, 0.0]))
    print(name, "start diff", np.max(np.abs(xa - xb)))
    worst = 0
    for i in range(400):
        u = 2e-3 * math.sin(5.0 * i * 1e-3)
        xa = a.step(xa, u, 1e-3); xb = b.step(xb, u, 1e-3)
        d = np.abs(xa - xb) / np.maximum(np.abs(xa), 1e-300)
        worst = max(worst, np.max(np.abs(xa[:13] - xb[:13])))
    print(name, "max |diff| first 13 states", worst, "z", xb[cm.IZ], xb[cm.IVZ], "xi", xa[cm.IXI], xb[cm.IXI], xb[cm.IXI2])
    print("  final", xa[:8]); print("  W", xa[cm.IWD], xb[cm.IWD])
