"""Sixth-session probes of Actually_worked's ball: what the braking half-lap is not.

Every probe scores the 100 ms ball prediction from the state the model fits to the 100 ms
before each window (the method of ``bfr_diagnose.locate.causal_prediction_errors``,
written out here so that the measurement, the model or the step can be swapped), on a
diagnosis pickled by ``run.py NAME`` (/tmp/s7/NAME.pkl). Figures in
docs/notes/issue-12.md, sixth session. Usage (source tree on PYTHONPATH, scripts/env.sh):

    python probes.py regions Actually_worked      # error by the ball's place on the frame
    python probes.py slip Actually_worked 0.5,0.2,0.05
    python probes.py shutter Actually_worked      # latency varying across the image
    python probes.py twist Actually_worked        # theta_plate = theta_encoder + c u
    python probes.py scan Actually_worked         # ball parameters of the library
    python probes.py refit Actually_worked        # seven parameters by the prediction error
"""

from __future__ import annotations

import dataclasses
import pickle
import sys

import numpy as np
from bfr_model.contact import ContactModel
from bfr_model.dynamics import RigidModel
from scipy.optimize import least_squares

NH = NW = 50  # horizon and fit window [grid samples of 2 ms]


class Probe:
    """One recording's corrected diagnosis and its prediction windows."""

    def __init__(self, name: str, every: int = 100) -> None:
        with open(f"/tmp/s7/{name}.pkl", "rb") as f:
            d = pickle.load(f)
        self.d, self.pr = d, d.parts[0]
        self.prep, self.res = self.pr.prep, self.pr.res_after
        self.params, self.sensor = d.selection.params, self.pr.sensor
        p = self.prep
        self.dt = float(p.t[1] - p.t[0])
        self.u = p.u_for(self.sensor)
        self.psi_w = p.psi_for(self.sensor)[0]
        self.theta = p.theta + self.sensor.theta_zero
        self.starts = [i0 for i0 in range(NW, p.n - NH - 1, every)
                       if p.ball_ok[i0 - NW:i0 + NH + 1].all()
                       and np.isfinite(self.res.phi[i0 - NW])
                       and np.isfinite(self.res.phi_dot[i0 - NW])]
        self.place = np.degrees(np.mod(self.res.phi[self.starts], np.pi))

    def errors(self, params=None, sensor=None, theta=None, psi_w=None):  # noqa: ANN001, ANN201
        """Per window: (fitted state at i0, ball-angle errors over the 100 ms after i0)."""
        model = RigidModel(params or self.params)
        u = self.u if sensor is None else self.prep.u_for(sensor)
        psi = self.psi_w if sensor is None else self.prep.psi_for(sensor)[0]
        psi = psi if psi_w is None else psi_w
        th = self.theta if theta is None else theta
        out = []
        for i0 in self.starts:
            j = i0 - NW

            def sim(z, n, j=j, model=model, u=u):  # noqa: ANN001, ANN202
                x = np.array([*z, 0.0, 0.0])
                xs = [x[:4]]
                for k in range(n):
                    x = model.step(x, u[j + k], self.dt, 1)
                    xs.append(x[:4])
                return np.array(xs)

            def resid(z, j=j, i0=i0, sim=sim, model=model):  # noqa: ANN001, ANN202
                xs = sim(z, NW)
                if not np.all(np.isfinite(xs)):
                    return np.full(2 * (NW + 1), 1.0)
                return np.concatenate([model.curve.ball_angle(xs[:, 1]) - xs[:, 0]
                                       - psi[j:i0 + 1], xs[:, 0] - th[j:i0 + 1]])

            z0 = np.array([th[j], self.res.phi[j], self.prep.theta_dot[j],
                           self.res.phi_dot[j]])
            z = least_squares(resid, z0, x_scale=[1e-3, 1e-3, 0.1, 0.1], method="lm").x
            xs = sim(z, NW + NH)
            e = model.curve.ball_angle(xs[NW + 1:, 1]) - xs[NW + 1:, 0] - psi[i0 + 1:i0 + NH + 1]
            out.append((xs[NW], e if np.all(np.isfinite(e)) else np.full(NH, 0.1)))
        return out

    def report(self, label: str, errs: list) -> None:  # noqa: ANN001
        """RMS over all windows, the braking half-lap (120-20 deg) and the rest."""
        e = np.array([x[1] for x in errs])
        hi = (self.place >= 120) | (self.place < 20)
        print(f"{label:40s} all {np.sqrt(np.mean(e ** 2)):.5f}  120-20 deg "
              f"{np.sqrt(np.mean(e[hi] ** 2)):.5f}  20-120 deg {np.sqrt(np.mean(e[~hi] ** 2)):.5f}",
              flush=True)


