"""Fourteenth-round probes of Actually_worked's ball (scratch, kept for the record).

Every probe reads a diagnosis pickled by ``../session6/run.py NAME`` (/tmp/s7/NAME.pkl) and
scores the corrected model's 100 ms ball prediction from a start state fitted to the 100 ms
before each window (the method of ``bfr_diagnose.locate.causal_prediction_errors``), on
every usable window every 50 ms (held out or not). Figures: docs/notes/issue-12.md,
"Thirteenth session". Usage (source tree on PYTHONPATH, scripts/env.sh):

    python probes.py windows NAME            # coupled model, error by place; caches windows
    python probes.py frame NAME              # the ball alone under the measured frame motion
    python probes.py extra NAME              # a constant extra phi_dd per 200 ms window
    python probes.py events NAME             # data - model phi_dot around the braking pulses
    python probes.py quasistatic             # missing phi_dd at rest, fin against AW
    python probes.py scan NAME shift 10,15   # camera time shift [ms]
    python probes.py scan NAME lead 6,12     # frame motion ahead of the encoder [ms]
    python probes.py scan NAME jb 0.4,0.5    # ball inertia ratio J_b / (m R^2)
    python probes.py scan NAME torsion 20,30 # frame behind the encoder through a torsion [Hz]
    python probes.py scan NAME harmonics 16  # contour harmonics 9..K fitted to the camera
    python probes.py slip NAME coulomb 0.15  # friction-limited rolling (Coulomb), mu
    python probes.py slip NAME creep 0.06    # linear creep, time constant [s]
    python probes.py slip NAME capped 0.02/0.15  # creep capped at mu F_n R_b

The ball-alone model (``frame``, ``scan``, ``slip``): theta, theta_dot and theta_ddot are the
measured frame angle's Savitzky-Golay derivatives (11 samples, cubic) and the ball row is
solved for phi_ddot at the measured theta_ddot (the rigid model's accelerations are affine
in the torque: the torque that gives the measured theta_ddot gives the ball's). With slip,
the ball's spin omega_b is a state: the translational row is the rigid model's with J_b = 0
plus the friction's generalized force ``(lam / R) tau_f``, and ``J_b omega_b' = tau_f``
(rolling, ``omega_b = theta_dot - lam phi_dot / R``, gives back the rigid model's row).
"""

from __future__ import annotations

import os
import pickle
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
from bfr_model.dynamics import I_R, RigidModel, rigid_terms
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from bfr_diagnose import locate

DT = 0.002  # grid step of the NTNU logs' preprocessing [s]
NW = NH = 50  # fit window and horizon [samples]


@dataclass
class Rec:
    """One pickled diagnosis and the measured frame motion on its grid."""

    name: str
    d: Any
    prep: Any
    sensor: Any
    theta: np.ndarray
    theta_dot: np.ndarray
    theta_ddot: np.ndarray

    @classmethod
    def load(cls, name: str) -> Rec:
        """The pickle /tmp/s7/NAME.pkl and the frame's derivatives."""
        with open(f"/tmp/s7/{name}.pkl", "rb") as f:
            d = pickle.load(f)
        pr = d.parts[0]
        th = pr.prep.theta + pr.sensor.theta_zero
        return cls(name=name, d=d, prep=pr.prep, sensor=pr.sensor, theta=th,
                   theta_dot=savgol_filter(th, 11, 3, deriv=1, delta=DT),
                   theta_ddot=savgol_filter(th, 11, 3, deriv=2, delta=DT))

    def predictor(self, params: Any = None) -> Any:
        """The diagnosis's predictor (the corrected model unless params are given)."""
        return locate._predictor(self.prep, params or self.d.selection.params, self.sensor,
                                 0.1, 0.05)


