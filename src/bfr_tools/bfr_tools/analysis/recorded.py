"""Energy along real recordings (the seed's recommendation 2).

The seed ends (section 5.2, recommendation 2): "the energy input can fairly easily be
derived from the energy consumption of the motor [and] compared with the energy
fluctuations as described in Chapter 2 and with the ideal energy input. The discrepancy can
be used to further investigate the impact of the small scale perturbations". A recording
of the rig holds the commanded torque u, the frame's angle and speed and the camera's ball
fixes, so along the recorded states ``x = [theta, phi, theta_dot, phi_dot]``:

==================  ============================================  ============================
quantity            definition                                    source
==================  ============================================  ============================
motor work          ``W_m(t) = int k_u u theta_dot dt``           the recording, the model's
                                                                  torque gain
ideal energy input  ``E_in(t) = E(x(t)) - E(x(t0))``, E = T + V   seed eq. 2.3, the model's
                    of the model                                  exact Lagrangian
model dissipation   ``W_d(t) = int P_diss(x, u) dt``              the model's friction terms
                                                                  (0 in the nominal model)
discrepancy         ``D(t) = W_m - E_in - W_d``                   what the model leaves out
==================  ============================================  ============================

D is evaluated per turn of the frame (the increase between its averages over half turns one
turn apart: :func:`_rates`; per second where the frame makes no two full turns) and over the
run, once with the nominal model (rig.yaml: no
dissipation, so D is all the motor's work that the ideal system cannot store) and once
with ``bfr diagnose``'s correction (its ``corrected_params.yaml``: fitted inertia, friction,
torque gain; a file of today's tool or of a later one, whatever physics it adds to the
rigid model). Beside it, the chapter-2 perturbation energies at the seed's magnitudes
(:func:`bfr_tools.analysis.energy.energy_analysis`, evaluated along the recorded states):
the dissipative ones (E_rol, E_joint) remove energy every turn and could explain D if their
loss per turn reaches half of it; the conservative ones (E_mass, E_rot, E_pot, E_ela, E_tr,
E_ell, E_g) return to their value every turn: they cannot explain a steady loss, only a
fluctuation of D about its trend (compared by their median peak-to-peak per turn). Also
reported: what it would take, the joint Coulomb torque ``D / int |theta_dot| dt`` or the
rolling resistance ``D / int F_n |s_dot| dt`` that would account for D alone.

States: the recording is smoothed onto a 2 ms grid by the diagnosis' preprocessing
(:func:`bfr_diagnose.preprocess.prepare`: the servo's speed re-timed and fused with the
angle, the ball's world angle from the fixes). The contact angle is the model's inverse of
the ball-centre angle ``psi = theta + psi_w`` (round ball: ``OffsetCurve.
phi_from_ball_angle``) and ``phi_dot = psi_dot / psi'(phi)``. Without ball fixes (the
friction and step runs, a ball lost early) the same model without the ball (mass 1e-12 kg)
gives the frame's energy and friction. Only the samples inside the preprocessing's usable
segments count; integrals restart in each segment and are summed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from bfr_diagnose.preprocess import Prepared, prepare, segments_from_mask
from bfr_model.dynamics import RigidModel, rigid_terms
from bfr_model.params import RigParams
from bfr_model.perturbations import StudySettings
from bfr_model.recording import Recording
from numpy.typing import NDArray

from bfr_tools.analysis.energy import SEED, energy_analysis, rigid_forces
from bfr_tools.analysis.trajectory import Trajectory

__all__ = [
    "DISSIPATIVE",
    "EnergyTrack",
    "analyze_recording",
    "energy_track",
    "frame_only",
    "plot_recorded",
    "recorded_states",
]

FloatArray = NDArray[np.float64]

#: Chapter-2 terms that remove energy every turn (the others are state functions).
DISSIPATIVE = ("E_rol", "E_joint")
#: A perturbation "could explain" the discrepancy when it reaches this share of it.
EXPLAINS = 0.5
#: Ball mass standing in for "no ball" in the frame-only model [kg].
NO_BALL_MASS = 1e-12


def frame_only(params: RigParams) -> RigParams:
    """``params`` with a negligible ball: the rigid model of the frame alone.

    Every ball term of the Lagrangian and the friction vanishes with the ball's mass and
    inertia; the frame's inertia, joint friction (with the frame's weight as bearing load)
    and torque gain remain, from the one model (:mod:`bfr_model.dynamics`).
    """
    return params.replace(**{"ball.mass": NO_BALL_MASS,
                             "ball.inertia": NO_BALL_MASS * 1e-4})


@dataclass(frozen=True)
class RecordedStates:
    """Model states along a recording's usable segments.

    Attributes
    ----------
    segments : list of (t, x, u)
        Per segment: times [s], states ``[theta, phi, theta_dot, phi_dot]`` and the
        commanded torque [N m].
    has_ball : bool
        Whether phi comes from ball fixes (else 0: frame only).
    """

    segments: list[tuple[FloatArray, FloatArray, FloatArray]]
    has_ball: bool


def recorded_states(prep: Prepared, params: RigParams, min_len: int = 50) -> RecordedStates:
    """States of the model ``params`` along the usable segments of a preprocessed recording.

    With the ball: the segments where ``prep.ball_ok``; phi from the ball-centre angle by the
    model's curve (module docstring). Without: ``prep.frame_ok``, phi = phi_dot = 0. Segments
    shorter than ``min_len`` samples are left out.
    """
    mask = prep.usable
    curve = RigidModel(params).curve
    out = []
    for i0, i1 in segments_from_mask(mask):
        if i1 - i0 < min_len:
            continue
        sl = slice(i0, i1)
        th, thd, u = prep.theta[sl], prep.theta_dot[sl], prep.u[sl]
        if prep.has_ball:
            psi = th + prep.psi_w[sl]
            phi = curve.phi_from_ball_angle(psi)
            p, p1 = curve.derivatives(phi)[:2]
            dpsi = ((p[..., 1] * p1[..., 0] - p[..., 0] * p1[..., 1])
                    / (p[..., 0] ** 2 + p[..., 1] ** 2))
            phid = (thd + prep.psi_w_dot[sl]) / dpsi
        else:
            phi = np.zeros_like(th)
            phid = np.zeros_like(th)
        out.append((prep.t[sl], np.stack([th, phi, thd, phid], axis=1), u))
    return RecordedStates(segments=out, has_ball=prep.has_ball)


def _cumulative(rate: FloatArray, t: FloatArray) -> FloatArray:
    return np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])


@dataclass(frozen=True)
class EnergyTrack:
    """Motor work, ideal energy input, model dissipation along the segments [J].

    Each array is per segment, starting at 0 (module docstring).
    """

    label: str
    source: str
    t: list[FloatArray]
    theta: list[FloatArray]
    motor_work: list[FloatArray]
    energy_in: list[FloatArray]
    dissipation: list[FloatArray]
    normal_force: list[FloatArray]
    path_speed: list[FloatArray]

    @property
    def discrepancy(self) -> list[FloatArray]:
        """``W_m - E_in - W_d`` per segment [J]."""
        return [w - e - d for w, e, d in
                zip(self.motor_work, self.energy_in, self.dissipation, strict=True)]

    def total(self, name: str) -> float:
        """Sum over the segments of the final value of ``name`` [J]."""
        return float(sum(a[-1] for a in getattr(self, name)))


def energy_track(states: RecordedStates, params: RigParams, label: str, source: str
                 ) -> EnergyTrack:
    """The energy balance of the model ``params`` along recorded states (module docstring)."""
    p = params if states.has_ball else frame_only(params)
    model = RigidModel(p)
    cols: dict[str, list[FloatArray]] = {k: [] for k in (
        "t", "theta", "motor_work", "energy_in", "dissipation", "normal_force", "path_speed")}
    for t, x, u in states.segments:
        kin, pot = model.energy(x)
        e = kin + pot
        _, _, p_in, p_diss, fn = rigid_terms(x[:, 0], x[:, 1], x[:, 2], x[:, 3], u,
                                             *model.kernel_args)
        cols["t"].append(t)
        cols["theta"].append(x[:, 0])
        cols["motor_work"].append(_cumulative(p_in, t))
        cols["energy_in"].append(e - e[0])
        cols["dissipation"].append(_cumulative(p_diss, t))
        cols["normal_force"].append(np.asarray(fn, float))
        cols["path_speed"].append(np.abs(model.curve.speed(x[:, 1]) * x[:, 3]))
    return EnergyTrack(label=label, source=source, **cols)


def _turn_marks(theta: FloatArray, step: float = 2.0 * np.pi) -> NDArray[np.intp]:
    """Indices where theta first reaches ``theta[0] + step k`` (k = 1, 2, ...; or -step k)."""
    direction = 1.0 if theta[-1] >= theta[0] else -1.0
    top = np.maximum.accumulate(direction * (theta - theta[0]))
    levels = np.arange(1, int(np.floor(top[-1] / step)) + 1) * step
    return np.searchsorted(top, levels).astype(np.intp)


def _basis(track: EnergyTrack) -> str:
    """``"turn"`` when the segments hold two full frame turns or more, else ``"second"``."""
    turns = sum(_turn_marks(th).size for th in track.theta)
    return "turn" if turns >= 2 else "second"


def _rates(track: EnergyTrack, series: list[FloatArray], basis: str) -> FloatArray:
    """A cumulative series' increase per turn (or per second) [J].

    Per turn: the series averaged over each half turn of the frame (the closed loop's period:
    ``Theta(phi + pi) = Theta(phi) + pi``), then the increase between the averages one turn
    apart, so the fluctuation within the period cancels. Per second: the least-squares slope
    of each segment.
    """
    out: list[float] = []
    for th, t, a in zip(track.theta, track.t, series, strict=True):
        if basis == "turn":
            marks = np.concatenate([[0], _turn_marks(th, np.pi)])
            means = np.array([np.mean(a[i0:i1]) for i0, i1 in itertools.pairwise(marks)
                              if i1 > i0])
            out += list(means[2:] - means[:-2])
        elif t.size > 2:
            out.append(float(np.polyfit(t - t[0], a, 1)[0]))
    return np.asarray(out, float)


def _amplitude(track: EnergyTrack, series: list[FloatArray], basis: str) -> float:
    """The series' peak-to-peak about its trend: median over turns (or over the segments)."""
    amps = []
    for th, t, a in zip(track.theta, track.t, series, strict=True):
        marks = (np.concatenate([[0], _turn_marks(th), [th.size - 1]]) if basis == "turn"
                 else np.array([0, th.size - 1]))
        for i0, i1 in itertools.pairwise(marks):
            if i1 - i0 < 10:
                continue
            seg = a[i0:i1 + 1]
            fit = np.polyval(np.polyfit(t[i0:i1 + 1] - t[i0], seg, 1), t[i0:i1 + 1] - t[i0])
            amps.append(float(np.ptp(seg - fit)))
    return float(np.median(amps)) if amps else math.nan


