import sys
import numpy as np
from bfr_model.params import load_params
from bfr_model.dynamics import RigidModel
th0 = -0.0139
for f in sys.argv[1:]:
    P = load_params(f)
    m = RigidModel(P)
    ph = np.linspace(-0.6, 0.6, 12001)
    G = np.array([m.gravity_vector(th0, p)[1] for p in ph])
    for i in np.where(np.diff(np.sign(G)) != 0)[0]:
        p0 = ph[i]; dG = (G[i + 1] - G[i]) / (ph[1] - ph[0])
        M22 = m.mass_matrix(p0)[1, 1]
        if dG / M22 > 0:
            w = np.sqrt(dG / M22)
            # path curvature of ball centre near rest
            pts = np.array([np.ravel(m.ball_position(np.array([th0, p, 0, 0])))[:2] for p in (p0 - 0.05, p0, p0 + 0.05)])
            a, b, c = pts
            # circumradius
            la, lb, lc = np.linalg.norm(b - c), np.linalg.norm(a - c), np.linalg.norm(a - b)
            area = 0.5 * abs(np.cross(b - a, c - a))
            Rc = la * lb * lc / (4 * area)
            print(f"{f}: rest phi {np.degrees(p0):6.2f} deg, centre {pts[1]*1e3} mm, period {2*np.pi/w:.3f} s, path radius {Rc*1e3:.1f} mm")