def windows(rec: Rec) -> list[dict]:
    """The coupled model's causal windows (cached in /tmp/s14/NAME_windows.pkl)."""
    path = f"/tmp/s14/{rec.name}_windows.pkl"
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    except FileNotFoundError:
        pass
    pred, res = rec.predictor(), rec.d.parts[0].res_after
    rows = []
    for i0 in pred.starts(np.ones(rec.prep.n, bool), lead=NW):
        j = i0 - NW
        guess = np.array([pred.theta[j], res.phi[j], rec.prep.theta_dot[j], res.phi_dot[j]])
        fit = locate._fit_start(pred, guess, j, NW) if np.all(np.isfinite(guess)) else None
        if fit is None:
            continue
        xs = pred.rollout(fit.state, j, NW + NH)
        e = pred.ball_angle(xs)[NW + 1:] - pred.psi_w[i0 + 1:i0 + NH + 1]
        rows.append({"i0": i0, "phi": float(np.degrees(np.mod(xs[NW, 1], np.pi))),
                     "start": xs[0], "rms": float(np.sqrt(np.mean(e ** 2))),
                     "umin": float(np.min(pred.u[i0:i0 + NH + 1]))})
    os.makedirs("/tmp/s14", exist_ok=True)
    with open(path, "wb") as f:
        pickle.dump(rows, f)
    return rows


def by_place(label: str, err: np.ndarray, place: np.ndarray) -> None:
    """Print the RMS over all windows, the braking half-lap (phi >= 110 deg) and the rest."""
    bad = place >= 110
    print(f"{label:44s} all {np.sqrt(np.mean(err ** 2)):.4f}  phi>=110 "
          f"{np.sqrt(np.mean(err[bad] ** 2)):.4f}  rest {np.sqrt(np.mean(err[~bad] ** 2)):.4f}",
          flush=True)


class BallAlone:
    """The ball's row under the measured frame motion, with a contact law.

    ``law``: ``"rolling"``; ``("coulomb", mu)``; ``("creep", tau_s)``; ``("capped", tau_s,
    mu)``. ``extra`` [rad/s^2] is added to phi_ddot (the ``extra`` probe).
    """

    def __init__(self, rec: Rec, params: Any, law: Any = "rolling", lead: int = 0,
                 frame: tuple | None = None) -> None:
        self.rec, self.law = rec, law
        self.full = RigidModel(params)
        self.trans = RigidModel(params.replace(**{"ball.inertia": 1e-15}))
        self.jb, self.rb, self.r = params.ball.inertia, params.ball.radius, self.full.P[I_R]
        th, thd, thdd = frame or (rec.theta, rec.theta_dot, rec.theta_ddot)
        self.th, self.thd, self.thdd = (np.roll(x, -lead) for x in (th, thd, thdd))

    def _acc(self, model: RigidModel, th: float, thd: float, thdd: float, ph: float,
             phd: float) -> tuple[float, float]:
        """(phi_ddot, F_n) of a model at the measured theta_ddot."""
        a0, c0, _, _, f0 = rigid_terms(th, ph, thd, phd, 0.0, *model.kernel_args)
        a1, c1, _, _, f1 = rigid_terms(th, ph, thd, phd, 1.0, *model.kernel_args)
        s = (thdd - a0) / (a1 - a0)
        return c0 + (c1 - c0) * s, f0 + (f1 - f0) * s

    def roll(self, z: np.ndarray, j: int, n: int, extra: float = 0.0, ns: int = 4) -> np.ndarray:
        """The contact angle on the grid from ``z`` at grid sample j.

        ``z = (phi, phi_dot[, omega_b - rolling spin])``.
        """
        ph, phd = float(z[0]), float(z[1])
        curve, r = self.trans.curve, self.r
        w = self.thd[j] - curve.speed(ph) * phd / r + (float(z[2]) if len(z) > 2 else 0.0)
        rolling = self.law == "rolling" or (len(z) <= 2 or z[2] == 0.0)
        out = [ph]
        h = DT / ns
        for k in range(j, j + n):
            for s in range(ns):
                f = s / ns
                th = self.th[k] + f * (self.th[k + 1] - self.th[k])
                td = self.thd[k] + f * (self.thd[k + 1] - self.thd[k])
                tdd = self.thdd[k] + f * (self.thdd[k + 1] - self.thdd[k])
                lam = curve.speed(ph)
                a_r, fn = self._acc(self.full, th, td, tdd, ph, phd)
                if self.law == "rolling":
                    phd += h * (a_r + extra)
                    ph += h * phd
                    continue
                kind = self.law[0]
                cap = self.law[-1] * max(fn, 0.0) * self.rb
                if kind == "coulomb" and rolling:
                    dlam = (curve.speed(ph + 1e-5) - lam) / 1e-5
                    tau = self.jb * (tdd - (dlam * phd ** 2 + lam * a_r) / r)
                    if abs(tau) <= cap:  # rolling holds
                        phd += h * a_r
                        ph += h * phd
                        w = td + h * tdd - curve.speed(ph) * phd / r
                        continue
                    rolling, w, tau = False, td - lam * phd / r, np.sign(tau) * cap
                    rel = 0.0
                else:
                    rel = w - (td - lam * phd / r)
                    tau = -self.jb / self.law[1] * rel if kind != "coulomb" else \
                        -np.sign(rel) * cap
                    if kind == "capped":
                        tau = min(max(tau, -cap), cap)
                m22 = self.trans.mass_matrix(ph)[1, 1]
                a = self._acc(self.trans, th, td, tdd, ph, phd)[0] + (lam / r) * tau / m22
                w += h * tau / self.jb
                phd += h * a
                ph += h * phd
                if kind == "coulomb" and rel != 0.0:  # the relative spin crossed zero: stick
                    rolling = rel * (w - (td + h * tdd - curve.speed(ph) * phd / r)) <= 0
                    if rolling:
                        w = td + h * tdd - curve.speed(ph) * phd / r
            if not np.isfinite(ph) or abs(phd) > 100:
                return np.full(n + 1, np.nan)
            out.append(ph)
        return np.array(out)

    def errors(self, rows: list[dict], psi_w: np.ndarray, fit_spin: bool = False,
               fit_extra: bool = False) -> tuple[np.ndarray, list]:
        """Per window: RMS ball-angle error over the horizon (fit on the window before)."""
        ang = self.trans.curve.ball_angle
        th = self.rec.theta
        err, fits = [], []
        for row in rows:
            i0 = row["i0"]
            j = i0 - NW
            meas = psi_w[j:i0 + NH + 1] + th[j:i0 + NH + 1]
            z0 = [row["start"][1], row["start"][3]] + ([0.0] if fit_spin else [])
            scale = [1e-3, 0.1] + ([1.0] if fit_spin else [])
            if fit_extra:
                def fun(z, j=j, meas=meas):  # noqa: ANN001, ANN202
                    return np.nan_to_num(ang(self.roll(z[:2], j, NW + NH, z[2])) - meas, nan=1.0)
                z = least_squares(fun, np.r_[z0, 0.0], x_scale=[*scale, 5.0], method="lm").x
                e = ang(self.roll(z[:2], j, NW + NH, z[2])) - meas
                fits.append(z)
                err.append(np.sqrt(np.mean(e ** 2)))
                continue

            def fun(z, j=j, meas=meas):  # noqa: ANN001, ANN202
                return np.nan_to_num(ang(self.roll(z, j, NW)) - meas[:NW + 1], nan=1.0)
            z = least_squares(fun, np.array(z0), x_scale=scale, method="lm").x
            ps = self.roll(z, j, NW + NH)
            e = ang(ps[NW + 1:]) - meas[NW + 1:] if np.all(np.isfinite(ps)) else np.full(NH, .3)
            fits.append(z)
            err.append(np.sqrt(np.mean(e ** 2)))
        return np.array(err), fits