def _balance(track: EnergyTrack) -> dict[str, Any]:
    """Totals, rates per turn (or second), mean powers and equivalent friction of a track."""
    disc = track.discrepancy
    dur = float(sum(t[-1] - t[0] for t in track.t))
    basis = _basis(track)
    series = {"motor_work": track.motor_work, "energy_in": track.energy_in,
              "dissipation": track.dissipation, "discrepancy": disc}
    rates = {k: _rates(track, v, basis) for k, v in series.items()}
    d_tot = float(sum(a[-1] for a in disc))
    abs_th = float(sum(np.sum(np.abs(np.diff(th))) for th in track.theta))  # int |theta'|
    rolled = float(sum(_cumulative(np.maximum(fn, 0.0) * v, t)[-1] for fn, v, t in
                       zip(track.normal_force, track.path_speed, track.t, strict=True)))

    def stats(a: FloatArray) -> dict[str, float | None]:
        return {"mean": float(np.mean(a)) if a.size else None,
                "std": float(np.std(a)) if a.size > 1 else None}

    return {
        "label": track.label, "params": track.source, "duration": dur,
        "motor_work": track.total("motor_work"), "energy_in": track.total("energy_in"),
        "model_dissipation": track.total("dissipation"), "discrepancy": d_tot,
        "basis": basis, "count": int(rates["discrepancy"].size),
        "rate": {k: stats(v) for k, v in rates.items()},
        "mean_power": {"motor": track.total("motor_work") / dur if dur else None,
                       "discrepancy": d_tot / dur if dur else None},
        "equivalent": {"joint_coulomb_torque": d_tot / abs_th if abs_th > 1e-9 else None,
                       "rolling_resistance": d_tot / rolled if rolled > 1e-12 else None},
    }


