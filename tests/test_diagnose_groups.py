"""The group test of ``bfr diagnose``: an effect that shows in some recordings of a rig only.

The rig's drive has a small torque offset and its joint a dry friction. Six long recordings
turn one way only (there the offset is indistinguishable from the friction: only their
difference acts), two short ones turn both ways (there the two separate). In the pooled
held-out gain the offset is a share of all eight recordings' cost and falls under its
threshold; scored per recording, it is significant in the two that can see it and hurts
none of the others. The clean controls: the same eight recordings without offset (nothing
but the friction found) and without anything (nothing found).

The recordings come from a generator of this file, not bfr's simulator: the frame alone
(no ball), semi-implicit Euler at 0.2 ms, a PI speed loop at the logger's 500 Hz, an
encoder of 4096 counts and a noisy logged velocity.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from bfr_diagnose.api import DiagnoseOptions, diagnose_recordings
from bfr_model.params import RigParams
from bfr_model.recording import Recording


def frame_run(*, inertia: float, torque_offset: float, coulomb: float, both_ways: bool,
              duration: float, rng: np.random.Generator, rate: float = 250.0,
              counts: int = 4096, vel_noise: float = 0.02) -> Recording:
    """One frame-only run under a PI speed loop: a speed sine through zero (``both_ways``)
    or about +3 rad/s; torque = command + offset - friction, ``J theta'' = torque``."""
    h = 4e-4
    sub = round(1.0 / (rate * h))
    th = om = integ = u = 0.0
    ts, ths, us = [], [], []
    ph = float(rng.uniform(0.0, 2.0 * math.pi))
    mean, amp = (0.0, 3.0) if both_ways else (3.0, 1.5)
    for k in range(round(duration / h)):
        t = k * h
        if k % sub == 0:
            e = mean + amp * math.sin(2.0 * math.pi * t / 4.0 + ph) - om
            integ += e / rate
            u = min(max(0.02 * e + 0.05 * integ, -0.1), 0.1)
            ts.append(t)
            ths.append(th)
            us.append(u)
        om += h * (u + torque_offset - coulomb * math.tanh(om / 1e-3)) / inertia
        th += h * om
    t = np.array(ts)
    q = 2.0 * math.pi / counts
    theta = np.round(np.array(ths) / q) * q
    nan = np.full(t.size, np.nan)
    return Recording(t=t, theta=theta, theta_dot=np.gradient(theta, t)
                     + rng.normal(0.0, vel_noise, t.size), torque=np.array(us),
                     ball_x=nan, ball_y=nan.copy(), ball_valid=np.zeros(t.size, bool),
                     phi=nan.copy(), meta={"source": "test frame_run", "source_kind":
                                           "simulation", "sample_rate": rate,
                                           "theta_resolution": q})


def _eight(offset: float, coulomb: float, seed: int) -> dict:
    base = RigParams()
    rng = np.random.default_rng(seed)
    recs = [(f"run{i}", [frame_run(inertia=base.frame.inertia, torque_offset=offset,
                                   coulomb=coulomb, both_ways=i < 2,
                                   duration=6.0 if i < 2 else 60.0, rng=rng)])
            for i in range(8)]
    return diagnose_recordings(recs, base, DiagnoseOptions(max_effects=3, block=1.0)).summary


def _row(s: dict, name: str) -> dict:
    return next(r for st in s["stages"] for r in st["candidates"]
                if r["effect"] == name and r["selected"])


def test_offset_seen_by_two_of_eight_found_by_the_group_test() -> None:
    s = _eight(3e-5, 2e-3, 2)
    assert sorted(s["effects"]) == ["joint_coulomb_friction", "torque_offset"], s["effects"]
    row = _row(s, "torque_offset")
    assert row["significant_by"] == "group"
    assert row["heldout_gain"] < 0.05      # the pooled gain alone is at its threshold
    grp = row["group"]
    assert set(grp["recordings"]) <= {"run0", "run1"} and grp["recordings"]
    assert grp["gain"] > grp["threshold"] and grp["dbic"] < -6.0
    val = {p["name"]: p["value"] for p in s["parameters"]}
    assert val["tau_0"] == pytest.approx(3e-5, abs=1.5e-5)
    assert val["T_c"] == pytest.approx(2e-3, rel=0.05)
    rank = next(r for r in s["ranking"] if r["effect"] == "torque_offset")
    assert rank["significant_by"] == "group" and rank["group_at_selection"]["recordings"]


@pytest.mark.parametrize("coulomb", [0.0, 2e-3])
def test_clean_eight_stay_clean(coulomb: float) -> None:
    s = _eight(0.0, coulomb, 6)
    assert s["effects"] == (["joint_coulomb_friction"] if coulomb else []), s["effects"]
    assert not any(r["significant_by"] == "group" for st in s["stages"]
                   for r in st["candidates"] if r["selected"])