def missing_phi_ddot(rec: Rec, width: int = 31) -> dict[str, np.ndarray]:
    """Measured minus model phi_ddot at the measured states (both smoothed over ``width``)."""
    res = rec.d.parts[0].res_after
    ph = res.phi
    ok = np.isfinite(ph)
    phd = savgol_filter(np.nan_to_num(ph), 11, 3, deriv=1, delta=DT)
    ball = BallAlone(rec, rec.d.selection.params)
    model = np.full(ph.size, np.nan)
    for k in np.where(ok)[0]:
        model[k] = ball._acc(ball.full, rec.theta[k], rec.theta_dot[k], rec.theta_ddot[k],
                             ph[k], phd[k])[0]
    data = savgol_filter(np.nan_to_num(ph), width, 3, deriv=2, delta=DT)
    okw = np.convolve((ok & np.isfinite(model)).astype(float), np.ones(width), "same")
    okw = okw >= width - 0.5
    dd = np.where(okw, data - savgol_filter(np.nan_to_num(model), width, 3), np.nan)
    return {"dd": dd, "phi": ph, "model": model,
            "phi_dot": savgol_filter(np.nan_to_num(ph), 21, 3, deriv=1, delta=DT)}


def main(argv: list[str]) -> None:
    """Run one probe (module docstring)."""
    what = argv[0]
    if what == "quasistatic":
        for name in ("Actually_worked", "fin"):
            rec = Rec.load(name)
            m = missing_phi_ddot(rec)
            qs = np.isfinite(m["dd"]) & (np.abs(rec.theta_dot) < 1.5) & \
                (np.abs(rec.theta_ddot) < 30)
            pb = np.degrees(np.mod(m["phi"], np.pi))
            tb = np.degrees(np.mod(rec.theta, np.pi))
            print(name, "quasi-static samples", int(qs.sum()))
            for p0 in range(0, 180, 20):
                cells = []
                for t0 in range(0, 180, 30):
                    s = qs & (pb >= p0) & (pb < p0 + 20) & (tb >= t0) & (tb < t0 + 30)
                    cells.append(f"{np.nanmean(m['dd'][s]):6.1f}({s.sum():4d})" if s.sum() > 20
                                 else "     .      ")
                print(f"  phi {p0:3d}: " + " ".join(cells))
        return
    rec = Rec.load(argv[1])
    rows = windows(rec)
    place = np.array([r["phi"] for r in rows])
    if what == "windows":
        err = np.array([r["rms"] for r in rows])
        by_place("coupled model, corrected", err, place)
        for b in range(0, 180, 20):
            s = (place >= b) & (place < b + 20)
            print(f"  phi {b:3d}-{b + 20:3d}: {s.sum():3d} windows, ball "
                  f"{np.sqrt(np.mean(err[s] ** 2)):.4f} rad, braking in "
                  f"{np.mean([r['umin'] < -0.05 for r, k in zip(rows, s, strict=True) if k]):.2f}")
        return
    pred = rec.predictor()
    if what == "frame":
        err, _ = BallAlone(rec, rec.d.selection.params).errors(rows, pred.psi_w)
        by_place("ball alone under the measured frame", err, place)
        return
    if what == "extra":
        sub = rows[::2]
        err, fits = BallAlone(rec, rec.d.selection.params).errors(sub, pred.psi_w,
                                                                   fit_extra=True)
        a = np.array([z[2] for z in fits])
        p = place[::2]
        for b in range(0, 180, 15):
            s = (p >= b) & (p < b + 15)
            if s.any():
                print(f"  phi {b:3d}: {s.sum():3d} windows, extra phi_dd median "
                      f"{np.median(a[s]):6.2f}"
                      f" IQR [{np.percentile(a[s], 25):6.2f}, {np.percentile(a[s], 75):6.2f}]"
                      f", 200 ms fit RMS {np.sqrt(np.mean(err[s] ** 2)):.4f}")
        return
    if what == "events":
        m = missing_phi_ddot(rec)
        u = pred.u
        on = np.where((u[1:] < -0.05) & (u[:-1] >= -0.05))[0]
        pre, post = 50, 150
        diffs = []
        for i in on:
            seg = m["model"][i - pre:i + post]
            if i - pre < 0 or i + post >= u.size or not np.all(np.isfinite(seg)):
                continue
            dat = m["phi_dot"][i - pre:i + post] - m["phi_dot"][i - pre]
            mod = np.concatenate([[0.0], np.cumsum(seg[:-1]) * DT])
            diffs.append(dat - mod)
        diffs = np.array(diffs)
        print(f"{len(diffs)} braking onsets (u < -0.05 N m): data - model phi_dot change [rad/s]")
        for ms in (0, 40, 80, 120, 160, 200, 290):
            k = pre + ms // 2
            print(f"  {ms:4d} ms: {diffs[:, k].mean():+.2f} +- "
                  f"{diffs[:, k].std() / np.sqrt(len(diffs)):.2f}")
        return
    sub = rows[::2]
    psub = place[::2]
    base = rec.d.selection.params
    values = argv[3].split(",") if len(argv) > 3 else []
    if what == "scan":
        kind = argv[2]
        by_place("rolling, corrected", BallAlone(rec, base).errors(sub, pred.psi_w)[0], psub)
        for v in values:
            if kind == "shift":
                psi = np.interp(rec.prep.t + float(v) / 1000, rec.prep.t, pred.psi_w)
                err = BallAlone(rec, base).errors(sub, psi)[0]
            elif kind == "lead":
                err = BallAlone(rec, base, lead=round(float(v) / 2)).errors(sub, pred.psi_w)[0]
            elif kind == "jb":
                p = base.replace(**{"ball.inertia": float(v) * base.ball.mass
                                    * base.ball.radius ** 2})
                err = BallAlone(rec, p).errors(sub, pred.psi_w)[0]
            elif kind == "torsion":
                frame = _torsion(rec, float(v), 0.1)
                err = BallAlone(rec, base, frame=frame).errors(sub, pred.psi_w)[0]
            elif kind == "harmonics":
                p = _harmonics(rec, base, int(v))
                err = BallAlone(rec, p).errors(sub, rec.predictor(p).psi_w)[0]
            by_place(f"{kind} {v}", err, psub)
        return
    if what == "slip":
        kind = argv[2]
        p = base.replace(**{"ball.inertia": 5.48e-7})  # the seed's hollow ball
        by_place("rolling, seed J_b", BallAlone(rec, p).errors(sub, pred.psi_w)[0], psub)
        for v in values:
            law = (kind, *[float(x) for x in v.split("/")])
            for fit_spin in (False, True):
                err = BallAlone(rec, p, law=law).errors(sub, pred.psi_w, fit_spin=fit_spin)[0]
                by_place(f"{kind} {v}{', start slip fitted' if fit_spin else ''}", err, psub)
        return
    raise SystemExit(f"unknown probe {what!r}")