def _perturbations(states: RecordedStates, params: RigParams, study: StudySettings,
                   nominal: EnergyTrack, measured: dict[str, Any]) -> dict[str, Any]:
    """The chapter-2 energies at the seed's magnitudes along the recorded states."""
    p = params if states.has_ball else frame_only(params)
    terms: dict[str, dict[str, list[FloatArray]]] = {}
    titles: dict[str, str] = {}
    for t, x, u in states.segments:
        rep = energy_analysis(Trajectory(t, x, u, label="recording"), p, study)
        for sym, term in rep.terms.items():
            terms.setdefault(sym, {"seed": [], "exact": []})
            terms[sym]["seed"].append(term.seed - term.seed[0])
            terms[sym]["exact"].append(term.exact - term.exact[0])
            titles[sym] = term.title
    basis = measured["basis"]
    loss = measured["rate"]["discrepancy"]["mean"]
    amp_meas = _amplitude(nominal, nominal.discrepancy, basis)
    out: dict[str, Any] = {"basis": basis, "measured_loss": loss,
                           "measured_amplitude": amp_meas}
    ball_terms = {"E_rol", "E_rot", "E_tr", "E_pot", "E_ela", "E_ell", "E_g"}
    rows = {}
    for sym, kinds in terms.items():
        applies = states.has_ball or sym not in ball_terms
        row: dict[str, Any] = {"title": titles[sym], "applies": applies,
                               "kind": "dissipative" if sym in DISSIPATIVE else "conservative"}
        for kind, arrs in kinds.items():
            r = _rates(nominal, arrs, basis)
            row[kind] = {"rate": float(np.mean(r)) if r.size else None,
                         "amplitude": _amplitude(nominal, arrs, basis)}
        row["verdict"] = _verdict(row, loss, amp_meas, basis)
        rows[sym] = row
    out["terms"] = rows
    return out


