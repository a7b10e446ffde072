import math, numpy as np
from bfr_model.params import load_params
from bfr_model import contact as cm
P = load_params()
h = 5e-4
p = P.replace(**{"frame.inertia": 1e3, "track.asperity_phi": [0.0], "track.asperity_height": [h],
                 "track.asperity_width": [0.3], "track.asperity_edge": [1]})
m = cm.ContactModel(p)
print("edges", m.edges)
x = m.state_from_rigid(np.array([0.0, 0.0, 0.0, 0.0]), preload=False)
x[cm.IY] += h  # resting on edge 1's bump top, edge 2 below
m.reset(x, phi_guess=0.0)
for i in range(300):
    x = m.step(x, 0.0, 1e-3)
rb, ze = P.ball.radius, 0.5 * P.ball.plate_distance
rho = P.frame.contour.a - P.frame.contour.b
half = math.sqrt(ze**2 + h**2 / 4); L = math.sqrt(rb**2 - half**2); nrm = math.sqrt(4 * ze**2 + h**2)
y_ex = rho + h / 2 + L * 2 * ze / nrm; z_ex = -L * h / nrm
y0 = rho + P.ball.rolling_radius
print("y rise", x[cm.IY] - y0, "exact", y_ex - y0, "z", x[cm.IZ], "exact", z_ex, "x", x[cm.IX], "vz", x[cm.IVZ])
d = m.diagnostics(x)
print(d["edge_normal_force"], sum(d["edge_normal_force"]), p.ball.mass * 9.81)
# compliance: static deflection