def _torsion(rec: Rec, hz: float, zeta: float) -> tuple:
    """A frame behind the encoder through a torsion of ``hz`` [Hz] and damping ``zeta``."""
    w = 2 * np.pi * hz
    n = rec.theta.size
    sub = 20
    h = DT / sub
    x, v = rec.theta[0], rec.theta_dot[0]
    out = np.empty((n, 3))
    for k in range(n):
        k1 = min(k + 1, n - 1)
        for s in range(sub):
            f = s / sub
            te = rec.theta[k] + f * (rec.theta[k1] - rec.theta[k])
            ve = rec.theta_dot[k] + f * (rec.theta_dot[k1] - rec.theta_dot[k])
            a = w * w * (te - x) + 2 * zeta * w * (ve - v)
            v += h * a
            x += h * v
        out[k] = (x, v, a)
    return out[:, 0], out[:, 1], out[:, 2]


def _harmonics(rec: Rec, params: Any, kmax: int) -> Any:
    """Contour harmonics 9..kmax fitted to the camera's ball distance (three passes)."""
    ks = list(range(9, kmax + 1))
    for _ in range(3):
        pred = rec.predictor(params)
        m = pred.model
        phs = np.linspace(0, 2 * np.pi, 40001)
        pos = m.ball_position(np.column_stack([0 * phs, phs, 0 * phs, 0 * phs]))
        rho_m = np.hypot(pos[:, 0], pos[:, 1])
        ba = m.curve.ball_angle(phs)
        psi_f = pred.psi_w + pred.theta
        ok = np.isfinite(psi_f) & np.isfinite(pred.rho) & rec.prep.ball_ok
        x = np.mod(psi_f[ok] - ba[0], 2 * np.pi) + ba[0]
        o = np.argsort(ba)
        r = pred.rho[ok] - np.interp(x, ba[o], rho_m[o])
        phi = np.interp(x, ba[o], phs[o])
        cols = np.column_stack([f(k * phi) for k in ks for f in (np.cos, np.sin)])
        beta = np.linalg.lstsq(cols, r - np.median(r), rcond=None)[0]
        print(f"  harmonics: distance residual {1000 * np.std(r):.3f} mm; amplitudes [mm] "
              + ", ".join(f"{k}: {1000 * np.hypot(beta[2 * i], beta[2 * i + 1]):.3f}"
                          for i, k in enumerate(ks)))
        c = params.frame.contour
        orders, cs, ss = list(c.harmonic_orders), list(c.harmonic_cos), list(c.harmonic_sin)
        for i, k in enumerate(ks):
            if k in orders:
                q = orders.index(k)
                cs[q] += float(beta[2 * i])
                ss[q] += float(beta[2 * i + 1])
            else:
                orders.append(k)
                cs.append(float(beta[2 * i]))
                ss.append(float(beta[2 * i + 1]))
        params = params.replace(**{"frame.contour.harmonic_orders": tuple(orders),
                                   "frame.contour.harmonic_cos": tuple(cs),
                                   "frame.contour.harmonic_sin": tuple(ss)})
    return params


if __name__ == "__main__":
    main(sys.argv[1:])