def _verdict(row: dict[str, Any], loss: float | None, amp_meas: float, basis: str) -> str:
    """Whether the term could explain the loss (or only a fluctuation about it)."""
    if not row["applies"]:
        return "does not apply: no ball in the recording"
    s = row["seed"]
    if loss is None or not math.isfinite(loss) or loss <= 0.0:
        return (f"no loss per {basis} to explain (the motor supplied less than the ideal "
                "system gained: its inertia is too large, or the motor's gain too small)")
    if row["kind"] == "dissipative":
        per = abs(s["rate"] or 0.0)
        if per <= 1e-9 * loss:
            return "cannot explain the loss: none along this recording (nothing it acts on)"
        ratio = per / loss
        if ratio >= EXPLAINS:
            return f"could explain the loss: {ratio:.2g} of it per {basis}"
        return (f"cannot explain the loss: {ratio:.2g} of it per {basis} "
                f"(would need {loss / max(per, 1e-300):.3g} times the seed's magnitude)")
    amp = s["amplitude"]
    flu = (f"; its fluctuation is {amp / amp_meas:.2g} of the discrepancy's"
           if math.isfinite(amp) and amp_meas > 0.0 else "")
    return f"cannot explain the loss: conservative, no net energy per {basis}" + flu


@dataclass
class RecordedEnergy:
    """Result of :func:`analyze_recording`: the JSON-ready figures and the tracks."""

    figures: dict[str, Any]
    nominal: EnergyTrack
    corrected: EnergyTrack | None
    plots: list[Path] = field(default_factory=list)


def analyze_recording(rec: Recording, nominal: RigParams, study: StudySettings,
                      corrected: RigParams | None = None, *, label: str = "",
                      nominal_source: str = "rig.yaml", corrected_source: str = ""
                      ) -> RecordedEnergy:
    """Motor work, ideal energy input and their discrepancy along one recording.

    Parameters
    ----------
    rec : Recording
        A recording of the rig (any reader of :func:`bfr_model.io.read_recording`).
    nominal : RigParams
        The nominal model (rig.yaml).
    study : StudySettings
        The chapter-2 perturbation magnitudes (the seed's by default).
    corrected : RigParams, optional
        ``bfr diagnose``'s correction for this recording.
    label, nominal_source, corrected_source : str
        Names for the report.

    Returns
    -------
    RecordedEnergy
        Figures (module docstring) and the energy tracks.
    """
    prep = prepare(rec)
    states = recorded_states(prep, nominal)
    if not states.segments:
        raise ValueError(f"{label or 'recording'}: no usable segment of 0.1 s or more")
    nom = energy_track(states, nominal, "nominal", nominal_source)
    figs: dict[str, Any] = {
        "recording": label, "duration": rec.duration, "has_ball": states.has_ball,
        "ball_note": (prep.info.get("ball") if states.has_ball else
                      "no usable ball fixes: the frame alone"),
        "segments": len(states.segments),
        "analysed": float(sum(t[-1] - t[0] for t, _, _ in states.segments)),
        "frame_turns": float(sum(abs(x[-1, 0] - x[0, 0]) for _, x, _ in states.segments)
                             / (2.0 * np.pi)),
        "nominal": _balance(nom)}
    cor = None
    if corrected is not None:
        cor = energy_track(recorded_states(prep, corrected), corrected, "corrected",
                           corrected_source)
        figs["corrected"] = _balance(cor)
        d0, d1 = figs["nominal"]["discrepancy"], figs["corrected"]["discrepancy"]
        figs["corrected"]["share_left"] = abs(d1) / abs(d0) if d0 else None
    figs["perturbations"] = _perturbations(states, nominal, study, nom, figs["nominal"])
    figs["seed"] = {"fraction_of_controller": SEED["fraction_of_controller"]}
    forces = [rigid_forces(RigidModel(nominal if states.has_ball else frame_only(nominal)),
                           Trajectory(t, x, u)) for t, x, u in states.segments]
    figs["bearing_load_mean"] = float(np.mean(np.concatenate([f["F_load"] for f in forces])))
    return RecordedEnergy(figures=figs, nominal=nom, corrected=cor)