def regions(pb: Probe) -> None:
    errs = pb.errors()
    e = np.array([x[1] for x in errs])
    for b in range(0, 180, 30):
        s = (pb.place >= b) & (pb.place < b + 30)
        if s.any():
            print(f"phi {b:3d}-{b + 30:3d} deg: {s.sum():3d} windows, ball "
                  f"{np.sqrt(np.mean(e[s] ** 2)):.5f} rad")


def slip(pb: Probe, mus: str) -> None:
    rigid = pb.errors()
    pb.report("rigid", rigid)
    for mu in (float(m) for m in mus.split(",")):
        cm = ContactModel(pb.params.replace(**{"contact.static_friction": 1.2 * mu,
                                               "contact.dynamic_friction": mu}))
        out = []
        for (z, _), i0 in zip(rigid, pb.starts, strict=True):
            x = cm.state_from_rigid(z, pb.u[i0])
            cm.reset(x)
            rows = []
            for k in range(NH):
                x = cm.step(x, pb.u[i0 + k], pb.dt, 1)
                rows.append(x)
            rr = cm.rigid_state(np.array(rows), z[1])
            model = RigidModel(pb.params)
            out.append((z, model.curve.ball_angle(rr[:, 1]) - rr[:, 0]
                        - pb.psi_w[i0 + 1:i0 + NH + 1]))
        pb.report(f"contact model, mu_d {mu}", out)


def shutter(pb: Probe) -> None:
    xy = pb.prep.ball_xy[:2]
    xc, yc = xy[0] - np.nanmean(xy[0]), xy[1] - np.nanmean(xy[1])
    rate = np.gradient(pb.psi_w, pb.dt)
    for lx, ly in [(0, 0), (0.05, 0), (-0.05, 0), (0, 0.05), (0, -0.05), (0.1, 0), (0, 0.1)]:
        pb.report(f"latency {lx} x + {ly} y [s/m]",
                  pb.errors(psi_w=pb.psi_w + (lx * xc + ly * yc) * rate))


def twist(pb: Probe) -> None:
    for c in (0.0, 0.1, -0.1, 0.3, -0.3):
        pb.report(f"theta + {c} u", pb.errors(theta=pb.theta + c * pb.u))


def scan(pb: Probe) -> None:
    pb.report("as fitted", pb.errors())
    for k, vals in [("ball.mass", [0.0015, 0.002, 0.0045, 0.006]),
                    ("ball.inertia", [1.65e-7, 2.2e-7, 5e-7, 6.6e-7]),
                    ("ball.plate_distance", [0.020, 0.023, 0.028, 0.030]),
                    ("ball.radius", [0.0155, 0.0175])]:
        for v in vals:
            pb.report(f"{k} = {v}", pb.errors(params=pb.params.replace(**{k: v})))


def refit(pb: Probe) -> None:
    names = ["frame.inertia", "ball.inertia", "frame.contour.a", "frame.contour.b",
             "latency", "torque_delay", "ball.plate_distance"]
    sensor_names = ("latency", "torque_delay")

    def value(n: str) -> float:
        if n in sensor_names:
            return getattr(pb.sensor, n)
        obj = pb.params
        for k in n.split("."):
            obj = getattr(obj, k)
        return obj

    x0 = np.array([value(n) for n in names])
    scale = 0.1 * np.where(np.abs(x0) > 0, np.abs(x0), 1e-3)

    def build(z):  # noqa: ANN001, ANN202
        x = x0 + z * scale
        ch = {n: float(v) for n, v in zip(names, x, strict=True) if n not in sensor_names}
        sc = {n: float(v) for n, v in zip(names, x, strict=True) if n in sensor_names}
        return pb.params.replace(**ch), dataclasses.replace(pb.sensor, **sc)

    def fun(z):  # noqa: ANN001, ANN202
        params, sensor = build(z)
        return np.concatenate([e for _, e in pb.errors(params=params, sensor=sensor)])

    z0 = np.zeros(len(names))
    print("start", np.sqrt(np.mean(fun(z0) ** 2)))
    sol = least_squares(fun, z0, diff_step=0.1, max_nfev=15)
    print("end", np.sqrt(np.mean(sol.fun ** 2)), dict(zip(names, x0 + sol.x * scale,
                                                            strict=True)))


if __name__ == "__main__":
    what, name, *rest = sys.argv[1:]
    probe = Probe(name)
    {"regions": regions, "slip": slip, "shutter": shutter, "twist": twist, "scan": scan,
     "refit": refit}[what](probe, *rest)