def plot_recorded(res: RecordedEnergy, out_dir: Path, stem: str) -> list[Path]:
    """Figures in the seed's style (Fig. 2.2-2.4) for one recording, PNGs in out_dir."""
    import matplotlib  # noqa: PLC0415 - optional heavy: plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - optional heavy: plots only

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    nom, cor = res.nominal, res.corrected
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for s, t in enumerate(nom.t):
        first = s == 0
        ax[0].plot(t, nom.motor_work[s], color="C0", lw=1.0,
                   label="motor work W_m = int u theta_dot dt" if first else None)
        ax[0].plot(t, nom.energy_in[s], color="C1", lw=0.8,
                   label="ideal input E_in (seed eq. 2.3), nominal" if first else None)
        if cor is not None:
            ax[0].plot(cor.t[s], cor.energy_in[s] + cor.dissipation[s], color="C2", lw=0.8,
                       label="E_in + W_diss, corrected model" if first else None)
        dt = np.diff(t)
        ax[1].plot(t[:-1], np.diff(nom.motor_work[s]) / dt, color="C0", lw=0.4,
                   label="motor power" if first else None)
        ax[1].plot(t[:-1], np.diff(nom.energy_in[s]) / dt, color="C1", lw=0.4,
                   label="dE_in/dt (eq. 2.13)" if first else None)
    ax[0].set(xlabel="t [s]", ylabel="energy [J]", title="(a) energy input")
    ax[1].set(xlabel="t [s]", ylabel="power [W]", title="(b) its fluctuation")
    ax[0].legend(fontsize=7)
    ax[1].legend(fontsize=7)
    fig.suptitle(f"{stem}: motor work and the ideal energy input (cf. seed Fig. 2.2)")
    fig.tight_layout()
    paths.append(out_dir / f"{stem}_energy_input.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for s, t in enumerate(nom.t):
        ax.plot(t, nom.discrepancy[s], color="C3", lw=1.0,
                label="W_m - E_in, nominal model" if s == 0 else None)
        if cor is not None:
            ax.plot(cor.t[s], cor.discrepancy[s], color="C2", lw=1.0,
                    label="W_m - E_in - W_diss, corrected" if s == 0 else None)
        for i in _turn_marks(nom.theta[s]):
            ax.axvline(t[i], color="0.85", lw=0.5, zorder=0)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set(xlabel="t [s] (grey: frame turns)", ylabel="energy [J]",
           title=f"{stem}: energy the model does not account for")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{stem}_energy_discrepancy.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    f = res.figures
    pt = f["perturbations"]
    names, vals, colors = [], [], []

    def bar(name: str, v: float | None, c: str) -> None:
        if v is not None and math.isfinite(v) and abs(v) > 0.0:
            names.append(name)
            vals.append(abs(v))
            colors.append(c)

    basis = pt["basis"]
    bar("measured loss\n(nominal)", f["nominal"]["rate"]["discrepancy"]["mean"], "C3")
    bar("its p-p\nabout the trend", pt["measured_amplitude"], "salmon")
    if "corrected" in f:
        bar("|left| after\ncorrection", f["corrected"]["rate"]["discrepancy"]["mean"], "C2")
    for sym, row in pt["terms"].items():
        if not row["applies"]:
            continue
        if row["kind"] == "dissipative":
            bar(f"{sym}\n(loss)", row["seed"]["rate"], "C0")
        else:
            bar(f"{sym}\n(p-p)", row["seed"]["amplitude"], "C7")
    fig, ax = plt.subplots(figsize=(11, 4.2))
    if vals:
        ax.bar(range(len(vals)), vals, color=colors)
        ax.set_xticks(range(len(vals)), names, fontsize=7)
        ax.set_yscale("log")
    unit = "frame turn [J]" if basis == "turn" else "second [W]"
    ax.set(ylabel=f"energy per {unit}",
           title=f"{stem}: per {basis}, the measured loss beside the seed's perturbation "
                 "energies (cf. Fig. 2.3-2.4)")
    fig.tight_layout()
    paths.append(out_dir / f"{stem}_energy_per_{basis}.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
